"""Which category an asset is (``categories.yaml``): names and synonyms, request
mentions, and :func:`recognize_category` weighing request words, ``model_cat``
and semantic labels (``Generic`` for thin evidence; ``docs/design/priors.md``).
"""

from __future__ import annotations

import functools
import re
from collections.abc import Iterable
from dataclasses import dataclass, field, replace

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
    """Result of :func:`recognize_category`: ``confidence`` in [0, 1], the evidence ``reason`` and ``scores``,
    and the ``variant`` the request names."""

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
        for key in [name, *cat.model_cats]:
            by_key.setdefault(_simple(key), name)
    for name, cat in pri.categories.items():
        for syn in cat.synonyms:
            by_key.setdefault(_simple(syn.lstrip("~")), name)
        for tok in [*cat.label_tokens, name.lower(), *(m.lower() for m in cat.model_cats)]:
            tokens.setdefault(_simple(tok), name)
    return by_key, tokens


def resolve_category(name: str | None) -> str | None:
    """Canonical category for a name, model_cat or synonym (case and punctuation ignored), else None."""
    return _lookup_tables()[0].get(_simple(name)) if name else None


def category_prior(name: str, strict: bool = False) -> CategoryPrior:
    """The prior of category ``name``; unknown names give ``Generic``, or ``KeyError`` when ``strict``."""
    canon = resolve_category(name)
    if canon is None:
        if strict:
            raise KeyError(f"unknown category {name!r} (not in categories.yaml)")
        canon = GENERIC
    return load_priors().categories[canon]


@dataclass(frozen=True)
class CategoryMention:
    """A category named in a request: span, words, category, ambiguous (weak), a part of another object."""

    start: int
    end: int
    phrase: str
    category: str
    weak: bool
    possessive: bool


_WORD_L = r"(?<![\w-])"
_WORD_R = r"(?![\w-])"


def phrase_regex(phrase: str, plural: bool = False) -> str:
    """Regex source matching ``phrase`` as whole words (any whitespace inside; optional plural)."""
    body = r"\s+".join(re.escape(w) for w in phrase.split())
    if plural:
        body += r"(?:s|es)?"
    return _WORD_L + body + _WORD_R


@functools.lru_cache(maxsize=1)
def _mention_regex() -> tuple[re.Pattern[str], dict[str, tuple[str, bool]]]:
    # phrase -> (category, weak)
    phrase_to: dict[str, tuple[str, bool]] = {}
    for name, cat in load_priors().categories.items():
        for syn in cat.synonyms:
            phrase_to.setdefault(" ".join(syn.lstrip("~").lower().split()), (name, syn.startswith("~")))
    alts = sorted(phrase_to, key=lambda p: (-len(p), p))
    src = "|".join(f"(?:{phrase_regex(p, plural=True)})" for p in alts)
    # tried only where a word starts with some phrase's first letter
    first = "".join(re.escape(c) for c in sorted({p[0] for p in alts}))
    return re.compile(f"{_WORD_L}(?=[{first}])(?:{src})"), phrase_to


_POSSESSIVES = {"its", "their", "his", "her", "whose"}
_BACKWARD = re.compile(r"[.,;:!?()]|[a-z']+")


def _last_words(rev: str, pos: int, n: int = 2) -> list[str]:
    """The last ``n`` words of the clause ending where ``rev[pos:]`` (the text reversed) begins, in text order."""
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
    """Every category synonym in ``text``, left to right, longest first; ``possessive`` after its/their/his/her
    within two words ("with its door"), before "of a <category>" ("the door of a microwave") or after "<category> with a"
    and at most two words ("a safe with a stiff door")."""
    low = text.lower()
    rx, phrase_to = _mention_regex()
    out: list[CategoryMention] = []
    rev = low[::-1]  # words before a mention are read backwards: linear in len(text)
    for m in rx.finditer(low):
        # the phrase, else its singular
        key = " ".join(m.group(0).split())
        key = next((k for k in (key, key.removesuffix("es"), key.removesuffix("s")) if k in phrase_to), key)
        cat, weak = phrase_to[key]
        possessive = any(w in _POSSESSIVES for w in _last_words(rev, len(low) - m.start()))
        out.append(CategoryMention(m.start(), m.end(), m.group(0), cat, weak, possessive))
    # "the door of a microwave": a mention followed by "of <det>" and another
    # mention within three words names a part of that other object
    for i, (m, nxt) in enumerate(zip(out, out[1:])):
        if re.fullmatch(r"\s+of\s+(?:(?:a|an|the|this|that|my|your|our|its)\s+)?(?:[\w-]+\s+){0,2}", low[m.end: nxt.start]):
            out[i] = replace(m, possessive=True)
        # "a safe with a stiff door": a mention after "with <det>" and at most two words, right after another
        # mention, names a part of that object
        elif re.fullmatch(r"\s+with\s+(?:(?:a|an|the|its|one|two|three|four)\s+)?(?:[\w-]+\s+){0,2}", low[m.end: nxt.start]):
            out[i + 1] = replace(nxt, possessive=True)
    return out


def request_category(text: str) -> tuple[str | None, CategoryMention | None]:
    """(category, mention) a request is about: the first strong non-possessive mention, else the first."""
    mentions = find_category_mentions(text)
    m = next((m for m in mentions if not m.weak and not m.possessive), mentions[0] if mentions else None)
    return (None, None) if m is None else (m.category, m)


def find_variant(category: str, text: str) -> VariantPrior | None:
    """The variant of ``category`` named earliest in ``text``, or None."""
    return (variant_mention(category, text) or (None, None, None))[2]


def variant_mention(category: str, text: str) -> tuple[int, int, VariantPrior] | None:
    """(start, end, variant) of the earliest variant of ``category`` (unknown: ``Generic``) in ``text`` (longest first), or None."""
    if not text:
        return None
    low = text.lower()
    hits = [(m.start(), m.end(), var) for var in category_prior(category).variants for ph in var.phrases
            if (m := re.search(phrase_regex(" ".join(ph.lower().split())), low))]
    return min(hits, key=lambda h: (h[0], -h[1]), default=None)


def recognize_category(
    model_cat: str | None, semantic_labels: Iterable[str | None], request_text: str = ""
) -> CategoryMatch:
    """Recognise the category of an asset: scores for the request's object (4.0; other mentions 1.0),
    ``model_cat`` (2.5), a body label (1.0) and part labels (at most 1.0); below 0.5 ``Generic``.
    ``confidence`` = (best / total) * min(1, best / 3). Never raises; ``semantic_labels`` may hold None.
    """
    ev = _Evidence()
    text = request_text or ""
    head_cat, head = request_category(text)  # the request's object, then each other category it mentions
    if head is not None:
        ev.add(head.category, _W_REQUEST_OTHER if (head.weak or head.possessive) else _W_REQUEST_HEAD,
               f"request names {head.phrase!r}")
    for m in find_category_mentions(text):
        if m.category == head_cat or m.possessive or any("request" in r for r in ev.why.get(m.category, [])):
            continue  # "with its door" names a part, not the object
        ev.add(m.category, _W_REQUEST_OTHER, f"request also mentions {m.phrase!r}")
    mc = resolve_category(model_cat)
    if mc not in (None, GENERIC):
        ev.add(mc, _W_MODEL_CAT, f"model_cat {model_cat!r}")
    labels = sorted({lab for lab in semantic_labels if lab})
    _label_evidence(ev, labels)
    scores, why = ev.scores, ev.why
    rounded = {k: round(v, 3) for k, v in scores.items()}
    if not scores or max(scores.values()) < _MIN_SCORE:  # the generic fallback, with why the evidence was not enough
        reason = ("no usable evidence" + (f" (model_cat {model_cat!r} unknown)" if model_cat else "")
                  + (f"; labels {labels}" if labels else ""))
        return CategoryMatch(name=GENERIC, prior=load_priors().categories[GENERIC], confidence=0.0,
                             reason=reason + "; using the generic fallback", scores=rounded)

    def rank(name: str) -> tuple[float, bool, bool, str]:  # ties: request evidence, model_cat, name
        reasons = why.get(name, [])
        return round(scores[name], 6), any("request" in r for r in reasons), any(r.startswith("model_cat") for r in reasons), name

    best = max(scores, key=rank)
    conf = (scores[best] / sum(scores.values())) * min(1.0, scores[best] / 3.0)
    others = sorted(((n, s) for n, s in scores.items() if n != best), key=lambda t: -t[1])
    reason = f"{best}: " + ", ".join(why[best])
    if others:
        reason += "; against: " + ", ".join(f"{n} ({s:.1f}: {', '.join(why[n])})" for n, s in others)
    return CategoryMatch(name=best, prior=load_priors().categories[best], confidence=round(max(0.0, min(1.0, conf)), 3),
                         reason=reason, variant=find_variant(best, text), scores=rounded)


@dataclass
class _Evidence:
    """Evidence score (dimensionless) per candidate category and the reasons for it."""

    scores: dict[str, float] = field(default_factory=dict)
    why: dict[str, list[str]] = field(default_factory=dict)

    def add(self, cat: str, w: float, msg: str) -> None:
        self.scores[cat] = self.scores.get(cat, 0.0) + w
        self.why.setdefault(cat, []).append(msg)


def _label_evidence(ev: _Evidence, labels: list[str]) -> None:
    """Evidence of body labels naming a category and of characteristic part labels."""
    pri = load_priors()
    tokens = _lookup_tables()[1]
    body_hit: set[str] = set()
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
                part_why.setdefault(name, []).append(canon)
    for name, canons in part_why.items():
        ev.add(name, min(_W_PART_CAP, sum(pri.categories[name].part_evidence[c] for c in canons)), f"part labels {canons}")
