"""Numbers, units, masses, materials and explicit joint parameters in a request:
each function reads the lower-cased request and returns typed findings with
their character spans. Values in SI and radians; the inch, foot, pound and
ounce factors are the exact ones of NIST SP 811, Appendix B. Linear in the
length of the text.
"""

from __future__ import annotations

import itertools
import math
import re
from dataclasses import dataclass

from asset2sim.schemas.request import BAND_TARGET, DynamicsValue, PartProperty, SizeTarget, StateTarget
from asset2sim.prior_tables import load_priors
from asset2sim.tasks.interpret.part_labels import canonical_label
from asset2sim.package_data import package_yaml

_L = r"(?<![\w.-])"
_R = r"(?![\w-])"


#: The request parser's vocabulary, ``words.yaml`` beside this module: word lists, ``fragments`` (name -> regex) and
#: phrase tables (name -> list of [regex, value] or [regex, value, flag]).
WORDS: dict = package_yaml(__package__, "words.yaml")


#: Part nouns a request may name (singular and plural; ``words.yaml`` ``part_words``).
PART_WORDS = WORDS["part_words"]
PART_RX = re.compile(r"(?<![\w-])(?:" + PART_WORDS + r")(?![\w-])")
#: Words for the object's fixed body (material per part: "on a plastic body").
BODY_RX = re.compile(r"(?<![\w-])(?:" + WORDS["body_words"] + r")(?![\w-])")

_WORD_NUMBERS = WORDS["numbers"]
NUM = r"(?:\d+(?:\.\d+)?|\.\d+|" + "|".join(sorted((re.escape(w) for w in _WORD_NUMBERS), key=len, reverse=True)) + r")"


def part_label(word: str) -> str:
    """The label a request's part word names, singular: its canonical label (``part_labels.canonical_label``:
    "covers" -> lid, "hatches" -> door), else the word made singular ("arms" -> arm)."""
    known = set(load_priors().labels.labels)
    cands = [word] + ([word[:-2]] if word.endswith("es") else []) + ([word[:-1]] if word.endswith("s") and not word.endswith("ss") else [])
    for c in cands:
        hit = canonical_label(c)
        if hit in known:
            return hit
    if word.endswith(("ches", "shes", "xes", "sses")):
        return word[:-2]
    return word[:-1] if word.endswith("s") and not word.endswith(("ss", "us", "is")) and len(word) > 3 else (canonical_label(word) or word)


def number_value(text: str) -> float:
    """The value of a number matched by :data:`NUM` ("30", "0.5", "two")."""
    t = text.strip()
    return float(_WORD_NUMBERS.get(t, t))


#: Units per quantity (``words.yaml`` ``units``, NIST SP 811, Appendix B): [regex, factor to SI].
_ANGLE_UNITS, _LENGTH_UNITS, _VOLUME_UNITS, _MASS_UNITS = (WORDS["units"][q] for q in ("angle", "length", "volume", "mass"))


def _unit_rx(units: list[tuple[str, float]]) -> str:
    return "|".join(f"(?:{u})" for u, _ in units)


def _factor(units: list[tuple[str, float]], text: str) -> float:
    for u, f in units:
        if re.fullmatch(u, text):
            return f
    raise ValueError(f"unknown unit {text!r}")


def _quantity(m: re.Match, units: list[tuple[str, float]]) -> float:
    """The SI value of a number-and-unit match (groups ``num`` and ``unit``) in ``units``."""
    return number_value(m.group("num")) * _factor(units, m.group("unit"))


#: A unit right after a number ("drawer 10 cm" is a distance, not drawer number 10).
UNIT_AHEAD = re.compile(r"\s*-?\s*(?:%|percent|" + _unit_rx(_ANGLE_UNITS + _LENGTH_UNITS + _MASS_UNITS + _VOLUME_UNITS) + r")(?![\w])")

_QTY = r"(?P<num>" + NUM + r")\s*-?\s*(?P<unit>{units})(?![\w])"
_ANGLE_RX, _LENGTH_RX, _MASS_RX, _VOLUME_RX = (re.compile(_L + _QTY.format(units=_unit_rx(u)))
                                               for u in (_ANGLE_UNITS, _LENGTH_UNITS, _MASS_UNITS, _VOLUME_UNITS))
#: "at a right angle", "open at right angles", "perpendicular": 90 degrees.
_RIGHT_ANGLE_RX = re.compile(_L + r"(?:(?:a )?right[- ]angles?|perpendicular)" + _R)
_PERCENT_RX = re.compile(_L + r"(?P<num>" + NUM + r")\s*(?:%|percent|per cent)(?![\w])")
_THIRDS_RX = re.compile(
    _L + r"(?P<frac>(?:two|2)[- ]thirds?|(?:a|one|1)[- ]third|(?P<n>\d)\s*/\s*(?P<d>[1-9]))"
    r"(?:(?: of the way)?(?: of its (?:travel|range))?)" + _R
)

_STATE_BEFORE = re.compile(
    r"(?<![\w-])(?:(?:(?:propped|popped|held|left|kept|flipped|swung|thrown|pulled|pushed|tilted)\s+)?(?:open(?:ed)?|rotated|tilted|swung(?: open)?|turned|raised|lifted|pulled(?: out)?|pushed(?: in)?|slid(?: out| open)?|"
    r"extended|lowered|set|positioned|sits?|stands?|out)\s+)?(?:(?:up )?to |by |at |of )?(?:about |around |roughly |approximately |exactly |an? angle of )?$"
)
_STATE_AFTER = re.compile(
    r"^(?:\s+(?:open(?:ed)?|ajar|out|outwards?|apart|up|from (?:the )?(?:closed|shut)(?: position)?|(?:of |of the )?(?:opening|travel)))+"
)
_STATE_WORD_BEFORE = re.compile(r"(?<![\w-])(?:open(?:ed)?|rotated|tilted|swung|raised|lifted|pulled|pushed|slid|extended|lowered)\s+(?:\w+\s+){0,3}$")
_DIM_AFTER = re.compile(r"^\s*(?P<dim>tall|high|in height|wide|in width|across|in diameter|diameter|deep|in depth|long|in length)" + _R)
_DIM_BEFORE = re.compile(r"(?P<dim>height|width|depth|length|diameter)\s*(?:of|is|:|=|at)?\s*(?:about |around |roughly |approximately |exactly )?$")
_DIM_NAMES = WORDS["dimensions"]


@dataclass
class Found:
    """One finding with its character span in the lower-cased request."""

    start: int
    end: int
    text: str
    value: object


def _next_words(low: str, end: int, n: int) -> list[tuple[int, int, str]]:
    """(start, end, word) of the first ``n`` (at least one) words or clause marks after ``end``."""
    return [(end + m.start(), end + m.end(), m.group(0))
            for m in itertools.islice(re.finditer(r"[\w'-]+|[,;:.!?]", low[end: end + 80]), max(n, 1))]


def _near_category(low: str, end: int, mention_starts: list[int]) -> bool:
    """A category mention starts within two words after ``end``."""
    for s, _e, w in _next_words(low, end, 3):
        if s in mention_starts or w in {",", ";", ":", ".", "!", "?"}:
            return s in mention_starts
    return False


@dataclass(frozen=True, slots=True)
class StateQuantities:
    """The numbers of a request (:func:`state_quantities`): ``states`` (band,
    StateTarget) values (angles in rad, lengths in m by a state word, percentages and fractions by open),
    ``sizes`` SizeTarget values (a length in m with a dimension word, or before the object's name: largest),
    ``warnings`` for lengths that are neither, ``verbs`` the state verbs a number refers to."""

    states: list[Found]
    sizes: list[Found]
    warnings: list[str]
    verbs: list[Found]


def state_quantities(low: str, mention_starts: list[int]) -> StateQuantities:
    """The states, sizes, warnings and verbs in numbers of ``low`` (the request in lower case)."""
    states: list[Found] = []
    sizes: list[Found] = []
    warnings: list[str] = []
    verbs: list[Found] = []

    def widen(m: re.Match) -> tuple[int, int]:
        b = _STATE_BEFORE.search(low[max(0, m.start() - 40): m.start()])
        start = m.start() - (len(b.group(0)) if b else 0)
        a = _STATE_AFTER.match(low[m.end():])
        end = m.end() + (len(a.group(0)) if a else 0)
        return start, end

    for m in [*_ANGLE_RX.finditer(low), *_RIGHT_ANGLE_RX.finditer(low)]:
        v = _quantity(m, _ANGLE_UNITS) if "num" in m.re.groupindex else math.pi / 2
        s, e = widen(m)
        states.append(Found(s, e, low[s:e].strip(), ("halfway", StateTarget(kind="angle", value=v))))
    for m in [*_PERCENT_RX.finditer(low), *_THIRDS_RX.finditer(low)]:
        s, e = widen(m)
        if m.re is _PERCENT_RX:
            f = number_value(m.group("num")) / 100.0
        elif s == m.start() and e == m.end():
            continue  # "a third" without open/out next to it is not a state
        else:
            f = int(m.group("n")) / int(m.group("d")) if m.group("n") else (2 / 3 if m.group("frac").startswith(("two", "2")) else 1 / 3)
        # the nearest band (by target fraction)
        band = min(BAND_TARGET, key=lambda b: abs(BAND_TARGET[b] - f))
        states.append(Found(s, e, low[s:e].strip(), (band, StateTarget(kind="fraction", value=f))))
    for m in _LENGTH_RX.finditer(low):
        v = _quantity(m, _LENGTH_UNITS)
        if v <= 0:
            continue
        if m.group("unit") == "in" and (not m.group("num")[0].isdigit() or re.match(r"\s*\d", low[m.end():])):
            continue  # "two in a row", "a 2 in 1 laptop": a preposition
        after = _DIM_AFTER.match(low[m.end():])
        before = _DIM_BEFORE.search(low[max(0, m.start() - 40): m.start()])
        if after or before:
            s = m.start() if after else m.start() - len(before.group(0))
            e = m.end() + len(after.group(0)) if after else m.end()
            phrase = low[s:e].strip()
            sizes.append(Found(s, e, phrase, SizeTarget(dimension=_DIM_NAMES[(after or before).group("dim")], value=v, phrase=phrase)))
            continue
        s, e = widen(m)
        w0 = max(0, m.start() - 60)
        verb = _STATE_WORD_BEFORE.search(low[w0: m.start()])
        if verb is not None and (s, e) == (m.start(), m.end()):
            v_end = w0 + verb.start() + len(verb.group(0).split()[0])
            verbs.append(Found(w0 + verb.start(), v_end, low[w0 + verb.start(): v_end], None))
        if (s, e) != (m.start(), m.end()) or verb is not None:
            states.append(Found(s, e, low[s:e].strip(), ("halfway", StateTarget(kind="distance", value=v))))
        elif _near_category(low, m.end(), mention_starts):
            sizes.append(Found(m.start(), m.end(), m.group(0), SizeTarget(dimension="largest", value=v, phrase=m.group(0))))
        else:
            warnings.append(f"'{m.group(0)}' is a length but neither a size (tall/wide/deep/long) nor a state (open/out): not used")
    states.sort(key=lambda f: f.start)
    return StateQuantities(leftmost_longest(states), sizes, warnings, verbs)


def volumes(low: str) -> list[Found]:
    """A container's volume in numbers ("a 500 ml bottle", "2 litres", "16 fl oz") as a ``SizeTarget`` of
    dimension ``volume`` (m^3)."""
    return [Found(m.start(), m.end(), m.group(0), SizeTarget(dimension="volume", value=v, phrase=m.group(0)))
            for m in _VOLUME_RX.finditer(low)  # "a l": not a number
            if (m.group("unit") != "l" or m.group("num")[0].isdigit()) and (v := _quantity(m, _VOLUME_UNITS)) > 0]


def leftmost_longest(found: list) -> list:
    """The findings (anything with ``start`` and ``end``) that do not overlap: leftmost first, then longest."""
    out: list = []
    last = -1
    for f in sorted(found, key=lambda f: (f.start, -(f.end - f.start))):
        if f.start >= last:
            out.append(f)
            last = f.end
    return out


_WEIGHS_BEFORE = re.compile(r"(?:weighs?|weighing|weight(?: of| is|:)?|mass(?: of| is|:)?|of)\s+(?:about |around |roughly |approximately |exactly |only |just )?$")


def part_before(low: str, pos: int, max_words: int = 4, mention_starts: list[int] | None = None) -> tuple[str | None, int]:
    """(label, end) of the part noun closest before ``pos`` within ``max_words`` words of the clause; the label None
    when it is a category mention (the object itself) or there is none (end ``pos``)."""
    w0 = max(0, pos - 60)
    window = low[w0: pos]
    cut = max((m.end() for m in re.finditer(r"[,;:.!?]", window)), default=0)
    words = list(re.finditer(r"[\w'-]+", window[cut:]))[-max_words:]
    for m in reversed(words):
        w = m.group(0)
        start = w0 + cut + m.start()
        if PART_RX.fullmatch(w):
            return (None if mention_starts and start in mention_starts else part_label(w)), start + len(w)
        if BODY_RX.fullmatch(w):
            return "body", start + len(w)
    return None, pos


def part_after(low: str, end: int, mention_starts: list[int] | None = None) -> tuple[str | None, int]:
    """(label, end) of the part or body noun within two words after ``end``; None for a category mention."""
    for s, e, w in _next_words(low, end, 2):
        if PART_RX.fullmatch(w):
            return (None if mention_starts and s in mention_starts else part_label(w)), e
        if BODY_RX.fullmatch(w):
            return "body", e
        if w in {",", ";", ":", ".", "!", "?", "and", "with", "on", "in", "of"}:
            break
    return None, end


_MASS_RANGE_RX = re.compile(
    _L + r"(?:(?P<lead>between|from)\s+)?(?P<lo>" + NUM + r")\s*(?P<lo_unit>" + _unit_rx(_MASS_UNITS) + r")?\s*"
    r"(?P<sep>and|to|-|–)\s*" + _QTY.format(units=_unit_rx(_MASS_UNITS)))


def mass_ranges(low: str) -> list[re.Match]:
    """Ranges of masses in numbers: "between 20 and 30 kg", "from 2 kg to 3 kg", "20-30 kg", "20 to 30 kg" (the first
    number in the second's unit unless it has its own; "and" only after "between")."""
    return [m for m in _MASS_RANGE_RX.finditer(low) if (m.group("sep") == "and") == (m.group("lead") == "between")]


def _mass_found(low: str, m: re.Match, mention_starts: list[int] | None, **values: object) -> Found:
    """The mass phrase ``m`` of ``low`` as a :class:`Found`: the part named after it (or, after "weighs", before it),
    the phrase's span and text, and ``values`` (``mass`` in kg or ``mass_range`` (low, high) in kg) on its
    ``PartProperty``."""
    label, end = part_after(low, m.end(), mention_starts=mention_starts)
    start = m.start()
    w = _WEIGHS_BEFORE.search(low[max(0, m.start() - 40): m.start()])
    if w:
        start -= len(w.group(0))
        if label is None:
            label = part_before(low, start, mention_starts=mention_starts)[0]
    text = low[start:max(end, m.end())].strip()
    return Found(start, max(end, m.end()), text, PartProperty(label=label, phrase=text, **values))


def masses(low: str, mention_starts: list[int] | None = None) -> list[Found]:
    """Masses in numbers ("weighs 2 kg", "a 300 g lid": per part; "between 20 and 30 kg": a range), values
    ``PartProperty``."""
    out: list[Found] = []
    ranges = mass_ranges(low)
    for m in ranges:
        hi = _quantity(m, _MASS_UNITS)
        lo = number_value(m.group("lo")) * _factor(_MASS_UNITS, m.group("lo_unit") or m.group("unit"))
        if lo <= 0 or hi <= 0:
            continue
        out.append(_mass_found(low, m, mention_starts, mass_range=(min(lo, hi), max(lo, hi))))
    return out + [_mass_found(low, m, mention_starts, mass=v) for m in _MASS_RX.finditer(low)
                  if not any(r.start() <= m.start() < r.end() for r in ranges) and (v := _quantity(m, _MASS_UNITS)) > 0]


_MASS_LEVEL_RX = re.compile(
    _L + r"(?:(?:very|quite|really|rather|fairly|extra)[- ])?(?P<w>heavy(?:weight)?|heavier|light(?:weight)?|lighter)" + _R
)
_MASS_LEVEL_BEFORE = re.compile(r"(?:is|it's|feels?|be|and|but|,)\s+$")


#: Words of a joint's mechanism: "a heavy hinge", "a heavy action" speak of how it moves, not of a mass.
JOINT_WORD_RX = re.compile(r"(?:hinges?|joints?|action|feel|slides?|runners?|pivots?|springs?|mechanisms?)")


def joint_word_soon(low: str, end: int) -> bool:
    """Whether a joint word (:data:`JOINT_WORD_RX`) is among the next three words after ``end``, before any
    ("a heavy, well-damped hinge": yes; "a heavy 25 kg door": no)."""
    return any(JOINT_WORD_RX.fullmatch(w) for _, _, w in _next_words(low, end, 3))


def mass_levels(low: str, mention_starts: list[int]) -> list[Found]:
    """Mass words ("a heavy box", "lightweight", "a heavy 25 kg door": the number is its mass, "a box with a heavy
    lid": the object is heavier): ``"heavy"`` / ``"light"``; not before a joint word ("a heavy hinge": a stiff one)."""
    out: list[Found] = []
    for m in _MASS_LEVEL_RX.finditer(low):
        w = m.group("w")
        nxt = _next_words(low, m.end(), 1)
        if not joint_word_soon(low, m.end()) and (
                w.endswith("weight") or _near_category(low, m.end(), mention_starts) or _MASS_RX.match(low, m.end() + 1)
                or any(PART_RX.fullmatch(x) for _, _, x in _next_words(low, m.end(), 3))
                or _MASS_LEVEL_BEFORE.search(low[max(0, m.start() - 12): m.start()])
                and (not nxt or nxt[0][2] in {",", ".", ";", "!", "and", "but", "to"})):
            out.append(Found(m.start(), m.end(), m.group(0), "heavy" if w.startswith("heav") else "light"))
    return out


#: Request words -> ``materials.yaml`` key (``words.yaml`` ``materials``: "metal": sheet steel, "plastic": ABS).
MATERIAL_WORDS: dict[str, str] = WORDS["materials"]
_MATERIAL_RX = [(re.compile(_L + r"(?:made (?:of|from|out of) |in )?(?:solid |real )?(?:" + pat + r")" + _R), key) for pat, key in MATERIAL_WORDS.items()]
_MADE_OF = re.compile(r"(?:made (?:of|from|out of)|in) ")


def materials(low: str, mention_starts: list[int], head_starts: list[int] | None = None) -> list[Found]:
    """Material words as ``PartProperty``: per part or body when its noun follows, the whole object before the
    object's name (``mention_starts``; ``head_starts``: the object's own mention) or after "made of"."""
    hits = [Found(m.start(), m.end(), m.group(0), key) for rx, key in _MATERIAL_RX for m in rx.finditer(low)]
    out: list[Found] = []
    for h in leftmost_longest(hits):
        made_of = _MADE_OF.match(h.text) is not None
        label, end = ((part_before(low, h.start, 3, head_starts)[0], h.end) if made_of
                      else part_after(low, h.end, mention_starts=head_starts))
        if not made_of and label is None:
            nxt = _next_words(low, h.end, 1)
            if not (_near_category(low, h.end, mention_starts) or not nxt or nxt[0][2] in {",", ".", ";", "!", "and", "with", "but"}):
                continue  # "a rubber duck": not the object's material
        text = low[h.start:max(end, h.end)].strip()
        out.append(Found(h.start, max(end, h.end), text, PartProperty(label=label, material=str(h.value), phrase=text)))
    return out


_NSEP = r"\s*[·*.\-]?\s*"
_DYN_UNITS = [
    ("damping", "rotational", r"n" + _NSEP + r"m" + _NSEP + r"s\s*/\s*rad|nms/rad"),
    ("damping", "linear", r"n" + _NSEP + r"s\s*/\s*m|ns/m"),
    ("stiffness", "rotational", r"n" + _NSEP + r"m\s*/\s*rad|nm/rad"),
    ("stiffness", "linear", r"n\s*/\s*m"),
    ("friction", "rotational", r"n" + _NSEP + r"m|nm"),
    ("friction", "linear", r"n"),
]
_DYN_NAME = r"(?P<q>damping|friction|stiffness|spring (?:constant|stiffness|rate))(?: coefficient)?"
_DYN_UNIT = "|".join(f"(?:{u})" for _q, _m, u in _DYN_UNITS)
_DYN_RX = re.compile(
    _L + _DYN_NAME + r"(?:\s+(?:of|=|is|at|to|about|around)|\s*[:=])*\s*(?P<num>" + NUM + r")\s*(?P<unit>" + _DYN_UNIT + r")?(?![\w/])"
)
_DYN_RX_AFTER = re.compile(_L + r"(?P<num>" + NUM + r")\s*(?P<unit>" + _DYN_UNIT + r")\s+(?:of\s+)?" + _DYN_NAME + _R)


def dynamics_values(low: str, mention_starts: list[int] | None = None) -> tuple[list[Found], list[str]]:
    """Explicit joint parameters ("damping 0.5 N m s/rad") as :class:`DynamicsValue`, per part when a part noun
    precedes; warnings when the unit does not fit the quantity."""
    out: list[Found] = []
    warns: list[str] = []
    for rx in (_DYN_RX, _DYN_RX_AFTER):
        for m in rx.finditer(low):
            q = "stiffness" if m.group("q").startswith("spring") else m.group("q")
            v = number_value(m.group("num"))
            motion = "any"
            unit = m.group("unit")
            if unit:
                same = [mm for qq, mm, u in _DYN_UNITS if re.fullmatch(u, unit) and qq == q]
                if same:
                    motion = same[0]
                else:
                    warns.append(f"'{m.group(0)}': the unit {unit!r} does not fit {q} (expected "
                                 + " or ".join(u for qq, _mm, u in _DYN_UNITS if qq == q).replace("\\s*", " ") + "); used as a number without unit")
            label = part_before(low, m.start(), mention_starts=mention_starts)[0]
            out.append(Found(m.start(), m.end(), m.group(0), DynamicsValue(quantity=q, value=v, motion=motion, label=label if label != "body" else None, phrase=m.group(0))))
    return leftmost_longest(out), warns


_COUNT_WORDS = WORDS["counts"]
_COUNT_RX = re.compile(
    _L + r"(?P<n>one(?=-)|single|two|double|twin|three|triple|four|five|six|[1-9])[- ](?P<part>drawers?|doors?|slots?|slices?|lids?|"
    r"shel(?:f|ves)|compartments?|burners?|buttons?|knobs?|handles?|wheels?)" + _R
)


def part_counts(low: str) -> list[Found]:
    """Counts of parts ("a two-drawer cabinet"): value (canonical label, count)."""
    return [Found(m.start(), m.end(), m.group(0), (canonical_label(m["part"]) or m["part"].rstrip("s"),
                                                   int(m["n"]) if m["n"].isdigit() else _COUNT_WORDS[m["n"]]))
            for m in _COUNT_RX.finditer(low)]


#: Words naming the kind of joint or motion ("sliding joints") or a part left as it is ("the knobs left alone"):
#: understood, no effect (``words.yaml`` ``descriptors``).
DESCRIPTOR_RX = re.compile(_L + "(?:" + WORDS["descriptors"] + ")" + _R)
