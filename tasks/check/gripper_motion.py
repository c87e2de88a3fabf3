"""How the task's gripper moves the joint it grasps (steps 4 and 5 of
:mod:`asset2sim.tasks.check.task_execution`): q_des on a trapezoidal speed
profile, the gripper led along the joint's motion (pressing or lifting
vertically where that motion is within 60 deg of vertical), the peak forces,
the release and the wait; and the knobs of task execution (:class:`TaskConfig`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np

from asset2sim.frames import axis_angle_matrix
from asset2sim.tasks.check.contact_points import joint_frame_axis, off_axis
from asset2sim.tasks.check.gripper import BoundedGrasp, GripperLimits
from asset2sim.tasks.check.stroke import run_stroke
from asset2sim.tasks.check.support import SupportWatch

_UP = np.array([0.0, 0.0, 1.0])
#: |q_dot| below which a joint counts as stopped: rad/s (revolute), m/s (prismatic).
STOPPED_REVOLUTE, STOPPED_PRISMATIC = 0.05, 0.005


@dataclass(frozen=True)
class TaskConfig:
    """Knobs of task execution (units on every field)."""

    #: free settling before the approach, s
    settle_time: float = 0.5
    #: stand-off the gripper covers before the grasp, m (time only: it has no shapes)
    approach_distance: float = 0.05
    #: time to ramp the commanded joint speed up to the gripper's top speed, s
    accel_time: float = 0.2
    #: time allowed per unit of travel time at top speed (dimensionless)
    travel_margin: float = 1.5
    #: time after the commanded motion ends to reach the target, s
    extra_time: float = 1.0
    #: wait after release, s
    hold_time: float = 1.0
    #: opening-fraction tolerance on the target's side (dimensionless)
    reach_tol: float = 0.05
    #: footprint displacement that counts as sliding, m
    slide_tol: float = 0.005
    #: root rotation that counts as tipping, rad
    tip_tol: float = 0.05
    #: the gripper presses or lifts vertically while |t_z| >= this share of |t| (0.5: 60 deg)
    vertical_share: float = 0.5
    #: a joint already at the target is first set to the far side; False: it succeeds without motion
    from_far_side: bool = True
    #: shares of the top speed at which an attempt under which the object slid or tipped is made again
    retry_speed_shares: tuple[float, ...] = (0.5, 0.25)
    limits: GripperLimits = field(default_factory=GripperLimits)


@dataclass
class Motion:
    """What a task's motion recorded (opening fractions; N, N m; m)."""

    moved: bool
    f_rel: float = 0.0  # opening fraction at release, and after hold_time
    f_end: float = 0.0
    held_ok: bool = False
    steps: int = 0  # engine steps simulated from the grasp on
    peak_force: float = 0.0
    peak_tau: float = 0.0
    peak_ax: float = 0.0
    peak_op: float = 0.0
    lever: float | None = None
    force_limited: bool = False
    #: every :data:`RECORD_EVERY` steps from the grasp on: ``t`` (s), ``joints`` (joint -> rad or m),
    #: ``root_pos`` (3,) m, ``root_rot`` (3, 3), ``grip`` (3,) m the grasp point (NaN once released); for clips
    trace: dict[str, list] = field(default_factory=dict, repr=False, compare=False)


#: Engine steps between recorded samples of a task's motion (4 at 240 Hz: 60 samples per s).
RECORD_EVERY = 4


def record_sample(session, m: Motion, grip: np.ndarray | None) -> None:
    """Append the session's state now to ``m.trace`` (its joints, root pose and the grasp point ``grip`` (3,) m,
    None once released); reads only."""
    tr = m.trace
    if not tr:
        tr.update(t=[], joints={n: [] for n in session.joint_types}, root_pos=[], root_rot=[], grip=[])
    q = session.joint_positions()
    pos, R = session.link_frame(session.link_names[0])
    tr["t"].append(m.steps * float(session.options.conventions.timestep))
    for n, v in tr["joints"].items():
        v.append(float(q[n]))
    tr["root_pos"].append(np.asarray(pos, float))
    tr["root_rot"].append(np.asarray(R, float))
    tr["grip"].append(np.full(3, np.nan) if grip is None else np.asarray(grip, float))


@dataclass
class GripperMove:
    """The task's gripper leading one grasped ``joint`` of ``session`` (``side_sign`` -1 where it moves the parent
    side): what stays the same through a motion. ``frac(q)``: the opening fraction of q (rad or m);
    ``reached(f)``: f is on the target's side; ``watch``: the object's support, updated every step."""

    session: Any
    joint: str
    grasp: BoundedGrasp
    side_sign: float
    cfg: TaskConfig
    frac: Callable[[float], float]
    reached: Callable[[float], bool]
    watch: SupportWatch

    def move(self, q0: float, q_target: float, speed_share: float, notes: list[str]) -> Motion:
        """Lead the joint from ``q0`` to ``q_target`` (rad or m) at ``speed_share`` of the gripper's top speed,
        release and wait ``hold_time``; what happened is said in ``notes``."""
        session, joint, grasp, cfg = self.session, self.joint, self.grasp, self.cfg
        dt = float(session.options.conventions.timestep)
        m = Motion(moved=True)
        o, a = joint_frame_axis(session, joint, grasp.link)
        p = grasp.grasp_point_world()
        v_cmd = cfg.limits.max_speed_m_s * speed_share
        prismatic = session.joint_types[joint] == "prismatic"
        m.lever = None if prismatic else _lever(o, a, p)
        qdot_max = v_cmd / (m.lever or 1.0)
        record_sample(session, m, p)
        travel = abs(q_target - q0) * (m.lever or 1.0)
        n_move = int(round((cfg.accel_time + cfg.travel_margin * travel / v_cmd + cfg.extra_time) / dt))
        # lead the gripper for at most n_move steps, q_des from q0 to q_target at up to qdot_max (rad/s or m/s), the
        # peaks recorded into m; done: the joint reached the target and stopped
        stopped = STOPPED_PRISMATIC if prismatic else STOPPED_REVOLUTE
        sgn = 1.0 if q_target >= q0 else -1.0
        decel = qdot_max / cfg.accel_time
        q_des, pushed_steps, done = q0, 0, False

        def law(k, q, qd):
            nonlocal q_des, pushed_steps
            # trapezoidal speed profile: ramped up over accel_time, and down at the same rate before the target
            speed = qdot_max * min(1.0, (k + 1) * dt / cfg.accel_time)
            speed = min(speed, max(float(np.sqrt(2.0 * decel * abs(q_target - q_des))), decel * dt))
            q_des = q_des + sgn * speed * dt
            if sgn * (q_des - q_target) > 0:
                q_des = q_target
            o, a = joint_frame_axis(session, joint, grasp.link)
            p = grasp.grasp_point_world()
            # the gripper led with p moved by dq about or along the axis a through o, or, where the motion is near
            # vertical (|t_z| >= vertical_share |t|), pressing or lifting vertically as far as moves the part as far
            dq = self.side_sign * (q_des - q)
            target = p + a * dq if prismatic else o + axis_angle_matrix(a, dq) @ (p - o)
            t_dir = a if prismatic else np.cross(a, p - o)
            nt = float(np.linalg.norm(t_dir))
            push = nt > 0 and abs(float(t_dir[2])) >= cfg.vertical_share * nt
            if push:  # (progress along the tangent) / t_z
                t_hat = t_dir / nt
                target = p + _UP * (float((target - p) @ t_hat) / float(t_hat[2]))
            F = grasp.step_towards(target, dt, direction=_UP if push else None)
            pushed_steps += int(push)
            if prismatic:  # the peaks of the gripper's force F (3,) N at the grasp point p
                m.peak_ax = max(m.peak_ax, abs(float(F @ a)))
                m.peak_op = m.peak_ax
            else:
                tau = abs(float(a @ np.cross(p - o, F)))
                m.peak_tau = max(m.peak_tau, tau)
                m.peak_op = max(m.peak_op, tau / _lever(o, a, p))
            if float(np.linalg.norm(F)) >= cfg.limits.max_force_n * (1 - 1e-9):
                m.force_limited = True

        def record(k, q, qd):
            nonlocal done
            m.steps += 1
            if m.steps % RECORD_EVERY == 0:
                record_sample(session, m, grasp.grasp_point_world())
            slide, tilt = self.watch.update()
            if not np.isfinite(q) or slide > cfg.slide_tol or tilt > cfg.tip_tol:
                return True  # the object moves instead of the joint: the gripper stops
            done = q_des == q_target and self.reached(self.frac(q)) and abs(qd) < stopped
            return done

        run_stroke(session, joint, n_move, law=law, record=record)
        m.peak_force = grasp.peak_force_n
        grasp.release()
        if pushed_steps:
            notes.append(f"vertical press/lift for {pushed_steps * dt:.2f} s of the motion")
        q_rel, _ = session.joint_state(joint)
        m.f_rel = self.frac(q_rel)
        if not done and self.reached(m.f_rel):
            notes.append("target reached but the joint was still moving at the time limit")

        def wait(k, q, qd):
            m.steps += 1
            self.watch.update()
            if m.steps % RECORD_EVERY == 0:
                record_sample(session, m, None)

        m.f_end = self.frac(run_stroke(session, joint, int(round(cfg.hold_time / dt)), record=wait).q)
        m.held_ok = self.reached(m.f_end) if np.isfinite(m.f_end) else False
        return m


def _lever(o: np.ndarray, a: np.ndarray, p: np.ndarray) -> float:
    """Distance (m, >= 1e-3) of ``p`` (3,) from the axis ``a`` through ``o``."""
    return max(float(off_axis(p[None], o, a)[0]), 1e-3)
