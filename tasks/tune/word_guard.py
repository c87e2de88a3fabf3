"""The request's words about how a part moves, kept: after the estimate applied them ("swings freely", "stiff",
"stays where it is put", "self-closing"), no step of the post-check (escalation, the task's relief, the bracketed
search) moves that part's damping, friction or stiffness against them (``schemas.request.MOTION_GUARDS``: "max"
not raised, "min" not lowered). A step that would is undone on that parameter and says so; when the output then
fails, the as-asked tier names the word and the conflict (``tasks/check/as_asked.py``).
"""

from __future__ import annotations

from dataclasses import dataclass

from asset2sim.schemas.overlay import Overlay
from asset2sim.schemas.request import MOTION_GUARDS
from asset2sim.tasks.synthesize import joint_dynamics, request_apply, request_findings
from asset2sim.tasks.synthesize.context import EstimationContext



@dataclass(frozen=True)
class Guard:
    """One parameter of one joint a word of the request keeps: never above (``way`` ``"max"``) or below (``"min"``)
    ``value`` (SI: N m s/rad or N s/m, N m or N, N m/rad or N/m), the value the estimate gave it."""

    joint: str
    parameter: str
    way: str
    value: float
    phrase: str
    prismatic: bool = False

    def allows(self, value: float) -> bool:
        """Whether ``value`` keeps the word."""
        return value <= self.value * (1 + 1e-9) if self.way == "max" else value >= self.value * (1 - 1e-9)

    def note(self, wanted: float) -> str:
        """``joint_1: 'swings freely' keeps its damping at 0.795 N m s/rad (the step asked 2.39)``."""
        unit = request_findings.DYNAMICS_UNITS[self.parameter][self.prismatic]
        return (f"{self.joint}: '{self.phrase}' keeps its {self.parameter} at {self.value:.3g} {unit} "
                f"(the step asked {wanted:.3g})")


def guards(ctx: EstimationContext, overlay: Overlay) -> list[Guard]:
    """The guards of ``overlay`` (the estimate, bounded to the hand's operating range): one per parameter each word
    of ``ctx.request.motions`` sets on a joint it applies to
    (:func:`~asset2sim.tasks.synthesize.joint_dynamics.motion_choices`), at the overlay's value."""
    choices, _ = joint_dynamics.motion_choices(ctx, request_apply.task_relevant_joints(ctx))
    return [Guard(joint, parameter, way, float(getattr(dyn, parameter)), word.phrase, ctx.asset.joint(joint).type == "prismatic")
            for joint, ch in choices.items() if (dyn := overlay.joints.get(joint)) is not None
            for word in ch.words for parameter, way in MOTION_GUARDS[word.kind].items()]


def keep(before: Overlay, overlay: Overlay, kept: list[Guard]) -> tuple[Overlay, list[str]]:
    """``overlay`` (a step's proposal from ``before``) with every parameter the step moved against a word of ``kept``
    set back to the word's value; a joint left with no change at all is ``before``'s again (its source too). Returns
    (the overlay, one note per parameter set back)."""
    notes: list[str] = []
    joints = dict(overlay.joints)
    for g in kept:
        dyn = joints.get(g.joint)
        if dyn is None or g.allows(wanted := float(getattr(dyn, g.parameter))):
            continue
        mark = f"; '{g.phrase}' kept its {g.parameter}"
        joints[g.joint] = dyn.model_copy(update={g.parameter: g.value,
                                                 "source": dyn.source if mark in dyn.source else dyn.source + mark})
        notes.append(g.note(wanted))
    for name, dyn in joints.items():
        old = before.joints.get(name)
        if notes and old is not None and dyn is not old and all(getattr(dyn, k) == getattr(old, k) for k in ("damping", "friction", "stiffness")):
            joints[name] = old
    return (overlay.model_copy(update={"joints": joints}) if notes else overlay), notes
