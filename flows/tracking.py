"""Experiment tracking of flow runs with MLflow (one run per flow run, one nested run per asset; new
experiments keep their artifacts in ``<project>/mlruns/<experiment>``), and the run's artifacts.
"""

from __future__ import annotations

import contextlib
import io
import json
import math
import os
import time
from datetime import datetime
from pathlib import Path
from typing import Any, Iterator

from asset2sim import atomic, library_dirs
from asset2sim.flows.catalog import NOTHING_TO_DO
from asset2sim.flows.catalog_config import TrackingSettings
from asset2sim.flows.queries import failure_modes, run_summary
from asset2sim.schemas.report import FAILURE_MODES
from asset2sim.inert import csv_text, plot_text, shorten

#: Columns of the run's summary table, in order.
SUMMARY_COLUMNS = (
    "asset_id", "category", "status", "failure_mode", "scale", "total_mass_kg", "penetration_mm",
    "rest_stable", "d_pos_m", "d_ori_rad", "oscillation_pass", "prompt_alignment", "scale_deviation_pct",
    "model_queries", "tokens", "wall_seconds", "initial_state", "out_dir", "error",
)  # fmt: skip


def resolve_tracking_uri(project_root: Path | str, configured: str | None) -> str:
    """``MLFLOW_TRACKING_URI`` if set, else ``configured``, else the project's SQLite store."""
    return os.environ.get("MLFLOW_TRACKING_URI") or configured or "sqlite:///" + str((Path(project_root) / "mlflow.db").resolve())


def mlflow_client(tracking_uri: str):
    """An ``MlflowClient`` of the store at ``tracking_uri`` (never the process-wide URI), MLflow first imported after
    :func:`asset2sim.library_dirs.configure` (no telemetry file or report)."""
    library_dirs.configure()
    from mlflow.tracking import MlflowClient

    return MlflowClient(tracking_uri=tracking_uri)


def new_figure(width: float, height: float):
    """``(fig, ax)``: a matplotlib Figure ``width`` x ``height`` in at 100 dpi (the Agg backend) with one Axes."""
    library_dirs.configure()  # before matplotlib's first import
    import matplotlib

    matplotlib.use("Agg", force=False)
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width, height), dpi=100)
    return fig, fig.add_subplot(1, 1, 1)


def write_png(path: Path, fig) -> Path:
    """``fig`` written atomically as a PNG at ``path``."""
    buf = io.BytesIO()
    fig.savefig(buf, format="png")
    return atomic.write_bytes(path, buf.getvalue())


def failure_mode_figure(df, title: str):
    """A matplotlib Figure: stacked bars of failure modes per category (assets; ``none`` green)."""
    table = failure_modes(df, by="category")
    table = table.drop(index="total", errors="ignore")
    modes = [m for m in FAILURE_MODES if m in table.columns and table[m].sum() > 0]
    fig, ax = new_figure(max(5.0, 0.9 * len(table) + 2.5), 4.0)
    from matplotlib.ticker import MaxNLocator

    colors = {
        "none": "#4caf50", "invalid_input": "#9e9e9e", "estimator_failure": "#795548",
        "invalid_overlay": "#ff9800", "unresolved_penetration": "#e91e63", "unstable": "#f44336",
        "oscillating": "#9c27b0", "timeout": "#3f51b5", "crash": "#212121",
    }  # fmt: skip
    bottom = [0] * len(table)
    x = list(range(len(table)))
    for m in modes:
        vals = [int(v) for v in table[m]]
        ax.bar(x, vals, bottom=bottom, label=m, color=colors.get(m))
        bottom = [b + v for b, v in zip(bottom, vals)]
    ax.set_xticks(x)
    ax.set_xticklabels([plot_text(shorten(i, 40)) for i in table.index], rotation=30, ha="right", fontsize=8)  # names: never mathtext
    ax.yaxis.set_major_locator(MaxNLocator(integer=True))
    ax.set_ylabel("assets")
    ax.set_title(plot_text(title))
    if modes:
        ax.legend(fontsize=7, loc="upper right")
    fig.tight_layout()
    return fig


def write_run_artifacts(df, out_dir: Path | str, title: str) -> dict[str, Path]:
    """Write ``summary.csv`` (:data:`SUMMARY_COLUMNS` by asset id), ``summary.json`` (:func:`asset2sim.flows.queries.run_summary`)
    and ``failure_modes.png`` into ``out_dir`` atomically; returns name -> path."""
    out_dir = Path(out_dir)
    table = df.sort_values("asset_id")[[c for c in SUMMARY_COLUMNS if c in df.columns]].reset_index(drop=True)
    paths = {"summary.csv": atomic.write_text(out_dir / "summary.csv", csv_text(table))}
    paths["summary.json"] = atomic.write_json(out_dir / "summary.json", atomic.jsonable(run_summary(df)))
    paths["failure_modes.png"] = write_png(out_dir / "failure_modes.png", failure_mode_figure(df, title))
    return paths


def flow_metrics(summary: dict[str, Any]) -> dict[str, float]:
    """MLflow metrics of a run summary: finite numbers only; failure-mode
    counts as ``failures_<mode>``."""
    out: dict[str, float] = {}
    for k, v in summary.items():
        if k == "failure_modes" and isinstance(v, dict):
            for m, c in v.items():
                out[f"failures_{m}"] = float(c)
        elif isinstance(v, (int, float)) and math.isfinite(float(v)):  # booleans as 1.0 / 0.0
            out[k] = float(v)
    return out


def run_outcome(summary: dict[str, Any]) -> str:
    """``nothing_to_do`` when the run refined no asset (every row skipped: reused from an earlier run), else
    ``worked``: what ``_run.json`` and the MLflow run say, so ``asset2sim failures`` passes over such a run."""
    done, skipped, failed = (int(summary.get(k) or 0) for k in ("done", "skipped", "failed"))
    return NOTHING_TO_DO if skipped > 0 and not done and not failed else "worked"


def _asset_metrics(row: dict[str, Any]) -> dict[str, float]:
    out = {}
    for k in ("scale", "total_mass_kg", "penetration_mm", "d_pos_m", "d_ori_rad", "prompt_alignment",
              "scale_deviation_pct", "model_queries", "tokens", "wall_seconds"):  # fmt: skip
        with contextlib.suppress(TypeError, ValueError):
            if math.isfinite(f := float(row.get(k))):
                out[k] = f
    for k in ("rest_stable", "oscillation_pass"):
        v = row.get(k)
        if v is None or (isinstance(v, float) and math.isnan(v)):
            continue
        out[k] = float(bool(v))
    out["all_checks_pass"] = float(row.get("failure_mode") == "none")
    return out


def log_flow_run(
    df,
    summary: dict[str, Any],
    *,
    params: dict[str, Any],
    artifacts: dict[str, Path],
    project_root: Path | str,
    settings: TrackingSettings,
    tags: dict[str, str],
    started_at: float | str | None,
    ended_at: float,
) -> str:
    """Log one flow run and a nested run per asset row of ``df`` (its own start and end; for an asset refined in
    this run, :func:`asset_artifacts`) to MLflow; returns the MLflow run id.

    ``summary``: :func:`asset2sim.flows.queries.run_summary` plus timings (s); ``params`` stringified (cut at
    500 characters); ``artifacts``: name -> file; ``project_root``: where the default store lives; ``settings``:
    :class:`asset2sim.flows.catalog_config.TrackingSettings`; ``started_at`` / ``ended_at``: the flow run's start and
    end (epoch s; the start may be ISO 8601 text).

    Raises:
        ImportError: MLflow is not installed (``pip install asset2sim[pipeline]``).
        mlflow.exceptions.MlflowException: the store refused a write.
    """
    project_root = Path(project_root)
    client = mlflow_client(resolve_tracking_uri(project_root, settings.uri))
    from mlflow.entities import Metric, Param, RunTag

    exp = client.get_experiment_by_name(settings.experiment)
    art = project_root / settings.artifact_root / settings.experiment.replace("/", "_")
    exp_id = exp.experiment_id if exp else client.create_experiment(settings.experiment, artifact_location=art.resolve().as_uri())
    if exp is None or EXPERIMENT_KIND_TAG not in (exp.tags or {}):  # MLflow 3 opens other kinds on a GenAI overview
        client.set_experiment_tag(exp_id, EXPERIMENT_KIND_TAG, EXPERIMENT_KIND)
    ts = int(time.time() * 1000)
    run_name = f"{params.get('dataset', '')}/{params.get('run', '')}".strip("/") or None
    rid = client.create_run(exp_id, run_name=run_name, start_time=_ms(started_at) or ts,
                            tags={"asset2sim.kind": "flow_run", "asset2sim.outcome": run_outcome(summary), **tags}).info.run_id
    try:
        client.log_batch(
            rid,
            metrics=[Metric(k, v, ts, 0) for k, v in flow_metrics(summary).items()],
            params=[Param(k, str(v)[:500]) for k, v in params.items() if v is not None],
            tags=[RunTag("failure_modes", json.dumps(summary.get("failure_modes", {}), sort_keys=True))],
        )
        for path in artifacts.values():
            client.log_artifact(rid, str(path))
        for row in df.to_dict("records"):
            child = client.create_run(
                exp_id,
                run_name=str(row["asset_id"]),
                start_time=_asset_start(row) or ts,
                tags={"mlflow.parentRunId": rid, "asset2sim.kind": "asset", "asset_id": str(row["asset_id"]),
                      **{k: str(row.get(k) or "") for k in ("category", "status", "failure_mode")}},
            ).info.run_id
            client.log_batch(
                child,
                metrics=[Metric(k, v, ts, 0) for k, v in _asset_metrics(row).items()],
                params=[Param(k, str(row.get(k) or "")[:500]) for k in ("prompt", "estimator", "input_hash", "config_hash")],
            )
            if row.get("status") != "skipped":  # a reused asset's files belong to the run that made them
                for path in asset_artifacts(row.get("out_dir")):
                    client.log_artifact(child, str(path), artifact_path=_artifact_dir(path, row["out_dir"]))
            client.set_terminated(child, "FINISHED", end_time=_ms(row.get("finished_at")) or ts)
    except BaseException:
        client.set_terminated(rid, "FAILED", end_time=int(time.time() * 1000))
        raise
    client.set_terminated(rid, "FINISHED", end_time=_ms(ended_at) or int(time.time() * 1000))
    return rid


#: The experiment tag by which the MLflow 3 UI chooses its first page, and the kind that opens on the runs table.
EXPERIMENT_KIND_TAG, EXPERIMENT_KIND = "mlflow.experimentKind", "custom_model_development"
#: An asset's files logged with its MLflow run (relative to its output folder; globs).
ASSET_ARTIFACTS = ("report.json", "report.html", "evaluation.json", "timings.json", "views/*.png", "clips/clips.json",
                   "clips/*.webm", "clips/*.png")
"""The report's videos and posters (``clips/``) travel with it, so ``report.html`` plays them in MLflow's artifact view."""


def asset_artifacts(out_dir: Any) -> list[Path]:
    """The files of :data:`ASSET_ARTIFACTS` present in the local output folder ``out_dir`` (none for an
    object-store URI, a missing folder or None)."""
    if not out_dir or "://" in str(out_dir) or not Path(str(out_dir)).is_dir():
        return []
    root = Path(str(out_dir))
    return [p for pattern in ASSET_ARTIFACTS for p in sorted(root.glob(pattern)) if p.is_file() and not p.is_symlink()]


def _artifact_dir(path: Path, out_dir: Any) -> str | None:
    """The artifact folder of ``path`` inside its output folder (None: the run's root)."""
    rel = path.parent.relative_to(Path(str(out_dir)))
    return None if str(rel) == "." else rel.as_posix()


def _asset_start(row: dict[str, Any]) -> int | None:
    """Epoch ms an asset's MLflow run starts at: its end less the wall time of its own stages (``wall_seconds``), so
    the run spans the asset's work and not the time it waited for a worker; its recorded start when either is
    unknown."""
    end, wall = _ms(row.get("finished_at")), row.get("wall_seconds")
    try:
        wall = float(wall)
    except (TypeError, ValueError):
        wall = math.nan
    if end is None or not math.isfinite(wall) or wall < 0:
        return _ms(row.get("started_at"))
    return max(end - int(round(wall * 1000)), _ms(row.get("started_at")) or 0)


def _ms(when: Any) -> int | None:
    """Epoch milliseconds of ``when`` (epoch s, a datetime, an ISO text or a pandas Timestamp); None when unknown."""
    try:  # None, a text that is no time, NaT: unknown
        when = datetime.fromisoformat(when) if isinstance(when, str) else when
        v = float(when.timestamp()) if hasattr(when, "timestamp") else float(when)
    except (TypeError, ValueError, OverflowError):
        return None
    return int(round(v * 1000)) if math.isfinite(v) else None


@contextlib.contextmanager
def client_run(client: Any, experiment: str, artifact_location: str | None, run_name: str,
               tags: dict[str, str] | None = None) -> Iterator[str]:
    """One MLflow run through ``client`` (an ``MlflowClient`` of one store, never the process-wide URI) in
    ``experiment`` (created with ``artifact_location`` when missing): yields the run id; the run ends FINISHED, or
    FAILED when the block raises (the error is raised again)."""
    found = client.get_experiment_by_name(experiment)
    exp_id = found.experiment_id if found else client.create_experiment(experiment, artifact_location=artifact_location)
    run_id = client.create_run(exp_id, run_name=run_name, tags=dict(tags or {})).info.run_id
    try:
        yield run_id
    except BaseException:
        client.set_terminated(run_id, "FAILED")
        raise
    client.set_terminated(run_id)
