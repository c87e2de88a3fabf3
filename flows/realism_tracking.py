"""MLflow tracking of realism scores: one run per scoring, the Bradley-Terry scores of every method as metrics,
the ratings table as an artifact; always through an ``MlflowClient`` of the given tracking URI, never the
process-wide one."""

from __future__ import annotations

import json
import re
from pathlib import Path
from urllib.parse import unquote, urlparse

from asset2sim.flows.tracking import client_run
from asset2sim.schemas.realism import MethodScore
from asset2sim.apps.realism.bradley_terry import PRIOR_GAMES
from asset2sim import library_dirs

#: The default experiment of realism runs.
REALISM_EXPERIMENT = "asset2sim-realism"
#: The metrics logged per method (fields of :class:`MethodScore`).
SCORE_METRICS = ("strength", "ci_low", "ci_high", "elo", "comparisons", "wins")


def metric_key(source: str, method: str, field: str) -> str:
    """The MLflow metric name of ``field`` of ``method``'s score from ``source``: ``<source>/<method>/<field>``,
    characters MLflow refuses (anything but letters, digits, ``_ - . /`` and space; ``:`` of ``defect:<name>``
    included, which Windows stores cannot hold) replaced by ``_``."""
    def clean(text: str) -> str:
        return re.sub(r"[^\w.\- ]", "_", text).strip(".") or "_"

    return f"{clean(source)}/{clean(method)}/{field}"


def log_realism_scores(scores: list[MethodScore], *, tracking_uri: str, experiment: str = REALISM_EXPERIMENT,
                       ratings_parquet: Path | None = None, run_name: str | None = None) -> str:
    """Log ``scores`` as one MLflow run in ``experiment`` (created when missing) of the store at
    ``tracking_uri``; returns the run id.

    Logged: metrics ``<source>/<method>/<field>`` for each field of :data:`SCORE_METRICS` (:func:`metric_key`;
    ``strength`` dimensionless log strength with its 95 % interval ``ci_low`` / ``ci_high``, ``elo`` points,
    ``comparisons`` and ``wins`` counts); params ``sources``, ``methods``, ``model`` (Bradley-Terry),
    ``prior_games``, ``interval``; the scores as ``realism_scores.json``; ``ratings_parquet`` (when given) as
    an artifact. A failure while logging marks the run FAILED and is raised.

    Raises:
        ValueError: no scores, or ``ratings_parquet`` missing.
        mlflow.exceptions.MlflowException: the store refuses the run.
    """
    library_dirs.configure()  # before MLflow's first import: no telemetry file or report
    from mlflow.tracking import MlflowClient

    if not scores:
        raise ValueError("no realism scores to log")
    if ratings_parquet is not None and not Path(ratings_parquet).is_file():
        raise ValueError(f"{ratings_parquet}: no such ratings table")
    client = MlflowClient(tracking_uri=tracking_uri)  # never the process-wide URI
    sources = sorted({s.source for s in scores})
    # artifacts of a new experiment of a SQLite store beside the database (``<db folder>/mlruns/<experiment>``), not
    # under the working folder; None (MLflow's default) for other stores
    parsed, location = urlparse(tracking_uri), None
    if parsed.scheme == "sqlite" and parsed.path:
        location = (Path(unquote(parsed.path)).resolve().parent / "mlruns" / re.sub(r"[^\w.-]", "_", experiment)).as_uri()
    with client_run(client, experiment, location, run_name or f"realism-{'-'.join(sources)}",
                    tags={"asset2sim.kind": "realism"}) as run_id:
        for key, value in {"sources": ",".join(sources), "methods": ",".join(sorted({s.method for s in scores})),
                           "model": "Bradley-Terry (MAP, virtual games prior)", "prior_games": PRIOR_GAMES,
                           "interval": "95% Wald, observed information, sum-to-zero"}.items():
            client.log_param(run_id, key, value)
        for s in scores:
            for field in SCORE_METRICS:
                client.log_metric(run_id, metric_key(s.source, s.method, field), float(getattr(s, field)))
        client.log_text(run_id, json.dumps([s.model_dump() for s in scores], indent=2), "realism_scores.json")
        if ratings_parquet is not None:
            client.log_artifact(run_id, str(ratings_parquet))
    return run_id
