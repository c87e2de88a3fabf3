"""How much joint friction and damping does robust rest need? A grid over
one joint of a written asset, beside the real operating range of its part.

    python benchmarks/bench_hold_margin.py ASSET_DIR JOINT [--friction 8,15,22] \\
        [--damping 14,40,100] [--trials tilt+y,tilt-y] [--engine pybullet] [--label drawer]

ASSET_DIR is a written asset (``mobility.urdf``, ``initial_state.json``,
``overlay.json``: the output of ``asset2sim refine``). For each (friction,
damping) pair the joint's ``<dynamics>`` is replaced in a copy of the URDF
(in a temporary folder that links to the asset's meshes), robust rest
(:func:`tasks.check.robust_rest.run_robust_rest`, the trials
given, the joint springs of ``overlay.json``) runs in the engine, and the joint's largest drift in each trial is
printed with the tolerance (2 mm / 0.02 rad). The header prints the part's
operating range (:func:`tasks.check.force_ranges.operating_range`,
category from ``overlay.json``, part label from ``--label``): friction above
its upper end is not a real hinge or slide.

Use: to tell a joint that robust rest cannot hold within a real operating
force (the failure is physical: an impact the friction of a real slide does
not stop within the tolerance) from one that refine's search stopped short
of. Nothing of the asset is modified.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def _floats(s: str) -> list[float]:
    return [float(x) for x in s.split(",") if x.strip()]


def main(argv: list[str] | None = None) -> int:
    from asset2sim.urdf import UrdfDynamics, read_urdf, write_urdf
    from asset2sim.tasks.check import robust_rest
    from asset2sim.engines.source import SimObject, UrdfFile
    from asset2sim.tasks.interpret.operating_forces import operating_range
    from asset2sim.refined_asset import springs_from_overlay

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("asset", type=Path)
    ap.add_argument("joint")
    ap.add_argument("--friction", default="8,15,22", help="joint friction values, N (prismatic) or N m (revolute)")
    ap.add_argument("--damping", default="14,40,100", help="joint damping values, N s/m or N m s/rad")
    ap.add_argument("--trials", default=",".join(robust_rest.TRIALS))
    ap.add_argument("--engine", default="pybullet")
    ap.add_argument("--label", default=None, help="part label for the operating range (e.g. drawer, lid)")
    a = ap.parse_args(argv)

    urdf = a.asset / "mobility.urdf"
    model = read_urdf(urdf)
    try:
        joint = model.joint(a.joint)
    except KeyError:
        raise SystemExit(f"{urdf}: no joint {a.joint!r}; movable joints: "
                         f"{', '.join(j.name for j in model.movable_joints())}") from None
    state = json.loads((a.asset / "initial_state.json").read_text())["initial_joint_positions"]
    springs = springs_from_overlay(a.asset, state)
    category = json.loads((a.asset / "overlay.json").read_text()).get("category")
    rng, where = operating_range(category, a.label)
    unit = "N" if joint.type == "prismatic" else "N m"
    trials = tuple(t for t in a.trials.split(",") if t)
    cfg = robust_rest.RobustRestConfig(trials=trials)
    tol = cfg.joint_tol_prismatic if joint.type == "prismatic" else cfg.joint_tol_revolute
    print(f"{urdf} {a.joint} ({joint.type}), written friction {joint.friction:.3g} {unit}, damping {joint.damping:.3g}")
    print(f"operating range {where}: force {rng.force_n} N, torque {rng.torque_nm} N m; tolerance {tol:g}")
    scale = 1000.0 if joint.type == "prismatic" else 1.0
    shown = "mm" if joint.type == "prismatic" else "rad"
    print(f"{'friction':>9} {'damping':>8}  " + "  ".join(f"{t:>9}" for t in trials) + f"   (drift, {shown})")
    with tempfile.TemporaryDirectory() as tmp:
        for entry in a.asset.iterdir():  # the meshes, by their relative paths, without copying them
            if entry.name != urdf.name:
                (Path(tmp) / entry.name).symlink_to(entry.resolve())
        for f in _floats(a.friction):
            for c in _floats(a.damping):
                joint.dynamics = UrdfDynamics(damping=c, friction=f)
                out = Path(tmp) / "scan.urdf"
                out.write_bytes(write_urdf(model))
                run = robust_rest.run_robust_rest(a.engine, SimObject(UrdfFile(out), state, springs), config=cfg)
                cells = [f"{t.joint_drift.get(a.joint, float('nan')) * scale:9.3g}" for t in run.trials]
                print(f"{f:9.3g} {c:8.3g}  " + "  ".join(cells), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
