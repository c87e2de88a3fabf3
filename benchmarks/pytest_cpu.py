"""CPU seconds of a test run, per test and per test module's collection, from every process of the run (pytest-xdist's
workers included): what the test tiers cost, free of the wall-clock noise of a shared machine.

    PYTEST_CPU_DIR=/tmp/cpu PYTHONPATH=benchmarks .venv/bin/python -m pytest -p pytest_cpu -m "not slow" -q -n 2 --dist loadfile
    .venv/bin/python benchmarks/pytest_cpu.py /tmp/cpu [--top 30]

As a pytest plugin (``-p pytest_cpu``, ``benchmarks/`` on ``PYTHONPATH``; ``PYTEST_ADDOPTS="-p pytest_cpu"`` for
``make test``) each process writes ``PYTEST_CPU_DIR/<worker>.tsv``: a test's CPU (``getrusage``: the process and the
children it waited for) over its setup, call and teardown, each module's collection (its imports), and the process's
``os.fsync`` calls with their wall seconds (waits on the disk that the CPU figures leave out). Run as a script
it prints the sums per process and the ``--top`` tests and modules.
"""

from __future__ import annotations

import argparse
import os
import resource
import time
from pathlib import Path

import pytest

_ROWS: list[tuple[str, float, float, str]] = []  # (kind: test | collect, cpu s, wall s, node id)


_FSYNC = [0, 0.0]  # os.fsync calls of this process and their wall seconds (waits on the disk, not CPU)
_os_fsync = os.fsync


def _timed_fsync(fd):
    t0 = time.perf_counter()
    try:
        return _os_fsync(fd)
    finally:
        _FSYNC[0] += 1
        _FSYNC[1] += time.perf_counter() - t0


os.fsync = _timed_fsync


def _cpu() -> float:
    own, children = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + children.ru_utime + children.ru_stime


@pytest.hookimpl(hookwrapper=True)
def pytest_make_collect_report(collector):
    if not isinstance(collector, pytest.Module):
        yield
        return
    c0, t0 = _cpu(), time.perf_counter()
    yield
    _ROWS.append(("collect", _cpu() - c0, time.perf_counter() - t0, collector.nodeid))


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_protocol(item, nextitem):
    c0, t0 = _cpu(), time.perf_counter()
    yield
    _ROWS.append(("test", _cpu() - c0, time.perf_counter() - t0, item.nodeid))


def pytest_unconfigure(config):
    folder = os.environ.get("PYTEST_CPU_DIR")
    if not folder or not _ROWS:
        return
    Path(folder).mkdir(parents=True, exist_ok=True)
    name = os.environ.get("PYTEST_XDIST_WORKER", f"main-{os.getpid()}")
    rows = [*_ROWS, ("fsync", _FSYNC[0], _FSYNC[1], "os.fsync calls (cpu column: count)")]
    Path(folder, f"{name}.tsv").write_text("".join(f"{k}\t{c:.3f}\t{w:.3f}\t{n}\n" for k, c, w, n in rows))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("folder", type=Path)
    ap.add_argument("--top", type=int, default=30)
    args = ap.parse_args()
    rows = []
    for path in sorted(args.folder.glob("*.tsv")):
        kinds: dict[str, list[float]] = {"test": [0.0, 0.0, 0], "collect": [0.0, 0.0, 0], "fsync": [0.0, 0.0, 0]}
        for line in path.read_text().splitlines():
            kind, cpu, wall, node = line.split("\t")
            kinds[kind][0] += float(cpu)
            kinds[kind][1] += float(wall)
            kinds[kind][2] += 1
            rows.append((float(cpu), float(wall), kind, node))
        for kind, (cpu, wall, n) in kinds.items():
            if kind == "fsync":
                print(f"{path.stem:10s} fsync    {int(cpu):5d} calls  wall {wall:8.1f} s")
            else:
                print(f"{path.stem:10s} {kind:8s} {n:5d} items  cpu {cpu:8.1f} s  wall {wall:8.1f} s")
    print(f"{'all':10s} test     cpu {sum(r[0] for r in rows if r[2] == 'test'):8.1f} s")
    print(f"{'all':10s} collect  cpu {sum(r[0] for r in rows if r[2] == 'collect'):8.1f} s")
    print(f"{'all':10s} fsync    {int(sum(r[0] for r in rows if r[2] == 'fsync')):5d} calls  wall {sum(r[1] for r in rows if r[2] == 'fsync'):8.1f} s")
    for kind in ("test", "collect"):
        print(f"\nthe {args.top} costliest ({kind}), cpu s, wall s:")
        for cpu, wall, _, node in sorted((r for r in rows if r[2] == kind), reverse=True)[:args.top]:
            print(f"{cpu:7.2f} {wall:7.2f}  {node}")


if __name__ == "__main__":
    main()
