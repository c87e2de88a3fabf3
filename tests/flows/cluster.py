"""A real Dask cluster for flow tests and by-hand runs: ``dask scheduler`` and
``dask worker`` started as separate processes on 127.0.0.1, and the check
that a flow run with one worker killed (SIGKILL) mid-run, followed by a
rerun, leaves every asset done exactly once or failed with its reason.

By hand (the 21 dev objects, the real pipeline)::

    .venv/bin/python tests/flows/cluster.py --catalog catalog.yaml --dataset partnet_dev

starts a Prefect server, a scheduler and 2 workers, runs ``asset2sim flow
--scheduler ...``, kills one worker when the first asset is recorded, reruns,
and prints the per-asset tally.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

import psutil

from asset2sim.flows.catalog import ResultCatalog
from asset2sim.flows.catalog_config import load_catalog
from asset2sim.output_folder import MARKER_NAME

DASK = str(Path(sys.executable).with_name("dask"))


@dataclass
class Cluster:
    """A scheduler and its workers (each its own process group)."""

    address: str
    scheduler: subprocess.Popen
    workers: list[subprocess.Popen] = field(default_factory=list)

    def worker_processes(self) -> list[psutil.Process]:
        """The processes that run tasks: the child of each ``dask worker`` nanny."""
        out = []
        for w in self.workers:
            try:
                out.extend(c for c in psutil.Process(w.pid).children() if "python" in c.name().lower())
            except psutil.Error:
                pass
        return out

    def close(self) -> None:
        for p in [*self.workers, self.scheduler]:
            try:
                os.killpg(p.pid, signal.SIGKILL)
            except (ProcessLookupError, PermissionError):
                pass
            try:
                p.wait(timeout=30)
            except subprocess.TimeoutExpired:
                pass


def start_cluster(workdir: Path, n_workers: int = 2, env: dict[str, str] | None = None, timeout: float = 180.0) -> Cluster:
    """``dask scheduler`` on 127.0.0.1 (a free port) and ``n_workers``
    single-threaded ``dask worker`` processes (each with its nanny, which
    restarts a crashed worker), all with ``env``. Waits until every worker
    has joined.

    Raises:
        RuntimeError: the scheduler or the workers did not come up in ``timeout`` s
            (their logs are in ``workdir``).
    """
    from distributed import Client

    workdir.mkdir(parents=True, exist_ok=True)
    env = {**os.environ, **(env or {})}
    sched_file = workdir / "scheduler.json"
    log = open(workdir / "scheduler.log", "wb")
    sched = subprocess.Popen([DASK, "scheduler", "--host", "127.0.0.1", "--port", "0", "--dashboard-address", "127.0.0.1:0",
                              "--scheduler-file", str(sched_file)], env=env, stdout=log, stderr=subprocess.STDOUT,
                             start_new_session=True)
    deadline = time.time() + timeout
    while not sched_file.is_file() and time.time() < deadline and sched.poll() is None:
        time.sleep(0.2)
    if not sched_file.is_file():
        sched.kill()
        raise RuntimeError(f"dask scheduler did not start (log {workdir / 'scheduler.log'})")
    import json

    time.sleep(0.2)
    address = json.loads(sched_file.read_text())["address"]
    cluster = Cluster(address=address, scheduler=sched)
    for i in range(n_workers):
        wlog = open(workdir / f"worker{i}.log", "wb")
        cluster.workers.append(subprocess.Popen(
            [DASK, "worker", address, "--host", "127.0.0.1", "--nthreads", "1", "--nworkers", "1",
             "--no-dashboard", "--name", f"w{i}", "--local-directory", str(workdir / f"w{i}")],
            env=env, stdout=wlog, stderr=subprocess.STDOUT, start_new_session=True))
    with Client(address, timeout=timeout) as client:
        try:
            client.wait_for_workers(n_workers, timeout=max(1.0, deadline - time.time()))
        except Exception as exc:
            cluster.close()
            raise RuntimeError(f"{n_workers} dask workers did not join {address}: {exc}") from exc
    return cluster


def kill_one_worker_when(cluster: Cluster, ready, timeout: float = 600.0) -> psutil.Process | None:
    """SIGKILL the task process of one worker (its nanny restarts it) as soon
    as ``ready()`` is true; returns the killed process (None when the deadline passed)."""
    deadline = time.time() + timeout
    while time.time() < deadline:
        if ready():
            victims = cluster.worker_processes()
            if victims:
                victims[0].send_signal(signal.SIGKILL)
                return victims[0]
        time.sleep(0.05)
    return None


@dataclass
class Tally:
    """Per asset: catalog rows with status done / failed / skipped over all
    runs, complete output folders over all runs, and the failure reasons."""

    done: Counter
    failed: Counter
    skipped: Counter
    folders: Counter
    reasons: dict[str, list[str]]
    rows_per_run: dict[str, Counter]


def tally(catalog: Path, dataset: str) -> Tally:
    """The catalog and output folders of ``dataset`` counted per asset."""
    cat = load_catalog(catalog)
    df = ResultCatalog(cat.catalog_root).read(dataset)
    t = Tally(Counter(), Counter(), Counter(), Counter(), {}, {})
    for r in df.to_dict("records"):
        getattr(t, r["status"])[r["asset_id"]] += 1
        t.rows_per_run.setdefault(r["run"], Counter())[r["asset_id"]] += 1
        if r["status"] == "failed":
            t.reasons.setdefault(r["asset_id"], []).append(f"{r.get('failure_mode')}: {r.get('error')}")
    base = cat.output_root / dataset
    for marker in base.glob(f"*/*/{MARKER_NAME}"):
        t.folders[marker.parent.name] += 1
    return t


def check_exactly_once(t: Tally, ids: list[str]) -> list[str]:
    """The problems (empty: none): every run holds at most one row per asset;
    every asset is done exactly once over all runs with exactly one complete
    folder, or failed in every run with a reason."""
    problems = []
    for run, counts in t.rows_per_run.items():
        dup = [a for a, n in counts.items() if n > 1]
        if dup:
            problems.append(f"run {run}: duplicate rows for {dup}")
    for a in ids:
        if t.done[a] == 1 and t.folders[a] == 1:
            continue
        if t.done[a] == 0 and t.failed[a] >= 1 and all(t.reasons.get(a, [])):
            continue
        problems.append(f"{a}: done {t.done[a]} times, {t.folders[a]} complete folders, failed {t.failed[a]}, "
                        f"skipped {t.skipped[a]}")
    return problems


def _main() -> int:
    import argparse
    import tempfile

    from asset2sim.flows import server

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--catalog", type=Path, default=Path("catalog.yaml"))
    ap.add_argument("--dataset", default="partnet_dev")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--no-force", action="store_true", help="first run without --force")
    args = ap.parse_args()
    cat = load_catalog(args.catalog)
    work = Path(tempfile.mkdtemp(prefix="a2s-cluster-"))
    proc, url = server.start_local_server(cat.project_root, timeout=300, ephemeral=True)
    env = {"PREFECT_API_URL": url, "MPLBACKEND": "Agg"}
    t0 = time.perf_counter()
    cluster = start_cluster(work, args.workers, env=env)
    print(f"cluster {cluster.address} up in {time.perf_counter() - t0:.1f} s (logs in {work})", flush=True)
    before = set(ResultCatalog(cat.catalog_root).read(args.dataset)["run"]) if ResultCatalog(cat.catalog_root).runs(args.dataset) else set()
    cmd = [sys.executable, "-m", "asset2sim", "flow", "--catalog", str(args.catalog), "--dataset", args.dataset,
           "--scheduler", cluster.address, "--no-progress"]
    try:
        t0 = time.perf_counter()
        flow = subprocess.Popen(cmd + ([] if args.no_force else ["--force"]), env={**os.environ, **env})
        rows_dir = Path(str(cat.catalog_root)) / f"dataset={args.dataset}"

        def some_row_recorded() -> bool:
            return any(p for p in rows_dir.glob("run=*/*.parquet") if p.parent.name[4:] not in before and not p.name.startswith("_"))

        killed = kill_one_worker_when(cluster, some_row_recorded)
        print(f"killed worker process {killed.pid if killed else None} at {time.perf_counter() - t0:.1f} s", flush=True)
        rc1 = flow.wait()
        print(f"first run: exit {rc1} after {time.perf_counter() - t0:.1f} s", flush=True)
        t0 = time.perf_counter()
        rc2 = subprocess.call(cmd, env={**os.environ, **env})
        print(f"rerun: exit {rc2} after {time.perf_counter() - t0:.1f} s", flush=True)
    finally:
        cluster.close()
        server.stop_server(proc)
    from asset2sim.flows.catalog_config import read_manifest_entries

    ids = [e.asset_id for e in read_manifest_entries(cat.manifest_path(args.dataset), cat.dataset_root(args.dataset))[0]]
    t = tally(args.catalog, args.dataset)
    new_runs = sorted(set(t.rows_per_run) - before)
    sub = Tally(Counter(), Counter(), Counter(), Counter(), {}, {r: t.rows_per_run[r] for r in new_runs})
    df = ResultCatalog(cat.catalog_root).read(args.dataset)
    for r in df[df["run"].isin(new_runs)].to_dict("records"):
        getattr(sub, r["status"])[r["asset_id"]] += 1
        if r["status"] == "failed":
            sub.reasons.setdefault(r["asset_id"], []).append(f"{r.get('failure_mode')}: {r.get('error')}")
    for run in new_runs:
        for marker in (cat.output_root / args.dataset / run).glob(f"*/{MARKER_NAME}"):
            sub.folders[marker.parent.name] += 1
    for run in new_runs:
        print(f"run {run}: {sum(sub.rows_per_run[run].values())} rows")
    print(f"{len(ids)} assets: done once {sum(1 for a in ids if sub.done[a] == 1)}, "
          f"failed {sum(1 for a in ids if sub.done[a] == 0)}")
    for a, rs in sub.reasons.items():
        print(f"  failed {a}: {rs}")
    problems = check_exactly_once(sub, ids)
    print("\n".join(problems) or "every asset done exactly once or failed with its reason")
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(_main())
