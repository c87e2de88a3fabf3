"""Requests as people write them, on the real dev rows: every line of ``benchmarks/people_requests.tsv``
(row id, request) refined once with the command people use, and the verdicts counted.

    python benchmarks/bench_people_requests.py [--dataset DIR] [--requests FILE] [--work DIR] [--jobs 2] [--ids 148,8877]

Each request runs ``asset2sim refine ROW -p REQUEST --out WORK/<n> --defer-media --quiet --json`` in its own process
(the user's cache as it is: warm after the first run of a row). Prints one line per request (row, verdict, the first
why-it-failed line) and the count of each verdict; writes WORK/results.jsonl. A not-ready verdict is not a failure of
the benchmark: whether a person agrees with it is read from its why-it-failed line.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from collections import Counter
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _refine(dataset: Path, work: Path, n: int, row: str, request: str) -> dict:
    out = work / f"{n:03d}_{row}"
    t0 = time.perf_counter()
    done = subprocess.run([sys.executable, "-m", "asset2sim", "refine", str(dataset / row), "-p", request, "--out", str(out),
                           "--defer-media", "--quiet", "--json", "--force"], capture_output=True, text=True, cwd=ROOT)
    rec = {"n": n, "row": row, "request": request, "exit": done.returncode, "seconds": round(time.perf_counter() - t0, 1)}
    try:
        reply = json.loads(done.stdout)
        rec.update(failure_mode=reply["failure_mode"], why=reply.get("why_it_failed", []))
    except (json.JSONDecodeError, KeyError):
        rec.update(failure_mode="error", why=[(done.stderr or done.stdout).strip().splitlines()[-1:]])
    return rec


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--dataset", type=Path, default=ROOT.parent / "shared" / "datasets" / "partnet_mobility")
    ap.add_argument("--requests", type=Path, default=ROOT / "benchmarks" / "people_requests.tsv")
    ap.add_argument("--work", type=Path, default=ROOT / "out" / "bench_people_requests")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--ids", default="", help="comma-separated rows (default: every row of the file)")
    args = ap.parse_args(argv)
    keep = set(filter(None, args.ids.split(",")))
    lines = [ln.split("\t") for ln in args.requests.read_text().splitlines() if ln.strip() and not ln.startswith("#")]
    todo = [(n, row, req) for n, (row, req) in enumerate(lines) if not keep or row in keep]
    args.work.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    with ThreadPoolExecutor(args.jobs) as pool:
        results = list(pool.map(lambda t: _refine(args.dataset, args.work, *t), todo))
    with (args.work / "results.jsonl").open("w") as f:
        for rec in results:
            f.write(json.dumps(rec) + "\n")
            why = rec["why"][0] if rec["why"] else ""
            print(f"{rec['row']:>7} {rec['failure_mode']:<22} {rec['seconds']:6.1f} s  {rec['request']}" + (f"\n{'':>31}{why[:200]}" if why else ""))
    counts = Counter(r["failure_mode"] for r in results)
    print(f"{len(results)} requests on {len({r['row'] for r in results})} rows in {time.perf_counter() - t0:.0f} s, {args.jobs} jobs: "
          + ", ".join(f"{k} {v}" for k, v in counts.most_common()))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
