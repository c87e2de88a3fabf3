"""What the flow's orchestration costs per task: empty Prefect tasks on the flow's own Dask task runner
(``flows.flow_runtime.dask_task_runner``: local cluster, one thread per worker process, the flow's Prefect API), then
the same empty function submitted to the same cluster as plain Dask tasks; printed per process (the driver with the
in-process Dask scheduler, the Prefect server, the Dask workers) as CPU seconds over the tasks, and as milliseconds of
CPU per task.

    .venv/bin/python benchmarks/bench_orchestration.py [--tasks 100] [--workers 2]

A dataset flow runs one ``refine-metrics`` task per asset and one ``prepare`` task per batch of assets
(``flows.subflow.prepare_batch_size``), so its orchestration costs about (1 + 1 / batch) times the Prefect
figure per asset. Measured on an idle machine; the numbers move with the host's load.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def empty(i: int) -> int:
    """The task: nothing (its cost is the orchestration's)."""
    return i


def _cpu_by_process() -> dict[int, tuple[str, float]]:
    """pid -> (role, user + system CPU seconds) of this process and every process below it."""
    import psutil

    me = psutil.Process()
    out = {}
    for p in [me, *me.children(recursive=True)]:
        try:
            cmd = " ".join(p.cmdline())
            t = p.cpu_times()
        except psutil.Error:
            continue
        role = ("driver" if p.pid == me.pid else "Prefect server" if "uvicorn" in cmd
                else "Dask worker" if "spawn_main" in cmd else "other")
        out[p.pid] = (role, t.user + t.system)
    return out


def _delta(before: dict, after: dict) -> dict[str, float]:
    """role -> CPU seconds spent between the two readings (processes present in both)."""
    out: dict[str, float] = {}
    for pid, (role, cpu) in after.items():
        if pid in before:
            out[role] = out.get(role, 0.0) + cpu - before[pid][1]
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--tasks", type=int, default=100, help="empty tasks per measurement")
    ap.add_argument("--workers", type=int, default=2, help="Dask worker processes")
    args = ap.parse_args(argv)

    sys.path.insert(0, str(ROOT))
    from asset2sim.cli import QUIET_LIBRARY_LOGS
    from asset2sim.flows import stages

    for k, v in QUIET_LIBRARY_LOGS.items():  # the libraries' logs off the terminal, as the commands keep them
        os.environ.setdefault(k, v)
    stages.prepare_prefect_environment(ROOT)  # before Prefect is imported, as the flow command does
    from asset2sim.flows.flow_runtime import dask_task_runner
    from prefect import flow, task
    from prefect.cache_policies import NO_CACHE
    from prefect_dask import get_dask_client

    empty_task = task(empty, name="empty", cache_policy=NO_CACHE, persist_result=False)
    n = int(args.tasks)
    load = os.getloadavg()
    results: dict[str, tuple[float, dict[str, float]]] = {}

    @flow(name="bench-orchestration", persist_result=False, task_runner=dask_task_runner(args.workers, None, dashboard=False))
    def measure() -> None:
        [f.result() for f in [empty_task.submit(i) for i in range(2 * args.workers)]]  # workers warm
        before, t0 = _cpu_by_process(), time.perf_counter()
        [f.result() for f in [empty_task.submit(i) for i in range(n)]]
        results["Prefect task"] = (time.perf_counter() - t0, _delta(before, _cpu_by_process()))
        with get_dask_client() as client:
            client.gather(client.map(empty, range(2 * args.workers), pure=False))
            before, t0 = _cpu_by_process(), time.perf_counter()
            client.gather(client.map(empty, range(n), pure=False))
            results["plain Dask task"] = (time.perf_counter() - t0, _delta(before, _cpu_by_process()))

    measure()
    print(f"{n} empty tasks on {args.workers} Dask worker processes (load average before: "
          f"{' '.join(f'{x:.1f}' for x in load)})")
    for kind, (wall, cpu) in results.items():
        total = sum(cpu.values())
        parts = ", ".join(f"{role} {s:.2f} s" for role, s in sorted(cpu.items(), key=lambda kv: -kv[1]))
        print(f"  {kind:15s} wall {wall:6.2f} s, CPU {total:6.2f} s = {1000 * total / n:5.1f} ms per task ({parts})")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
