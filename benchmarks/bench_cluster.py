"""The flow on a cluster that is not a local one, against the local flow: the guide's recipe for N machines
(``docs/guide/pipeline.md``, "On N machines", run as written by :mod:`cluster_run`) on 127.0.0.1 with a moto S3
server as the store, over the dev rows.

    .venv/bin/python benchmarks/bench_cluster.py [--requests 1] [--machines 2] [--work DIR]

1. Builds the dev rows' dataset as ``bench_flow.py`` does (``--requests`` requests per object; 21 assets by default).
2. Starts an S3-compatible server (``moto_server``) and, after the local run, the recipe: a Prefect server and a Dask scheduler as
   processes of their own, ``--machines`` ``dask worker`` processes of one single-threaded worker each.
3. Runs ``asset2sim flow`` on this machine alone (its own temporary Prefect server and Dask cluster, catalog and
   outputs in local folders) before the recipe starts, then the recipe's driver line (``--scheduler``, catalog and outputs in the store), each
   from an empty on-disk cache of its own, and prints each run's first phase (assets an hour, per-asset median) and
   the CPU of every process by role (``flow_cpu.FlowCpu``: the driver, the Prefect server, the scheduler, the
   nannies, the workers, the stage servers, the refine children; the S3 server apart, as the store's stand-in).
   Both runs refine with ``run.extras: false`` (the verdict's files; no exports or media: a deferred media phase makes
   a local run's media and leaves a store's outputs deferred, so the folders would differ by design).
4. Compares the two runs asset for asset (:func:`cluster_run.compare_runs`: every catalog column but the timings and
   the run's names, every output file's bytes but ``timings.json``) and prints what differs (nothing, when the
   cluster run matches); exits 1 when anything does.

Both runs share the machine's 2 cores with the servers; the load average is printed before each.
"""

from __future__ import annotations

import argparse
import os
import shutil
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))
DEV = ROOT.parent / "shared" / "datasets" / "partnet_mobility"

from bench_flow import build_dataset, quantiles  # noqa: E402
from bench_flow_synthetic import _load, flow_times  # noqa: E402
from flow_cpu import FlowCpu, print_report  # noqa: E402

import cluster_run  # noqa: E402

BUCKET = "a2s-bench"


def _timed(label: str, run, catalog: Path, work: Path) -> tuple[float, object]:
    """Run ``run()`` (a flow run to its end), sampling the CPU of every process; print its throughput and CPU by
    role; returns (wall s, its catalog rows)."""
    print(f"{label}: load before {_load()}", flush=True)
    t0 = time.perf_counter()
    with FlowCpu() as cpu:
        done = run()
    wall = time.perf_counter() - t0
    if done.returncode not in (0, 5):
        print(done.stdout[-4000:], done.stderr[-4000:])
        raise SystemExit(f"{label}: asset2sim flow exited with {done.returncode}")
    rows = cluster_run.run_rows(catalog)
    per = [v[0] for v in flow_times(rows).values()]
    med, _, p99 = quantiles(per)
    n = int((rows["status"] != "skipped").sum())
    print(f"  {n} assets in {wall:.1f} s wall (the command, start-up included: {n / wall * 3600:.0f} assets/hour); "
          f"per asset median {med:.2f} s, p99 {p99:.2f} s; failure modes "
          + ", ".join(f"{k} {v}" for k, v in rows["failure_mode"].fillna("none").value_counts().items()))
    print_report(cpu.report("start", "end"), "the whole command")
    return wall, rows


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--manifest", type=Path, default=DEV / "manifest.csv")
    ap.add_argument("--requests", type=int, default=1, help="requests per object, 1-5 (default 1: 21 assets)")
    ap.add_argument("--machines", type=int, default=2, help="dask worker processes (one single-threaded worker each)")
    ap.add_argument("--work", type=Path, default=None, help="work folder (default: a temporary one, removed)")
    args = ap.parse_args(argv)
    work = args.work or Path(tempfile.mkdtemp(prefix="a2s-bench-cluster-"))
    try:
        raw = work / "raw"
        rows = build_dataset(args.manifest, raw, max(1, min(5, args.requests)))
        os.environ.setdefault("PREFECT_HOME", str(work / ".prefect"))
        local, cluster = cluster_run.write_catalogs(work, raw, raw / "manifest.csv", BUCKET,
                                                    {"workers": args.machines, "evaluate": True, "time_limit_seconds": 900,
                                                     "extras": False})
        print(f"dataset: {len(rows)} assets; the recipe on 127.0.0.1 with {args.machines} worker machines of one core")
        with cluster_run.S3Server(work / "s3", BUCKET) as s3:
            os.environ.update(s3.environ())  # this process reads the cluster run's catalog and files from the store
            os.environ["ASSET2SIM_CACHE"] = str(work / "cache-local")  # each run from an empty on-disk cache
            _, a = _timed("local flow (its own Prefect server and Dask cluster, local folders)",
                          lambda: cluster_run.local_flow(local, args.machines, {k: v for k, v in os.environ.items()
                                                                                if k != "PREFECT_API_URL"}), local, work)
            os.environ["ASSET2SIM_CACHE"] = str(work / "cache-cluster")  # the recipe's workers start cold too
            t0 = time.perf_counter()
            with cluster_run.RecipeCluster(work / "cluster-logs", s3.store, machines=args.machines) as rc:
                print(f"recipe up in {time.perf_counter() - t0:.1f} s (scheduler {rc.scheduler}, logs in {work / 'cluster-logs'})")
                _, b = _timed("the recipe's flow (its Prefect server, scheduler, workers and store)",
                              lambda: rc.flow(cluster), cluster, work)
                problems = cluster_run.compare_runs(a, b)
        print(f"asset for asset ({len(a)} local, {len(b)} on the cluster): "
              + ("the same catalog columns and output bytes, timings aside" if not problems else f"{len(problems)} differences"))
        for p in problems[:40]:
            print(f"  {p}")
        return 1 if problems else 0
    finally:
        if args.work is None:
            shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    sys.exit(main())
