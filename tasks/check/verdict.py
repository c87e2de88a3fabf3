"""The failure mode of an asset (vocabulary :data:`asset2sim.schemas.report.FAILURE_MODES`)
and its interaction-readiness (:func:`readiness`: no measured metric of any
tier fails, in any engine), decided in one place for the refine report, the
terminal, ``report.html`` and the catalog (``docs/design/metrics.md``, section 3a); why it failed, in
sentences: :mod:`.failure_reasons`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

#: Phi (mm) above which penetration counts as unresolved (refine's verdict).
UNRESOLVED_PENETRATION_MM = 5.0
#: Metrics read against :data:`UNRESOLVED_PENETRATION_MM` (their own pass threshold is the writer's tolerance):
#: metric -> the detail read instead of the value when present (a child inside its parent beyond the modelled pose).
PENETRATION_METRICS = {"penetration": None, "parent_child_penetration": "beyond_modelled_mm"}
#: What a catalog row without a failure mode counts as.
MISSING_FAILURE_MODE = "crash"
#: Stage statuses of a stage that ran and failed (``flows.isolation``).
FAILED_STATUSES = ("error", "timeout", "crash")
#: Mode of an asset whose manifest row cannot be used (the row's ``MANIFEST_*`` code is in the error text).
INVALID_MANIFEST_ROW = "invalid_manifest_row"


#: Modes of a run that stopped before any tier was measured: no "why it failed" sentence, the error line names the
#: code and the file instead (``refine`` and ``evaluate`` exit 1 or 2; a flow's catalog row keeps the error text).
STOPPED_MODES: tuple[str, ...] = ("invalid_input", "estimator_failure", "invalid_overlay", "timeout", "crash",
                                  INVALID_MANIFEST_ROW)

#: Interaction-readiness tiers: tier -> (metrics that decide it, failure mode when one fails), in
#: reporting order. Penetration fails above :data:`UNRESOLVED_PENETRATION_MM` (no SPEC threshold), the SPEC's Phi
#: and a child inside its parent alike (the pairs Phi skips: a door opened through a bar of its own body).
TIERS: dict[str, tuple[tuple[str, ...], str]] = {
    "rest": (("rest_stability", "settle_tilt", "divergence", "ground_penetration", "oscillation", "state_hold"), "unstable"),
    "penetration": (tuple(PENETRATION_METRICS), "unresolved_penetration"),
    "sweep": (("joint_sweep",), "blocked_joint"),
    "operability": (("operability",), "not_operable"),
    "robust_rest": (("robust_rest",), "not_robust_at_rest"),
    "task": (("task_execution",), "task_failed"),
    "force": (("operating_force",), "implausible_force"),
    "request": (("request_met",), "request_not_met"),  # as asked (tasks/check/as_asked.py), after the physical tiers
}


#: Rest-tier metrics of a joint that leaves its state (the object itself at rest).
HOLD_METRICS: tuple[str, ...] = ("state_hold",)


@dataclass
class Readiness:
    """The interaction-readiness verdict: ``tiers`` tier -> True / False / None
    (not measured); ``failures`` ``metric@engine`` in tier order;
    ``failure_mode`` the first failing tier's mode, ``none`` when ready."""

    tiers: dict[str, bool | None]
    failures: list[str]
    failure_mode: str

    @property
    def ready(self) -> bool:
        """No tier fails (tiers not measured do not count)."""
        return not any(v is False for v in self.tiers.values())

    def line(self) -> str:
        """One line, the words every command and report uses (:func:`verdict_line`): ``interaction-ready (rest pass,
        ...)`` or ``NOT READY: not_robust_at_rest (robust_rest@pybullet, ...; rest pass, ..., robust_rest FAIL, ...)``."""
        return verdict_line(self.failure_mode, self.tiers, self.failures)

    def short(self) -> str:
        """:meth:`line` without the tiers: ``interaction-ready`` or ``NOT READY: not_robust_at_rest (robust_rest@pybullet)``."""
        return verdict_line(self.failure_mode, {}, self.failures)


def tiers_text(tiers: dict[str, bool | None]) -> str:
    """``rest pass, sweep FAIL, task n/a``: each readiness tier with its verdict, in order."""
    return ", ".join(f"{t} {'pass' if v else ('FAIL' if v is False else 'n/a')}" for t, v in tiers.items())


def verdict_line(failure_mode: str, tiers: dict[str, bool | None], failures: list[str] | tuple[str, ...] = ()) -> str:
    """The verdict in the one vocabulary of the terminal (``refine``, ``demo``, ``evaluate``, ``audit``),
    ``report.html`` and ``audit.md``: ``interaction-ready`` when ``failure_mode`` is ``none``, else ``NOT READY:
    <failure mode>``, then in parentheses the failing checks (``metric@engine``) and the ``tiers``
    (:func:`tiers_text`) when given."""
    inside = "; ".join(x for x in (", ".join(failures), tiers_text(tiers)) if x)
    word = "interaction-ready" if failure_mode == "none" else f"NOT READY: {failure_mode}"
    return f"{word} ({inside})" if inside else word


def metric_verdict(m: Any) -> bool | None:
    """A metric's pass/fail as the readiness verdict reads it (:data:`PENETRATION_METRICS`: at most
    :data:`UNRESOLVED_PENETRATION_MM`, a child inside its parent beyond its modelled pose); None: not graded."""
    if m.name in PENETRATION_METRICS:
        value = m.details.get(PENETRATION_METRICS[m.name] or "", m.value)
        return None if value is None else bool(value <= UNRESOLVED_PENETRATION_MM)
    return m.passed


def readiness(metrics: list[Any]) -> Readiness:
    """The verdict of :class:`~asset2sim.schemas.report.MetricResult` s (any
    engines; :data:`TIERS`); a metric with ``passed`` None does not count."""
    tiers: dict[str, bool | None] = {}
    failures: list[str] = []
    mode = "none"
    for tier, (names, _) in TIERS.items():
        ms = [m for m in metrics if m.name in names and metric_verdict(m) is not None]
        bad = [m for m in ms if metric_verdict(m) is False]
        tiers[tier] = None if not ms else not bad
        failures += list(dict.fromkeys(f"{m.name}@{m.engine}" for m in bad))
        if bad and mode == "none":
            mode = mode_of(tier, bad)
    return Readiness(tiers, failures, mode)


def penetration_measures(metrics: list[Any]) -> list[str]:
    """The penetration tier's measures at the initial state, each named by kind and engine, with its verdict against
    :data:`UNRESOLVED_PENETRATION_MM`: ``self-contact Phi 0.000 mm (pybullet) pass`` (links that are not parent and
    child, the SPEC's Phi) and ``parent-child 35.090 mm (pybullet, base/door; 35.090 mm beyond its modelled pose)
    FAIL``; empty when neither was measured."""
    out = []
    for m in metrics:
        if m.name not in PENETRATION_METRICS or m.value is None:
            continue
        verdict = {True: "pass", False: "FAIL", None: "n/a"}[metric_verdict(m)]
        if m.name == "penetration":
            out.append(f"self-contact {m.value:.3f} mm ({m.engine}) {verdict}")
            continue
        pairs = m.details.get("pairs") or {}
        worst = max(pairs, key=pairs.get, default=None)
        beyond = m.details.get("beyond_modelled_mm")
        where = ", ".join([m.engine] + ([worst] if worst else []))
        out.append(f"parent-child {m.value:.3f} mm ({where}" + (f"; {beyond:.3f} mm beyond its modelled pose" if pairs and beyond is not None
                                                                 else "") + f") {verdict}")
    return out


def mode_of(tier: str, bad: list[Any]) -> str:
    """The failure mode a failing ``tier`` names, from its failing metrics ``bad`` (as :func:`readiness` decides)."""
    if tier == "rest" and all(m.name == "oscillation" for m in bad):
        return "oscillating"
    if tier == "rest" and all(m.name in HOLD_METRICS for m in bad):
        return "joint_not_held"
    return TIERS[tier][1]


def exception_failure_mode(exc: BaseException, retryable: type[BaseException] | None = None) -> str:
    """Mode of an exception that stopped an asset's chain outside its stages:
    ``estimator_failure`` (or its own) for ``retryable``, ``timeout``, else ``crash``."""
    if retryable is not None and isinstance(exc, retryable):
        return getattr(exc, "failure_mode", "estimator_failure")
    if isinstance(exc, TimeoutError) or "Timeout" in type(exc).__name__:
        return "timeout"
    return "crash"


@dataclass
class AssetVerdict:
    """The failure mode of a catalog row and the error notes that explain it."""

    failure_mode: str
    errors: list[str] = field(default_factory=list)


def asset_failure_mode(*, manifest_error: str | None = None, input_failure: str | None = None,
                       refine_status: str | None = None, refine_mode: str | None = None,
                       measured_status: str | None = None, chain_error_mode: str | None = None) -> AssetVerdict:
    """Failure mode of one asset in a flow run from what each stage recorded (``manifest_error``:
    :data:`INVALID_MANIFEST_ROW` whatever else; the input check's mode, the refine stage's status and mode (the
    verdict ``report.json`` records, decided once), the metrics stage's status, a chain error's mode): the first
    failure in stage order; a metrics stage that failed to run or a chain error only when nothing failed before (the
    metrics stage presents the record and never decides the verdict again); ``crash`` when nothing was recorded."""
    if manifest_error is not None:
        return AssetVerdict(INVALID_MANIFEST_ROW, [f"manifest: {manifest_error}"])
    mode = input_failure
    if refine_status == "ok":
        mode = refine_mode or "none"
    elif refine_status in FAILED_STATUSES:
        mode = refine_mode or ("crash" if refine_status == "error" else refine_status)  # the exception's, else timeout / crash
    if measured_status in FAILED_STATUSES and mode in (None, "none"):
        mode = "timeout" if measured_status == "timeout" else "crash"
    if chain_error_mode is not None and mode in (None, "none"):
        mode = chain_error_mode
    return AssetVerdict(MISSING_FAILURE_MODE if mode is None else mode, [])
