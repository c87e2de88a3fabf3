"""Host environments built with a refined object swapped in. The package's file holding the object, written back
by refine (``mjcf/host/files/<its path in the package>``), replaces the package's in a copy of the package (the
installed one is only read), and the package's own environment is built from the copy:

- Meta-World: the drawer, faucet and lever (scene files ``objects/<name>.xml`` around the object, whose
  environments include ``objects/assets/<name>.xml``); ``drawer-open-v3``, ``faucet-open-v3`` and
  ``lever-pull-v3`` run Meta-World's scripted policies, which move the part against the refined masses, damping
  and friction;
- robosuite: the door (``objects/door.xml``, loaded by the ``Door`` task as it is); the task runs with the refined
  masses, and a torque beyond the hinge's friction swings the door to its stop.

Neither package is a dependency of asset2sim (Meta-World pins ``mujoco==3.3.0``; robosuite pulls numba, mink and
qpsolvers): each runs in its own Python, named by ``ASSET2SIM_METAWORLD_PYTHON`` / ``ASSET2SIM_ROBOSUITE_PYTHON``
(default: this interpreter). A test is skipped, saying why, where that Python cannot build the package's
environments."""

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

from asset2sim.schemas.config import RefineConfig
from asset2sim.urdf import read_urdf

CONFIG = RefineConfig(engines=["pybullet"])
#: Run in Meta-World's Python with ``sys.argv[1]`` a JSON list (task, policy class, joint, bodies): the environment
#: built from the package on PYTHONPATH, its scripted policy run for 300 steps; prints what the compiled model
#: holds and where the joint went.
METAWORLD_SCRIPT = textwrap.dedent("""
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
#: Run in robosuite's Python: the ``Door`` task (no latch) built from the package on PYTHONPATH, 200 steps of a
#: zero action with a torque 2 N m beyond the hinge's friction loss on the hinge; prints the door's masses and
#: where the hinge went.
ROBOSUITE_SCRIPT = textwrap.dedent("""
    import json, mujoco, numpy as np, robosuite
    env = robosuite.make("Door", robots="Panda", has_renderer=False, has_offscreen_renderer=False,
                         use_camera_obs=False, use_latch=False)
    env.reset()
    m, d = env.sim.model._model, env.sim.data._data
    j = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, "Door_hinge")
    dof, adr = m.jnt_dofadr[j], m.jnt_qposadr[j]
    q0 = float(d.qpos[adr])
    for _ in range(200):
        d.qfrc_applied[dof] = m.dof_frictionloss[dof] + 2.0
        env.step(np.zeros(env.action_dim))
    print(json.dumps({"package": robosuite.__file__, "q0": q0, "q": float(d.qpos[adr]), "range": m.jnt_range[j].tolist(),
                      "mass": {m.body(i).name.removeprefix("Door_"): float(m.body_mass[i]) for i in range(m.nbody)
                               if m.body(i).name.startswith("Door_")}}))
""")
#: (task, scene file refined, request, policy, joint, bodies with geometry, the joint's least travel under the
#: policy: m or rad).
METAWORLD_TASKS = [
    ("drawer-open-v3", "drawer", "A drawer, slightly open.", "SawyerDrawerOpenV3Policy", "goal_slidey",
     ["drawercase_link", "drawer_link"], 0.05),
    ("faucet-open-v3", "faucet", "A faucet.", "SawyerFaucetOpenV3Policy", "knob_Joint_1", ["faucet_link2"], 0.3),
    ("lever-pull-v3", "lever", "A lever.", "SawyerLeverPullV3Policy", "LeverAxis", ["lever_link1"], 0.3),
]


def _host_python(package: str, variable: str, probe: str, why_separate: str) -> tuple[str, Path]:
    """(the Python named by ``variable``, else this one; its installed ``package`` folder) once ``probe`` (which
    prints the package's ``__file__`` last) runs there; skips, saying why, where it does not."""
    python = os.environ.get(variable, sys.executable)
    try:
        done = subprocess.run([python, "-c", probe], capture_output=True, text=True, timeout=300, check=False)
    except (OSError, subprocess.TimeoutExpired) as exc:
        pytest.skip(f"{python} cannot run {package}: {exc}")
    if done.returncode != 0:
        why = (done.stderr.strip().splitlines() or ["no output"])[-1]
        pytest.skip(f"{python} cannot build {package}'s environments ({why}); {package} is not a dependency of "
                    f"asset2sim and {why_separate}: install it in its own environment and name its Python in {variable}")
    return python, Path(done.stdout.strip().splitlines()[-1]).parent


@pytest.fixture(scope="module")
def metaworld_host() -> tuple[str, Path]:
    return _host_python("metaworld", "ASSET2SIM_METAWORLD_PYTHON",
                        "import metaworld; metaworld.MT1('drawer-open-v3', seed=0); print(metaworld.__file__)",
                        "pins mujoco==3.3.0")


@pytest.fixture(scope="module")
def robosuite_host() -> tuple[str, Path]:
    return _host_python("robosuite", "ASSET2SIM_ROBOSUITE_PYTHON",
                        "import robosuite; robosuite.make('Door', robots='Panda', has_renderer=False, "
                        "has_offscreen_renderer=False, use_camera_obs=False); print(robosuite.__file__)",
                        "pulls numba, mink and qpsolvers")


def _swapped(res, package: Path, tmp_path: Path) -> Path:
    """A copy of ``package`` with every file of ``mjcf/host/files/`` in place (paths inside the package's asset
    folder, found by the one the refined object's file came from); returns the copy's parent, for PYTHONPATH."""
    files = res.out_dir / "mjcf" / "host" / "files"
    written = sorted(files.rglob("*.xml"))
    assert written, res.report.notes
    copy = tmp_path / "host" / package.name
    shutil.copytree(package, copy, ignore=shutil.ignore_patterns("__pycache__"))
    assets = {"metaworld": copy / "assets", "robosuite": copy / "models" / "assets"}[package.name]
    for f in written:
        shutil.copyfile(f, assets / f.relative_to(files))
    return copy.parent


def _run(python: str, packages: Path, script: str, *args) -> dict:
    env = {**os.environ, "PYTHONPATH": str(packages)}
    done = subprocess.run([python, "-c", script, *args], capture_output=True, text=True, timeout=300, env=env, check=False)
    assert done.returncode == 0, done.stderr[-3000:]
    return json.loads(done.stdout.strip().splitlines()[-1])


@pytest.mark.parametrize("task, scene, prompt, policy, joint, bodies, travel", METAWORLD_TASKS,
                         ids=[t[0] for t in METAWORLD_TASKS])
def test_a_meta_world_environment_runs_with_the_refined_object_swapped_in(metaworld_host, tmp_path, task, scene, prompt,
                                                                          policy, joint, bodies, travel, refine_once):
    python, package = metaworld_host
    res = refine_once(package / "assets" / "objects" / f"{scene}.xml", prompt, CONFIG, extras=False)
    assert res.report.failure_mode == "none", res.report.failure_mode
    assert (res.out_dir / "mjcf" / "host" / "files" / "objects" / "assets" / f"{scene}.xml").is_file(), res.report.notes
    packages = _swapped(res, package, tmp_path)
    swapped = _run(python, packages, METAWORLD_SCRIPT, json.dumps([task, policy, joint, bodies]))
    assert Path(swapped["package"]).parent.parent == packages  # the copy was built, not the installed package
    model = read_urdf(res.out_dir / "mobility.urdf")
    for body in bodies:
        assert swapped["mass"][body] == pytest.approx(model.links[body].inertial.mass, rel=1e-5), body
    refined = next(j for j in model.joints if j.name == joint)
    assert swapped["damping"] == pytest.approx(refined.dynamics.damping, rel=1e-5)
    assert swapped["frictionloss"] == pytest.approx(refined.dynamics.friction, rel=1e-5)
    assert abs(swapped["q"] - swapped["q0"]) > travel, swapped  # the policy moved the refined part


def test_robosuite_s_door_task_runs_with_the_refined_door_swapped_in(robosuite_host, tmp_path, refine_once):
    """robosuite's ``Door`` task sets the hinge's damping and friction itself (``DoorObject(friction=0.0,
    damping=0.1)``); the masses and inertias are the file's."""
    python, package = robosuite_host
    xml = package / "models" / "assets" / "objects" / "door.xml"
    res = refine_once(xml, "A door, slightly open.", CONFIG, extras=False)
    assert res.report.failure_mode == "none", res.report.failure_mode
    assert (res.out_dir / "mjcf" / "host" / "files" / "objects" / "door.xml").is_file(), res.report.notes
    packages = _swapped(res, package, tmp_path)
    swapped = _run(python, packages, ROBOSUITE_SCRIPT)
    assert Path(swapped["package"]).parent.parent == packages
    model = read_urdf(res.out_dir / "mobility.urdf")
    for body in ("frame", "door", "latch"):
        assert swapped["mass"][body] == pytest.approx(model.links[body].inertial.mass, rel=1e-5), body
    hinge = next(j for j in model.joints if j.name == "hinge")
    assert swapped["range"] == pytest.approx([hinge.limit.lower, hinge.limit.upper], abs=1e-6)  # radians, as robosuite compiles it
    assert swapped["q"] > swapped["q0"] + 0.3, swapped  # pushed open to its 0.4 rad stop
