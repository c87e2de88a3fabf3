"""Machine-readable results: metric values, refine reports, failure modes."""

from __future__ import annotations

from typing import Any, Literal

from asset2sim.schemas import Strict
from asset2sim.schemas.overlay import RootMount
from asset2sim.schemas.request import RequestFindings

#: Fixed vocabulary of per-asset failure modes (pipeline catalog, reports).
FailureMode = Literal[
    "none", "invalid_input", "estimator_failure", "invalid_overlay", "unresolved_penetration", "unstable", "oscillating",
    "joint_not_held", "blocked_joint", "not_operable", "not_robust_at_rest", "task_failed", "implausible_force", "timeout",
    "crash", "invalid_manifest_row", "request_not_met",
]
FAILURE_MODES: tuple[str, ...] = FailureMode.__args__  # type: ignore[attr-defined]


class MetricResult(Strict):
    """One measured metric.

    ``value`` in ``unit``; ``passed`` is None when the metric has no threshold;
    ``threshold`` human-readable; ``details`` metric-specific (JSON-able).
    """

    name: str
    value: float | None
    unit: str
    passed: bool | None = None
    threshold: str = ""
    details: dict[str, Any] = {}
    engine: str = "pybullet"


class EscalationRound(Strict):
    """One post-check round: what was measured and what was changed."""

    round: int
    metrics: list[MetricResult]
    changes: dict[str, dict[str, float]] = {}
    """joint -> {parameter: new value}"""
    reason: str = ""
    words_kept: list[str] = []
    """Changes this round's step asked and a word of the request about the part's motion kept from it
    (``tasks/tune/word_guard.py``), one line each."""


class StateRefinement(Strict):
    """What state refinement did (penetrations in m, states rad/m)."""

    requested: dict[str, float]
    result: dict[str, float]
    phi_requested: float
    phi_result: float
    evaluations: int
    method: str
    worst_pairs: list[dict[str, Any]] = []
    collision_changes: list[str] = []
    seconds: float = 0.0
    model_queries: int = 0
    """Model calls made by the state search (joint proposals when it stalled)."""
    room_made: dict[str, float] = {}
    """joint -> opening fraction of each joint the request left closed that the
    search opened to make room (:func:`asset2sim.tasks.state.refine_state.joints_in_the_way`)."""


class SolverAid(Strict):
    """A solver parameter an export writes beyond the files' physics (``asset2sim.engines.mjcf.aids``): its ``kind``,
    the joint or geom (``element``) it is written on, the attributes ``written``, the pre-flight ``criterion`` that
    asked for it with its ``measure`` (the predicted quantity over its bound: above 1 the aid is needed) and its
    ``effect`` on the part's dynamics."""

    kind: str
    element: str
    written: dict[str, str]
    criterion: str
    measure: float
    effect: str = ""
    file: str = "mjcf"


class RefineReport(Strict):
    """Contents of ``report.json``."""

    asset_id: str
    source: str
    prompt: str
    category: str | None
    task: str | None = None
    """The manipulation task refine was given (``--task``): its post-check executed it (tiers task, force)."""
    version: str
    input_hash: str
    config_hash: str
    estimator: str
    model: str | None = None
    model_queries: int = 0
    model_tokens: int = 0
    """Tokens reported by the model API (0 when unknown or offline)."""
    model_cost_usd: float | None = None
    model_seconds: float = 0.0
    """Wall time in model calls, s."""
    scale: float
    total_mass: float
    """kg"""
    initial_joint_positions: dict[str, float]
    closed_positions: dict[str, float] = {}
    """Geometric closed end of each movable joint (rad/m, output units)."""
    closed_ends: dict[str, dict[str, float | None]] = {}
    """The closed end each check used, per movable joint, decided once: ``q_closed`` (rad/m, output units),
    ``direction`` (+1 when opening increases q), ``open_range`` (rad/m), ``lower`` / ``upper`` (None: unbounded); an output read back
    (``asset2sim evaluate``) is checked with these."""
    requested_bands: dict[str, str] = {}
    opening_fractions: dict[str, float] = {}
    """|q - q_closed| / largest opening the range allows from q_closed, per joint,
    at the written initial state (the measure the state bands use)."""
    state: StateRefinement | None = None
    metrics: list[MetricResult] = []
    parity: list[dict[str, Any]] = []
    """One row per engine of ``--engines`` (``tasks.parity.parity_table``)."""
    escalation: list[EscalationRound] = []
    validation: list[dict[str, Any]] = []
    failure_mode: str = "none"
    stage_seconds: dict[str, float] = {}
    notes: list[str] = []
    request: RequestFindings | None = None
    """The request's findings (:func:`asset2sim.tasks.synthesize.request_findings.findings`)."""
    mounting: RootMount | None = None
    """How the root was held in every check (``tasks.interpret.mounting``);
    None in reports written before it was recorded (free-standing)."""
    readiness: dict[str, bool | None] = {}
    """Interaction-readiness per tier (``tasks.check.verdict.TIERS``): True
    pass, False fail, None not measured; ``failure_mode`` is the first failing tier's."""
    design_changes: list[str] = []
    """What stability by design changed and why (``tasks.state.stability``)."""
    solver_aids: list[SolverAid] = []
    """The solver aids the exports wrote, each with its criterion (read back from the exported files)."""
    media: Literal["done", "deferred", "off"] | None = None
    """The media phase (renders in ``views/``, sweep clips in ``clips/``, ``report.html``): ``done``;
    ``deferred`` (``refine --defer-media``, a flow with ``extras: deferred``: ``asset2sim report OUT`` makes
    it); ``off`` (``--no-extras``); None in reports written before the phases were recorded."""

    def metric(self, name: str) -> MetricResult | None:
        return next((m for m in self.metrics if m.name == name), None)
