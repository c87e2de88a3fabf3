"""Parse a natural-language request into a :class:`RequestSpec` (grammar: ``docs/guide/requests.md``;
numbers, masses and materials: :mod:`.request_values`; words about motion: :mod:`.motion_words`; the
phrase tables' scanning: :mod:`.phrase_scan`). Pure, linear in the length; never raises on a
string of at most :data:`MAX_REQUEST_CHARS` characters.
"""

from __future__ import annotations

import functools
import itertools
import math
import re
from bisect import bisect_left, bisect_right
from dataclasses import dataclass

from asset2sim.schemas.request import JointStateRequest, PartProperty, RequestSpec, StateTarget
from asset2sim.tasks.interpret.categories import CategoryMention, find_category_mentions, phrase_regex, request_category, variant_mention
from asset2sim.tasks.interpret.mounting import mounting_mentions
from asset2sim.prior_tables import load_priors
from asset2sim.tasks.interpret import request_values as rv
from asset2sim.tasks.interpret.motion_words import dynamics_words
from asset2sim.tasks.interpret.phrase_scan import (
    CLAUSE_MARK, TOKEN, WORD_RUN, Hit, Tokens, compile_table, negated, scan, sentences,
)


#: Longest request accepted (characters): 64 KiB, hundreds of times a real request.
MAX_REQUEST_CHARS = 65_536


class RequestTooLong(ValueError):
    """The request is longer than :data:`MAX_REQUEST_CHARS` (``code`` ``REQUEST_TOO_LONG``)."""

    code = "REQUEST_TOO_LONG"

    def __init__(self, length: int):
        super().__init__(f"REQUEST_TOO_LONG: the request has {length} characters; at most {MAX_REQUEST_CHARS} are accepted")
        self.length = length
        self.codes = [self.code]


def check_request_length(text: str) -> None:
    """Raise :class:`RequestTooLong` when ``text`` exceeds :data:`MAX_REQUEST_CHARS`."""
    if len(text) > MAX_REQUEST_CHARS:
        raise RequestTooLong(len(text))


_OPEN = r"open(?:ed)?"
#: Verbs of a part's motion a degree word may follow ("pulled out halfway"): the degree is the state.
_MOVED = (r"(?:(?:pulled|slid|drawn|pushed) (?:out|in)|pulled|slid|extended|retracted|raised|lifted|lowered|swung|tilted|"
          r"turned|rotated|unfolded|folded|unscrewed|screwed (?:off|open)|loosened)")
#: Hedges before a degree word ("open about halfway"): the degree is what is asked.
_ABOUT = r"(?:(?:about|around|roughly|approximately|approx\.?|some|more or less|close to|nearly|almost|just about) )?"
#: Comparatives around halfway ("a little less than halfway open"): an opening fraction a step below or above it.
_LESS = r"(?:(?:a (?:little|bit|tad)|slightly|just|somewhat) )?(?:less than|under|short of|below)"
_MORE = r"(?:(?:a (?:little|bit|tad)|slightly|just|somewhat) )?(?:more than|over|past|beyond|above)"
_HALF = r"(?:half[- ]?way|half(?: of the way)?|the halfway (?:point|mark))"
#: Opening fraction of "less than halfway" / "more than halfway": one band step (0.1 of the range) from 0.5.
LESS_THAN_HALF, MORE_THAN_HALF = 0.4, 0.6
_SZ = r"[- ]?siz(?:ed?|es)"

# (regex, size class, flag) - flag "weak": only counts right before a category word.
_SIZE_TABLE = compile_table(
    [
        (r"tiny|teeny(?:[- ]tiny)?|miniature|minuscule|itsy[- ]bitsy", "tiny", ""),
        (r"pocket" + _SZ, "tiny", ""),
        (r"(?:a )?(?:quarter|third) (?:the|its|of the) (?:usual |normal |regular )?size", "tiny", ""),
        (r"half (?:the|its|of the) (?:usual |normal |regular )?size", "very_small", ""),
        (r"(?:twice|double|two times) (?:the|its) (?:usual |normal |regular )?size", "very_large", ""),
        (r"(?:very|really|super|extremely|extra|quite)[- ]small", "very_small", ""),
        (r"(?:very|really|super)[- ]little", "very_small", "weak"),
        (r"for (?:a |the |my )?(?:bab(?:y|ies)|toddlers?|infants?|newborns?)", "very_small", ""),
        (r"for an (?:infant|newborn)", "very_small", ""),
        (r"bab(?:y|ies)|toddlers?|infants?|toy|doll" + r"(?:[- ]?house)?", "very_small", ""),
        (r"small(?:er|ish)?|mini|minifridge|compact|petite|personal|carry[- ]?on", "small", ""),
        (r"(?:cabinet|cupboard|desk|travel|child|kid|apartment)" + _SZ, "small", ""),
        (r"countertop|counter[- ]top|benchtop|tabletop|table[- ]top|desktop", "small", ""),
        (r"life[- ]?siz(?:e|ed)|real[- ]siz(?:e|ed)|actual size", "regular", ""),
        (r"for (?:a |the |my )?(?:child(?:ren)?|kids?)", "small", ""),
        (r"little", "small", "weak"),
        (r"regular(?:" + _SZ + r")?", "regular", ""),
        (r"(?:standard|normal|average|medium|typical|full|mid)" + _SZ, "regular", ""),
        (r"standard|normal|average|medium|typical|ordinary", "regular", "weak"),
        (r"(?:very|really|super|extremely|extra)[- ](?:large|big)|huge|giant|enormous|massive|oversized?|xx?l", "very_large", ""),
        (r"(?:large|big)(?:ger|r)?|jumbo|family" + _SZ + r"|king" + _SZ, "large", ""),
        (r"(?:large|big)" + _SZ, "large", ""),
    ]
)

# (regex, band, flag) - flag "bare" for a lone "open".
_STATE_TABLE = compile_table(
    [
        # negations first (longest match wins at a position)
        (r"(?:not (?:at all |even slightly |yet )?|no longer |never )" + _OPEN + r"(?: at all)?", "closed", ""),
        (r"no longer (?:closed|shut)", "mostly", ""),
        (r"(?:is|are|was)n'?t " + _OPEN, "closed", ""),
        (r"not (?:quite|fully|completely|entirely) (?:closed|shut)", "slightly_open", ""),
        (r"not (?:closed|shut)", "halfway", ""),
        (r"not (?:fully|completely|all the way|entirely) " + _OPEN, "mostly", ""),
        # hedged and compared ("mostly closed": a small opening, not closed; "a little less than halfway open")
        (r"(?:mostly|largely|almost|nearly|practically|just about|almost fully|nearly fully|not quite fully) (?:closed|shut)", "slightly_open", ""),
        (r"(?:" + _OPEN + r" |" + _MOVED + r" )?" + _LESS + r" " + _HALF + r"(?:[- ]" + _OPEN + r")?",
         ("halfway", StateTarget(kind="fraction", value=LESS_THAN_HALF)), ""),
        (r"(?:" + _OPEN + r" |" + _MOVED + r" )?" + _MORE + r" " + _HALF + r"(?:[- ]" + _OPEN + r")?",
         ("halfway", StateTarget(kind="fraction", value=MORE_THAN_HALF)), ""),
        # closed
        (r"(?:fully |completely |all the way )?(?:closed|shut)(?: all the way| completely| tight)?", "closed", ""),
        (r"(?:turned|switched|shut) off", "closed", ""),
        # fully
        (r"(?:fully|completely|totally|maximally|wide) " + _OPEN, "fully", ""),
        (r"(?:" + _OPEN + r" )?all the way(?: " + _OPEN + r")?", "fully", ""),
        (_OPEN + r" (?:fully|completely|wide|to the max(?:imum)?|as far as (?:it|they) (?:can|will) go|to (?:its|their|the) (?:limit|maximum|max))", "fully", ""),
        (r"(?:turned|switched) (?:fully )?on(?: (?:full|fully|completely|all the way))?|fully (?:extended|raised|pulled out)|pulled all the way out", "fully", ""),
        (r"(?:" + _OPEN + r"|laid open|lying open|unfolded|folded out|swung open) flat|flat open|(?:" + _OPEN + r"|folded|swung) (?:out )?flat", "fully", ""),
        (r"(?:folded|bent|pushed|tilted|laid|swung) (?:all the way )?back(?: flat| all the way)?", "fully", ""),
        # named states: which end they are does not depend on the geometry
        (r"(?:pulled|slid|drawn) (?:all the way )?out|extended|unfolded|unscrewed|deployed", "fully", ""),
        (r"(?:(?:pulled|slid|drawn) out|extended|unfolded) (?:all the way|fully|completely)", "fully", ""),
        (r"pushed (?:all the way )?in|retracted|folded(?: up| shut| closed| down)?|screwed (?:on|shut|closed|tight)|pressed (?:down|in)|pressed|depressed|tucked in", "closed", ""),
        # physical ends: decided from the geometry after scaling (request_apply)
        (r"(?:raised|lifted) (?:all the way|fully|completely|to the top)", "end:high", "end"),
        (r"(?:in|at|to) (?:the|its|their) (?:up|raised|upper|top|highest) position|(?:raised|lifted|propped|popped|sprung|flipped|pulled|pushed|swung|tilted|turned|flicked|moved|set|left)(?: all the way)? up|raised|lifted|(?:all the way |fully )?up", "end:high", "end"),
        (r"(?:in|at|to) (?:the|its|their) (?:down|lowered|lower|bottom|lowest) position|(?:lowered|flipped|pulled|pushed|swung|tilted|flicked|moved|set|left)(?: all the way)? down|lowered|(?:all the way |fully )?down", "end:low", "end"),
        (r"(?:in|at|to) (?:the|its) on position|(?:set|flipped|flicked|toggled|left) on|on", "end:on", "end"),
        (r"(?:in|at|to) (?:the|its) off position|(?:flipped|flicked|toggled|left) off|off", "end:off", "end"),
        # mostly
        (r"(?:mostly|largely|almost fully|nearly fully|almost completely|nearly completely|almost all the way|nearly all the way) " + _OPEN, "mostly", ""),
        (r"(?:almost|nearly) (?:fully|all the way)(?: " + _OPEN + r")?", "mostly", ""),
        (r"three[- ]quarters?(?: of the way)?(?:[- ]" + _OPEN + r")?", "mostly", ""),
        (_OPEN + r" (?:most of the way|three[- ]quarters?(?: of the way)?)", "mostly", ""),
        (_MOVED + r" (?:most of the way|three[- ]quarters?(?: of the way)?)", "mostly", ""),
        # halfway
        (_ABOUT + r"half[- ]?way(?:[- ]" + _OPEN + r")?|mid[- ]?way(?:[- ]" + _OPEN + r")?", "halfway", ""),
        (_ABOUT + r"half[- ]" + _OPEN + r"|half of the way(?: " + _OPEN + r")?|half[- ](?:closed|shut)", "halfway", ""),
        (_OPEN + r" " + _ABOUT + r"(?:half[- ]?way|half)", "halfway", ""),
        (_MOVED + r" " + _ABOUT + r"(?:half[- ]?way|half(?: of the way)?)", "halfway", ""),
        (r"(?:partially|partly) " + _OPEN, "halfway", ""),
        # quarter
        (_ABOUT + r"(?:a |one )?quarter(?:[- ]way| of the way)?[- ]" + _OPEN, "quarter", ""),
        (_OPEN + r" " + _ABOUT + r"(?:a |one )?quarter(?:[- ]way| of the way)?", "quarter", ""),
        (_MOVED + r" " + _ABOUT + r"(?:a |one )?quarter(?:[- ]way| of the way)?", "quarter", ""),
        (r"(?:a |one )?quarter of the way", "quarter", ""),
        # slightly open
        (r"(?:slightly|barely|just|a (?:little |tiny )?bit|a little|a tad|a crack|a touch) " + _OPEN, "slightly_open", ""),
        (_OPEN + r" (?:slightly|a (?:little |tiny )?bit|a little|a crack|a tad|just a (?:little|bit))", "slightly_open", ""),
        (_MOVED + r" (?:slightly|a (?:little |tiny )?bit|a little|a tad|just a (?:little|bit))", "slightly_open", ""),
        (r"(?:slightly |partially )?ajar|cracked(?: " + _OPEN + r")?(?: (?:a (?:little|bit|crack)|slightly))?", "slightly_open", ""),
        (r"slightly (?:raised|lifted|pulled out|extended|apart|rotated|turned)", "slightly_open", ""),
        # "open" after a verb that leaves it open ("the lid propped open"): as a lone "open", never the verb "to open"
        (r"(?:propped|popped|sprung|flipped|swung|thrown|flung|left|kept|held|standing|stands|hanging|hangs|wedged) " + _OPEN, "mostly", ""),
        # a lone "open"
        (_OPEN, "mostly", "bare"),
    ]
)

_VERB_AFTER = re.compile(r"\s+(?:the|a|an|its|their|it|them|up|and close|or close)\b")
_VERB_BEFORE = re.compile(
    r"(?:\bto|\bcan|\bcould|\bwill|\bwould|\bshould|\bmust|\bplease|\blet me|\band|\bor|\bto be able to)\s+$"
)

_PART_WORD = re.compile(r"(?:" + rv.PART_WORDS + r")")
_NUM_AFTER = re.compile(
    r"\s*(?:#|no\.?\s*|numbers?\s*)?(\d{1,2}(?:\s*(?:,\s*(?:and\s+)?|and\s+|or\s+|&\s*)\d{1,2})*)\b"
)

_ORDINALS = compile_table(
    [
        (r"first|1st", 0, ""),
        (r"second|2nd", 1, ""),
        (r"third|3rd", 2, ""),
        (r"fourth|4th", 3, ""),
        (r"fifth|5th", 4, ""),
        (r"top(?:most)?|upper(?:most)?|highest", 0, ""),
        (r"bottom(?:most)?|lowest|lower|last", -1, ""),
        (r"every|all|each|both", None, "quant"),
        # spatial words: the flag is the order they count in (docs/guide/requests.md)
        (r"left(?:most|[- ]hand)?", 0, "left_right"),
        (r"right(?:most|[- ]hand)?", 0, "right_left"),
        (r"front(?:most)?", 0, "front_back"),
        (r"back(?:most)?|rear(?:most)?", -1, "front_back"),
        # resolved from the geometry (tasks/interpret/named_parts.py): the middle one of an odd count, along the
        # direction the parts are spread in; by the size of the moving part's box, smallest first ("the freezer
        # door": a refrigerator's smaller door; "the main door": its largest)
        (r"middle(?:most)?|cent(?:er|re)|central", 0, "middle"),
        (r"freezer|small(?:er|est)|narrow(?:er|est)", 0, "size"),
        (r"main|large(?:r|st)|bigg(?:er|est)|wid(?:er|est)", -1, "size"),
        # "one door open and the other shut": one of them (the first, top to bottom), the rest by "the other"
        (r"one", 0, "vertical"),
    ]
)
#: Ordinal flags that only count right before the part noun ("the freezer door", not "a freezer with its door").
_ADJACENT_ORDERS = frozenset({"middle", "size"})
#: "one of its two doors": one of them, however many words name them.
_ONE_OF = re.compile(r"one\s+of\s+(?:(?:the|its|their|his|her)\s+)?(?:(?:two|three|four|five|both|\d)\s+)?")
_THE_BEFORE = re.compile(r"(?<![\w-])(?:the|its|their)\s+$")


_POSE_TABLE = compile_table(
    [
        (r"(?:lying|laid|lies|lay|placed|resting|rests|set|put) flat|lying down|flat on (?:its|the) (?:back|floor|ground|table|base)|lying on its back", "lying_flat", ""),
        (r"(?:resting|lying|lies|rests|placed|laid|sitting|sits|standing|set|tipped|turned|put|lay) (?:on (?:its|their|one|a) side|sideways)|on (?:its|their) side", "sideways", ""),
        (r"(?:standing |placed |set )?upright|standing up|right side up", "upright", ""),
    ]
)


@functools.lru_cache(maxsize=1)
def _size_factors() -> dict[str, float]:
    return {k: v.factor for k, v in load_priors().size_classes.items()}


_COMPARED = re.compile(r"(?:small|large|big)(?:ger|er|r|est|st)")


@dataclass(frozen=True, slots=True)
class _SizeWords:
    """The size words of a request: ``size_class`` (None without one), its ``factor`` on the size (1 without
    one), ``phrase`` (the words counted, comma-joined), ``hits`` (those words) and ``against`` (the words
    pointing the other way from the first one)."""

    size_class: str | None
    factor: float
    phrase: str
    hits: list[Hit]
    against: list[Hit]


def _parse_size(low: str, mentions: list[CategoryMention], tokens: Tokens) -> _SizeWords:
    """The size class, factor, phrase, the size words used, and those pointing the other way from the first one."""
    used: list[Hit] = []
    mention_starts = [m.start for m in mentions]  # left to right
    for h in scan(low, _SIZE_TABLE):
        if negated(low, h.start):
            continue
        if _COMPARED.fullmatch(h.text) and rv.PART_RX.match(low, h.end + 1):
            continue  # "the smaller door": which door (an ordinal by size), not the object's size
        if h.flag == "weak":
            k = bisect_left(mention_starts, h.end)  # the first mention after the word
            if k == len(mentions) or tokens.count(h.end, mentions[k].start) > 2:
                continue
        used.append(h)
    if not used:
        return _SizeWords(None, 1.0, "", [], [])
    facs = _size_factors()
    first_dir = math.copysign(1.0, math.log(facs[str(used[0].value)])) if facs[str(used[0].value)] != 1.0 else 0.0
    same = [h for h in used if first_dir == 0.0 or math.log(facs[str(h.value)]) * first_dir >= 0.0]
    best = max(same, key=lambda h: abs(math.log(facs[str(h.value)])))
    cls = str(best.value)
    counted = [h for h in same if h.value != "regular" or cls == "regular"]
    return _SizeWords(cls, facs[cls], ", ".join(h.text for h in counted), counted, [h for h in used if h not in same])


_END_TAIL = re.compile(r"\s*(?:$|[,.;:!?)]|and\b|but\b|with\b|while\b|position\b)")
_BARE_END = re.compile(r"(?:all the way |fully )?(?:up|down|on|off)")
_END_LEAD = re.compile(r"(?:" + rv.PART_WORDS + r")(?:\s+(?:are\s+)?(?:both|all|each))?"
                       r"(?:\s+(?:is|are|was|were|set|turned|switched|flipped|pushed|pulled|left|stays?|kept))?\s+$")


def _state_hits(low: str, numeric: list[rv.Found] | None = None) -> list[Hit]:
    """State phrases left to right, not overlapping: the state table's words and the ``numeric`` states."""
    nums = [Hit(f.start, f.end, f.text, f.value, "number") for f in (numeric or [])]  # left to right, not overlapping
    num_ends = [n.end for n in nums]

    def under_number(h: Hit) -> bool:  # the first number ending after h starts overlaps it when it starts before h ends
        k = bisect_right(num_ends, h.start)
        return k < len(nums) and nums[k].start < h.end

    # a number wins over the words it overlaps ("propped open about a third of the way": a third)
    hits = [h for h in scan(low, _STATE_TABLE) if not under_number(h)] + nums
    return rv.leftmost_longest([h for h in hits if _is_state(low, h)])


def _is_state(low: str, h: Hit) -> bool:
    """False for a bare "open" that is a verb ("to open the lid") and a bare end word without a part noun before it."""
    if h.flag == "bare":
        return not (_VERB_AFTER.match(low, h.end) or _VERB_BEFORE.search(low[max(0, h.start - 20): h.start]))
    if h.flag == "end" and _BARE_END.fullmatch(h.text):
        if not _END_LEAD.search(low[max(0, h.start - 40): h.start]) or negated(low, h.start):
            return False
        return not (h.text.endswith(("on", "off")) and not _END_TAIL.match(low, h.end))  # "a door on a plastic body": a preposition
    return True


def _band_and_target(value: object) -> tuple[str, StateTarget | None]:
    """A state hit's value -> (band, target)."""
    if isinstance(value, tuple):
        return value[0], value[1]
    v = str(value)
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
_ORD_JOIN = re.compile(r"\s*(?:,\s*(?:and|or)?|and|or|&)\s*(?:the\s+)?$")


def _parts(low: str, tokens: Tokens) -> list[_Part]:
    """Part nouns with their ordinals ("the first and second drawers", "drawer 2") or quantifier."""
    ords = scan(low, _ORDINALS)  # left to right, not overlapping: ends ascend too
    ord_ends = [o.end for o in ords]
    # enumerations ("the first, second and third drawers"): chain[j] is the first ordinal of the run ending at ords[j]
    chain: list[int] = []
    for j, o in enumerate(ords):
        prev = ords[j - 1] if j else None
        joined = prev is not None and prev.flag != "quant" and _ORD_JOIN.match(low, prev.end, o.start) is not None
        chain.append(chain[j - 1] if joined else j)
    out: list[_Part] = []
    for m in rv.PART_RX.finditer(low):
        label = rv.part_label(m.group(0))
        ordinals: list[tuple[int, str]] = []
        quant = False
        pstart = m.start()
        n_before = bisect_right(ord_ends, m.start())  # ordinals ending before the noun
        if n_before:
            o = ords[n_before - 1]
            gap = tokens.count(o.end, m.start())
            if (gap == 0 or gap <= 2 and o.flag not in _ADJACENT_ORDERS or _ONE_OF.fullmatch(low, o.start, m.start())) \
                    and not tokens.marks_between(o.end, m.start()):
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
        out.append(_Part(m.start(), m.end(), label, ordinals, quant, none.start() if none else pstart, none is not None))
    return out


_FWD_STOP = {"and", "with", "but", "or", "while", "its", "the", "a", "an", "their", "his", "her", "in", "of", "for", "to", ","}


def _forward_part(low: str, end: int, limit: int, part_at: dict[int, _Part]) -> _Part | None:
    """A part noun (``part_at``: by start) right after a state, at most one modifier word between."""
    for t in itertools.islice(TOKEN.finditer(low, end, limit), 2):
        p = part_at.get(t.start())
        if p is not None:
            return p
        if t.group(0) in _FWD_STOP or t.group(0) in {",", ";", ":"}:
            return None
    return None


_ELIDED = re.compile(r"\s*(?:,\s*)?(?:and|or|but|then|yet)?\s*(?:also\s+|at the same time\s+)?")
_OTHERS = re.compile(r"(?<![\w-])(?:others|(?:the )?rest(?: of them)?|remaining(?: ones)?|other(?: ones?)?)(?![\w-])")


@dataclass(frozen=True, slots=True)
class _JointStates:
    """The joint states a request asks: ``requests`` (every joint first, then per label, then one part: the
    specific one wins), ``hits`` (the state words used), ``warnings`` (contradictions) and ``overridden`` (the
    phrases a later one for the same part replaced)."""

    requests: list[JointStateRequest]
    hits: list[Hit]
    warnings: list[str]
    overridden: list[str]


def _joint_states(low: str, tokens: Tokens, numeric: list[rv.Found] | None = None) -> _JointStates:
    """The joint-state requests of ``low`` (``numeric``: the states in numbers, :func:`rv.state_quantities`)."""
    # step 1: the state words, the part nouns and the ordinals, left to right
    bands = _state_hits(low, numeric)  # every list here is left to right and not overlapping
    parts = _parts(low, tokens)
    # ordinals without a part noun ("the second slightly open"; "the freezer open": the smallest part)
    ords = [o for o in scan(low, _ORDINALS) if o.flag == "" or o.flag in _ADJACENT_ORDERS and _THE_BEFORE.search(low, max(0, o.start - 8), o.start)]
    band_starts = [b.start for b in bands]
    part_starts = [p.start for p in parts]
    part_ends = [p.end for p in parts]
    part_at = {p.start: p for p in parts}
    ord_starts = [o.start for o in ords]
    ord_ends = [o.end for o in ords]
    # step 2: what the sentences build
    result: list[JointStateRequest] = []
    used: list[Hit] = []
    last_label: str | None = None
    prev_subjects: list[_Part] = []
    claimed: set[int] = set()

    def make(selector: str, label: str | None, ordinal: int | None, order: str, b: Hit, phrase: str, none: bool = False) -> JointStateRequest:
        band, target = _band_and_target(b.value)
        if none:  # "none of the drawers open": closed; "none of the doors closed": open
            band, target = ("mostly" if band == "closed" else "closed"), None
        return JointStateRequest(selector=selector, label=label, ordinal=ordinal, order=order,  # type: ignore[arg-type]
                                 band=band, target=target, phrase=phrase)  # type: ignore[arg-type]

    # step 3: per state word, its subject: a part after or before it, the parts of the last state, "the others", an ordinal, else every part
    for s0, s1 in sentences(low):
        sb = bands[bisect_left(band_starts, s0): bisect_left(band_starts, s1)]
        for i, b in enumerate(sb):
            seg0 = sb[i - 1].end if i > 0 else s0
            seg1 = sb[i + 1].start if i + 1 < len(sb) else s1
            fwd = _forward_part(low, b.end, seg1, part_at)
            # parts before the state, but not one an earlier state went forward to ("a fully open door and the cap ajar")
            back = [p for p in parts[bisect_left(part_starts, seg0): bisect_right(part_ends, b.start)] if p.start not in claimed]
            if fwd is not None:
                claimed.add(fwd.start)
            subjects: list[_Part] = []
            if fwd is not None:
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
                        result.append(make("label", p.label, ordinal, order, b, phrase, p.none))
                    last_label = p.label
                prev_subjects = subjects
                continue
            prev_subjects = []
            others = _OTHERS.search(low, seg0, b.start)
            if others is not None and last_label is not None:
                used.append(Hit(others.start(), others.end(), others.group(0), None))
                result.append(make("label", last_label, None, "vertical", b, " ".join(low[others.start(): b.end].split())))
                continue
            seg_ords = ords[bisect_left(ord_starts, seg0): bisect_right(ord_ends, b.start)]
            if seg_ords:
                o = seg_ords[-1]
                phrase = " ".join(low[o.start: b.end].split())
                result.append(make("label" if last_label is not None else "all", last_label, int(o.value), o.flag or "vertical", b, phrase))  # type: ignore[arg-type]
                continue
            result.append(make("all", None, None, "vertical", b, b.text))
    # step 4: one request per target, contradictions warned
    # one request per target: a later phrase overrides an earlier one; a different state is warned
    warnings: list[str] = []
    overridden: list[str] = []
    dedup: dict[tuple, JointStateRequest] = {}
    for js in result:
        key = (js.selector, js.label, js.ordinal, js.order)
        old = dedup.pop(key, None)
        if old is not None and (old.band, old.target) != (js.band, js.target):
            who = "every task-relevant part" if js.selector == "all" else (js.label or "part") + ("" if js.ordinal is None else f" #{js.ordinal} ({js.order})")
            warnings.append(f"contradiction: '{old.phrase}' and '{js.phrase}' both set {who}; the later one ('{js.phrase}') is used")
            overridden.append(old.phrase)
        dedup[key] = js
    specific = sorted(dedup.values(), key=lambda js: 0 if js.selector == "all" and js.ordinal is None else (1 if js.ordinal is None else 2))
    kept = {js.phrase for js in specific}
    return _JointStates(specific, bands + used, warnings, [p for p in dict.fromkeys(overridden) if p not in kept])


def parse_request(text: str) -> RequestSpec:
    """Parse a request (any string, may be empty) into a :class:`~asset2sim.schemas.request.RequestSpec`.

    Raises:
        TypeError: ``text`` is not a string.
        RequestTooLong: ``text`` has more than :data:`MAX_REQUEST_CHARS`
            characters.
    """
    if not isinstance(text, str):
        raise TypeError(f"request must be a string, got {type(text).__name__}")
    check_request_length(text)
    # step 1: the text in plain quotes and dashes; the object and the size words
    low = text.lower().replace("\u2019", "'").replace("\u2018", "'").replace("\u2013", "-").replace("\u2014", " ")  # plain quotes, dashes
    mentions = find_category_mentions(low)
    mention_starts = [m.start for m in mentions]
    hint, head = request_category(low)
    head_starts = [head.start] if head is not None else []  # the object itself ("a wooden door")
    matched: list[tuple[int, str]] = [(head.start, head.phrase)] if head is not None else []
    tokens = Tokens(low)
    size = _parse_size(low, mentions, tokens)
    warnings = [f"contradiction: size words {size.phrase!r} and " + ", ".join(repr(h.text) for h in size.against)
                + f" point opposite ways; '{size.size_class}' (the first direction) is used"] if size.against else []
    # step 2: states, sizes and volumes in numbers; the joint states
    numbers = rv.state_quantities(low, mention_starts)
    sizes = numbers.sizes
    states = _joint_states(low, tokens, numbers.states)
    warnings += numbers.warnings + states.warnings
    vols = rv.volumes(low)
    if vols and sizes:  # a length is the closer measure of a size: the volume is named as not used
        warnings += [f"'{v.text}' is a volume; the size in numbers ({', '.join(f.text for f in sizes)}) sets the size: '{v.text}' not used"
                     for v in vols]
    elif len(vols) > 1:
        warnings += [f"'{v.text}' is a second volume; the first ('{vols[0].text}') sets the size: not used" for v in vols[1:]]
        sizes = vols[:1]
    else:
        sizes = sizes + vols
    if sizes and size.size_class is not None:
        warnings.append(f"size words ({size.phrase}) and a size in numbers ({', '.join(f.text for f in sizes)}): the numbers are used")
    # step 3: masses, materials and explicit dynamics; the words about motion and pose
    mass_found = rv.masses(low, head_starts)
    material_found = rv.materials(low, mention_starts, head_starts)
    level_found = rv.mass_levels(low, mention_starts)
    dyn_found, dyn_warn = rv.dynamics_values(low, head_starts)
    warnings += dyn_warn
    properties = _merge_properties([f.value for f in mass_found + material_found], warnings)  # type: ignore[misc]
    mass_level = _mass_level(level_found, properties, warnings)
    counts = rv.part_counts(low)
    found: list = size.hits + size.against + states.hits + sizes + vols + numbers.verbs + mass_found + material_found + level_found + dyn_found + counts
    matched += [(f.start, f.text) for f in found] + [(m.start(), m.group(0)) for m in rv.DESCRIPTOR_RX.finditer(low)]
    motion = dynamics_words(low, [(f.start, f.end) for f in level_found], matched, warnings, head_starts)
    pose = None
    for h in scan(low, _POSE_TABLE):  # the last pose word not negated
        if not negated(low, h.start):
            pose = h.value
            matched.append((h.start, h.text))
    # step 4: what was understood and what was not
    var = variant_mention(hint, low) if hint is not None else None  # the variant's phrases count as understood
    if var is not None:
        matched += [(m.start(), m.group(0)) for ph in var[2].phrases for m in re.finditer(phrase_regex(" ".join(ph.lower().split())), low)]
    matched += [(pos, phrase) for pos, _, phrase in mounting_mentions(low)]  # "free-standing", "mounted on the wall" (tasks.interpret.mounting)
    unused, groups = _unused_words(low, matched, mentions)
    in_order = [" ".join(ph.split()) for _pos, ph in dict.fromkeys(sorted(matched, key=lambda t: t[0]))]  # by position, each once
    # step 5: the spec
    return RequestSpec(
        text=text, category_hint=hint, size_class=size.size_class, size_factor=size.factor, size_phrase=size.phrase,  # type: ignore[arg-type]
        joint_states=states.requests, damping=motion.damping, holds_position=motion.holds_position, spring=motion.spring,  # type: ignore[arg-type]
        stiff=motion.stiff, free_moving=motion.free_moving, motions=motion.motions, pose_hint=pose, mass_level=mass_level, properties=properties,  # type: ignore[arg-type]
        sizes=[f.value for f in sizes], dynamics_values=[f.value for f in dyn_found],  # type: ignore[misc]
        part_counts={str(f.value[0]): int(f.value[1]) for f in counts},  # type: ignore[index]
        ignored=groups, warnings=warnings, overridden=states.overridden, matched=in_order, unused_words=unused,
    )


def _mass_level(level_found: list[rv.Found], properties: list[PartProperty], warnings: list[str]) -> object:
    """The last mass word's level (None without one); two levels, or one beside a number, are warned."""
    mass_level = level_found[-1].value if level_found else None
    if len({f.value for f in level_found}) > 1:
        warnings.append("contradiction: " + " and ".join(f"'{f.text}'" for f in level_found) + f" for the mass; '{level_found[-1].text}' is used")
    if mass_level is not None and any(p.mass is not None and p.label is None for p in properties):
        warnings.append(f"'{level_found[-1].text}' and a mass in numbers: the number is used")
    return mass_level


def _merge_properties(props: list[PartProperty], warnings: list[str]) -> list[PartProperty]:
    """One :class:`PartProperty` per label (None = whole object); two values for one part are warned."""
    out: dict[str | None, PartProperty] = {}
    for p in props:
        old = out.get(p.label)
        if old is None:
            out[p.label] = p
            continue
        upd = {}
        for field in ("mass", "mass_range", "material"):
            new, prev = getattr(p, field), getattr(old, field)
            if new is None:
                continue
            if field == "mass_range" and old.mass is not None or field == "mass" and old.mass_range is not None:
                prev = old.mass if field == "mass_range" else old.mass_range
            if prev is not None and prev != new:
                what = "materials" if field == "material" else "masses"
                warnings.append(f"contradiction: '{old.phrase}' and '{p.phrase}' give the {p.label or 'object'} two {what}; "
                                f"'{p.phrase}' is used")
            upd[field] = new
            if field == "mass":
                upd["mass_range"] = None
            elif field == "mass_range":
                upd["mass"] = None
        out[p.label] = old.model_copy(update={**upd, "phrase": f"{old.phrase}; {p.phrase}"})
    return list(out.values())


#: Function words of English requests, never reported as unused.
_FUNCTION_WORDS = frozenset(
    "a an the i i'd i'm me my we our you your it its it's their them his her this that these those "
    "want wants need needs would like please give make made get have has having be is are was were being "
    "with without and or but of for to in on at by from as into onto so such some any one which who whose "
    "can could should will shall may might must do does also just very really quite rather more most less "
    "there here where when while than then every all each both everything pair none neither".split()
)


_SELECTOR_AFTER = re.compile(r"\s+(?:[\w'-]+\s+){0,2}?(?:" + rv.PART_WORDS + r"|ones?)(?![\w-])")


def _unused_words(low: str, matched: list[tuple[int, str]], mentions) -> tuple[list[str], list[str]]:
    """Words outside every recognised phrase and mention that are neither function words nor part labels,
    in order, each once; and their groups within one clause ("rubber duck on top"), each once."""
    spans = []
    for pos, phrase in matched:
        for prefix in ("no ", "not "):
            if phrase.startswith(prefix) and not low.startswith(prefix, pos):
                phrase = phrase[len(prefix):]
        spans.append((pos, pos + len(phrase)))
    spans += [(m.start, m.end) for m in mentions]
    spans.sort()
    starts = [a for a, _ in spans]
    for h in scan(low, _ORDINALS):  # joint selectors: before a part noun or "one", or right before a state
        after = low[h.end: h.end + 60]
        k = bisect_left(starts, h.end)
        state_next = k < len(spans) and spans[k][0] - h.end <= 12 and not CLAUSE_MARK.search(low, h.end, spans[k][0])
        if _SELECTOR_AFTER.match(after) or state_next:
            spans.append((h.start, h.end))
    spans.sort()
    labels = load_priors().labels
    known = set(labels.labels) | set(labels.aliases)
    out: list[str] = []
    seen: set[str] = set()
    groups: list[str] = []
    cur: list[int] = []  # [start, end] of the open group

    def close() -> None:
        if cur:
            g = " ".join(low[cur[0]: cur[1]].split())
            if g not in groups:
                groups.append(g)
            cur.clear()

    k = 0
    for m in WORD_RUN.finditer(low):
        while k < len(spans) and spans[k][1] <= m.start():
            k += 1
        if k < len(spans) and spans[k][0] <= m.start() < spans[k][1]:
            close()
            continue
        if cur and CLAUSE_MARK.search(low, cur[1], m.start()) or cur and re.search(r"[.!?()]", low[cur[1]: m.start()]):
            close()
        word = m.group(0).strip("'-")
        if not word or word in _FUNCTION_WORDS:
            continue
        if word.isdigit() or word in known or word.rstrip("s") in known or _PART_WORD.fullmatch(word):
            close()
            continue
        if cur:
            cur[1] = m.end()
        else:
            cur.extend([m.start(), m.end()])
        if word not in seen:
            seen.add(word)
            out.append(word)
    close()
    return out, groups


def request_notes(spec: RequestSpec) -> list[str]:
    """The report's and the terminal's lines on the request's unused words: a warning when none was
    understood (the category's defaults are used), else the unused words; empty when every word was used. A note
    on which parse was used and why comes first when the model was asked to parse (``--request-parser model``)."""
    if not spec.understood:
        return ([spec.parse_note] if spec.parse_note else []) + [f"WARNING: request not understood (English words only; none recognised): {spec.text[:120]!r}; "
                "refined with the category's defaults (typical size, closed, moderate damping)"]
    out = [f"WARNING: {w}" for w in spec.warnings] + ([spec.parse_note] if spec.parse_note else [])
    if spec.ignored:
        out.append("request words not used: " + "; ".join(f"'{g}'" for g in spec.ignored[:30]) + (" ..." if len(spec.ignored) > 30 else ""))
    return out


def parse_prompt(prompt: str | None) -> tuple[RequestSpec | None, str | None]:
    """(RequestSpec of ``prompt`` or None, the parser's error or None)."""
    if not prompt:
        return None, None
    try:
        return parse_request(prompt), None
    except Exception as exc:  # a parser failure must not stop the evaluation
        return None, f"request parser failed: {type(exc).__name__}: {exc}"


def request_warnings(spec: RequestSpec, unmatched: list[str], category: str | None) -> list[str]:
    """What of the request the output could not honour, in plain words: nothing understood, the parser's
    warnings, ``unmatched`` phrases (:func:`~asset2sim.tasks.interpret.named_parts.requested_joints`: naming no part of
    the object) and the words
    no rule used."""
    if not spec.understood:
        return [f"no word of the request was understood: {spec.text[:120]!r}; refined with the category's defaults"]
    out = list(spec.warnings)
    out += [f"'{p}' names no part of this {category or 'object'}: not applied" for p in unmatched]
    if spec.ignored:
        out.append("words not used: " + "; ".join(f"'{g}'" for g in spec.ignored))
    return out
