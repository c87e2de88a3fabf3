"""The evaluation of one asset as handed over: the contents of ``evaluation.json``.

Made by :func:`asset2sim.tasks.evaluation.evaluate.evaluate_asset`; read by
the flows (catalog rows), the benchmark records and
:func:`asset2sim.tasks.evaluation.report_html.write_report`, which renders it.
"""

from __future__ import annotations

from typing import Any

from pydantic import BaseModel, ConfigDict, Field, PrivateAttr

from asset2sim.schemas.report import MetricResult

#: Version of the ``evaluation.json`` layout.
EVALUATION_VERSION = "1"


class Evaluation(BaseModel):
    """Contents of ``evaluation.json``.

    ``metrics``: every metric result (one per engine for the simulator metrics).
    ``passed``: every metric that has a verdict passed. ``failures``: names of
    the failed metrics (``name@engine``). ``scale`` dimensionless (relative to
    the raw input); ``initial_state`` rad/m; ``seconds`` wall time of the
    evaluation without report writing.

    Not serialised: the raw measurements per engine (``_runs``, engine ->
    :class:`asset2sim.tasks.evaluation.engine_run.EngineRun`) and the context
    (``_context``, :class:`asset2sim.tasks.evaluation.eval_context.Context`)
    the report draws from.
    """

    model_config = ConfigDict(extra="forbid")
    version: str = EVALUATION_VERSION
    asset_id: str
    urdf: str
    method: str | None = None
    prompt: str | None = None
    reference: str | None = None
    category: str | None = None
    scale: float | None = None
    scale_source: str = ""
    engines: list[str] = Field(default_factory=list)
    seed: int = 0
    initial_state: dict[str, float] = Field(default_factory=dict)
    initial_state_source: str = ""
    task_joints: list[str] = Field(default_factory=list)
    closed_positions: dict[str, dict[str, float]] = Field(default_factory=dict)
    metrics: list[MetricResult] = Field(default_factory=list)
    passed: bool = False
    failures: list[str] = Field(default_factory=list)
    notes: list[str] = Field(default_factory=list)
    seconds: float = 0.0
    _runs: dict[str, Any] = PrivateAttr(default_factory=dict)
    _context: Any = PrivateAttr(default=None)

    def metric(self, name: str, engine: str | None = None) -> MetricResult | None:
        """The first metric called ``name`` (of ``engine`` when given; a
        metric of engine ``"none"`` matches any engine)."""
        for m in self.metrics:
            if m.name == name and (engine is None or m.engine in (engine, "none")):
                return m
        return None
