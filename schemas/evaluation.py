"""The evaluation of one asset: the contents of ``evaluation.json``."""

from __future__ import annotations

from typing import Any

from pydantic import PrivateAttr

from asset2sim.schemas import Strict
from asset2sim.schemas.report import MetricResult

#: Version of the ``evaluation.json`` layout.
EVALUATION_VERSION = "1"


class Evaluation(Strict):
    """Contents of ``evaluation.json``: ``metrics`` (one per engine for the
    simulator metrics; a refine's are its ``report.json``'s), ``failure_mode`` (the verdict: a refine's is its
    ``report.json``'s, never decided again; else the readiness of ``metrics``), ``passed`` (ready), ``failures``
    (the failing checks ``name@engine`` of the verdict's tiers), ``initial_state`` rad/m, ``seconds`` wall time. Not
    serialised: ``_runs`` (engine -> the runs the checks were graded from) and ``_context`` (the evaluated files), for
    the report."""

    version: str = EVALUATION_VERSION
    asset_id: str
    urdf: str
    method: str | None = None
    prompt: str | None = None
    reference: str | None = None
    category: str | None = None
    scale: float | None = None
    scale_source: str = ""
    engines: list[str] = []
    seed: int = 0
    initial_state: dict[str, float] = {}
    initial_state_source: str = ""
    task_joints: list[str] = []
    closed_positions: dict[str, dict[str, float]] = {}
    metrics: list[MetricResult] = []
    passed: bool = False
    failure_mode: str | None = None
    failures: list[str] = []
    notes: list[str] = []
    seconds: float = 0.0
    _runs: dict[str, Any] = PrivateAttr(default_factory=dict)
    _context: Any = PrivateAttr(default=None)

    def metric(self, name: str, engine: str | None = None) -> MetricResult | None:
        """The first metric called ``name`` (of ``engine`` when given; a
        metric of engine ``"none"`` matches any engine)."""
        return next((m for m in self.metrics if m.name == name and (engine is None or m.engine in (engine, "none"))), None)
