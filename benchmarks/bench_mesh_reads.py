"""What reading and copying an object's meshes costs: per dev row, the seconds (CPU, this process) to read every OBJ
file's groups as the collision pieces and the cavity analysis read them (``mesh_io.obj_groups`` and
``mesh_io.group_meshes``), and to copy the object's meshes into a fresh folder as a refine copies them into its
workspace and its output (``copied_meshes.copy_meshes``, the MTL and texture files with them).

    .venv/bin/python benchmarks/bench_mesh_reads.py [--ids 9912 7236 ...] [--repeat N]

Each step is run ``--repeat`` times (default 3) per row: the first run's CPU time (what a refine of a new object
pays) and the least of the runs (the machine is shared; a per-process cache answers the repeats) are printed, one
line per row and the totals.
"""

from __future__ import annotations

import argparse
import csv
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DEV = ROOT.parent / "shared" / "datasets" / "partnet_mobility"


def _cpu(fn, repeat: int) -> tuple[float, float]:
    """(the first, the least) process CPU seconds of ``repeat`` calls of ``fn()``."""
    times = []
    for _ in range(max(1, repeat)):
        t = time.process_time()
        fn()
        times.append(time.process_time() - t)
    return times[0], min(times)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--ids", nargs="*", default=None, help="dev row ids (default: every row)")
    ap.add_argument("--repeat", type=int, default=3, help="runs per step, the least CPU time kept")
    args = ap.parse_args(argv)

    from asset2sim import mesh_io
    from asset2sim.tasks.assemble.copied_meshes import copy_meshes
    from asset2sim.tasks.ingest.extract import extract_asset

    with open(DEV / "manifest.csv", newline="") as fh:
        ids = [r["id"] for r in csv.DictReader(fh) if args.ids is None or r["id"] in args.ids]
    totals = [0.0, 0.0, 0.0, 0.0]
    print(f"{'row':>8} {'OBJ files':>9} {'read groups s (first / least)':>30} {'copy meshes s (first / least)':>30}")
    with tempfile.TemporaryDirectory(prefix="a2s-bench-reads-") as tmp:
        for rid in ids:
            objs = sorted((DEV / rid).rglob("*.obj"))
            asset = extract_asset(DEV / rid)

            def read() -> None:
                for p in objs:
                    mesh_io.obj_groups(p)
                    mesh_io.group_meshes(p)

            runs = iter(range(max(1, args.repeat)))
            row = (*_cpu(read, args.repeat), *_cpu(lambda: copy_meshes(asset, Path(tmp) / f"{rid}_{next(runs)}"), args.repeat))
            totals = [a + b for a, b in zip(totals, row)]
            print(f"{rid:>8} {len(objs):>9} {row[0]:>21.3f} / {row[1]:<6.3f} {row[2]:>21.3f} / {row[3]:<6.3f}", flush=True)
    print(f"{'all':>8} {'':>9} {totals[0]:>21.2f} / {totals[1]:<6.2f} {totals[2]:>21.2f} / {totals[3]:<6.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
