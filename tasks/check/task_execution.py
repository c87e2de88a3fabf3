"""Task execution by a gripper: a force- and speed-limited floating gripper
(:class:`~asset2sim.tasks.check.gripper.BoundedGrasp`) performs the task of the manifest row on the object
(root free on the ground, fixed for a mounted asset). Definition: ``docs/design/metrics.md``, "task_execution".
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from asset2sim.engines.quiet import quiet_stdout
from asset2sim.engines.source import SimObject
from asset2sim.schemas.report import MetricResult
from asset2sim.tasks.check.contact_points import contact_point_rule, grasp_side
from asset2sim.tasks.check.gripper import BoundedGrasp
from asset2sim.tasks.check.gripper_motion import GripperMove, Motion, TaskConfig
from asset2sim.tasks.check.metrics import root_label
from asset2sim.tasks.check.probes import CLOSE_TARGET, OPEN_TARGET, check_action
from asset2sim.tasks.check.support import SupportWatch
from asset2sim.urdf import UrdfError, UrdfModel

#: Opening fraction a close task starts from when the delivered state is already closed.
FAR_SIDE_OPEN = OPEN_TARGET


@dataclass
class TaskAttempt:
    """One joint, one action. Angles rad, lengths m, forces N, torques N m."""

    joint: str
    joint_type: str
    action: str
    link: str
    #: ``child`` (the part the joint moves) or ``parent`` (the child carries the object)
    side: str
    contact_rule: str
    #: grasp point in the link frame, m
    contact_point: list[float]
    #: ``initial state`` or the far side the joint was set to (``TaskConfig.from_far_side``)
    started_from: str
    start_fraction: float
    target_fraction: float
    reached: bool
    release_fraction: float
    final_fraction: float
    held: bool
    hold_required: bool
    #: peak |F| the gripper applied (a robot's load), N
    peak_force_n: float
    #: peak force along the part's motion, N: |torque about the axis| / lever or |F . a| (prismatic)
    peak_operating_force_n: float
    #: peak |torque about the joint axis| (revolute), N m
    peak_torque_nm: float | None
    #: peak |force along the axis| (prismatic), N
    peak_axial_force_n: float | None
    lever_m: float | None
    root_slide_m: float
    root_tilt_rad: float
    slid: bool
    tipped: bool
    #: the gripper's force reached its limit
    force_limited: bool
    #: the gripper had to move the joint (False: already at the target)
    moved: bool
    seconds_simulated: float
    success: bool
    failure: str = ""
    notes: list[str] = field(default_factory=list)
    #: commanded speed as a share of the gripper's top speed (lower on a retry)
    speed_share: float = 1.0
    #: the motion from the grasp on (:attr:`asset2sim.tasks.check.gripper_motion.Motion.trace`); for clips, not in
    #: :meth:`summary`
    trace: dict[str, Any] = field(default_factory=dict, repr=False, compare=False)

    def summary(self) -> dict[str, Any]:
        """JSON-able dict (the trace left out)."""
        return {k: v for k, v in self.__dict__.items() if k != "trace"}


@dataclass
class TaskRun:
    """Task execution of an asset in one engine."""

    engine: str
    #: ``free (on the ground)`` or ``fixed (mounted)``
    root: str
    attempts: list[TaskAttempt] = field(default_factory=list)
    task: str | None = None
    config: TaskConfig = field(default_factory=TaskConfig)


def execute_task(session, joint: str, closed: tuple[float, float, float], *, action: str,
                 target_fraction: float | None = None, config: TaskConfig | None = None,
                 model: UrdfModel | None = None, hold_required: bool = True, speed_share: float = 1.0) -> TaskAttempt:
    """Execute one ``action`` (``close`` / ``open``) on ``joint`` from the session's
    current state (stepped in place): ``closed`` (q_c rad or m, direction +-1, open range R > 0 rad or m);
    ``target_fraction`` None: close 0.05, open 0.6; ``model``: the URDF (handles); a session with its root fixed
    (mounted) always moves the child side; ``speed_share`` in (0, 1] of the gripper's top speed.

    Raises:
        ValueError: unknown action, non-positive ``open_range``, ``speed_share`` outside (0, 1].
        KeyError: unknown joint.
    """
    closed, direction, open_range = closed
    check_action(session, joint, action, open_range, "task", f"joint {joint!r} is not a movable joint of the session")
    if not 0.0 < speed_share <= 1.0:
        raise ValueError(f"joint {joint!r}: speed_share must be in (0, 1], got {speed_share!r}")
    cfg = config or TaskConfig()
    dt = float(session.options.conventions.timestep)
    prismatic = session.joint_types[joint] == "prismatic"
    if target_fraction is None:
        target_fraction = CLOSE_TARGET if action == "close" else OPEN_TARGET

    def frac(q: float) -> float:
        return float(direction * (q - closed) / open_range)

    def reached(f: float) -> bool:
        return f <= target_fraction + cfg.reach_tol if action == "close" else f >= target_fraction - cfg.reach_tol

    notes: list[str] = []
    # settle and approach; where the joint is already at the target (``TaskConfig.from_far_side``) from the far side
    n_settle = int(round((cfg.settle_time + cfg.approach_distance / cfg.limits.max_speed_m_s) / dt))
    session.step(n_settle)
    q0, started_from = session.joint_state(joint)[0], "initial state"
    if reached(frac(q0)) and cfg.from_far_side:
        f_from = FAR_SIDE_OPEN if action == "close" else 0.0
        session.set_joint_positions({joint: closed + direction * f_from * open_range})
        session.step(n_settle)
        q0, _ = session.joint_state(joint)
        started_from = f"far side (opening fraction {f_from:g}): the initial state was already at the target"
        notes.append(started_from)
    f0 = frac(q0)
    side = grasp_side(session, joint, model, root_fixed=bool(session.options.fixed_base))
    link, point, rule = contact_point_rule(session, joint, model, opening_direction=direction, side=side)
    watch = SupportWatch(session, session.link_names[0] if side == "child" else session.joint_child[joint])
    q_target = closed + direction * target_fraction * open_range
    if reached(f0):
        m = Motion(moved=False, f_rel=f0, f_end=f0, held_ok=True)
        notes.append("at the target before the motion: nothing to move")
    else:
        # moving the parent side by -dq gives the same relative motion dq
        m = GripperMove(session, joint, BoundedGrasp(session, link, point, cfg.limits), 1.0 if side == "child" else -1.0,
                        cfg, frac, reached, watch).move(q0, q_target, speed_share, notes)
    slid = watch.slide > cfg.slide_tol
    tipped = watch.tilt > cfg.tip_tol
    ok_reached = reached(m.f_rel) if np.isfinite(m.f_rel) else False
    failure = ""  # why the attempt failed; a target not held that need not be is noted
    if not np.isfinite(m.f_end):
        failure = "diverged"
    elif slid or tipped:
        failure = "the object " + ("slid" if slid else "tipped") + (" before the target was reached" if not ok_reached else "")
    elif not ok_reached:
        failure = "target not reached" + (f" (gripper at its {cfg.limits.max_force_n:g} N limit)" if m.force_limited else "")
    elif not m.held_ok and hold_required:
        failure = "target not held 1 s after release"
    if not m.held_ok and not hold_required and not failure:
        notes.append("does not hold the target after release (allowed: the joint moves freely or returns by its spring "
                     "by design)")
    return TaskAttempt(
        joint=joint, joint_type=session.joint_types[joint], action=action, link=link, side=side, contact_rule=rule,
        contact_point=[float(x) for x in point], started_from=started_from, start_fraction=f0, target_fraction=float(target_fraction),
        reached=bool(ok_reached), release_fraction=float(m.f_rel), final_fraction=float(m.f_end) if np.isfinite(m.f_end) else float("nan"),
        held=bool(m.held_ok), hold_required=bool(hold_required), peak_force_n=float(m.peak_force),
        peak_operating_force_n=float(m.peak_op),
        peak_torque_nm=None if prismatic or not m.moved else float(m.peak_tau),
        peak_axial_force_n=float(m.peak_ax) if prismatic and m.moved else None, lever_m=m.lever,
        root_slide_m=float(watch.slide), root_tilt_rad=float(watch.tilt), slid=bool(slid), tipped=bool(tipped),
        force_limited=bool(m.force_limited), moved=m.moved, seconds_simulated=m.steps * dt, success=not failure,
        failure=failure, notes=notes, speed_share=float(speed_share), trace=m.trace)


def run_task(engine: str, obj: SimObject, joints: dict[str, tuple[float, float, float]], *,
             actions: tuple[str, ...] = ("close", "open"), targets: dict[str, float] | None = None,
             config: TaskConfig | None = None, hold_required: dict[str, bool] | None = None,
             task: str | None = None) -> TaskRun:
    """A :class:`TaskRun`: every joint of ``joints`` (joint -> (q_closed,
    direction, open_range), rad or m) of ``obj`` with every action, each in a fresh
    session of ``engine`` (the root as ``obj`` declares); a slid or tipped attempt is made again at each of
    :attr:`TaskConfig.retry_speed_shares` in turn, the last one recorded.
    ``targets``: action -> target fraction; ``hold_required``: joint -> bool (missing: True).

    Raises:
        EngineUnavailable, and whatever loading the URDF raises.
    """
    cfg = config or TaskConfig()
    source, fixed_base = obj.source, obj.fixed_base
    try:
        model = source.model(mode="lenient")
    except (UrdfError, OSError):
        model = None
    run = TaskRun(engine=engine, root=root_label(fixed_base), task=task, config=cfg)
    opts = obj.options()
    shares = (1.0,) if fixed_base else (1.0, *cfg.retry_speed_shares)  # a mounted object cannot slide or tip
    for name, end in joints.items():
        for action in actions:
            tried: list[str] = []
            for share in shares:
                with quiet_stdout():
                    session = source.open(engine, opts)
                try:
                    att = execute_task(session, name, end, action=action, target_fraction=(targets or {}).get(action),
                                       config=cfg, model=model, hold_required=(hold_required or {}).get(name, True),
                                       speed_share=share)
                finally:
                    session.close()
                if tried:
                    att.notes = [f"retried more slowly after: {'; '.join(tried)}"] + att.notes
                if not (att.slid or att.tipped):
                    break
                tried.append(f"{att.failure} at {share:g}x the top speed ({att.peak_operating_force_n:.3g} N)")
            run.attempts.append(att)
    return run


def task_metric(run: TaskRun) -> MetricResult:
    """``task_execution``: value = failed attempts; passes iff none failed (None with no attempt)."""
    failed = [a for a in run.attempts if not a.success]
    cfg = run.config
    return MetricResult(
        name="task_execution", value=float(len(failed)), unit="failed attempts", passed=(not failed) if run.attempts else None,
        threshold=(f"a {cfg.limits.max_force_n:g} N, {cfg.limits.max_speed_m_s:g} m/s gripper reaches the target "
                   f"(+-{cfg.reach_tol:g} opening fraction), it holds {cfg.hold_time:g} s after release, the object "
                   f"slides <= {cfg.slide_tol * 1e3:g} mm and tips <= {cfg.tip_tol:g} rad"),
        details={"root": run.root, "task": run.task, "attempts": [a.summary() for a in run.attempts],
                 "failures": [f"{a.joint} {a.action}: {a.failure}" for a in failed],
                 "peak_force_n": max((a.peak_force_n for a in run.attempts), default=None),
                 "peak_operating_force_n": max((a.peak_operating_force_n for a in run.attempts), default=None)},
        engine=run.engine)
