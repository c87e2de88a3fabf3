"""The refine flow's per-asset stages as plain functions (no Prefect here).

``flows.refine_flow`` wraps them in Prefect tasks; each is a plain, typed,
testable function:

- :func:`plan_run` (:func:`plan_jobs`): ``catalog.yaml`` and the manifest ->
  one :class:`AssetJob` per usable manifest row, one :class:`BadManifestRow`
  per row that cannot be used (recorded as a failed catalog row, the others
  run), and per asset the job records of earlier runs that wrote no catalog
  row for it (a killed flow's finished work, :func:`unrecorded_jobs`);
- :func:`prepare_asset` (input stage): read (validate and extract) the asset,
  once, for its input hash and the skip decision
  (:func:`asset2sim.tasks.publish.contract.finished_result`), or find a
  complete folder of a killed run to record instead of refining
  (:func:`asset2sim.tasks.publish.contract.resumable_output`); the extracted
  description and its findings travel on in the
  :class:`~asset2sim.tasks.publish.contract.Prepared` record;
- :func:`refine_stage`: the refine function (``tasks.refine.refine_asset``:
  synthesize, refine state, write, post-check, extras) in an isolated child
  process inside the asset's time limit, given the extracted asset (as JSON
  across the process boundary) and the reference for the extras' evaluation;
- :func:`metrics_stage`: the catalog's metric columns. When refine's extras
  wrote ``evaluation.json`` for this prompt, category and reference
  (:func:`refined_evaluation`), that typed Evaluation is read; otherwise
  (extras off, or a refine function that writes none) the stability metrics
  are evaluated (``tasks.evaluation.evaluate``), recording the post-check's
  rest-test measurement instead of running it again when the engine and
  conventions match (:func:`reusable_rest_test`).

Each stage returns a :class:`~asset2sim.tasks.publish.contract.StageRecord`;
:func:`asset2sim.tasks.publish.contract.build_row` turns them into the
asset's catalog row. Nothing here imports Prefect, Dask or MLflow.
"""

from __future__ import annotations

import os
import socket
import time
import uuid
from dataclasses import asdict, dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

from asset2sim import __version__, array_cache, atomic
from asset2sim.flows.catalog import (
    Catalog,
    CatalogError,
    ManifestEntry,
    ResultCatalog,
    read_manifest_entries,
    result_key,
)
from asset2sim.demo_assets import ensure_demo_dataset
from asset2sim.flows import store as store_mod
from asset2sim.flows.forkserver import run_forked, start_soon
from asset2sim.flows.isolation import call_target, import_target, run_isolated
from asset2sim.schemas.asset import AssetDescription
from asset2sim.schemas.config import RefineConfig, SimConventions
from asset2sim.schemas.metrics import REST_TEST_METRICS, column_values
from asset2sim.schemas.report import MetricResult, RefineReport
from asset2sim.tasks.evaluation.evaluate import Evaluation, evaluate_asset
from asset2sim.tasks.ingest import partnet_mobility
from asset2sim.tasks.ingest.extract import extract_asset_checked
from asset2sim.tasks.ingest.partnet_mobility import ManifestRowError
from asset2sim.tasks.ingest.validate_input import Finding
from asset2sim.tasks.publish.contract import (
    JOB_RECORD_NAME,
    JobRecord,
    Measurement,
    Prepared,
    RefineOutput,
    StageRecord,
    finished_result,
    flow_config_hash,
    manifest_row_id,
    refined_output,
    report_tokens,
    resumable_output,
    run_hash,
    skip_code_hash,
    write_job_record,
)
from asset2sim.tasks.publish.contract import code_version as contract_code_version
from asset2sim.output_folder import EVALUATION_NAME

FLOW_NAME = "refine-dataset"
SUBFLOW_NAME = "refine-assets"
#: Per run, ``<output_root>/<dataset>/<run>/_metrics/<asset id>/evaluation.json``
#: holds the metrics stage's measurement (beside, not inside, the refined folder).
METRICS_DIRNAME = "_metrics"
DEFAULT_REFINE_FUNCTION = "asset2sim.tasks.refine:refine_asset"

#: Failure modes a retry cannot fix are recorded at once; this one is retried
#: when the estimator calls a model.
RETRYABLE_FAILURE = "estimator_failure"


class ModelCallFailure(RuntimeError):
    """A model-backed estimator failed (the only failure Prefect retries)."""

    failure_mode = RETRYABLE_FAILURE


class RegressionFailure(RuntimeError):
    """The run regressed beyond ``catalog.yaml`` ``results.regression`` with
    ``fail_flow`` on: raised at the very end of the flow (everything is
    recorded by then), so the flow run's state, the nightly deployment's
    included, is Failed with the regression report as its message.
    ``summary``: the run summary the flow would have returned."""

    def __init__(self, report: str, summary: dict[str, Any]):
        super().__init__(report)
        self.summary = summary


# ----------------------------------------------------------------------------- jobs


@dataclass
class AssetJob:
    """Everything one asset's task chain needs (JSON-able, shipped to workers).

    Paths absolute (``out_dir`` the refined folder, ``metrics_dir`` the metrics
    stage's ``evaluation.json``, ``work_dir`` scratch of isolated stages); ``time_limit_seconds`` s over all stages of the asset;
    ``config`` the :class:`~asset2sim.schemas.config.RefineConfig` as a dict;
    ``finished`` the catalog rows of earlier finished runs keyed by
    :func:`asset2sim.flows.catalog.result_key` for this asset (empty when forced);
    ``resumable`` the job records (:class:`~asset2sim.tasks.publish.contract.JobRecord`
    dicts, newest first) of earlier runs that wrote no catalog row for this
    asset (empty when forced). With an output store (:mod:`asset2sim.flows.store`)
    ``out_dir`` / ``metrics_dir`` / ``work_dir`` are local temporary folders
    of the worker and ``out_uri`` / ``metrics_uri`` where the publish stage
    uploads them (None: the outputs stay in ``out_dir``).
    """

    dataset: str
    run_id: str
    asset_id: str
    prompt: str
    asset_dir: str
    out_dir: str
    work_dir: str
    metrics_dir: str
    category: str | None = None
    reference_scale: float | None = None
    reference_dir: str | None = None
    config: dict[str, Any] = field(default_factory=dict)
    refine_function: str = DEFAULT_REFINE_FUNCTION
    evaluate: bool = True
    probes: bool = False
    extras: bool = True
    isolation: str = "process"
    time_limit_seconds: float = 1800.0
    memory_limit_mb: int | None = 8192
    finished: dict[str, dict[str, Any]] = field(default_factory=dict)
    resumable: list[dict[str, Any]] = field(default_factory=list)
    code_version: str = __version__
    out_uri: str | None = None
    metrics_uri: str | None = None


@dataclass
class BadManifestRow:
    """A manifest row of a run that cannot be used: ``asset_id`` its catalog
    id (:func:`asset2sim.tasks.publish.contract.manifest_row_id`), ``error``
    the reader's typed error (line, id as written, code, message)."""

    asset_id: str
    error: ManifestRowError


@dataclass
class RunPlan:
    """What a run works on: ``jobs`` (usable manifest rows) and ``bad_rows``
    (rows recorded as failed without running), each in manifest order."""

    jobs: list[AssetJob]
    bad_rows: list[BadManifestRow] = field(default_factory=list)


def code_version() -> str:
    """The code that produced a result (:func:`asset2sim.tasks.publish.contract.code_version`:
    the package version plus the git commit, or the hash of the package source)."""
    return contract_code_version()


def make_run_id(now: datetime | None = None) -> str:
    """A run id that sorts chronologically: ``YYYYmmddTHHMMSSZ-xxxxxx`` (UTC)."""
    now = now or datetime.now(timezone.utc)
    return now.strftime("%Y%m%dT%H%M%SZ") + "-" + uuid.uuid4().hex[:6]


def flow_parameters(
    catalog: str | Path = "catalog.yaml",
    dataset: str | None = None,
    workers: int | None = None,
    dask_address: str | None = None,
    out: str | None = None,
) -> dict[str, Any]:
    """The parameters ``make flow`` passes to :data:`refine_dataset` (and the
    nightly deployment stores): the catalog as an absolute path, the dataset,
    workers, Dask scheduler address and output store (None = catalog/environment
    defaults; ``out`` only when given)."""
    params = {
        "catalog": str(Path(catalog).expanduser().resolve()),
        "dataset": dataset,
        "workers": workers,
        "dask_address": dask_address,
    }
    if out:
        params["out"] = out
    return params


def plan_jobs(cat: Catalog, dataset: str, run_id: str, *, ids: list[str] | None = None, limit: int | None = None,
              force: bool = False) -> list[AssetJob]:
    """The jobs of a run (:func:`plan_run` without the manifest's bad rows).

    Raises:
        CatalogError: as :func:`plan_run`.
    """
    return plan_run(cat, dataset, run_id, ids=ids, limit=limit, force=force).jobs


def plan_run(
    cat: Catalog,
    dataset: str,
    run_id: str,
    *,
    ids: list[str] | None = None,
    limit: int | None = None,
    force: bool = False,
    out_store: str | None = None,
) -> RunPlan:
    """The work of a run: one job per usable manifest row and one
    :class:`BadManifestRow` per row that cannot be used (optionally only
    ``ids``, at most ``limit`` rows of both kinds in manifest order), with
    earlier finished results and unrecorded finished work for the skip
    decision (none when ``force``). ``out_store``: publish the outputs there
    (:mod:`asset2sim.flows.store`; default ``catalog.yaml`` ``output_store``);
    with a store, the work of a killed run that wrote no catalog row is not
    looked for (it is redone; its folder in the store has no row pointing at it).

    Generates the demo assets first when the dataset says ``generate: demo``
    and they are missing or outdated.

    Raises:
        CatalogError: a manifest that is missing, not UTF-8 text or without
            ``id`` / ``prompt`` column; an unknown dataset; an id in ``ids``
            that no manifest row has.
    """
    name, ds = cat.dataset(dataset)
    root = cat.dataset_root(name)
    if ds.generate == "demo":
        ensure_demo_dataset(root)
    entries, errors = read_manifest_entries(cat.manifest_path(name), root)
    taken = {e.asset_id for e in entries}
    bad = [BadManifestRow(manifest_row_id(err, taken), err) for err in errors]
    ordered: list[ManifestEntry | BadManifestRow] = sorted([*entries, *bad], key=_manifest_line)  # file order
    if ids:
        known = {e.asset_id for e in entries} | {b.asset_id for b in bad} | {b.error.id for b in bad if b.error.id}
        unknown = [i for i in ids if i not in known]
        if unknown:
            raise CatalogError(f"{cat.manifest_path(name)}: unknown id(s) {unknown}")
        wanted = set(ids)
        ordered = [it for it in ordered if it.asset_id in wanted or (isinstance(it, BadManifestRow) and it.error.id in wanted)]
    if limit is not None:
        ordered = ordered[: max(0, int(limit))]
    settings = cat.config.run
    config = cat.refine_config().model_dump(mode="json")
    finished = {} if force else ResultCatalog(cat.catalog_root).finished(
        name, code_hash=skip_code_hash(cat.config.results.code_change))
    store = out_store or cat.output_store
    unrecorded = {} if force or store else unrecorded_jobs(cat, name, run_id)
    run_out = (store_mod.local_work_root() if store else cat.output_root) / name / run_id
    version = code_version()
    jobs = []
    for e in ordered:
        if isinstance(e, BadManifestRow):
            continue
        ref_dir = None
        if ds.reference and partnet_mobility.has_reference(e.asset_dir):
            ref_dir = str(e.asset_dir)
        jobs.append(
            AssetJob(
                dataset=name,
                run_id=run_id,
                asset_id=e.asset_id,
                prompt=e.prompt,
                asset_dir=str(e.asset_dir),
                out_dir=str(run_out / e.asset_id),
                work_dir=str(run_out / ".work" / e.asset_id),
                metrics_dir=str(run_out / METRICS_DIRNAME / e.asset_id),
                category=e.category,
                reference_scale=e.reference_scale,
                reference_dir=ref_dir,
                config=config,
                refine_function=settings.refine_function,
                evaluate=settings.evaluate,
                probes=settings.probes,
                extras=settings.extras,
                isolation=settings.isolation,
                time_limit_seconds=e.time_limit_seconds or settings.time_limit_seconds,
                memory_limit_mb=settings.memory_limit_mb,
                finished={k: v for k, v in finished.items() if k.startswith(e.asset_id + "|")},
                resumable=unrecorded.get(e.asset_id, []),
                code_version=version,
                out_uri=store_mod.join_uri(store, name, run_id, e.asset_id) if store else None,
                metrics_uri=store_mod.join_uri(store, name, run_id, METRICS_DIRNAME, e.asset_id) if store else None,
            )
        )
    return RunPlan(jobs=jobs, bad_rows=[b for b in ordered if isinstance(b, BadManifestRow)])


def _manifest_line(item: ManifestEntry | BadManifestRow) -> int:
    return item.error.line if isinstance(item, BadManifestRow) else (item.line or 0)


def unrecorded_jobs(cat: Catalog, dataset: str, run_id: str | None = None) -> dict[str, list[dict[str, Any]]]:
    """Per asset id, the job records (:class:`~asset2sim.tasks.publish.contract.JobRecord`
    dicts, newest run first) that earlier runs of ``dataset`` (all but
    ``run_id``) left in their work folders without writing the asset's
    catalog row: work of a flow killed between finishing an asset and
    recording it. Lists two folders per run (outputs' ``.work`` and the
    catalog partition) and reads only the records of unrecorded assets."""
    store = ResultCatalog(cat.catalog_root)
    base = cat.output_root / dataset
    out: dict[str, list[dict[str, Any]]] = {}
    try:
        runs = sorted((p.name for p in base.iterdir() if p.is_dir() and p.name != run_id), reverse=True)
    except OSError:
        return out
    for run in runs:
        work = base / run / ".work"
        if not work.is_dir():
            continue
        try:
            recorded = store.recorded_assets(dataset, run)  # row files and the compacted file
        except ValueError:  # not a run id the catalog could hold
            continue
        for folder in sorted(work.iterdir()):
            if folder.name in recorded or not (folder / JOB_RECORD_NAME).is_file():
                continue
            try:
                rec = JobRecord.model_validate_json((folder / JOB_RECORD_NAME).read_text())
            except (OSError, ValueError):
                continue
            if rec.job.get("asset_id") == folder.name and rec.job.get("run_id") == run:
                out.setdefault(folder.name, []).append(rec.model_dump(mode="json"))
    return out


# --------------------------------------------------------------------------- stages


def _worker_name() -> str:
    return f"{socket.gethostname()}:{os.getpid()}"


def job_config_hash(job: AssetJob, refine_hash: str) -> str:
    """The catalog configuration hash of ``job``'s result
    (:func:`asset2sim.tasks.publish.contract.flow_config_hash` of its settings)."""
    return flow_config_hash(
        refine_hash,
        refine_function=job.refine_function,
        evaluate=job.evaluate,
        probes=job.probes,
        extras=job.extras,
        reference=bool(job.reference_dir),
        reference_scale=job.reference_scale,
    )


def finished_in_store(row: dict[str, Any] | None, input_hash: str) -> dict[str, Any] | None:
    """The skip rule (:func:`asset2sim.tasks.publish.contract.finished_result`)
    for a row whose output is a local folder or a folder in an output store
    (:func:`asset2sim.flows.store.store_complete`, read from the store)."""
    if row is not None and store_mod.is_store_uri(row.get("out_dir")):
        return row if store_mod.store_complete(row["out_dir"], input_hash, row.get("refine_config_hash") or "") else None
    return finished_result(row, input_hash)


def publish_stage(job: AssetJob, refined: StageRecord, measured: StageRecord | None = None) -> StageRecord:
    """Publish stage: with an output store (``job.out_uri``), upload the
    refined folder (completion marker last) and the metrics folder, then
    delete the worker's local copies; ``skipped`` without a store or without
    an output. ``value``: ``{"out_uri", "files", "bytes"}``.

    Never raises for a store that refuses the upload: status ``error`` with
    the reason (the asset's row is then failed)."""
    if job.out_uri is None or refined is None or refined.status != "ok":
        return StageRecord(status="skipped", seconds=0.0)
    t0 = time.perf_counter()
    value: RefineOutput = refined.value
    local = value.out_dir or job.out_dir
    try:
        up = store_mod.upload_folder(local, job.out_uri)
        if job.metrics_uri and Path(job.metrics_dir).is_dir():
            store_mod.upload_folder(job.metrics_dir, job.metrics_uri)
    except (OSError, ValueError) as exc:
        return StageRecord(status="error", error=f"upload of {local} to {job.out_uri} failed: {type(exc).__name__}: {exc}",
                           error_type=type(exc).__name__, failure_mode="crash", seconds=time.perf_counter() - t0,
                           worker=_worker_name())
    for folder in (local, job.metrics_dir, job.work_dir):
        store_mod.remove_local(folder)
    return StageRecord(status="ok", value={"out_uri": job.out_uri, "files": up["files"], "bytes": up["bytes"]},
                       seconds=time.perf_counter() - t0, worker=_worker_name())


def stage_server_modules(job: AssetJob) -> tuple[str, ...]:
    """The modules a job's stage server imports before it forks (these stage
    functions, which its forked children run, and the job's refine
    function's), or () when the job does not run isolated in one."""
    return (__name__, job.refine_function.split(":", 1)[0]) if job.isolation == "process" else ()


def prepare_batch(jobs: list[AssetJob]) -> list[Prepared | Exception]:
    """:func:`prepare_asset` for several jobs in one call (one task of the
    flow's task runner instead of one per asset: a rerun of finished assets
    pays the orchestration once per batch). An exception of one job is its
    item of the list; the others go on. Starts this worker's stage server
    in the background meanwhile when the jobs run isolated in it."""
    for job in jobs[:1]:
        if modules := stage_server_modules(job):
            start_soon(modules)
    out: list[Prepared | Exception] = []
    for job in jobs:
        try:
            out.append(prepare_asset(job))
        except Exception as exc:  # recorded in that asset's row
            out.append(exc)
    return out


@dataclass
class ChainResult:
    """The stage records of one asset's chain after prepare: ``refined``,
    ``measured`` (None when metrics raised), ``published`` (None without an
    output store) and ``error`` the exception that stopped metrics or publish."""

    refined: StageRecord
    measured: StageRecord | None = None
    published: StageRecord | None = None
    error: Exception | None = None


def refine_chain(job: AssetJob, prepared: Prepared) -> ChainResult:
    """refine -> metrics -> publish of one asset in one call (one task of
    the flow: the orchestration's cost is paid once per asset, not per stage).

    Raises:
        ModelCallFailure: from the refine stage (the flow retries the chain).
    """
    refined = refine_stage(job, prepared)
    res = ChainResult(refined=refined)
    try:
        res.measured = metrics_stage(job, prepared, refined)
        if job.out_uri:
            res.published = publish_stage(job, refined, res.measured)
    except Exception as exc:  # recorded in the row, like a failed stage
        res.error = exc
    return res


def prepare_asset(job: AssetJob) -> Prepared:
    """Input stage: validate and read the asset, hash input and
    configuration, decide whether an earlier result can be reused.

    When no catalog row allows a skip, an earlier run's complete folder for
    the same input and flow configuration that has no catalog row (a killed
    flow's finished work, ``job.resumable``) is taken instead
    (``resume``). Otherwise the job record is written into ``job.work_dir``
    (:data:`~asset2sim.tasks.publish.contract.JOB_RECORD_NAME`) before the
    refine stage, so a later run can find this run's finished folder.

    Returns:
        The :class:`~asset2sim.tasks.publish.contract.Prepared` record with
        the extracted description and its validation findings (``ok`` False
        with ``failure_mode`` ``invalid_input`` and ``error`` for an asset
        that cannot be read). Never raises for a bad asset.

    Raises:
        OSError: the job record cannot be written.
    """
    t0 = time.perf_counter()
    rec = Prepared(worker=_worker_name())
    try:
        asset, findings = extract_asset_checked(Path(job.asset_dir), asset_id=job.asset_id, category=job.category)
    except Exception as exc:  # any reading problem is the input's
        rec.failure_mode, rec.error, rec.seconds = "invalid_input", f"{type(exc).__name__}: {exc}", time.perf_counter() - t0
        return rec
    rhash = run_hash(asset.input_hash, RefineConfig(**job.config), job.prompt, job.category)
    chash = job_config_hash(job, rhash)
    rec.ok = True
    rec.input_hash, rec.config_hash, rec.refine_config_hash = asset.input_hash, chash, rhash
    rec.category = job.category or asset.category
    rec.links, rec.movable_joints = len(asset.links), len(asset.movable_joints())
    rec.skip = finished_in_store(job.finished.get(result_key(job.asset_id, asset.input_hash, chash)), asset.input_hash)
    if rec.skip is None:
        found = resumable_output(job.resumable, asset.input_hash, chash, rhash)
        rec.resume = None if found is None else found.model_dump(mode="json")
    if rec.skip is None and rec.resume is None:
        rec.asset, rec.findings = asset, list(findings)
        job_fields = {k: v for k, v in asdict(job).items() if k not in ("finished", "resumable")}
        write_job_record(job.work_dir, JobRecord(job=job_fields, input_hash=asset.input_hash, config_hash=chash,
                                                 refine_config_hash=rhash))
    rec.seconds = time.perf_counter() - t0
    return rec


def stage_refine(
    asset_dir: str,
    prompt: str,
    out_dir: str,
    config: dict[str, Any],
    category: str | None,
    asset_id: str,
    refine_function: str = DEFAULT_REFINE_FUNCTION,
    extras: bool = True,
    extracted: dict[str, Any] | None = None,
    reference_dir: str | None = None,
) -> dict[str, Any]:
    """Run the refine function on one asset (in whichever process calls it).

    ``extracted``: the prepare stage's reading of the asset as JSON
    (``{"asset": AssetDescription, "findings": [Finding, ...]}``), handed to
    a refine function that takes ``extracted`` so it does not read the asset
    again; ``reference_dir``: the reference folder for its extras'
    evaluation (a refine function that takes ``reference``).

    Returns:
        A :class:`~asset2sim.tasks.publish.contract.RefineOutput` as JSON
        (it crosses the isolation boundary as JSON).

    Raises:
        Whatever the refine function raises (``RefineError`` carries
        ``failure_mode``).
    """
    import inspect

    fn = import_target(refine_function)
    t0 = time.perf_counter()
    progress: list[list[Any]] = []

    def say(stage: str, message: str) -> None:
        progress.append([stage, message, round(time.perf_counter() - t0, 3)])

    kwargs: dict[str, Any] = {"category": category, "progress": say}
    params = inspect.signature(fn).parameters
    if "asset_id" in params:
        kwargs["asset_id"] = asset_id
    if "extras" in params:
        kwargs["extras"] = extras
    if extracted is not None and "extracted" in params:
        kwargs["extracted"] = (
            AssetDescription.model_validate(extracted["asset"]),
            [Finding.model_validate(f) for f in extracted["findings"]],
        )
    if reference_dir is not None and "reference" in params:
        kwargs["reference"] = Path(reference_dir)
    result = fn(Path(asset_dir), prompt, Path(out_dir), RefineConfig(**config), **kwargs)
    report = RefineReport.model_validate(result.report.model_dump(mode="json"))
    out = RefineOutput(
        report=report,
        out_dir=str(result.out_dir),
        skipped=bool(getattr(result, "skipped", False)),
        progress=progress,
        tokens=report_tokens(report, Path(result.out_dir)),
    )
    return out.model_dump(mode="json")


def reusable_rest_test(report: RefineReport, config: dict[str, Any], engine: str = "pybullet") -> list[MetricResult] | None:
    """The post-check's rest-test measurement in ``engine``
    (:data:`asset2sim.schemas.metrics.REST_TEST_METRICS`) when the metrics
    stage may record it instead of measuring again: the refine run used the
    SPEC conventions the evaluation uses, and every rest-test metric of
    ``engine`` is in the report. None otherwise."""
    if RefineConfig(**config).sim != SimConventions():
        return None
    found = {m.name: m for m in report.metrics if m.engine == engine and m.name in REST_TEST_METRICS}
    if set(found) != set(REST_TEST_METRICS):
        return None
    return [found[n] for n in REST_TEST_METRICS]


def refined_evaluation(out_dir: str | Path, prompt: str, category: str | None, reference_dir: str | None) -> Evaluation | None:
    """The typed :class:`~asset2sim.tasks.evaluation.evaluate.Evaluation`
    refine's extras wrote into the refined folder (``evaluation.json``), when
    it is the evaluation the metrics stage would make: PyBullet only, the
    same prompt, category and reference (resolved path, or none). It then
    holds every metric of the catalog row, the rest-test ones measured by
    the post-check. None otherwise (no file, unreadable, another request or
    reference)."""
    try:
        ev = Evaluation.model_validate_json((Path(out_dir) / EVALUATION_NAME).read_text())
    except (OSError, ValueError):
        return None
    ref = str(Path(reference_dir).resolve()) if reference_dir else None
    if ev.engines != ["pybullet"] or ev.prompt != (prompt or None) or ev.category != category or ev.reference != ref:
        return None
    return ev


def measurement_from_refine(out_dir: str, prompt: str, category: str | None, reference_dir: str | None,
                            metrics_dir: str | None) -> Measurement | None:
    """The metrics stage's measurement from refine's evaluation
    (:func:`refined_evaluation`), copied into ``metrics_dir`` when given;
    None when there is none to reuse. Reads and copies a file only."""
    t0 = time.perf_counter()
    ev = refined_evaluation(out_dir, prompt, category, reference_dir)
    if ev is None:
        return None
    if metrics_dir:
        atomic.copy_file(Path(out_dir) / EVALUATION_NAME, Path(metrics_dir) / EVALUATION_NAME)
    return _measurement(ev, time.perf_counter() - t0, reused_post_check=True, reused_evaluation=True)


def _measurement(ev: Evaluation, seconds: float, **flags: bool) -> Measurement:
    """The catalog's PyBullet metric columns and the failures of ``ev``, measured in ``seconds`` s."""
    return Measurement(columns=column_values(ev.metrics, "pybullet"), failures=list(ev.failures), seconds=seconds, **flags)


def stage_metrics(
    out_dir: str,
    prompt: str,
    category: str | None,
    reference_dir: str | None = None,
    probes: bool = False,
    metrics_dir: str | None = None,
    post_check: list[dict[str, Any]] | None = None,
) -> dict[str, Any]:
    """Stability metrics of a refined asset (``asset2sim.tasks.evaluation.evaluate``,
    PyBullet, SPEC conventions); writes ``evaluation.json`` into
    ``metrics_dir`` when given. The refined folder itself is never touched
    (its completion marker covers every file in it).

    When refine's extras already evaluated the folder for this prompt,
    category and reference (:func:`refined_evaluation`), that evaluation is
    read and copied to ``metrics_dir``: nothing is simulated here.
    Otherwise the asset is evaluated; ``post_check``: the post-check's
    rest-test metrics (JSON of :class:`~asset2sim.schemas.report.MetricResult`,
    :func:`reusable_rest_test`), recorded instead of running the rest test again.

    Returns:
        A :class:`~asset2sim.tasks.publish.contract.Measurement` as JSON:
        the catalog's metric columns (``penetration_mm`` mm, ``rest_stable``,
        ``d_pos_m`` m, ``d_ori_rad`` rad, ``oscillation_pass``,
        ``prompt_alignment`` 0..1, ``scale_deviation_pct`` %), failures, seconds.

    Raises:
        EvaluationError: the output cannot be read.
    """
    reused = measurement_from_refine(out_dir, prompt, category, reference_dir, metrics_dir)
    if reused is not None:
        return reused.model_dump(mode="json")
    measured = None if post_check is None else [MetricResult.model_validate(m) for m in post_check]
    with array_cache.guard(out_dir, reference_dir, metrics_dir):  # no cache entry in the refined folder or the reference
        ev = evaluate_asset(
            Path(out_dir),
            reference=Path(reference_dir) if reference_dir else None,
            prompt=prompt,
            engines=("pybullet",),
            category=category,
            out_dir=Path(metrics_dir) if metrics_dir else None,
            write_report=False,
            probes=probes,
            measured=measured,
        )
    return _measurement(ev, float(ev.seconds), reused_post_check=measured is not None).model_dump(mode="json")


def _run_stage(job: AssetJob, name: str, target: str, kwargs: dict[str, Any], timeout: float) -> StageRecord:
    """Run a stage function per the job's isolation; a uniform record
    (``status`` ok/error/timeout/crash, ``value`` the JSON it returned)."""
    t0 = time.perf_counter()
    if timeout <= 0:
        return StageRecord(status="timeout", error=f"no time left for stage {name}", failure_mode="timeout", seconds=0.0)
    if job.isolation == "process":  # a child forked from this worker's pre-imported stage server
        rec = asdict(run_forked(target, kwargs, timeout=timeout, workdir=Path(job.work_dir) / name,
                                memory_limit_mb=job.memory_limit_mb, preload=stage_server_modules(job)))
    elif job.isolation == "spawn":  # a fresh interpreter per call (imports paid every time)
        rec = asdict(run_isolated(target, kwargs, timeout=timeout, workdir=Path(job.work_dir) / name,
                                  memory_limit_mb=job.memory_limit_mb))
    else:
        out = call_target(target, kwargs)
        rec = {"status": "ok" if out["ok"] else "error", **out}
    rec["seconds"] = time.perf_counter() - t0
    return StageRecord.model_validate(rec)


def refine_stage(job: AssetJob, prepared: Prepared) -> StageRecord:
    """Refine stage: synthesize, refine state, write and post-check one asset
    (the refine function), inside the asset's time limit.

    With ``prepared.resume`` (an earlier run's complete folder) nothing is
    refined: the value is read from that folder's ``report.json``
    (:func:`~asset2sim.tasks.publish.contract.refined_output`), ``seconds``
    the refine time its report records.

    Returns:
        The stage record, ``value`` a :class:`~asset2sim.tasks.publish.contract.RefineOutput`;
        ``skipped`` when ``prepared`` says so or the asset was invalid.

    Raises:
        ModelCallFailure: a model-backed estimator failed (Prefect retries it).
    """
    if not prepared.ok or prepared.skip is not None:
        return StageRecord(status="skipped", seconds=0.0)
    if prepared.resume is not None:
        out_dir = prepared.resume["job"]["out_dir"]
        try:
            value = refined_output(out_dir)
        except (OSError, ValueError) as exc:
            return StageRecord(status="error", error=f"{out_dir}: cannot read the finished report: {exc}",
                               error_type=type(exc).__name__, seconds=0.0, worker=_worker_name())
        return StageRecord(status="ok", value=value, worker=_worker_name(),
                           seconds=float(sum(value.report.stage_seconds.values())))
    budget = job.time_limit_seconds - float(prepared.seconds or 0.0)
    rec = _run_stage(
        job,
        "refine",
        "asset2sim.flows.stages:stage_refine",
        {
            "asset_dir": job.asset_dir,
            "prompt": job.prompt,
            "out_dir": job.out_dir,
            "config": job.config,
            "category": job.category,
            "asset_id": job.asset_id,
            "refine_function": job.refine_function,
            "extras": job.extras,
            "extracted": None if prepared.asset is None else {
                "asset": prepared.asset.model_dump(mode="json"),
                "findings": [f.model_dump(mode="json") for f in prepared.findings],
            },
            "reference_dir": job.reference_dir,
        },
        budget,
    )
    rec.worker = _worker_name()
    if rec.status == "ok":
        rec.value = RefineOutput.model_validate(rec.value)
    if rec.failure_mode == RETRYABLE_FAILURE and str(job.config.get("estimator", "offline")) != "offline":
        raise ModelCallFailure(f"{job.asset_id}: estimator {job.config.get('estimator')!r} failed: {rec.error}")
    return rec


def metrics_stage(job: AssetJob, prepared: Prepared, refined: StageRecord) -> StageRecord:
    """Metrics stage: the metric columns of the refined output, inside what
    is left of the asset's time limit: read from refine's evaluation when it
    matches (:func:`refined_evaluation`), else evaluated, recording the
    post-check's rest test when :func:`reusable_rest_test` allows.
    ``skipped`` when there is no output or ``job.evaluate`` is off. For an
    earlier run's folder (``prepared.resume``) that run's metrics folder is
    used: its ``evaluation.json`` when the metrics stage had written it."""
    if refined.status != "ok" or not job.evaluate:
        return StageRecord(status="skipped", seconds=0.0)
    value: RefineOutput = refined.value
    category = value.report.category or job.category
    metrics_dir = job.metrics_dir
    if prepared.resume is not None:  # the earlier run's measurement, when it made one
        metrics_dir = prepared.resume["job"]["metrics_dir"]
        ev = refined_evaluation(metrics_dir, job.prompt, category, job.reference_dir)
        if ev is not None:
            earlier = _measurement(ev, float(ev.seconds))
            return StageRecord(status="ok", value=earlier, seconds=earlier.seconds)
    reused = measurement_from_refine(value.out_dir or job.out_dir, job.prompt, category, job.reference_dir, metrics_dir)
    if reused is not None:  # nothing to simulate: no child process needed
        return StageRecord(status="ok", value=reused, seconds=reused.seconds)
    budget = job.time_limit_seconds - float(prepared.seconds or 0.0) - float(refined.seconds or 0.0)
    post = reusable_rest_test(value.report, job.config)
    rec = _run_stage(
        job,
        "metrics",
        "asset2sim.flows.stages:stage_metrics",
        {
            "out_dir": value.out_dir or job.out_dir,
            "prompt": job.prompt,
            "category": category,
            "reference_dir": job.reference_dir,
            "probes": job.probes,
            "metrics_dir": metrics_dir,
            "post_check": None if post is None else [m.model_dump(mode="json") for m in post],
        },
        budget,
    )
    if rec.status == "ok":
        rec.value = Measurement.model_validate(rec.value)
    return rec


# ------------------------------------------------------------------------- Prefect env


def default_prefect_home(project_root: Path | str) -> Path:
    """Where the CLI keeps Prefect's local state (``<project>/.prefect``), so
    runs of this project do not share a SQLite database with other projects."""
    return Path(project_root) / ".prefect"


def prepare_prefect_environment(project_root: Path | str) -> dict[str, str]:
    """Environment defaults for Prefect, to apply *before* Prefect is imported:
    ``PREFECT_HOME`` under the project, analytics off, a longer start-up
    timeout of the temporary server. Existing variables win. Returns what was set."""
    defaults = {
        "PREFECT_HOME": str(default_prefect_home(project_root)),
        "PREFECT_SERVER_ANALYTICS_ENABLED": "false",
        "DO_NOT_TRACK": "1",
        # a first start migrates a fresh SQLite database: slower than Prefect's 20 s on a busy machine
        "PREFECT_SERVER_EPHEMERAL_STARTUP_TIMEOUT_SECONDS": "180",
    }
    set_now = {}
    for k, v in defaults.items():
        if k not in os.environ:
            os.environ[k] = v
            set_now[k] = v
    return set_now
