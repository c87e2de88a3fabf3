"""A hand's press against a stop: a handled part pushed into each end of its range (from :data:`START` of the range before
it) by a hand at its grasp point,
with at most a given force (the top of its operating range, or 20 N) rising over :data:`RAMP_TIME`, moving no faster than the hand's speed
(0.25 m/s at the grasp point, operability's hand: a force-limited velocity drive of the engine) and pressing on at
full force where the stop holds it, on the stroke runner.

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
#: The press starts this share of the range before the stop (the other joints at the session's state).
START = 0.05
#: A part faster than this many times the hand's speed has left the hand: the engine diverged.
DIVERGED = 50.0
#: How long the hand presses on once the part no longer moves toward the stop (s), and the time its force takes to
#: rise from 0 (operability's hand, :class:`~asset2sim.tasks.check.operability.OperabilityConfig` ``ramp_time``).
HOLD_TIME = 0.5
RAMP_TIME = 0.25


@dataclass(frozen=True)
class Press:
    """One press of ``joint`` toward its ``limit`` (rad or m) with at most ``effort`` (N*m or N): the farthest it
    went ``past`` the limit (rad or m; <= 0 inside it), how much deeper its deepest self-contact ``sank`` (m) and
    whether the engine ``diverged``."""

    joint: str
    limit: float
    effort: float
    past: float
    sank: float
    diverged: bool
    bound: float

    @property
    def passed(self) -> bool:
        return not self.diverged and self.past <= self.bound and self.sank <= SINK


def press_joint(session: SimSession, joint: str, limit: float, effort: float, speed: float) -> Press:
    """Press ``joint`` of an open session from :data:`START` of its range before ``limit`` (rad or m, one end of its
    range) toward it
    with at most ``effort`` (N*m or N) at most at ``speed`` (rad/s or m/s), for twice the travel at that speed plus
    :data:`HOLD_TIME`, the other joints held still (``HOLD_FORCE`` beyond their friction); the state is restored
    afterwards.

    Raises:
        EngineUnsupported: the engine cannot apply a joint effort or save its state.
    """
    lower, upper = session.joint_limits[joint]
    s = 1.0 if abs(limit - upper) < abs(limit - lower) else -1.0
    q0 = limit - s * START * (upper - lower)
    dt = session.options.conventions.timestep
    steps = int(round((2.0 * abs(limit - q0) / speed + HOLD_TIME) / dt)) + 1
    far = [-np.inf, False]  # the farthest past the limit, diverged

    def law(k, q, qd):  # the hand's speed with at most its force, rising over RAMP_TIME
        session.drive_joint(joint, s * speed, effort * min(1.0, (k + 1) * dt / RAMP_TIME))

    def record(k, q, qd):
        if not (np.isfinite(q) and np.isfinite(qd)) or abs(qd) > DIVERGED * speed:
            far[1] = True
            return True
        far[0] = max(far[0], s * (q - limit))
        return False

    held = [o for o in session.joint_types if o != joint]  # the other parts held where they are (operability's)
    def deepest() -> float:
        return max((p.max_depth for p in session.self_penetration()[1]), default=0.0)

    saved = session.save_state()
    try:
        session.set_joint_positions({**session.joint_positions(), joint: q0})
        deep = deepest()
        run_stroke(session, joint, steps, law, record, held, HOLD_FORCE)
        sank = deepest() - deep if not far[1] else float("nan")
    finally:
        for o in [joint, *held]:
            session.release_joint(o)
        session.restore_state(saved)
        session.discard_state(saved)
    kind = session.joint_types.get(joint, "revolute")
    return Press(joint, limit, effort, float(far[0]), float(sank), bool(far[1]), BOUND.get(kind, BOUND["revolute"]))
