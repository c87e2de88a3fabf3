"""Where a refine's time goes in its collision pieces: per dev row, the refine's wall time, how many times its
collision pieces were built (limits or meshes changed) and the seconds of each step of a build.

    .venv/bin/python benchmarks/bench_pieces.py [--ids 102990 9912 ...] [--out DIR]

Refines each row of ``../shared/datasets/partnet_mobility/manifest.csv`` (its own request, no extras) in this
process with an empty on-disk cache of its own (``ASSET2SIM_CACHE`` under ``--out``) and one BLAS thread, as a flow
worker runs, and times :func:`asset2sim.tasks.assemble.collision_geometry._made_pieces` (a build) and its steps:
the containment cuts (``_resolve_containment``), the merges (``_merge_link``), the parent-child separation
(``separate_parent_child``, also run per initial state), the running and swept clearance and the group hulls; and
every CoACD decomposition (``coacd.run_coacd``, where CoACD is installed: the collision repairs', and an open
container's inside a build, which then counts in both). Prints one line per row and the totals with each step's
share of all refine time.
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # as the flow's workers (asset2sim.cli), before numpy

import argparse  # noqa: E402
import collections  # noqa: E402
import csv  # noqa: E402
import functools  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
DEV = ROOT.parent / "shared" / "datasets" / "partnet_mobility"

#: Steps of a build timed (names in ``collision_geometry``), in the order printed.
STEPS = ("_made_pieces", "_resolve_containment", "_merge_link", "separate_parent_child", "running_clearance",
         "swept_clearance", "_group_hulls")
LABELS = {"_made_pieces": "builds", "_resolve_containment": "containment", "_merge_link": "merges",
          "separate_parent_child": "separation", "running_clearance": "running", "swept_clearance": "swept",
          "_group_hulls": "hulls", "coacd": "CoACD"}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--ids", nargs="*", default=None, help="dev row ids (default: every row)")
    ap.add_argument("--out", type=Path, default=None, help="work folder (default: a temporary one)")
    args = ap.parse_args(argv)
    out = args.out or Path(tempfile.mkdtemp(prefix="a2s-bench-pieces-"))
    os.environ.setdefault("ASSET2SIM_CACHE", str(out / "cache"))  # empty: every build made, none read back

    from asset2sim.tasks.assemble import collision_geometry as cg
    from asset2sim.tasks.refine import refine_asset

    seconds: collections.Counter = collections.Counter()
    calls: collections.Counter = collections.Counter()

    def timed(name, fn):
        @functools.wraps(fn)
        def wrapper(*a, **k):
            t = time.perf_counter()
            try:
                return fn(*a, **k)
            finally:
                seconds[name] += time.perf_counter() - t
                calls[name] += 1
        return wrapper

    for name in STEPS:
        setattr(cg, name, timed(name, getattr(cg, name)))
    steps = STEPS
    try:  # the decomposition module imports CoACD when it runs it: the wrapped function is the one it calls
        import coacd

        coacd.run_coacd = timed("coacd", coacd.run_coacd)
        steps = (*STEPS, "coacd")
    except ImportError:
        pass
    with open(DEV / "manifest.csv", newline="") as fh:
        rows = [r for r in csv.DictReader(fh) if args.ids is None or r["id"] in args.ids]
    totals: collections.Counter = collections.Counter()
    wall = 0.0
    print(f"{'row':>8} {'refine s':>9} " + " ".join(f"{LABELS[s]:>12}" for s in steps) + "   (s / calls)")
    for r in rows:
        seconds.clear()
        calls.clear()
        t = time.perf_counter()
        refine_asset(DEV / r["id"], r["prompt"], out / r["id"], category=r["category"], extras=False, media=False,
                     skip_if_complete=False, overwrite=True)
        dt = time.perf_counter() - t
        wall += dt
        totals.update(seconds)
        print(f"{r['id']:>8} {dt:9.1f} " + " ".join(f"{seconds[s]:7.2f}/{calls[s]:<4d}" for s in steps), flush=True)
    print(f"{'all':>8} {wall:9.1f} " + " ".join(f"{totals[s]:7.1f}     " for s in steps))
    print("share of refine time: " + ", ".join(f"{LABELS[s]} {totals[s] / wall:.0%}" for s in steps if wall))
    return 0


if __name__ == "__main__":
    sys.exit(main())
