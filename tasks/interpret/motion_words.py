"""The request's words about how parts move: damping, holding a position, springs and self-closing, stiff or
free motion (a phrase table), and the kinds of slides (``asset2sim/priors/slides.yaml``), each with the part it names
(:func:`dynamics_words`, a :class:`MotionWords`).
"""

from __future__ import annotations

import functools
import re
from dataclasses import dataclass

from asset2sim.prior_tables import load_priors
from asset2sim.schemas.request import MotionPhrase, ordinal_words
from asset2sim.tasks.interpret import request_values as rv
from asset2sim.tasks.interpret.phrase_scan import compile_table, negated, scan, word_table

#: The words about motion (``words.yaml`` ``motion``): value (kind, level), flag "strong" for an explicit damping
#: phrase. Each hit is also a MotionPhrase (:func:`_motion_kind` names its kind) for the part it names.
_DYN_TABLE = word_table("motion")


@functools.lru_cache(maxsize=1)
def _slide_table() -> list[tuple[re.Pattern[str], object, str]]:
    """The request words of each kind of slide (``asset2sim/priors/slides.yaml``: "on ball-bearing slides", "wooden
    runners"); a hit's value is the slide's key."""
    return compile_table([(w, key, "") for key, sp in load_priors().slides.items() for w in sp.words])


def _motion_kind(kind: str, value: object, flag: str) -> str:
    """The :class:`~asset2sim.schemas.request.MotionPhrase` kind of a dynamics word (its table entry's kind, value
    and flag)."""
    if kind == "damping":
        return "soft_close" if flag == "soft" else f"{value}_damping"
    if kind == "spring":
        return "self_closing" if flag == "close" else "spring"
    return {"free": "free", "heavy": "stiff", "hold": "hold", "stiff": "stiff"}[kind]


def _motion_part(low: str, start: int, end: int, head_starts: list[int], ordinals: dict[int, tuple[int, str]]) -> dict:
    """The part a word about motion names, as :class:`MotionPhrase` fields: the part noun before it in its clause ("the
    door swings freely", "the lid hinge has low damping"), else right after it ("a stiff handle joint", "low damping
    drawer slides"); its ``label`` None for the object itself (``head_starts``: where the request names it, "a heavy
    oak door that swings freely") or no part (the task's parts); with its ``ordinal`` and ``order`` when the noun is
    one part by its place (``ordinals``: noun end -> (ordinal, order), "the main door has a stiff hinge")."""
    label, at = rv.part_before(low, start, mention_starts=head_starts)
    if label is None:
        label, at = rv.part_after(low, end, mention_starts=head_starts)
    if label in (None, "body"):
        return {"label": None}
    place = ordinals.get(at)
    return {"label": label} if place is None else {"label": label, "ordinal": place[0], "order": place[1]}


@dataclass(frozen=True, slots=True)
class MotionWords:
    """What a request's words about motion ask (:func:`dynamics_words`): the ``damping`` level, whether the
    parts should hold their position, have a spring, be stiff or move freely, and the motion phrases per part."""

    damping: str
    holds_position: bool
    spring: bool
    stiff: bool
    free_moving: bool
    motions: list[MotionPhrase]


def dynamics_words(low: str, level_spans: list[tuple[int, int]], matched: list[tuple[int, str]],
                    warnings: list[str], head_starts: list[int], ordinals: dict[int, tuple[int, str]]) -> MotionWords:
    """The motion the dynamics words ask (explicit damping phrases win over cues); phrases go to ``matched``,
    contradictions to ``warnings``; ``ordinals`` (part noun end -> (ordinal, order), ``state_words.JointStates``)
    narrow a word to the one part its noun names by its place.
    A mass word ("a heavy box", "a heavy 25 kg door", "a heavy drawer") is a mass, not a stiffness; "heavy" before a
    joint word ("a heavy hinge") is stiff."""
    damping, strong_set, holds, spring, stiff, free = "moderate", False, False, False, False, False
    motions: list[MotionPhrase] = []
    hits = scan(low, _DYN_TABLE)
    for h in hits:
        kind, val = h.value  # type: ignore[misc]
        if any(a <= h.start < b for a, b in level_spans) or (kind == "heavy" and not rv.joint_word_soon(low, h.end)):
            continue  # "a heavy box", "a heavy 25 kg door", "a heavy drawer": a mass; "a heavy hinge": stiff
        neg = negated(low, h.start)
        matched.append((h.start, (("no " if kind == "spring" else "not ") if neg else "") + h.text))
        if kind == "spring":
            spring = not neg
        if neg:
            continue
        motions.append(MotionPhrase(kind=_motion_kind(kind, val, h.flag), phrase=h.text,
                                    **_motion_part(low, h.start, h.end, head_starts, ordinals)))
        holds |= kind == "hold"
        stiff |= kind in ("stiff", "heavy")
        free |= kind == "free"
        if kind in ("free", "heavy", "damping") and (h.flag == "strong" or not strong_set):
            damping = str(val)
            strong_set = strong_set or h.flag == "strong"
    for h in scan(low, _slide_table()):
        if negated(low, h.start):
            continue
        matched.append((h.start, h.text))
        part = _motion_part(low, h.start, h.end, head_starts, ordinals)
        motions.append(MotionPhrase(kind="slides", mechanism=str(h.value), phrase=h.text, **{**part, "label": part["label"] or "drawer"}))
    motions.sort(key=lambda m: low.find(m.phrase))
    for part in dict.fromkeys((m.label, m.ordinal, m.order) for m in motions):  # "the main door" and "the freezer door" apart
        kinds = [m for m in motions if (m.label, m.ordinal, m.order) == part]
        label = ordinal_words(part[1], part[2], part[0]).removeprefix("the ") if part[1] is not None else part[0]
        hard = [m for m in kinds if m.kind == "stiff"]
        loose = [m for m in kinds if m.kind == "free"]
        if hard and loose:
            warnings.append(f"contradiction: '{hard[0].phrase}' (stiff) and '{loose[0].phrase}' (moves freely) for the "
                            f"{label or 'object'}; both are applied (friction x4 over the floor, then no extra floor)")
    levels = {str(h.value[1]) for h in hits if h.flag == "strong" and not negated(low, h.start)}  # type: ignore[index]
    if len(levels) > 1:
        warnings.append(f"contradiction: damping levels {sorted(levels)} are all asked; '{damping}' (the last) is used")
    return MotionWords(damping, holds, spring, stiff, free, motions)
