"""The dataset refinement flow: ``catalog.yaml`` in, refined assets, Parquet
catalog rows and an MLflow run out. ``refine_dataset`` plans the run in the
driver, ``refine_assets`` (a subflow on a DaskTaskRunner) runs each asset's
stages (:mod:`asset2sim.flows.stages`) and appends its catalog row; a run
regressed beyond ``results.regression`` with ``fail_flow`` raises
:class:`RegressionFailure` after everything is recorded. Imports Prefect.
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import logging
import os
import time
import uuid
from concurrent.futures import ThreadPoolExecutor
from dataclasses import asdict
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

from prefect import flow, get_run_logger, task
from prefect.cache_policies import NO_CACHE
from prefect.context import FlowRunContext
from prefect.futures import as_completed
from prefect.settings import PREFECT_API_URL

from asset2sim.flows import catalog_compare, catalog_finish, queries, tracking
from asset2sim import flow_progress
from asset2sim.flows.catalog import ResultCatalog
from asset2sim.flows.catalog_config import load_catalog
from asset2sim.flow_progress import ProgressEvent
from asset2sim.flows import driver_skip, job_order, server, stages
from asset2sim.flows.forkserver import StageServer, ready_server
from asset2sim.flows.store import join_uri, upload_folder
from asset2sim.flows.stages import (FLOW_NAME, SUBFLOW_NAME, AssetJob, ModelCallFailure, RegressionFailure,
                                    code_version, flow_parameters, make_run_id, plan_run)
from asset2sim.tasks.check.verdict import exception_failure_mode
from asset2sim.flows.job_records import Prepared, build_manifest_row, build_row

__all__ = ["FLOW_NAME", "SUBFLOW_NAME", "AssetJob", "flow_parameters", "refine_assets", "refine_dataset", "run_refine_flow"]


class Sealed:
    """A task argument Prefect hands to the task whole, without looking inside: Prefect walks every argument for
    futures and states to link (``visit_collection``), rebuilding each pydantic model and dataclass it holds, twice
    in the driver and twice in the worker, which costs 2-12 ms per pass for one asset's description. An asset's
    arguments hold no future (the flow passes each prepared record itself), so nothing is lost. (Prefect's own
    ``quote`` and ``opaque`` wrappers are tuples, which Dask's task spec unpacks on the way.) Dask names each
    submission by a token of its arguments, pickling what it does not know (about 10 ms for one asset's record):
    a sealed value's token is drawn once instead (``__dask_tokenize__``), as for ``pure=False`` submissions."""

    __slots__ = ("value", "_token")

    def __init__(self, value: Any):
        self.value = value
        self._token = uuid.uuid4().hex

    def __dask_tokenize__(self) -> str:
        return self._token

    def __getstate__(self) -> tuple:
        return (self.value,)  # never false: pickle calls __setstate__ for an empty value too

    def __setstate__(self, state: tuple) -> None:
        self.value, self._token = state[0], uuid.uuid4().hex


def prepare_sealed(batch: Sealed) -> list:
    """:func:`asset2sim.flows.stages.prepare_batch` of a sealed batch of jobs."""
    return stages.prepare_batch(batch.value)


def chain_sealed(job: Sealed, prepared: Sealed) -> stages.ChainResult:
    """:func:`asset2sim.flows.stages.refine_chain` of a sealed job and its prepared record."""
    return stages.refine_chain(job.value, prepared.value)


prepare_many = task(prepare_sealed, name="prepare", cache_policy=NO_CACHE, persist_result=False)
chain = task(chain_sealed, name="refine-metrics", cache_policy=NO_CACHE, persist_result=False)

#: Largest batch of assets one prepare task reads.
PREPARE_BATCH_MAX = 25


def prepare_batch_size(n_jobs: int, workers: int | None) -> int:
    """Assets per prepare task: about four batches per worker, 1 to
    :data:`PREPARE_BATCH_MAX` (small runs keep one asset per task)."""
    return max(1, min(PREPARE_BATCH_MAX, n_jobs // (4 * max(1, int(workers or 2)))))


def _retry_on_model_failure(task, task_run, state) -> bool:
    """Prefect ``retry_condition_fn``: retry only :class:`ModelCallFailure`."""
    try:
        state.result(raise_on_failure=True)
    except Exception as exc:
        return isinstance(exc, ModelCallFailure)
    return False


def _outcome(fut) -> tuple[Any, BaseException | None]:
    """A future's value, or the exception that ended it."""
    try:
        return fut.result(raise_on_failure=True), None
    except BaseException as exc:  # recorded in the row
        return None, exc


def _current_flow_run_id() -> str | None:
    try:
        from prefect.runtime import flow_run

        return str(flow_run.id) if flow_run.id else None
    except Exception:
        return None


@flow(name=SUBFLOW_NAME, persist_result=False, validate_parameters=False)
def refine_assets(
    jobs: list[dict[str, Any]],
    catalog_root: str,
    retries: int = 0,
    retry_delay_seconds: float = 10.0,
    parent_flow_run_id: str | None = None,
    batch_size: int = 1,
    fingerprints: dict[str, str | None] | None = None,
) -> dict[str, Any]:
    """Fan out ``prepare`` (``batch_size`` assets per task) and
    ``refine-metrics`` (:func:`asset2sim.flows.stages.refine_chain`) per asset
    on the flow's task runner and append each asset's catalog row under
    ``catalog_root`` as its chain ends. ``fingerprints``: asset id -> folder
    fingerprint taken by the driver (:mod:`asset2sim.flows.driver_skip`).

    Returns:
        ``{"rows": [CatalogRow, ...], "inputs": {asset id: InputEntry},
        "cluster_up": epoch s, "servers_seconds": s (:func:`_ready_stage_servers`),
        "body_started": epoch s, "body_seconds": s}`` (the body: the assets, after the servers).
    """
    log = get_run_logger()
    flow_run_id = parent_flow_run_id or _current_flow_run_id()
    cluster_up = time.time()  # the Dask cluster is up once the body runs
    rec = _AssetRecorder(ResultCatalog(catalog_root), flow_run_id, log)
    chain_task = chain.with_options(
        retries=retries, retry_delay_seconds=retry_delay_seconds, retry_condition_fn=_retry_on_model_failure,
        timeout_seconds=None,
    )  # fmt: skip
    all_jobs = job_order.start_order([AssetJob(**j) for j in jobs])  # copies of one folder apart, largest first
    servers_seconds = _ready_stage_servers(all_jobs, log)
    body_started = time.time()  # the stage servers' start-up is not the assets'
    prep_futures = _submit_prepares(all_jobs, batch_size, rec.starts)
    chains = _submit_chains(prep_futures, chain_task, rec, fingerprints or {})
    _record_chains(chains, rec)
    return {"rows": rec.rows, "inputs": rec.inputs, "body_started": body_started, "body_seconds": time.time() - body_started,
            "cluster_up": cluster_up, "servers_seconds": servers_seconds}


@dataclasses.dataclass
class _AssetRecorder:
    """What :func:`refine_assets` records: each asset's catalog row as its chain ends (``rows``), its start
    (``starts``: asset id -> epoch s) and its input index entry (``inputs``)."""

    store: ResultCatalog
    flow_run_id: str | None
    log: Any
    rows: list = dataclasses.field(default_factory=list)
    starts: dict[str, float] = dataclasses.field(default_factory=dict)
    inputs: dict[str, driver_skip.InputEntry] = dataclasses.field(default_factory=dict)

    def record(self, job: AssetJob, prepared, refined, measured, exc: BaseException | None, published=None) -> None:
        """Append the asset's catalog row; emit its progress event and log line."""
        publish_error = None
        if published is not None and published.status == "ok":  # the row points at the store
            refined.value.out_dir = published.value["out_uri"]
        elif published is not None and published.status == "error":
            publish_error = f"publish: {published.error}"
        if exc is None and prepared is not None and prepared.resume is not None and refined is not None and refined.status == "ok":
            skipped = _record_resumed(self.store, job, prepared, refined, measured, self.starts[job.asset_id])
            if skipped is not None:
                prepared, refined, measured = skipped, None, None
        row = build_row(
            job, prepared, refined, measured,
            error=publish_error if exc is None else f"{type(exc).__name__}: {exc}",
            failure_mode=None if exc is None else exception_failure_mode(exc, ModelCallFailure),
            flow_run_id=self.flow_run_id, started_at=self.starts[job.asset_id], finished_at=time.time(),
        )  # fmt: skip
        _add_isolation_times(row, refined, measured)
        if published is not None and published.status == "ok" and isinstance(published.value.get("clips"), list):
            row.clips = json.dumps(published.value["clips"])  # read in the worker: the row's out_dir is the store's
        self.store.append_row(job.dataset, job.run_id, row)
        self.rows.append(row)
        _emit_finished(job.dataset, job.run_id, row)
        self.log.info("%s: %s (%s) in %.1f s", job.asset_id, row.status, row.failure_mode, row.wall_seconds or 0.0)


def _emit_finished(dataset: str, run_id: str, row) -> None:
    """The progress event of an asset whose row was written."""
    flow_progress.emit(ProgressEvent("asset_finished", dataset, run_id, asset_id=row.asset_id,
                                     status=row.status, failure_mode=row.failure_mode, seconds=row.wall_seconds))


def _submit_prepares(jobs: list[AssetJob], batch_size: int, starts: dict[str, float]) -> dict:
    """Submit one ``prepare`` task per batch of ``batch_size`` jobs, noting each job's start (epoch s) in ``starts``;
    returns future -> batch."""
    prep_futures = {}
    size = max(1, int(batch_size))
    for i in range(0, len(jobs), size):
        batch = jobs[i:i + size]
        for job in batch:
            starts[job.asset_id] = time.time()
        prep_futures[prepare_many.submit(Sealed(batch))] = batch
    return prep_futures


def _submit_chains(prep_futures: dict, chain_task, rec: _AssetRecorder, fingerprints: dict[str, str | None]) -> dict:
    """As each prepare batch ends: record its input index entries, the row of each asset that ends there (failed,
    skipped, invalid) and submit the ``refine-metrics`` chain of the others; returns future -> (job, prepared)."""
    # the time limit of a non-isolated stage is Prefect's (process isolation has its own)
    chains = {}
    for fut in as_completed(list(prep_futures)):
        batch = prep_futures[fut]
        results, exc_b = _outcome(fut)
        for k, job in enumerate(batch):
            prepared = None if exc_b is not None else results[k]
            exc = exc_b if exc_b is not None else (prepared if isinstance(prepared, BaseException) else None)
            if exc is not None:
                prepared = None
            else:
                entry = driver_skip.entry_for(job, prepared, fingerprints.get(job.asset_id))
                if entry is not None:
                    rec.inputs[job.asset_id] = entry
            if exc is not None or prepared is None or prepared.skip is not None or not prepared.ok:
                rec.record(job, prepared, None, None, exc)
                continue
            # a killed run's complete folder (prepared.resume): refine reads its report, metrics its evaluation
            limit = {} if job.isolation in ("process", "spawn") else {"timeout_seconds": job.time_limit_seconds}
            chains[chain_task.with_options(**limit).submit(Sealed(job), Sealed(prepared))] = (job, prepared)
    return chains


def _record_chains(chains: dict, rec: _AssetRecorder) -> None:
    """Record each asset's row as its chain ends."""
    for cf in as_completed(list(chains)):
        job, prepared = chains[cf]
        res, exc = _outcome(cf)
        if exc is not None:
            rec.record(job, prepared, None, None, exc)
        else:
            rec.record(job, prepared, res.refined, res.measured, res.error, res.published)


def _ready_stage_servers(jobs: list[AssetJob], log) -> float:
    """Start every Dask worker's stage server before the first asset (a failure is logged); returns the seconds
    waited (0 without stage servers or a Dask runner)."""
    from prefect_dask import DaskTaskRunner

    mods = tuple(dict.fromkeys(m for j in jobs for m in stages.stage_server_modules(j)))
    ctx = FlowRunContext.get()
    runner = getattr(ctx, "task_runner", None)
    if not mods or not isinstance(runner, DaskTaskRunner):
        return 0.0
    t0 = time.perf_counter()
    try:
        runner.client.run(ready_server, mods)
    except (RuntimeError, OSError, TimeoutError) as exc:
        log.warning("stage servers not started before the first asset: %s: %s", type(exc).__name__, exc)
    return time.perf_counter() - t0


@flow(name=FLOW_NAME, persist_result=False)
def refine_dataset(catalog: str = "catalog.yaml", dataset: str | None = None, workers: int | None = None,
                   dask_address: str | None = None, ids: list[str] | None = None, limit: int | None = None, force: bool = False,
                   out: str | None = None, dask_host: str | None = None, dashboard: bool | None = None,
                   requested_at: float | None = None) -> dict[str, Any]:
    """Refine every asset of ``dataset`` as declared in ``catalog`` (arguments
    as :func:`run_refine_flow`; ``requested_at``: when the run was asked for, epoch s, before any server started);
    returns the run summary."""
    return run_dataset(get_run_logger(), catalog, dataset, workers, dask_address, ids=ids, limit=limit,
                       force=force, out=out, dask_host=dask_host, dashboard=dashboard, requested_at=requested_at)


@dataclasses.dataclass
class DriverPlan:
    """A run planned by the driver before Prefect or Dask start (``skips``: asset id -> prepared record)."""

    run_id: str
    started: datetime
    plan: Any
    fingerprints: dict[str, str | None]
    skips: dict[str, Prepared]

    @property
    def pending(self) -> list[AssetJob]:
        """The jobs left for the workers."""
        return [j for j in self.plan.jobs if j.asset_id not in self.skips]


def plan_driver(cat, name: str, *, ids=None, limit=None, force: bool = False, out: str | None = None) -> DriverPlan:
    """Plan a run of dataset ``name`` and decide which assets are finished already (none when ``force``).
    Raises CatalogError as :func:`asset2sim.flows.stages.plan_run`."""
    started = datetime.now(timezone.utc)
    run_id = make_run_id(started)
    plan = plan_run(cat, name, run_id, ids=ids, limit=limit, force=force, out_store=out)
    fps = driver_skip.fingerprints(plan.jobs)
    skips = {} if force else driver_skip.decide_skips(
        plan.jobs, driver_skip.read_index(ResultCatalog(cat.catalog_root), name), fps,
        stages.job_config_hash, stages.finished_in_store)
    return DriverPlan(run_id=run_id, started=started, plan=plan, fingerprints=fps, skips=skips)


def run_dataset(log, catalog: str = "catalog.yaml", dataset: str | None = None, workers: int | None = None,
                dask_address: str | None = None, *, ids: list[str] | None = None, limit: int | None = None, force: bool = False,
                out: str | None = None, planned: DriverPlan | None = None, dask_host: str | None = None,
                dashboard: bool | None = None, requested_at: float | None = None) -> dict[str, Any]:
    """The body of :func:`refine_dataset`, also run without a Prefect flow run when nothing is left to dispatch;
    ``planned``: a plan made already by :func:`plan_driver`; ``requested_at``: when the run was asked for (epoch s;
    ``_run.json``'s ``requested_at``, the start of its MLflow run: Prefect's and Dask's start-up are the run's too).
    Raises :class:`RegressionFailure` (the report logged) when the run regressed beyond ``catalog.yaml``
    ``results.regression`` with ``fail_flow``."""
    t0, body_started_epoch = time.perf_counter(), time.time()
    cat = load_catalog(catalog)
    name, _ = cat.dataset(dataset)
    if planned is None:
        planned = plan_driver(cat, name, ids=ids, limit=limit, force=force, out=out)
    run = _start_run(log, cat, name, planned, workers, dask_address, dask_host, dashboard)
    if requested_at is not None:
        run.info["requested_at"] = float(requested_at)
    _record_without_workers(log, run, planned)
    timing = _dispatch(log, run, planned)
    if run.cat.config.run.extras == "deferred":
        timing.update(media_phase(log, run.store.read(run.name, run.run_id, columns=["out_dir", "media"]),
                                  workers=run.n_workers or 1))
    t_track = time.perf_counter()
    flow_progress.emit(ProgressEvent("run_finished", name, run.run_id, total=run.info["assets"]))
    finish, run_out = _finish_partition(log, run)
    summary, df = _run_summary(run, finish, run_out, out, timing)
    tracked = _track(log, run, summary, finish, df, run_out)
    summary.update(
        flow_run_id=run.info["flow_run_id"],  # None: recorded without a Prefect flow run (nothing was dispatched)
        mlflow_run_id=tracked.mlflow_run_id,
        tracking_error=tracked.tracking_error,
        tracking_seconds=time.perf_counter() - t_track,
        flow_body_seconds=time.perf_counter() - t0,
        flow_started_epoch=body_started_epoch,
        artifacts={k: str(v) for k, v in tracked.artifacts.items()},
    )
    run.info.update(
        status="finished",
        outcome=run_outcome(summary),
        finished_at=datetime.now(timezone.utc).isoformat(),
        mlflow_run_id=tracked.mlflow_run_id,
        regression={k: summary["regression"][k] for k in ("status", "exceeded", "previous_run", "regressed", "reasons")},
        summary={k: v for k, v in summary.items() if isinstance(v, (int, float, str, type(None)))},
    )
    run.store.write_run_info(run.name, run.run_id, run.info)
    regression = summary["regression"]
    if regression.get("exceeded") and cat.config.results.regression.fail_flow:
        report = "\n".join(["run regressed beyond catalog.yaml results.regression", *regression.get("lines", [])])
        log.error("%s", report)
        raise RegressionFailure(report, summary)
    return summary


#: ``_run.json``'s ``outcome`` of a run that refined nothing: every asset finished before and reused (``skipped``).
NOTHING_TO_DO = "nothing_to_do"


def run_outcome(summary: dict[str, Any]) -> str:
    """``nothing_to_do`` when the run refined no asset (every row skipped: reused from an earlier run), else
    ``worked``: what ``_run.json`` and the MLflow run say, so ``asset2sim failures`` passes over such a run."""
    skipped_only = int(summary.get("skipped") or 0) > 0 and not int(summary.get("done") or 0) and not int(summary.get("failed") or 0)
    return NOTHING_TO_DO if skipped_only else "worked"


@dataclasses.dataclass
class _Run:
    """One run as :func:`run_dataset` resolved it: catalog, dataset ``name``, run id, result catalog ``store``,
    ``info`` (its ``_run.json``), Dask scheduler ``address`` or local cluster (``n_workers``, ``host``, ``dashboard``)."""

    cat: Any
    name: str
    run_id: str
    store: ResultCatalog
    info: dict[str, Any]
    address: str | None
    n_workers: int | None
    host: str
    dashboard: bool


def _start_run(log, cat, name: str, planned: DriverPlan, workers, dask_address, dask_host, dashboard) -> _Run:
    """The run resolved; its ``_run.json`` written (status ``running``), its start logged and announced."""
    run_id, jobs = planned.run_id, planned.plan.jobs
    address = dask_address or os.environ.get("DASK_ADDRESS") or None
    n_workers = workers or cat.config.run.workers
    store = ResultCatalog(cat.catalog_root)
    info = {
        "dataset": name,
        "run": run_id,
        "flow_run_id": _current_flow_run_id(),
        "catalog": str(cat.path),
        "started_at": planned.started.isoformat(),
        "status": "running",
        "assets": len(jobs) + len(planned.plan.bad_rows),
        "estimator": cat.config.estimator.name,
        "model": cat.config.estimator.model,
        "refine_config_hash": cat.refine_config().config_hash(),
        "workers": None if address else n_workers,
        "dask_address": address,
        "code_version": jobs[0].code_version if jobs else code_version(),
    }
    store.write_run_info(name, run_id, info)
    host = dask_host or cat.config.run.dask_host
    dashboard = cat.config.run.dashboard if dashboard is None else bool(dashboard)
    log.info("run %s: %d assets of dataset %s on %s", run_id, len(jobs), name,
             address or f"a local Dask cluster ({n_workers} workers, listening on {host}, "
                        f"dashboard {'on a free port' if dashboard else 'off'})")
    flow_progress.emit(ProgressEvent("run_started", name, run_id, total=info["assets"], pending=len(planned.pending)))
    return _Run(cat, name, run_id, store, info, address, n_workers, host, dashboard)


def _record_without_workers(log, run: _Run, planned: DriverPlan) -> None:
    """The rows of the manifest's bad rows (failed, ``invalid_manifest_row``) and of the assets the driver skips,
    before any worker starts."""
    bad_rows = planned.plan.bad_rows
    config = run.cat.refine_config().model_dump(mode="json")
    for bad in bad_rows:
        row = build_manifest_row(bad.error, asset_id=bad.asset_id, run_id=run.run_id, config=config,
                                 code_version=run.info["code_version"], flow_run_id=run.info["flow_run_id"])
        run.store.append_row(run.name, run.run_id, row)
        _emit_finished(run.name, run.run_id, row)
    for bad in bad_rows:
        log.warning("%s: manifest row refused (%s): %s", bad.asset_id, bad.error.code, bad.error.message[:300])
    _record_driver_skips(run.store, planned.plan.jobs, planned.skips, run.info["flow_run_id"])


def _dispatch(log, run: _Run, planned: DriverPlan) -> dict[str, Any]:
    """The pending assets refined on Dask (:func:`_fan_out`) and the input index updated; returns the timings (s)
    and ``driver_skipped``."""
    pending = planned.pending
    if planned.skips:
        log.info("%d of %d assets finished already (decided by the driver); %d to the workers",
                 len(planned.skips), len(planned.plan.jobs), len(pending))
    timing = _fan_out(run, pending, planned.fingerprints)
    try:  # the input index: the next run's skip decisions (a cache: a failed write costs only a miss)
        driver_skip.write_index(run.store, run.name, timing.pop("inputs", {}))
    except (OSError, ValueError) as exc:
        log.warning("input index not written: %s: %s", type(exc).__name__, exc)
    timing["driver_skipped"] = len(planned.skips)
    return timing


#: CPU priority (``nice`` increment) of a deferred media phase's children: the verdicts of other work come first.
MEDIA_NICENESS = 10


def media_phase(log, rows, *, workers: int = 1, time_limit_seconds: float = 1800.0) -> dict[str, Any]:
    """The deferred media phase of a run (``catalog.yaml`` ``run.extras: deferred``): what ``asset2sim report OUT`` does
    (:func:`asset2sim.tasks.publish.media.make_media`) for every local output folder of ``rows`` (a DataFrame with
    ``out_dir`` and ``media``) whose ``report.json`` still says its media are deferred, each in a child process forked
    from one of ``workers`` stage servers (:class:`asset2sim.flows.forkserver.StageServer`: the renderers, the
    evaluation and matplotlib imported once, not once per folder) at lower CPU priority (:data:`MEDIA_NICENESS`).
    A child that fails or passes ``time_limit_seconds`` (s) leaves its folder deferred and complete (``asset2sim report
    OUT`` or the next run's media phase makes it); the verdicts are made already and never change here.

    Returns:
        ``{"media_made": n, "media_failed": n, "media_seconds": s}``.
    """
    import queue
    import tempfile

    from asset2sim.tasks.publish.media import media_pending

    t0 = time.perf_counter()
    folders = sorted({str(d) for d, m in zip(rows.get("out_dir", []), rows.get("media", []))
                      if m == "deferred" and isinstance(d, str) and Path(d).is_dir() and media_pending(d)})
    started = [StageServer(("asset2sim.tasks.publish.media",), niceness=MEDIA_NICENESS)
               for _ in range(min(max(1, int(workers)), len(folders)))]
    servers: queue.Queue = queue.Queue()  # the servers not serving a folder now
    for srv in started:
        servers.put(srv)

    def make(folder: str) -> tuple[str, str | None]:
        srv = servers.get()
        try:
            with tempfile.TemporaryDirectory(prefix="asset2sim-media-") as work:
                res = srv.call("asset2sim.tasks.publish.media:make_media", {"out_dir": folder}, timeout=time_limit_seconds,
                               workdir=work)
        except (OSError, RuntimeError) as exc:  # no server: the folder stays deferred
            return folder, f"{type(exc).__name__}: {exc}"
        finally:
            servers.put(srv)
        if res.status == "ok":
            return folder, None
        return folder, f"more than {time_limit_seconds:g} s" if res.status == "timeout" else (res.error or res.status)

    failed = 0
    try:
        with ThreadPoolExecutor(max_workers=max(1, len(started))) as pool:
            for folder, error in pool.map(make, folders):
                if error is not None:
                    failed += 1
                    log.warning("media of %s not made (it stays deferred): %s", folder, error)
    finally:
        for srv in started:
            srv.close()
    seconds = time.perf_counter() - t0
    if folders:
        log.info("media phase: %d of %d outputs in %.1f s", len(folders) - failed, len(folders), seconds)
    return {"media_made": len(folders) - failed, "media_failed": failed, "media_seconds": seconds}


def _finish_partition(log, run: _Run) -> tuple[Any, Path]:
    """Compact the run's partition and compare it with the previous run (logged); returns the
    :func:`asset2sim.flows.catalog_finish.finish_run` result and the run's output folder."""
    run_out = run.cat.output_root / run.name / run.run_id
    finish = catalog_finish.finish_run(run.store, run.name, run.run_id, run_out, run.cat.config.results)
    for line in catalog_compare.comparison_lines(finish.comparison):
        log.info("%s", line)
    for err in finish.errors:
        log.warning("%s", err)
    return finish, run_out


def _run_summary(run: _Run, finish, run_out: Path, out: str | None, timing: dict[str, Any]) -> tuple[dict[str, Any], Any]:
    """The run summary (counts, pass rates, paths, timings, comparison) and the run's catalog rows (DataFrame)."""
    cat, name, run_id = run.cat, run.name, run.run_id
    df = run.store.read(name, run_id)
    summary = queries.run_summary(df)
    summary.update(dataset=name, run=run_id, catalog_root=str(cat.catalog_root), output_dir=str(run_out), **timing)
    out_store = out or cat.output_store
    summary["output_store"] = join_uri(out_store, name, run_id) if out_store else None
    summary.update(finish.comparison.metrics_for_tracking())
    summary["regression"] = catalog_compare.comparison_summary(finish.comparison)
    summary["compaction"] = None if finish.compaction is None else dataclasses.asdict(finish.compaction)
    return summary, df


@dataclasses.dataclass(frozen=True, slots=True)
class _Tracked:
    """What :func:`_track` recorded: ``artifacts`` (name -> file), the ``mlflow_run_id`` and the
    ``tracking_error`` (None when tracking worked)."""

    artifacts: dict[str, Any]
    mlflow_run_id: str | None
    tracking_error: str | None


def _track(log, run: _Run, summary: dict[str, Any], finish, df, run_out: Path) -> _Tracked:
    """The run's report files written (and uploaded to the output store), the MLflow run and the Prefect summary
    artifact."""
    artifacts = {} if df.empty else tracking.write_run_artifacts(df, run_out, title=f"{run.name} / {run.run_id}")
    artifacts.update(finish.artifacts)
    if summary["output_store"] and run_out.is_dir():  # the run's report files beside its assets in the store
        try:
            upload_folder(run_out, summary["output_store"])
        except (OSError, ValueError) as exc:
            log.warning("run artifacts not uploaded to %s: %s: %s", summary["output_store"], type(exc).__name__, exc)
    mlflow_run_id, tracking_error = _log_to_mlflow(run, df, summary, artifacts, extra_tags=finish.comparison.tags())
    if tracking_error:
        log.warning("MLflow tracking failed: %s", tracking_error)
    if run.info["flow_run_id"]:  # in a Prefect flow run
        _prefect_summary_artifact(summary, finish.comparison, mlflow_run_id, log)
    return _Tracked(artifacts, mlflow_run_id, tracking_error)


def _add_isolation_times(row, refined, measured) -> None:
    """Add the isolated stages' ``cpu.refine`` / ``cpu.metrics`` and ``isolation.server_start`` (s) to ``stage_seconds``."""
    add: dict[str, float] = {}
    for name, rec in (("refine", refined), ("metrics", measured)):
        extra = (getattr(rec, "model_extra", None) or {}).get("extra") if rec is not None else None
        if not isinstance(extra, dict):
            continue
        if extra.get("cpu_seconds") is not None:
            add[f"cpu.{name}"] = round(float(extra["cpu_seconds"]), 4)
        if extra.get("server_start_seconds") is not None:
            add["isolation.server_start"] = round(add.get("isolation.server_start", 0.0) + float(extra["server_start_seconds"]), 4)
    if add:
        stages_s = json.loads(row.stage_seconds or "{}")
        stages_s.update(add)
        row.stage_seconds = json.dumps(stages_s, sort_keys=True)


def _record_driver_skips(store: ResultCatalog, jobs: list[AssetJob], skips: dict[str, Prepared],
                         flow_run_id: str | None) -> None:
    """The catalog row of each asset the driver skipped (``skips``: asset id -> prepared record)."""
    todo = [job for job in jobs if job.asset_id in skips]
    if not todo:
        return

    def write(job: AssetJob):
        prepared = skips[job.asset_id]
        t = time.time()
        row = build_row(job, prepared, None, None, flow_run_id=flow_run_id,
                        started_at=t - float(prepared.seconds or 0.0), finished_at=t)
        store.append_row(job.dataset, job.run_id, row)
        return job, row

    with ThreadPoolExecutor(max_workers=min(4, len(todo))) as pool:
        for job, row in pool.map(write, todo):  # progress events from this thread, in manifest order
            _emit_finished(job.dataset, job.run_id, row)


def _record_resumed(store: ResultCatalog, job: AssetJob, prepared: Prepared, refined, measured,
                    started: float) -> Prepared | None:
    """Write the row a killed run owed for its complete folder (``prepared.resume``) into its partition; return
    ``prepared`` with that row as ``skip``, or None when that row would not be ``done``."""
    known = {f.name for f in dataclasses.fields(AssetJob)}
    earlier = AssetJob(**{k: v for k, v in prepared.resume["job"].items() if k in known})
    info = store.run_info(earlier.dataset, earlier.run_id) or {}
    old = build_row(earlier, prepared.model_copy(update={"resume": None}), refined, measured,
                    flow_run_id=info.get("flow_run_id"), started_at=started, finished_at=time.time())
    if old.status != "done":
        return None
    if not store.has_row(earlier.dataset, earlier.run_id, earlier.asset_id):  # row files and the compacted file
        store.append_row(earlier.dataset, earlier.run_id, old)
    prev = old.model_dump(mode="json")
    prev["run"] = earlier.run_id
    return prepared.model_copy(update={"skip": prev})


def _prefect_summary_artifact(summary: dict[str, Any], comparison, mlflow_run_id: str | None, log) -> None:
    """A markdown artifact on the Prefect flow run (a failure is logged, not raised)."""
    try:
        from prefect.artifacts import create_markdown_artifact

        lines = [
            f"### asset2sim run {summary['run']} of dataset {summary['dataset']}",
            f"{summary['assets']} assets: {summary['done']} done, {summary['skipped']} skipped, {summary['failed']} failed; "
            f"all checks passed {100 * (summary.get('pass_rate_all') or 0):.1f}%",
            f"MLflow run: `{mlflow_run_id or 'not logged'}`",
            "",
            "```",
            *catalog_compare.comparison_lines(comparison),
            "```",
        ]
        create_markdown_artifact(markdown="\n".join(lines), key="asset2sim-run-summary",
                                 description=f"asset2sim {summary['dataset']} / {summary['run']}")
    except Exception as exc:  # the catalog and MLflow are the record
        log.warning("Prefect summary artifact not created: %s", exc)


def _fan_out(run: _Run, jobs: list[AssetJob], fingerprints: dict[str, str | None] | None = None) -> dict[str, Any]:
    """Run :func:`refine_assets` on a Dask task runner (nothing starts for no jobs); returns its timings (s) and
    ``inputs``, the input index entries of the assets it read."""
    if not jobs:
        return {"dask_startup_seconds": 0.0, "stage_servers_seconds": 0.0, "assets_seconds": 0.0, "dask_teardown_seconds": 0.0,
                "inputs": {}}
    cat, n_workers, address = run.cat, run.n_workers, run.address
    t_fan, t_fan_epoch = time.perf_counter(), time.time()
    sub = refine_assets.with_options(task_runner=_dask_task_runner(n_workers, address, host=run.host, dashboard=run.dashboard))
    with _local_cluster_config(address, run.dashboard):
        out = sub(
            [asdict(j) for j in jobs],
            str(cat.catalog_root),
            retries=cat.config.estimator.retries if cat.config.estimator.name != "offline" else 0,
            retry_delay_seconds=cat.config.estimator.retry_delay_seconds,
            batch_size=prepare_batch_size(len(jobs), n_workers if not address else None),
            parent_flow_run_id=run.info["flow_run_id"],
            fingerprints={j.asset_id: (fingerprints or {}).get(j.asset_id) for j in jobs},
        )
    fan_seconds = time.perf_counter() - t_fan
    startup = max(0.0, out["cluster_up"] - t_fan_epoch)
    return {"dask_startup_seconds": startup, "stage_servers_seconds": out["servers_seconds"], "assets_seconds": out["body_seconds"],
            "dask_teardown_seconds": max(0.0, fan_seconds - startup - out["servers_seconds"] - out["body_seconds"]),
            "inputs": out.get("inputs", {})}


def _log_to_mlflow(run: _Run, df, summary, artifacts, extra_tags: dict[str, str] | None = None) -> tuple[str | None, str | None]:
    """Log the run to MLflow when tracking is enabled: (MLflow run id, error text)."""
    cat, info, run_id, address = run.cat, run.info, run.run_id, run.address
    if not cat.config.tracking.enabled:
        return None, None
    try:
        run = tracking.log_flow_run(
            df,
            summary,
            params={
                "dataset": info["dataset"],
                "run": run_id,
                "estimator": cat.config.estimator.name,
                "model": cat.config.estimator.model or "",
                "config_hash": info["refine_config_hash"],
                "workers": run.n_workers if not address else "",
                "dask_address": address or "",
                "code_version": info["code_version"],
                "assets": info["assets"],
            },
            artifacts=artifacts,
            project_root=cat.project_root,
            settings=cat.config.tracking,
            tags={"prefect.flow_run_id": info["flow_run_id"] or "", "asset2sim.run": run_id, **(extra_tags or {})},
            started_at=info.get("requested_at") or info.get("started_at"), ended_at=time.time(),
        )
    except Exception as exc:  # the catalog is the record; tracking must not lose it
        return None, f"{type(exc).__name__}: {exc}"
    return run, None


def _dask_task_runner(workers: int | None, address: str | None, *, host: str = "127.0.0.1",
                      dashboard: bool = True):
    """A DaskTaskRunner: the scheduler at ``address``, else a local cluster of ``workers`` single-threaded
    processes listening on ``host`` (dashboard on a free port when ``dashboard``)."""
    from prefect_dask import DaskTaskRunner

    if address:
        return DaskTaskRunner(address=address)
    n = int(workers or os.cpu_count() or 1)
    api = _prefect_api_url()
    env = {"PREFECT_API_URL": api} if api else {}
    http_address = (host.strip("[]"), 0)  # a free port on ``host`` (docs/design/pipeline.md)
    return DaskTaskRunner(
        cluster_kwargs={
            "n_workers": n,
            "threads_per_worker": 1,
            "processes": True,
            "host": host,
            "dashboard_address": http_address if dashboard else None,
            "scheduler_kwargs": {} if dashboard else {"dashboard_address": http_address},
            "env": env,
        }
    )


#: Dask's own bookkeeping kept light on the flow's cluster: no profiler sampling every worker's stacks 100 times a
#: second, the event-loop tick, the system monitor and the nanny's memory monitor at 1-2 s instead of 20-500 ms (CPU a
#: refine needs; ``docs/design/pipeline.md``, "What the orchestration costs"). A cluster the flow is given gets them
#: from its machines' environment (:func:`dask_settings_env`, the guide's recipe for N machines).
DASK_SETTINGS: dict[str, Any] = {
    "distributed.worker.profile.enabled": False,
    "distributed.admin.tick.interval": "1s",
    "distributed.admin.system-monitor.interval": "2s",
    "distributed.worker.memory.monitor-interval": "1s",
}


def dask_settings_env() -> dict[str, str]:
    """:data:`DASK_SETTINGS` as the environment variables Dask reads (``DASK_DISTRIBUTED__WORKER__PROFILE__ENABLED``
    ...)."""
    return {"DASK_" + key.replace(".", "__").replace("-", "_").upper(): str(value).lower() if isinstance(value, bool) else str(value)
            for key, value in DASK_SETTINGS.items()}


@contextlib.contextmanager
def _local_cluster_config(address: str | None, dashboard: bool):
    """Dask configuration for a local cluster: :data:`DASK_SETTINGS`; without ``dashboard``, no HTTP routes on
    scheduler and workers."""
    if address:
        yield
        return
    import dask

    settings = dict(DASK_SETTINGS)
    if not dashboard:
        settings.update({"distributed.scheduler.http.routes": [], "distributed.worker.http.routes": []})
    with dask.config.set(settings):
        yield


def _prefect_api_url() -> str | None:
    """The Prefect API this process talks to (its temporary server when none is configured), or None."""
    try:
        url = PREFECT_API_URL.value()
        if not url:
            from prefect.server.api.server import SubprocessASGIServer

            server = SubprocessASGIServer()
            if not server.running:
                server.start()
            url = server.api_url
    except Exception:  # no server to share: workers fall back to their own
        return None
    return str(url) if url else None


def run_refine_flow(
    catalog: str | Path = "catalog.yaml",
    dataset: str | None = None,
    workers: int | None = None,
    dask_address: str | None = None,
    *,
    ids: list[str] | None = None,
    limit: int | None = None,
    force: bool = False,
    out: str | None = None,
    dask_host: str | None = None,
    dashboard: bool | None = None,
) -> dict[str, Any]:
    """Run :func:`refine_dataset` in this process (what ``make flow`` does; call from a ``__main__``-guarded
    program). ``out``: the output store (``s3://bucket/prefix``); ``dask_host`` / ``dashboard``: the local Dask
    cluster's listening host and dashboard (None: ``catalog.yaml`` ``run``). Returns the run summary (also of a
    regressed run). Raises CatalogError: invalid catalog or manifest (before any asset runs)."""
    requested_at = time.time()  # the run's MLflow record starts here: server and cluster start-up are the run's
    params = flow_parameters(catalog, dataset, workers, dask_address, out)
    params.update({k: v for k, v in (("dask_host", dask_host), ("dashboard", dashboard)) if v is not None})
    cat = load_catalog(params["catalog"])  # fail early, before the flow starts
    if not PREFECT_API_URL.value():
        # no Prefect server to talk to: plan here first; a run with nothing to
        # dispatch (every asset finished) starts neither a server nor Dask
        name, _ = cat.dataset(dataset)
        planned = plan_driver(cat, name, ids=ids, limit=limit, force=force, out=params.get("out"))
        if not planned.pending:
            try:
                return run_dataset(logging.getLogger("asset2sim.flow"), **params, ids=ids, limit=limit, force=force,
                                   planned=planned, requested_at=requested_at)
            except RegressionFailure as exc:  # recorded and reported; the caller sets the exit status
                return exc.summary
    with prefect_api_for_run(cat.project_root):
        state = refine_dataset(**params, ids=ids, limit=limit, force=force, requested_at=requested_at, return_state=True)
    if state.is_failed():
        exc = state.result(raise_on_failure=False)
        if isinstance(exc, RegressionFailure):  # recorded and reported; the caller sets the exit status
            return exc.summary
    return state.result(raise_on_failure=True)


@contextlib.contextmanager
def prefect_api_for_run(project_root: Path | str):
    """Yield the Prefect API URL of one flow run: the configured ``PREFECT_API_URL``, else a temporary server stopped
    when the block ends (main thread only). RuntimeError: it did not start (log: ``<project>/.prefect/server.log``)."""
    from prefect.settings import (
        PREFECT_SERVER_EPHEMERAL_STARTUP_TIMEOUT_SECONDS,
        temporary_settings,
    )

    url = PREFECT_API_URL.value()
    if url:
        yield str(url)
        return
    proc, url = server.start_local_server(
        project_root, timeout=float(PREFECT_SERVER_EPHEMERAL_STARTUP_TIMEOUT_SECONDS.value()), ephemeral=True
    )
    try:
        with temporary_settings({PREFECT_API_URL: url}):
            try:
                yield url
            finally:
                _drain_prefect_workers()
    finally:
        server.stop_server(proc)


def _drain_prefect_workers() -> None:
    """Flush Prefect's background log and event workers before the server stops."""
    with contextlib.suppress(Exception):  # best effort: the catalog, not Prefect's log, is the record
        from prefect.events.worker import EventsWorker
        from prefect.logging.handlers import APILogWorker

        APILogWorker.drain_all(timeout=5)
        EventsWorker.drain_all(timeout=5)
