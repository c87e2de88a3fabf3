"""One budget of simulated steps for a whole refine, across every phase and engine.

Every check derives its step counts from simulated seconds over the time step (the rest test, the sweep, robust
rest's trials, operability's strokes, the gripper's task, the probes, the escalation's rounds), so a time step
inside its range but small multiplies them all; :class:`~asset2sim.schemas.config.SimConventions` bounds the time
step from below and the rest test's own steps, and this budget bounds the sum. Each session's ``step(n)``
spends ``n`` from the budget of the current context (:func:`spend`); past it,
:class:`StepBudgetExceeded` ends the work at once. Outside :func:`step_budget` nothing is counted.
"""

from __future__ import annotations

import contextlib
import contextvars
from dataclasses import dataclass
from typing import Iterator

__all__ = ["StepBudgetExceeded", "spend", "step_budget", "used"]


class StepBudgetExceeded(BaseException):
    """The simulated steps of one refine went past its budget (``code`` ``SIM_STEPS_EXCEEDED``; ``limit`` steps). A
    ``BaseException``, as ``KeyboardInterrupt`` is: no check's ``except Exception`` (an engine error noted, a trial
    failed) turns it into a result; the one who opened the budget (``refine_asset``) turns it into its error."""

    code = "SIM_STEPS_EXCEEDED"

    def __init__(self, message: str, limit: int):
        super().__init__(message)
        self.limit = limit


@dataclass
class _Budget:
    limit: int
    used: int = 0
    outer: "_Budget | None" = None


_CURRENT: contextvars.ContextVar[_Budget | None] = contextvars.ContextVar("asset2sim_step_budget", default=None)


@contextlib.contextmanager
def step_budget(limit: int) -> Iterator[_Budget]:
    """Within the block, every engine step of this context counts against ``limit`` (steps) and against every budget
    the block lies in. Yields the budget (``used``: steps so far)."""
    budget = _Budget(int(limit), outer=_CURRENT.get())
    token = _CURRENT.set(budget)
    try:
        yield budget
    finally:
        _CURRENT.reset(token)


def spend(n: int) -> None:
    """Count ``n`` steps about to be simulated. Raises :class:`StepBudgetExceeded` (before they run) when they would
    take the current budget past its limit; nothing without a budget."""
    chain, budget, n = [], _CURRENT.get(), int(n)
    while budget is not None:
        chain.append(budget)
        budget = budget.outer
    for budget in chain:
        if budget.used + n > budget.limit:
            raise StepBudgetExceeded(f"SIM_STEPS_EXCEEDED: the simulations passed {budget.limit} steps in all (the cap of one "
                                     "refine across every phase and engine, asset2sim.schemas.config.MAX_REFINE_STEPS): "
                                     "a larger sim.timestep or shorter sim times", budget.limit)
    for budget in chain:
        budget.used += n


def used() -> int | None:
    """Steps counted so far in the current budget (None outside one)."""
    budget = _CURRENT.get()
    return None if budget is None else budget.used
