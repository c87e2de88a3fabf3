"""What the rest test's bookkeeping costs beside the physics: robust rest's trials on refined outputs, each timed as
:func:`asset2sim.tasks.check.metrics.run_rest_test` runs it (a step, then the joint positions and the root pose
recorded) and again as the same number of bare ``session.step(1)`` calls from the same disturbance.

    .venv/bin/python benchmarks/bench_rest_steps.py [OUTPUT ...] [--ids 7236 9748 ...] [--out DIR]

OUTPUT: refined output folders (``mobility.urdf``, ``initial_state.json``, ``overlay.json``); without them the dev
rows of ``--ids`` (default: every row) are refined first (their own request, extras off) into ``--out``. Each
output is opened in PyBullet as robust rest opens it (state, springs; SPEC conventions); an output whose root is
fixed as mounted is skipped (robust rest skips it). Prints per output the steps, both times, the bookkeeping per step
(us) and its share of the rest tests' time, then the totals. Wall time of one process: run it on an idle machine.
"""

from __future__ import annotations

import argparse
import csv
import json
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DEV = ROOT.parent / "shared" / "datasets" / "partnet_mobility"


def _outputs(args) -> list[Path]:
    """The output folders to measure: those given, else the dev rows of ``args.ids`` refined into ``args.out``."""
    if args.outputs:
        return [Path(p) for p in args.outputs]
    from asset2sim.tasks.refine import refine_asset

    out = args.out or Path(tempfile.mkdtemp(prefix="a2s-bench-rest-steps-"))
    with open(DEV / "manifest.csv", newline="") as fh:
        rows = [r for r in csv.DictReader(fh) if args.ids is None or r["id"] in args.ids]
    done = []
    for r in rows:
        refine_asset(DEV / r["id"], r["prompt"], out / r["id"], category=r["category"], extras=False, media=False,
                     skip_if_complete=False, overwrite=True)
        done.append(out / r["id"])
    return done


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("outputs", nargs="*", help="refined output folders (default: refine the dev rows of --ids)")
    ap.add_argument("--ids", nargs="*", default=None, help="dev row ids to refine (default: every row)")
    ap.add_argument("--out", type=Path, default=None, help="where the dev rows are refined (default: a temporary folder)")
    args = ap.parse_args(argv)
    sys.path.insert(0, str(ROOT))
    from asset2sim.engines.source import SimObject, UrdfFile
    from asset2sim.refined_asset import springs_from_overlay
    from asset2sim.tasks.check import metrics, robust_rest

    cfg = robust_rest.RobustRestConfig()
    print(f"{'output':40s} {'steps':>7} {'rest tests s':>12} {'steps alone s':>13} {'us/step':>8} {'share':>6}")
    all_steps, all_test, all_bare = 0, 0.0, 0.0
    for folder in _outputs(args):
        state = json.loads((folder / "initial_state.json").read_text())["initial_joint_positions"]
        overlay = json.loads((folder / "overlay.json").read_text())
        if (overlay.get("mounting") or {}).get("fixed"):
            print(f"{folder.name:40s} skipped: root fixed as mounted")
            continue
        obj = SimObject(UrdfFile(folder / "mobility.urdf"), state, springs_from_overlay(folder, state))
        session = obj.open("pybullet")
        try:
            saved = session.save_state()
            steps, t_test, t_bare = 0, 0.0, 0.0
            for name in cfg.trials:
                session.restore_state(saved)
                robust_rest._disturb(session, name, cfg)
                step, count = session.step, [0]

                def counted(n: int = 1, step=step, count=count) -> None:
                    count[0] += n
                    step(n)

                session.step = counted
                t = time.perf_counter()
                metrics.run_rest_test(session, obj.conventions, recovery_time=cfg.recovery_time)
                t_test += time.perf_counter() - t
                session.step = step
                session.restore_state(saved)
                robust_rest._disturb(session, name, cfg)
                t = time.perf_counter()
                for _ in range(count[0]):
                    session.step(1)
                t_bare += time.perf_counter() - t
                steps += count[0]
            session.discard_state(saved)
        finally:
            session.close()
        all_steps, all_test, all_bare = all_steps + steps, all_test + t_test, all_bare + t_bare
        print(f"{folder.name:40s} {steps:7d} {t_test:12.3f} {t_bare:13.3f} {1e6 * (t_test - t_bare) / max(steps, 1):8.1f} "
              f"{(t_test - t_bare) / max(t_test, 1e-9):6.0%}", flush=True)
    if all_steps:
        print(f"{'all':40s} {all_steps:7d} {all_test:12.3f} {all_bare:13.3f} {1e6 * (all_test - all_bare) / all_steps:8.1f} "
              f"{(all_test - all_bare) / max(all_test, 1e-9):6.0%}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
