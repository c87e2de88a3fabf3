"""One attempt of the refine: synthesize -> validate -> write -> refine the state -> post-check, as a value
the report and the extras read (:class:`Attempt`)."""

from __future__ import annotations

from dataclasses import dataclass, field, replace

from asset2sim.schemas.asset import AssetDescription
from asset2sim.schemas.overlay import Overlay
from asset2sim.schemas.report import EscalationRound, StateRefinement
from asset2sim.tasks.assemble.candidate import Candidate
from asset2sim.tasks.check import postcheck
from asset2sim.tasks.geometry.closed_state import ClosedState


@dataclass(frozen=True)
class Attempt:
    """One synthesize -> validate -> write -> refine state -> post-check pass (frozen: a later stage that adds
    to it hands on a copy, ``dataclasses.replace``)."""

    asset: AssetDescription
    overlay: Overlay
    issues: list
    bands: dict[str, str]
    prismatic: set[str]
    closed_out: dict[str, ClosedState]
    st: StateRefinement
    state: dict[str, float]
    overrides: dict
    root_rotation: object
    check: postcheck.PostCheck
    rounds: list[EscalationRound]
    design: list[str] = field(default_factory=list)  # what stability by design changed and why
    targets: dict = field(default_factory=dict)  # joint -> request_apply.JointTarget
    rewritten: bool = False  # kept after another attempt was loaded: its files may differ from those ``check`` measured

    @property
    def candidate(self) -> Candidate:
        return Candidate(self.asset, self.overlay, self.state, self.overrides, self.root_rotation)

    def kept_after_another(self) -> "Attempt":
        """A copy of this attempt marked kept after another one was tried (its rest recording is not reused: the
        stages ask the workspace for the candidate they work on, so nothing needs loading again)."""
        return replace(self, rewritten=True)


def least_openings(att: Attempt, intervals: dict[str, tuple[float, float]]) -> dict[str, float]:
    """Joint -> the lower end of its opening-fraction interval, for the joints the attempt opened past
    that end (> 0) by more than 0.01 of the range."""
    return {name: float(lo) for name, (lo, hi) in intervals.items() if att.closed_out.get(name) is not None and name in att.state
            and 0 < lo < hi and att.closed_out[name].fraction(att.state[name]) > lo + 0.01}
