"""The merge of a link's collision pieces, its hold test measured lazily (as shipped) against every pair measured as
it enters the queue (the former order, the reference in ``tests/tasks/assemble/test_collision_geometry.py``).

    .venv/bin/python benchmarks/bench_merge.py [--ids 9912,9748,7119,100221,102990] [--work DIR]

Refines each dev row (its own request, ``--no-extras``) with an empty on-disk cache, once per way, each way in a
fresh process (the in-process caches empty too; one BLAS and one OpenMP thread, as the flow's workers run CoACD and
numpy; door 8877 refined first, uncounted, so the imports a first refine pays fall on neither side), and prints per row the refine's CPU seconds and its piece-building
stages' wall seconds (``write``, ``limits``, ``refine_state``, ``shut_repair``) for both ways, and whether the two
output folders are byte-identical (``timings.json`` aside). Exit status 1 when an output differs.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

for _var in ("OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "OMP_NUM_THREADS"):  # as the flow's workers, before numpy
    os.environ.setdefault(_var, "1")

ROOT = Path(__file__).resolve().parents[1]
DEV = ROOT.parent / "shared" / "datasets" / "partnet_mobility"
STAGES = ("write", "limits", "refine_state", "shut_repair")


def refine_each(mode: str, ids: list[str], work: Path) -> None:
    """In this process: refine every row of ``ids`` into ``work/<mode>_<id>`` (cache ``work/cache_<mode>_<id>``),
    with the merge as shipped (``lazy``) or measuring every pair on entry (``eager``); prints one JSON line per row."""
    sys.path.insert(0, str(ROOT))
    if mode == "eager":
        import numpy as np

        from asset2sim.tasks.assemble import collision_geometry, containment_cuts, convex_pieces
        from tests.tasks.assemble.test_collision_geometry import _merge_measuring_every_pair

        def eager(pieces, limit, others=None, neighbours=8, *, free_only=False):
            if len(pieces) <= limit:
                return list(pieces)
            rest = _merge_measuring_every_pair(pieces, limit, np.zeros((0, 3)) if others is None else np.asarray(others, float),
                                               free_only, neighbours)
            while len(rest) > limit and not free_only:  # merge_pieces' last resort, by order
                a, b = rest.pop(), rest.pop()
                rest.append(convex_pieces.Piece.of(np.vstack([a.points, b.points]), a.sources + b.sources))
            return rest

        containment_cuts.merge_pieces = collision_geometry.merge_pieces = eager
    from asset2sim.cli import main

    for i in ("8877", *ids):
        os.environ["ASSET2SIM_CACHE"] = str(work / f"cache_{mode}_{i}")
        shutil.rmtree(os.environ["ASSET2SIM_CACHE"], ignore_errors=True)
        out = work / f"{mode}_{i}"
        c0 = time.process_time()
        try:
            main(["refine", str(DEV / i), "--out", str(out), "--overwrite", "--quiet", "--no-extras"])
        except SystemExit:
            pass
        stages = json.loads((out / "timings.json").read_text())["stage_seconds"]
        if i == "8877" and "8877" not in ids:
            continue  # the warm-up
        print(json.dumps({"id": i, "cpu": time.process_time() - c0, **{s: stages.get(s, 0.0) for s in STAGES}}), flush=True)


def same_bytes(a: Path, b: Path) -> bool:
    """Whether the folders ``a`` and ``b`` hold the same files with the same bytes (``timings.json`` aside)."""
    def files(root: Path) -> dict[str, bytes]:
        return {p.relative_to(root).as_posix(): p.read_bytes() for p in sorted(root.rglob("*"))
                if p.is_file() and p.name != "timings.json"}
    return files(a) == files(b)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--ids", default="9912,9748,7119,100221,102990", help="comma-separated dev rows")
    ap.add_argument("--work", type=Path, default=None, help="folder for outputs and caches (default: a temporary one)")
    ap.add_argument("--mode", choices=("lazy", "eager"), help=argparse.SUPPRESS)  # one way, in this process
    args = ap.parse_args(argv)
    ids = [i for i in args.ids.split(",") if i]
    work = args.work or Path(tempfile.mkdtemp(prefix="bench_merge_"))
    work.mkdir(parents=True, exist_ok=True)
    if args.mode:
        refine_each(args.mode, ids, work)
        return 0
    rows: dict[str, dict[str, dict]] = {}
    for mode in ("eager", "lazy"):
        run = subprocess.run([sys.executable, __file__, "--mode", mode, "--ids", ",".join(ids), "--work", str(work)],
                             capture_output=True, text=True, check=True)
        for line in run.stdout.splitlines():
            if line.startswith("{"):
                r = json.loads(line)
                rows.setdefault(r["id"], {})[mode] = r
    print(f"{'row':>8}  {'CPU s, every pair / lazy':>26}  " + "  ".join(f"{s:>18}" for s in STAGES) + "  outputs")
    differ = 0
    for i in ids:
        e, z = rows[i]["eager"], rows[i]["lazy"]
        same = same_bytes(work / f"eager_{i}", work / f"lazy_{i}")
        differ += not same
        print(f"{i:>8}  {e['cpu']:11.2f} / {z['cpu']:<11.2f}   " + "  ".join(f"{e[s]:8.2f} / {z[s]:<7.2f}" for s in STAGES)
              + f"  {'identical' if same else 'DIFFER'}")
    tot_e, tot_z = (sum(rows[i][m]["cpu"] for i in ids) for m in ("eager", "lazy"))
    print(f"all rows: {tot_e:.2f} / {tot_z:.2f} CPU s ({100 * (1 - tot_z / tot_e):.0f} % less); "
          f"{len(ids) - differ} of {len(ids)} outputs byte-identical")
    return 1 if differ else 0


if __name__ == "__main__":
    sys.exit(main())
