"""Same input, same code, same bytes: refine every dev row twice into the same folder, the on-disk cache empty the
first time and warm the second, and compare every file byte for byte (the completion marker included; only
``timings.json``, the wall times, may differ). The second refine runs in a child process under another
``PYTHONHASHSEED``, so that a result that follows the iteration order of a set of names (which Python's string hashing
randomises per process) shows as a difference.

    .venv/bin/python benchmarks/bench_determinism.py [--manifest PATH] [--ids 103275,7236] [--work DIR] [--no-extras]
        [--keep DIR] [--against DIR]

Prints one line per row (identical, or the files that differ) and the count; exit status 1 when a row differs.
``--keep DIR`` copies each row's output to ``DIR/<id>``; ``--against DIR`` also compares each output with
``DIR/<id>`` kept by a run of another commit (a change that must not change outputs: run ``--keep`` on the commit
before it, ``--against`` on the commit after, both with the same ``--work``: ``evaluation.json`` and ``report.html``
record the output folder's path).
"""

from __future__ import annotations

import argparse
import csv
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DEV = ROOT.parent / "shared" / "datasets" / "partnet_mobility"
VOLATILE = {"timings.json"}
#: The second refine of a row, in a child process: argv = source folder, prompt, output folder, task ("" none), extras (1/0).
CHILD = ("import sys; from pathlib import Path; from asset2sim.schemas.config import RefineConfig; "
         "from asset2sim.tasks.refine import refine_asset; "
         "refine_asset(Path(sys.argv[1]), sys.argv[2], Path(sys.argv[3]), RefineConfig(), task=sys.argv[4] or None, "
         "skip_if_complete=False, extras=sys.argv[5] == '1')")


def snapshot(out: Path) -> dict[str, bytes]:
    """Relative path -> bytes of every file of ``out`` but the volatile ones."""
    return {p.relative_to(out).as_posix(): p.read_bytes() for p in sorted(out.rglob("*"))
            if p.is_file() and p.name not in VOLATILE}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--manifest", type=Path, default=DEV / "manifest.csv")
    ap.add_argument("--ids", default="", help="comma-separated subset of ids")
    ap.add_argument("--work", type=Path, default=None, help="work folder (default: a temporary one, removed)")
    ap.add_argument("--no-extras", action="store_true", help="without exports, renders, clips and report.html")
    ap.add_argument("--keep", type=Path, default=None, help="copy each row's output to DIR/<id>")
    ap.add_argument("--against", type=Path, default=None, help="compare each row's output with DIR/<id> too")
    args = ap.parse_args(argv)
    from asset2sim.schemas.config import RefineConfig
    from asset2sim.tasks.refine import refine_asset

    with open(args.manifest, newline="") as fh:
        rows = list(csv.DictReader(fh))
    wanted = {i.strip() for i in args.ids.split(",") if i.strip()}
    rows = [r for r in rows if not wanted or r["id"] in wanted]
    work = args.work or Path(tempfile.mkdtemp(prefix="a2s-determinism-"))
    os.environ["ASSET2SIM_CACHE"] = str(work / "cache")  # empty for the first refine of each row, warm for the second
    # the child's hash seed: another than this process's (random unless PYTHONHASHSEED is set)
    child_env = {**os.environ, "PYTHONHASHSEED": str((int(os.environ.get("PYTHONHASHSEED") or 0) + 1) % 4294967296)}
    differing = 0
    t0 = time.perf_counter()
    try:
        for r in rows:
            out = work / "out" / r["id"]
            refine_asset(args.manifest.parent / r["id"], r["prompt"], out, RefineConfig(), task=r.get("task") or None,
                         skip_if_complete=False, extras=not args.no_extras)
            a = snapshot(out)
            subprocess.run([sys.executable, "-c", CHILD, str(args.manifest.parent / r["id"]), r["prompt"], str(out),
                            r.get("task") or "", "0" if args.no_extras else "1"], check=True, env=child_env)
            b = snapshot(out)
            diff = sorted(k for k in set(a) | set(b) if a.get(k) != b.get(k))
            line = "identical" if not diff else f"{len(diff)} differ: {', '.join(diff[:6])}"
            if args.against is not None:
                ref = snapshot(args.against / r["id"]) if (args.against / r["id"]).is_dir() else {}
                other = sorted(k for k in set(a) | set(ref) if a.get(k) != ref.get(k))
                diff = diff + other
                line += "; against the kept output: " + ("identical" if not other else f"{len(other)} differ: {', '.join(other[:6])}")
            if args.keep is not None:
                shutil.rmtree(args.keep / r["id"], ignore_errors=True)
                shutil.copytree(out, args.keep / r["id"])
            differing += bool(diff)
            print(f"{r['id']:>8} {r['category']:<17} {len(a):4d} files: {line}", flush=True)
        print(f"{len(rows) - differing} of {len(rows)} rows byte-identical across two refines (cold, then warm cache in "
              f"a child process of hash seed {child_env['PYTHONHASHSEED']}) "
              f"in {time.perf_counter() - t0:.0f} s")
    finally:
        if args.work is None:
            shutil.rmtree(work, ignore_errors=True)
    return 1 if differing else 0


if __name__ == "__main__":
    sys.exit(main())
