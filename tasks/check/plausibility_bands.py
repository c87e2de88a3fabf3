"""Declared values against the product's estimates: one :class:`~asset2sim.schemas.audit.ValueVerdict` per
value (pure functions over numbers; ``docs/guide/audit.md`` gives the rules, ``docs/design/audit.md`` why).

Units: SI and radians (mass kg, density kg/m^3, inertia kg*m^2, lengths m, revolute damping N*m*s/rad,
friction N*m, stiffness N*m/rad; prismatic N*s/m, N, N/m).
"""

from __future__ import annotations

import functools
import math

import numpy as np

from asset2sim.schemas.audit import ValueVerdict
from asset2sim.tasks.ingest.tree_checks import MIN_PRISMATIC_SPAN, MIN_REVOLUTE_SPAN
from asset2sim.tasks.interpret import size_priors

#: A declared mass is implausible beyond this factor outside the span of the product's estimates for the
#: link (thin shell of its material at the typical wall, solid of its material): the wall thicknesses of
#: ``materials.yaml`` span 0.44-1.5x their typical value (Protolabs ranges cited there) and parts carry inserts
#: and hardware the meshes do not show, so values within 3x of that span are not called implausible.
MASS_TOLERANCE = 3.0
#: A density (declared, or mass over the enclosed volume) is implausible above this multiple of the part's
#: material density (the densest a part of that material can be, with the same tolerance as masses), and
#: above :data:`MAX_DENSITY` whatever the material.
DENSITY_TOLERANCE = 3.0
#: Densest material a household object is made of, kg/m^3 (brass 8500, ``materials.yaml``, x 1.25 as
#: ``validate_overlay.MAX_DENSITY``): above it only lead, tungsten and the like.
MAX_DENSITY = 10625.0
#: An inertia tensor's trace is implausible beyond this factor outside the span of the geometry's thin-shell
#: and solid tensors at the declared mass.
INERTIA_TOLERANCE = 3.0
#: Relative slack of the triangle inequality on principal moments (float rounding of written files).
TRIANGLE_SLACK = 1e-6
#: The center of mass is implausible outside the geometry's bounding box grown by this share of its diagonal.
COM_MARGIN = 0.10
#: The object's largest dimension is implausible beyond this factor from its category's typical one, and a
#: household object of unknown category outside this span (m): the rule refine keeps sizes by
#: (:func:`asset2sim.tasks.interpret.size_priors.plausible_largest_dimension`).
SCALE_TOLERANCE, GENERIC_SIZE_M = size_priors.SCALE_TOLERANCE, size_priors.GENERIC_SIZE_M
#: Damping ratio below which a spring-returned joint rings (zeta of 0.05 keeps 73 % of the swing per cycle;
#: damping ratios of light structures are 0.02-0.05, Chopra, Dynamics of Structures, 5th ed., table 11.2.1).
ZETA_MIN_SPRING = 0.05
#: Damping ratio above which a joint creeps (zeta 1 is critical; 10x over it a part takes 20x its natural
#: period to settle); ratios are taken against the joint's restoring stiffness or the 0.5 Hz floor of
#: :func:`asset2sim.tasks.synthesize.physics.damping_for`.
ZETA_MAX = 10.0
#: Seconds a hand at the part's highest operating force may take to move it across its range against its damping
#: (the joint sweep's window each way, ``tasks/check/sweep.py``): more damping than that is implausible.
OPERATE_SECONDS = 3.0
#: A friction (or spring force) is implausible when above this multiple of what a hand at the part's
#: operating force exerts (``operating_forces.yaml``) or of the product's holding friction, whichever is larger.
FRICTION_TOLERANCE = 3.0
#: A prismatic joint's travel is implausible beyond this multiple of the object's largest dimension.
MAX_TRAVEL_FACTOR = 1.5


def _factor(declared: float | None, estimate: float | None) -> float | None:
    if declared is None or estimate is None or estimate == 0 or not math.isfinite(declared):
        return None
    return float(declared / estimate)


def _band_verdict(where: str, quantity: str, unit: str, declared: float | None, estimate: float, low: float | None,
                  high: float | None, what: str) -> ValueVerdict:
    """``declared`` inside [low, high] (None: unbounded) is plausible; outside, implausible with the factor."""
    result = functools.partial(ValueVerdict, where=where, quantity=quantity, unit=unit, estimate=estimate, low=low, high=high)
    if declared is None:
        return result(declared=None, verdict="not_declared", reason=f"not declared; the product estimates {estimate:.4g} {unit} ({what})")
    f = _factor(declared, estimate)
    below = low is not None and declared < low
    above = high is not None and declared > high
    reason = f"{declared:.4g} {unit} within {_span(low, high, unit)} ({what})"
    if below or above:
        edge = low if below else high
        reason = (f"{declared:.4g} {unit} is {'below' if below else 'above'} {_span(low, high, unit)}"
                  + (f", x{declared / edge:.3g} of its {'lower' if below else 'upper'} end" if edge else "")
                  + (f" (x{f:.3g} the estimate)" if f is not None else "") + f" ({what})")
    return result(declared=declared, factor=f, verdict="implausible" if below or above else "plausible", reason=reason)


def _span(low: float | None, high: float | None, unit: str) -> str:
    lo = "0" if low is None else f"{low:.4g}"
    hi = "inf" if high is None else f"{high:.4g}"
    return f"the plausible {lo}-{hi} {unit}"


def mass_verdict(where: str, declared: float | None, estimate: float, alternatives: list[float], material: str) -> ValueVerdict:
    """A link's mass (kg) against ``estimate`` (the product's) and ``alternatives`` (thin shell and solid of
    ``material``, kg): plausible within [min / :data:`MASS_TOLERANCE`, max x :data:`MASS_TOLERANCE`]."""
    span = [v for v in [estimate, *alternatives] if v > 0]
    return _band_verdict(where, "mass", "kg", declared, estimate, min(span) / MASS_TOLERANCE, max(span) * MASS_TOLERANCE,
                         f"{material}, shell to solid")


def total_mass_verdict(declared: float | None, low: float, high: float, category: str) -> ValueVerdict:
    """The object's total mass (kg) against its category's plausible range at its size (``low``, ``high`` kg,
    :func:`asset2sim.tasks.synthesize.estimate.plausible_mass_range`), widened by :data:`MASS_TOLERANCE`."""
    return _band_verdict("object", "mass", "kg", declared, math.sqrt(low * high), low / MASS_TOLERANCE, high * MASS_TOLERANCE,
                         f"a {category} of this size weighs {low:.3g}-{high:.3g} kg")


def density_verdict(where: str, declared: float, material: str, material_density: float, declared_directly: bool) -> ValueVerdict:
    """A density (kg/m^3: the one the file declares when ``declared_directly``, else mass over the enclosed
    volume, which a hollow part keeps below its material's) against ``material_density``: implausible above
    :data:`DENSITY_TOLERANCE` x it or :data:`MAX_DENSITY`."""
    high = min(material_density * DENSITY_TOLERANCE, MAX_DENSITY)
    what = (f"declared density, {material} is {material_density:g} kg/m^3" if declared_directly
            else f"mass over enclosed volume, {material} is {material_density:g} kg/m^3")
    return _band_verdict(where, "density", "kg/m^3", declared, material_density, None, high, what)


def inertia_verdict(where: str, tensor: np.ndarray | None, mass: float | None, per_kg: list[np.ndarray],
                    written: np.ndarray | None = None) -> ValueVerdict:
    """An inertia tensor (3, 3) kg*m^2 about the COM: implausible when not symmetric positive definite, when its
    principal moments violate the triangle inequality (I1 + I2 >= I3), or when its trace lies beyond
    :data:`INERTIA_TOLERANCE` outside the traces of the geometry's tensors ``per_kg`` ((3, 3) kg*m^2 per kg,
    thin shell and solid) at ``mass``. ``declared`` is the trace. ``written`` (3,): the principal moments as the
    file writes them, where the simulator changed them on loading (judged instead of the loaded tensor's)."""
    result = functools.partial(ValueVerdict, where=where, quantity="inertia", unit="kg*m^2")
    if tensor is None or mass is None:
        return result(declared=None, verdict="not_declared", reason="no inertia tensor declared")
    t = np.asarray(tensor, float)
    trace = float(np.trace(t))
    traces = [float(np.trace(p)) * mass for p in per_kg if np.isfinite(p).all()]
    est = traces[-1] if traces else None
    if not np.isfinite(t).all() or not np.allclose(t, t.T, rtol=1e-6, atol=1e-12):
        return result(declared=trace if math.isfinite(trace) else None, estimate=est, verdict="implausible",
                      reason="the tensor is not symmetric (or not finite)")
    eig = np.sort(np.linalg.eigvalsh(t) if written is None else np.asarray(written, float))
    if written is not None:
        trace = float(np.sum(eig))
    invalid = ""  # why no rigid body has these principal moments
    if eig[0] <= 0:
        invalid = ": not positive definite"
    elif eig[0] + eig[1] < eig[2] * (1 - TRIANGLE_SLACK):
        invalid = (f" violate the triangle inequality ({eig[0]:.4g} + {eig[1]:.4g} < {eig[2]:.4g}): no rigid body has them"
                   + (" (the simulator changed them on loading)" if written is not None else ""))
    if invalid:
        return result(declared=trace, estimate=est, factor=_factor(trace, est), verdict="implausible",
                      reason=f"principal moments {_moments(eig)} kg*m^2{invalid}")
    if not traces:
        return result(declared=trace, verdict="plausible",
                      reason=f"valid (principal moments {_moments(eig)} kg*m^2); no geometry to compare with")
    return _band_verdict(where, "inertia", "kg*m^2", trace, est, min(traces) / INERTIA_TOLERANCE, max(traces) * INERTIA_TOLERANCE,
                         f"trace; the geometry's thin-shell to solid tensors at the declared {mass:.4g} kg")


def _moments(eig: np.ndarray) -> str:
    return "(" + ", ".join(f"{e:.4g}" for e in eig) + ")"


def com_verdict(where: str, com: np.ndarray | None, bbox_min: np.ndarray, bbox_max: np.ndarray, geometric: np.ndarray) -> ValueVerdict:
    """A center of mass (3,) m in the link frame: implausible outside the geometry's bounding box
    (``bbox_min``, ``bbox_max`` (3,) m) grown by :data:`COM_MARGIN` of its diagonal. ``declared`` is its distance
    from the geometric center of mass ``geometric`` (3,), ``high`` the distance to the grown box's far corner."""
    result = functools.partial(ValueVerdict, where=where, quantity="center_of_mass", unit="m")
    if com is None:
        return result(declared=None, verdict="not_declared", reason="no center of mass declared")
    c, lo, hi = (np.asarray(v, float) for v in (com, bbox_min, bbox_max))
    margin = COM_MARGIN * float(np.linalg.norm(hi - lo))
    outside = np.maximum(np.maximum(lo - margin - c, c - hi - margin), 0.0)
    dist = float(np.linalg.norm(c - np.asarray(geometric, float)))
    out = float(np.linalg.norm(outside))
    place = f"({', '.join(f'{v:.4g}' for v in c)}) m lies {out:.4g} m outside" if out > 0 else "inside"
    return result(declared=dist, estimate=0.0, verdict="implausible" if out > 0 else "plausible",
                  reason=f"{place} the link's geometry (its box grown by {margin:.3g} m); {dist:.4g} m from the geometric "
                         "center of mass")


def scale_verdict(largest: float, typical: float | None, category: str) -> ValueVerdict:
    """The object's largest closed dimension (m) against its category's typical one (m): plausible within
    :data:`SCALE_TOLERANCE` either way; a category without one (``Generic``) within :data:`GENERIC_SIZE_M`."""
    if typical is None:
        lo, hi = GENERIC_SIZE_M
        return _band_verdict("object", "scale", "m", largest, math.sqrt(lo * hi), lo, hi, "largest dimension; a household object")
    lo, hi = size_priors.plausible_span(typical)
    return _band_verdict("object", "scale", "m", largest, typical, lo, hi, f"largest dimension; a typical {category} is {typical:.3g} m")


def critical_damping(inertia_axis: float, stiffness: float) -> float:
    """Critical damping 2 sqrt(I k) (N*m*s/rad or N*s/m) of a joint with ``inertia_axis`` (kg*m^2 or kg) and restoring
    ``stiffness`` (N*m/rad or N/m) (Ogata, System Dynamics, 4th ed., ch. 8)."""
    return 2.0 * math.sqrt(max(inertia_axis, 0.0) * max(stiffness, 0.0))


def operating_damping(operable: float | None, travel: float | None) -> float | None:
    """The damping (N*m*s/rad or N*s/m) at which a hand's ``operable`` torque or force moves a part across ``travel``
    (rad or m) in :data:`OPERATE_SECONDS`; None when either is unknown."""
    if not operable or not travel or travel <= 0:
        return None
    return operable * OPERATE_SECONDS / travel


def damping_verdict(where: str, declared: float | None, inertia_axis: float, stiffness: float, estimate: float,
                    friction: float | None, unit: str, operable_damping: float | None = None) -> ValueVerdict:
    """Viscous damping against the damping ratio zeta = c / (2 sqrt(I k)) it gives (``inertia_axis`` kg*m^2 or kg
    of the moving subtree, ``stiffness`` the restoring stiffness: gravity's, or the 0.5 Hz floor's): implausible
    above the larger of :data:`ZETA_MAX` x critical and ``operable_damping`` (:func:`operating_damping`: a hand
    still moves the part across its range in :data:`OPERATE_SECONDS`), or when no damping and no friction leave
    nothing to stop a moving part. ``estimate``: the product's (zeta 0.7)."""
    crit = critical_damping(inertia_axis, stiffness)
    high = max(ZETA_MAX * crit, operable_damping or 0.0) or None
    what = f"critical damping {crit:.4g} {unit}" + (f"; a hand moves it across its range in {OPERATE_SECONDS:g} s up to "
                                                    f"{operable_damping:.3g}" if operable_damping else "")
    if declared is not None and declared <= 0 and not (friction or 0) > 0:
        return ValueVerdict(where=where, quantity="damping", unit=unit, declared=declared, estimate=estimate, high=high, factor=0.0,
                            verdict="implausible", reason=f"no damping and no friction: nothing stops the part once moving ({what})")
    return _band_verdict(where, "damping", unit, declared, estimate, None, high, what)


def spring_damping_verdict(where: str, declared: float | None, inertia_axis: float, stiffness: float, estimate: float,
                           unit: str, operable_damping: float | None = None) -> ValueVerdict:
    """Damping of a spring-returned joint: zeta = c / (2 sqrt(I k)) at least :data:`ZETA_MIN_SPRING` (below it the
    part rings), at most the larger of :data:`ZETA_MAX` and ``operable_damping`` (:func:`damping_verdict`)
    (``inertia_axis`` kg*m^2 or kg, ``stiffness`` N*m/rad or N/m of the spring)."""
    crit = critical_damping(inertia_axis, stiffness)
    return _band_verdict(where, "damping", unit, declared if declared is not None else 0.0, estimate, ZETA_MIN_SPRING * crit,
                         max(ZETA_MAX * crit, operable_damping or 0.0), f"a spring of {stiffness:.4g}: critical damping {crit:.4g} {unit}; zeta "
                         f"{(declared or 0.0) / crit if crit > 0 else float('nan'):.3g}, plausible {ZETA_MIN_SPRING:g}-{ZETA_MAX:g}")


def friction_verdict(where: str, declared: float | None, estimate: float, operable: float | None, unit: str) -> ValueVerdict:
    """Joint friction: implausible above :data:`FRICTION_TOLERANCE` x the larger of the product's holding
    friction ``estimate`` and ``operable`` (what a hand at the part's highest operating force exerts about or
    along the axis); no lower end (a free-moving part has none)."""
    ref = max(estimate, operable or 0.0)
    high = FRICTION_TOLERANCE * ref if ref > 0 else None
    what = (f"holding friction {estimate:.3g}" + (f", a hand's {operable:.3g}" if operable else "") + f" {unit}")
    return _band_verdict(where, "friction", unit, declared, estimate, None, high, what)


def stiffness_verdict(where: str, declared: float, travel: float, operable: float | None, unit: str,
                      carried: float = 0.0) -> ValueVerdict:
    """A joint spring: implausible when its force over the ``travel`` (rad or m: the farthest point of the range
    from the spring's reference), less the part's weight it ``carried`` there (N or N*m along the travel, >= 0: a
    window's sash balance, an oven door's counterbalance), exceeds :data:`FRICTION_TOLERANCE` x ``operable`` (a
    hand's force or torque): k <= (3 operable + carried) / travel."""
    if operable is None or travel <= 0:
        return ValueVerdict(where=where, quantity="stiffness", unit=unit, declared=declared, verdict="plausible",
                            reason="no operating force known to compare with")
    high = (FRICTION_TOLERANCE * operable + max(carried, 0.0)) / travel
    return _band_verdict(where, "stiffness", unit, declared, (operable + max(carried, 0.0)) / travel, None, high,
                         f"a hand's {operable:.3g} over {travel:.3g} of travel from the spring's reference"
                         + (f", with the {carried:.3g} of the part's weight it carries there" if carried > 0 else ""))


def limits_verdict(where: str, kind: str, lower: float | None, upper: float | None, largest: float) -> ValueVerdict:
    """Joint limits (rad or m): implausible when lower > upper, a revolute range over a full turn or under a degree,
    or a prismatic travel over :data:`MAX_TRAVEL_FACTOR` x the object's ``largest`` dimension (m) or under a
    millimetre (the unit rule of validation's ``JOINT_RANGE_WRONG_UNIT``). ``declared`` is the range."""
    unit = "m" if kind == "prismatic" else "rad"
    result = functools.partial(ValueVerdict, where=where, quantity="limits", unit=unit)
    if lower is None or upper is None:
        return result(declared=None, verdict="not_declared",
                      reason="no limits (continuous)" if kind == "continuous" else "no limits declared")
    rng = float(upper - lower)
    if rng < 0:
        return result(declared=rng, verdict="implausible", reason=f"lower {lower:.4g} > upper {upper:.4g}")
    small = MIN_PRISMATIC_SPAN if kind == "prismatic" else MIN_REVOLUTE_SPAN
    if 0 < rng < small:  # validation's JOINT_RANGE_WRONG_UNIT: the same rule
        what = "a millimetre (millimetres read as metres?)" if kind == "prismatic" else "a degree (radians read as degrees?)"
        return result(declared=rng, verdict="implausible",
                      reason=f"range {lower:.4g} to {upper:.4g} spans less than {what}: it only makes sense in the "
                             "other unit (JOINT_RANGE_WRONG_UNIT)")
    high, what = ((MAX_TRAVEL_FACTOR * largest, f"{MAX_TRAVEL_FACTOR:g} x the object's largest dimension") if kind == "prismatic"
                  else (2 * math.pi, "a full turn"))
    return _band_verdict(where, "limits", unit, rng, rng, 0.0, high, f"range {lower:.4g} to {upper:.4g}; at most {what}")
