"""The command line's start-up as a user meets it: ``asset2sim --help`` (every command's parser built, every module
the commands import loaded) in fresh processes, wall and CPU seconds, and the modules whose import costs most.

    .venv/bin/python benchmarks/bench_startup.py [--runs 5] [--top 8]

Prints the median and least wall and CPU seconds of ``--runs`` fresh processes, then the ``--top`` imports by their
cumulative time in one more (``python -X importtime``).
"""

from __future__ import annotations

import argparse
import resource
import statistics
import subprocess
import sys
import time


def one_run(argv: list[str]) -> tuple[float, float]:
    """(wall s, CPU s of the child) of one run of ``argv``."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t = time.perf_counter()
    subprocess.run(argv, check=True, capture_output=True)
    wall = time.perf_counter() - t
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return wall, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def top_imports(argv: list[str], n: int) -> list[tuple[float, str]]:
    """The ``n`` imports (cumulative s, module) that cost most in one run of ``argv`` under ``-X importtime``."""
    proc = subprocess.run([argv[0], "-X", "importtime", *argv[1:]], check=True, capture_output=True, text=True)
    rows = []
    for line in proc.stderr.splitlines():
        parts = line.removeprefix("import time:").split("|")
        if len(parts) == 3 and parts[1].strip().isdigit():
            rows.append((int(parts[1]) / 1e6, parts[2].rstrip()))
    return sorted(rows, reverse=True)[:n]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--runs", type=int, default=5, help="fresh processes timed (default 5)")
    ap.add_argument("--top", type=int, default=8, help="costliest imports listed (default 8)")
    args = ap.parse_args(argv)
    cmd = [sys.executable, "-m", "asset2sim", "--help"]
    runs = [one_run(cmd) for _ in range(args.runs)]
    walls, cpus = [r[0] for r in runs], [r[1] for r in runs]
    print(f"asset2sim --help, {args.runs} fresh processes: wall median {statistics.median(walls):.2f} s "
          f"(least {min(walls):.2f}), CPU median {statistics.median(cpus):.2f} s (least {min(cpus):.2f})")
    print("costliest imports (cumulative s, one run under -X importtime):")
    for seconds, module in top_imports(cmd, args.top):
        print(f"  {seconds:6.3f}  {module}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
