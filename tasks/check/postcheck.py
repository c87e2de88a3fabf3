"""Post-check (refine stage 7): the SPEC metrics of the written asset plus each
joint's sag (largest departure from its initial position, against
``RefineConfig.sag_tolerance_*``); the escalation of a check that fails is the
tuning's (:mod:`asset2sim.tasks.tune.escalation`).
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from asset2sim.engines.base import SimSession
from asset2sim.engines.source import SimObject, SimSource
from asset2sim.schemas.config import RefineConfig, SimConventions
from asset2sim.schemas.overlay import Overlay
from asset2sim.schemas.metrics import unit
from asset2sim.schemas.report import MetricResult
from asset2sim.tasks.check import closer_release, manipulation, metrics, parent_child, parity, robust_rest, task_tier
from asset2sim.tasks.check.task_spec import TaskSpec
from asset2sim.tasks.synthesize import joint_dynamics, request_apply
from asset2sim.tasks.synthesize.context import EstimationContext
from asset2sim.tasks.check.recorded_runs import RecordedRuns
from asset2sim.engines.loading import overlay_springs
from asset2sim.tasks.geometry.urdf_closed import aabb_extents


class _StepRecorder:
    """Wraps a session; records the root position and the step's ground penetration (m) after every step."""

    def __init__(self, session: SimSession):
        self._s = session
        self.root: list[np.ndarray] = []
        self.ground: list[float] = []

    def __getattr__(self, name):
        return getattr(self._s, name)

    def step(self, n: int = 1) -> None:
        for _ in range(n):
            self._s.step(1)
            self.root.append(self._s.root_pose()[0])
            self.ground.append(float(self._s.step_ground_penetration()))


@dataclass
class RestRecording:
    """One SPEC rest test recorded step by step, with what it was run on.

    ``root_series`` (K, 3) m root position after every step of settling and
    test; ``ground_series`` (K,) m deepest ground penetration; ``joint_series``
    joint -> (K,) rad or m; ``conventions`` those it ran under.
    """

    trace: metrics.RestTrace
    root_series: np.ndarray
    ground_series: np.ndarray
    joint_series: dict[str, np.ndarray]
    conventions: SimConventions
    #: The root was fixed (a mounted asset, ``tasks.interpret.mounting``).
    fixed_base: bool = False
    #: (3,) m extents of the links with collision geometry at the initial state (the divergence's travel limit).
    extents: np.ndarray | None = None


def measure_rest_test(engine: str, obj: SimObject) -> tuple[MetricResult, RestRecording]:
    """(penetration in mm, :class:`RestRecording`) of ``obj`` in a fresh session
    of ``engine`` (the root fixed where ``obj.fixed_base``): the SPEC rest test run in place, every step recorded.

    Raises:
        EngineUnavailable: the engine is not installed; whatever loading the URDF raises.
    """
    with obj.open(engine) as session:
        pen = metrics.penetration(session)
        extents = aabb_extents(session)
        rec = _StepRecorder(session)
        trace = metrics.run_rest_test(rec, obj.conventions)
        return pen, RestRecording(
            trace=trace, root_series=np.array(rec.root) if rec.root else np.zeros((0, 3)), ground_series=np.array(rec.ground),
            joint_series={n: np.concatenate([trace.settle_joints.get(n, np.empty(0)), trace.joints[n][1:]])
                          for n in trace.joints},
            conventions=obj.conventions, fixed_base=bool(session.options.fixed_base), extents=extents)


@dataclass
class PostCheck:
    """Result of one post-check (metrics, the trace and per-joint sag)."""

    metrics: list[MetricResult]
    trace: metrics.RestTrace
    #: joint -> where it came to rest, |q_end - q_initial| (rad or m)
    sag: dict[str, float]
    sagging: list[str] = field(default_factory=list)
    #: Other engines (``--engines``): engine -> [penetration, rest_stability, oscillation].
    engine_results: dict[str, list[MetricResult]] = field(default_factory=dict)
    recording: RestRecording | None = None
    #: The manipulation tiers' runs, reused by the evaluation of the same files.
    recorded: RecordedRuns = field(default_factory=RecordedRuns)
    #: metric -> the run it was graded from (``robust_rest``, ``joint_sweep``, ``operability``, ``task_execution``): the
    #: report's evidence and clips.
    runs: dict[str, Any] = field(default_factory=dict)
    #: With other engines (``--engines``), the reference engine's side of their parity rows: ``joints_held`` (joint
    #: -> came to rest in its band) and ``breakaway`` (:func:`~asset2sim.tasks.check.parity.engine_breakaway`).
    reference_holding: dict = field(default_factory=dict)

    def engine_failures(self) -> tuple[bool, list[str]]:
        """(any other engine unstable, joints oscillating in another engine)."""
        bad = [m for res in self.engine_results.values() for m in res if m.passed is False]
        return (any(m.name == "rest_stability" for m in bad),
                list(dict.fromkeys(j for m in bad if m.name == "oscillation" for j in m.details.get("failing", []))))

    def metric(self, name: str) -> MetricResult:
        return next(m for m in self.metrics if m.name == name)

    @property
    def stable(self) -> bool:
        """SPEC rest stability (in every engine) and no toppling while settling."""
        return bool(self.metric("rest_stability").passed and self.metric("settle_tilt").passed and not self.engine_failures()[0])

    @property
    def topples(self) -> bool:
        """A robust-rest trial toppled the object (:func:`~asset2sim.tasks.check.robust_rest.toppled`)."""
        return any(robust_rest.toppled(m) for m in self.metrics if m.name == "robust_rest")

    @property
    def only_topples(self) -> bool:
        """A robust-rest trial toppled the object, and no other metric fails."""
        return self.topples and {m.name for m in self.metrics if m.passed is False} <= {"robust_rest"}

    @property
    def passed(self) -> bool:
        return bool(self.stable and self.metric("oscillation").passed and not self.sagging and not self.engine_failures()[1]
                    and not manipulation.failing(self.metrics))


def overlay_object(source: SimSource, state: dict[str, float], overlay: Overlay,
                   conventions: SimConventions) -> SimObject:
    """``source`` as the post-check simulates it: at ``state`` (joint -> rad or m), with ``overlay``'s springs about
    their reference, else about ``state`` (:func:`~asset2sim.engines.loading.overlay_springs`, as the output's
    readers take them: :attr:`asset2sim.refined_asset.RefinedAsset.springs`) and its root as ``overlay.mounting``
    declares."""
    return SimObject(source, state, overlay_springs(overlay, state), conventions,
                     bool(overlay.mounting is not None and overlay.mounting.fixed))


def run_post_check(obj: SimObject, config: RefineConfig, closed: dict[str, tuple[float, float, float]] | None = None, *,
                   escalated: Callable[[PostCheck], bool] | None = None, recorded: RecordedRuns | None = None,
                   category: str | None = None, labels: dict[str, str | None] | None = None,
                   free_joints: tuple[str, ...] = ()) -> PostCheck:
    """Penetration, rest stability, oscillation, ground penetration, divergence and the undisturbed state hold of
    ``obj`` (:func:`overlay_object`: the written asset at its initial state, its springs, the root as declared, said
    in ``details["root"]``) in PyBullet, the reference engine, the SPEC metrics in every other engine of
    ``config.engines``, and with ``closed`` (joint -> (q_closed, direction, open range), rad or m) robust rest, the
    joint sweep and operability.

    ``escalated(check)``: whether the caller escalates ``check``; a check that
    fails and is escalated without the sweep records it as not run, and without
    the other engines when PyBullet's own tiers fail so. ``recorded``:
    manipulation runs taken from / recorded into it. ``category`` and ``labels``
    (link -> semantic label): the operating ranges of the operability tier; ``free_joints``: joints the request asks
    to move freely (robust rest grades them for coming to rest only)."""
    engine = "pybullet"
    conv, source = config.sim, obj.source
    obj = replace(obj, conventions=conv)
    pen, recording = measure_rest_test(engine, obj)
    trace = recording.trace
    stab = metrics.rest_stability(trace, conv, engine=engine)
    osc = metrics.oscillation(trace, conv, engine=engine)
    # undisturbed (SPEC "State hold at rest"): the floors alone, no share of the range (that is robust rest's band)
    settling = metrics.joint_settling(trace, {"revolute": config.sag_tolerance_revolute, "prismatic": config.sag_tolerance_prismatic},
                                      timestep=conv.timestep, share=0.0)
    drift = {name: s.settled for name, s in settling.items()}
    sagging = [name for name, s in settling.items() if not s.held]
    sag_metric = MetricResult(
        name="state_hold", value=max(drift.values()) if drift else 0.0, unit=unit("state_hold"), passed=not sagging,
        threshold=(f"undisturbed, every joint at rest within {config.sag_tolerance_revolute} rad / {config.sag_tolerance_prismatic} m "
                   "of its initial state"),
        details={"drift": drift, "sagging": sagging, "peak": {n: s.peak for n, s in settling.items()},
                 "moving": [n for n, s in settling.items() if s.moving],
                 "units": {n: "m" if trace.joint_types.get(n) == "prismatic" else "rad" for n in drift},
                 "tolerances": {n: s.band for n, s in settling.items()}}, engine=engine)
    tilt = metrics.settle_tilt(trace, engine=engine)
    others = [e for e in dict.fromkeys(config.engines) if e != engine]
    engine_results: dict[str, list[MetricResult]] = {}
    holding: dict = {}

    def run_parity() -> None:  # once, with other engines
        if others and not engine_results:
            options = obj.options()
            engine_results.update({e: parity.session_metrics(source, e, options) for e in others})
            holding.update(joints_held={n: s.held for n, s in settling.items()},  # the reference engine's parity row
                           breakaway=parity.engine_breakaway(source, engine, options))

    nested = parent_child.parent_child_penetration(source, obj.state, engine, conv)  # the pairs the SPEC's Phi skips
    ground = metrics.ground_penetration(recording.ground_series, conv.timestep, engine=engine)
    extent = float(np.max(recording.extents)) if recording.extents is not None and len(recording.extents) else 0.0
    div = metrics.divergence(trace, recording.root_series, recording.joint_series, conv.timestep, extent, engine=engine)
    base = [pen, stab, osc, sag_metric, tilt, nested, ground, div]
    for m in base:
        m.details["root"] = metrics.root_label(obj.fixed_base)
    recorded = recorded if recorded is not None else RecordedRuns()
    check = functools.partial(PostCheck, trace=trace, sag=drift, sagging=sagging, recording=recording, recorded=recorded)

    def partial_escalated(rr: MetricResult) -> bool:
        partial = check(metrics=[*base, rr], engine_results=engine_results)
        return not partial.passed and escalated(partial)

    def sweep_needed(rr: MetricResult) -> str | None:
        if escalated is None:
            return None
        if partial_escalated(rr):  # escalated on this engine's tiers alone: the other engines are not run either
            return ESCALATION_ROUND
        run_parity()
        return ESCALATION_ROUND if partial_escalated(rr) else None

    runs: dict[str, Any] = {}
    extra = [] if closed is None else manipulation.measure_manipulation(
        engine, obj, closed, recorded=recorded, sweep_needed=sweep_needed, category=category, labels=labels, runs=runs,
        free_joints=free_joints)
    if not sweep_not_run(extra):
        run_parity()
    return check(metrics=[*base, *extra], engine_results=engine_results, reference_holding=holding, runs=runs)


def check_object(ctx: EstimationContext, obj: SimObject, config: RefineConfig,
                 closed: dict[str, tuple[float, float, float]] | None = None, task: TaskSpec | None = None, *,
                 escalated: Callable[[PostCheck], bool] | None = None, recorded: RecordedRuns | None = None) -> PostCheck:
    """Every tier a refine measures on one object, the same for the refine's candidates and for an output read back
    (:func:`asset2sim.tasks.evaluation.evaluate.evaluate_asset`): :func:`run_post_check` of ``obj`` (the operating
    ranges from ``ctx``'s category and part labels; the parts its request asks to move freely, robust rest grades for
    coming to rest only), then, with ``task`` (a parsed task on ``obj``'s joints) and
    ``closed``, the task tier (:func:`~asset2sim.tasks.check.task_tier.run_task_tier`: the request's free motion and
    springs say which targets must hold); and where the request asks a part to shut on its own and ``closed`` is
    given, :func:`~asset2sim.tasks.check.closer_release.shuts_on_its_own`. Other arguments as :func:`run_post_check`.

    Raises:
        EngineUnavailable: an engine is not installed; whatever loading ``obj.source`` raises.
    """
    choices, _ = joint_dynamics.motion_choices(ctx, request_apply.task_relevant_joints(ctx))
    check = run_post_check(obj, config, closed, escalated=escalated, recorded=recorded, category=ctx.category,
                           labels=task_tier.link_labels(ctx.asset), free_joints=tuple(n for n, c in choices.items() if c.free_moving))
    closing = [n for n, c in choices.items() if c.self_closing]
    if closing and closed:  # the request's self-closing word, measured: the as-asked tier grades it
        check.metrics = [*check.metrics, closer_release.shuts_on_its_own("pybullet", obj, closed, closing)]
    if task is not None and closed:
        check.metrics = [*check.metrics, *task_tier.run_task_tier(
            "pybullet", obj, closed, task, ctx.asset, ctx.category, free_moving=ctx.request.free_moving,
            spring_requested=ctx.request.spring, recorded=check.recorded, runs=check.runs)]
    return check


#: Why an escalation round records the sweep as not run (:func:`run_post_check`).
ESCALATION_ROUND = "escalation round: the check fails without the sweep and is escalated whatever it says"


def sweep_not_run(metrics: list[MetricResult]) -> bool:
    """The joint sweep of ``metrics`` was not run (an escalation round:
    :func:`run_post_check`)."""
    return any(m.name == "joint_sweep" and "not_run" in m.details for m in metrics)
