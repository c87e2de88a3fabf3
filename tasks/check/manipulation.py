"""The post-check's manipulation tiers (refine stage 7): the joint sweep, operability and
robust rest of the written asset (``docs/design/metrics.md``).
"""

from __future__ import annotations

from collections.abc import Callable

from asset2sim.schemas.metrics import unit
from asset2sim.schemas.report import MetricResult
from asset2sim.tasks.check import metrics, operability, recorded_runs, robust_rest, sweep
from asset2sim.tasks.check.recorded_runs import RecordedRuns
from asset2sim.engines.source import SimObject
from asset2sim.tasks.interpret.mounting import category_mounting

#: The metrics this module adds to the post-check.
MANIPULATION_METRICS: tuple[str, ...] = ("joint_sweep", "operability", "robust_rest")


def measure_manipulation(engine: str, obj: SimObject, closed: dict[str, tuple[float, float, float]], *,
                         recorded: RecordedRuns | None = None,
                         sweep_needed: Callable[[MetricResult], str | None] | None = None,
                         category: str | None = None, labels: dict[str, str | None] | None = None,
                         runs: dict | None = None, free_joints: tuple[str, ...] = ()) -> list[MetricResult]:
    """[joint_sweep, operability, robust_rest] of ``obj`` in ``engine`` (robust rest run first;
    skipped where ``obj.fixed_base``). ``closed``: joint -> (q_closed, direction,
    open range), rad or m; ``recorded``: runs taken from / recorded into it;
    ``sweep_needed(robust_rest)``: why the sweep is not needed (then the sweep and
    operability are recorded as not run, ``details["not_run"]``), or None to run them;
    ``category`` and ``labels`` (link -> semantic label): the parts' operating ranges; ``runs``: metric -> the run it was
    graded from, filled in when given; ``free_joints``: the joints the request asks to move freely (robust rest grades
    them for coming to rest only).

    Raises:
        EngineUnavailable: the engine is not installed; whatever loading raises.
    """
    fixed_base = obj.fixed_base
    runs = runs if runs is not None else {}
    rr_config = robust_rest.RobustRestConfig(free_joints=tuple(sorted(free_joints)))
    runs["robust_rest"] = recorded_runs.robust_rest_run(engine, obj, rr_config, recorded=recorded)
    rr = robust_rest.robust_rest_metric(runs["robust_rest"], rr_config)
    # how the category is held in use, for the advice
    rr.details.update(root=metrics.root_label(fixed_base), category_mounting=category_mounting(category).kind)
    why_not = sweep_needed(rr) if sweep_needed is not None else None
    if why_not:
        sw, op = (MetricResult(name=name, value=None, unit=unit(name), passed=None, details={"not_run": why_not}, engine=engine)
                  for name in ("joint_sweep", "operability"))
    else:
        runs["joint_sweep"] = recorded_runs.sweep_run(engine, obj, closed, recorded=recorded)
        runs["operability"] = recorded_runs.operability_run(engine, obj, closed, category=category, labels=labels, recorded=recorded)
        sw, op = sweep.sweep_metric(runs["joint_sweep"]), operability.operability_metric(runs["operability"])
    sw.details["root"] = "fixed (mounted)" if fixed_base else "fixed (by definition of the sweep)"
    op.details["root"] = "fixed (mounted)" if fixed_base else "fixed (held by the other hand)"
    return [sw, op, rr]


def failing(metrics: list[MetricResult]) -> list[str]:
    """Names of the manipulation metrics of ``metrics`` that fail."""
    return [m.name for m in metrics if m.name in MANIPULATION_METRICS and m.passed is False]

