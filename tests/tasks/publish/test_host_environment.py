"""Meta-World environments built with a refined object swapped in: Meta-World's drawer, faucet and lever (scene
files ``objects/<name>.xml`` around the object) are refined, and the object's included file written back
(``mjcf/host/fragments/objects/assets/<name>.xml``) replaces the package's in a copy of the package (the installed
one is only read); ``drawer-open-v3``, ``faucet-open-v3`` and ``lever-pull-v3`` are built from the copy and run
with Meta-World's scripted policies, which move the part against the refined masses, damping and friction.

Meta-World is not a dependency of asset2sim and pins ``mujoco==3.3.0``: it runs in its own Python, named by
``ASSET2SIM_METAWORLD_PYTHON`` (default: this interpreter). The test is skipped, saying why, where that Python
cannot import Meta-World or build its environments."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

pytest.importorskip("mujoco")

from asset2sim.schemas.config import RefineConfig  # noqa: E402
from asset2sim.tasks.refine import refine_asset  # noqa: E402
from asset2sim.urdf import read_urdf  # noqa: E402

#: Run in the host's Python with ``sys.argv[1]`` a JSON list (task, policy class, joint, bodies): the environment
#: built from the package on PYTHONPATH, its scripted policy run for 300 steps; prints what the compiled model
#: holds and where the joint went.
SCRIPT = textwrap.dedent("""
    import json, sys, metaworld, metaworld.policies as policies
    task, policy_name, joint, bodies = json.loads(sys.argv[1])
    mt = metaworld.MT1(task, seed=0)
    env = mt.train_classes[task]()
    env.set_task(mt.train_tasks[0])
    obs, _ = env.reset()
    m, d = env.model, env.data
    j = m.joint(joint)
    q0 = float(d.qpos[j.qposadr[0]])
    policy = getattr(policies, policy_name)()
    for _ in range(300):
        obs, reward, terminated, truncated, info = env.step(policy.get_action(obs))
    print(json.dumps({"package": metaworld.__file__, "q0": q0, "q": float(d.qpos[j.qposadr[0]]),
                      "success": float(info["success"]), "mass": {b: float(m.body(b).mass[0]) for b in bodies},
                      "damping": float(m.dof_damping[j.dofadr[0]]), "frictionloss": float(m.dof_frictionloss[j.dofadr[0]])}))
""")
#: (task, scene file refined, request, policy, joint, bodies with geometry, the joint's least travel under the
#: policy: m or rad).
TASKS = [
    ("drawer-open-v3", "drawer", "A drawer, slightly open.", "SawyerDrawerOpenV3Policy", "goal_slidey",
     ["drawercase_link", "drawer_link"], 0.05),
    ("faucet-open-v3", "faucet", "A faucet.", "SawyerFaucetOpenV3Policy", "knob_Joint_1", ["faucet_link2"], 0.3),
    ("lever-pull-v3", "lever", "A lever.", "SawyerLeverPullV3Policy", "LeverAxis", ["lever_link1"], 0.3),
]


def _host_python() -> tuple[str, Path]:
    """(the host's Python, its installed ``metaworld`` package folder); skips, saying why, where it cannot build
    Meta-World's environments."""
    python = os.environ.get("ASSET2SIM_METAWORLD_PYTHON", sys.executable)
    probe = "import metaworld; metaworld.MT1('drawer-open-v3', seed=0); print(metaworld.__file__)"
    try:
        done = subprocess.run([python, "-c", probe], capture_output=True, text=True, timeout=300)
    except (OSError, subprocess.TimeoutExpired) as exc:
        pytest.skip(f"{python} cannot run Meta-World: {exc}")
    if done.returncode != 0:
        why = (done.stderr.strip().splitlines() or ["no output"])[-1]
        pytest.skip(f"{python} cannot build Meta-World's environments ({why}); Meta-World is not a dependency of "
                    "asset2sim and pins mujoco==3.3.0: install it in its own environment and name its Python in "
                    "ASSET2SIM_METAWORLD_PYTHON")
    return python, Path(done.stdout.strip().splitlines()[-1]).parent


@pytest.fixture(scope="module")
def host() -> tuple[str, Path]:
    """:func:`_host_python`, probed once for the module."""
    return _host_python()


def _run(python: str, packages: Path, args: list) -> dict:
    env = {**os.environ, "PYTHONPATH": str(packages)}
    done = subprocess.run([python, "-c", SCRIPT, json.dumps(args)], capture_output=True, text=True, timeout=300, env=env)
    assert done.returncode == 0, done.stderr[-3000:]
    return json.loads(done.stdout.strip().splitlines()[-1])


@pytest.mark.parametrize("task, scene, prompt, policy, joint, bodies, travel", TASKS, ids=[t[0] for t in TASKS])
def test_a_meta_world_environment_runs_with_the_refined_object_swapped_in(host, tmp_path, task, scene, prompt, policy,
                                                                          joint, bodies, travel):
    python, package = host
    xml = package / "assets" / "objects" / f"{scene}.xml"
    res = refine_asset(xml, prompt, tmp_path / "out", RefineConfig(engines=["pybullet"]), extras=False)
    assert res.report.failure_mode == "none", res.report.failure_mode
    fragment = res.out_dir / "mjcf" / "host" / "fragments" / "objects" / "assets" / f"{scene}.xml"
    assert fragment.is_file(), res.report.notes
    copy = tmp_path / "host" / "metaworld"
    shutil.copytree(package, copy, ignore=shutil.ignore_patterns("__pycache__"))
    shutil.copyfile(fragment, copy / "assets" / "objects" / "assets" / f"{scene}.xml")

    swapped = _run(python, copy.parent, [task, policy, joint, bodies])
    assert Path(swapped["package"]).parent == copy  # the copy was built, not the installed package
    model = read_urdf(res.out_dir / "mobility.urdf")
    for body in bodies:
        assert swapped["mass"][body] == pytest.approx(model.links[body].inertial.mass, rel=1e-5), body
    refined = next(j for j in model.joints if j.name == joint)
    assert swapped["damping"] == pytest.approx(refined.dynamics.damping, rel=1e-5)
    assert swapped["frictionloss"] == pytest.approx(refined.dynamics.friction, rel=1e-5)
    assert abs(swapped["q"] - swapped["q0"]) > travel, swapped  # the policy moved the refined part
