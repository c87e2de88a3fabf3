"""The failure mode of an asset (vocabulary :data:`asset2sim.schemas.report.FAILURE_MODES`)
and its interaction-readiness (:func:`readiness`: no measured metric of any
tier fails, in any engine), decided in one place for the refine report, the
terminal, ``report.html`` and the catalog (``docs/design/metrics.md``, section 3a).
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


#: Interaction-readiness tiers: tier -> (metrics that decide it, failure mode when one fails), in
#: reporting order. Penetration fails above :data:`UNRESOLVED_PENETRATION_MM` (no SPEC threshold), the SPEC's Phi
#: and a child inside its parent alike (the pairs Phi skips: a door opened through a bar of its own body).
TIERS: dict[str, tuple[tuple[str, ...], str]] = {
    "rest": (("rest_stability", "settle_tilt", "divergence", "ground_penetration", "oscillation", "state_hold",
              "joint_hold"), "unstable"),
    "penetration": (tuple(PENETRATION_METRICS), "unresolved_penetration"),
    "sweep": (("joint_sweep",), "blocked_joint"),
    "operability": (("operability",), "not_operable"),
    "robust_rest": (("robust_rest",), "not_robust_at_rest"),
    "probes": (("probes",), "probe_failed"),
    "task": (("task_execution",), "task_failed"),
    "force": (("operating_force",), "implausible_force"),
    "request": (("request_met",), "request_not_met"),  # as asked (tasks/check/as_asked.py), after the physical tiers
}


#: Rest-tier metrics of a joint that leaves its state (the object itself at rest).
HOLD_METRICS: tuple[str, ...] = ("state_hold", "joint_hold")


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
        """One line: ``interaction-ready (...)`` or ``NOT READY: probes@pybullet, ... (...)``."""
        tiers = ", ".join(f"{t} {'pass' if v else ('FAIL' if v is False else 'n/a')}" for t, v in self.tiers.items())
        if self.ready:
            return f"interaction-ready ({tiers})"
        return f"NOT READY: {', '.join(self.failures)} ({tiers})"


def _verdict(m: Any) -> bool | None:
    """A metric's pass/fail for readiness (:data:`PENETRATION_METRICS`: at most :data:`UNRESOLVED_PENETRATION_MM`)."""
    if m.name in PENETRATION_METRICS:
        value = (m.details or {}).get(PENETRATION_METRICS[m.name] or "", m.value)
        return None if value is None else bool(value <= UNRESOLVED_PENETRATION_MM)
    return m.passed


def readiness(metrics: list[Any]) -> Readiness:
    """The verdict of :class:`~asset2sim.schemas.report.MetricResult` s (any
    engines; :data:`TIERS`); a metric with ``passed`` None does not count."""
    tiers: dict[str, bool | None] = {}
    failures: list[str] = []
    mode = "none"
    for tier, (names, tier_mode) in TIERS.items():
        ms = [m for m in metrics if m.name in names and _verdict(m) is not None]
        bad = [m for m in ms if _verdict(m) is False]
        tiers[tier] = None if not ms else not bad
        failures += list(dict.fromkeys(f"{m.name}@{m.engine}" for m in bad))
        if bad and mode == "none":
            mode = tier_mode
            if tier == "rest" and all(m.name == "oscillation" for m in bad):
                mode = "oscillating"
            elif tier == "rest" and all(m.name in HOLD_METRICS for m in bad):
                mode = "joint_not_held"
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
        verdict = {True: "pass", False: "FAIL", None: "n/a"}[_verdict(m)]
        if m.name == "penetration":
            out.append(f"self-contact Phi {m.value:.3f} mm ({m.engine}) {verdict}")
            continue
        pairs = (m.details or {}).get("pairs") or {}
        worst = max(pairs, key=pairs.get) if pairs else None
        beyond = (m.details or {}).get("beyond_modelled_mm")
        where = ", ".join([m.engine] + ([worst] if worst else []))
        out.append(f"parent-child {m.value:.3f} mm ({where}" + (f"; {beyond:.3f} mm beyond its modelled pose" if pairs and beyond is not None
                                                                 else "") + f") {verdict}")
    return out


def penetration_why(metrics: list[Any]) -> list[str]:
    """Why the penetration tier failed (``unresolved_penetration``), one sentence per failing measure: which
    penetration, the links, the measured depth against :data:`UNRESOLVED_PENETRATION_MM`, and what a user can do;
    empty when the tier passes. The terminal summary and ``report.html`` print the same sentences."""
    out = []
    for m in metrics:
        if m.name not in PENETRATION_METRICS or _verdict(m) is not False:
            continue
        d = m.details or {}
        if m.name == "penetration":
            pairs = sorted(d.get("pairs") or [], key=lambda p: -float(p.get("max_depth_mm") or 0.0))
            links = f"links '{pairs[0]['link_a']}' and '{pairs[0]['link_b']}' (not parent and child) overlap by up to " \
                    f"{float(pairs[0]['max_depth_mm']):.1f} mm" if pairs else "links that are not parent and child overlap"
            out.append(f"self-contact penetration Phi {m.value:.1f} mm ({m.engine}) is above {UNRESOLVED_PENETRATION_MM:g} mm: "
                       f"{links} at the initial state. Ask for another state (--state JOINT=closed or a smaller opening) "
                       "or give these links collision meshes that do not overlap.")
            continue
        pairs = d.get("pairs") or {}
        worst = max(pairs, key=pairs.get) if pairs else "?/?"
        parent, _, child = worst.partition("/")
        depth = float(pairs.get(worst, m.value or 0.0))
        out.append(f"parent-child penetration ({m.engine}): link '{child}' is {depth:.1f} mm inside its parent '{parent}' at "
                   f"the initial state, {float(d.get('beyond_modelled_mm') or 0.0):.1f} mm deeper than at its modelled pose "
                   f"(fails above {UNRESOLVED_PENETRATION_MM:g} mm). Ask for a state the part reaches without entering its "
                   "parent (--state JOINT=closed or a smaller opening), or check the joint's axis, origin and limits in the input.")
    return out


#: How each robust-rest trial disturbed the object, for :func:`robust_rest_why`.
_TRIAL_WORDS = {"drop": "landed after the 2 cm drop", "tilt+x": "landed after the 5 deg tilt about +x",
                "tilt-x": "landed after the 5 deg tilt about -x", "tilt+y": "landed after the 5 deg tilt about +y",
                "tilt-y": "landed after the 5 deg tilt about -y", "nudge": "was nudged at 0.05 m/s"}


def robust_rest_why(metrics: list[Any]) -> list[str]:
    """Why robust rest failed (``not_robust_at_rest``), one sentence per part that moved (its largest drift over the
    trials against its tolerance, and the trial) or per toppling, with what a user can do; empty when it passes. A
    part's friction and damping stay within what a hand overcomes (the operability tier), so a drift here is the
    part's momentum when the object lands, not a search that stopped short (``docs/guide/metrics.md``)."""
    out: list[str] = []
    for m in metrics:
        if m.name != "robust_rest" or _verdict(m) is not False:
            continue
        trials = (m.details or {}).get("trials") or {}
        worst: dict[str, tuple[float, float, str]] = {}
        toppled: tuple[float, str] | None = None
        for name, t in trials.items():
            if not isinstance(t, dict) or t.get("passed") is not False:
                continue
            for j in t.get("failing_joints") or []:
                drift, tol = float((t.get("joint_drift") or {}).get(j, 0.0)), float((t.get("joint_tolerance") or {}).get(j, 0.0))
                if j not in worst or drift > worst[j][0]:
                    worst[j] = (drift, tol, name)
            if "toppled" in str(t.get("failure", "")) and (toppled is None or float(t.get("topple") or 0) > toppled[0]):
                toppled = (float(t.get("topple") or 0.0), name)
        for j, (drift, tol, name) in sorted(worst.items()):
            prismatic = tol < 0.01  # 2 mm against 0.02 rad
            amount = f"{1000 * drift:.1f} mm (tolerance {1000 * tol:.0f} mm)" if prismatic else f"{drift:.3f} rad (tolerance {tol:g} rad)"
            out.append(f"joint '{j}' moved {amount} when the object {_TRIAL_WORDS.get(name, name)} ({m.engine}); its friction "
                       "and damping stay within what a hand overcomes, and at that the part's momentum carries it. A lighter "
                       "part (--mass, --material) may hold; a mounted object (--mount fixed) is not dropped or tilted.")
        if toppled is not None:
            out.append(f"the object toppled ({toppled[0]:.2f} rad) when it {_TRIAL_WORDS.get(toppled[1], toppled[1])} "
                       f"({m.engine}): its centre of mass lies near the edge of its footprint in this state. Ask for a smaller "
                       "opening of its heavy parts, or --mount fixed when it stands fixed in use.")
    return out


def combine_verdict(report: Any, evaluation_metrics: list[Any]) -> Readiness:
    """Refine's final verdict once its evaluation ran: :func:`readiness` of the
    evaluation's metrics, set on ``report`` (a ``RefineReport``, in place:
    ``readiness`` and ``failure_mode``)."""
    r = readiness(list(evaluation_metrics))
    report.readiness = r.tiers
    report.failure_mode = r.failure_mode
    return r


def post_check_failure_mode(check: Any) -> str:
    """Failure mode of a refine run from its final ``PostCheck``: ``unstable``,
    ``oscillating``, ``unresolved_penetration``, then :func:`readiness`'s mode
    of its metrics, the first that applies."""
    osc = check.metric("oscillation")
    pen = check.metric("penetration")
    if not check.stable:
        return "unstable"
    if not osc.passed:
        return "oscillating"
    if pen.value is not None and pen.value > UNRESOLVED_PENETRATION_MM:
        return "unresolved_penetration"
    return readiness(list(check.metrics)).failure_mode


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
                       measured_status: str | None = None, rest_stable: bool | None = None,
                       oscillation_pass: bool | None = None, chain_error_mode: str | None = None,
                       measured_failures: list[str] | None = None) -> AssetVerdict:
    """Failure mode of one asset in a flow run from what each stage recorded
    (``manifest_error``: :data:`INVALID_MANIFEST_ROW` whatever else; the input
    check's mode, the refine stage's status and mode, the metrics stage's
    status, verdicts and failing ``metric@engine``, a chain error's mode): the
    first failure in stage order; a metrics-stage failure or a chain error only
    when nothing failed before; ``crash`` when nothing was recorded."""
    mode: str | None = None
    errors: list[str] = []
    if manifest_error is not None:
        return AssetVerdict(INVALID_MANIFEST_ROW, [f"manifest: {manifest_error}"])
    if input_failure is not None:
        mode = input_failure
    if refine_status == "ok":
        mode = refine_mode or "none"
    elif refine_status in FAILED_STATUSES:
        mode = refine_mode or ("crash" if refine_status == "error" else refine_status)  # the exception's, else timeout / crash
    if measured_status == "ok" and mode == "none":
        if rest_stable is False:
            mode = "unstable"
            errors.append("metrics stage: rest stability failed although the refine post-check passed")
        elif oscillation_pass is False:
            mode = "oscillating"
            errors.append("metrics stage: oscillation failed although the refine post-check passed")
        elif measured_failures:
            failing = {f.split("@", 1)[0] for f in measured_failures}
            for tier, (names, tier_mode) in TIERS.items():
                if tier != "rest" and failing & set(names):
                    mode = tier_mode
                    errors.append(f"metrics stage: {tier} failed ({', '.join(f for f in measured_failures if f.split('@', 1)[0] in names)})")
                    break
    elif measured_status in FAILED_STATUSES and mode in (None, "none"):
        mode = "timeout" if measured_status == "timeout" else "crash"
    if chain_error_mode is not None and mode in (None, "none"):
        mode = chain_error_mode
    if mode is None:
        mode = MISSING_FAILURE_MODE
    return AssetVerdict(mode, errors)
