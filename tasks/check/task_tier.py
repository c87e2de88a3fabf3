"""The task tier of refine's post-check: the gripper executes the task refine
was given (``refine --task``) on the written asset with the evaluation's
definitions (:mod:`asset2sim.tasks.check.task_execution`,
:mod:`asset2sim.tasks.check.force_ranges`); which targets must hold after release.
"""

from __future__ import annotations

from asset2sim.engines.base import Spring
from asset2sim.schemas.asset import AssetDescription
from asset2sim.schemas.report import MetricResult
from asset2sim.tasks.check import recorded_runs, task_execution
from asset2sim.tasks.check.force_ranges import force_metric
from asset2sim.tasks.check.task_spec import TaskSpec, parse_task, with_work_to_do
from asset2sim.tasks.interpret.part_priors import spring_expected
from asset2sim.engines.source import SimObject

#: The metrics this tier adds to the post-check.
TASK_METRICS: tuple[str, ...] = ("task_execution", "operating_force")
def link_labels(asset: AssetDescription) -> dict[str, str | None]:
    """link -> semantic label (``semantics.txt``) of ``asset``."""
    return {ln.name: ln.semantic_label for ln in asset.links}


def hold_required_by_label(joint_labels: dict[str, str | None], springs: dict[str, Spring], category: str | None,
                           *, free_moving: bool, spring_requested: bool) -> dict[str, bool]:
    """joint -> whether the task's target must hold after release, for
    ``joint_labels`` (joint -> its child link's semantic label): not where the
    parts move freely, nor for a joint with a spring the request or the
    category's part prior (:func:`~asset2sim.tasks.interpret.part_priors.spring_expected`) asks for."""
    return {n: not (free_moving or n in springs and (spring_requested or spring_expected(category or "", label)))
            for n, label in joint_labels.items()}


def hold_required(asset: AssetDescription, joints: list[str], springs: dict[str, Spring], category: str | None,
                  *, free_moving: bool, spring_requested: bool) -> dict[str, bool]:
    """:func:`hold_required_by_label` for ``joints`` of ``asset``."""
    labels, child = link_labels(asset), {j.name: j.child for j in reversed(asset.joints)}  # the first of a name, as asset.joint
    return hold_required_by_label({n: labels.get(child.get(n)) for n in joints}, springs, category, free_moving=free_moving,
                                  spring_requested=spring_requested)


def task_spec_for(text: str, asset: AssetDescription, category: str | None, task_joints: list[str],
                  state: dict[str, float] | None = None, closed: dict[str, tuple[float, float, float]] | None = None) -> TaskSpec:
    """The ``TaskSpec`` of ``text`` on ``asset``'s joints and part labels; with ``state`` and ``closed`` (joint ->
    (q_closed, direction, open range)) narrowed to the joints it has work on."""
    spec = parse_task(text, asset, category, task_joints)
    if state is not None and closed:
        fractions = {n: d * (state[n] - qc) / r for n, (qc, d, r) in closed.items() if n in state and r > 0}
        spec = with_work_to_do(spec, fractions)
    return spec


def run_task_tier(engine: str, obj: SimObject, closed: dict[str, tuple[float, float, float]], spec: TaskSpec,
                  asset: AssetDescription, category: str | None, *, free_moving: bool, spring_requested: bool,
                  recorded: recorded_runs.RecordedRuns | None = None, runs: dict | None = None) -> list[MetricResult]:
    """[``task_execution``, ``operating_force``] of the written asset ``obj`` in
    ``engine``; ``closed``: joint -> (q_closed, direction, open range) at the output scale; ``recorded``: the
    attempt is taken from / recorded there (:func:`~asset2sim.tasks.check.recorded_runs.task_run`); ``runs``: the
    run is put under ``task_execution`` when given (the report's evidence).

    Raises:
        EngineUnavailable; whatever loading ``obj.source`` raises.
    """
    joints = {n: closed[n] for n in spec.joints if n in closed and closed[n][2] > 0}
    actions = tuple(a for a in spec.actions if a in ("close", "open"))
    run = recorded_runs.task_run(engine, obj, joints, actions=actions, targets=dict(spec.targets), task=spec.text,
                                 recorded=recorded,
                                 hold_required=hold_required(asset, list(joints), dict(obj.springs), category,
                                                             free_moving=free_moving, spring_requested=spring_requested))
    if runs is not None:
        runs["task_execution"] = run
    tm = task_execution.task_metric(run)
    tm.details["joints_rule"] = spec.rule
    return [tm, force_metric(run, category, link_labels(asset))]


def task_failing(metrics: list[MetricResult]) -> bool:
    """The task tier fails in ``metrics`` (either of :data:`TASK_METRICS`)."""
    return any(m.name in TASK_METRICS and m.passed is False for m in metrics)
