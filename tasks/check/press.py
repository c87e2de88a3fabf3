"""A hand's press against a stop: a handled part moved from its state into each end of its range by a hand at its grasp
point (operability's hand: a force-limited velocity drive of the engine) at most at the hand's speed (0.25 m/s at the
grasp point), slowing as it nears the stop as a reach does, then pressed there with a force rising over
:data:`RAMP_TIME` to a given top (the top of its operating range, or 20 N) and held for :data:`HOLD_TIME`, on the
stroke runner.

It passes when the engine stays stable (every reading finite, the part never faster than :data:`DIVERGED` times the
hand's speed), the part goes at most :data:`BOUND` past the limit it is pressed into (1 degree, 2 mm) and, where
another link stops it first, the deepest self-contact point at the end of the press lies at most :data:`SINK`
(2 mm) deeper than at the initial state.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from asset2sim.engines.base import SimSession
from asset2sim.tasks.check.stroke import run_stroke
from asset2sim.tasks.check.sweep import HOLD_FORCE

#: How far past a limit a pressed part may go (rad revolute, m prismatic), and how much deeper than at its initial
#: state its deepest contact may sink where geometry stops it first (m).
BOUND = {"revolute": math.radians(1.0), "prismatic": 2e-3}
SINK = 2e-3
#: The hand presses once the part is at its stop; or once geometry stopped it first: the time of the approach is up
#: and the part moves toward the stop at under :data:`STALLED` of the hand's speed (a part the hand's force moves
#: slower, against its spring, is carried on to the stop, at most :data:`APPROACH_CAP` times that long, not let go for
#: its spring to slam it there).
STALLED = 0.05
APPROACH_CAP = 8
#: The approach slows in proportion to the distance left, v = d / APPROACH_TAU (s), down to :data:`CREEP` x the
#: hand's speed: a reach ends at rest (Flash & Hogan 1985, J. Neurosci. 5(7), the minimum-jerk profile), and 0.1 s
#: slows a hand at 0.25 m/s at 2.5 m/s^2, the peak deceleration of a minimum-jerk reach of about 4 cm at that speed
#: (5.77 D / T^2 with T = 1.875 D / v). At CREEP (twice :data:`STALLED`) the part meets the stop moving 0.1 mm a step
#: at the grasp point, where at full speed it went a whole step (1 mm, several degrees on a short lever) past it
#: before the engine's limit acted.
APPROACH_TAU = 0.1
CREEP = 0.1
#: A part faster than this many times the hand's speed has left the hand: the engine diverged.
DIVERGED = 50.0
#: How long the hand presses on once the part no longer moves toward the stop (s), and the time its force takes to
#: rise from 0 (operability's hand, :class:`~asset2sim.tasks.check.operability.OperabilityConfig` ``ramp_time``).
HOLD_TIME = 0.5
RAMP_TIME = 0.25


@dataclass(frozen=True)
class Press:
    """One press of ``joint`` toward its ``limit`` (rad or m) with at most ``effort`` (N*m or N): the farthest it
    went ``past`` the limit (rad or m; <= 0 inside it), the hand's force on it at that step ``peak_effort`` (N*m or
    N; None while the hand still moved it toward the stop at its speed), how much deeper its deepest self-contact
    ``sank`` (m) and whether the engine ``diverged``. A peak at a small share of ``effort`` is the one step an engine
    lets a part resting at its stop move freely: MuJoCo and Bullet make a limit's constraint only once the joint is
    past it, so a part at its stop moves (force / inertia) dt^2 in that step."""

    joint: str
    limit: float
    effort: float
    past: float
    sank: float
    diverged: bool
    bound: float
    peak_effort: float | None = None

    @property
    def passed(self) -> bool:
        return not self.diverged and self.past <= self.bound and self.sank <= SINK


def press_joint(session: SimSession, joint: str, limit: float, effort: float, speed: float) -> Press:
    """Move ``joint`` of an open session from its current state to ``limit`` (rad or m, one end of its range) at most at ``speed`` (rad/s or m/s), slowing near it, with at most ``effort`` (N*m or N), then press it there with ``effort``
    (module docstring), the other joints held still (``HOLD_FORCE`` beyond their friction); the state is restored
    afterwards.

    Raises:
        EngineUnsupported: the engine cannot apply a joint effort or save its state.
    """
    lower, upper = session.joint_limits[joint]
    s = 1.0 if abs(limit - upper) < abs(limit - lower) else -1.0
    q0 = session.joint_state(joint)[0]
    dt = session.options.conventions.timestep
    tail = APPROACH_TAU * math.log(1.0 / CREEP)  # the slowing's time from full speed to CREEP (s)
    approach = int(round((2.0 * abs(limit - q0) / speed + tail) / dt))  # steps the hand has to reach the stop
    pressed = int(round((RAMP_TIME + HOLD_TIME) / dt))
    steps = APPROACH_CAP * approach + pressed + 1
    pressing: list[int] = []  # the step the hand began to press
    far = [-np.inf, False, None]  # the farthest past the limit, diverged, the hand's force then
    force = [None]  # the hand's force of the current step (None: still driven at its speed)

    def law(k, q, qd):  # toward the stop, slowing as it nears it, then the hand's force rising over RAMP_TIME
        if not pressing and (s * (q - limit) >= 0.0 or k >= approach and s * qd < STALLED * speed
                             or k >= APPROACH_CAP * approach):
            session.release_joint(joint)
            pressing.append(k)
        if pressing:
            force[0] = effort * min(1.0, (k - pressing[0] + 1) * dt / RAMP_TIME)
            session.apply_joint_effort(joint, s * force[0])
        else:
            session.drive_joint(joint, s * min(speed, max(CREEP * speed, s * (limit - q) / APPROACH_TAU)), effort)

    def record(k, q, qd):
        if not (np.isfinite(q) and np.isfinite(qd)) or abs(qd) > DIVERGED * speed:
            far[1] = True
            return True
        if s * (q - limit) > far[0]:
            far[0], far[2] = s * (q - limit), force[0]
        return bool(pressing) and k - pressing[0] >= pressed  # pressed for its ramp and hold: done

    held = [o for o in session.joint_types if o != joint]  # the other parts held where they are (operability's)
    def deepest() -> float:
        return max((p.max_depth for p in session.self_penetration()[1]), default=0.0)

    saved = session.save_state()
    try:
        deep = deepest()
        run_stroke(session, joint, steps, law, record, held, HOLD_FORCE)
        sank = deepest() - deep if not far[1] else float("nan")
    finally:
        for o in [joint, *held]:
            session.release_joint(o)
        session.restore_state(saved)
        session.discard_state(saved)
    kind = session.joint_types.get(joint, "revolute")
    return Press(joint, limit, effort, float(far[0]), float(sank), bool(far[1]), BOUND.get(kind, BOUND["revolute"]), far[2])
