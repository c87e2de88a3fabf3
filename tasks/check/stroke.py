"""One stroke of a joint, the loop every hand of the checks runs: read the joint, apply a
bounded force or drive, hold the other joints, step, record. Each hand keeps its own force law
and pass rule (``docs/design/metrics.md``): the joint sweep's force-limited drive and
operability's hand, each to an opening fraction (:func:`reach_stroke`;
:mod:`~asset2sim.tasks.check.sweep`, :mod:`~asset2sim.tasks.check.operability`), the probes'
pusher (:mod:`~asset2sim.tasks.check.probes`), the task's gripper
(:mod:`~asset2sim.tasks.check.gripper_motion`) and a realism pair's push and release
(:mod:`asset2sim.apps.realism.motion`). Strokes of several parts at once read each part as
:class:`Reach` does (the sweep's batches, :func:`~asset2sim.tasks.check.sweep.sweep_together`); the
breakaway's ramps push one part or a batch (:func:`~asset2sim.tasks.check.breakaway.push_together`).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from asset2sim.engines.base import SimSession


@dataclass(frozen=True)
class StrokeEnd:
    """Where a stroke ended: after ``steps`` engine steps, the joint at ``q`` (rad or m)."""

    steps: int
    q: float


def run_stroke(session: SimSession, joint: str, steps: int, law: Callable | None = None,
               record: Callable | None = None, held: Sequence[str] = (),
               hold_force: float = 0.0) -> StrokeEnd:
    """At most ``steps`` engine steps of ``session`` moving ``joint``. Each step: the joint read
    (q rad or m, q_dot rad/s or m/s), ``law(k, q, qd)`` applying the force or drive of step k
    (0-based), every ``held`` joint driven still with at most ``hold_force`` (N m or N, beyond
    its friction), one step, the joint read again and ``record(k + 1, q, qd)``. Either callback
    ends the stroke by returning True.

    Raises:
        KeyError: ``joint`` is not a joint of the session.
    """
    q, qd = session.joint_state(joint)
    for k in range(steps):
        if law is not None and law(k, q, qd):
            return StrokeEnd(k, q)
        for other in held:
            session.drive_joint(other, 0.0, hold_force)
        session.step(1)
        q, qd = session.joint_state(joint)
        if record is not None and record(k + 1, q, qd):
            return StrokeEnd(k + 1, q)
    return StrokeEnd(steps, q)


@dataclass
class Reach:
    """A stroke towards an opening fraction (0 closed .. 1 open) in at most ``limit`` steps: the
    farthest fraction read (NaN: none), the steps taken when the target was reached (None: not
    reached; ``limit``: at the last reading), whether the joint diverged, and the fraction read
    before each step."""

    limit: int
    far: float = float("nan")
    steps: int | None = None
    diverged: bool = False
    fractions: list[float] = field(default_factory=list)

    def passed(self, closed: tuple[float, float, float], target: float, sign: float, q: float) -> bool:
        """Whether ``q`` (rad or m) is at ``target`` or past it along ``sign`` (``closed``: q_closed, direction,
        open range); the farthest fraction kept."""
        qc, d, rng = closed
        f = float(d * (q - qc) / rng)
        self.far = f if np.isnan(self.far) else (max if sign > 0 else min)(self.far, f)
        return (f - target) * sign >= 0

    def read(self, closed: tuple[float, float, float], target: float, sign: float, max_speed: float, k: int,
             q: float, qd: float) -> bool:
        """The reading (q, qd) before step ``k``: its fraction kept; True when the stroke ends there, diverged (not
        finite, or faster than ``max_speed``, rad/s or m/s) or at the target (``steps`` = k)."""
        qc, d, rng = closed
        self.fractions.append(float(d * (q - qc) / rng))
        if not (np.isfinite(q) and np.isfinite(qd)) or abs(qd) > max_speed:
            self.diverged = True
            return True
        if self.passed(closed, target, sign, q):
            self.steps = k
            return True
        return False

    def last(self, closed: tuple[float, float, float], target: float, sign: float, steps: int, q: float) -> None:
        """The reading ``q`` after the last of ``steps`` steps of a stroke that ran out of time: at the target there,
        it was reached at the time limit."""
        if not (self.diverged or self.steps is not None) and np.isfinite(q) and self.passed(closed, target, sign, q):
            self.steps = steps


def reach_stroke(session: SimSession, joint: str, closed: tuple[float, float, float],
                 target: float, sign: float, time_limit: float, drive: Callable, *,
                 held: Sequence[str] = (), hold_force: float = 0.0,
                 max_speed: float = float("inf"), record: Callable | None = None) -> Reach:
    """:func:`run_stroke` of ``joint`` for at most ``time_limit`` s until its opening fraction
    passes ``target`` (at least it with ``sign`` +1, at most it with -1), read before each step
    and after the last (:meth:`Reach.read`, :meth:`Reach.last`); ``closed``: (q_closed rad or m,
    direction +-1, open range > 0). ``drive(k, q, qd)`` applies the force law; ``held``,
    ``hold_force`` and ``record`` as :func:`run_stroke`; a reading that is not finite or faster
    than ``max_speed`` (rad/s or m/s) ends the stroke as diverged."""
    out = Reach(int(round(time_limit / session.options.conventions.timestep)))

    def law(k, q, qd):
        return True if out.read(closed, target, sign, max_speed, k, q, qd) else drive(k, q, qd)

    end = run_stroke(session, joint, out.limit, law, record, held, hold_force)
    out.last(closed, target, sign, end.steps, end.q)
    return out
