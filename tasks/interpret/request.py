"""Parse a natural-language request into a :class:`RequestSpec` (grammar: ``docs/guide/requests.md``;
numbers, masses and materials: :mod:`.request_values`; joint states: :mod:`.state_words`; words about motion:
:mod:`.motion_words`; the phrase tables' scanning: :mod:`.phrase_scan`). Pure, linear in the length; never raises on a
string of at most :data:`MAX_REQUEST_CHARS` characters.
"""

from __future__ import annotations

import math
import re
from bisect import bisect_left
from dataclasses import dataclass, fields

from asset2sim.schemas.request import PartProperty, RequestSpec
from asset2sim.tasks.interpret.categories import CategoryMention, find_category_mentions, phrase_regex, request_category, variant_mention
from asset2sim.tasks.interpret.mounting import mounting_mentions
from asset2sim.prior_tables import load_priors
from asset2sim.tasks.interpret import request_values as rv
from asset2sim.tasks.interpret.motion_words import dynamics_words
from asset2sim.tasks.interpret.phrase_scan import CLAUSE_MARK, WORD_RUN, Hit, Tokens, negated, scan, word_table
from asset2sim.tasks.interpret.state_words import ORDINALS, joint_states


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


#: Size words (``words.yaml`` ``size``): value a size class; flag "weak": only counts right before a category word.
_SIZE_TABLE = word_table("size")


_PART_WORD = re.compile(r"(?:" + rv.PART_WORDS + r")")


_POSE_TABLE = word_table("pose")


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
    facs = {k: v.factor for k, v in load_priors().size_classes.items()}
    first_dir = math.copysign(1.0, math.log(facs[str(used[0].value)])) if facs[str(used[0].value)] != 1.0 else 0.0
    same = [h for h in used if first_dir == 0.0 or math.log(facs[str(h.value)]) * first_dir >= 0.0]
    best = max(same, key=lambda h: abs(math.log(facs[str(h.value)])))
    cls = str(best.value)
    counted = [h for h in same if h.value != "regular" or cls == "regular"]
    return _SizeWords(cls, facs[cls], ", ".join(h.text for h in counted), counted, [h for h in used if h not in same])


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
    states = joint_states(low, tokens, numbers.states)
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
    mass_level = level_found[-1].value if level_found else None  # the last mass word's; two, or one beside a number: warned
    if len({f.value for f in level_found}) > 1:
        warnings.append("contradiction: " + " and ".join(f"'{f.text}'" for f in level_found)
                        + f" for the mass; '{level_found[-1].text}' is used")
    if mass_level is not None and any(p.mass is not None and p.label is None for p in properties):
        warnings.append(f"'{level_found[-1].text}' and a mass in numbers: the number is used")
    counts = rv.part_counts(low)
    found: list = size.hits + size.against + states.hits + sizes + vols + numbers.verbs + mass_found + material_found + level_found + dyn_found + counts
    matched += [(f.start, f.text) for f in found] + [(m.start(), m.group(0)) for m in rv.DESCRIPTOR_RX.finditer(low)]
    motion = dynamics_words(low, [(f.start, f.end) for f in level_found], matched, warnings, head_starts, states.ordinals)
    pose = None
    for h in scan(low, _POSE_TABLE):  # the last pose word not negated nor a part's state ("the handle upright")
        if not negated(low, h.start) and not any(b.start < h.end and h.start < b.end for b in states.hits):
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
        joint_states=states.requests, **{f.name: getattr(motion, f.name) for f in fields(motion)},
        pose_hint=pose, mass_level=mass_level, properties=properties,  # type: ignore[arg-type]
        sizes=[f.value for f in sizes], dynamics_values=[f.value for f in dyn_found],  # type: ignore[misc]
        part_counts={str(f.value[0]): int(f.value[1]) for f in counts},  # type: ignore[index]
        ignored=groups, warnings=warnings, overridden=states.overridden, matched=in_order, unused_words=unused,
    )


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
            # a mass and a range of masses exclude each other
            other = {"mass": "mass_range", "mass_range": "mass"}.get(field)
            if other and getattr(old, other) is not None:
                prev = getattr(old, other)
            if prev is not None and prev != new:
                what = "materials" if field == "material" else "masses"
                warnings.append(f"contradiction: '{old.phrase}' and '{p.phrase}' give the {p.label or 'object'} two {what}; "
                                f"'{p.phrase}' is used")
            upd[field] = new
            if other:
                upd[other] = None
        out[p.label] = old.model_copy(update={**upd, "phrase": f"{old.phrase}; {p.phrase}"})
    return list(out.values())


#: Function words of English requests, never reported as unused.
_FUNCTION_WORDS = frozenset(rv.WORDS["function_words"].split())


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
    for h in scan(low, ORDINALS):  # joint selectors: before a part noun or "one", or right before a state
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
    parse = [spec.parse_note] if spec.parse_note else []
    if not spec.understood:
        return parse + [f"WARNING: request not understood (English words only; none recognised): {spec.text[:120]!r}; "
                "refined with the category's defaults (typical size, closed, moderate damping)"]
    out = [f"WARNING: {w}" for w in spec.warnings] + parse
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
