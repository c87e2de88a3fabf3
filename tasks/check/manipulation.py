"""The post-check's manipulation tiers (refine stage 7): the joint sweep and
robust rest of the written asset, the joints robust rest found leaving their
state and the friction factor escalation gives them (``docs/design/metrics.md``).
"""

from __future__ import annotations

from collections.abc import Callable

from asset2sim.schemas.metrics import unit
from asset2sim.schemas.report import MetricResult
from asset2sim.tasks.check import operability, recorded_runs, robust_rest, sweep
from asset2sim.tasks.check.recorded_runs import RecordedRuns
from asset2sim.engines.source import SimObject
from asset2sim.tasks.interpret.mounting import category_mounting

#: The metrics this module adds to the post-check.
MANIPULATION_METRICS: tuple[str, ...] = ("joint_sweep", "operability", "robust_rest")


def measure_manipulation(engine: str, obj: SimObject, closed: dict[str, tuple[float, float, float]], *,
                         recorded: RecordedRuns | None = None,
                         sweep_needed: Callable[[MetricResult], str | None] | None = None,
                         category: str | None = None, labels: dict[str, str | None] | None = None) -> list[MetricResult]:
    """[joint_sweep, operability, robust_rest] of ``obj`` in ``engine`` (robust rest run first;
    skipped where ``obj.fixed_base``). ``closed``: joint -> (q_closed, direction,
    open range), rad or m; ``recorded``: runs taken from / recorded into it;
    ``sweep_needed(robust_rest)``: why the sweep is not needed (then the sweep and
    operability are recorded as not run, ``details["not_run"]``), or None to run them;
    ``category`` and ``labels`` (link -> semantic label): the parts' operating ranges.

    Raises:
        EngineUnavailable: the engine is not installed; whatever loading raises.
    """
    fixed_base = obj.fixed_base
    rr = robust_rest.robust_rest_metric(recorded_runs.robust_rest_run(engine, obj, recorded=recorded))
    rr.details["root"] = "fixed (mounted)" if fixed_base else "free (on the ground)"
    rr.details["category_mounting"] = category_mounting(category).kind  # how the category is held in use, for the advice
    why_not = sweep_needed(rr) if sweep_needed is not None else None
    if why_not:
        sw = MetricResult(name="joint_sweep", value=None, unit=unit("joint_sweep"), passed=None,
                          details={"not_run": why_not}, engine=engine)
        op = MetricResult(name="operability", value=None, unit=unit("operability"), passed=None,
                          details={"not_run": why_not}, engine=engine)
    else:
        sw = sweep.sweep_metric(recorded_runs.sweep_run(engine, obj, closed, recorded=recorded))
        op = operability.operability_metric(recorded_runs.operability_run(
            engine, obj, closed, category=category, labels=labels, recorded=recorded))
    sw.details["root"] = "fixed (mounted)" if fixed_base else "fixed (by definition of the sweep)"
    op.details["root"] = "fixed (mounted)" if fixed_base else "fixed (held by the other hand)"
    return [sw, op, rr]


def joints_not_held(metrics: list[MetricResult]) -> list[str]:
    """Joints that left their state in any robust-rest trial of ``metrics`` and,
    when one did, those whose drift exceeded :data:`HOLD_TARGET_SHARE` of their
    tolerance in some trial (coupled parts' drift varies between rounds), first-seen order."""
    failing_: list[str] = []
    near: list[str] = []
    for m in metrics:
        if m.name != "robust_rest":
            continue
        for trial in (m.details.get("trials") or {}).values():
            failing_.extend(trial.get("failing_joints") or [])
            for j, d in (trial.get("joint_drift") or {}).items():
                tol = (trial.get("joint_tolerance") or {}).get(j)
                if d is not None and tol and float(d) > HOLD_TARGET_SHARE * float(tol):
                    near.append(j)
    if not failing_:
        return []
    return list(dict.fromkeys(failing_ + near))


#: Share of a joint's tolerance that escalation aims its drift at (:func:`hold_factor`).
HOLD_TARGET_SHARE = 0.5
#: Exponents of :func:`hold_factor`: an impact's travel (drop, nudge) falls about
#: as 1 / friction^2, a slope load (tilt) needs friction about proportional to it.
HOLD_EXPONENT_IMPACT = 0.5
HOLD_EXPONENT_SLOPE = 1.0
#: Smallest friction step of :func:`hold_factor`.
HOLD_MIN_STEP = 1.2


def hold_factor(metrics: list[MetricResult], joint: str, largest: float) -> float:
    """Factor on the friction (and damping) of ``joint`` that should make it hold
    through robust rest: the largest over the trials of (drift /
    (HOLD_TARGET_SHARE tolerance)) ** e (e HOLD_EXPONENT_IMPACT for the drop
    and the nudge, HOLD_EXPONENT_SLOPE for the tilts), between HOLD_MIN_STEP and ``largest``."""
    best = HOLD_MIN_STEP
    for m in metrics:
        if m.name != "robust_rest":
            continue
        for name, trial in (m.details.get("trials") or {}).items():
            d = (trial.get("joint_drift") or {}).get(joint)
            tol = (trial.get("joint_tolerance") or {}).get(joint)
            if d is None or not tol or d <= HOLD_TARGET_SHARE * tol:
                continue
            e = HOLD_EXPONENT_SLOPE if name.startswith("tilt") else HOLD_EXPONENT_IMPACT
            best = max(best, (float(d) / (HOLD_TARGET_SHARE * float(tol))) ** e)
    return float(min(largest, best))


def failing(metrics: list[MetricResult]) -> list[str]:
    """Names of the manipulation metrics of ``metrics`` that fail."""
    return [m.name for m in metrics if m.name in MANIPULATION_METRICS and m.passed is False]

