"""The start-up of the temporary Prefect server a flow run starts when no ``PREFECT_API_URL`` is set
(:func:`asset2sim.flows.server.start_local_server`, the API alone, as one run uses it): on a new project folder,
whose database Prefect creates and migrates, then again on the same folder, migrated.

    .venv/bin/python benchmarks/bench_prefect_server.py [--work DIR] [--repeats 2]

Prints, per start, the wall seconds until the API answers and the CPU seconds of the server's processes by then;
the first start of each repeat is on a fresh ``DIR/project<k>`` (a new ``.prefect`` folder), the second on the
same folder. Goals: none; it sizes the part of a flow's start-up a project's first run pays
(``docs/design/pipeline.md``, "What the orchestration costs").
"""

from __future__ import annotations

import argparse
import shutil
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def start_once(project: Path) -> tuple[float, float]:
    """Start the server for ``project`` and stop it once its API answers; returns (wall s, CPU s of its processes)."""
    import psutil

    from asset2sim.flows import server

    t0 = time.perf_counter()
    proc, _url = server.start_local_server(project, ephemeral=True)
    wall = time.perf_counter() - t0
    cpu = 0.0
    try:
        root = psutil.Process(proc.pid)
        for p in [root, *root.children(recursive=True)]:
            try:
                t = p.cpu_times()
                cpu += t.user + t.system
            except psutil.Error:
                continue
    finally:
        server.stop_server(proc)
    return wall, cpu


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--work", type=Path, default=None, help="folder for the projects (default: a temporary one)")
    ap.add_argument("--repeats", type=int, default=2, help="fresh projects to start (each started twice)")
    args = ap.parse_args(argv)
    work = args.work or Path(tempfile.mkdtemp(prefix="bench_prefect_server_"))
    work.mkdir(parents=True, exist_ok=True)
    for k in range(args.repeats):
        project = work / f"project{k}"
        shutil.rmtree(project, ignore_errors=True)
        project.mkdir()
        for label in ("new project (database created and migrated)", "the same project again (migrated)"):
            wall, cpu = start_once(project)
            print(f"{label:48s} ready after {wall:5.1f} s wall, {cpu:5.1f} s of the server's CPU")
    return 0


if __name__ == "__main__":
    sys.exit(main())
