"""The flow's records of one asset's job: the skip rule (:func:`finished_result`), job records
(:func:`resumable_output`), the stage records and the catalog row of a flow run (:func:`build_row`).
The output contract they read (hashes, the completion marker, ``report.json``) is
:mod:`asset2sim.tasks.publish.contract`; ``docs/design/pipeline.md`` explains the skip key.
"""

from __future__ import annotations

import json
import time
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

from pydantic import BaseModel, ConfigDict

from asset2sim.schemas import Strict
from asset2sim import atomic
from asset2sim.output_folder import OVERLAY_NAME, read_record
from asset2sim.schemas.asset import AssetDescription
from asset2sim.schemas.catalog import CatalogRow
from asset2sim.schemas.metrics import column_values
from asset2sim.schemas.report import MetricResult, RefineReport
from asset2sim.tasks.check.verdict import FAILED_STATUSES, asset_failure_mode
from asset2sim.tasks.evaluation.clips import clip_videos
from asset2sim.tasks.ingest.partnet_mobility import ManifestRowError, is_valid_id
from asset2sim.tasks.ingest.validate_input import Finding
from asset2sim.tasks.publish import contract
from asset2sim.tasks.publish.contract import is_complete, read_report_json

#: The flow's record of an asset's job in its run's work folder (``<run>/.work/<asset id>/job.json``).
JOB_RECORD_NAME = "job.json"


def finished_result(row: dict[str, Any] | None, input_hash: str) -> dict[str, Any] | None:
    """The skip rule: ``row`` (an earlier catalog row for the same asset, input and flow configuration, or
    None) when its output folder is still complete for ``input_hash``, else None."""
    out = None if row is None else row.get("out_dir")
    return row if out and is_complete(out, input_hash, row.get("refine_config_hash") or "") else None


class JobRecord(BaseModel):
    """What a flow run set out to do for one asset: the job (``AssetJob`` as a dict), the input hash and
    both configuration hashes (:func:`flow_config_hash`, :func:`run_hash`)."""

    model_config = ConfigDict(extra="ignore")
    job: dict[str, Any]
    input_hash: str
    config_hash: str
    refine_config_hash: str


def write_job_record(work_dir: Path | str, record: JobRecord) -> Path:
    """Write ``record`` atomically as ``work_dir/job.json``."""
    return atomic.write_json(Path(work_dir) / JOB_RECORD_NAME, record.model_dump(mode="json"))


def resumable_output(candidates: list[dict[str, Any]], input_hash: str, config_hash: str,
                     refine_config_hash: str) -> JobRecord | None:
    """The first of ``candidates`` (:class:`JobRecord` dicts of earlier runs without a catalog row, newest
    first) with these hashes whose output folder is complete: finished work a killed flow did not record."""
    for cand in candidates:
        try:
            rec = JobRecord.model_validate(cand)
        except ValueError:
            continue
        if (rec.input_hash, rec.config_hash, rec.refine_config_hash) != (input_hash, config_hash, refine_config_hash):
            continue
        out = rec.job.get("out_dir")
        if out and is_complete(out, input_hash, refine_config_hash):
            return rec
    return None


def refined_output(out_dir: Path | str) -> "RefineOutput":
    """The refine stage's value (``skipped``) for a complete output folder, from its ``report.json``.
    Raises OSError or ValueError when there is no readable report."""
    out_dir = Path(out_dir)
    report = read_report_json(out_dir)
    return RefineOutput(report=report, out_dir=str(out_dir), skipped=True, tokens=report_tokens(report, out_dir))


def report_tokens(report: RefineReport, out_dir: Path | str) -> int | None:
    """Model tokens used: 0 when no model was queried, else the report's (or the overlay's) count when
    positive, else None."""
    if int(report.model_queries or 0) == 0:
        return 0
    if report.model_tokens > 0:
        return int(report.model_tokens)
    try:
        est = read_record(Path(out_dir) / OVERLAY_NAME).get("estimator", {})
        if isinstance(est.get("tokens"), (int, float)) and est["tokens"] > 0:
            return int(est["tokens"])
    except (OSError, ValueError, AttributeError):
        pass
    return None


class Prepared(Strict):
    """What the flow's input stage found for one asset: ``skip`` the earlier catalog row to reuse, ``resume``
    an earlier run's :class:`JobRecord` whose complete folder to record, ``asset`` and ``findings`` handed to
    the refine stage; ``seconds`` wall time, ``cpu_seconds`` the CPU time (user + system) of the
    thread that read the asset."""

    ok: bool = False
    worker: str | None = None
    seconds: float | None = None
    cpu_seconds: float | None = None
    input_hash: str | None = None
    config_hash: str | None = None
    refine_config_hash: str | None = None
    category: str | None = None
    links: int | None = None
    movable_joints: int | None = None
    skip: dict[str, Any] | None = None
    resume: dict[str, Any] | None = None
    failure_mode: str | None = None
    error: str | None = None
    asset: AssetDescription | None = None
    findings: list[Finding] = []


class RefineOutput(Strict):
    """The refine stage's value: the report, the folder, whether a complete folder was reused, progress
    ``[stage, message, t_s]`` and the model tokens (None: unknown)."""

    report: RefineReport
    out_dir: str
    skipped: bool = False
    progress: list[list[Any]] = []
    tokens: int | None = None


class Measurement(Strict):
    """The metrics stage's value: the catalog's metric columns, the failing checks of the verdict (``name@engine``),
    wall time (s) and whether the refine's ``evaluation.json`` was reused (nothing simulated)."""

    columns: dict[str, Any] = {}
    failures: list[str] = []
    seconds: float = 0.0
    reused_evaluation: bool = False


class StageRecord(BaseModel):
    """One stage's outcome: ``status`` ok / skipped / error / timeout / crash, ``value`` when ok,
    ``seconds`` wall time, error fields when it failed."""

    model_config = ConfigDict(extra="allow")
    status: str
    value: Any = None
    error: str = ""
    error_type: str = ""
    failure_mode: str | None = None
    seconds: float = 0.0
    log_tail: str = ""
    worker: str | None = None


def _s(seconds: float | None) -> float:
    """A stage's seconds as ``stage_seconds`` holds them (0.1 ms; None: 0)."""
    return round(float(seconds or 0.0), 4)


def _utc(ts: float | None) -> datetime | None:
    return None if ts is None else datetime.fromtimestamp(ts, timezone.utc)


#: Columns a skipped row copies from the finished row it reuses.
REUSED_COLUMNS = (
    "category", "estimator", "model", "scale", "scale_deviation_pct", "total_mass_kg", "initial_state",
    "penetration_mm", "rest_stable", "d_pos_m", "d_ori_rad", "oscillation_pass", "prompt_alignment",
    "failure_mode", "model_queries", "tokens", "out_dir", "error", "code_hash", "clips", "request_met", "request_unmet",
    "media", "postcheck_rounds", "extra_rounds",
)  # fmt: skip


def build_row(job: Any, prepared: Prepared | None, refined: StageRecord | None, measured: StageRecord | None, *,
              error: str | None = None, failure_mode: str | None = None, flow_run_id: str | None = None,
              started_at: float | None = None, finished_at: float | None = None) -> CatalogRow:
    """One catalog row from the typed stage records of an asset.

    Args:
        job: the asset's ``asset2sim.flows.stages.AssetJob``.
        prepared: the input stage's record (None: it did not finish).
        refined: the refine stage's record; ``value`` a :class:`RefineOutput`.
        measured: the metrics stage's record; ``value`` a :class:`Measurement`.
        error, failure_mode: an exception that stopped the chain outside the stages.
        flow_run_id: Prefect flow run; started_at, finished_at: epoch s.

    Verdict columns come from the metrics stage when it ran, else from the refine post-check; the failure
    mode is :func:`asset2sim.tasks.check.verdict.asset_failure_mode`'s.
    """
    prepared = prepared or Prepared()
    now = time.time()  # a ``failed`` row with the job's and the input stage's columns (times default to now)
    row = CatalogRow(
        asset_id=job.asset_id, status="failed", category=prepared.category or job.category, prompt=job.prompt,
        estimator=job.config.get("estimator"), model=job.config.get("model"), reference_scale=job.reference_scale,
        input_hash=prepared.input_hash, config_hash=prepared.config_hash, refine_config_hash=prepared.refine_config_hash,
        code_version=job.code_version, code_hash=contract.code_hash(), flow_run_id=flow_run_id,
        worker=(refined.worker if refined is not None else None) or prepared.worker,
        started_at=_utc(started_at or now), finished_at=_utc(finished_at or now), source_run=job.run_id)
    stages = {k: _s(v) for k, v in (("prepare", prepared.seconds), ("cpu.prepare", prepared.cpu_seconds)) if v is not None}
    if prepared.skip is not None:  # the ``skipped`` row reusing an earlier finished row
        prev = prepared.skip
        for col in REUSED_COLUMNS:
            setattr(row, col, prev.get(col))
        row.status = "skipped"
        row.source_run = prev.get("source_run") or prev.get("run")
        row.model_queries = row.tokens = 0
        row.stage_seconds = json.dumps(stages)
        row.wall_seconds = sum(v for k, v in stages.items() if "." not in k)
        return row
    errors: list[str] = []
    input_failure = None
    if not prepared.ok and prepared.seconds is not None:
        input_failure = prepared.failure_mode or "invalid_input"
        errors.append(f"prepare: {prepared.error or ''}")
    refine_status = refined.status if refined is not None else None
    # the refine's columns, seconds and failure mode (None: it did not finish)
    refine_mode = None
    if refine_status == "ok":
        value: RefineOutput = refined.value
        report = value.report
        row.out_dir = value.out_dir or job.out_dir
        row.clips = json.dumps(clip_videos(row.out_dir)) if row.out_dir else None
        row.media = report.media
        stages["refine"] = _s(refined.seconds)
        stages.update({f"refine.{k}": _s(v) for k, v in report.stage_seconds.items()})
        row.scale = report.scale
        row.total_mass_kg = report.total_mass
        row.initial_state = json.dumps(report.initial_joint_positions or {}, sort_keys=True)
        row.model_queries = int(report.model_queries or 0)
        row.postcheck_rounds = len(report.escalation) or None
        row.extra_rounds = json.dumps(extra_rounds(report)) if report.escalation else None
        row.refine_config_hash = report.config_hash or row.refine_config_hash
        row.tokens = value.tokens
        for col in ("estimator", "model", "category"):  # the report's when it names one
            setattr(row, col, getattr(report, col) or getattr(row, col))
        post = column_values(report.metrics, engine=None, names=("penetration", "rest_stability", "oscillation", "request_met"))
        row.penetration_mm = post.get("penetration_mm")
        for col in ("rest_stable", "d_pos_m", "d_ori_rad", "oscillation_pass", "request_met", "request_unmet"):
            if col in post:
                setattr(row, col, post[col])
        refine_mode = report.failure_mode
    elif refine_status in FAILED_STATUSES:
        stages["refine"] = _s(refined.seconds)
        errors.append(f"refine: {refined.error_type} {refined.error}".strip())
        if refine_status == "crash" and refined.log_tail:
            errors.append(refined.log_tail[-600:])
        refine_mode = refined.failure_mode
    measured_status = measured.status if measured is not None else None
    if measured_status == "ok":  # the metrics stage's columns
        stages["metrics"] = _s(measured.seconds)
        for col, v in measured.value.columns.items():
            if v is not None:
                setattr(row, col, v)
    verdict = asset_failure_mode(input_failure=input_failure, refine_status=refine_status, refine_mode=refine_mode,
                                 measured_status=measured_status, chain_error_mode=(failure_mode or "crash") if error else None)
    errors += verdict.errors
    if measured_status in FAILED_STATUSES:
        stages["metrics"] = _s(measured.seconds)
        errors.append(f"metrics: {measured.error_type} {measured.error}".strip())
    if error:
        errors.append(error)
    recorded_nothing = (
        input_failure is None and refine_status not in ("ok", *FAILED_STATUSES)
        and measured_status not in FAILED_STATUSES and not error
    )  # fmt: skip
    if recorded_nothing and not errors:
        errors.append("the asset's task chain produced no result")
    finished_stages = refine_status == "ok" and (measured_status in ("ok", "skipped", None) or not job.evaluate)
    row.status = "done" if finished_stages and not error and measured_status not in FAILED_STATUSES else "failed"
    row.failure_mode = verdict.failure_mode
    row.error = "\n".join(e for e in errors if e) or None
    row.stage_seconds = json.dumps(stages, sort_keys=True)
    row.wall_seconds = round(sum(v for k, v in stages.items() if "." not in k), 4)
    return row


def failed_checks(metrics: list[MetricResult]) -> list[str]:
    """The checks of one post-check round that failed, ``name(engine)``; a robust-rest check with its failing
    trials after a colon (``robust_rest(pybullet): tilt+y, drop``)."""
    out = []
    for m in metrics:
        if m.passed is not False:
            continue
        trials = (m.details or {}).get("trials") if m.name == "robust_rest" else None
        failing = [str(k) for k, t in trials.items() if isinstance(t, dict) and t.get("passed") is False] if isinstance(trials, dict) else []
        out.append(f"{m.name}({m.engine})" + (f": {', '.join(failing)}" if failing else ""))
    return out


def extra_rounds(report: RefineReport) -> list[dict[str, Any]]:
    """What started each post-check round of ``report`` after its first: ``{"round": n, "after": [...], "reason":
    text}``, ``after`` the checks that failed the round before (:func:`failed_checks`; empty when that round passed,
    as before the final setting is checked again with the joint sweep), ``reason`` the round's own account (its
    ``reason``). Empty when the first post-check decided."""
    rounds = report.escalation
    return [{"round": cur.round, "after": failed_checks(prev.metrics), "reason": cur.reason}
            for prev, cur in zip(rounds, rounds[1:])]


def manifest_row_id(error: ManifestRowError, taken: set[str]) -> str:
    """The catalog ``asset_id`` of an unusable manifest row: its id when usable and free, else
    ``manifest-line-<line>`` (unique against ``taken``, to which it is added)."""
    rid = error.id if is_valid_id(error.id) and error.code != "MANIFEST_DUPLICATE_ID" else None
    if rid is None or rid in taken:
        base = rid = f"manifest-line-{error.line}"
        n = 1
        while rid in taken:
            n += 1
            rid = f"{base}-{n}"
    taken.add(rid)
    return rid


def build_manifest_row(error: ManifestRowError, *, asset_id: str, run_id: str, config: dict[str, Any], code_version: str,
                       flow_run_id: str | None = None) -> CatalogRow:
    """The failed catalog row of an unusable manifest row (``invalid_manifest_row``, its code and message as
    the error), stamped now."""
    verdict = asset_failure_mode(manifest_error=f"{error.code}: {error.message}")
    when = _utc(time.time())
    return CatalogRow(
        asset_id=asset_id, status="failed", failure_mode=verdict.failure_mode, error="\n".join(verdict.errors),
        estimator=config.get("estimator"), model=config.get("model"), code_version=code_version, code_hash=contract.code_hash(),
        flow_run_id=flow_run_id, started_at=when, finished_at=when, source_run=run_id, wall_seconds=0.0,
        stage_seconds=json.dumps({}))
