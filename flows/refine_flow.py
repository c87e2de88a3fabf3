"""The dataset refinement flow: ``catalog.yaml`` in, refined assets, Parquet
catalog rows and an MLflow run out. ``refine_dataset`` plans the run in the
driver, ``refine_assets`` (a subflow on a DaskTaskRunner, :mod:`asset2sim.flows.subflow`) runs each asset's
stages (:mod:`asset2sim.flows.stages`) and appends its catalog row; a run
regressed beyond ``results.regression`` with ``fail_flow`` raises
:class:`RegressionFailure` after everything is recorded. Imports Prefect.
"""

from __future__ import annotations

import dataclasses
import logging
import os
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import asdict
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

from prefect import flow, get_run_logger
from prefect.settings import PREFECT_API_URL

from asset2sim.flows import catalog_compare, catalog_finish, driver_skip, queries, tracking
from asset2sim import flow_progress
from asset2sim.flows.catalog import NOTHING_TO_DO, ResultCatalog
from asset2sim.flows.catalog_config import load_catalog
from asset2sim.flow_progress import ProgressEvent
from asset2sim.flows.flow_runtime import dask_task_runner, local_cluster_config, prefect_api_for_run
from asset2sim.flows.forkserver import StageServer
from asset2sim.flows.store import join_uri, upload_folder
from asset2sim.flows.tracking import run_outcome
from asset2sim.output_paths import write_inside
from asset2sim.flows.run_plan import flow_parameters, make_run_id, plan_run
from asset2sim.flows.stages import FLOW_NAME, SUBFLOW_NAME, AssetJob, RegressionFailure
from asset2sim.tasks.publish.contract import code_version
from asset2sim.flows.subflow import current_flow_run_id, emit_finished, prepare_batch_size, refine_assets
from asset2sim.flows.job_records import Prepared, build_manifest_row, build_row

__all__ = ["FLOW_NAME", "NOTHING_TO_DO", "SUBFLOW_NAME", "AssetJob", "flow_parameters", "refine_assets", "refine_dataset",
           "run_outcome", "run_refine_flow"]


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


def plan_driver(cat, name: str, *, ids: list[str] | None, limit: int | None, force: bool, out: str | None) -> DriverPlan:
    """Plan a run of dataset ``name`` and decide which assets are finished already (none when ``force``).
    Raises CatalogError as :func:`asset2sim.flows.run_plan.plan_run`."""
    started = datetime.now(timezone.utc)
    run_id = make_run_id(started)
    plan = plan_run(cat, name, run_id, ids=ids, limit=limit, force=force, out_store=out)
    fps = driver_skip.fingerprints(plan.jobs)
    skips = {} if force else driver_skip.decide_skips(
        plan.jobs, driver_skip.read_index(ResultCatalog(cat.catalog_root), name), fps)
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
    artifacts = _track(log, run, summary, finish, df, run_out)
    summary.update(tracking_seconds=time.perf_counter() - t_track, flow_body_seconds=time.perf_counter() - t0,
                   flow_started_epoch=body_started_epoch, artifacts={k: str(v) for k, v in artifacts.items()})
    _record_run_info(run, summary)
    _raise_on_regression(log, run, summary)
    return summary


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
        "flow_run_id": current_flow_run_id(),
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
    if jobs:  # the run's folder in the output root as named and as resolved: never through a symlinked dataset folder
        write_inside(Path(jobs[0].work_dir).parent.parent, cat.output_root, cat.output_root.resolve())
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
    config = run.cat.refine_config().model_dump(mode="json")
    for bad in planned.plan.bad_rows:
        row = build_manifest_row(bad.error, asset_id=bad.asset_id, run_id=run.run_id, config=config,
                                 code_version=run.info["code_version"], flow_run_id=run.info["flow_run_id"])
        run.store.append_row(run.name, run.run_id, row)
        emit_finished(run.name, run.run_id, row)
        log.warning("%s: manifest row refused (%s): %s", bad.asset_id, bad.error.code, bad.error.message[:300])
    todo = [job for job in planned.plan.jobs if job.asset_id in planned.skips]
    if not todo:
        return

    def write(job: AssetJob):
        prepared = planned.skips[job.asset_id]
        t = time.time()
        row = build_row(job, prepared, None, None, flow_run_id=run.info["flow_run_id"],
                        started_at=t - float(prepared.seconds or 0.0), finished_at=t)
        run.store.append_row(job.dataset, job.run_id, row)
        return job, row

    with ThreadPoolExecutor(max_workers=min(4, len(todo))) as pool:
        for job, row in pool.map(write, todo):  # progress events from this thread, in manifest order
            emit_finished(job.dataset, job.run_id, row)


def _dispatch(log, run: _Run, planned: DriverPlan) -> dict[str, Any]:
    """The pending assets refined by :func:`refine_assets` on a Dask task runner (nothing starts when none is pending)
    and the input index updated; returns the timings (s) and ``driver_skipped``."""
    jobs, inputs = planned.pending, {}
    if planned.skips:
        log.info("%d of %d assets finished already (decided by the driver); %d to the workers",
                 len(planned.skips), len(planned.plan.jobs), len(jobs))
    timing = dict.fromkeys(("dask_startup_seconds", "stage_servers_seconds", "assets_seconds", "dask_teardown_seconds"), 0.0)
    if jobs:
        cat, n_workers, address = run.cat, run.n_workers, run.address
        t_fan, t_fan_epoch = time.perf_counter(), time.time()
        sub = refine_assets.with_options(task_runner=dask_task_runner(n_workers, address, host=run.host, dashboard=run.dashboard))
        with local_cluster_config(address, run.dashboard, Path(jobs[0].work_dir).parent):  # the run's .work folder
            out = sub(
                [asdict(j) for j in jobs],
                str(cat.catalog_root),
                retries=cat.config.estimator.retries if cat.config.estimator.name != "offline" else 0,
                retry_delay_seconds=cat.config.estimator.retry_delay_seconds,
                batch_size=prepare_batch_size(len(jobs), n_workers if not address else None),
                parent_flow_run_id=run.info["flow_run_id"],
                fingerprints={j.asset_id: planned.fingerprints.get(j.asset_id) for j in jobs},
            )
        fan_seconds = time.perf_counter() - t_fan
        startup = max(0.0, out["cluster_up"] - t_fan_epoch)
        timing.update(dask_startup_seconds=startup, stage_servers_seconds=out["servers_seconds"],
                      assets_seconds=out["body_seconds"],
                      dask_teardown_seconds=max(0.0, fan_seconds - startup - out["servers_seconds"] - out["body_seconds"]))
        inputs = out.get("inputs", {})
    try:  # the input index: the next run's skip decisions (a cache: a failed write costs only a miss)
        driver_skip.write_index(run.store, run.name, inputs)
    except (OSError, ValueError) as exc:
        log.warning("input index not written: %s: %s", type(exc).__name__, exc)
    timing["driver_skipped"] = len(planned.skips)
    return timing



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
    df = run.store.read(run.name, run.run_id)
    summary = queries.run_summary(df)
    out_store = out or run.cat.output_store
    summary.update(dataset=run.name, run=run.run_id, catalog_root=str(run.cat.catalog_root), output_dir=str(run_out), **timing,
                   output_store=join_uri(out_store, run.name, run.run_id) if out_store else None,
                   **finish.comparison.metrics_for_tracking(),
                   regression=catalog_compare.comparison_summary(finish.comparison),
                   compaction=None if finish.compaction is None else dataclasses.asdict(finish.compaction))
    return summary, df


def _track(log, run: _Run, summary: dict[str, Any], finish, df, run_out: Path) -> dict[str, Any]:
    """The run's report files written (and uploaded to the output store), the MLflow run and the Prefect summary
    artifact; ``summary`` gets ``flow_run_id``, ``mlflow_run_id`` and ``tracking_error`` (None when tracking worked).
    Returns the report files (name -> file)."""
    artifacts = {} if df.empty else tracking.write_run_artifacts(df, run_out, title=f"{run.name} / {run.run_id}")
    artifacts.update(finish.artifacts)
    if summary["output_store"] and run_out.is_dir():  # the run's report files beside its assets in the store
        try:
            upload_folder(run_out, summary["output_store"])
        except (OSError, ValueError) as exc:
            log.warning("run artifacts not uploaded to %s: %s: %s", summary["output_store"], type(exc).__name__, exc)
    mlflow_run_id, tracking_error = _log_to_mlflow(run, df, summary, artifacts, finish.comparison.tags())
    if tracking_error:
        log.warning("MLflow tracking failed: %s", tracking_error)
    if run.info["flow_run_id"]:  # in a Prefect flow run
        _prefect_summary_artifact(summary, finish.comparison, mlflow_run_id, log)
    # flow_run_id None: recorded without a Prefect flow run (nothing was dispatched)
    summary.update(flow_run_id=run.info["flow_run_id"], mlflow_run_id=mlflow_run_id, tracking_error=tracking_error)
    return artifacts


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


def _record_run_info(run: _Run, summary: dict[str, Any]) -> None:
    """The run's ``_run.json`` written finished: outcome, MLflow run, regression and the summary's scalars."""
    run.info.update(
        status="finished",
        outcome=run_outcome(summary),
        finished_at=datetime.now(timezone.utc).isoformat(),
        mlflow_run_id=summary["mlflow_run_id"],
        regression={k: summary["regression"][k] for k in ("status", "exceeded", "previous_run", "regressed", "reasons")},
        summary={k: v for k, v in summary.items() if isinstance(v, (int, float, str, type(None)))},
    )
    run.store.write_run_info(run.name, run.run_id, run.info)


def _raise_on_regression(log, run: _Run, summary: dict[str, Any]) -> None:
    """Raise :class:`RegressionFailure` (the report logged) when the run regressed beyond ``catalog.yaml``
    ``results.regression`` with ``fail_flow``."""
    regression = summary["regression"]
    if regression.get("exceeded") and run.cat.config.results.regression.fail_flow:
        report = "\n".join(["run regressed beyond catalog.yaml results.regression", *regression.get("lines", [])])
        log.error("%s", report)
        raise RegressionFailure(report, summary)

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


def _log_to_mlflow(run: _Run, df, summary, artifacts, extra_tags: dict[str, str]) -> tuple[str | None, str | None]:
    """Log the run to MLflow when tracking is enabled: (MLflow run id, error text)."""
    cat, info, run_id, address = run.cat, run.info, run.run_id, run.address
    if not cat.config.tracking.enabled:
        return None, None
    try:
        return tracking.log_flow_run(
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
            tags={"prefect.flow_run_id": info["flow_run_id"] or "", "asset2sim.run": run_id, **extra_tags},
            started_at=info.get("requested_at") or info.get("started_at"), ended_at=time.time(),
        ), None
    except Exception as exc:  # the catalog is the record; tracking must not lose it
        return None, f"{type(exc).__name__}: {exc}"


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
        planned = plan_driver(cat, cat.dataset(dataset)[0], ids=ids, limit=limit, force=force, out=params.get("out"))
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


