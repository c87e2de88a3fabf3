"""Physical priors as data: categories, materials, part labels, size classes.

The numbers live in ``asset2sim/priors/*.yaml`` (package data), each with its
source; this module loads and validates them (pydantic) and answers the
questions the estimator asks:

- which category is this asset (:func:`recognize_category`), from the
  request words, ``meta.json``'s ``model_cat`` and the semantic labels;
- how big and how heavy a regular / small / large one is
  (:func:`target_size`, :func:`mass_range`);
- what a part is made of (:func:`material_for`): density, whether it is a
  hollow shell and its wall thickness, contact friction;
- which parts are task-relevant, accessories or spring-returned
  (:func:`part_role`, :func:`spring_expected`, :func:`request_label_matches`).

Units: SI throughout: lengths m, masses kg, densities kg/m^3. Nothing here is
object-specific; unknown categories and labels fall back to the ``Generic``
category and to the per-label defaults of ``labels.yaml``.

Sources of the tables: see each yaml entry and ``docs/priors.md``.
"""

from __future__ import annotations

import functools
import math
import re
from collections.abc import Iterable
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any, Literal

import yaml
from pydantic import AfterValidator, BaseModel, ConfigDict, Field, ValidationError, model_validator

from asset2sim.schemas.request import SizeClass

if TYPE_CHECKING:  # pragma: no cover
    from asset2sim.schemas.request import RequestSpec

#: Largest object width (m) a robot's parallel gripper is assumed to close on.
#: Source: Franka Emika Hand datasheet, stroke 80 mm (2 x 40 mm); Robotiq 2F-85
#: datasheet, stroke 85 mm; 0.075 m leaves ~5-10 mm of approach margin. A
#: handheld object keeps at least two of its three dimensions within it.
GRASPABLE_WIDTH_M: float = 0.075

#: Smallest plausible total mass of any object, kg (a few grams: a USB stick,
#: a pen refill). Floor for the scaled mass ranges.
MASS_FLOOR_KG: float = 0.001

#: Canonical name of the fallback category.
GENERIC: str = "Generic"

SIZE_CLASSES: tuple[str, ...] = ("tiny", "very_small", "small", "regular", "large", "very_large")

PartRole = Literal["task", "body", "accessory", "other"]

_BODY_LABELS = frozenset({"body", "base", "frame"})

# Evidence weights of recognize_category (dimensionless scores).
_W_REQUEST_HEAD = 4.0  # the object the request is about (first non-possessive mention)
_W_REQUEST_OTHER = 1.0  # any other / ambiguous mention
_W_MODEL_CAT = 2.5  # meta.json model_cat
_W_BODY_LABEL = 1.0  # "<category>_body" style label
_W_PART_CAP = 1.0  # cap on the sum of characteristic part labels
_MIN_SCORE = 0.5  # below this the Generic fallback is returned


class PriorsError(ValueError):
    """Bad prior data; the message names the yaml file and the key."""


# --------------------------------------------------------------------------- models


class _Model(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)


class MaterialPrior(_Model):
    """One material (``materials.yaml``).

    ``density`` kg/m^3; ``shell`` True for hollow molded/sheet/panel parts
    (mass = area * wall_thickness * density); ``wall_thickness`` m;
    ``lateral_friction`` dry Coulomb coefficient for contacts; ``restitution``
    0..1. ``*_source`` fields cite the references.
    """

    key: str = ""
    name: str = Field(min_length=1)
    density: float = Field(gt=50.0, lt=25000.0)
    density_source: str = Field(min_length=10)
    shell: bool
    wall_thickness: float = Field(gt=0.0, lt=0.1)
    wall_thickness_source: str = Field(min_length=10)
    lateral_friction: float = Field(ge=0.05, le=1.5)
    friction_source: str = Field(min_length=10)
    restitution: float = Field(default=0.1, ge=0.0, le=1.0)

    @property
    def source(self) -> str:
        """All sources of this entry in one string."""
        return (
            f"density: {self.density_source}; wall: {self.wall_thickness_source}; "
            f"friction: {self.friction_source}"
        )


class SizeClassPrior(_Model):
    """Linear size factor of one size class (``size_classes.yaml``), dimensionless."""

    factor: float = Field(gt=0.0, lt=10.0)
    source: str = Field(min_length=10)


class LabelPrior(_Model):
    """Defaults of one canonical part label (``labels.yaml``)."""

    material: str
    role: PartRole
    spring: bool = False


class LabelTable(_Model):
    """``labels.yaml``: canonicalisation rules and per-label defaults."""

    strip_prefixes: list[str] = Field(default_factory=list)
    aliases: dict[str, str] = Field(default_factory=dict)
    labels: dict[str, LabelPrior]


Dims = tuple[float, float, float]


def _check_dims(v: Dims) -> Dims:
    if any(not (x > 0.0) for x in v):
        raise ValueError(f"dims must be positive metres, got {v}")
    if not (v[0] >= v[1] >= v[2]):
        raise ValueError(f"dims must be sorted [longest, middle, shortest], got {v}")
    if v[0] > 20.0:
        raise ValueError(f"dims larger than 20 m are not a household object: {v}")
    return v


def _check_mass(v: tuple[float, float]) -> tuple[float, float]:
    lo, hi = v
    if not (0.0 < lo < hi):
        raise ValueError(f"mass_range must satisfy 0 < low < high (kg), got {v}")
    return v


#: Dimensions (m, sorted longest first) and a mass range (kg) as read from the
#: yaml tables, checked on load.
CheckedDims = Annotated[Dims, AfterValidator(_check_dims)]
MassRange = Annotated[tuple[float, float], AfterValidator(_check_mass)]


class VariantPrior(_Model):
    """A sub-type of a category named by request words (e.g. ``mini fridge``).

    ``dims`` m sorted [longest, middle, shortest]; ``size_class`` is the size
    class these dims already represent relative to the category; ``mass_range``
    kg for that size.
    """

    name: str = Field(min_length=1)
    phrases: list[str] = Field(min_length=1)
    dims: CheckedDims
    size_class: SizeClass = "regular"
    mass_range: MassRange
    body_material: str | None = None
    part_materials: dict[str, str] = Field(default_factory=dict)
    source: str = Field(min_length=10)


class CategoryPrior(_Model):
    """Priors of one category (``categories.yaml``); see that file's header.

    ``dims`` m sorted [longest, middle, shortest] of a regular-size object in
    its closed state; ``mass_range`` kg of a regular-size object.
    """

    name: str = ""
    synonyms: list[str] = Field(default_factory=list)
    model_cats: list[str] = Field(default_factory=list)
    label_tokens: list[str] = Field(default_factory=list)
    dims: CheckedDims
    dims_source: str = Field(min_length=10)
    handheld: bool = False
    mass_range: MassRange
    mass_source: str = Field(min_length=10)
    body_material: str
    part_materials: dict[str, str] = Field(default_factory=dict)
    material_source: str = Field(min_length=10)
    spring_labels: list[str] = Field(default_factory=list)
    spring_source: str = ""
    task_relevant: list[str] = Field(default_factory=list)
    accessories: list[str] = Field(default_factory=list)
    label_synonyms: dict[str, list[str]] = Field(default_factory=dict)
    part_evidence: dict[str, float] = Field(default_factory=dict)
    variants: list[VariantPrior] = Field(default_factory=list)
    notes: str = ""

    @model_validator(mode="after")
    def _consistency(self) -> "CategoryPrior":
        if self.spring_labels and len(self.spring_source) < 10:
            raise ValueError("spring_labels given without a spring_source")
        if self.handheld and self.dims[1] > GRASPABLE_WIDTH_M + 1e-9:
            raise ValueError(
                f"handheld but the middle dimension {self.dims[1]} m exceeds the "
                f"gripper limit GRASPABLE_WIDTH_M = {GRASPABLE_WIDTH_M} m"
            )
        for k, w in self.part_evidence.items():
            if not (0.0 < w <= 1.0):
                raise ValueError(f"part_evidence[{k!r}] must be in (0, 1], got {w}")
        return self

    def variant(self, name: str) -> VariantPrior | None:
        """The variant called ``name`` (case-insensitive), or None."""
        for v in self.variants:
            if v.name.lower() == name.lower():
                return v
        return None


class Priors(_Model):
    """All prior tables, validated and cross-checked."""

    size_classes: dict[str, SizeClassPrior]
    materials: dict[str, MaterialPrior]
    labels: LabelTable
    categories: dict[str, CategoryPrior]


class CategoryMatch(_Model):
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


class SizeTarget(_Model):
    """The size and mass an output asset should have (:func:`target_size`).

    ``dims`` m sorted [longest, middle, shortest] = ``base_dims * factor``;
    ``factor`` dimensionless; ``mass_range`` kg; ``gripper_limit_factor`` the
    largest factor on ``dims`` that keeps a handheld object graspable (None
    when not handheld).
    """

    category: str
    variant: str | None = None
    size_class: SizeClass | None = None
    base_dims: Dims
    factor: float
    dims: Dims
    mass_range: tuple[float, float]
    body_material: str
    handheld: bool
    gripper_limit_factor: float | None = None
    note: str = ""


# --------------------------------------------------------------------------- loading

_FILES = ("materials.yaml", "labels.yaml", "size_classes.yaml", "categories.yaml")


def _read_yaml(directory: Path | None, fname: str) -> Any:
    try:
        if directory is None:
            text = resources.files("asset2sim.priors").joinpath(fname).read_text(encoding="utf-8")
        else:
            text = (Path(directory) / fname).read_text(encoding="utf-8")
    except FileNotFoundError as exc:
        raise PriorsError(f"{fname}: file not found ({exc})") from exc
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        raise PriorsError(f"{fname}: not valid YAML: {exc}") from exc
    if not isinstance(data, dict):
        raise PriorsError(f"{fname}: top level must be a mapping, got {type(data).__name__}")
    return data


def _fmt_validation(fname: str, prefix: str, exc: ValidationError) -> str:
    lines = []
    for err in exc.errors():
        loc = ".".join(str(p) for p in (prefix, *err["loc"]) if str(p) != "")
        lines.append(f"{fname}: {loc}: {err['msg']}")
    return "; ".join(lines)


def _validate_entry(
    model: type[BaseModel], fname: str, where: str, data: Any, **extra: Any
) -> Any:
    if not isinstance(data, dict):
        raise PriorsError(f"{fname}: {where}: entry must be a mapping, got {type(data).__name__}")
    try:
        return model.model_validate({**data, **extra})
    except ValidationError as exc:
        raise PriorsError(_fmt_validation(fname, where, exc)) from exc


def _build(directory: Path | None) -> Priors:
    raw_mat = _read_yaml(directory, "materials.yaml")
    materials = {
        k: _validate_entry(MaterialPrior, "materials.yaml", k, v, key=k) for k, v in raw_mat.items()
    }
    raw_sc = _read_yaml(directory, "size_classes.yaml")
    size_classes = {
        k: _validate_entry(SizeClassPrior, "size_classes.yaml", k, v) for k, v in raw_sc.items()
    }
    if set(size_classes) != set(SIZE_CLASSES):
        raise PriorsError(
            f"size_classes.yaml: keys must be exactly {list(SIZE_CLASSES)}, got {sorted(size_classes)}"
        )
    facs = [size_classes[c].factor for c in SIZE_CLASSES]
    if any(b <= a for a, b in zip(facs, facs[1:])) or size_classes["regular"].factor != 1.0:
        raise PriorsError(
            "size_classes.yaml: factors must increase from tiny to very_large with regular = 1.0"
        )
    labels = _validate_entry(LabelTable, "labels.yaml", "", _read_yaml(directory, "labels.yaml"))
    for lab, lp in labels.labels.items():
        if lp.material not in materials:
            raise PriorsError(f"labels.yaml: labels.{lab}.material: unknown material {lp.material!r}")
    for alias, target in labels.aliases.items():
        if target not in labels.labels:
            raise PriorsError(f"labels.yaml: aliases.{alias}: target {target!r} is not a label")

    raw_cat = _read_yaml(directory, "categories.yaml")
    categories = {
        k: _validate_entry(CategoryPrior, "categories.yaml", k, v, name=k) for k, v in raw_cat.items()
    }
    if GENERIC not in categories:
        raise PriorsError(f"categories.yaml: the fallback category {GENERIC!r} is missing")
    seen_syn: dict[str, str] = {}
    for name, cat in categories.items():
        where = f"categories.yaml: {name}"
        mats = [("body_material", cat.body_material)] + [
            (f"part_materials.{k}", m) for k, m in cat.part_materials.items()
        ]
        for i, var in enumerate(cat.variants):
            if var.body_material is not None:
                mats.append((f"variants.{i}.body_material", var.body_material))
            mats += [(f"variants.{i}.part_materials.{k}", m) for k, m in var.part_materials.items()]
        for key, mat in mats:
            if mat not in materials:
                raise PriorsError(f"{where}.{key}: unknown material {mat!r} (not in materials.yaml)")
        label_refs: list[tuple[str, str]] = []
        label_refs += [(f"part_materials.{k}", k) for k in cat.part_materials]
        label_refs += [("spring_labels", k) for k in cat.spring_labels]
        label_refs += [("task_relevant", k) for k in cat.task_relevant]
        label_refs += [("accessories", k) for k in cat.accessories]
        label_refs += [(f"label_synonyms.{k}", k) for k in cat.label_synonyms]
        label_refs += [(f"label_synonyms.{k}", v) for k, vs in cat.label_synonyms.items() for v in vs]
        label_refs += [(f"part_evidence.{k}", k) for k in cat.part_evidence]
        for i, var in enumerate(cat.variants):
            label_refs += [(f"variants.{i}.part_materials.{k}", k) for k in var.part_materials]
        for key, lab in label_refs:
            if lab not in labels.labels:
                raise PriorsError(
                    f"{where}.{key}: {lab!r} is not a canonical label of labels.yaml"
                )
        for syn in cat.synonyms:
            s = syn.lstrip("~").strip().lower()
            if not s:
                raise PriorsError(f"{where}.synonyms: empty synonym")
            if s in seen_syn and seen_syn[s] != name:
                raise PriorsError(
                    f"{where}.synonyms: {s!r} is also a synonym of {seen_syn[s]} (ambiguous)"
                )
            seen_syn[s] = name
    return Priors(size_classes=size_classes, materials=materials, labels=labels, categories=categories)


@functools.lru_cache(maxsize=1)
def load_priors() -> Priors:
    """The packaged prior tables, validated once and cached.

    Raises :class:`PriorsError` naming the yaml file and key on bad data.
    Sources: each yaml entry; summary in ``docs/priors.md``.
    """
    return _build(None)


def load_priors_from(directory: str | Path) -> Priors:
    """Load and validate the four prior yaml files from ``directory`` (not cached).

    Used to check edited tables. Raises :class:`PriorsError` (file and key in
    the message) on missing files or bad data.
    """
    return _build(Path(directory))


# --------------------------------------------------------------------------- labels


def _norm_token(s: str) -> str:
    return re.sub(r"[\s\-]+", "_", s.strip().lower()).strip("_")


@functools.lru_cache(maxsize=4096)
def canonical_label(label: str | None) -> str | None:
    """Canonical part label of a PartNet-Mobility semantic label.

    ``rotation_lid`` -> ``lid``, ``stapler_body`` -> ``body``, ``door_frame``
    -> ``frame``, ``foot_pad`` -> ``foot``, ``drawers`` -> ``drawer``. Rules in
    ``labels.yaml``. Unknown labels are returned normalised (lower case, ``_``);
    None or blank gives None.
    """
    if label is None or not label.strip():
        return None
    table = load_priors().labels
    known = table.labels
    s = _norm_token(label)

    def look(x: str) -> str | None:
        if x in table.aliases:
            return table.aliases[x]
        if x in known:
            return x
        if x.endswith("s") and x[:-1] in known:
            return x[:-1]
        return None

    hit = look(s)
    if hit:
        return hit
    stripped = s
    changed = True
    while changed:
        changed = False
        for p in table.strip_prefixes:
            if stripped.startswith(p) and len(stripped) > len(p):
                stripped = stripped[len(p):]
                changed = True
    hit = look(stripped)
    if hit:
        return hit
    toks = [t for t in stripped.split("_") if t]
    for tok in reversed(toks):
        hit = look(tok)
        if hit:
            return hit
    return stripped


def _body_label_tokens(label: str) -> list[str]:
    """Prefix words of a body-like label (``suitcase_body`` -> [``suitcase``])."""
    s = _norm_token(label)
    toks = [t for t in s.split("_") if t]
    if len(toks) >= 2 and canonical_label(toks[-1]) in _BODY_LABELS:
        return toks[:-1]
    return []


# --------------------------------------------------------------------------- categories


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
    if not text:
        return None
    cat = category_prior(category)
    low = text.lower()
    best: tuple[int, int, VariantPrior] | None = None
    for var in cat.variants:
        for ph in var.phrases:
            m = re.search(phrase_regex(" ".join(ph.lower().split())), low)
            if m and (best is None or (m.start(), -(m.end() - m.start())) < (best[0], best[1])):
                best = (m.start(), -(m.end() - m.start()), var)
    return best[2] if best else None


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
    pri = load_priors()
    scores: dict[str, float] = {}
    why: dict[str, list[str]] = {}

    def add(cat: str, w: float, msg: str) -> None:
        scores[cat] = scores.get(cat, 0.0) + w
        why.setdefault(cat, []).append(msg)

    text = request_text or ""
    head_cat, head = request_category(text)
    if head is not None and head_cat is not None:
        w = _W_REQUEST_OTHER if (head.weak or head.possessive) else _W_REQUEST_HEAD
        add(head_cat, w, f"request names {head.phrase!r}")
    for m in find_category_mentions(text):
        if m.category == head_cat or m.possessive:
            continue  # "with its door" names a part, not the object
        if m.category in why and any("request" in r for r in why[m.category]):
            continue
        add(m.category, _W_REQUEST_OTHER, f"request also mentions {m.phrase!r}")

    if model_cat:
        mc = resolve_category(model_cat)
        if mc is not None and mc != GENERIC:
            add(mc, _W_MODEL_CAT, f"model_cat {model_cat!r}")

    labels = sorted({lab for lab in semantic_labels if lab})
    tokens = _lookup_tables()[1]
    body_hit: set[str] = set()
    part_sum: dict[str, float] = {}
    part_why: dict[str, list[str]] = {}
    for lab in labels:
        for tok in _body_label_tokens(lab):
            cat = tokens.get(_simple(tok))
            if cat and cat not in body_hit and cat != GENERIC:
                body_hit.add(cat)
                add(cat, _W_BODY_LABEL, f"label {lab!r}")
        canon = canonical_label(lab)
        if canon is None:
            continue
        for name, cat in pri.categories.items():
            w = cat.part_evidence.get(canon)
            if w and canon not in part_why.get(name, []):
                part_sum[name] = part_sum.get(name, 0.0) + w
                part_why.setdefault(name, []).append(canon)
    for name, s in part_sum.items():
        add(name, min(_W_PART_CAP, s), f"part labels {part_why[name]}")

    variant_text = text
    if not scores or max(scores.values()) < _MIN_SCORE:
        reason = "no usable evidence"
        if model_cat:
            reason += f" (model_cat {model_cat!r} unknown)"
        if labels:
            reason += f"; labels {labels}"
        return CategoryMatch(
            name=GENERIC,
            prior=pri.categories[GENERIC],
            confidence=0.0,
            reason=reason + "; using the generic fallback",
            scores={k: round(v, 3) for k, v in scores.items()},
        )

    def rank(name: str) -> tuple[float, bool, bool, str]:
        has_req = any("request" in r for r in why.get(name, []))
        has_mc = any(r.startswith("model_cat") for r in why.get(name, []))
        return (round(scores[name], 6), has_req, has_mc, name)

    best = max(scores, key=rank)
    total = sum(scores.values())
    conf = (scores[best] / total) * min(1.0, scores[best] / 3.0)
    others = sorted(
        ((n, s) for n, s in scores.items() if n != best), key=lambda t: -t[1]
    )
    reason = f"{best}: " + ", ".join(why[best])
    if others:
        reason += "; against: " + ", ".join(
            f"{n} ({s:.1f}: {', '.join(why[n])})" for n, s in others
        )
    return CategoryMatch(
        name=best,
        prior=pri.categories[best],
        confidence=round(max(0.0, min(1.0, conf)), 3),
        reason=reason,
        variant=find_variant(best, variant_text),
        scores={k: round(v, 3) for k, v in scores.items()},
    )


# --------------------------------------------------------------------------- materials


def material(key: str) -> MaterialPrior:
    """The material ``key`` of materials.yaml. Raises ``KeyError`` if unknown."""
    mats = load_priors().materials
    if key not in mats:
        raise KeyError(f"unknown material {key!r} (not in materials.yaml)")
    return mats[key]


def material_for(
    category: str, semantic_label: str | None, variant: str | None = None
) -> MaterialPrior:
    """The default material of a part (density kg/m^3, shell, wall m, friction).

    Lookup order: the variant's and then the category's ``part_materials`` for
    the canonical label; body/base/frame (and a missing label) -> the
    variant's or category's ``body_material``; else the label's default in
    ``labels.yaml``; unknown labels -> the category's body material. Unknown
    categories use ``Generic``. Sources: materials.yaml, categories.yaml.
    """
    cat = category_prior(category)
    var = cat.variant(variant) if variant else None
    canon = canonical_label(semantic_label)
    body = (var.body_material if var and var.body_material else None) or cat.body_material
    key: str
    if canon is not None and var is not None and canon in var.part_materials:
        key = var.part_materials[canon]
    elif canon is not None and canon in cat.part_materials:
        key = cat.part_materials[canon]
    elif canon is None or canon in _BODY_LABELS:
        key = body
    else:
        lp = load_priors().labels.labels.get(canon)
        key = lp.material if lp is not None else body
    return material(key)


# --------------------------------------------------------------------------- roles


def part_role(category: str, semantic_label: str | None) -> PartRole:
    """Role of a part: ``task`` (its joint state is what a task/request acts on),
    ``body``, ``accessory`` or ``other``.

    The category's ``task_relevant`` and ``accessories`` lists win over the
    per-label defaults of labels.yaml; body/base/frame labels are ``body``.
    """
    canon = canonical_label(semantic_label)
    if canon is None:
        return "other"
    cat = category_prior(category)
    if canon in cat.task_relevant:
        return "task"
    if canon in _BODY_LABELS:
        return "body"
    if canon in cat.accessories:
        return "accessory"
    lp = load_priors().labels.labels.get(canon)
    if lp is None:
        return "other"
    if lp.role == "task" and cat.task_relevant:
        # the category names its task parts; a generic 'task' label not in the
        # list (e.g. a toilet's pump lid) is secondary
        return "other"
    return lp.role


def task_relevant_rank(category: str, semantic_label: str | None) -> int | None:
    """Priority (0 = highest) of a part among the category's task-relevant
    labels, or None if it is not task-relevant. For ``Generic`` (no list) the
    labels.yaml ``task`` role gives rank 0."""
    canon = canonical_label(semantic_label)
    if canon is None:
        return None
    cat = category_prior(category)
    if canon in cat.task_relevant:
        return cat.task_relevant.index(canon)
    if not cat.task_relevant:
        lp = load_priors().labels.labels.get(canon)
        if lp is not None and lp.role == "task":
            return 0
    return None


def spring_expected(category: str, semantic_label: str | None) -> bool:
    """True when a joint moving this part naturally has a return spring (stapler
    top arm, toaster lever, push buttons). Sources: ``spring_source`` of
    categories.yaml and the header of labels.yaml."""
    canon = canonical_label(semantic_label)
    if canon is None:
        return False
    cat = category_prior(category)
    if canon in cat.spring_labels:
        return True
    lp = load_priors().labels.labels.get(canon)
    return bool(lp and lp.spring)


def request_label_matches(category: str, request_label: str | None, semantic_label: str | None) -> bool:
    """Whether a part word of a request (``JointStateRequest.label``) names a link
    with this semantic label: equal canonical labels, or a category
    ``label_synonyms`` entry (a faucet's "handle" is labelled ``switch``, a
    laptop's "lid" is its ``screen``). When no joint matches, callers should fall
    back to the category's task-relevant joints."""
    a = canonical_label(request_label)
    b = canonical_label(semantic_label)
    if a is None or b is None:
        return False
    if a == b:
        return True
    return b in category_prior(category).label_synonyms.get(a, [])


# --------------------------------------------------------------------------- sizes, masses


def size_factor(size_class: str | None) -> float:
    """Linear size factor of a size class (None -> 1.0), dimensionless.

    Source: size_classes.yaml. Raises ``KeyError`` for an unknown class.
    """
    if size_class is None:
        return 1.0
    sc = load_priors().size_classes
    if size_class not in sc:
        raise KeyError(f"unknown size class {size_class!r}; expected one of {list(SIZE_CLASSES)}")
    return sc[size_class].factor


def scale_mass_range(lo: float, hi: float, factor: float) -> tuple[float, float]:
    """Mass range (kg) of an object whose linear size is ``factor`` times one of
    mass ``lo..hi`` kg.

    Solid objects scale with volume (factor^3), thin-walled ones whose wall
    thickness does not change with size scale with area (factor^2); the range
    spans both: smaller -> [lo f^3, hi f^2], larger -> [lo f^2, hi f^3], with
    the floor ``MASS_FLOOR_KG``. Monotone non-decreasing in ``factor``.
    Raises ``ValueError`` for a non-positive factor.
    """
    if not (factor > 0.0 and math.isfinite(factor)):
        raise ValueError(f"size factor must be positive and finite, got {factor}")
    if factor <= 1.0:
        a, b = lo * factor**3, hi * factor**2
    else:
        a, b = lo * factor**2, hi * factor**3
    a = max(a, MASS_FLOOR_KG)
    b = max(b, 1.05 * a)
    return (a, b)


def mass_range(category: str, size_class: str | None = None, variant: str | None = None) -> tuple[float, float]:
    """Plausible total mass (kg) of an object of ``category`` in ``size_class``.

    The regular-size range of categories.yaml (or the variant's, whose own size
    class is taken into account) scaled by :func:`scale_mass_range` with the
    size factor of the class. Unknown categories use ``Generic``. Raises
    ``KeyError`` for an unknown size class. Table: docs/priors.md.
    """
    cat = category_prior(category)
    var = cat.variant(variant) if variant else None
    if var is not None:
        f = size_factor(size_class) / size_factor(var.size_class) if size_class else 1.0
        lo, hi = var.mass_range
    else:
        f = size_factor(size_class)
        lo, hi = cat.mass_range
    return scale_mass_range(lo, hi, f)


def gripper_limit_factor(dims: Iterable[float]) -> float:
    """Largest uniform factor on ``dims`` (m, any order, 3 values) that keeps two
    of them within ``GRASPABLE_WIDTH_M``. Raises ``ValueError`` unless 3
    positive values are given."""
    d = sorted(float(x) for x in dims)
    if len(d) != 3 or d[0] <= 0.0:
        raise ValueError(f"dims must be 3 positive lengths in m, got {d}")
    return GRASPABLE_WIDTH_M / d[1]


def fits_gripper(dims: Iterable[float]) -> bool:
    """True when at least two of the 3 dimensions (m) are within
    ``GRASPABLE_WIDTH_M`` (the object can be grasped whole)."""
    return gripper_limit_factor(dims) >= 1.0 - 1e-9


def target_size(category: str, request: "RequestSpec | str | None" = None) -> SizeTarget:
    """Target dimensions and mass range for an output asset.

    ``request`` is a parsed :class:`~asset2sim.schemas.request.RequestSpec`,
    raw request text (parsed here) or None. If the request names a variant of
    the category (``mini fridge``, ``carry-on``, ``jewelry box``) its dims are
    the base and the size words are applied relative to the variant's own size
    class, never enlarging it by a smaller word ("mini fridge" is already a
    small refrigerator; "very small jewelry box" is 0.5/0.75 of a jewelry box).
    Otherwise base = the category's dims times the size class factor. For
    handheld categories the note warns when the result no longer fits the
    gripper. Units: m, kg.
    """
    if isinstance(request, str):
        from asset2sim.tasks.interpret.request import parse_request

        request = parse_request(request)
    cat = category_prior(category)
    size_class = request.size_class if request is not None else None
    text = request.text if request is not None else ""
    var = find_variant(cat.name, text) if text else None
    notes: list[str] = []
    if var is not None:
        base = var.dims
        f = size_factor(size_class) / size_factor(var.size_class) if size_class else 1.0
        if f > 1.0 and size_class is not None and size_factor(size_class) <= 1.0:
            f = 1.0  # a "small"/"regular" word never enlarges a variant that is already smaller
        lo, hi = var.mass_range
        body = var.body_material or cat.body_material
        notes.append(
            f"variant {var.name!r} ({var.size_class}) dims {list(base)} m; "
            f"size words {size_class or 'none'} -> factor {f:.3g} relative to it"
        )
    else:
        base = cat.dims
        f = request.size_factor if request is not None and size_class else 1.0
        lo, hi = cat.mass_range
        body = cat.body_material
        notes.append(
            f"{cat.name} regular dims {list(base)} m; size class {size_class or 'regular'} -> factor {f:.3g}"
        )
    dims = tuple(x * f for x in base)
    mr = scale_mass_range(lo, hi, f)
    glf = None
    if cat.handheld:
        glf = gripper_limit_factor(dims)
        if glf < 1.0:
            notes.append(
                f"handheld but the middle dimension {sorted(dims)[1]:.3f} m exceeds the gripper "
                f"limit {GRASPABLE_WIDTH_M} m (largest graspable factor {glf:.3g})"
            )
    return SizeTarget(
        category=cat.name,
        variant=var.name if var else None,
        size_class=size_class,
        base_dims=base,
        factor=f,
        dims=dims,  # type: ignore[arg-type]
        mass_range=mr,
        body_material=body,
        handheld=cat.handheld,
        gripper_limit_factor=glf,
        note="; ".join(notes),
    )
