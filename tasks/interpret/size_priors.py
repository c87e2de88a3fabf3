"""How big and how heavy an object of a category and size class is (m, kg;
``size_classes.yaml``, ``categories.yaml``, ``docs/design/priors.md``); the evaluation's summary of
them (:func:`size_mass_prior`, never raising) and the mass range scaled to measured extents
(:func:`scaled_mass_range`)."""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

import numpy as np

from asset2sim.schemas.request import RequestSpec, SizeClass
from asset2sim.tasks.interpret.categories import category_prior, find_variant
from asset2sim.prior_tables import GENERIC, GRASPABLE_WIDTH_M, SIZE_CLASSES, Dims, PriorModel, load_priors
from asset2sim.tasks.interpret.request import parse_request

#: Smallest plausible total mass of any object, kg: the floor of the scaled mass ranges.
MASS_FLOOR_KG: float = 0.001
#: An object's largest dimension is plausible within this factor either way of its category's typical one: unit
#: mistakes are 10x (mm/cm), 25.4x (inch), 100x (cm/m) or 1000x (mm/m); sizes within a category span less.
#: The one rule of refine (a size in real units is kept when plausible) and the audit (its scale verdict).
SCALE_TOLERANCE: float = 5.0
#: Largest dimension span of a household object of unknown category, m (a 2 cm part to a 3 m wardrobe).
GENERIC_SIZE_M: tuple[float, float] = (0.02, 3.0)


class SizeTarget(PriorModel):
    """The size and mass an output asset should have: ``dims`` m = ``base_dims * factor``, ``mass_range`` kg (the
    category's or variant's ``base_mass_range`` kg scaled by ``factor``), ``gripper_limit_factor`` the largest factor
    keeping a handheld object graspable (else None)."""

    category: str
    variant: str | None = None
    size_class: SizeClass | None = None
    base_dims: Dims
    factor: float
    dims: Dims
    mass_range: tuple[float, float]
    base_mass_range: tuple[float, float]
    handheld: bool
    gripper_limit_factor: float | None = None
    note: str = ""


def size_factor(size_class: str | None) -> float:
    """Linear size factor of a size class (None -> 1.0); ``KeyError`` for an unknown class."""
    if size_class is None:
        return 1.0
    sc = load_priors().size_classes
    if size_class not in sc:
        raise KeyError(f"unknown size class {size_class!r}; expected one of {list(SIZE_CLASSES)}")
    return sc[size_class].factor


def scale_mass_range(lo: float, hi: float, factor: float) -> tuple[float, float]:
    """Mass range (kg) of an object ``factor`` times the size of one of ``lo..hi`` kg, spanning solid (f^3)
    and thin-walled (f^2) scaling, floored at ``MASS_FLOOR_KG``; ``ValueError`` for a non-positive factor."""
    if not (factor > 0.0 and math.isfinite(factor)):
        raise ValueError(f"size factor must be positive and finite, got {factor}")
    a, b = (lo * factor**3, hi * factor**2) if factor <= 1.0 else (lo * factor**2, hi * factor**3)
    a = max(a, MASS_FLOOR_KG)
    return a, max(b, 1.05 * a)


def mass_range(category: str, size_class: str | None = None, variant: str | None = None) -> tuple[float, float]:
    """Plausible total mass (kg) of ``category`` (or its variant) in ``size_class``; ``KeyError`` for an
    unknown size class."""
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
    """Largest uniform factor on 3 ``dims`` (m) keeping two within ``GRASPABLE_WIDTH_M``; else ``ValueError``."""
    d = sorted(float(x) for x in dims)
    if len(d) != 3 or d[0] <= 0.0:
        raise ValueError(f"dims must be 3 positive lengths in m, got {d}")
    return GRASPABLE_WIDTH_M / d[1]


def fits_gripper(dims: Iterable[float]) -> bool:
    """True when at least two of the 3 dimensions (m) are within ``GRASPABLE_WIDTH_M``."""
    return gripper_limit_factor(dims) >= 1.0 - 1e-9


def target_size(category: str, request: RequestSpec | str | None = None) -> SizeTarget:
    """Target dimensions and mass range for ``request`` (parsed, text or None): a named variant's dims with the
    size words relative to its own size class (never enlarged by a smaller word), else the category's dims
    times the size factor; the note warns when a handheld result no longer fits the gripper.
    """
    if isinstance(request, str):
        request = parse_request(request)
    cat = category_prior(category)
    size_class = request.size_class if request is not None else None
    var = find_variant(cat.name, request.text) if request is not None else None
    notes: list[str] = []
    if var is not None:
        base = var.dims
        f = size_factor(size_class) / size_factor(var.size_class) if size_class else 1.0
        if f > 1.0 and size_factor(size_class) <= 1.0:
            f = 1.0  # a "small"/"regular" word never enlarges a variant that is already smaller
        lo, hi = var.mass_range
        notes.append(
            f"variant {var.name!r} ({var.size_class}) dims {list(base)} m; "
            f"size words {size_class or 'none'} -> factor {f:.3g} relative to it"
        )
    else:
        base = cat.dims
        f = request.size_factor if request is not None and size_class else 1.0
        lo, hi = cat.mass_range
        notes.append(
            f"{cat.name} regular dims {list(base)} m; size class {size_class or 'regular'} -> factor {f:.3g}"
        )
    dims = tuple(x * f for x in base)
    glf = None
    if cat.handheld:
        glf = gripper_limit_factor(dims)
        if glf < 1.0:
            notes.append(f"handheld but the middle dimension {sorted(dims)[1]:.3f} m exceeds the gripper "
                         f"limit {GRASPABLE_WIDTH_M} m (largest graspable factor {glf:.3g})")
    return SizeTarget(category=cat.name, variant=var.name if var else None, size_class=size_class, base_dims=base, factor=f,
                      dims=dims, mass_range=scale_mass_range(lo, hi, f), base_mass_range=(lo, hi),  # type: ignore[arg-type]
                      handheld=cat.handheld,
                      gripper_limit_factor=glf, note="; ".join(notes))


@dataclass(frozen=True, slots=True)
class LargestDimension:
    """The plausible largest dimension of an object (:func:`plausible_largest_dimension`): ``low`` to ``high`` m,
    and the ``typical`` one (m; None for ``Generic``)."""

    low: float
    high: float
    typical: float | None


def plausible_largest_dimension(category: str) -> LargestDimension:
    """The span of plausible largest dimensions of an object of ``category`` at its
    typical size (:func:`target_size`): the typical largest dimension divided and multiplied by
    :data:`SCALE_TOLERANCE`; for ``Generic``, :data:`GENERIC_SIZE_M` and no typical one (None). The audit's scale
    verdict and refine's choice to keep a size in real units both read it."""
    if category == GENERIC:
        return LargestDimension(*GENERIC_SIZE_M, None)
    typical = float(max(target_size(category).dims))
    return LargestDimension(*plausible_span(typical), typical)


def plausible_span(typical: float) -> tuple[float, float]:
    """(low, high) m: the plausible largest dimensions around a ``typical`` one (m), :data:`SCALE_TOLERANCE` either way."""
    return typical / SCALE_TOLERANCE, typical * SCALE_TOLERANCE


def size_mass_prior(category: str | None, spec: RequestSpec | None = None) -> dict[str, Any]:
    """Size target and mass prior of ``category`` with the request ``spec``'s
    size words: {"category", "target_dims" (m, largest first), "base_dims" (m),
    "factor", "variant", "base_mass_range" (kg), "note", "source"}, or {} without a prior.
    """
    if not category:
        return {}
    try:
        t = target_size(category, spec)
        cat = category_prior(category)
    except Exception:
        return {}
    return {"category": t.category, "target_dims": [float(x) for x in t.dims], "base_dims": [float(x) for x in t.base_dims],
            "factor": float(t.factor), "variant": t.variant, "base_mass_range": tuple(map(float, t.base_mass_range)),
            "note": t.note, "source": f"asset2sim/priors/categories.yaml: {cat.dims_source}; {cat.mass_source}"}


def scaled_mass_range(prior: dict[str, Any], extents: Any) -> tuple[tuple[float, float] | None, float]:
    """Plausible mass range (kg) for closed-state ``extents`` (3,) m: the base
    range scaled by :func:`scale_mass_range` with f the geometric mean of extent / base
    dimension over the two largest (f^3 where that rejects f).

    Returns:
        (range or None without a base mass range, f).
    """
    if not prior or not prior.get("base_mass_range"):
        return None, 1.0
    lo, hi = prior["base_mass_range"]
    f = 1.0
    ext = None if extents is None else np.sort(np.asarray(extents, float).ravel())[::-1]
    if ext is not None and len(ext) >= 2 and prior.get("base_dims") and float(ext[0]) > 0:
        base = np.sort(np.asarray(prior["base_dims"], float))[::-1]
        f = float(np.exp(np.mean(np.log(np.maximum(ext[:2], 1e-9) / base[:2]))))
    try:
        return scale_mass_range(lo, hi, f), f
    except Exception:
        return (lo * f**3, hi * f**3), f
