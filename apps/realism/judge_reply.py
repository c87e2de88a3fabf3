"""Reading a realism judge's reply: which video it found more realistic.

Strict JSON first (``{"more_realistic": "A" | "B", "reason": "..."}``, one
Markdown fence tolerated), then a tolerant reading of prose such as "Video B
looks more realistic": only claims of the forms below count, and a reply whose
claims name both videos, or none, is no answer. The prose is read with every
run of white space made one space first, so the patterns' ``\s*`` never
backtrack over long runs (a reply of "Answer", 2,000 spaces and "x" is read in
linear time). Refusals, content-filter
blocks and empty replies are no answer. The judge protocol:
``docs/guide/realism.md``.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Literal

from asset2sim.models.errors import ReplyInvalid
from asset2sim.models.replies import parse_json_strict

Letter = Literal["A", "B"]

#: Longest reason kept from a reply, characters.
MAX_REASON_CHARS = 500

_VIDEO = r"(?:video|clip)\s*([ab])\b"
_ADVERB = r"(?:(?:much|far|slightly|clearly|somewhat|definitely|noticeably|a\s+bit|a\s+little)\s+)?"
_REAL = r"(?:physically\s+)?(?:realistic|plausible|natural|believable|convincing)"
_VERB = r"(?:is|looks|seems|appears|feels|moves|behaves)"
_UPPER = r"(?-i:([AB]))\b"

#: Claims that name the more realistic video (re.I; the group is the letter).
_FOR = [re.compile(p, re.I) for p in (
    rf"\b{_VIDEO}\s+{_VERB}\s+{_ADVERB}more\s+{_REAL}",
    rf"\b{_VIDEO}\s+is\s+(?:the\s+)?(?:more|most)\s+{_REAL}",
    rf"\b(?:more|most)\s+{_REAL}(?:\s+(?:one|video|clip))?\s*(?:is|:|is\s*:)\s*\**\s*(?:(?:video|clip)\s*([ab])\b|{_UPPER})",
    rf"\b(?:i\s+)?(?:prefer|choose|pick|select)\s+(?:the\s+)?{_VIDEO}",
    rf"\b(?:answer|verdict|choice|winner)\s*(?:is)?\s*[:=]?\s*\**\s*(?:(?:video|clip)\s*([ab])\b|{_UPPER})",
)]
#: Claims that name the less realistic video (the other one is then the answer).
_AGAINST = [re.compile(p, re.I) for p in (
    rf"\b{_VIDEO}\s+{_VERB}\s+{_ADVERB}less\s+{_REAL}",
)]
_JSON_FIELD = re.compile(r'"more_realistic"\s*:\s*"\s*(?:video\s*)?([ab])\s*"', re.I)


@dataclass(frozen=True)
class Reading:
    """What one reply says: ``choice`` the video it found more realistic (None: no usable answer) and
    ``reason`` (the model's reason, or why the reply is no answer)."""

    choice: Letter | None
    reason: str


def _letter(text: object) -> Letter | None:
    """``A`` / ``B`` from ``"A"``, ``"b"``, ``"Video A"`` (else None)."""
    if not isinstance(text, str):
        return None
    t = re.sub(r"^(?:video|clip)\s*", "", text.strip(), flags=re.I).strip().upper()
    return t if t in ("A", "B") else None  # type: ignore[return-value]


def _short(text: str) -> str:
    t = " ".join(str(text).split())
    return t if len(t) <= MAX_REASON_CHARS else t[:MAX_REASON_CHARS - 3] + "..."


def _claims(text: str) -> set[str]:
    """Letters the prose's claims make the more realistic video."""
    return ({g.upper() for pat in _FOR for m in pat.finditer(text) for g in m.groups() if g}
            | {{"A": "B", "B": "A"}[g.upper()] for pat in _AGAINST for m in pat.finditer(text) for g in m.groups() if g})


def read_reply(content: str, *, finish_reason: str | None = None, refusal: str | None = None) -> Reading:
    """The verdict of one reply.

    Order of reading: a refusal (``refusal`` set, or ``finish_reason`` ``content_filter``) or an empty
    reply is no answer; a reply that is exactly one JSON object answers through its ``more_realistic``
    field (``"A"``, ``"B"``, ``"Video A"`` ...; anything else is no answer); otherwise a
    ``"more_realistic": "A"`` field inside the text, else the prose claims ("Video B looks more
    realistic", "the more realistic one is A", "I prefer video A", "Answer: B", "Video A is less
    realistic" ...). Claims naming both videos, or none, are no answer. Never raises.
    """
    if refusal:
        return Reading(None, f"refused: {_short(refusal)}")
    if finish_reason == "content_filter":
        return Reading(None, "blocked by the provider's content filter")
    text = content or ""
    cut = " (cut off at the token limit)" if finish_reason == "length" else ""
    if not text.strip():
        return Reading(None, "empty reply" + cut)
    try:
        obj = parse_json_strict(text)
    except ReplyInvalid:
        obj = None
    if obj is not None:
        choice = _letter(obj.get("more_realistic"))
        if choice is None:
            return Reading(None, f"JSON reply without more_realistic 'A' or 'B': {_short(text)}")
        return Reading(choice, _short(obj.get("reason", "") if isinstance(obj.get("reason"), str) else ""))
    prose = " ".join(text.split())  # one space between words: every \s* below matches at most one character
    letters = {m.upper() for m in _JSON_FIELD.findall(prose)} or _claims(prose)
    if len(letters) == 1:
        return Reading(letters.pop(), _short(text))  # type: ignore[arg-type]
    why = "names both videos as more realistic" if letters else "names no video as more realistic"
    return Reading(None, f"prose that {why}{cut}: {_short(text)}")
