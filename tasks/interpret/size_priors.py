"""How big and how heavy an object of a category and size class is.

:func:`target_size` gives the dimensions (m) and mass range (kg) an output
asset should have for a request (the category's or the named variant's
dimensions times the size class factor); :func:`mass_range` and
:func:`scale_mass_range` scale mass ranges with size (solid f^3 to thin-walled
f^2); :func:`gripper_limit_factor` and :func:`fits_gripper` check handheld
objects against a parallel gripper's stroke. Sources: ``size_classes.yaml``,
``categories.yaml``, ``docs/design/priors.md``.
"""

from __future__ import annotations

import math
from collections.abc import Iterable

from asset2sim.schemas.request import RequestSpec, SizeClass
from asset2sim.tasks.interpret.categories import category_prior, find_variant
from asset2sim.prior_tables import GRASPABLE_WIDTH_M, SIZE_CLASSES, Dims, PriorModel, load_priors
from asset2sim.tasks.interpret.request import parse_request

#: Smallest plausible total mass of any object, kg (a few grams: a USB stick,
#: a pen refill). Floor for the scaled mass ranges.
MASS_FLOOR_KG: float = 0.001


class SizeTarget(PriorModel):
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
    ``KeyError`` for an unknown size class. Table: docs/design/priors.md.
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


def target_size(category: str, request: RequestSpec | str | None = None) -> SizeTarget:
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
