"""Breakaway: does each joint start to move under a push of its declared friction, in this engine?

The SPEC: "a joint declared with friction f starts to move under a push of f (within 20 %) in each of [the engines the
outputs are made for]". Each movable joint with friction is pushed alone, root fixed, gravity off (so that friction,
and a spring, are all that resist), by an effort along its axis that ramps from :data:`RAMP_FROM` f to
:data:`RAMP_TO` f over :data:`RAMP_TIME` s, the spring's force k (q - q_s) added each step so the push meets friction
alone. The breakaway is the push (N*m or N, the spring's share and the damping's share c v at that step left out) at
the first step the joint moves along the push faster than :data:`START_SPEED` (rad/s or m/s) for :data:`START_STEPS`
steps in a row; it passes within
:data:`TOLERANCE` of f. The push goes toward the farther limit. A joint without friction is not pushed (nothing to
break away from).

Why a ramp and a speed: a part held by viscous damping c as well moves at (push - f) / c once the push passes f, so a
displacement threshold would read c as friction (a damped lid needing 1.3 f to travel 1 mm in time); at
:data:`START_SPEED` the damping's share is c times that speed, which the breakaway leaves out (a bag's free handle,
f = 3.3e-5 N*m and c = 6.2e-4 N*m*s/rad, has c v near 10 % of f). A ramp of 1 s
adds at most f / 240 per step, and the inertia's lag is a few steps (a 5 kg drawer held by 5 N reaches 1e-4 m/s within
0.014 s of the push passing f).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from asset2sim.engines.base import EngineUnsupported, SimSession
from asset2sim.tasks.check import joint_batches
from asset2sim.tasks.check.sweep import HOLD_FORCE
from asset2sim.tasks.geometry import limits
from asset2sim.urdf import UrdfModel

#: The push ramps from this share of the declared friction ...
RAMP_FROM = 0.5
#: ... to this share ...
RAMP_TO = 1.5
#: ... over this time (s).
RAMP_TIME = 1.0
#: Speed along the push (rad/s revolute, m/s prismatic) at which a joint has started to move: above MuJoCo's creep
#: under a load below its friction (a stapler lid's, I ~ 1e-5 kg*m^2, passed 1e-3 rad/s at 0.62 f with the MJCF's
#: friction solver parameters), far below a part let go; the damping's share of the push at that speed is c * speed,
#: at most 2.5 % of f on the dev rows (revolute c / f <= 5 s, prismatic <= 85 s).
START_SPEED = {"revolute": 5e-3, "continuous": 5e-3, "prismatic": 1e-4}
#: Steps in a row at that speed.
START_STEPS = 3
#: The SPEC's tolerance on the breakaway push (relative to the declared friction).
TOLERANCE = 0.2
#: Below this difference (N*m revolute, N prismatic) a breakaway is the declared friction whatever the ratio: the
#: resolution of a fingertip force/torque sensor (ATI Nano17, SI-12-0.12 calibration: 1/64 N*mm, 1/320 N), the least
#: push a gripper could tell apart. A part asked to move freely declares a friction near it (a bag's free handle:
#: 3.3e-5 N*m), where an engine's contact solver reaches the push within a few 1e-6 N*m but not within 20 %.
RESOLUTION = {"revolute": 1.0 / 64000.0, "continuous": 1.0 / 64000.0, "prismatic": 1.0 / 320.0}


@dataclass(frozen=True)
class JointBreakaway:
    """One joint pushed: ``declared`` friction (N*m or N), the ``breakaway`` push (same unit; None: it did not move up
    to :data:`RAMP_TO` f), ``ratio`` breakaway / declared (None when it did not move; 0 for a joint that moved under
    the first step's push is reported as :data:`RAMP_FROM`), ``direction`` +1 or -1 along the axis."""

    joint: str
    declared: float
    breakaway: float | None
    direction: int
    #: N*m or N: :data:`RESOLUTION` of the joint's type
    resolution: float = 0.0

    @property
    def ratio(self) -> float | None:
        return None if self.breakaway is None or self.declared <= 0 else self.breakaway / self.declared

    @property
    def passed(self) -> bool:
        """Started to move within :data:`TOLERANCE` of the declared friction, or within :data:`RESOLUTION` of it."""
        r = self.ratio
        return r is not None and (abs(r - 1.0) <= TOLERANCE + 1e-9 or abs(self.breakaway - self.declared) <= self.resolution)

    def as_dict(self) -> dict:
        return {"declared": self.declared, "breakaway": self.breakaway, "ratio": self.ratio, "direction": self.direction,
                "passed": self.passed}


def push_direction(q0: float, lower: float, upper: float) -> int:
    """+1 or -1: toward the farther limit from ``q0`` (+1 without finite limits)."""
    return 1 if not (np.isfinite(lower) and np.isfinite(upper)) or upper - q0 >= q0 - lower else -1


def joint_breakaway(session: SimSession, joint: str, friction: float, damping: float = 0.0) -> JointBreakaway:
    """Push ``joint`` of an open session (root fixed and gravity off, as :func:`measure_breakaway` opens it) along the
    ramp from its current state, springs from ``session.options.springs``; ``damping`` (N*m*s/rad or N*s/m, the
    file's) gives the share c v of the push the joint's speed v takes, left out of the breakaway; the state is
    restored afterwards.

    Raises:
        EngineUnsupported: the engine cannot apply a joint effort or save its state.
    """
    return push_together(session, [joint], {joint: friction}, {joint: damping})[joint]


def measure_breakaway(session: SimSession, frictions: dict[str, float], dampings: dict[str, float] | None = None,
                      model: UrdfModel | None = None) -> dict[str, JointBreakaway]:
    """:func:`joint_breakaway` of every movable joint of ``session`` with friction > 0 in ``frictions`` (joint ->
    N*m or N, the files' ``<dynamics friction>``; ``dampings`` their ``<dynamics damping>``), one after the other
    from the session's state; with the session's ``model``, the root's branches whose parts are apart are pushed in
    batches first (:func:`push_together`), and a joint that does not pass there is pushed alone.

    Raises:
        EngineUnsupported: as :func:`joint_breakaway`.
    """
    dampings = dampings or {}
    pushed = [j for j in session.joint_names if float(frictions.get(j, 0.0)) > 0.0]
    found: dict[str, JointBreakaway] = {}
    branches = joint_batches.root_branches(model, pushed) if model is not None else []
    if len(branches) > 1:
        moved = limits.subtrees(model)
        try:  # an engine that reads no link boxes or has no drive (ovphysx) pushes each part alone
            boxes = {j: joint_batches.links_box(session, [ln for ln in moved[j] if ln in session.link_names]) for j in branches}
            for batch in joint_batches.batches(boxes):
                if len(batch) > 1:
                    found.update({j: b for j, b in push_together(session, batch, frictions, dampings).items() if b.passed})
        except EngineUnsupported:
            found = {}
    return {j: found[j] if j in found else joint_breakaway(session, j, float(frictions[j]), float(dampings.get(j, 0.0)))
            for j in pushed}


def push_together(session: SimSession, joints: list[str], frictions: dict[str, float],
                  dampings: dict[str, float]) -> dict[str, JointBreakaway]:
    """:func:`joint_breakaway` of each of ``joints`` at once, each on its own ramp from the session's state: for parts
    that cannot act on one another (:mod:`~asset2sim.tasks.check.joint_batches`), so each part's push and motion are
    the ones it has alone. A part that started to move is held still (its push ended, as alone) while the others'
    ramps go on (a drive: one part alone needs none); the state is restored afterwards.

    Raises:
        EngineUnsupported: the engine cannot apply a joint effort or save its state, or, with more than one part, drive
            a joint.
    """
    dt = session.options.conventions.timestep
    n = max(2, round(RAMP_TIME / dt))
    q0 = session.joint_positions()
    saved = session.save_state()
    pushes = {}
    for j in joints:
        jtype = session.joint_types.get(j, "revolute")
        pushes[j] = (push_direction(q0[j], *session.joint_limits.get(j, (-np.inf, np.inf))), session.options.springs.get(j),
                     START_SPEED.get(jtype, 1e-3), RESOLUTION.get(jtype, 0.0),
                     float(frictions[j]) * np.linspace(RAMP_FROM, RAMP_TO, n + 1), [])
    read = {j: session.joint_state(j) for j in joints}
    found: dict[str, JointBreakaway] = {}
    held: list[str] = []
    try:
        for k in range(n + 1):
            for j in read:  # the push, the spring's pull k (q - q_s) met
                direction, spring, _, _, ramp, _ = pushes[j]
                hold = spring.stiffness * (read[j][0] - spring.reference) if spring is not None and spring.stiffness > 0 else 0.0
                session.apply_joint_effort(j, direction * ramp[k] + hold)
            session.step(1)
            for j in list(read):
                direction, _, speed, resolution, ramp, speeds = pushes[j]
                read[j] = session.joint_state(j)
                speeds.append(direction * read[j][1])
                if k + 1 >= START_STEPS and min(speeds[-START_STEPS:]) > speed:
                    brk = max(float(ramp[k]) - float(dampings.get(j, 0.0)) * speeds[-1], 0.0)
                    found[j] = JointBreakaway(j, float(frictions[j]), brk, direction, resolution)
                    del read[j]
                    if read:  # still moving while the others' ramps go on: held
                        session.drive_joint(j, 0.0, HOLD_FORCE)
                        held.append(j)
            if not read:
                break
        for j in read:
            found[j] = JointBreakaway(j, float(frictions[j]), None, pushes[j][0], pushes[j][3])
    finally:
        for j in held:
            session.release_joint(j)
        session.restore_state(saved)
        session.discard_state(saved)
    return found


def breakaway_summary(results: dict[str, JointBreakaway] | None, reason: str = "") -> dict:
    """JSON of one engine's breakaway: {"measured": bool, "reason", "passed": bool | None, "joints": {joint: ...}}."""
    if results is None:
        return {"measured": False, "reason": reason, "passed": None, "joints": {}}
    return {"measured": True, "reason": "", "passed": all(r.passed for r in results.values()),
            "joints": {j: r.as_dict() for j, r in results.items()}}


