"""A Meta-World environment built with a refined object swapped in: Meta-World's drawer (``objects/drawer.xml``, a
scene file around the drawer) is refined, and the object's included file written back
(``mjcf/host/fragments/objects/assets/drawer.xml``) replaces the package's in a copy of the package (the installed
one is only read); ``drawer-open-v3`` is built from the copy and run with Meta-World's scripted policy, which
pulls the drawer open against the refined masses, damping and friction.

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

ENV = "drawer-open-v3"
#: Run in the host's Python: the environment built from the package on PYTHONPATH, the scripted policy for 300
#: steps; prints what the compiled model holds and how far the drawer moved.
SCRIPT = textwrap.dedent("""
    import json, sys, metaworld
    from metaworld.policies import SawyerDrawerOpenV3Policy
    mt = metaworld.MT1("drawer-open-v3", seed=0)
    env = mt.train_classes["drawer-open-v3"]()
    env.set_task(mt.train_tasks[0])
    obs, _ = env.reset()
    m, d = env.model, env.data
    j = m.joint("goal_slidey")
    q0 = float(d.qpos[j.qposadr[0]])
    policy = SawyerDrawerOpenV3Policy()
    for _ in range(300):
        obs, reward, terminated, truncated, info = env.step(policy.get_action(obs))
    print(json.dumps({"package": metaworld.__file__, "q0": q0, "q": float(d.qpos[j.qposadr[0]]),
                      "success": float(info["success"]),
                      "mass": {b: float(m.body(b).mass[0]) for b in ("drawercase_link", "drawer_link")},
                      "damping": float(m.dof_damping[j.dofadr[0]]), "frictionloss": float(m.dof_frictionloss[j.dofadr[0]])}))
""")


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


def _run(python: str, packages: Path) -> dict:
    env = {**os.environ, "PYTHONPATH": str(packages)}
    done = subprocess.run([python, "-c", SCRIPT], capture_output=True, text=True, timeout=300, env=env)
    assert done.returncode == 0, done.stderr[-3000:]
    return json.loads(done.stdout.strip().splitlines()[-1])


def test_a_meta_world_drawer_environment_runs_with_the_refined_drawer_swapped_in(tmp_path):
    python, package = _host_python()
    xml = package / "assets" / "objects" / "drawer.xml"
    res = refine_asset(xml, "A drawer, slightly open.", tmp_path / "out", RefineConfig(engines=["pybullet"]), extras=False)
    assert res.report.failure_mode == "none", res.report.failure_mode
    fragment = res.out_dir / "mjcf" / "host" / "fragments" / "objects" / "assets" / "drawer.xml"
    assert fragment.is_file(), res.report.notes
    copy = tmp_path / "host" / "metaworld"
    shutil.copytree(package, copy, ignore=shutil.ignore_patterns("__pycache__"))
    shutil.copyfile(fragment, copy / "assets" / "objects" / "assets" / "drawer.xml")

    swapped = _run(python, copy.parent)
    assert Path(swapped["package"]).parent == copy  # the copy was built, not the installed package
    model = read_urdf(res.out_dir / "mobility.urdf")
    for body in ("drawercase_link", "drawer_link"):
        assert swapped["mass"][body] == pytest.approx(model.links[body].inertial.mass, rel=1e-5), body
    slide = next(j for j in model.joints if j.name == "goal_slidey")
    assert swapped["damping"] == pytest.approx(slide.dynamics.damping, rel=1e-5)
    assert swapped["frictionloss"] == pytest.approx(slide.dynamics.friction, rel=1e-5)
    assert swapped["q"] < swapped["q0"] - 0.05, swapped  # the policy pulled the refined drawer open (its range is -0.16..0 m)
