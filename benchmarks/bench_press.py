"""A hand's press into each stop of every handled part (``asset2sim.tasks.check.press``) of refined output folders,
in several engines: root fixed (the other hand holds it), gravity on, no ground, the files' springs; the part pressed
from its initial state into each end of its range at its grasp point (``report.json``'s operability hand: grasp
lever, the top of its operating range) with 20 N and with that top, at most at the hand's speed, slowing near the stop (0.25 m/s at the
grasp point). A push button or key (``part_priors.push_buttons``) is pressed only into the end it is pressed toward,
away from its closed end, where it rests out of its body: a hand pushes a button in and never pulls it out. Prints per
part, engine and force how far past the limit it went (deg or mm, and mm at the grasp
point: at 1/240 s a hand at 0.25 m/s moves the grasp point 1 mm a step, several degrees on a 3 cm lever), how much
deeper its deepest self-contact sank (mm), whether the engine diverged and the share of the force the hand pressed
with at the farthest step (none: the hand still moved it at its speed; a small share: the one step a part resting at
its stop moves freely, ``asset2sim.tasks.check.press.Press``); then the counts. ``--root-hold constraint``: the root loaded free and
held by the engine's bounded fixed constraint (``hold_root``, 1000 N) instead of a fixed base. A MuJoCo or MJX session
judges its solver aids on the object as its export writes it (``SessionOptions.object_root_fixed``): each session's
joint aids are compared with those ``report.json`` lists for the exported file, and a difference is printed.

    python benchmarks/bench_press.py --root DIR [--ids 102990,103275] [--engines pybullet,mujoco,mjx] [--forces 20,top]
        [--root-hold fixed|constraint]
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--root", type=Path, default=ROOT / "out" / "bench_refine")
    ap.add_argument("--ids", default="")
    ap.add_argument("--engines", default="pybullet,mujoco,mjx")
    ap.add_argument("--forces", default="20,top", help="N at the grasp point, 'top' the top of the operating range")
    ap.add_argument("--root-hold", choices=("fixed", "constraint"), default="fixed")
    args = ap.parse_args(argv)

    from asset2sim.engines.base import EngineUnsupported
    from asset2sim.engines.quiet import quiet_stdout
    from asset2sim.engines.source import UrdfFile
    from asset2sim.refined_asset import RefinedAsset
    from asset2sim.tasks.check.gripper import GripperLimits
    from asset2sim.tasks.check.press import press_joint
    from asset2sim.tasks.check.sweep import HOLD_FORCE
    from asset2sim.tasks.ingest.extract import extract_asset
    from asset2sim.tasks.interpret.part_labels import labels_from_names
    from asset2sim.tasks.interpret.part_priors import push_buttons

    speed = GripperLimits().max_speed_m_s
    folders = sorted(p.parent for p in args.root.glob("*/mobility.urdf"))
    if args.ids:
        folders = [f for f in folders if f.name in set(args.ids.split(","))]
    counts: dict[str, list[int]] = {}
    for f in folders:
        asset = RefinedAsset(f)
        op = asset.report.metric("operability")
        parts = {j: p for j, p in (op.details.get("parts", {}) if op is not None else {}).items() if p.get("hand_force_n")}
        if not parts:
            print(f"{f.name:>7}  no handled part", flush=True)
            continue
        pushed = push_buttons(labels_from_names(extract_asset(f)), asset.report.category)
        ends = asset.report.closed_ends
        options = asset.session_options()
        fixed = args.root_hold == "fixed"
        options = type(options)(**{**options.__dict__, "fixed_base": fixed, "gravity": True, "ground": False})
        for engine in args.engines.split(","):
            t0 = time.perf_counter()
            with quiet_stdout():
                session = UrdfFile(asset.urdf_path).open(engine, options)
            try:
                if engine in ("mujoco", "mjx") and joint_aids(session.build.aids) != joint_aids(asset.report.solver_aids):
                    print(f"{f.name:>7} {engine:<8} solver aids differ from report.json's: {joint_aids(session.build.aids)}", flush=True)
                try:
                    session.hold_root(HOLD_FORCE)
                except EngineUnsupported as exc:
                    print(f"{f.name:>7} {engine:<8} skipped: {exc}", flush=True)
                    continue
                for j, p in parts.items():
                    lever = p.get("lever_m")
                    lo, hi = session.joint_limits[j]
                    for force in args.forces.split(","):
                        newton = float(p["hand_force_n"]) if force == "top" else float(force)
                        pressed_in = j in pushed and j in ends  # only into the end away from where it rests
                        for limit in ((hi,) if ends[j]["direction"] > 0 else (lo,)) if pressed_in else (lo, hi):
                            r = press_joint(session, j, limit, newton * (lever or 1.0), speed / lever if lever else speed)
                            unit, k = ("deg", math.degrees(1)) if lever else ("mm", 1e3)
                            at_grasp = r.past * (lever or 1.0)  # m the grasp point went past the stop
                            c = counts.setdefault(engine, [0, 0, 0, 0])
                            c[0] += 1
                            c[1] += r.passed
                            c[2] += r.diverged
                            c[3] += r.passed or (not r.diverged and r.sank <= 2e-3 and at_grasp <= 2e-3)
                            share = "" if r.peak_effort is None else f", at {r.peak_effort / r.effort:4.0%} of the force"
                            print(f"{f.name:>7} {engine:<8} {j:<9} {newton:6.1f} N into {limit:+.3f}: past {r.past * k:+8.3f} {unit}"
                                  f" ({at_grasp * 1e3:+.2f} mm at the grasp point{share}), contact {r.sank * 1e3:+6.2f} mm"
                                  f"{'  DIVERGED' if r.diverged else ''}{'' if r.passed else '  FAIL'}", flush=True)
            finally:
                session.close()
            print(f"{f.name:>7} {engine:<8} {time.perf_counter() - t0:.1f} s", flush=True)
    print()
    print("engine    presses  within 1 deg / 2 mm, stable  diverged  within 1 deg or 2 mm at the grasp point, stable")
    for e, (n, ok, bad, grasp) in counts.items():
        print(f"{e:<9} {n:>7} {ok:>28} {bad:>9} {grasp:>47}")
    return 0


def joint_aids(aids) -> list[tuple]:
    """(kind, element, written) of every solver aid in ``aids`` but the ground's (the press has no ground), sorted."""
    return sorted((a.kind, a.element, sorted(a.written.items())) for a in aids if a.kind != "ground_contact_impedance")


if __name__ == "__main__":
    sys.exit(main())
