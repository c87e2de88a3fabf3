"""Throughput of the dataset flow on N generated articulated assets.

    .venv/bin/python benchmarks/bench_flow_synthetic.py            # N = 200, 2 workers
    .venv/bin/python benchmarks/bench_flow_synthetic.py --n 10 --sample 3
    .venv/bin/python benchmarks/bench_flow_synthetic.py --manifest ../shared/datasets/partnet_mobility/manifest.csv

With ``--manifest`` the flow runs over that dataset's rows (real objects, their
requests and tasks) instead of generated cabinets; step 1 is skipped.

1. Generates N PartNet-Mobility-style asset folders (``mobility.urdf``,
   ``textured_objs/*.obj``, ``semantics.txt``, ``meta.json``) and a
   ``manifest.csv``: storage cabinets of varied width, height and depth
   (0.6-1.4 x 0.35-1.9 x 0.5-0.9 object units) with 1 to 6 sliding drawers
   (joint count 1-6, 7-37 mesh files), built from boxes with the demo
   generator's serialiser (:mod:`asset2sim.demo_assets`, :mod:`asset2sim.demo_geometry`);
   deterministic for a seed.
2. Runs the flow (``run_refine_flow``, what ``make flow`` runs: Prefect,
   a local Dask cluster of ``--workers`` single-threaded workers, per-asset
   isolation in a child forked from each worker's pre-imported stage
   server) over them with extras (MJCF export, renders, HTML report) and the
   metrics stage, and prints assets per hour, start-up (Prefect, Dask),
   the per-asset worker time, and the CPU of every kind of process the
   flow starts (stage servers and children, Dask workers, Prefect's
   server) beside what other processes took from the same cores.
3. In the same run, side by side: for a sample of the assets (``--sample``,
   spread over sizes), the same stages in this process (prepare: read and
   hash; refine with extras; metrics), timed per asset, against the flow's
   per-asset worker time of the same assets: the overhead ratio. The flow
   and the in-process side each start from an empty on-disk cache of their
   own (``ASSET2SIM_CACHE`` under the work folder; ``--keep-cache`` uses the
   environment's): the caches are keyed by content and the assets are the
   same for a seed, so a shared cache would time one side warm.
4. Reruns the flow: every asset skipped; prints its wall time.
5. Prints the isolation's cost: the stage server's start-up (once per
   worker) and a call through it (fork + pipe messages) against a direct call.

Goals: >= 2,000 assets/hour with extras, overhead <= 1.3x,
rerun of 200 skipped assets <= 10 s. The machine's load (other processes on
the same cores) is printed with the results; numbers from a loaded machine
are upper bounds of the cost.
"""

from __future__ import annotations

import argparse
import csv
import io
import json
import os
import random
import resource
import shutil
import statistics
import sys
import tempfile
import time
from pathlib import Path

# The in-process side runs as `asset2sim refine` does (asset2sim.cli): one BLAS
# thread unless set, freed memory kept for reuse (asset2sim.allocator).
for _var in ("OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

from asset2sim import allocator  # noqa: E402
from asset2sim.demo_assets import _serialise, _write_folder  # noqa: E402
from asset2sim.demo_geometry import DemoArticulation, DemoJoint, DemoLink, Part, box_xyz  # noqa: E402

_BASE_RPY = "1.570796326794897 0 -1.570796326794897"  # PartNet-Mobility's y-up body under a z-up base
_WOOD, _METAL = (0.62, 0.45, 0.3), (0.75, 0.76, 0.78)


# ------------------------------------------------------------------------ generator


def cabinet(asset_id: str, width: float, height: float, depth: float, drawers: int) -> DemoArticulation:
    """A storage cabinet of ``width`` x ``height`` x ``depth`` object units
    (x across, y up, z front) with ``drawers`` sliding drawers stacked in an
    open-front carcass of 0.03 boards; every drawer closed at 0 with 0.005
    clearance in front of the carcass and at least 0.01 to every board,
    sliding +z up to 0.75 of the depth."""
    t, c = 0.03, 0.01
    x0, x1, y0, y1, z0, z1 = -width / 2, width / 2, -height / 2, height / 2, -depth / 2, depth / 2
    body = [
        Part("board-1", [box_xyz(x0, x0 + t, y0, y1, z0, z1)], _WOOD),
        Part("board-2", [box_xyz(x1 - t, x1, y0, y1, z0, z1)], _WOOD),
        Part("board-3", [box_xyz(x0 + t, x1 - t, y1 - t, y1, z0, z1)], _WOOD),
        Part("board-4", [box_xyz(x0 + t, x1 - t, y0, y0 + t, z0, z1)], _WOOD),
        Part("board-5", [box_xyz(x0 + t, x1 - t, y0 + t, y1 - t, z0, z0 + t)], _WOOD),
    ]
    slot = (height - 2 * t - (drawers - 1) * t) / drawers
    links, joints, n = [], [], 10
    for i in range(drawers):
        s0 = y0 + t + i * (slot + t)
        s1 = s0 + slot
        if i > 0:
            body.append(Part(f"shelf-{6 + i}", [box_xyz(x0 + t, x1 - t, s0 - t, s0, z0 + t, z1)], _WOOD))
        fy0, fy1 = s0 - t / 2 + 0.005, s1 + t / 2 - 0.005
        bx0, bx1, by0, by1, bz0 = x0 + t + c, x1 - t - c, s0 + c, s1 - c, z0 + t + c
        ym = 0.5 * (s0 + s1)
        hw = min(0.165, 0.3 * width)
        parts = [
            Part(f"drawer_front-{n}", [box_xyz(x0 + 0.005, x1 - 0.005, fy0, fy1, z1 + 0.005, z1 + 0.035)], _WOOD),
            Part(f"drawer_bottom-{n + 1}", [box_xyz(bx0, bx1, by0, by0 + 0.02, bz0, z1 + 0.005)], _WOOD),
            Part(f"drawer_side-{n + 2}", [box_xyz(bx0, bx0 + 0.02, by0 + 0.02, by1, bz0, z1 + 0.005)], _WOOD),
            Part(f"drawer_side-{n + 3}", [box_xyz(bx1 - 0.02, bx1, by0 + 0.02, by1, bz0, z1 + 0.005)], _WOOD),
            Part(f"drawer_back-{n + 4}", [box_xyz(bx0 + 0.02, bx1 - 0.02, by0 + 0.02, by1, bz0, bz0 + 0.02)], _WOOD),
            Part(f"handle-{n + 5}", [
                box_xyz(-hw, -hw + 0.03, ym - 0.015, ym + 0.015, z1 + 0.035, z1 + 0.075),
                box_xyz(hw - 0.03, hw, ym - 0.015, ym + 0.015, z1 + 0.035, z1 + 0.075),
                box_xyz(-hw - 0.005, hw + 0.005, ym - 0.015, ym + 0.015, z1 + 0.07, z1 + 0.095),
            ], _METAL),
        ]
        n += 10
        links.append(DemoLink(f"link_{i}", "slider", "drawer", parts))
        joints.append(DemoJoint(f"joint_{i}", "prismatic", f"link_{drawers}", f"link_{i}", axis=(0.0, 0.0, 1.0),
                                lower=0.0, upper=round(0.75 * depth, 3)))
    links.append(DemoLink(f"link_{drawers}", "heavy", "furniture_body", body))
    joints.append(DemoJoint(f"joint_{drawers}", "fixed", "base", f"link_{drawers}", rpy=_BASE_RPY))
    return DemoArticulation(asset_id=asset_id, category="StorageFurniture", robot_name=f"synthetic_{asset_id}",
                            links=links, joints=joints, extra_meta={"synthetic": {"width": width, "height": height,
                                                                                   "depth": depth, "drawers": drawers}})


def generate(root: Path, n: int, seed: int = 0) -> list[dict]:
    """Write ``n`` cabinets under ``root/<id>/`` and ``root/manifest.csv``;
    returns the manifest rows (id, category, prompt, drawers, size)."""
    rng = random.Random(seed)
    rows = []
    root.mkdir(parents=True, exist_ok=True)
    for i in range(n):
        drawers = 1 + i % 6
        width = round(rng.uniform(0.6, 1.4), 3)
        height = round(drawers * rng.uniform(0.25, 0.3) + 0.06, 3)
        depth = round(rng.uniform(0.5, 0.9), 3)
        aid = f"syn{i:04d}_d{drawers}"
        _write_folder(root / aid, _serialise(cabinet(aid, width, height, depth, drawers)))
        size = "small" if width * height < 0.6 else "large"
        rows.append({"id": aid, "category": "StorageFurniture", "drawers": drawers, "size": round(width * height * depth, 3),
                     "prompt": f"A {size} wooden cabinet with {drawers} drawer{'s' if drawers > 1 else ''}, all closed, "
                               "with low damping sliding joints."})
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=["id", "category", "prompt"], extrasaction="ignore", lineterminator="\n")
    w.writeheader()
    w.writerows(rows)
    (root / "manifest.csv").write_text(buf.getvalue())
    return rows


# ------------------------------------------------------------------------ measuring


def _cpu() -> float:
    ru = resource.getrusage(resource.RUSAGE_SELF)
    return ru.ru_utime + ru.ru_stime


def in_process(job) -> float:
    """Wall time (s) of the flow's stages for one job run directly in this
    process: prepare (read, hash), refine (with extras), metrics
    (:data:`LAST_CPU`: the CPU time, user + system, s, of refine and metrics,
    the part the flow runs in an isolated child whose CPU time it records)."""
    from asset2sim.flows import stages

    global LAST_CPU
    t0 = time.perf_counter()
    prepared = stages.prepare_asset(job)
    c0 = _cpu()
    extracted = {"asset": prepared.asset.model_dump(mode="json"),
                 "findings": [f.model_dump(mode="json") for f in prepared.findings]}
    out = stages.stage_refine(job.asset_dir, job.prompt, job.out_dir, job.config, job.category, job.asset_id,
                              job.refine_function, job.extras, extracted=extracted, reference_dir=job.reference_dir)
    stages.stage_metrics(out["out_dir"], job.prompt, job.category, job.reference_dir, job.probes, job.metrics_dir)
    wall = time.perf_counter() - t0
    LAST_CPU = _cpu() - c0
    return wall


#: CPU time (s) of the last :func:`in_process` call.
LAST_CPU = 0.0


def flow_times(df) -> dict[str, tuple[float, float, float]]:
    """Per asset of a flow run's catalog rows: (wall s of its stages without
    the stage server's start-up, CPU s of refine and metrics: the isolated
    children's CPU, the metrics stage's wall time when it needed no child,
    the server's start-up s when this asset paid it)."""
    out = {}
    for rec in df.to_dict("records"):
        st = json.loads(rec["stage_seconds"] or "{}")
        start = float(st.get("isolation.server_start", 0.0))
        cpu = float(st.get("cpu.refine", 0.0)) + float(st.get("cpu.metrics", st.get("metrics", 0.0)))
        out[rec["asset_id"]] = (float(rec["wall_seconds"] or 0.0) - start, cpu, start)
    return out


def _timed_in_process(job) -> tuple[str, tuple[float, float]]:
    """(asset id, (wall s, CPU s)); NaNs, with the error printed, when the stages raised."""
    try:
        wall = in_process(job)
    except Exception as exc:  # noqa: BLE001 - reported, the benchmark goes on
        print(f"    in process: {job.asset_id} raised {type(exc).__name__}: {str(exc)[:200]}", flush=True)
        return job.asset_id, (float("nan"), float("nan"))
    return job.asset_id, (wall, LAST_CPU)


def in_process_concurrent(jobs: list, workers: int) -> dict[str, tuple[float, float]]:
    """:func:`in_process` of ``jobs`` on ``workers`` processes at once
    (forked from this warm process), so the cores are shared the way the
    flow's workers share them: asset id -> (wall s, CPU s)."""
    import multiprocessing as mp
    from concurrent.futures import ProcessPoolExecutor

    with ProcessPoolExecutor(max_workers=max(1, workers), mp_context=mp.get_context("fork")) as pool:
        return dict(pool.map(_timed_in_process, jobs))


def isolation_cost(work: Path, calls: int = 10) -> dict[str, float]:
    """The stage server's start-up (s) and the median time of a trivial call
    through it against the same call made directly (s)."""
    from asset2sim.flows.forkserver import StageServer
    from asset2sim.flows.isolation import call_target

    srv = StageServer()
    t0 = time.perf_counter()
    srv.start()
    start = time.perf_counter() - t0
    via, direct = [], []
    try:
        for i in range(calls):
            t0 = time.perf_counter()
            res = srv.call("asset2sim.flows.store:join_uri", {"root": "s3://b/p"}, timeout=60, workdir=work / f"call{i}")
            via.append(time.perf_counter() - t0)
            assert res.status == "ok", res.error
            t0 = time.perf_counter()
            call_target("asset2sim.flows.store:join_uri", {"root": "s3://b/p"})
            direct.append(time.perf_counter() - t0)
    finally:
        srv.close()
    return {"server_start_s": start, "call_via_server_s": statistics.median(via), "call_direct_s": statistics.median(direct)}


def _load() -> str:
    try:
        return " ".join(f"{v:.1f}" for v in os.getloadavg()) + f" on {os.cpu_count()} cores"
    except OSError:
        return "n/a"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--n", type=int, default=200, help="assets to generate and refine (default 200)")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--sample", type=int, default=10, help="assets also refined in process for the overhead ratio")
    ap.add_argument("--no-extras", action="store_true", help="without renders, MJCF export and HTML report")
    ap.add_argument("--work", type=Path, default=None, help="work folder (default: a temporary one, removed)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--manifest", type=Path, default=None, help="a dataset's manifest.csv to run instead of generated cabinets")
    ap.add_argument("--keep-cache", action="store_true",
                    help="use the environment's on-disk cache (ASSET2SIM_CACHE or ~/.cache/asset2sim) for both sides")
    args = ap.parse_args(argv)
    os.environ.setdefault("MPLBACKEND", "Agg")
    allocator.keep_freed_memory()
    work = args.work or Path(tempfile.mkdtemp(prefix="a2s-bench-flow-"))
    keep = args.work is not None
    work.mkdir(parents=True, exist_ok=True)
    try:
        return _run(args, work)
    finally:
        if not keep:
            shutil.rmtree(work, ignore_errors=True)


def _own_cache(args, work: Path, name: str) -> None:
    """Point this process and the processes it starts from now on at an
    empty on-disk cache folder ``work/name`` (``ASSET2SIM_CACHE``), unless
    ``--keep-cache``."""
    if not args.keep_cache:
        os.environ["ASSET2SIM_CACHE"] = str(work / name)


def _run(args, work: Path) -> int:
    from asset2sim.flows.catalog_config import load_catalog

    if args.manifest is not None:
        with open(args.manifest, newline="") as fh:
            rows = list(csv.DictReader(fh))
        print(f"dataset: {len(rows)} rows of {args.manifest}")
    else:
        rows = _generated(args, work)
    catalog = _write_catalog(args, work)
    # both sides start from an empty on-disk cache of their own (asset2sim.array_cache: CoACD, collision
    # pieces, link analyses, keyed by content): the generated assets are the same for a seed, so an earlier run's
    # entries would speed the flow up, and the flow's own entries the in-process side after it
    _own_cache(args, work, "cache-flow")
    print(f"load before the flow: {_load()}; on-disk cache {os.environ.get('ASSET2SIM_CACHE') or 'the default'}")
    summary, cost = _timed_flow(catalog, args)
    cat = load_catalog(catalog)
    ft, occupancy = _print_flow(cat, summary, cost, args)
    _side_by_side(args, work, cat, rows, ft, occupancy)
    _print_rerun(catalog, args)
    iso = isolation_cost(work / "iso")
    print(f"isolation: stage server start-up {iso['server_start_s']:.2f} s once per worker; a call through it "
          f"{1000 * iso['call_via_server_s']:.1f} ms against {1000 * iso['call_direct_s']:.2f} ms direct")
    return 0


def _generated(args, work: Path) -> list[dict]:
    """:func:`generate` of ``--n`` assets under ``work/raw``, timed and described."""
    t0 = time.perf_counter()
    rows = generate(work / "raw", args.n, args.seed)
    gen_s = time.perf_counter() - t0
    drawers = [r["drawers"] for r in rows]
    print(f"generated {args.n} assets in {gen_s:.1f} s: drawers {min(drawers)}-{max(drawers)} "
          f"(joints = drawers), volume {min(r['size'] for r in rows)}-{max(r['size'] for r in rows)} units^3")
    return rows


def _write_catalog(args, work: Path) -> Path:
    """``work/catalog.yaml`` of the generated dataset (tracking off); Prefect's environment set up under ``work``."""
    from asset2sim.flows.stages import prepare_prefect_environment

    config = {
        "version": 1, "default_dataset": "synthetic", "output_root": "refined", "catalog_root": "catalog",
        "datasets": {"synthetic": {"root": str(args.manifest.resolve().parent), "manifest": str(args.manifest.resolve())}
                     if args.manifest is not None else {"root": "raw", "manifest": "raw/manifest.csv"}},
        "run": {"workers": args.workers, "time_limit_seconds": 900, "extras": not args.no_extras, "evaluate": True},
        "tracking": {"enabled": False},
        "results": {"code_change": "keep"},  # the rerun measures skipping, whatever else edits the source meanwhile
    }
    catalog = work / "catalog.yaml"
    catalog.write_text(json.dumps(config))  # JSON is YAML
    prepare_prefect_environment(work)
    return catalog


def _cpu_since(before, after) -> float:
    """CPU seconds (user + system) between two ``resource.getrusage`` readings."""
    return (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


class ProcessCpu:
    """CPU seconds of this process's descendants by kind while it runs (a thread sampling them every
    ``interval`` s with psutil; a process's last interval before it ends is missed), and of the whole machine
    (``psutil.cpu_times``), so that what other processes took from the same cores shows."""

    KINDS = ("stage servers", "stage children", "Dask workers", "Prefect server", "other children")

    def __init__(self, interval: float = 0.25):
        import threading

        import psutil

        self._psutil, self.interval = psutil, interval
        self._me = psutil.Process()
        self._seen: dict[tuple[int, float], tuple[float, str]] = {}
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._loop, daemon=True)

    def _kind(self, proc) -> str:
        cmd = " ".join(proc.cmdline())
        if "asset2sim.flows.forkserver" in cmd:
            parent = proc.parent()
            return "stage children" if parent is not None and "forkserver" in " ".join(parent.cmdline()) else "stage servers"
        if "spawn_main" in cmd:
            return "Dask workers"
        if "uvicorn" in cmd and "prefect" in cmd:
            return "Prefect server"
        return "other children"

    def _loop(self) -> None:
        while not self._stop.wait(self.interval):
            for proc in self._me.children(recursive=True):
                try:
                    key = (proc.pid, proc.create_time())
                    t = proc.cpu_times()
                    kind = self._seen[key][1] if key in self._seen else self._kind(proc)
                    self._seen[key] = (t.user + t.system, kind)
                except (self._psutil.NoSuchProcess, self._psutil.AccessDenied, self._psutil.ZombieProcess):
                    continue

    def __enter__(self) -> "ProcessCpu":
        self._machine0 = self._psutil.cpu_times()
        self._self0 = sum(self._me.cpu_times()[:2])
        self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self._stop.set()
        self._thread.join()
        t0, t1 = self._machine0, self._psutil.cpu_times()
        busy = [f for f in t1._fields if f not in ("idle", "iowait", "steal", "guest", "guest_nice")]
        self.machine = sum(getattr(t1, f) - getattr(t0, f) for f in busy)
        self.steal = getattr(t1, "steal", 0.0) - getattr(t0, "steal", 0.0)  # taken by the hypervisor
        self.own = sum(self._me.cpu_times()[:2]) - self._self0

    def by_kind(self) -> dict[str, float]:
        """Kind -> CPU seconds sampled."""
        out = dict.fromkeys(self.KINDS, 0.0)
        for cpu, kind in self._seen.values():
            out[kind] += cpu
        return out


def _timed_flow(catalog: Path, args) -> tuple[dict, dict[str, float]]:
    """The flow's run summary and its cost (s): ``wall``, ``driver_cpu``, ``kids_cpu`` (ended child processes),
    ``prefect`` (start-up before the flow body), ``by_kind`` (:class:`ProcessCpu`) and ``others`` (the machine's
    CPU outside this process tree)."""
    from asset2sim.flows.refine_flow import run_refine_flow

    ru_self0, ru_kids0 = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    t0, t0_epoch = time.perf_counter(), time.time()
    with ProcessCpu() as sampled:
        summary = run_refine_flow(catalog, workers=args.workers)
    wall = time.perf_counter() - t0
    ru_self1, ru_kids1 = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    by_kind = sampled.by_kind()
    cost = {"wall": wall, "driver_cpu": _cpu_since(ru_self0, ru_self1), "kids_cpu": _cpu_since(ru_kids0, ru_kids1),
            "prefect": max(0.0, float(summary["flow_started_epoch"]) - t0_epoch), "by_kind": by_kind,
            "others": max(0.0, sampled.machine - sampled.own - sum(by_kind.values())), "steal": sampled.steal}
    return summary, cost


def _print_flow(cat, summary: dict, cost: dict[str, float], args) -> tuple[dict, float]:
    """Print the flow's throughput, start-up, per-asset worker time and CPU; returns :func:`flow_times` of its rows
    and the worker occupancy per asset (s)."""
    from asset2sim.flows.catalog import ResultCatalog

    wall, driver_cpu, kids_cpu = cost["wall"], cost["driver_cpu"], cost["kids_cpu"]
    df = ResultCatalog(cat.catalog_root).read("synthetic", summary["run"])
    worked = int(summary["done"]) + int(summary["failed"])
    assets_s = float(summary["assets_seconds"])
    ft = flow_times(df)
    stage_s = df["asset_id"].map(lambda a: ft[a][0]).astype(float)
    starts = [v[2] for v in ft.values() if v[2] > 0]
    occupancy = assets_s * args.workers / max(1, worked)
    print(f"flow: {summary['assets']} assets ({summary['done']} done, {summary['failed']} failed, "
          f"{summary['skipped']} skipped) in {wall:.1f} s wall; load after: {_load()}")
    print(f"  start-up: Prefect {cost['prefect']:.1f} s, Dask {summary['dask_startup_seconds']:.1f} s "
          f"(+ tear-down {summary['dask_teardown_seconds']:.1f} s), stage servers on every worker "
          f"{summary.get('stage_servers_seconds', 0.0):.1f} s; assets phase {assets_s:.1f} s; "
          f"summary {summary['tracking_seconds']:.1f} s")
    print(f"  throughput: {worked / assets_s * 3600:.0f} assets/hour over the assets phase, "
          f"{worked / wall * 3600:.0f} assets/hour over the whole run (goal >= 2000)")
    p90 = float(stage_s.quantile(0.9))
    print(f"  per-asset stages: median {stage_s.median():.2f} s, p90 {p90:.2f} s ({p90 / max(1e-9, stage_s.median()):.2f}x the "
          f"median; goal <= 3x), slowest " + ", ".join(f"{a} {t:.1f} s" for a, t in
                                                      sorted(zip(df["asset_id"], stage_s), key=lambda x: -x[1])[:3]))
    print(f"  per-asset worker time: stages {stage_s.median():.2f} s median ({stage_s.mean():.2f} mean, "
          f"{stage_s.sum() / max(1e-9, assets_s * args.workers):.0%} of the workers' time in the assets phase; "
          f"stage server start-up {statistics.mean(starts) if starts else 0.0:.2f} s paid by {len(starts)} assets, "
          f"once per worker, not counted here); "
          f"worker occupancy (assets phase x workers / assets) {occupancy:.2f} s")
    print(f"  CPU: driver process (flow engine, Dask scheduler, catalog rows) {driver_cpu:.1f} s "
          f"({driver_cpu / max(1, worked):.2f} s per asset); its ended child processes (Prefect server, Dask nannies "
          f"and workers with what they reaped) {kids_cpu:.1f} s ({kids_cpu / max(1, worked):.2f} s per asset); "
          f"isolated stage children {sum(v[1] for v in ft.values()):.1f} s")
    print("  CPU by process, sampled every 0.25 s over the run (a process's last 0.25 s missed): "
          + ", ".join(f"{k} {v:.1f} s" for k, v in cost["by_kind"].items())
          + f"; processes outside the flow on this machine {cost['others']:.1f} s, the hypervisor (steal) {cost['steal']:.1f} s")
    fails = df[df["status"] == "failed"]
    if len(fails):
        print("  failed: " + ", ".join(f"{a} ({m})" for a, m in zip(fails["asset_id"], fails["failure_mode"])))
    return ft, occupancy


def _placed(jobs: list, work: Path, tag: str) -> list:
    """Copies of ``jobs`` writing under ``work/tag``."""
    import copy

    jobs = [copy.deepcopy(j) for j in jobs]
    for job in jobs:
        job.out_dir = str(work / tag / job.asset_id)
        job.metrics_dir = str(work / tag / "_metrics" / job.asset_id)
        job.work_dir = str(work / tag / ".work" / job.asset_id)
    return jobs


def _side_by_side(args, work: Path, cat, rows: list[dict], ft: dict, occupancy: float) -> None:
    """The same stages in this process, alone and ``--workers`` at a time, on a sample of ``--sample`` assets spread
    over the manifest and over drawer counts (asset i has 1 + i % 6 drawers), against the flow's times ``ft``."""
    from asset2sim.flows.run_plan import plan_run

    k = max(0, min(args.sample, len(rows)))
    sample_ids = list(dict.fromkeys(rows[min(len(rows) - 1, i * (len(rows) // max(1, k)) + i % 6)]["id"] for i in range(k)))
    if not sample_ids:
        return
    plan = plan_run(cat, "synthetic", "inprocess", ids=sample_ids, force=True)
    # warm this process first (the flow's stage servers import everything before their first asset) on an
    # asset outside the sample: caches keyed by an asset's files must not favour a sampled asset
    _own_cache(args, work, "cache-inprocess")  # as cold as the flow's was
    spare = [r["id"] for r in rows if r["id"] not in sample_ids][:1] or sample_ids[:1]
    _timed_in_process(_placed(plan_run(cat, "synthetic", "inprocess", ids=spare, force=True).jobs, work, "inprocess-warmup")[0])
    inproc = dict(_timed_in_process(j) for j in _placed(plan.jobs, work, "inprocess"))
    _own_cache(args, work, "cache-concurrent")  # cold again for the 2-at-a-time side
    conc = in_process_concurrent(_placed(plan.jobs, work, "inprocess-concurrent"), args.workers)
    sample_ids = [a for a in sample_ids if a in ft and inproc[a][0] == inproc[a][0] and conc[a][0] == conc[a][0]]
    flow_s = [ft[a][0] for a in sample_ids]
    ip = [inproc[a][0] for a in sample_ids]
    cc = [conc[a][0] for a in sample_ids]
    f_cpu = [ft[a][1] for a in sample_ids]
    i_cpu = [inproc[a][1] for a in sample_ids]
    ratios = [f / i for f, i in zip(flow_s, ip)]
    print(f"side by side on {len(sample_ids)} assets: in process alone {statistics.mean(ip):.2f} s mean, in process "
          f"{args.workers} at a time {statistics.mean(cc):.2f} s mean, flow stages {statistics.mean(flow_s):.2f} s mean")
    print(f"  overhead (flow stages / in process alone) {sum(flow_s) / sum(ip):.2f}x (per asset median "
          f"{statistics.median(ratios):.2f}x); against in process {args.workers} at a time (the same share of the "
          f"cores) {sum(flow_s) / sum(cc):.2f}x; worker occupancy per asset {occupancy / statistics.mean(ip):.2f}x "
          f"of the in-process-alone mean, {occupancy / statistics.mean(cc):.2f}x of the {args.workers}-at-a-time mean "
          f"(goal <= 1.3x)")
    print(f"  CPU time of refine + metrics (user + system; what a loaded machine does not inflate): in process "
          f"{statistics.mean(i_cpu):.2f} s mean, flow (isolated child) {statistics.mean(f_cpu):.2f} s mean: "
          f"overhead {sum(f_cpu) / sum(i_cpu):.2f}x")
    for a in sample_ids:
        print(f"    {a}: in process alone {inproc[a][0]:.2f} s ({inproc[a][1]:.2f} s CPU), {args.workers} at a time "
              f"{conc[a][0]:.2f} s, flow stages {ft[a][0]:.2f} s ({ft[a][1]:.2f} s CPU)")


def _print_rerun(catalog: Path, args) -> None:
    """Run the flow again (every asset skipped) and print its wall time."""
    from asset2sim.flows.refine_flow import run_refine_flow

    t0 = time.perf_counter()
    again = run_refine_flow(catalog, workers=args.workers)
    rerun = time.perf_counter() - t0
    print(f"rerun: {again['skipped']} of {again['assets']} skipped in {rerun:.1f} s wall, {again.get('driver_skipped', 0)} "
          f"decided by the driver before any worker or server started (assets phase {again['assets_seconds']:.1f} s, "
          f"Dask start-up {again['dask_startup_seconds']:.1f} s, Prefect flow run: "
          f"{'yes' if again.get('flow_run_id') else 'none'}; goal <= 10 s)")


if __name__ == "__main__":
    sys.exit(main())
