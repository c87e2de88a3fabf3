"""Which category an asset is: names, request mentions and recognition.

A category (``categories.yaml``) is named by its canonical name, PartNet's
``model_cat`` or a synonym (:func:`resolve_category`, :func:`category_prior`);
requests mention categories in free text (:func:`find_category_mentions`,
:func:`request_category`, :func:`find_variant`); :func:`recognize_category`
weighs the request words, ``meta.json``'s ``model_cat`` and the semantic labels
to pick one, with the ``Generic`` fallback for thin evidence.

Never raises on unknown names. Sources: ``categories.yaml``, ``docs/design/priors.md``.
"""

from __future__ import annotations

import functools
import re
from collections.abc import Iterable
from dataclasses import dataclass, field

from pydantic import Field

from asset2sim.tasks.interpret.part_labels import body_label_tokens, canonical_label
from asset2sim.prior_tables import GENERIC, CategoryPrior, PriorModel, VariantPrior, load_priors

# Evidence weights of recognize_category (dimensionless scores).
_W_REQUEST_HEAD = 4.0  # the object the request is about (first non-possessive mention)
_W_REQUEST_OTHER = 1.0  # any other / ambiguous mention
_W_MODEL_CAT = 2.5  # meta.json model_cat
_W_BODY_LABEL = 1.0  # "<category>_body" style label
_W_PART_CAP = 1.0  # cap on the sum of characteristic part labels
_MIN_SCORE = 0.5  # below this the Generic fallback is returned


class CategoryMatch(PriorModel):
    """Result of :func:`recognize_category`.

    ``confidence`` in [0, 1]; ``reason`` explains the evidence; ``scores`` the
    evidence score per candidate category; ``variant`` the sub-type named by
    the request, if any.
    """

    name: str
    prior: CategoryPrior
    confidence: float = Field(ge=0.0, le=1.0)
    reason: str
    variant: VariantPrior | None = None
    scores: dict[str, float] = Field(default_factory=dict)


def _simple(s: str) -> str:
    return re.sub(r"[^a-z0-9]", "", s.lower())


@functools.lru_cache(maxsize=1)
def _lookup_tables() -> tuple[dict[str, str], dict[str, str]]:
    """(name/model_cat/synonym key -> category, body-label token -> category)."""
    pri = load_priors()
    by_key: dict[str, str] = {}
    tokens: dict[str, str] = {}
    for name, cat in pri.categories.items():
        by_key.setdefault(_simple(name), name)
        for mc in cat.model_cats:
            by_key.setdefault(_simple(mc), name)
    for name, cat in pri.categories.items():
        for syn in cat.synonyms:
            by_key.setdefault(_simple(syn.lstrip("~")), name)
        for tok in [*cat.label_tokens, name.lower(), *(m.lower() for m in cat.model_cats)]:
            tokens.setdefault(_simple(tok), name)
    return by_key, tokens


def resolve_category(name: str | None) -> str | None:
    """Canonical category for a category name, model_cat or synonym, else None.

    Case and punctuation are ignored (``trash can`` -> ``TrashCan``,
    ``fridge`` -> ``Refrigerator``).
    """
    if not name:
        return None
    return _lookup_tables()[0].get(_simple(name))


def category_prior(name: str, strict: bool = False) -> CategoryPrior:
    """The prior of category ``name`` (canonical name, model_cat or synonym).

    Unknown names give the ``Generic`` fallback, or raise ``KeyError`` when
    ``strict``. Sources: ``categories.yaml``.
    """
    canon = resolve_category(name)
    if canon is None:
        if strict:
            raise KeyError(f"unknown category {name!r} (not in categories.yaml)")
        canon = GENERIC
    return load_priors().categories[canon]


@dataclass(frozen=True)
class CategoryMention:
    """A category named in a request: character span, the words, the category,
    whether the word is ambiguous (weak) and whether it reads as a part of
    another object (``its door``)."""

    start: int
    end: int
    phrase: str
    category: str
    weak: bool
    possessive: bool


_WORD_L = r"(?<![\w-])"
_WORD_R = r"(?![\w-])"


def phrase_regex(phrase: str, plural: bool = False) -> str:
    """Regex source matching ``phrase`` as whole words (hyphenated compounds are
    one word; internal spaces match any whitespace; optional plural ``s``/``es``)."""
    body = r"\s+".join(re.escape(w) for w in phrase.split())
    if plural:
        body += r"(?:s|es)?"
    return _WORD_L + body + _WORD_R


@functools.lru_cache(maxsize=1)
def _mention_regex() -> tuple[re.Pattern[str], dict[str, tuple[str, bool]]]:
    pri = load_priors()
    phrase_to: dict[str, tuple[str, bool]] = {}
    for name, cat in pri.categories.items():
        for syn in cat.synonyms:
            weak = syn.startswith("~")
            s = " ".join(syn.lstrip("~").lower().split())
            phrase_to.setdefault(s, (name, weak))
    alts = sorted(phrase_to, key=lambda p: (-len(p), p))
    src = "|".join(f"(?:{phrase_regex(p, plural=True)})" for p in alts)
    # the same matches, tried only where a word starts with a first letter of
    # some phrase (the alternation is otherwise tried at every character)
    first = "".join(re.escape(c) for c in sorted({p[0] for p in alts}))
    return re.compile(f"{_WORD_L}(?=[{first}])(?:{src})"), phrase_to


_POSSESSIVES = {"its", "their", "his", "her", "whose"}
_BACKWARD = re.compile(r"[.,;:!?()]|[a-z']+")


def _last_words(rev: str, pos: int, n: int = 2) -> list[str]:
    """The last ``n`` words (``[a-z']+``) of the clause that ends where
    ``rev[pos:]`` (the text reversed) begins, in text order: the same as
    ``re.findall(r"[a-z']+", re.split(r"[.,;:!?()]", text[:i])[-1])[-n:]``,
    but reading only back to the n-th word or the clause mark."""
    words: list[str] = []
    for t in _BACKWARD.finditer(rev, pos):
        w = t.group(0)
        if w in ".,;:!?()":
            break
        words.append(w[::-1])
        if len(words) == n:
            break
    return words[::-1]


def find_category_mentions(text: str) -> list[CategoryMention]:
    """Every category synonym in ``text`` (lower-cased), left to right, longest
    match first (``microwave oven`` before ``oven``, ``desk lamp`` before
    ``desk``). A mention preceded within two words by its/their/his/her is
    marked ``possessive`` (a part of the object: "with its door"), and so is one
    followed by "of a <category>" ("the door of a microwave")."""
    low = text.lower()
    rx, phrase_to = _mention_regex()
    out: list[CategoryMention] = []
    rev = low[::-1]  # words before a mention are read backwards: linear in len(text)
    for m in rx.finditer(low):
        words = " ".join(m.group(0).split())
        key = words
        if key not in phrase_to:
            for suf in ("es", "s"):
                if key.endswith(suf) and key[: -len(suf)] in phrase_to:
                    key = key[: -len(suf)]
                    break
        if key not in phrase_to:  # pragma: no cover - regex built from the keys
            continue
        cat, weak = phrase_to[key]
        before = _last_words(rev, len(low) - m.start())
        possessive = any(w in _POSSESSIVES for w in before)
        out.append(CategoryMention(m.start(), m.end(), m.group(0), cat, weak, possessive))
    # "the door of a microwave": a mention followed by "of <det>" and another
    # mention within three words names a part of that other object
    for i, m in enumerate(out[:-1]):
        nxt = out[i + 1]
        gap = low[m.end: nxt.start]
        if re.fullmatch(r"\s+of\s+(?:(?:a|an|the|this|that|my|your|our|its)\s+)?(?:[\w-]+\s+){0,2}", gap):
            out[i] = CategoryMention(m.start, m.end, m.phrase, m.category, m.weak, True)
    return out


def request_category(text: str) -> tuple[str | None, CategoryMention | None]:
    """The category a request is about: its first strong, non-possessive
    mention, else its first mention of any kind; (None, None) if none."""
    mentions = find_category_mentions(text)
    for m in mentions:
        if not m.weak and not m.possessive:
            return m.category, m
    if mentions:
        return mentions[0].category, mentions[0]
    return None, None


def find_variant(category: str, text: str) -> VariantPrior | None:
    """The variant of ``category`` named earliest in ``text`` (longest phrase
    wins at a position), or None."""
    found = variant_mention(category, text)
    return found[2] if found else None


def variant_mention(category: str, text: str) -> tuple[int, int, VariantPrior] | None:
    """Where ``text`` names a variant of ``category`` ("kitchen faucet",
    "mini fridge"): (start, end, variant) in character offsets of ``text``,
    the earliest mention (longest phrase at a position), or None.

    Raises:
        KeyError: ``category`` is not in categories.yaml.
    """
    if not text:
        return None
    cat = category_prior(category)
    low = text.lower()
    best: tuple[int, int, VariantPrior] | None = None
    for var in cat.variants:
        for ph in var.phrases:
            m = re.search(phrase_regex(" ".join(ph.lower().split())), low)
            if m and (best is None or (m.start(), -m.end()) < (best[0], -best[1])):
                best = (m.start(), m.end(), var)
    return best


def recognize_category(
    model_cat: str | None, semantic_labels: Iterable[str | None], request_text: str = ""
) -> CategoryMatch:
    """Recognise the category of an asset from all the evidence.

    Evidence (scores, dimensionless): the object the request is about (its first
    strong non-possessive category word, 4.0; other category words 1.0),
    ``model_cat`` (2.5), a body label naming a category (``suitcase_body``,
    1.0) and characteristic part labels (``part_evidence`` of
    categories.yaml, summed, at most 1.0). The request outweighs model_cat plus
    a body label, since it says what the user wants the asset to be (e.g. a
    Suitcase-filed asset requested as a "purse" gives Bag; Table-filed drawer
    cabinets requested as a "cabinet" give StorageFurniture). Best score below
    0.5 gives the ``Generic`` fallback with confidence 0.

    ``confidence`` = (best / sum of all scores) * min(1, best / 3): 1 when
    several sources agree, lower with conflicts or thin evidence.

    Never raises on unknown names; ``semantic_labels`` may contain None.
    """
    ev = _Evidence()
    text = request_text or ""
    _request_evidence(ev, text)
    if model_cat:
        mc = resolve_category(model_cat)
        if mc is not None and mc != GENERIC:
            ev.add(mc, _W_MODEL_CAT, f"model_cat {model_cat!r}")
    labels = sorted({lab for lab in semantic_labels if lab})
    _label_evidence(ev, labels)
    if not ev.scores or max(ev.scores.values()) < _MIN_SCORE:
        return _generic_match(ev, model_cat, labels)
    return _best_match(ev, text)


@dataclass
class _Evidence:
    """Evidence score (dimensionless) per candidate category and the reasons for it."""

    scores: dict[str, float] = field(default_factory=dict)
    why: dict[str, list[str]] = field(default_factory=dict)

    def add(self, cat: str, w: float, msg: str) -> None:
        self.scores[cat] = self.scores.get(cat, 0.0) + w
        self.why.setdefault(cat, []).append(msg)


def _request_evidence(ev: _Evidence, text: str) -> None:
    """The object the request is about (:data:`_W_REQUEST_HEAD`, or :data:`_W_REQUEST_OTHER` when weak or
    possessive) and each other category it mentions (:data:`_W_REQUEST_OTHER`)."""
    head_cat, head = request_category(text)
    if head is not None and head_cat is not None:
        w = _W_REQUEST_OTHER if (head.weak or head.possessive) else _W_REQUEST_HEAD
        ev.add(head_cat, w, f"request names {head.phrase!r}")
    for m in find_category_mentions(text):
        if m.category == head_cat or m.possessive:
            continue  # "with its door" names a part, not the object
        if m.category in ev.why and any("request" in r for r in ev.why[m.category]):
            continue
        ev.add(m.category, _W_REQUEST_OTHER, f"request also mentions {m.phrase!r}")


def _label_evidence(ev: _Evidence, labels: list[str]) -> None:
    """Body labels naming a category (:data:`_W_BODY_LABEL` once per category) and characteristic part
    labels (``part_evidence``, summed per category, at most :data:`_W_PART_CAP`)."""
    pri = load_priors()
    tokens = _lookup_tables()[1]
    body_hit: set[str] = set()
    part_sum: dict[str, float] = {}
    part_why: dict[str, list[str]] = {}
    for lab in labels:
        for tok in body_label_tokens(lab):
            cat = tokens.get(_simple(tok))
            if cat and cat not in body_hit and cat != GENERIC:
                body_hit.add(cat)
                ev.add(cat, _W_BODY_LABEL, f"label {lab!r}")
        canon = canonical_label(lab)
        if canon is None:
            continue
        for name, cat in pri.categories.items():
            w = cat.part_evidence.get(canon)
            if w and canon not in part_why.get(name, []):
                part_sum[name] = part_sum.get(name, 0.0) + w
                part_why.setdefault(name, []).append(canon)
    for name, s in part_sum.items():
        ev.add(name, min(_W_PART_CAP, s), f"part labels {part_why[name]}")


def _generic_match(ev: _Evidence, model_cat: str | None, labels: list[str]) -> CategoryMatch:
    """The ``Generic`` fallback (confidence 0) with the reason the evidence was not enough."""
    reason = "no usable evidence"
    if model_cat:
        reason += f" (model_cat {model_cat!r} unknown)"
    if labels:
        reason += f"; labels {labels}"
    return CategoryMatch(
        name=GENERIC,
        prior=load_priors().categories[GENERIC],
        confidence=0.0,
        reason=reason + "; using the generic fallback",
        scores={k: round(v, 3) for k, v in ev.scores.items()},
    )


def _best_match(ev: _Evidence, text: str) -> CategoryMatch:
    """The best-scoring category (ties: request evidence, then model_cat, then the name), its confidence
    (best / total) * min(1, best / 3), the reasons for it and against the others, and its variant in ``text``."""
    scores, why = ev.scores, ev.why

    def rank(name: str) -> tuple[float, bool, bool, str]:
        has_req = any("request" in r for r in why.get(name, []))
        has_mc = any(r.startswith("model_cat") for r in why.get(name, []))
        return (round(scores[name], 6), has_req, has_mc, name)

    best = max(scores, key=rank)
    total = sum(scores.values())
    conf = (scores[best] / total) * min(1.0, scores[best] / 3.0)
    others = sorted(((n, s) for n, s in scores.items() if n != best), key=lambda t: -t[1])
    reason = f"{best}: " + ", ".join(why[best])
    if others:
        reason += "; against: " + ", ".join(f"{n} ({s:.1f}: {', '.join(why[n])})" for n, s in others)
    return CategoryMatch(
        name=best,
        prior=load_priors().categories[best],
        confidence=round(max(0.0, min(1.0, conf)), 3),
        reason=reason,
        variant=find_variant(best, text),
        scores={k: round(v, 3) for k, v in scores.items()},
    )

