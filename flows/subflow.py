"""The refine flow's subflow, :func:`refine_assets`: on the flow's Dask task runner, one ``prepare`` task per
batch of assets and one ``refine-metrics`` chain per asset (:func:`asset2sim.flows.stages.refine_chain`), each asset's
catalog row appended as its chain ends (:class:`AssetRecorder`). The tasks' arguments travel :class:`Sealed`.
Imports Prefect.
"""

from __future__ import annotations

import dataclasses
import json
import queue
import time
import uuid
from typing import Any

from prefect import flow, get_run_logger, task
from prefect.cache_policies import NO_CACHE
from prefect.context import FlowRunContext

from asset2sim import flow_progress
from asset2sim.flow_progress import ProgressEvent
from asset2sim.flows import driver_skip, job_order, stages
from asset2sim.flows.catalog import ResultCatalog
from asset2sim.flows.forkserver import ready_server
from asset2sim.flows.job_records import build_row
from asset2sim.flows.stages import SUBFLOW_NAME, AssetJob, ModelCallFailure
from asset2sim.tasks.check.verdict import exception_failure_mode


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


def current_flow_run_id() -> str | None:
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
        ``{"inputs": {asset id: InputEntry}, "cluster_up": epoch s, "servers_seconds": s
        (:func:`_ready_stage_servers`), "body_seconds": s}`` (the body: the assets, after the servers).
    """
    log = get_run_logger()
    flow_run_id = parent_flow_run_id or current_flow_run_id()
    cluster_up = time.time()  # the Dask cluster is up once the body runs
    rec = _AssetRecorder(ResultCatalog(catalog_root), flow_run_id, log)
    chain_task = chain.with_options(
        retries=retries, retry_delay_seconds=retry_delay_seconds, retry_condition_fn=_retry_on_model_failure,
        timeout_seconds=None,
    )  # fmt: skip
    all_jobs = job_order.start_order([AssetJob(**j) for j in jobs])  # copies of one folder apart, largest first
    servers_seconds = _ready_stage_servers(all_jobs, log)
    body_started = time.time()  # the stage servers' start-up is not the assets'
    prep_futures = {}  # one prepare task per batch of ``batch_size`` jobs -> the batch
    size = max(1, int(batch_size))
    for i in range(0, len(all_jobs), size):
        batch = all_jobs[i:i + size]
        rec.starts.update({job.asset_id: time.time() for job in batch})
        prep_futures[prepare_many.submit(Sealed(batch))] = batch
    _run_assets(prep_futures, chain_task, rec, fingerprints or {})
    return {"inputs": rec.inputs, "body_seconds": time.time() - body_started, "cluster_up": cluster_up,
            "servers_seconds": servers_seconds}


@dataclasses.dataclass
class _AssetRecorder:
    """What :func:`refine_assets` records: each asset's catalog row as its chain ends, its start (``starts``:
    asset id -> epoch s) and its input index entry (``inputs``)."""

    store: ResultCatalog
    flow_run_id: str | None
    log: Any
    starts: dict[str, float] = dataclasses.field(default_factory=dict)
    inputs: dict[str, driver_skip.InputEntry] = dataclasses.field(default_factory=dict)

    def record(self, job: AssetJob, prepared, refined, measured, exc: BaseException | None, published=None) -> None:
        """Append the asset's catalog row; emit its progress event and log line."""
        published_status = None if published is None else published.status
        publish_error = f"publish: {published.error}" if published_status == "error" else None
        if published_status == "ok":  # the row points at the store
            refined.value.out_dir = published.value["out_uri"]
        if exc is None and prepared is not None and prepared.resume is not None and refined is not None and refined.status == "ok":
            # the row a killed run owed for its complete folder (prepared.resume), written into its partition; when it
            # is ``done``, this run's row reuses it (``skip``)
            known = {f.name for f in dataclasses.fields(AssetJob)}
            earlier = AssetJob(**{k: v for k, v in prepared.resume["job"].items() if k in known})
            info = self.store.run_info(earlier.dataset, earlier.run_id) or {}
            old = build_row(earlier, prepared.model_copy(update={"resume": None}), refined, measured,
                            flow_run_id=info.get("flow_run_id"), started_at=self.starts[job.asset_id], finished_at=time.time())
            if old.status == "done":
                if not self.store.has_row(earlier.dataset, earlier.run_id, earlier.asset_id):  # row files, compacted file
                    self.store.append_row(earlier.dataset, earlier.run_id, old)
                skip = {**old.model_dump(mode="json"), "run": earlier.run_id}
                prepared, refined, measured = prepared.model_copy(update={"skip": skip}), None, None
        row = build_row(
            job, prepared, refined, measured,
            error=publish_error if exc is None else f"{type(exc).__name__}: {exc}",
            failure_mode=None if exc is None else exception_failure_mode(exc, ModelCallFailure),
            flow_run_id=self.flow_run_id, started_at=self.starts[job.asset_id], finished_at=time.time(),
        )  # fmt: skip
        # the isolated stages' ``cpu.refine`` / ``cpu.metrics`` and ``isolation.server_start`` (s) in ``stage_seconds``
        add: dict[str, float] = {}
        for name, rec in (("refine", refined), ("metrics", measured)):
            extra = (getattr(rec, "model_extra", None) or {}).get("extra") if rec is not None else None
            if not isinstance(extra, dict):
                continue
            if extra.get("cpu_seconds") is not None:
                add[f"cpu.{name}"] = round(float(extra["cpu_seconds"]), 4)
            if extra.get("server_start_seconds") is not None:
                add["isolation.server_start"] = round(
                    add.get("isolation.server_start", 0.0) + float(extra["server_start_seconds"]), 4)
        if add:
            row.stage_seconds = json.dumps({**json.loads(row.stage_seconds or "{}"), **add}, sort_keys=True)
        if published_status == "ok" and isinstance(published.value.get("clips"), list):
            row.clips = json.dumps(published.value["clips"])  # read in the worker: the row's out_dir is the store's
        self.store.append_row(job.dataset, job.run_id, row)
        emit_finished(job.dataset, job.run_id, row)
        self.log.info("%s: %s (%s) in %.1f s", job.asset_id, row.status, row.failure_mode, row.wall_seconds or 0.0)


def emit_finished(dataset: str, run_id: str, row) -> None:
    """The progress event of an asset whose row was written."""
    flow_progress.emit(ProgressEvent("asset_finished", dataset, run_id, asset_id=row.asset_id,
                                     status=row.status, failure_mode=row.failure_mode, seconds=row.wall_seconds))


def _run_assets(prep_futures: dict, chain_task, rec: _AssetRecorder, fingerprints: dict[str, str | None]) -> None:
    """Record every asset's row as soon as what ends it has ended, prepares and chains alike, in the order they
    finish (one queue fed by the futures' done callbacks: ``PrefectFuture.add_done_callback``): as a prepare batch
    ends, its input index entries and the rows of the assets that end there (failed, skipped, invalid), and the
    ``refine-metrics`` chain of each other one submitted; as a chain ends, its asset's row. No row waits for the
    prepares of other assets (its ``finished_at``, its progress event and its log line come when its chain ends)."""
    finished: queue.SimpleQueue = queue.SimpleQueue()
    chains: dict = {}
    for fut in prep_futures:
        fut.add_done_callback(finished.put)
    while prep_futures or chains:  # a chain joins the queue as it is submitted
        fut = finished.get()
        if fut in chains:
            job, prepared = chains.pop(fut)  # the asset's chain ended
            res, exc = _outcome(fut)
            if exc is not None:
                rec.record(job, prepared, None, None, exc)
            else:
                rec.record(job, prepared, res.refined, res.measured, res.error, res.published)
            continue
        results, exc_b = _outcome(fut)  # a prepare batch ended
        for k, job in enumerate(prep_futures.pop(fut)):
            # the batch's exception, else the job's record or exception
            prepared = exc_b or results[k]
            if isinstance(prepared, BaseException):
                rec.record(job, None, None, None, prepared)
                continue
            if (entry := driver_skip.entry_for(job, prepared, fingerprints.get(job.asset_id))) is not None:
                rec.inputs[job.asset_id] = entry
            if prepared is None or prepared.skip is not None or not prepared.ok:
                rec.record(job, prepared, None, None, None)
                continue
            # a killed run's complete folder (prepared.resume): refine reads its report, metrics its evaluation; the
            # time limit of a non-isolated stage is Prefect's (process isolation has its own)
            limit = {} if job.isolation in ("process", "spawn") else {"timeout_seconds": job.time_limit_seconds}
            cf = chain_task.with_options(**limit).submit(Sealed(job), Sealed(prepared))
            chains[cf] = job, prepared
            cf.add_done_callback(finished.put)


def _ready_stage_servers(jobs: list[AssetJob], log) -> float:
    """Start every Dask worker's stage server before the first asset (a failure is logged); returns the seconds
    waited (0 without stage servers or a Dask runner)."""
    from prefect_dask import DaskTaskRunner

    mods = tuple(dict.fromkeys(m for j in jobs for m in stages.stage_server_modules(j)))
    runner = getattr(FlowRunContext.get(), "task_runner", None)
    if not mods or not isinstance(runner, DaskTaskRunner):
        return 0.0
    t0 = time.perf_counter()
    try:
        runner.client.run(ready_server, mods)
    except (RuntimeError, OSError, TimeoutError) as exc:
        log.warning("stage servers not started before the first asset: %s: %s", type(exc).__name__, exc)
    return time.perf_counter() - t0
