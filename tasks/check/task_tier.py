"""The task tier of refine's post-check: the gripper executes the task refine
was given (``refine --task``) on the written asset with the evaluation's
definitions (:mod:`asset2sim.tasks.check.task_execution`,
:mod:`asset2sim.tasks.check.force_ranges`), the operating limits escalation
keeps to (:func:`operating_limits`) and the relief of a task that needed
more than a real force (:func:`relieve`).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

from asset2sim.engines.base import Spring
from asset2sim.schemas.asset import AssetDescription, LinkGeometry
from asset2sim.schemas.overlay import Overlay
from asset2sim.schemas.report import MetricResult
from asset2sim.tasks.check import operating, recorded_runs, sweep, task_execution
from asset2sim.tasks.check.force_ranges import force_metric
from asset2sim.tasks.check.asset_files import parse_urdf
from asset2sim.tasks.check.task_spec import TaskSpec, parse_task, task_actions, with_work_to_do
from asset2sim.tasks.interpret.part_priors import handled, spring_expected
from asset2sim.engines.source import SimObject, UrdfFile
from asset2sim.urdf import UrdfModel

#: The metrics this tier adds to the post-check.
TASK_METRICS: tuple[str, ...] = ("task_execution", "operating_force")
#: Smallest share of its friction a joint keeps in one relief round (:func:`relieve`).
RELIEF_MIN_SHARE = 0.5


def link_labels(asset: AssetDescription) -> dict[str, str | None]:
    """link -> semantic label (``semantics.txt``) of ``asset``."""
    return {ln.name: ln.semantic_label for ln in asset.links}


def hold_required_by_label(joint_labels: dict[str, str | None], springs: dict[str, Spring], category: str | None,
                           *, free_moving: bool, spring_requested: bool) -> dict[str, bool]:
    """joint -> whether the task's target must hold after release, for
    ``joint_labels`` (joint -> its child link's semantic label): not where the
    parts move freely, nor for a joint with a spring the request or the
    category's part prior (:func:`~asset2sim.tasks.interpret.part_priors.spring_expected`) asks for."""
    out = {}
    for n, label in joint_labels.items():
        sprung = n in springs and (spring_requested or spring_expected(category or "", label))
        out[n] = not (free_moving or sprung)
    return out


def hold_required(asset: AssetDescription, joints: list[str], springs: dict[str, Spring], category: str | None,
                  *, free_moving: bool, spring_requested: bool) -> dict[str, bool]:
    """:func:`hold_required_by_label` for ``joints`` of ``asset``."""
    labels = link_labels(asset)
    named = {}
    for n in joints:
        try:
            named[n] = labels.get(asset.joint(n).child)
        except KeyError:
            named[n] = None
    return hold_required_by_label(named, springs, category, free_moving=free_moving, spring_requested=spring_requested)


def task_spec_for(text: str, model: UrdfModel, asset: AssetDescription, category: str | None,
                  task_joints: list[str], state: dict[str, float] | None = None,
                  closed: dict[str, tuple[float, float, float]] | None = None) -> TaskSpec:
    """The ``TaskSpec`` of ``text`` on the written asset's ``model`` (labels from
    ``asset``); with ``state`` and ``closed`` (joint -> (q_closed, direction,
    open range)) narrowed to the joints it has work on."""
    _, joints = parse_urdf(UrdfFile(model))
    semantics = {ln.name: (ln.semantic_joint or "", ln.semantic_label or "") for ln in asset.links if ln.semantic_label}
    spec = parse_task(text, joints, semantics, category, task_joints)
    if state is not None and closed:
        fractions = {n: d * (state[n] - qc) / r for n, (qc, d, r) in closed.items() if n in state and r > 0}
        spec = with_work_to_do(spec, fractions)
    return spec


def run_task_tier(engine: str, obj: SimObject, closed: dict[str, tuple[float, float, float]], spec: TaskSpec,
                  asset: AssetDescription, category: str | None, *, free_moving: bool, spring_requested: bool,
                  recorded: recorded_runs.RecordedRuns | None = None) -> list[MetricResult]:
    """[``task_execution``, ``operating_force``] of the written asset ``obj`` in
    ``engine``; ``closed``: joint -> (q_closed, direction, open range) at the output scale; ``recorded``: the
    attempt is recorded there (:func:`~asset2sim.tasks.check.recorded_runs.task_run`) for the evaluation.

    Raises:
        EngineUnavailable; whatever loading ``obj.source`` raises.
    """
    joints = {n: closed[n] for n in spec.joints if n in closed and closed[n][2] > 0}
    actions = tuple(a for a in spec.actions if a in ("close", "open"))
    run = recorded_runs.task_run(engine, obj, joints, actions=actions, targets=dict(spec.targets), task=spec.text,
                                 recorded=recorded,
                                 hold_required=hold_required(asset, list(joints), dict(obj.springs), category,
                                                             free_moving=free_moving, spring_requested=spring_requested))
    tm = task_execution.task_metric(run)
    tm.details["joints_rule"] = spec.rule
    return [tm, force_metric(run, category, link_labels(asset))]


@dataclass
class OperatingLimits:
    """What escalation keeps to: joint -> friction cap and damping cap (N m
    or N; N m s/rad or N s/m), the budgets they come from, and notes."""

    friction_caps: dict[str, float]
    damping_caps: dict[str, float]
    budgets: dict[str, operating.OperatingBudget] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)
    hand_caps: dict[str, float] = field(default_factory=dict)
    """joint -> the friction (N m or N) a hand inside the part's range still moves both ways over the whole range
    (the operability tier's): no step of the dynamics search goes above it"""


def operating_limits(obj: SimObject, overlay: Overlay, asset: AssetDescription, geometry: dict[str, LinkGeometry],
                     closed: dict[str, tuple[float, float, float]] | None, *, category: str | None, task: str | None,
                     free_moving: bool, joints: list[str] | None = None) -> OperatingLimits:
    """Friction and damping caps of every movable joint of the written asset ``obj`` (its root as mounted): the
    operating budget (:func:`~asset2sim.tasks.check.operating.operating_budgets`) of a hand inside the part's real
    range, both ways with the root fixed, for every handled part
    (:func:`~asset2sim.tasks.interpret.part_priors.handled`) where the closed ends are known, the tighter of it and
    the task gripper's for the task's ``joints``; else the probe's cap
    (:func:`~asset2sim.tasks.check.operating.friction_caps`); damping at most what the joint sweep's drive still
    moves (:func:`~asset2sim.tasks.check.sweep.damping_caps`).

    Raises:
        EngineUnavailable; whatever loading ``obj.source`` raises.
    """
    labels = link_labels(asset)
    hand = {n: c for n, c in (closed or {}).items() if handled(labels.get(asset.joint(n).child))}
    # every handled part, both ways, root fixed (the operability tier's hand); a task's joints also as its gripper meets them
    budgets = operating.operating_budgets(dataclasses.replace(obj, fixed_base=True), overlay, hand, category=category,
                                          labels=labels, free_moving=free_moving, whole=True) if hand else {}
    hand_caps = {n: b.friction_cap for n, b in budgets.items()}
    sel = {n: c for n, c in (closed or {}).items() if joints is None or n in joints}
    if sel and task:
        for n, b in operating.operating_budgets(obj, overlay, sel, category=category, labels=labels,
                                                actions=task_actions(task), free_moving=free_moving).items():
            if n not in budgets or b.budget < budgets[n].budget:
                budgets[n] = b
    caps = operating.friction_caps(overlay, overlay, asset, geometry)
    caps.update({n: b.friction_cap for n, b in budgets.items()})
    dcaps = {n: b.damping_cap for n, b in budgets.items()}
    if closed:  # what the joint sweep's drive still moves through the range in time
        for name, c in sweep.damping_caps(obj, closed).items():
            dcaps[name] = min(c, dcaps.get(name, c))
    return OperatingLimits(friction_caps=caps, damping_caps=dcaps, budgets=budgets,
                           notes=[b.conflict for b in budgets.values() if b.conflict], hand_caps=hand_caps)


def force_excess(metrics: list[MetricResult], budgets: dict[str, operating.OperatingBudget]) -> tuple[dict[str, float], dict[str, str]]:
    """Joints whose task needed more than a real operating force -> the measured excess (N m or N), and why:
    an ``operating_force`` attempt outside its range, or a moved part under which the free object slid or
    tipped at a peak operating force above the budget's allowed force."""
    excess: dict[str, float] = {}
    why: dict[str, str] = {}
    for m in metrics:
        if m.name == "operating_force" and m.passed is False:
            for row in m.details.get("attempts") or []:
                if row.get("passed") is not False:
                    continue
                b = budgets.get(row["joint"])
                e = 0.0
                if row.get("force_range_n"):
                    e = max(e, float(row["peak_operating_force_n"]) - float(row["force_range_n"][1]))
                    if b is not None and b.lever:
                        e *= b.lever
                if row.get("torque_range_nm") and row.get("peak_torque_nm") is not None:
                    e = max(e, float(row["peak_torque_nm"]) - float(row["torque_range_nm"][1]))
                if e > 0:
                    excess[row["joint"]] = max(excess.get(row["joint"], 0.0), e)
                    why[row["joint"]] = "operating force above the real range"
        if m.name == "task_execution" and m.passed is False:
            for a in m.details.get("attempts") or []:
                b = budgets.get(a["joint"])
                if not (a.get("slid") or a.get("tipped")) or b is None or not a.get("moved"):
                    continue
                e = float(a["peak_operating_force_n"]) - b.force_n
                e = e * b.lever if b.lever else e
                if e > 0:
                    excess[a["joint"]] = max(excess.get(a["joint"], 0.0), e)
                    why.setdefault(a["joint"], "the free object slid under the gripper's push")
    return excess, why


def relieve(overlay: Overlay, metrics: list[MetricResult], limits: OperatingLimits) -> tuple[Overlay, dict[str, dict[str, float]], str]:
    """Lower the friction (then the damping at top speed) of joints whose task
    needed more than a real operating force by the excess (:func:`force_excess`)
    / ``BUDGET_SHARE``, at most down to :data:`RELIEF_MIN_SHARE` of the friction
    per round and never below the hold floor; ``limits``' caps are lowered with them.

    Returns:
        (new overlay, joint -> {"friction", "damping"} changed, reason); no
        changes when nothing failed on force.
    """
    excess, why = force_excess(metrics, limits.budgets)
    ov = overlay.model_copy(deep=True)
    changes: dict[str, dict[str, float]] = {}
    for name, e in excess.items():
        d = ov.joints.get(name)
        b = limits.budgets.get(name)
        if d is None or b is None:
            continue
        need = e / operating.BUDGET_SHARE
        fr = max(d.friction - need, RELIEF_MIN_SHARE * d.friction, min(b.hold_floor, d.friction))
        left = need - (d.friction - fr)
        dm = max(d.damping - left / b.speed, 0.0) if left > 0 else d.damping
        if fr == d.friction and dm == d.damping:
            continue
        unit = "N" if b.joint_type == "prismatic" else "N m"
        ov.joints[name] = d.model_copy(update={"friction": fr, "damping": dm, "source": d.source + (
            f"; task needed {e:.3g} {unit} more than a real operating force: friction {d.friction:.3g} -> {fr:.3g}, "
            f"damping {d.damping:.3g} -> {dm:.3g}")})
        limits.friction_caps[name] = fr
        limits.damping_caps[name] = dm
        changes[name] = {"damping": dm, "friction": fr}
    reason = "; ".join(f"{j}: {w}" for j, w in why.items() if j in changes)
    return ov, changes, reason


def task_failing(metrics: list[MetricResult]) -> bool:
    """The task tier fails in ``metrics`` (either of :data:`TASK_METRICS`)."""
    return any(m.name in TASK_METRICS and m.passed is False for m in metrics)
