"""The prior tables of ``asset2sim/priors/*.yaml`` (materials, labels, size
classes, categories): their models, loading (:func:`load_priors`) and
cross-checks, raising :class:`PriorsError` naming the yaml file and key.
Units SI (m, kg, kg/m^3); sources in each yaml entry and ``docs/design/priors.md``.
"""

from __future__ import annotations

import functools
import re
from pathlib import Path
from typing import Annotated, Any, Literal

import yaml
from pydantic import AfterValidator, BaseModel, ConfigDict, Field, ValidationError, model_validator

from asset2sim.package_data import package_text
from asset2sim.schemas.request import SizeClass

#: Largest object width (m) a parallel gripper is assumed to close on (Franka
#: Hand stroke 80 mm, Robotiq 2F-85 85 mm, less approach margin).
GRASPABLE_WIDTH_M: float = 0.075

#: Canonical name of the fallback category.
GENERIC: str = "Generic"

SIZE_CLASSES: tuple[str, ...] = ("tiny", "very_small", "small", "regular", "large", "very_large")

PartRole = Literal["task", "body", "accessory", "other"]
#: The references of a prior value, as the yaml tables give them (at least 10 characters).
Source = Annotated[str, Field(min_length=10)]


class PriorsError(ValueError):
    """Bad prior data; the message names the yaml file and the key."""


class PriorModel(BaseModel):
    """Base of the prior models: no extra fields, immutable, finite numbers."""

    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)


class MaterialPrior(PriorModel):
    """One material: ``density`` kg/m^3, ``shell`` (mass = area *
    wall_thickness * density), ``panel`` (a board: half that area), ``wall_thickness`` m, ``lateral_friction``
    (Coulomb), ``restitution`` 0..1, ``*_source`` the references."""

    key: str = ""
    name: str = Field(min_length=1)
    density: float = Field(gt=50.0, lt=25000.0)
    density_source: Source
    shell: bool
    panel: bool = False
    wall_thickness: float = Field(gt=0.0, lt=0.1)
    wall_thickness_source: Source
    lateral_friction: float = Field(ge=0.05, le=1.5)
    friction_source: Source
    restitution: float = Field(default=0.1, ge=0.0, le=1.0)

    @property
    def source(self) -> str:
        """All sources of this entry in one string."""
        return f"density: {self.density_source}; wall: {self.wall_thickness_source}; friction: {self.friction_source}"


class SizeClassPrior(PriorModel):
    """Linear size factor of one size class (``size_classes.yaml``), dimensionless."""

    factor: float = Field(gt=0.0, lt=10.0)
    source: Source


class LabelPrior(PriorModel):
    """Defaults of one canonical part label (``labels.yaml``)."""

    material: str
    role: PartRole
    spring: bool = False


class LabelTable(PriorModel):
    """``labels.yaml``: canonicalisation rules and per-label defaults."""

    strip_prefixes: list[str] = Field(default_factory=list)
    aliases: dict[str, str] = Field(default_factory=dict)
    words: dict[str, list[str]] = Field(default_factory=dict)
    """A request's part word -> the canonical labels it may also name, in order; tried only when no part of the
    object carries the word's own label or a category synonym of it (``part_priors.named_by_word``)."""
    labels: dict[str, LabelPrior]


Dims = tuple[float, float, float]

#: Largest dimension (m) a category or variant prior may give: beyond it an
#: object is not a household object (checked on load).
MAX_PRIOR_DIM_M: float = 20.0


def _check_dims(v: Dims) -> Dims:
    if any(not (x > 0.0) for x in v):
        raise ValueError(f"dims must be positive metres, got {v}")
    if not (v[0] >= v[1] >= v[2]):
        raise ValueError(f"dims must be sorted [longest, middle, shortest], got {v}")
    if v[0] > MAX_PRIOR_DIM_M:
        raise ValueError(f"dims larger than {MAX_PRIOR_DIM_M:g} m are not a household object: {v}")
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


class VariantPrior(PriorModel):
    """A sub-type of a category named by request words (``mini fridge``):
    ``dims`` m sorted longest first, the ``size_class`` they represent, and
    ``mass_range`` kg for that size."""

    name: str = Field(min_length=1)
    phrases: list[str] = Field(min_length=1)
    dims: CheckedDims
    size_class: SizeClass = "regular"
    mass_range: MassRange
    body_material: str | None = None
    part_materials: dict[str, str] = Field(default_factory=dict)
    source: Source


class CategoryPrior(PriorModel):
    """Priors of one category (see ``categories.yaml``'s header): ``dims`` m
    sorted longest first and ``mass_range`` kg of a regular-size closed object."""

    name: str = ""
    synonyms: list[str] = Field(default_factory=list)
    model_cats: list[str] = Field(default_factory=list)
    label_tokens: list[str] = Field(default_factory=list)
    dims: CheckedDims
    dims_source: Source
    handheld: bool = False
    mass_range: MassRange
    mass_source: Source
    body_material: str
    part_materials: dict[str, str] = Field(default_factory=dict)
    material_source: Source
    spring_labels: list[str] = Field(default_factory=list)
    spring_source: str = ""
    task_relevant: list[str] = Field(default_factory=list)
    accessories: list[str] = Field(default_factory=list)
    label_synonyms: dict[str, list[str]] = Field(default_factory=dict)
    """A request's part word (a label or any word, "arm") -> the labels it also names on this category."""
    part_evidence: dict[str, float] = Field(default_factory=dict)
    variants: list[VariantPrior] = Field(default_factory=list)
    levelling_feet_m: float | None = Field(default=None, gt=0.0, le=0.05)
    """The height (m) the category's adjustable levelling feet take up so that the body stands level on every foot;
    None: no such feet (the footprint is levelled by a contact margin only)."""
    levelling_feet_source: str = ""
    opened_lying: bool = False
    """Whether the object is laid on its back to be opened (a suitcase: upright, its lid opens into the floor); a
    request for an opening and no pose is then met lying down where standing it is not."""
    opened_lying_source: str = ""
    notes: str = ""

    @model_validator(mode="after")
    def _consistency(self) -> "CategoryPrior":
        for given, source, article in (("spring_labels", "spring_source", "a"),
                                       ("levelling_feet_m", "levelling_feet_source", "a"),
                                       ("opened_lying", "opened_lying_source", "an")):
            if getattr(self, given) and len(getattr(self, source)) < 10:  # levelling_feet_m is > 0 when given
                raise ValueError(f"{given} given without {article} {source}")
        if self.handheld and self.dims[1] > GRASPABLE_WIDTH_M + 1e-9:
            raise ValueError(f"handheld but the middle dimension {self.dims[1]} m exceeds the "
                             f"gripper limit GRASPABLE_WIDTH_M = {GRASPABLE_WIDTH_M} m")
        for k, w in self.part_evidence.items():
            if not (0.0 < w <= 1.0):
                raise ValueError(f"part_evidence[{k!r}] must be in (0, 1], got {w}")
        return self

    def variant(self, name: str) -> VariantPrior | None:
        """The variant called ``name`` (case-insensitive), or None."""
        return next((v for v in self.variants if v.name.lower() == name.lower()), None)


class SlidePrior(PriorModel):
    """One kind of drawer slide or runner (``slides.yaml``): ``friction_coefficient`` (lo, hi) of the drawer's weight
    (dimensionless), the request ``words`` that name it (regular expressions), its ``source``."""

    key: str = ""
    friction_coefficient: tuple[float, float]
    words: list[str] = Field(min_length=1)
    source: Source
    estimate: bool = False
    note: str = ""

    @model_validator(mode="after")
    def _check(self) -> "SlidePrior":
        lo, hi = self.friction_coefficient
        if not 0.0 < lo <= hi <= 1.0:
            raise ValueError(f"friction_coefficient must be 0 < lo <= hi <= 1, got {[lo, hi]}")
        for w in self.words:
            re.compile(w)
        return self


class Priors(PriorModel):
    """All prior tables, validated and cross-checked."""

    size_classes: dict[str, SizeClassPrior]
    materials: dict[str, MaterialPrior]
    labels: LabelTable
    categories: dict[str, CategoryPrior]
    slides: dict[str, SlidePrior]
    """``slides.yaml``, smoothest first"""


def _read_yaml(directory: Path | None, fname: str) -> Any:
    try:
        text = package_text("asset2sim.priors", fname) if directory is None else (Path(directory) / fname).read_text(encoding="utf-8")
    except FileNotFoundError as exc:
        raise PriorsError(f"{fname}: file not found ({exc})") from exc
    try:
        data = yaml.load(text, Loader=getattr(yaml, "CSafeLoader", yaml.SafeLoader))  # libyaml: same result, ~7x faster
    except yaml.YAMLError as exc:
        raise PriorsError(f"{fname}: not valid YAML: {exc}") from exc
    if not isinstance(data, dict):
        raise PriorsError(f"{fname}: top level must be a mapping, got {type(data).__name__}")
    return data


def _validate_entry(model: type[BaseModel], fname: str, where: str, data: Any, **extra: Any) -> Any:
    if not isinstance(data, dict):
        raise PriorsError(f"{fname}: {where}: entry must be a mapping, got {type(data).__name__}")
    try:
        return model.model_validate({**data, **extra})
    except ValidationError as exc:
        raise PriorsError("; ".join(f"{fname}: " + ".".join(str(p) for p in (where, *err["loc"]) if str(p) != "") + f": {err['msg']}"
                                    for err in exc.errors())) from exc


def _table(directory: Path | None, model: type[BaseModel], fname: str, name_field: str | None = None) -> dict[str, Any]:
    """Every entry of the mapping ``fname`` validated as ``model`` (its key given as ``name_field`` too)."""
    return {k: _validate_entry(model, fname, k, v, **({name_field: k} if name_field else {}))
            for k, v in _read_yaml(directory, fname).items()}


def _build(directory: Path | None) -> Priors:
    materials = _table(directory, MaterialPrior, "materials.yaml", "key")
    size_classes = _table(directory, SizeClassPrior, "size_classes.yaml")
    if set(size_classes) != set(SIZE_CLASSES):
        raise PriorsError(f"size_classes.yaml: keys must be exactly {list(SIZE_CLASSES)}, got {sorted(size_classes)}")
    facs = [size_classes[c].factor for c in SIZE_CLASSES]
    if any(b <= a for a, b in zip(facs, facs[1:])) or size_classes["regular"].factor != 1.0:
        raise PriorsError("size_classes.yaml: factors must increase from tiny to very_large with regular = 1.0")
    labels = _validate_entry(LabelTable, "labels.yaml", "", _read_yaml(directory, "labels.yaml"))
    for lab, lp in labels.labels.items():
        if lp.material not in materials:
            raise PriorsError(f"labels.yaml: labels.{lab}.material: unknown material {lp.material!r}")
    refs = [(f"aliases.{a}: target", t) for a, t in labels.aliases.items()]
    refs += [(f"words.{w}:", t) for w, targets in labels.words.items() for t in targets]
    for where, target in refs:
        if target not in labels.labels:
            raise PriorsError(f"labels.yaml: {where} {target!r} is not a label")

    categories = _table(directory, CategoryPrior, "categories.yaml", "name")
    if GENERIC not in categories:
        raise PriorsError(f"categories.yaml: the fallback category {GENERIC!r} is missing")
    seen_syn: dict[str, str] = {}
    for name, cat in categories.items():
        where = f"categories.yaml: {name}"
        owners = [("", cat), *((f"variants.{i}.", var) for i, var in enumerate(cat.variants))]  # the category, then each variant
        mats = [(f"{at}{key}", m) for at, o in owners
                for key, m in [("body_material", o.body_material),
                               *((f"part_materials.{k}", v) for k, v in o.part_materials.items())]]
        for key, mat in mats:
            if mat is not None and mat not in materials:
                raise PriorsError(f"{where}.{key}: unknown material {mat!r} (not in materials.yaml)")
        label_refs = [(f"part_materials.{k}", k) for k in cat.part_materials]
        label_refs += [(key, k) for key in ("spring_labels", "task_relevant", "accessories") for k in getattr(cat, key)]
        label_refs += [(f"label_synonyms.{k}", v) for k, vs in cat.label_synonyms.items() for v in vs]
        label_refs += [(f"part_evidence.{k}", k) for k in cat.part_evidence]
        label_refs += [(f"{at}part_materials.{k}", k) for at, var in owners[1:] for k in var.part_materials]
        for key, lab in label_refs:
            if lab not in labels.labels:
                raise PriorsError(f"{where}.{key}: {lab!r} is not a canonical label of labels.yaml")
        for syn in cat.synonyms:
            s = syn.lstrip("~").strip().lower()
            if not s:
                raise PriorsError(f"{where}.synonyms: empty synonym")
            if seen_syn.setdefault(s, name) != name:
                raise PriorsError(f"{where}.synonyms: {s!r} is also a synonym of {seen_syn[s]} (ambiguous)")
    slides = _table(directory, SlidePrior, "slides.yaml", "key")
    return Priors(size_classes=size_classes, materials=materials, labels=labels, categories=categories, slides=slides)


@functools.lru_cache(maxsize=1)
def load_priors() -> Priors:
    """The packaged prior tables, validated once and cached (:class:`PriorsError` on bad data)."""
    return _build(None)


def load_priors_from(directory: str | Path) -> Priors:
    """The prior tables of ``directory``, validated, not cached (:class:`PriorsError`)."""
    return _build(Path(directory))
