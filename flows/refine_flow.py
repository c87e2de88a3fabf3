"""The dataset refinement flow: ``catalog.yaml`` in, refined assets, Parquet
catalog rows and an MLflow run out.

Shape (DEVELOPERS.md, "Shape of the product")::

    refine-dataset (Prefect flow, driver process)
      read catalog.yaml -> generate the demo assets if needed -> read manifest
      -> refine-assets (Prefect subflow on a DaskTaskRunner)
           per asset, a chain of Prefect tasks on Dask workers:
             prepare  (extract: validate + input hash; skip when finished)
             refine   (synthesize -> refine state -> write -> post-check:
                       ``refine_asset`` of ``asset2sim.tasks.refine``)
             metrics  (stability metrics: ``asset2sim.tasks.evaluation.evaluate``:
                       penetration, rest stability, oscillation,
                       prompt alignment, scale deviation)
           each finished chain -> one catalog row, appended atomically
      -> summary table + failure-mode plot -> MLflow run (nested run per asset)

The per-asset stages of the lead's refine pipeline run inside one call
(``refine_asset``), which does extract, analyze, closed state, synthesize,
validate, write, state refinement and the post-check and records their wall
times (``report.stage_seconds``, copied into the catalog row); the flow chains
``prepare -> refine -> metrics`` as separate tasks around it.

Failure handling: every stage returns a record instead of raising, so a failed
asset never stops the others; a Prefect retry happens only when a model-backed
estimator failed (``estimator_failure`` with an estimator other than
``offline``): that is the only failure a retry can fix. Each asset has a
wall-time limit over all its stages; with ``isolation: process`` (default)
stages run in a child process killed at the limit (:mod:`.isolation`), so
hangs and native crashes become ``timeout`` / ``crash`` rows.

Dask: a local cluster with ``workers`` processes by default; an existing
scheduler when ``dask_address`` (parameter) or ``DASK_ADDRESS`` (environment)
is given. Workers of a local cluster are pointed at the driver's Prefect API
(``PREFECT_API_URL``); workers of a remote cluster need a Prefect server they
can reach (set ``PREFECT_API_URL`` on them).

Prefect is imported only inside the functions that need it; the Prefect
objects (:data:`refine_dataset`, the tasks) are built on first access.
"""

from __future__ import annotations

import json
import math
import os
import socket
import time
import uuid
from dataclasses import asdict, dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

from asset2sim import __version__
from asset2sim.catalog import Catalog, ManifestEntry, ResultCatalog, load_catalog, read_manifest, result_key

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


# ----------------------------------------------------------------------------- jobs


@dataclass
class AssetJob:
    """Everything one asset's task chain needs (JSON-able, shipped to workers).

    Paths absolute (``out_dir`` the refined folder, ``metrics_dir`` the metrics
    stage's ``evaluation.json``, ``work_dir`` scratch of isolated stages); ``time_limit_seconds`` s over all stages of the asset;
    ``config`` the :class:`~asset2sim.schemas.config.RefineConfig` as a dict;
    ``finished`` the catalog rows of earlier finished runs keyed by
    :func:`asset2sim.catalog.result_key` for this asset (empty when forced).
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
    finished: dict[str, dict[str, Any]] = field(default_factory=dict)
    code_version: str = __version__


def code_version() -> str:
    """The code that produced a result: the package version, plus the git
    commit of the source tree (``+g<sha>``, ``.dirty`` with uncommitted
    changes to tracked files) when the package runs from a git checkout."""
    import subprocess

    src = Path(__file__).resolve().parent.parent
    try:
        sha = subprocess.run(
            ["git", "-C", str(src), "rev-parse", "--short", "HEAD"], capture_output=True, text=True, timeout=10
        )
        if sha.returncode != 0 or not sha.stdout.strip():
            return __version__
        dirty = subprocess.run(
            ["git", "-C", str(src), "status", "--porcelain", "--untracked-files=no"],
            capture_output=True,
            text=True,
            timeout=20,
        )
    except (OSError, subprocess.SubprocessError):
        return __version__
    return f"{__version__}+g{sha.stdout.strip()}" + (".dirty" if dirty.stdout.strip() else "")


def make_run_id(now: datetime | None = None) -> str:
    """A run id that sorts chronologically: ``YYYYmmddTHHMMSSZ-xxxxxx`` (UTC)."""
    now = now or datetime.now(timezone.utc)
    return now.strftime("%Y%m%dT%H%M%SZ") + "-" + uuid.uuid4().hex[:6]


def flow_parameters(
    catalog: str | Path = "catalog.yaml",
    dataset: str | None = None,
    workers: int | None = None,
    dask_address: str | None = None,
) -> dict[str, Any]:
    """The parameters ``make flow`` passes to :data:`refine_dataset` (and the
    nightly deployment stores): the catalog as an absolute path, the dataset,
    workers and Dask scheduler address (None = catalog/environment defaults)."""
    return {
        "catalog": str(Path(catalog).expanduser().resolve()),
        "dataset": dataset,
        "workers": workers,
        "dask_address": dask_address,
    }


def plan_jobs(
    cat: Catalog,
    dataset: str,
    run_id: str,
    *,
    ids: list[str] | None = None,
    limit: int | None = None,
    force: bool = False,
) -> list[AssetJob]:
    """The jobs of a run: one per manifest entry (optionally only ``ids``, at
    most ``limit``), with earlier finished results for the skip decision.

    Generates the demo assets first when the dataset says ``generate: demo``
    and they are missing or outdated.

    Raises:
        CatalogError: bad manifest or dataset; an id in ``ids`` not in the manifest.
    """
    from asset2sim.catalog import CatalogError

    name, ds = cat.dataset(dataset)
    root = cat.dataset_root(name)
    if ds.generate == "demo":
        from asset2sim.demo_assets import ensure_demo_dataset

        ensure_demo_dataset(root)
    entries: list[ManifestEntry] = read_manifest(cat.manifest_path(name), root)
    if ids:
        known = {e.asset_id for e in entries}
        unknown = [i for i in ids if i not in known]
        if unknown:
            raise CatalogError(f"{cat.manifest_path(name)}: unknown id(s) {unknown}")
        entries = [e for e in entries if e.asset_id in set(ids)]
    if limit is not None:
        entries = entries[: max(0, int(limit))]
    settings = cat.config.run
    config = cat.refine_config().model_dump(mode="json")
    finished = {} if force else ResultCatalog(cat.catalog_root).finished(name)
    run_out = cat.output_root / name / run_id
    version = code_version()
    jobs = []
    for e in entries:
        ref_dir = None
        if ds.reference and (e.asset_dir / "reference_gensim2.json").is_file():
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
                finished={k: v for k, v in finished.items() if k.startswith(e.asset_id + "|")},
                code_version=version,
            )
        )
    return jobs


# --------------------------------------------------------------------------- hashes


def _refine_run_hash(input_hash: str, config: dict[str, Any], prompt: str, category: str | None) -> str:
    from asset2sim.schemas.config import RefineConfig

    cfg = RefineConfig(**config)
    try:
        from asset2sim.tasks.refine import run_hash
    except ImportError:  # the refine module is optional for the flow itself
        import hashlib

        blob = json.dumps(
            {"config": cfg.config_hash(), "prompt": prompt, "category": category, "version": __version__},
            sort_keys=True,
        ).encode()
        return hashlib.sha256(blob).hexdigest()[:16]
    return run_hash(input_hash, cfg, prompt, category)


def flow_config_hash(job: AssetJob, refine_hash: str) -> str:
    """Configuration hash of one asset's result in the catalog (hex, 16):
    the refine run hash (configuration, prompt, category, code version) plus
    the flow settings that change the result (refine function, metrics stage,
    reference)."""
    import hashlib

    blob = json.dumps(
        {
            "refine": refine_hash,
            "refine_function": job.refine_function,
            "evaluate": job.evaluate,
            "probes": job.probes,
            "extras": job.extras,
            "reference": bool(job.reference_dir),
            "reference_scale": job.reference_scale,
        },
        sort_keys=True,
    ).encode()
    return hashlib.sha256(blob).hexdigest()[:16]


# --------------------------------------------------------------------------- stages


def _worker_name() -> str:
    return f"{socket.gethostname()}:{os.getpid()}"


def prepare_asset(job: AssetJob) -> dict[str, Any]:
    """Stage 1 (extract): validate and read the asset, hash input and
    configuration, decide whether an earlier result can be reused.

    Returns a record: ``ok`` (bool), ``input_hash``, ``config_hash``,
    ``refine_config_hash``, ``category`` (asset's own when the manifest has
    none), ``skip`` (the earlier catalog row to reuse, or None), ``seconds``,
    ``worker``; on failure ``failure_mode`` (``invalid_input``) and ``error``.
    Never raises for a bad asset.
    """
    t0 = time.perf_counter()
    rec: dict[str, Any] = {"ok": False, "skip": None, "worker": _worker_name()}
    try:
        from asset2sim.tasks.ingest.extract import extract_asset

        asset = extract_asset(Path(job.asset_dir), asset_id=job.asset_id, category=job.category)
    except Exception as exc:  # any reading problem is the input's
        rec.update(failure_mode="invalid_input", error=f"{type(exc).__name__}: {exc}", seconds=time.perf_counter() - t0)
        return rec
    rhash = _refine_run_hash(asset.input_hash, job.config, job.prompt, job.category)
    chash = flow_config_hash(job, rhash)
    rec.update(
        ok=True,
        input_hash=asset.input_hash,
        config_hash=chash,
        refine_config_hash=rhash,
        category=job.category or asset.category,
        links=len(asset.links),
        movable_joints=len(asset.movable_joints()),
    )
    prev = job.finished.get(result_key(job.asset_id, asset.input_hash, chash))
    if prev is not None and _output_still_valid(prev, asset.input_hash):
        rec["skip"] = prev
    rec["seconds"] = time.perf_counter() - t0
    return rec


def _output_still_valid(row: dict[str, Any], input_hash: str) -> bool:
    out = row.get("out_dir")
    if not out or not Path(out).is_dir():
        return False
    try:
        from asset2sim.tasks.refine import is_complete
    except ImportError:
        return (Path(out) / "report.json").is_file()
    return is_complete(Path(out), input_hash, row.get("refine_config_hash") or "")


def stage_refine(
    asset_dir: str,
    prompt: str,
    out_dir: str,
    config: dict[str, Any],
    category: str | None,
    asset_id: str,
    refine_function: str = DEFAULT_REFINE_FUNCTION,
    extras: bool = True,
) -> dict[str, Any]:
    """Run the refine function on one asset (in whichever process calls it).

    Returns ``{"report": report.json contents, "out_dir", "skipped",
    "progress": [[stage, message, t_s], ...], "tokens": int | None}``.

    Raises:
        Whatever the refine function raises (``RefineError`` carries
        ``failure_mode``).
    """
    import inspect

    from asset2sim.flows.isolation import import_target
    from asset2sim.schemas.config import RefineConfig

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
    result = fn(Path(asset_dir), prompt, Path(out_dir), RefineConfig(**config), **kwargs)
    report = result.report.model_dump(mode="json")
    return {
        "report": report,
        "out_dir": str(result.out_dir),
        "skipped": bool(getattr(result, "skipped", False)),
        "progress": progress,
        "tokens": _tokens(report, Path(result.out_dir)),
    }


def _tokens(report: dict[str, Any], out_dir: Path) -> int | None:
    """Model tokens used: 0 when no model was queried, else the report's
    ``model_tokens`` (or the overlay's estimator ``tokens``) when positive,
    else None (the model API did not say)."""
    if int(report.get("model_queries") or 0) == 0:
        return 0
    for value in (report.get("model_tokens"), report.get("tokens")):
        if isinstance(value, (int, float)) and value > 0:
            return int(value)
    try:
        est = json.loads((out_dir / "overlay.json").read_text()).get("estimator", {})
        if isinstance(est.get("tokens"), (int, float)) and est["tokens"] > 0:
            return int(est["tokens"])
    except (OSError, ValueError, AttributeError):
        pass
    return None


def stage_metrics(
    out_dir: str,
    prompt: str,
    category: str | None,
    reference_dir: str | None = None,
    probes: bool = False,
    metrics_dir: str | None = None,
) -> dict[str, Any]:
    """Stability metrics of a refined asset (``asset2sim.tasks.evaluation.evaluate``,
    PyBullet, SPEC conventions); writes ``evaluation.json`` into
    ``metrics_dir`` when given. The refined folder itself is never touched
    (its completion marker covers every file in it).

    Returns ``penetration_mm`` (mm), ``rest_stable``, ``d_pos_m`` (m),
    ``d_ori_rad`` (rad), ``oscillation_pass``, ``prompt_alignment`` (0..1 or
    None), ``scale_deviation_pct`` (% or None), ``failures``, ``seconds``.

    Raises:
        EvaluationError: the output cannot be read.
    """
    from asset2sim.tasks.evaluation.evaluate import evaluate_asset

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

    def value(name: str) -> float | None:
        m = ev.metric(name, "pybullet")
        return None if m is None or m.value is None else float(m.value)

    rest = ev.metric("rest_stability", "pybullet")
    osc = ev.metric("oscillation", "pybullet")
    return {
        "penetration_mm": value("penetration"),
        "rest_stable": None if rest is None else rest.passed,
        "d_pos_m": None if rest is None else rest.details.get("D_pos_m"),
        "d_ori_rad": None if rest is None else rest.details.get("D_ori_rad"),
        "oscillation_pass": None if osc is None else osc.passed,
        "prompt_alignment": value("prompt_alignment"),
        "scale_deviation_pct": value("scale_deviation"),
        "failures": list(ev.failures),
        "seconds": float(ev.seconds),
    }


def _run_stage(job: AssetJob, name: str, target: str, kwargs: dict[str, Any], timeout: float) -> dict[str, Any]:
    """Run a stage function per the job's isolation; a uniform record:
    ``status`` ok/error/timeout/crash, ``value``, ``error``, ``failure_mode``,
    ``seconds``."""
    from asset2sim.flows.isolation import call_target, run_isolated

    t0 = time.perf_counter()
    if timeout <= 0:
        return {"status": "timeout", "error": f"no time left for stage {name}", "failure_mode": "timeout", "seconds": 0.0}
    if job.isolation == "process":
        res = run_isolated(target, kwargs, timeout=timeout, workdir=Path(job.work_dir) / name)
        rec = asdict(res)
    else:
        out = call_target(target, kwargs)
        rec = {"status": "ok" if out["ok"] else "error", **out}
    rec["seconds"] = time.perf_counter() - t0
    return rec


def refine_stage(job: AssetJob, prepared: dict[str, Any]) -> dict[str, Any]:
    """Stage 2: synthesize, refine state, write and post-check one asset
    (the refine function), inside the asset's time limit.

    Returns the stage record (see :func:`_run_stage`); ``skipped`` when
    ``prepared`` says so or the asset was invalid.

    Raises:
        ModelCallFailure: a model-backed estimator failed (Prefect retries it).
    """
    if not prepared.get("ok") or prepared.get("skip") is not None:
        return {"status": "skipped", "seconds": 0.0}
    budget = job.time_limit_seconds - float(prepared.get("seconds") or 0.0)
    rec = _run_stage(
        job,
        "refine",
        "asset2sim.flows.refine_flow:stage_refine",
        {
            "asset_dir": job.asset_dir,
            "prompt": job.prompt,
            "out_dir": job.out_dir,
            "config": job.config,
            "category": job.category,
            "asset_id": job.asset_id,
            "refine_function": job.refine_function,
            "extras": job.extras,
        },
        budget,
    )
    rec["worker"] = _worker_name()
    if rec.get("failure_mode") == RETRYABLE_FAILURE and str(job.config.get("estimator", "offline")) != "offline":
        raise ModelCallFailure(f"{job.asset_id}: estimator {job.config.get('estimator')!r} failed: {rec.get('error')}")
    return rec


def metrics_stage(job: AssetJob, prepared: dict[str, Any], refined: dict[str, Any]) -> dict[str, Any]:
    """Stage 3: the stability metrics of the refined output, inside what is
    left of the asset's time limit. ``skipped`` when there is no output or
    ``job.evaluate`` is off."""
    if refined.get("status") != "ok" or not job.evaluate:
        return {"status": "skipped", "seconds": 0.0}
    value = refined.get("value") or {}
    budget = job.time_limit_seconds - float(prepared.get("seconds") or 0.0) - float(refined.get("seconds") or 0.0)
    category = (value.get("report") or {}).get("category") or job.category
    return _run_stage(
        job,
        "metrics",
        "asset2sim.flows.refine_flow:stage_metrics",
        {
            "out_dir": value.get("out_dir") or job.out_dir,
            "prompt": job.prompt,
            "category": category,
            "reference_dir": job.reference_dir,
            "probes": job.probes,
            "metrics_dir": job.metrics_dir,
        },
        budget,
    )


# ------------------------------------------------------------------------------ rows


def _utc(ts: float | None) -> datetime | None:
    return None if ts is None else datetime.fromtimestamp(ts, timezone.utc)


def _metric(report: dict[str, Any], name: str) -> dict[str, Any] | None:
    for m in report.get("metrics") or []:
        if m.get("name") == name:
            return m
    return None


def _num(v: Any) -> float | None:
    try:
        f = float(v)
    except (TypeError, ValueError):
        return None
    return f if math.isfinite(f) else None


def build_row(
    job: AssetJob,
    prepared: dict[str, Any] | None,
    refined: dict[str, Any] | None,
    measured: dict[str, Any] | None,
    *,
    error: str | None = None,
    failure_mode: str | None = None,
    flow_run_id: str | None = None,
    started_at: float | None = None,
    finished_at: float | None = None,
) -> dict[str, Any]:
    """One catalog row (see :data:`asset2sim.catalog.ROW_COLUMNS`) from the
    stage records of an asset.

    ``error``/``failure_mode`` describe an exception that stopped the chain
    outside the stages (a killed worker, a Prefect timeout, retries exhausted).
    Verdicts come from the metrics stage when it ran (the independent
    measurement), else from the refine post-check; ``failure_mode`` is the
    refine report's, or ``unstable``/``oscillating`` when the metrics stage
    found a failure the post-check did not.
    """
    prepared = prepared or {}
    refined = refined or {}
    measured = measured or {}
    now = time.time()
    row: dict[str, Any] = {
        "asset_id": job.asset_id,
        "category": prepared.get("category") or job.category,
        "prompt": job.prompt,
        "estimator": job.config.get("estimator"),
        "model": job.config.get("model"),
        "reference_scale": job.reference_scale,
        "input_hash": prepared.get("input_hash"),
        "config_hash": prepared.get("config_hash"),
        "refine_config_hash": prepared.get("refine_config_hash"),
        "code_version": job.code_version,
        "flow_run_id": flow_run_id,
        "worker": refined.get("worker") or prepared.get("worker"),
        "started_at": _utc(started_at or now),
        "finished_at": _utc(finished_at or now),
        "source_run": job.run_id,
    }
    stages: dict[str, float] = {}
    if "seconds" in prepared:
        stages["prepare"] = round(float(prepared["seconds"]), 4)

    prev = prepared.get("skip")
    if prev is not None:  # reuse an earlier finished result
        for col in (
            "category", "estimator", "model", "scale", "scale_deviation_pct", "total_mass_kg", "initial_state",
            "penetration_mm", "rest_stable", "d_pos_m", "d_ori_rad", "oscillation_pass", "prompt_alignment",
            "failure_mode", "model_queries", "tokens", "out_dir", "error",
        ):  # fmt: skip
            row[col] = prev.get(col)
        row["status"] = "skipped"
        row["source_run"] = prev.get("source_run") or prev.get("run")
        row["model_queries"] = 0  # nothing was asked in this run
        row["tokens"] = 0
        row["stage_seconds"] = json.dumps(stages)
        row["wall_seconds"] = sum(stages.values())
        return row

    errors: list[str] = []
    mode: str | None = None
    if not prepared.get("ok", False) and prepared:
        mode = prepared.get("failure_mode") or "invalid_input"
        errors.append(f"prepare: {prepared.get('error', '')}")
    report: dict[str, Any] = {}
    if refined.get("status") == "ok":
        value = refined.get("value") or {}
        report = value.get("report") or {}
        row["out_dir"] = value.get("out_dir") or job.out_dir
        stages["refine"] = round(float(refined.get("seconds") or 0.0), 4)
        for k, v in (report.get("stage_seconds") or {}).items():
            stages[f"refine.{k}"] = round(float(v), 4)
        row["scale"] = _num(report.get("scale"))
        row["total_mass_kg"] = _num(report.get("total_mass"))
        row["initial_state"] = json.dumps(report.get("initial_joint_positions") or {}, sort_keys=True)
        row["model_queries"] = int(report.get("model_queries") or 0)
        # the hash the refine function wrote into its completion marker
        row["refine_config_hash"] = report.get("config_hash") or row["refine_config_hash"]
        row["tokens"] = value.get("tokens")
        row["estimator"] = report.get("estimator") or row["estimator"]
        row["model"] = report.get("model") or row["model"]
        row["category"] = report.get("category") or row["category"]
        mode = report.get("failure_mode") or "none"
        pen, rest, osc = _metric(report, "penetration"), _metric(report, "rest_stability"), _metric(report, "oscillation")
        row["penetration_mm"] = _num(pen.get("value")) if pen else None
        if rest:
            row["rest_stable"] = rest.get("passed")
            row["d_pos_m"] = _num((rest.get("details") or {}).get("D_pos_m"))
            row["d_ori_rad"] = _num((rest.get("details") or {}).get("D_ori_rad"))
        if osc:
            row["oscillation_pass"] = osc.get("passed")
    elif refined.get("status") in ("error", "timeout", "crash"):
        stages["refine"] = round(float(refined.get("seconds") or 0.0), 4)
        mode = refined.get("failure_mode") or ("crash" if refined.get("status") == "error" else refined["status"])
        errors.append(f"refine: {refined.get('error_type', '')} {refined.get('error', '')}".strip())
        if refined.get("status") == "crash" and refined.get("log_tail"):
            errors.append(refined["log_tail"][-600:])

    if measured.get("status") == "ok":
        m = measured.get("value") or {}
        stages["metrics"] = round(float(measured.get("seconds") or 0.0), 4)
        for col in ("penetration_mm", "rest_stable", "d_pos_m", "d_ori_rad", "oscillation_pass", "prompt_alignment", "scale_deviation_pct"):
            if m.get(col) is not None:
                row[col] = m[col]
        if mode == "none":
            if m.get("rest_stable") is False:
                mode = "unstable"
                errors.append("metrics stage: rest stability failed although the refine post-check passed")
            elif m.get("oscillation_pass") is False:
                mode = "oscillating"
                errors.append("metrics stage: oscillation failed although the refine post-check passed")
    elif measured.get("status") in ("error", "timeout", "crash"):
        stages["metrics"] = round(float(measured.get("seconds") or 0.0), 4)
        errors.append(f"metrics: {measured.get('error_type', '')} {measured.get('error', '')}".strip())
        if mode in (None, "none"):
            mode = "timeout" if measured.get("status") == "timeout" else "crash"

    if error:
        errors.append(error)
        if mode in (None, "none"):
            mode = failure_mode or "crash"
    if mode is None:
        mode = failure_mode or "crash"
        if not errors:
            errors.append("the asset's task chain produced no result")
    finished_stages = refined.get("status") == "ok" and (measured.get("status") in ("ok", "skipped", None) or not job.evaluate)
    row["status"] = "done" if finished_stages and not error and measured.get("status") not in ("error", "timeout", "crash") else "failed"
    row["failure_mode"] = mode
    row["error"] = "\n".join(e for e in errors if e) or None
    row["stage_seconds"] = json.dumps(stages, sort_keys=True)
    row["wall_seconds"] = round(sum(v for k, v in stages.items() if "." not in k), 4)
    return row


# --------------------------------------------------------------------- Prefect parts


def _retry_on_model_failure(task, task_run, state) -> bool:
    """Prefect ``retry_condition_fn``: retry only :class:`ModelCallFailure`."""
    try:
        state.result(raise_on_failure=True)
    except ModelCallFailure:
        return True
    except Exception:
        return False
    return False


def _exception_failure_mode(exc: BaseException) -> str:
    name = type(exc).__name__
    if isinstance(exc, ModelCallFailure):
        return RETRYABLE_FAILURE
    if isinstance(exc, TimeoutError) or "Timeout" in name:
        return "timeout"
    return "crash"


_PREFECT: dict[str, Any] = {}


def _prefect_objects() -> dict[str, Any]:
    """Build the Prefect tasks and flows once (Prefect imported here)."""
    if _PREFECT:
        return _PREFECT
    from prefect import flow, task
    from prefect.cache_policies import NO_CACHE

    prepare_task = task(prepare_asset, name="prepare", cache_policy=NO_CACHE, persist_result=False)
    refine_task = task(refine_stage, name="refine", cache_policy=NO_CACHE, persist_result=False)
    metrics_task = task(metrics_stage, name="metrics", cache_policy=NO_CACHE, persist_result=False)

    def refine_assets(
        jobs: list[dict[str, Any]],
        catalog_root: str,
        retries: int = 0,
        retry_delay_seconds: float = 10.0,
        parent_flow_run_id: str | None = None,
    ) -> dict[str, Any]:
        """Fan out one task chain per asset on the flow's task runner and append
        each asset's catalog row (under ``catalog_root``) as soon as its chain
        ends; returns the rows and the body's start time and duration."""
        return _refine_assets_body(
            [AssetJob(**j) for j in jobs], Path(catalog_root), retries, retry_delay_seconds, parent_flow_run_id
        )

    def refine_dataset(
        catalog: str = "catalog.yaml",
        dataset: str | None = None,
        workers: int | None = None,
        dask_address: str | None = None,
        ids: list[str] | None = None,
        limit: int | None = None,
        force: bool = False,
    ) -> dict[str, Any]:
        """Refine every asset of ``dataset`` (default: the catalog's) as
        declared in ``catalog``; see :mod:`asset2sim.flows.refine_flow`."""
        return _refine_dataset_body(catalog, dataset, workers, dask_address, ids, limit, force)

    refine_assets.__module__ = __name__
    refine_dataset.__module__ = __name__
    refine_dataset.__qualname__ = "refine_dataset"
    refine_assets.__qualname__ = "refine_assets"
    _PREFECT.update(
        prepare=prepare_task,
        refine=refine_task,
        metrics=metrics_task,
        refine_assets=flow(refine_assets, name=SUBFLOW_NAME, persist_result=False, validate_parameters=False),
        refine_dataset=flow(refine_dataset, name=FLOW_NAME, persist_result=False),
    )
    return _PREFECT


def __getattr__(name: str):
    """``refine_dataset`` (the Prefect flow) and ``refine_assets`` (its Dask
    subflow) are built on first access, so importing this module needs no Prefect."""
    if name in ("refine_dataset", "refine_assets"):
        return _prefect_objects()[name]
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def _dask_task_runner(workers: int | None, address: str | None):
    """A DaskTaskRunner: the scheduler at ``address``, else a local cluster of
    ``workers`` single-threaded worker processes (dashboard on a free port) that report to
    this process's Prefect API."""
    from prefect_dask import DaskTaskRunner

    if address:
        return DaskTaskRunner(address=address)
    n = int(workers or os.cpu_count() or 1)
    env = {}
    api = _prefect_api_url()
    if api:
        env["PREFECT_API_URL"] = api
    return DaskTaskRunner(
        cluster_kwargs={
            "n_workers": n,
            "threads_per_worker": 1,
            "processes": True,
            "dashboard_address": ":0",  # a free port: several clusters may run on one machine
            "env": env,
        }
    )


def _current_flow_run_id() -> str | None:
    try:
        from prefect.runtime import flow_run

        return str(flow_run.id) if flow_run.id else None
    except Exception:
        return None


def _refine_assets_body(
    jobs: list[AssetJob],
    catalog_root: Path,
    retries: int,
    retry_delay_seconds: float,
    parent_flow_run_id: str | None = None,
) -> dict[str, Any]:
    """Returns ``{"rows": [...], "body_started": epoch s, "body_seconds": s}``."""
    from prefect import get_run_logger
    from prefect.futures import as_completed

    objs = _prefect_objects()
    log = get_run_logger()
    flow_run_id = parent_flow_run_id or _current_flow_run_id()
    body_started = time.time()  # the Dask cluster is up once the body runs
    rows: list[dict[str, Any]] = []
    store = ResultCatalog(catalog_root)

    refine_task = objs["refine"].with_options(
        retries=retries,
        retry_delay_seconds=retry_delay_seconds,
        retry_condition_fn=_retry_on_model_failure,
        timeout_seconds=None,
    )
    metrics_task = objs["metrics"]
    starts: dict[str, float] = {}
    prep_futures = {}
    for job in jobs:
        starts[job.asset_id] = time.time()
        prep_futures[objs["prepare"].submit(job)] = job

    chains: dict[Any, tuple[AssetJob, Any, Any]] = {}

    def record(job: AssetJob, prepared, refined, measured, exc: BaseException | None) -> None:
        row = build_row(
            job,
            prepared,
            refined,
            measured,
            error=None if exc is None else f"{type(exc).__name__}: {exc}",
            failure_mode=None if exc is None else _exception_failure_mode(exc),
            flow_run_id=flow_run_id,
            started_at=starts[job.asset_id],
            finished_at=time.time(),
        )
        store.append_row(job.dataset, job.run_id, row)
        rows.append(row)
        log.info(
            "%s: %s (%s) in %.1f s", job.asset_id, row["status"], row["failure_mode"], row["wall_seconds"] or 0.0
        )

    def outcome(fut) -> tuple[Any, BaseException | None]:
        try:
            return fut.result(raise_on_failure=True), None
        except BaseException as exc:  # recorded in the row
            return None, exc

    # the timeout of a non-isolated stage is Prefect's (process isolation has its own)
    for fut in as_completed(list(prep_futures)):
        job = prep_futures[fut]
        prepared, exc = outcome(fut)
        if exc is not None or prepared is None:
            record(job, prepared, None, None, exc)
            continue
        if prepared.get("skip") is not None or not prepared.get("ok"):
            record(job, prepared, None, None, None)
            continue
        opts = {} if job.isolation == "process" else {"timeout_seconds": job.time_limit_seconds}
        rf = refine_task.with_options(**opts).submit(job, prepared) if opts else refine_task.submit(job, prepared)
        mf = (metrics_task.with_options(**opts) if opts else metrics_task).submit(job, prepared, rf)
        chains[mf] = (job, prepared, rf)

    for mf in as_completed(list(chains)):
        job, prepared, rf = chains[mf]
        refined, exc_r = outcome(rf)
        measured, exc_m = outcome(mf) if exc_r is None else (None, None)
        record(job, prepared, refined, measured, exc_r or exc_m)
    return {"rows": rows, "body_started": body_started, "body_seconds": time.time() - body_started}


def _prefect_api_url() -> str | None:
    """The Prefect API this process talks to, for the local cluster's workers.

    With no ``PREFECT_API_URL`` configured, Prefect runs a temporary local
    server for this process; without its address each worker process would
    start a server of its own. None when no address can be found.
    """
    try:
        from prefect.settings import PREFECT_API_URL

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


def _refine_dataset_body(
    catalog: str,
    dataset: str | None,
    workers: int | None,
    dask_address: str | None,
    ids: list[str] | None,
    limit: int | None,
    force: bool,
) -> dict[str, Any]:
    from prefect import get_run_logger

    log = get_run_logger()
    t0 = time.perf_counter()
    body_started_epoch = time.time()
    started = datetime.now(timezone.utc)
    cat = load_catalog(catalog)
    name, _ = cat.dataset(dataset)
    run_id = make_run_id(started)
    jobs = plan_jobs(cat, name, run_id, ids=ids, limit=limit, force=force)
    address = dask_address or os.environ.get("DASK_ADDRESS") or None
    n_workers = workers or cat.config.run.workers
    store = ResultCatalog(cat.catalog_root)
    info = {
        "dataset": name,
        "run": run_id,
        "flow_run_id": _current_flow_run_id(),
        "catalog": str(cat.path),
        "started_at": started.isoformat(),
        "status": "running",
        "assets": len(jobs),
        "estimator": cat.config.estimator.name,
        "model": cat.config.estimator.model,
        "refine_config_hash": cat.refine_config().config_hash(),
        "workers": None if address else n_workers,
        "dask_address": address,
        "code_version": jobs[0].code_version if jobs else code_version(),
    }
    store.write_run_info(name, run_id, info)
    log.info(
        "run %s: %d assets of dataset %s on %s",
        run_id,
        len(jobs),
        name,
        address or f"a local Dask cluster ({n_workers} workers)",
    )
    t_fan, t_fan_epoch = time.perf_counter(), time.time()
    timing = {"dask_startup_seconds": 0.0, "assets_seconds": 0.0, "dask_teardown_seconds": 0.0}
    if jobs:
        sub = _prefect_objects()["refine_assets"].with_options(task_runner=_dask_task_runner(n_workers, address))
        out = sub(
            [asdict(j) for j in jobs],
            str(cat.catalog_root),
            retries=cat.config.estimator.retries if cat.config.estimator.name != "offline" else 0,
            retry_delay_seconds=cat.config.estimator.retry_delay_seconds,
            parent_flow_run_id=info["flow_run_id"],
        )
        fan_seconds = time.perf_counter() - t_fan
        timing["dask_startup_seconds"] = max(0.0, out["body_started"] - t_fan_epoch)
        timing["assets_seconds"] = out["body_seconds"]
        timing["dask_teardown_seconds"] = max(0.0, fan_seconds - timing["dask_startup_seconds"] - out["body_seconds"])
    t_track = time.perf_counter()

    from asset2sim import queries

    df = store.read(name, run_id)
    run_out = cat.output_root / name / run_id
    summary = queries.run_summary(df)
    summary.update(
        dataset=name,
        run=run_id,
        catalog_root=str(cat.catalog_root),
        output_dir=str(run_out),
        **timing,
    )
    artifacts: dict[str, Path] = {}
    if not df.empty:
        from asset2sim import tracking as _tracking

        artifacts = _tracking.write_run_artifacts(df, run_out, title=f"{name} / {run_id}")
    tracking_error = None
    mlflow_run_id = None
    if cat.config.tracking.enabled:
        try:
            from asset2sim import tracking

            mlflow_run_id = tracking.log_flow_run(
                df,
                summary,
                params={
                    "dataset": name,
                    "run": run_id,
                    "estimator": cat.config.estimator.name,
                    "model": cat.config.estimator.model or "",
                    "config_hash": info["refine_config_hash"],
                    "workers": n_workers if not address else "",
                    "dask_address": address or "",
                    "code_version": info["code_version"],
                    "assets": len(jobs),
                },
                artifacts=artifacts,
                project_root=cat.project_root,
                settings=cat.config.tracking,
                tags={"prefect.flow_run_id": info["flow_run_id"] or "", "asset2sim.run": run_id},
            )
        except Exception as exc:  # the catalog is the record; tracking must not lose it
            tracking_error = f"{type(exc).__name__}: {exc}"
            log.warning("MLflow tracking failed: %s", tracking_error)
    body_seconds = time.perf_counter() - t0
    summary.update(
        mlflow_run_id=mlflow_run_id,
        tracking_error=tracking_error,
        tracking_seconds=time.perf_counter() - t_track,
        flow_body_seconds=body_seconds,
        flow_started_epoch=body_started_epoch,
        artifacts={k: str(v) for k, v in artifacts.items()},
    )
    info.update(
        status="finished",
        finished_at=datetime.now(timezone.utc).isoformat(),
        mlflow_run_id=mlflow_run_id,
        summary={k: v for k, v in summary.items() if isinstance(v, (int, float, str, type(None)))},
    )
    store.write_run_info(name, run_id, info)
    return summary


# --------------------------------------------------------------------------- driver


def run_refine_flow(
    catalog: str | Path = "catalog.yaml",
    dataset: str | None = None,
    workers: int | None = None,
    dask_address: str | None = None,
    *,
    ids: list[str] | None = None,
    limit: int | None = None,
    force: bool = False,
) -> dict[str, Any]:
    """Run :data:`refine_dataset` in this process (what ``make flow`` does).

    Returns the run summary (counts, pass rates, failure modes, paths, MLflow
    run id, timings in s: ``dask_startup_seconds``, ``assets_seconds`` (the
    fan-out with the cluster up), ``dask_teardown_seconds``,
    ``tracking_seconds`` (summary, plot, MLflow), ``flow_body_seconds``, and
    ``flow_started_epoch``). Call from a ``__main__``-guarded program:
    the local Dask cluster starts worker processes.

    Raises:
        CatalogError: invalid catalog or manifest (before any asset runs).
    """
    params = flow_parameters(catalog, dataset, workers, dask_address)
    load_catalog(params["catalog"])  # fail early, before Prefect starts
    flow_obj = _prefect_objects()["refine_dataset"]
    return flow_obj(**params, ids=ids, limit=limit, force=force)


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
