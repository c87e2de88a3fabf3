"""How often a refine writes its candidate into the workspace: per dev row, the times a stage asked the workspace
for a candidate (``Workspace.load``, under ``Workspace.model`` and ``Workspace.session`` too), the writes that
followed (a candidate not on disk already), the seconds of those writes and the refine's wall time.

    .venv/bin/python benchmarks/bench_workspace_writes.py [--ids 7236 9912 ...] [--out DIR]

Refines each row of ``../shared/datasets/partnet_mobility/manifest.csv`` (its own request, no extras) in this
process, one BLAS thread, with an on-disk cache of its own under ``--out`` (empty at the start). Prints one line per
row and the totals.
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # as the flow's workers (asset2sim.cli), before numpy

import argparse  # noqa: E402
import csv  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
DEV = ROOT.parent / "shared" / "datasets" / "partnet_mobility"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--ids", nargs="*", default=None, help="dev row ids (default: every row)")
    ap.add_argument("--out", type=Path, default=None, help="work folder (default: a temporary one)")
    args = ap.parse_args(argv)
    out = args.out or Path(tempfile.mkdtemp(prefix="a2s-bench-writes-"))
    os.environ.setdefault("ASSET2SIM_CACHE", str(out / "cache"))

    from asset2sim.tasks.assemble.candidate import Candidate, Workspace
    from asset2sim.tasks.refine import refine_asset

    counts = {"asks": 0, "writes": 0, "write_s": 0.0}
    real_load, real_write = Workspace.load, Candidate.write_into

    def load(self, candidate):
        counts["asks"] += 1
        return real_load(self, candidate)

    def write_into(self, folder, **kw):
        t = time.perf_counter()
        try:
            return real_write(self, folder, **kw)
        finally:
            if "asset2sim-candidates-" in str(folder):  # the workspace's, not publish's
                counts["writes"] += 1
                counts["write_s"] += time.perf_counter() - t

    Workspace.load, Candidate.write_into = load, write_into
    with open(DEV / "manifest.csv", newline="") as fh:
        rows = [r for r in csv.DictReader(fh) if args.ids is None or r["id"] in args.ids]
    total = {"asks": 0, "writes": 0, "write_s": 0.0, "refine_s": 0.0}
    print(f"{'row':>8} {'category':<18} {'asks':>5} {'writes':>6} {'write s':>8} {'refine s':>9}")
    for r in rows:
        counts.update(asks=0, writes=0, write_s=0.0)
        t = time.perf_counter()
        refine_asset(DEV / r["id"], r["prompt"], out / r["id"], category=r["category"], extras=False, media=False,
                     skip_if_complete=False, overwrite=True)
        dt = time.perf_counter() - t
        print(f"{r['id']:>8} {r['category']:<18} {counts['asks']:>5} {counts['writes']:>6} {counts['write_s']:>8.2f} {dt:>9.1f}",
              flush=True)
        for k in ("asks", "writes", "write_s"):
            total[k] += counts[k]
        total["refine_s"] += dt
    print(f"{'all':>8} {len(rows):<18} {total['asks']:>5} {total['writes']:>6} {total['write_s']:>8.2f} {total['refine_s']:>9.1f}")
    print(f"writes per refine {total['writes'] / max(len(rows), 1):.2f}; writes take {total['write_s'] / max(total['refine_s'], 1e-9):.0%} "
          f"of refine time")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
