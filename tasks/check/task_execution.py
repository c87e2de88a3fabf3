"""Task execution by a gripper: a force- and speed-limited floating gripper
performs the task of the manifest row on the free object (issue 15, Build 3;
SPEC, "Interaction under manipulation").

Definitions (re-derivable; ``docs/design/metrics.md``, "task_execution"):

1. Session: SPEC conventions (timestep 1/240 s, gravity, a ground plane; the
   root **free**, resting on the ground; a mounted asset keeps its root fixed
   as it declares, :func:`asset2sim.tasks.interpret.mounting.session_root_options`),
   joints at the initial state, springs as the asset has them. Ground
   contact friction is the engines' documented default, mu = 0.25 (PyBullet
   multiplies the link's default lateral friction 0.5 by the plane's 0.5;
   PhysX and MuJoCo are given the same product: ``asset2sim/engines``), or the
   link's ``<contact><lateral_friction>`` where the asset writes one.
2. The object settles for ``settle_time`` s, then the gripper approaches for
   ``approach_distance / max_speed`` s (a floating gripper without collision
   shapes: nothing touches the object); the root pose at the grasp is the
   reference of sliding and tipping.
3. Grasp at the contact point (:func:`asset2sim.tasks.check.contact_points.contact_point_rule`:
   a handle when a geometry element is named so, else the middle of the
   moving link's far edge from the axis, a drawer's front) with a bounded-force
   attachment (:class:`~asset2sim.tasks.check.gripper.BoundedGrasp`, the
   standard grasp model of simulation benchmarks; limits
   :class:`~asset2sim.tasks.check.gripper.GripperLimits`: 70 N, 0.25 m/s).
4. Move along the joint's motion: the gripper is led towards the grasp
   point's position at the commanded joint position q_des (an arc about the
   joint axis for revolute joints, a line along it for prismatic ones),
   q_des going from the start q0 to q_target = q_c + d f_target R at the
   gripper's top speed (v_max / r rad/s at lever r; v_max m/s), ramped up
   over ``accel_time`` s and down at the same rate before the target (a
   trapezoidal speed profile: an arm decelerates; an abrupt stop would brake
   the part's momentum within a step). While the grasp point's direction of motion is
   within 60 deg of vertical (``vertical_share``) the gripper presses or
   lifts vertically only (the attachment's force projected on world z, the
   finger sliding along the part): as a person closes a lid or presses a
   stapler, the press loads the object onto the ground instead of pushing it
   sideways; otherwise the full attachment drives the part along its path. At most ``accel_time + travel_margin * travel /
   v_max + extra_time`` s; the move ends once q_des = q_target and the joint
   has reached the target (opening fraction within ``reach_tol`` on the
   target's side: close f <= f_target + 0.05, open f >= f_target - 0.05) and
   slowed below 0.05 rad/s (0.005 m/s). When the free object slid or tipped
   under the gripper, the attempt is made again from a fresh session with
   v_max replaced by 0.5 and then 0.25 of it (``retry_speed_shares``; the
   top speed is a limit, not a required speed: a robot or a person that
   pushes the object away does it again more slowly, and the damping's share
   of the force falls with the speed); the last attempt is the one recorded.
5. Release; wait ``hold_time`` = 1 s.
6. Success iff the target was reached, is still reached 1 s after release
   (waived only where the joint is meant to return: the request asks it to
   move freely, a freely swinging handle, or it returns by a spring the
   request or the category's part prior asks for, a stapler's arm), and the object neither slid (its
   footprint point, the point below the carrying link's origin at the
   object's lowest height at the grasp, carried with that link, moved
   horizontally > ``slide_tol`` = 5 mm) nor tipped (that link's rotation >
   ``tip_tol`` = 0.05 rad) from the grasp to the end of the wait; the
   carrying link is the root, or the joint's child when the gripper moves
   the parent side. A joint already at the target needs
   no motion (success, no force recorded).
7. Recorded: peak gripper force |F| (N, the robot's load), peak torque
   about the joint axis tau = |a . ((p - o) x F)| (N m; prismatic: the axial
   force |F . a|, N), p the grasp point, o the joint origin, and the peak
   operating force tau / r (r the grasp point's distance from the axis;
   prismatic |F . a|): the force along the part's motion, what a hand
   pushing along it needs. The force plausibility check
   (:mod:`asset2sim.tasks.check.force_ranges`) compares them with real
   operating forces of the category and part.

Opening fractions f = d (q - q_c) / R (0 closed, 1 fully open; closed ends:
``docs/design/metrics.md`` section 4). Targets: the task's
(:mod:`asset2sim.tasks.check.task_spec`): close 0.05, open 0.6. A joint
whose initial state already meets the target is first set to the far side
(close: f = 0.6, open: f = 0) and settled again, so every task moves its
joint (an asset delivered closed is still asked to close).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

import numpy as np

from asset2sim.engines.base import SessionOptions, Spring
from asset2sim.engines.quiet import quiet_stdout
from asset2sim.engines.registry import open_session
from asset2sim.schemas.config import SimConventions
from asset2sim.schemas.report import MetricResult
from asset2sim.tasks.check.contact_points import contact_point_rule, grasp_side
from asset2sim.tasks.check.gripper import BoundedGrasp, GripperLimits
from asset2sim.tasks.check.gripper_motion import Motion, TaskConfig, move_joint
from asset2sim.tasks.check.probes import CLOSE_TARGET, OPEN_TARGET
from asset2sim.tasks.check.support import SupportWatch
from asset2sim.tasks.interpret.mounting import session_root_options
from asset2sim.urdf import UrdfError, UrdfModel, read_urdf

#: Opening fraction a close task starts from when the delivered state is already closed.
FAR_SIDE_OPEN = OPEN_TARGET


@dataclass
class TaskAttempt:
    """One joint, one action. Angles rad, lengths m, forces N, torques N m."""

    joint: str
    joint_type: str
    action: str
    link: str
    side: str
    """``child`` (the part the joint moves) or ``parent`` (the child carries the object)"""
    contact_rule: str
    contact_point: list[float]
    """grasp point in the link frame, m"""
    started_from: str
    """``initial state`` or the far side the joint was set to (``TaskConfig.from_far_side``)"""
    start_fraction: float
    target_fraction: float
    reached: bool
    release_fraction: float
    final_fraction: float
    held: bool
    hold_required: bool
    peak_force_n: float
    """peak |F| the gripper applied (a robot's load), N"""
    peak_operating_force_n: float
    """peak force along the part's motion: |torque about the axis| / lever
    (revolute) or |F . a| (prismatic), N: what a hand pushing along the
    motion needs (the quantity accessibility standards bound)"""
    peak_torque_nm: float | None
    """peak |torque about the joint axis| (revolute), N m"""
    peak_axial_force_n: float | None
    """peak |force along the axis| (prismatic), N"""
    lever_m: float | None
    root_slide_m: float
    root_tilt_rad: float
    slid: bool
    tipped: bool
    force_limited: bool
    """the gripper's force reached its limit"""
    moved: bool
    """the gripper had to move the joint (False: already at the target)"""
    seconds_simulated: float
    success: bool
    failure: str = ""
    notes: list[str] = field(default_factory=list)
    speed_share: float = 1.0
    """commanded joint speed as a share of the gripper's top speed (1: top
    speed; lower on a retry, :attr:`TaskConfig.retry_speed_shares`)"""

    def summary(self) -> dict[str, Any]:
        """JSON-able dict."""
        return dict(self.__dict__)


@dataclass
class TaskRun:
    """Task execution of an asset in one engine."""

    engine: str
    root: str
    """``free (on the ground)`` or ``fixed (mounted)``"""
    attempts: list[TaskAttempt] = field(default_factory=list)
    task: str | None = None
    config: TaskConfig = field(default_factory=TaskConfig)


def execute_task(session, joint: str, *, closed: float, direction: float, open_range: float, action: str,
                 target_fraction: float | None = None, config: TaskConfig | None = None,
                 model: UrdfModel | None = None, hold_required: bool = True, root_fixed: bool = False,
                 speed_share: float = 1.0) -> TaskAttempt:
    """Execute one action on ``joint`` from the session's current state (module docstring).

    Args:
        session: a :class:`~asset2sim.engines.base.SimSession` at the initial
            state (root as declared); it is stepped in place.
        joint: movable joint name.
        closed, direction, open_range: q_c (rad or m), opening direction +-1,
            range R > 0 (rad or m).
        action: ``close`` or ``open``.
        target_fraction: the task's target opening fraction; None: close 0.05,
            open 0.6 (0.9 when the joint starts beyond 0.55).
        config: knobs.
        model: the URDF model (handles, :func:`~asset2sim.tasks.check.contact_points.handle_points`).
        hold_required: the target must still be reached 1 s after release.
        root_fixed: the session's root is fixed (mounted): the child side is
            always the one moved.
        speed_share: the commanded speed as a share of the gripper's top
            speed, in (0, 1].

    Raises:
        ValueError: unknown action, non-positive ``open_range``, ``speed_share`` outside (0, 1].
        KeyError: unknown joint.
    """
    _check_task(session, joint, action, open_range, speed_share)
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
    q0, f0, started_from = _settle(session, joint, action, closed, direction, open_range, cfg, frac, reached, notes)
    side = grasp_side(session, joint, model, root_fixed=root_fixed)
    link, point, rule = contact_point_rule(session, joint, model, opening_direction=direction, side=side)
    # Sliding and tipping of the link that carries the object.
    watch = SupportWatch(session, session.link_names[0] if side == "child" else session.joint_child[joint])
    q_target = closed + direction * target_fraction * open_range
    if reached(f0):
        m = Motion(moved=False, f_rel=f0, f_end=f0, held_ok=True)
        notes.append("at the target before the motion: nothing to move")
    else:
        # Moving the parent side by -dq about the joint gives the same relative motion dq.
        m = move_joint(session, joint, BoundedGrasp(session, link, point, cfg.limits), 1.0 if side == "child" else -1.0, q0,
                       q_target, cfg, speed_share, frac, reached, watch, notes)
    slid = watch.slide > cfg.slide_tol
    tipped = watch.tilt > cfg.tip_tol
    ok_reached = reached(m.f_rel) if np.isfinite(m.f_rel) else False
    failure = _task_failure(m, slid, tipped, ok_reached, cfg.limits, hold_required, notes)
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
        failure=failure, notes=notes, speed_share=float(speed_share),
    )


def _check_task(session, joint: str, action: str, open_range: float, speed_share: float) -> None:
    """Raises :func:`execute_task`'s ValueError or KeyError for bad arguments."""
    if action not in ("close", "open"):
        raise ValueError(f"task action must be 'close' or 'open', got {action!r}")
    if not open_range > 0:
        raise ValueError(f"joint {joint!r}: open_range must be > 0, got {open_range}")
    if joint not in session.joint_child:
        raise KeyError(f"joint {joint!r} is not a movable joint of the session")
    if not 0.0 < speed_share <= 1.0:
        raise ValueError(f"joint {joint!r}: speed_share must be in (0, 1], got {speed_share!r}")


def _settle(session, joint: str, action: str, closed: float, direction: float, open_range: float, cfg: TaskConfig,
            frac: Callable[[float], float], reached: Callable[[float], bool], notes: list[str]) -> tuple[float, float, str]:
    """Settle and approach (module docstring, step 2), from the far side where
    the joint is already at the target (``TaskConfig.from_far_side``, with a
    note). Returns (q0, rad or m; its opening fraction; where it started)."""
    dt = float(session.options.conventions.timestep)
    n_settle = int(round((cfg.settle_time + cfg.approach_distance / cfg.limits.max_speed_m_s) / dt))
    session.step(n_settle)
    q0, _ = session.joint_state(joint)
    if not (reached(frac(q0)) and cfg.from_far_side):
        return q0, frac(q0), "initial state"
    # The delivered state already does the task: start from the far side so
    # that every task moves its joint (close from open, open from closed).
    f_from = FAR_SIDE_OPEN if action == "close" else 0.0
    session.set_joint_positions({joint: closed + direction * f_from * open_range})
    session.step(n_settle)
    q0, _ = session.joint_state(joint)
    started_from = f"far side (opening fraction {f_from:g}): the initial state was already at the target"
    notes.append(started_from)
    return q0, frac(q0), started_from


def _task_failure(m: Motion, slid: bool, tipped: bool, ok_reached: bool, lim: GripperLimits, hold_required: bool,
                  notes: list[str]) -> str:
    """Why the attempt failed ("" when it succeeded; module docstring, step 6),
    with a note where the target is not held but need not be."""
    failure = ""
    if not np.isfinite(m.f_end):
        failure = "diverged"
    elif slid or tipped:
        failure = "the object " + ("slid" if slid else "tipped") + (" before the target was reached" if not ok_reached else "")
    elif not ok_reached:
        failure = "target not reached" + (f" (gripper at its {lim.max_force_n:g} N limit)" if m.force_limited else "")
    elif not m.held_ok and hold_required:
        failure = "target not held 1 s after release"
    if not m.held_ok and not hold_required and not failure:
        notes.append("does not hold the target after release (allowed: the joint moves freely or returns by its spring by design)")
    return failure


def run_task(engine: str, urdf: Path | str, joints: dict[str, tuple[float, float, float]], *,
             actions: tuple[str, ...] = ("close", "open"), targets: dict[str, float] | None = None,
             initial_state: dict[str, float] | None = None, springs: dict[str, Spring] | None = None,
             conventions: SimConventions | None = None, fixed_base: bool = False, config: TaskConfig | None = None,
             hold_required: dict[str, bool] | None = None, task: str | None = None) -> TaskRun:
    """Execute the task on every joint of ``joints`` with every action, each
    in a fresh session of ``engine`` (the root as declared: ``fixed_base``);
    an attempt under which the free object slid or tipped is made again at
    each of :attr:`TaskConfig.retry_speed_shares` of the top speed in turn
    (fresh sessions) until one does not; the last attempt is recorded, with
    a note of the ones before.

    Args:
        joints: joint -> (q_closed, direction, open_range), rad or m.
        actions: ``close`` / ``open``.
        targets: action -> target opening fraction (the task's); None: defaults.
        initial_state, springs, conventions: the session's.
        hold_required: joint -> whether the target must hold after release
            (:func:`execute_task`; False where the joint moves freely or returns
            by a requested spring); missing joints: True.
        task: the task text, recorded.

    Returns:
        A :class:`TaskRun`, one attempt per joint and action in order.

    Raises:
        EngineUnavailable, and whatever loading the URDF raises.
    """
    cfg = config or TaskConfig()
    conv = conventions or SimConventions()
    try:
        model = read_urdf(urdf, mode="lenient")
    except (UrdfError, OSError):
        model = None
    run = TaskRun(engine=engine, root="fixed (mounted)" if fixed_base else "free (on the ground)", task=task, config=cfg)
    opts = SessionOptions(initial_state=dict(initial_state or {}), springs=dict(springs or {}), conventions=conv,
                          **session_root_options(fixed_base))
    shares = (1.0,) if fixed_base else (1.0, *cfg.retry_speed_shares)  # a mounted object cannot slide or tip
    for name, (qc, d, rng) in joints.items():
        for action in actions:
            tried: list[str] = []
            for share in shares:
                with quiet_stdout():
                    session = open_session(engine, urdf, opts)
                try:
                    att = execute_task(session, name, closed=qc, direction=d, open_range=rng, action=action,
                                       target_fraction=(targets or {}).get(action), config=cfg, model=model,
                                       hold_required=(hold_required or {}).get(name, True),
                                       root_fixed=fixed_base, speed_share=share)
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
    """``task_execution``: value = failed attempts; passes iff none failed
    (``passed`` None when nothing was attempted)."""
    failed = [a for a in run.attempts if not a.success]
    cfg = run.config
    return MetricResult(
        name="task_execution",
        value=float(len(failed)),
        unit="failed attempts",
        passed=(not failed) if run.attempts else None,
        threshold=(f"a {cfg.limits.max_force_n:g} N, {cfg.limits.max_speed_m_s:g} m/s gripper reaches the target "
                   f"(+-{cfg.reach_tol:g} opening fraction), it holds {cfg.hold_time:g} s after release, the object "
                   f"slides <= {cfg.slide_tol * 1e3:g} mm and tips <= {cfg.tip_tol:g} rad"),
        details={
            "root": run.root,
            "task": run.task,
            "attempts": [a.summary() for a in run.attempts],
            "failures": [f"{a.joint} {a.action}: {a.failure}" for a in failed],
            "peak_force_n": max((a.peak_force_n for a in run.attempts), default=None),
            "peak_operating_force_n": max((a.peak_operating_force_n for a in run.attempts), default=None),
        },
        engine=run.engine,
    )
