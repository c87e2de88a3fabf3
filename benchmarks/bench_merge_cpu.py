"""CPU seconds of the merges of a cold refine's collision pieces (``merge_pieces``), this checkout's against
another commit's ``tasks/assemble/convex_pieces.py``, on the same calls, and whether they make the same pieces.

    .venv/bin/python benchmarks/bench_merge_cpu.py [--ids 102622,9912] [--base f9a0c56] [--repeat 3]

Refines each dev row (its own request, ``--no-extras``, the on-disk cache off, one BLAS thread as the flow's
workers) until its first collision pieces are written, recording every ``merge_pieces`` call; then runs the
calls with each module in turn, ``--repeat`` times (the process's hull memo emptied before each run), and prints
the CPU seconds of each run and whether both made the same pieces, bit for bit. Exit status 1 when they differ.
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # as the flow's workers (asset2sim.cli), before numpy
os.environ["ASSET2SIM_CACHE"] = "off"

import argparse  # noqa: E402
import csv  # noqa: E402
import hashlib  # noqa: E402
import importlib.util  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
DEV = ROOT.parent / "shared" / "datasets" / "partnet_mobility"


class _Written(Exception):
    """The first collision pieces are written: the calls are recorded."""


def record(row: dict, work: Path) -> list:
    """The ``merge_pieces`` calls (args, kwargs) of ``row``'s refine up to its first collision pieces."""
    from asset2sim.schemas.config import RefineConfig
    from asset2sim.tasks.assemble import collision_geometry, containment_cuts, convex_pieces
    from asset2sim.tasks.refine import refine_asset

    calls, merge, convex = [], convex_pieces.merge_pieces, collision_geometry.convex_collisions

    def merge_recorded(*a, **k):
        calls.append((a, k))
        return merge(*a, **k)

    def convex_then_stop(*a, **k):
        convex(*a, **k)
        raise _Written

    containment_cuts.merge_pieces = collision_geometry.merge_pieces = merge_recorded
    collision_geometry.convex_collisions = convex_then_stop
    try:
        refine_asset(DEV / row["id"], row["prompt"], work / row["id"], RefineConfig(), task=row.get("task") or None,
                     skip_if_complete=False, overwrite=True, extras=False)
    except _Written:
        pass
    finally:
        containment_cuts.merge_pieces = collision_geometry.merge_pieces = merge
        collision_geometry.convex_collisions = convex
    return calls


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--ids", default="102622,9912")
    ap.add_argument("--base", default="f9a0c56", help="commit whose convex_pieces.py is the other side")
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args(argv)
    from asset2sim.tasks.assemble import convex_pieces as head

    work = Path(tempfile.mkdtemp(prefix="a2s-merge-cpu-"))
    (work / "base.py").write_text(subprocess.run(["git", "show", f"{args.base}:tasks/assemble/convex_pieces.py"], cwd=ROOT,
                                                 check=True, capture_output=True, text=True).stdout)
    spec = importlib.util.spec_from_file_location("convex_pieces_base", work / "base.py")
    base = sys.modules[spec.name] = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(base)
    with open(DEV / "manifest.csv", newline="") as fh:
        rows = {r["id"]: r for r in csv.DictReader(fh)}
    differ = 0
    for rid in args.ids.split(","):
        calls = record(rows[rid], work)
        seconds: dict[str, list[float]] = {args.base: [], "this": []}
        digest = {}
        for _ in range(args.repeat):
            for name, module in ((args.base, base), ("this", head)):
                module._HULLS.clear()
                h, t = hashlib.sha256(), time.process_time()
                for a, k in calls:
                    for p in module.merge_pieces(*a, **k):
                        h.update(p.points.tobytes() + p.equations.tobytes())
                seconds[name].append(time.process_time() - t)
                digest[name] = h.hexdigest()
        same = digest[args.base] == digest["this"]
        differ += not same
        print(f"{rid:>8} {len(calls)} merges, CPU s: " + "; ".join(f"{n} " + " ".join(f"{s:.2f}" for s in v) for n, v in seconds.items())
              + ("; same pieces" if same else "; DIFFERENT pieces"), flush=True)
    return 1 if differ else 0


if __name__ == "__main__":
    sys.exit(main())
