"""The request's words about joint states: how open each part should be ("the door half open", "the second
drawer slightly open", "the lid and the door closed", "the others closed"), as one
:class:`~asset2sim.schemas.request.JointStateRequest` per target (:func:`joint_states`): a band and a target
fraction of the range, the part by label and ordinal, or every task-relevant part.
"""

from __future__ import annotations

import itertools
import re
from bisect import bisect_left, bisect_right
from dataclasses import dataclass

from asset2sim.schemas.request import JointStateRequest, StateTarget
from asset2sim.tasks.interpret import request_values as rv
from asset2sim.tasks.interpret.phrase_scan import TOKEN, Hit, Tokens, negated, scan, sentences, word_table

#: Opening fraction of "less than halfway" / "more than halfway" (``words.yaml``): one band step (0.1 of the range)
#: from 0.5.
LESS_THAN_HALF, MORE_THAN_HALF = 0.4, 0.6

#: The state words (``words.yaml`` ``state``): value a band, (band, target) for a fraction; flag "bare" for a lone
#: "open", "end" for a physical end.
_STATE_TABLE = [(rx, (val[0], StateTarget(kind="fraction", value=val[1])) if isinstance(val, tuple) else val, flag)
                for rx, val, flag in word_table("state")]

_VERB_AFTER = re.compile(r"\s+(?:the|a|an|its|their|it|them|up|and close|or close)\b")

_VERB_BEFORE = re.compile(
    r"(?:\bto|\bcan|\bcould|\bwill|\bwould|\bshould|\bmust|\bplease|\blet me|\band|\bor|\bto be able to)\s+$"
)

_NUM_AFTER = re.compile(
    r"\s*(?:#|no\.?\s*|numbers?\s*)?(\d{1,2}(?:\s*(?:,\s*(?:and\s+)?|and\s+|or\s+|&\s*)\d{1,2})*)\b"
)

ORDINALS = word_table("ordinals")

#: Ordinal flags that only count right before the part noun ("the freezer door", not "a freezer with its door").
_ADJACENT_ORDERS = frozenset({"middle", "size"})

#: "one of its two doors": one of them, however many words name them.
_ONE_OF = re.compile(r"one\s+of\s+(?:(?:the|its|their|his|her)\s+)?(?:(?:two|three|four|five|both|\d)\s+)?")

_THE_BEFORE = re.compile(r"(?<![\w-])(?:the|its|their)\s+$")

_END_TAIL = re.compile(r"\s*(?:$|[,.;:!?)]|and\b|but\b|with\b|while\b|position\b)")

#: Labels (:func:`request_values.part_label`'s) pressed from their rest, the closed end: "pressed" is the far end. A
#: pump dispenser's pump and its head rest up, their closed end, as push buttons do (``part_priors.push_buttons``,
#: ``docs/design/refine.md`` "Closed state"); a stapler's arm is not one: it is closed pressed down.
PRESSED_LABELS = frozenset({"button", "lever", "trigger", "plunger", "foot", "pump", "head", "nozzle"})

_BARE_END = re.compile(r"(?:all the way |fully )?(?:up|down|on|off)|upright|" + rv.WORDS["fragments"]["FLAT"])  # "the handle upright": a part's end

_END_LEAD = re.compile(r"(?:" + rv.PART_WORDS + r")(?:\s+(?:are\s+)?(?:both|all|each))?"
                       r"(?:\s+(?:is|are|was|were|set|turned|switched|flipped|pushed|pulled|left|stays?|kept))?\s+$")


def _state_hits(low: str, numeric: list[rv.Found]) -> list[Hit]:
    """State phrases left to right, not overlapping: the state table's words and the ``numeric`` states."""
    nums = [Hit(f.start, f.end, f.text, f.value, "number") for f in numeric]  # left to right, not overlapping
    num_ends = [n.end for n in nums]

    def under_number(h: Hit) -> bool:  # the first number ending after h starts overlaps it when it starts before h ends
        k = bisect_right(num_ends, h.start)
        return k < len(nums) and nums[k].start < h.end

    words = []
    for h in scan(low, _STATE_TABLE):  # a number wins over the words it overlaps ("propped open about a third of the way")
        k = bisect_left(num_ends, h.end)  # and takes in the words right before it ("tilted back 120 degrees")
        if k < len(nums) and not low[h.end: nums[k].start].strip() and nums[k].start >= h.end:
            nums[k] = Hit(h.start, nums[k].end, low[h.start: nums[k].end], nums[k].value, "number")
        elif not under_number(h):
            words.append(h)
    moving = [(h.start, h.end) for h in scan(low, _MOVING_TABLE)]  # "swings shut on its own": a closer, not a state
    return rv.leftmost_longest([h for h in words + nums
                                if _is_state(low, h) and not any(a <= h.start and h.end <= b for a, b in moving)])


#: The words about motion that say how a part moves or closes (``words.yaml`` ``motion``: flags "close" and "soft",
#: kind "free": "swings shut on its own", "snaps shut", "never slams shut", "swings open freely"): the end word inside
#: one names the motion, not the state the part is at.
_MOVING_TABLE = [row for row in word_table("motion") if row[2] in ("close", "soft") or row[1][0] == "free"]


def _is_state(low: str, h: Hit) -> bool:
    """False for a bare "open" that is a verb ("to open the lid") and a bare end word without a part noun before it."""
    if h.flag == "bare" and h.text.startswith("open"):
        return not (_VERB_AFTER.match(low, h.end) or _VERB_BEFORE.search(low[max(0, h.start - 20): h.start]))
    if h.flag == "end" and _BARE_END.fullmatch(h.text):
        if not _END_LEAD.search(low[max(0, h.start - 40): h.start]) or negated(low, h.start):
            return False
        return not (h.text.endswith(("on", "off")) and not _END_TAIL.match(low, h.end))  # "a door on a plastic body": a preposition
    return True


def _band_and_target(value: object, label: str | None = None) -> tuple[str, StateTarget | None]:
    """A state hit's value -> (band, target); ``label``: the part it names (None: every part)."""
    if isinstance(value, tuple):
        return value[0], value[1]
    v = str(value)
    if v == "pressed":  # a stapler's arm pressed down is closed
        return ("fully" if label in PRESSED_LABELS else "closed"), None
    if v == "pressed_slightly":  # a button or a pump's head pressed a little is a little from its rest; a stapler's arm
        return ("slightly_open" if label in PRESSED_LABELS else "mostly"), None  # from its open rest
    if v.startswith("end:"):
        end = v[4:]
        return ("fully" if end in ("high", "on") else "closed"), StateTarget(kind="end", end=end)  # type: ignore[arg-type]
    return v, None


@dataclass
class _Part:
    start: int
    end: int
    label: str
    ordinals: list[tuple[int, str]]
    """(ordinal, order) pairs; order "vertical" or a spatial order."""
    quant: bool
    phrase_start: int
    none: bool = False
    """"none of the drawers open": the state is negated (open -> closed, closed -> open)."""


_FRACTION_AHEAD = re.compile(r"\s*/\s*\d")

_NONE_OF = re.compile(r"(?<![\w-])(?:none|neither) of (?:the |its |their |these |those )?$")

#: What may follow a state's phrase in a later one that says it more exactly ("turned on" -> "turned on halfway"):
#: words, no conjunction or mark ("fully open and closed" is two states).
_MORE_EXACTLY = re.compile(r" (?!(?:and|or|but|then|yet)\b)[\w -]+")

#: "lying on its back with the lid open": "with" starts another noun phrase, the place word is not the lid's.
_WITH = re.compile(r"(?<![\w-])with(?![\w-])")

_ORD_JOIN = re.compile(r"\s*(?:,\s*(?:and|or)?|and|or|&)\s*(?:the\s+)?$")


def _parts(low: str, tokens: Tokens) -> list[_Part]:
    """Part nouns with their ordinals ("the first and second drawers", "drawer 2") or quantifier."""
    ords = scan(low, ORDINALS)  # left to right, not overlapping: ends ascend too
    ord_ends = [o.end for o in ords]
    # enumerations ("the first, second and third drawers"): chain[j] is the first ordinal of the run ending at ords[j]
    chain: list[int] = []
    for j, o in enumerate(ords):
        joined = j and ords[j - 1].flag != "quant" and _ORD_JOIN.match(low, ords[j - 1].end, o.start) is not None
        chain.append(chain[j - 1] if joined else j)
    out: list[_Part] = []
    for m in rv.PART_RX.finditer(low):
        ordinals: list[tuple[int, str]] = []
        quant = False
        pstart = m.start()
        n_before = bisect_right(ord_ends, m.start())  # ordinals ending before the noun
        if n_before:
            o = ords[n_before - 1]
            gap = tokens.count(o.end, m.start())
            if (gap == 0 or gap <= 2 and o.flag not in _ADJACENT_ORDERS or _ONE_OF.fullmatch(low, o.start, m.start())) \
                    and not tokens.marks_between(o.end, m.start()) and not _WITH.search(low, o.end, m.start()):
                if o.flag == "quant":
                    quant = True
                    pstart = o.start
                else:
                    first = chain[n_before - 1]
                    ordinals = [(int(ords[i].value), ords[i].flag or "vertical") for i in range(first, n_before)]  # type: ignore[arg-type]
                    pstart = ords[first].start
        num = _NUM_AFTER.match(low, m.end())
        if num is not None and (rv.UNIT_AHEAD.match(low, num.end()) or _FRACTION_AHEAD.match(low, num.end())):
            num = None  # "drawer 10 cm": a distance; "door 3/4 open": a fraction
        if not ordinals and num is not None and not quant:
            ordinals = [(int(n) - 1, "vertical") for n in re.findall(r"\d+", num.group(1)) if int(n) >= 1]
        none = _NONE_OF.search(low, max(0, pstart - 24), pstart)
        out.append(_Part(m.start(), m.end(), rv.part_label(m.group(0)), ordinals, quant, none.start() if none else pstart,
                         none is not None))
    return out


_FWD_STOP = {"and", "with", "but", "or", "while", "its", "the", "a", "an", "their", "his", "her", "in", "of", "for", "to",
             ",", ";", ":"}


def _forward_part(low: str, end: int, limit: int, part_at: dict[int, _Part]) -> _Part | None:
    """A part noun (``part_at``: by start) right after a state, at most one modifier word between."""
    for t in itertools.islice(TOKEN.finditer(low, end, limit), 2):
        if (p := part_at.get(t.start())) is not None or t.group(0) in _FWD_STOP:
            return p
    return None


_ELIDED = re.compile(r"\s*(?:,\s*)?(?:and|or|but|then|yet)?\s*(?:also\s+|at the same time\s+)?")

#: "the others", "the rest", "the remaining ones": the parts of the last label no other phrase set.
OTHERS = re.compile(r"(?<![\w-])(?:others|(?:the )?rest(?: of them)?|remaining(?: ones)?|other(?: ones?)?)(?![\w-])")


@dataclass(frozen=True, slots=True)
class JointStates:
    """The joint states a request asks: ``requests`` (every joint first, then per label, then one part: the
    specific one wins), ``hits`` (the state words used), ``warnings`` (contradictions), ``overridden`` (the
    phrases a later one for the same part replaced) and ``ordinals`` (where each part noun named by one place ends ->
    (ordinal, order): "the main door" -> (-1, "size"), for the words about its motion)."""

    requests: list[JointStateRequest]
    hits: list[Hit]
    warnings: list[str]
    overridden: list[str]
    ordinals: dict[int, tuple[int, str]]


def joint_states(low: str, tokens: Tokens, numeric: list[rv.Found]) -> JointStates:
    """The joint-state requests of ``low`` (``numeric``: the states in numbers, :func:`rv.state_quantities`)."""
    # step 1: the state words, the part nouns and the ordinals, left to right
    bands = _state_hits(low, numeric)  # every list here is left to right and not overlapping
    parts = _parts(low, tokens)
    # ordinals without a part noun ("the second slightly open"; "the freezer open": the smallest part)
    ords = [o for o in scan(low, ORDINALS) if o.flag == "" or o.flag in _ADJACENT_ORDERS and _THE_BEFORE.search(low, max(0, o.start - 8), o.start)]
    band_starts = [b.start for b in bands]
    part_starts = [p.start for p in parts]
    part_ends = [p.end for p in parts]
    part_at = {p.start: p for p in parts}
    ord_starts = [o.start for o in ords]
    ord_ends = [o.end for o in ords]
    # step 2: what the sentences build
    result: list[JointStateRequest] = []
    lone: set[int] = set()  # ids of the requests of a lone "open" ("the lid wide open, held open": "wide open" says more)
    used: list[Hit] = []
    last_label: str | None = None
    prev_subjects: list[_Part] = []
    claimed: set[int] = set()

    # a request for the parts of ``label`` (None: every part)
    def make(label: str | None, b: Hit, phrase: str, ordinal: int | None = None, order: str = "vertical",
             none: bool = False) -> JointStateRequest:
        band, target = _band_and_target(b.value, label)
        if none:  # "none of the drawers open": closed; "none of the doors closed": open
            band, target = ("mostly" if band == "closed" else "closed"), None
        js = JointStateRequest(selector="all" if label is None else "label", label=label,  # type: ignore[arg-type]
                               ordinal=ordinal, order=order, band=band, target=target, phrase=phrase,  # type: ignore[arg-type]
                               bare=b.flag == "bare" and not none)
        if js.bare:
            lone.add(id(js))
        return js

    # step 3: per state word, its subject: a part after or before it, the parts of the last state, "the others", an ordinal, else every part
    for s0, s1 in sentences(low):
        sb = bands[bisect_left(band_starts, s0): bisect_left(band_starts, s1)]
        for i, b in enumerate(sb):
            seg0 = sb[i - 1].end if i > 0 else s0
            seg1 = sb[i + 1].start if i + 1 < len(sb) else s1
            fwd = _forward_part(low, b.end, seg1, part_at)
            # parts before the state, but not one an earlier state went forward to ("a fully open door and the cap ajar")
            back = [p for p in parts[bisect_left(part_starts, seg0): bisect_right(part_ends, b.start)] if p.start not in claimed]
            subjects: list[_Part] = []
            if fwd is not None:
                claimed.add(fwd.start)
                subjects = [fwd]
            elif not back and i > 0 and prev_subjects and _ELIDED.fullmatch(low, seg0, b.start):
                subjects = list(prev_subjects)  # "the lid fully open and closed": the same lid
            elif back:
                subjects = [back[-1]]
                # "the lid and the door closed"
                if len(back) >= 2 and re.fullmatch(
                    r"\s*(?:,|and|or|&)\s*(?:(?:the|a|an|its|their)\s+)?", low[back[-2].end: back[-1].phrase_start]
                ):
                    subjects.insert(0, back[-2])
            if subjects:
                for p in subjects:
                    start = min(p.phrase_start, b.start)
                    end = max(p.end, b.end)
                    phrase = " ".join(low[start:end].split())
                    for ordinal, order in (p.ordinals if p.ordinals and not p.quant else [(None, "vertical")]):
                        result.append(make(p.label, b, phrase, ordinal, order, p.none))
                    last_label = p.label
                prev_subjects = subjects
                continue
            prev_subjects = []
            others = OTHERS.search(low, seg0, b.start)
            if others is not None and last_label is not None:
                used.append(Hit(others.start(), others.end(), others.group(0), None))
                result.append(make(last_label, b, " ".join(low[others.start(): b.end].split())))
                continue
            seg_ords = ords[bisect_left(ord_starts, seg0): bisect_right(ord_ends, b.start)]
            if seg_ords:
                o = seg_ords[-1]
                phrase = " ".join(low[o.start: b.end].split())
                result.append(make(last_label, b, phrase, int(o.value), o.flag or "vertical"))  # type: ignore[arg-type]
                continue
            result.append(make(None, b, b.text))
    # step 4: one request per target, contradictions warned
    # one request per target: a later phrase overrides an earlier one; a different state is warned
    warnings: list[str] = []
    overridden: list[str] = []
    dedup: dict[tuple, JointStateRequest] = {}
    for js in result:
        key = (js.selector, js.label, js.ordinal, js.order)
        old = dedup.pop(key, None)
        if old is not None and "closed" not in (old.band, js.band) and lone & {id(js), id(old)}:
            js, old = (old if id(js) in lone else js), None  # a lone "open" and a more exact opening of one part: the exact one
        elif old is not None and _MORE_EXACTLY.fullmatch(js.phrase.removeprefix(old.phrase)) and js.phrase.startswith(old.phrase):
            old = None  # "the handle turned on halfway": the later phrase is the earlier one said more exactly
        if old is not None and (old.band, old.target) != (js.band, js.target):
            who = "every task-relevant part" if js.selector == "all" else (js.label or "part") + ("" if js.ordinal is None else f" #{js.ordinal} ({js.order})")
            warnings.append(f"contradiction: '{old.phrase}' and '{js.phrase}' both set {who}; the later one ('{js.phrase}') is used")
            overridden.append(old.phrase)
        dedup[key] = js
    specific = sorted(dedup.values(), key=lambda js: 0 if js.selector == "all" and js.ordinal is None else (1 if js.ordinal is None else 2))
    kept = {js.phrase for js in specific}
    return JointStates(specific, bands + used, warnings, [p for p in dict.fromkeys(overridden) if p not in kept],
                       {p.end: p.ordinals[0] for p in parts if len(p.ordinals) == 1})
