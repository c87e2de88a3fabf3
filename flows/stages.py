"""The refine flow's per-asset stages as plain functions (no Prefect, Dask or
MLflow here): :func:`~asset2sim.flows.run_plan.plan_run`, then per asset :func:`prepare_asset`,
:func:`refine_stage`, :func:`metrics_stage` and :func:`publish_stage`, each
returning a :class:`~asset2sim.flows.job_records.StageRecord`.
"""

from __future__ import annotations

import os
import shutil
import socket
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from asset2sim import __version__, array_cache, atomic, output_folder
from asset2sim.flows.catalog import result_key
from asset2sim.flows import server, store as store_mod
from asset2sim.flows.forkserver import run_forked, start_soon
from asset2sim.flows.isolation import call_target, import_target, run_isolated
from asset2sim.schemas.asset import AssetDescription
from asset2sim.schemas.config import RefineConfig
from asset2sim.schemas.metrics import column_values
from asset2sim.schemas.report import RefineReport
from asset2sim.tasks.evaluation.clips import clip_videos
from asset2sim.tasks.evaluation.evaluate import Evaluation, evaluate_asset
from asset2sim.tasks.ingest.extract import extract_asset_checked
from asset2sim.formats import ReadOptions
from asset2sim.tasks.ingest.validate_input import Finding
from asset2sim.tasks.publish.contract import flow_config_hash, run_hash
from asset2sim.flows.job_records import (JobRecord, Measurement, Prepared, RefineOutput, StageRecord, finished_result,
                                         refined_output, report_tokens, resumable_output, write_job_record)
from asset2sim.output_folder import EVALUATION_NAME

FLOW_NAME = "refine-dataset"
SUBFLOW_NAME = "refine-assets"
#: ``<output_root>/<dataset>/<run>/_metrics/<asset id>/`` holds the metrics stage's ``evaluation.json``.
METRICS_DIRNAME = "_metrics"
DEFAULT_REFINE_FUNCTION = "asset2sim.tasks.refine:refine_asset"
#: The one failure mode retried (when the estimator calls a model).
RETRYABLE_FAILURE = "estimator_failure"


class ModelCallFailure(RuntimeError):
    """A model-backed estimator failed (the only failure Prefect retries)."""

    failure_mode = RETRYABLE_FAILURE


class RegressionFailure(RuntimeError):
    """The run regressed beyond ``results.regression`` with ``fail_flow`` (raised at the end of the flow);
    ``summary``: the run summary the flow would have returned."""

    def __init__(self, report: str, summary: dict[str, Any]):
        super().__init__(report)
        self.summary = summary


@dataclass
class AssetJob:
    """Everything one asset's task chain needs (JSON-able, shipped to workers): absolute paths,
    ``time_limit_seconds`` s over all stages, ``config`` a RefineConfig dict, ``finished`` earlier rows by
    :func:`asset2sim.flows.catalog.result_key`, ``resumable`` killed runs' job records (newest first),
    ``out_uri`` / ``metrics_uri`` upload targets (None: no output store)."""

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
    media: bool = True
    """with ``extras``: the renders, clips and HTML report with the refine (False: deferred to the run's media phase)"""
    isolation: str = "process"
    time_limit_seconds: float = 1800.0
    memory_limit_mb: int | None = 8192
    finished: dict[str, dict[str, Any]] = field(default_factory=dict)
    resumable: list[dict[str, Any]] = field(default_factory=list)
    code_version: str = __version__
    out_uri: str | None = None
    metrics_uri: str | None = None


def worker_name() -> str:
    """This worker's name in the records: ``host:pid``."""
    return f"{socket.gethostname()}:{os.getpid()}"


def finished_in_store(row: dict[str, Any] | None, input_hash: str) -> dict[str, Any] | None:
    """The skip rule (:func:`asset2sim.flows.job_records.finished_result`) for a row whose output is a local
    folder or a folder in an output store (:func:`asset2sim.flows.store.store_complete`)."""
    if row is not None and store_mod.is_store_uri(row.get("out_dir")):
        return row if store_mod.store_complete(row["out_dir"], input_hash, row.get("refine_config_hash") or "") else None
    return finished_result(row, input_hash)


def reusable(rec: Prepared, job: AssetJob, input_hash: str) -> Prepared:
    """``rec`` made the record of ``job``'s asset read (``ok``) with ``input_hash``: its configuration hashes and
    ``skip``, the earlier finished row to reuse (:func:`finished_in_store` of ``job.finished``; None: none)."""
    rec.ok, rec.input_hash, rec.refine_config_hash = True, input_hash, run_hash(RefineConfig(**job.config), job.prompt, job.category)
    rec.config_hash = flow_config_hash(rec.refine_config_hash, refine_function=job.refine_function, evaluate=job.evaluate,
                                       probes=job.probes, extras=job.extras, reference=bool(job.reference_dir),
                                       reference_scale=job.reference_scale)
    rec.skip = finished_in_store(job.finished.get(result_key(job.asset_id, input_hash, rec.config_hash)), input_hash)
    return rec


def publish_stage(job: AssetJob, refined: StageRecord) -> StageRecord:
    """Publish stage: upload the refined and metrics folders to ``job.out_uri`` / ``job.metrics_uri`` and delete
    the local copies; ``value``: ``{"out_uri", "files", "bytes", "clips"}`` (``clips``: the folder's clip videos,
    :func:`asset2sim.tasks.evaluation.clips.clip_videos`, read before the local copy goes); a refused upload is status
    ``error``."""
    if job.out_uri is None or refined is None or refined.status != "ok":
        return StageRecord(status="skipped")
    t0 = time.perf_counter()
    local = refined.value.out_dir or job.out_dir
    clips = clip_videos(local)
    try:
        up = store_mod.upload_folder(local, job.out_uri)
        if job.metrics_uri and Path(job.metrics_dir).is_dir():
            store_mod.upload_folder(job.metrics_dir, job.metrics_uri)
    except (OSError, ValueError) as exc:
        return StageRecord(status="error", error=f"upload of {local} to {job.out_uri} failed: {type(exc).__name__}: {exc}",
                           error_type=type(exc).__name__, failure_mode="crash", seconds=time.perf_counter() - t0,
                           worker=worker_name())
    output_folder.remove_owned(local)  # the refine's own files; anything else in the folder stays
    for folder in (job.metrics_dir, job.work_dir):  # the flow's bookkeeping folders (under the run's .work and metrics)
        shutil.rmtree(folder, ignore_errors=True)
    return StageRecord(status="ok", value={"out_uri": job.out_uri, "files": up["files"], "bytes": up["bytes"], "clips": clips},
                       seconds=time.perf_counter() - t0, worker=worker_name())


def stage_server_modules(job: AssetJob) -> tuple[str, ...]:
    """The modules a job's stage server imports before it forks (these stage functions and the refine function's),
    () when the job does not run in one."""
    return (__name__, job.refine_function.split(":", 1)[0]) if job.isolation == "process" else ()


def prepare_batch(jobs: list[AssetJob]) -> list[Prepared | Exception]:
    """:func:`prepare_asset` for several jobs (an exception is that job's item),
    starting this worker's stage server in the background meanwhile."""
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
    """The stage records of one asset's chain after prepare (None when not
    made) and ``error``, the exception that stopped metrics or publish."""

    refined: StageRecord
    measured: StageRecord | None = None
    published: StageRecord | None = None
    error: Exception | None = None


def refine_chain(job: AssetJob, prepared: Prepared) -> ChainResult:
    """refine -> metrics -> publish of one asset in one call (one task of the flow).

    Raises:
        ModelCallFailure: from the refine stage (the flow retries the chain).
    """
    refined = refine_stage(job, prepared)
    res = ChainResult(refined=refined)
    try:
        res.measured = metrics_stage(job, prepared, refined)
        if job.out_uri:
            res.published = publish_stage(job, refined)
    except Exception as exc:  # recorded in the row, like a failed stage
        res.error = exc
    return res


def prepare_asset(job: AssetJob) -> Prepared:
    """Input stage: read and hash the asset and decide whether an earlier result (``skip``) or a killed run's
    folder (``resume``) can be reused; else write the job record into ``job.work_dir``. Returns the Prepared
    record (``ok`` False, ``invalid_input``, for an unreadable asset). Raises OSError: record not written."""
    t0, c0 = time.perf_counter(), time.thread_time()
    rec = Prepared(worker=worker_name())
    try:
        config = RefineConfig(**job.config)
        reading = ReadOptions(body=config.body, mjcf_angle=config.mjcf.angle)
        asset, findings = extract_asset_checked(Path(job.asset_dir), asset_id=job.asset_id, category=job.category, reading=reading)
    except Exception as exc:  # any reading problem is the input's
        rec.failure_mode, rec.error = "invalid_input", f"{type(exc).__name__}: {exc}"
    else:
        chash, rhash = reusable(rec, job, asset.input_hash).config_hash, rec.refine_config_hash
        rec.category = job.category or asset.category
        rec.links, rec.movable_joints = len(asset.links), len(asset.movable_joints())
        if rec.skip is None:
            found = resumable_output(job.resumable, asset.input_hash, chash, rhash)
            rec.resume = None if found is None else found.model_dump(mode="json")
        if rec.skip is None and rec.resume is None:
            rec.asset, rec.findings = asset, list(findings)
            job_fields = {k: v for k, v in asdict(job).items() if k not in ("finished", "resumable")}
            write_job_record(job.work_dir, JobRecord(job=job_fields, input_hash=asset.input_hash, config_hash=chash,
                                                     refine_config_hash=rhash))
    rec.seconds, rec.cpu_seconds = time.perf_counter() - t0, time.thread_time() - c0
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
    media: bool = True,
) -> dict[str, Any]:
    """Run the refine function on one asset; ``extracted`` (``{"asset", "findings"}`` JSON) and ``reference_dir``
    go to a refine function that takes them. Returns a RefineOutput as JSON; raises what the function raises."""
    import inspect

    fn = import_target(refine_function)
    t0 = time.perf_counter()
    progress: list[list[Any]] = []

    def say(stage: str, message: str) -> None:
        progress.append([stage, message, round(time.perf_counter() - t0, 3)])

    optional = {
        "asset_id": asset_id, "extras": extras,
        "media": None if media else False,  # False: the media phase deferred to the end of the run
        "extracted": None if extracted is None else (AssetDescription.model_validate(extracted["asset"]),
                                                     [Finding.model_validate(f) for f in extracted["findings"]]),
        "reference": None if reference_dir is None else Path(reference_dir),
    }
    params = inspect.signature(fn).parameters
    kwargs = {"category": category, "progress": say, **{k: v for k, v in optional.items() if v is not None and k in params}}
    with output_folder.guarding(Path(out_dir).parent):  # the run's folder: no asset's output through a symlink out of it
        result = fn(Path(asset_dir), prompt, Path(out_dir), RefineConfig(**config), **kwargs)
    report = RefineReport.model_validate(result.report.model_dump(mode="json"))
    return RefineOutput(
        report=report,
        out_dir=str(result.out_dir),
        skipped=bool(getattr(result, "skipped", False)),
        progress=progress,
        tokens=report_tokens(report, Path(result.out_dir)),
    ).model_dump(mode="json")


def refined_evaluation(out_dir: str | Path, prompt: str, category: str | None, reference_dir: str | None) -> Evaluation | None:
    """The :class:`~asset2sim.tasks.evaluation.evaluate.Evaluation` in ``out_dir`` (``evaluation.json``) when it is
    the one the metrics stage would make (PyBullet's columns in it, the same prompt and reference, the category asked
    for when one was); else None. The refine's record is the verdict (one reading of an object): the metrics stage
    presents it rather than measuring the folder again."""
    try:
        ev = Evaluation.model_validate_json((Path(out_dir) / EVALUATION_NAME).read_text())
    except (OSError, ValueError):
        return None
    ref = str(Path(reference_dir).resolve()) if reference_dir else None
    if ("pybullet" not in ev.engines or ev.prompt != (prompt or None) or (category is not None and ev.category != category)
            or ev.reference != ref):
        return None
    return ev


def measurement_from_refine(out_dir: str, prompt: str, category: str | None, reference_dir: str | None,
                            metrics_dir: str | None) -> Measurement | None:
    """The measurement of refine's evaluation (:func:`refined_evaluation`), copied into ``metrics_dir`` when given;
    None when there is none to reuse."""
    t0 = time.perf_counter()
    ev = refined_evaluation(out_dir, prompt, category, reference_dir)
    if ev is None:
        return None
    if metrics_dir:
        atomic.copy_file(Path(out_dir) / EVALUATION_NAME, Path(metrics_dir) / EVALUATION_NAME)
    return _measurement(ev, time.perf_counter() - t0, reused_evaluation=True)


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
) -> dict[str, Any]:
    """The catalog's measurement of a refined asset (``evaluation.json`` into ``metrics_dir`` when given): refine's own
    evaluation when it wrote a matching one and no probes are asked (nothing simulated), else the folder evaluated with
    the checks refine ran (:func:`~asset2sim.tasks.evaluation.evaluate.evaluate_asset`, PyBullet; with ``probes``).

    Returns:
        A :class:`~asset2sim.flows.job_records.Measurement` as JSON: the catalog's metric columns
        (``penetration_mm`` mm, ``rest_stable``, ``d_pos_m`` m, ``d_ori_rad`` rad, ``oscillation_pass``,
        ``prompt_alignment`` 0..1, ``scale_deviation_pct`` %), failures, seconds.

    Raises:
        EvaluationError: the output cannot be read.
    """
    reused = None if probes else measurement_from_refine(out_dir, prompt, category, reference_dir, metrics_dir)
    if reused is not None:
        return reused.model_dump(mode="json")
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
        )
    return _measurement(ev, float(ev.seconds)).model_dump(mode="json")


def _run_stage(job: AssetJob, name: str, kwargs: dict[str, Any], timeout: float) -> StageRecord:
    """Run the stage function ``stage_<name>`` per the job's isolation; a uniform record (``value``: the JSON it
    returned)."""
    t0, target = time.perf_counter(), f"{__name__}:stage_{name}"
    if timeout <= 0:
        return StageRecord(status="timeout", error=f"no time left for stage {name}", failure_mode="timeout")
    limits = {"timeout": timeout, "workdir": Path(job.work_dir) / name, "memory_limit_mb": job.memory_limit_mb}
    if job.isolation == "process":  # a child forked from this worker's pre-imported stage server
        rec = asdict(run_forked(target, kwargs, **limits, preload=stage_server_modules(job)))
    elif job.isolation == "spawn":  # a fresh interpreter per call (imports paid every time)
        rec = asdict(run_isolated(target, kwargs, **limits))
    else:
        out = call_target(target, kwargs)
        rec = {"status": "ok" if out["ok"] else "error", **out}
    rec["seconds"] = time.perf_counter() - t0
    return StageRecord.model_validate(rec)


def refine_stage(job: AssetJob, prepared: Prepared) -> StageRecord:
    """Refine stage within the asset's time limit (for ``prepared.resume``, the earlier ``report.json``); ``value`` a
    RefineOutput. Raises ModelCallFailure: a model-backed estimator failed (Prefect retries it)."""
    if not prepared.ok or prepared.skip is not None:
        return StageRecord(status="skipped")
    if prepared.resume is not None:
        out_dir = prepared.resume["job"]["out_dir"]
        try:
            value = refined_output(out_dir)
        except (OSError, ValueError) as exc:
            return StageRecord(status="error", error=f"{out_dir}: cannot read the finished report: {exc}",
                               error_type=type(exc).__name__, worker=worker_name())
        return StageRecord(status="ok", value=value, worker=worker_name(),
                           seconds=float(sum(value.report.stage_seconds.values())))
    budget = job.time_limit_seconds - float(prepared.seconds or 0.0)
    rec = _run_stage(
        job,
        "refine",
        {
            **{k: getattr(job, k) for k in ("asset_dir", "prompt", "out_dir", "config", "category", "asset_id",
                                            "refine_function", "extras", "media")},
            "extracted": None if prepared.asset is None else {
                "asset": prepared.asset.model_dump(mode="json"),
                "findings": [f.model_dump(mode="json") for f in prepared.findings],
            },
            "reference_dir": job.reference_dir,
        },
        budget,
    )
    rec.worker = worker_name()
    if rec.status == "ok":
        rec.value = RefineOutput.model_validate(rec.value)
    if rec.failure_mode == RETRYABLE_FAILURE and str(job.config.get("estimator", "offline")) != "offline":
        raise ModelCallFailure(f"{job.asset_id}: estimator {job.config.get('estimator')!r} failed: {rec.error}")
    return rec


def metrics_stage(job: AssetJob, prepared: Prepared, refined: StageRecord) -> StageRecord:
    """Metrics stage (:func:`stage_metrics`) within what is left of the time limit; for ``prepared.resume`` the
    earlier run's measurement when it made one."""
    if refined.status != "ok" or not job.evaluate:
        return StageRecord(status="skipped")
    value: RefineOutput = refined.value
    category = value.report.category or job.category
    metrics_dir, reused = job.metrics_dir, None
    if prepared.resume is not None:  # the earlier run's measurement, when it made one
        metrics_dir = prepared.resume["job"]["metrics_dir"]
        ev = refined_evaluation(metrics_dir, job.prompt, category, job.reference_dir)
        reused = None if ev is None else _measurement(ev, float(ev.seconds))
    if reused is None and not job.probes:
        reused = measurement_from_refine(value.out_dir or job.out_dir, job.prompt, category, job.reference_dir, metrics_dir)
    if reused is not None:  # nothing to simulate: no child process needed
        return StageRecord(status="ok", value=reused, seconds=reused.seconds)
    budget = job.time_limit_seconds - float(prepared.seconds or 0.0) - float(refined.seconds or 0.0)
    rec = _run_stage(
        job,
        "metrics",
        {
            "out_dir": value.out_dir or job.out_dir,
            "prompt": job.prompt,
            "category": category,
            "reference_dir": job.reference_dir,
            "probes": job.probes,
            "metrics_dir": metrics_dir,
        },
        budget,
    )
    if rec.status == "ok":
        rec.value = Measurement.model_validate(rec.value)
    return rec


def prepare_prefect_environment(project_root: Path | str) -> dict[str, str]:
    """Set Prefect's environment defaults (home under the project, analytics off, a longer start-up timeout) where
    unset, before Prefect is imported; returns what was set."""
    defaults = {
        "PREFECT_HOME": str(Path(project_root) / ".prefect"),
        "PREFECT_SERVER_ANALYTICS_ENABLED": "false",
        "DO_NOT_TRACK": "1",
        "MLFLOW_DISABLE_TELEMETRY": "true",  # no ~/.config/mlflow/telemetry.json, no usage sent
        "PREFECT_SERVER_EPHEMERAL_STARTUP_TIMEOUT_SECONDS": f"{server.STARTUP_TIMEOUT:g}",  # a fresh database's first start
    }
    set_now = {k: v for k, v in defaults.items() if k not in os.environ}
    os.environ.update(set_now)
    return set_now
