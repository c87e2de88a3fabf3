"""One budget of simulated steps and of wall time for a whole refine, across every phase and engine.

Every check derives its step counts from simulated seconds over the time step (the rest test, the sweep, robust
rest's trials, operability's strokes, the gripper's task, the probes, the escalation's rounds), so a time step
inside its range but small multiplies them all; :class:`~asset2sim.schemas.config.SimConventions` bounds the time
step from below and the rest test's own steps, and this budget bounds the sum. A step's cost grows with the bodies
and contacts of the object (32 links step about 5 times slower than a box with a lid), so the budget also carries a
deadline in wall-clock seconds, checked before every step. Each session's ``step(n)`` spends ``n`` from the budget
of the current context (:func:`spend`); past either bound, :class:`StepBudgetExceeded` ends the work at once: the
run fails with a named error, never a different verdict (``docs/design/trust.md``, "Bounded work"). Outside
:func:`step_budget` nothing is counted.
"""

from __future__ import annotations

import contextlib
import contextvars
import math
import time
from dataclasses import dataclass
from typing import Iterator

__all__ = ["StepBudgetExceeded", "spend", "step_budget", "used"]


class StepBudgetExceeded(BaseException):
    """The simulations of one refine went past its budget: ``code`` ``SIM_STEPS_EXCEEDED`` (``limit`` steps) or
    ``SIM_TIME_EXCEEDED`` (its deadline). A ``BaseException``, as ``KeyboardInterrupt`` is: no check's
    ``except Exception`` (an engine error noted, a trial failed) turns it into a result; the one who opened the
    budget (``refine_asset``) turns it into its error."""

    def __init__(self, message: str, limit: int, code: str = "SIM_STEPS_EXCEEDED"):
        super().__init__(message)
        self.limit = limit
        self.code = code


@dataclass
class _Budget:
    limit: int
    seconds: float = math.inf
    deadline: float = math.inf  # time.monotonic() past which no step starts
    used: int = 0
    outer: "_Budget | None" = None


_CURRENT: contextvars.ContextVar[_Budget | None] = contextvars.ContextVar("asset2sim_step_budget", default=None)


@contextlib.contextmanager
def step_budget(limit: int, seconds: float = math.inf) -> Iterator[_Budget]:
    """Within the block, every engine step of this context counts against ``limit`` (steps) and ``seconds`` (wall
    time from now) and against every budget the block lies in. Yields the budget (``used``: steps so far)."""
    budget = _Budget(int(limit), float(seconds), time.monotonic() + float(seconds), outer=_CURRENT.get())
    token = _CURRENT.set(budget)
    try:
        yield budget
    finally:
        _CURRENT.reset(token)


def spend(n: int) -> None:
    """Count ``n`` steps about to be simulated. Raises :class:`StepBudgetExceeded` (before they run) when they would
    take the current budget past its limit, or its deadline has passed; nothing without a budget."""
    chain, budget, n = [], _CURRENT.get(), int(n)
    while budget is not None:
        chain.append(budget)
        budget = budget.outer
    for budget in chain:
        if budget.used + n > budget.limit:
            raise StepBudgetExceeded(f"SIM_STEPS_EXCEEDED: the simulations passed {budget.limit} steps in all (the cap of one "
                                     "refine across every phase and engine, asset2sim.schemas.config.MAX_REFINE_STEPS): "
                                     "a larger sim.timestep or shorter sim times", budget.limit)
        if time.monotonic() > budget.deadline:
            raise StepBudgetExceeded(f"SIM_TIME_EXCEEDED: the simulations ran past the deadline of {budget.seconds:g} s of one "
                                     f"refine after {budget.used} steps (asset2sim.schemas.config.MAX_REFINE_SECONDS): an "
                                     "object this large needs a larger sim.timestep or shorter sim times", budget.limit,
                                     "SIM_TIME_EXCEEDED")
    for budget in chain:
        budget.used += n


def used() -> int | None:
    """Steps counted so far in the current budget (None outside one)."""
    budget = _CURRENT.get()
    return None if budget is None else budget.used
