"""Whether a refined URDF's passive ``<limit effort velocity>`` changes anything in the simulators that read it: each
output folder's ``mobility.urdf`` is loaded as written and with ``effort`` and ``velocity`` removed from every
``<limit>``, in PyBullet (its default motors left on, gravity, 2 s), MuJoCo (its own URDF import, 2 s) and SAPIEN 3
(its URDF loader on the file without its ``<visual>`` elements, which need a renderer, 2 s), every movable joint started 0.3 of its range from its lower limit; prints per folder and
engine the largest joint difference between the two (0 when the attributes change nothing) and the per-joint
``effort`` / ``velocity`` each engine keeps.

    .venv/bin/python benchmarks/bench_limit_attributes.py OUT [OUT ...]
"""

from __future__ import annotations

import argparse
import re
import shutil
import tempfile
from pathlib import Path

import numpy as np

STEPS = 480  # 2 s at 1/240 s


def _stripped(urdf: Path, dest: Path) -> Path:
    text = re.sub(r'\s(?:effort|velocity)="[^"]*"', "", urdf.read_text())
    out = dest / urdf.name
    out.write_text(text)
    return out


def _starts(lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    return lo + 0.3 * (hi - lo)


def pybullet_run(urdf: Path) -> tuple[np.ndarray, list]:
    import pybullet as p
    c = p.connect(p.DIRECT)
    try:
        p.setGravity(0, 0, -9.81, physicsClientId=c)
        b = p.loadURDF(str(urdf), useFixedBase=True, flags=p.URDF_USE_INERTIA_FROM_FILE, physicsClientId=c)
        idx = [i for i in range(p.getNumJoints(b, physicsClientId=c)) if p.getJointInfo(b, i, physicsClientId=c)[2] in (0, 1)]
        info = [p.getJointInfo(b, i, physicsClientId=c) for i in idx]
        q0 = _starts(np.array([x[8] for x in info]), np.array([x[9] for x in info]))
        for i, q in zip(idx, q0):
            p.resetJointState(b, i, float(q), physicsClientId=c)
        qs = []
        for _ in range(STEPS):
            p.stepSimulation(physicsClientId=c)
            qs.append([p.getJointState(b, i, physicsClientId=c)[0] for i in idx])
        return np.array(qs), [(x[10], x[11]) for x in info]
    finally:
        p.disconnect(c)


def mujoco_run(urdf: Path) -> tuple[np.ndarray, list]:
    import mujoco
    m = mujoco.MjModel.from_xml_path(str(urdf))
    d = mujoco.MjData(m)
    lim = m.jnt_range[m.jnt_limited.astype(bool)] if m.njnt else np.zeros((0, 2))
    d.qpos[-len(lim):] = _starts(lim[:, 0], lim[:, 1]) if len(lim) else d.qpos[-0:]
    qs = []
    for _ in range(STEPS):
        mujoco.mj_step(m, d)
        qs.append(d.qpos.copy())
    return np.array(qs), [(bool(a), [float(x) for x in r]) for a, r in zip(m.jnt_actfrclimited, m.jnt_actfrcrange)]


def sapien_run(urdf: Path) -> tuple[np.ndarray, list]:
    import sapien
    scene = sapien.Scene([sapien.physx.PhysxCpuSystem()])  # physics only
    scene.set_timestep(1 / 240)
    loader = scene.create_urdf_loader()
    loader.fix_root_link = True
    physics_only = urdf.with_name(urdf.stem + "_physics.urdf")  # SAPIEN's loader needs a renderer for <visual>: dropped
    physics_only.write_text(re.sub(r"<visual\b.*?</visual>", "", urdf.read_text(), flags=re.S))
    art = loader.load(str(physics_only))
    lim = np.array([j.get_limits()[0] for j in art.get_active_joints()])
    art.set_qpos(_starts(lim[:, 0], lim[:, 1]).astype(np.float32))
    qs = []
    for _ in range(STEPS):
        scene.step()
        qs.append(art.get_qpos().copy())
    return np.array(qs), [(float(np.ravel(j.force_limit)[0]), float(np.ravel(j.drive_velocity_target)[0])) for j in art.get_active_joints()]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("outs", nargs="+", type=Path)
    args = ap.parse_args()
    for out in args.outs:
        urdf = out / "mobility.urdf"
        with tempfile.TemporaryDirectory() as tmp:
            work = Path(tmp) / "out"
            shutil.copytree(out, work)
            bare = _stripped(work / "mobility.urdf", Path(tmp))
            shutil.move(str(bare), work / "bare.urdf")
            for name, run in (("pybullet", pybullet_run), ("mujoco", mujoco_run), ("sapien", sapien_run)):
                try:
                    (a, kept), (b, _) = run(work / "mobility.urdf"), run(work / "bare.urdf")
                except Exception as exc:  # an engine not installed or refusing the file: said, the others still run
                    print(f"{out.name:<24} {name:<9} not run: {type(exc).__name__}: {exc}")
                    continue
                print(f"{out.name:<24} {name:<9} max |q_written - q_bare| = {float(np.abs(a - b).max(initial=0.0)):.3g}"
                      f" over {a.shape[1]} joints, {STEPS} steps; what the engine kept of the limit: {kept}")


if __name__ == "__main__":
    main()
