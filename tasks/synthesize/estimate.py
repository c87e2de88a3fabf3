"""Overlay synthesis (SPEC stage 2): the helpers every estimator shares (scale,
state bands, plausible mass, materials). The protocol and registry are
:mod:`.estimator`, the joint dynamics from loads :mod:`.joint_dynamics`, the
physics :mod:`.physics`."""

from __future__ import annotations

import numpy as np

from asset2sim.engines.base import SimSession
from asset2sim.schemas.request import BAND_INTERVAL, BAND_TARGET
from asset2sim.tasks.geometry.closed_state import ClosedState
from asset2sim.tasks.ingest import partnet_mobility
from asset2sim.tasks.ingest.declared import real_units
from asset2sim.prior_tables import GRASPABLE_WIDTH_M
from asset2sim.tasks.interpret.categories import find_variant
from asset2sim.tasks.interpret.part_priors import material_for
from asset2sim.tasks.interpret.size_priors import plausible_largest_dimension, scale_mass_range, target_size
from asset2sim.tasks.synthesize import physics, request_apply
from asset2sim.tasks.synthesize.context import EstimationContext


def requested_bands(ctx: EstimationContext, kin: SimSession) -> tuple[dict[str, str], list[str]]:
    """(joint -> band, notes with warnings first) from the request at the scale of :func:`choose_scale`
    (``kin``, the input's kinematics session, moved for ordinals and ends)."""
    res = request_apply.resolve_states(ctx, kin, choose_scale(ctx)[0])
    return res.bands, res.warnings + res.notes


def state_from_bands(closed: dict[str, ClosedState], bands: dict[str, str], scale: float, prismatic: set[str]) -> dict[str, float]:
    """Joint positions (output units) at each band's target opening fraction."""
    return {name: cs.position(BAND_TARGET[bands.get(name, "closed")]) * (scale if name in prismatic else 1.0)
            for name, cs in closed.items()}


def choose_scale(ctx: EstimationContext) -> tuple[float, str]:
    """(uniform scale s, note): sizes in numbers decide alone; else s is the geometric mean of the ratios
    of the two largest sorted target dimensions (``target_size``) to the closed extents, capped for
    handheld categories so two dimensions fit ``GRASPABLE_WIDTH_M``."""
    sized = request_apply.scale_from_sizes(ctx)
    if sized is not None:
        return sized
    kept, why_not = _real_size(ctx, real_units(ctx.asset))
    if kept is not None:
        return 1.0, kept
    target = target_size(ctx.category, ctx.request)
    dims = np.sort(np.asarray(target.dims, float))[::-1]
    ext = np.maximum(np.sort(np.asarray(ctx.closed_extents, float))[::-1], 1e-9)
    s = float(np.exp(np.mean(np.log(dims[:2] / ext[:2]))))
    note = (
        f"closed extents at scale 1 {np.round(ext, 4).tolist()}; target {np.round(dims, 4).tolist()} m ({target.note})"
        f" -> s = geometric mean of the two largest ratios = {s:.4g}"
    )
    if target.handheld:
        cap = GRASPABLE_WIDTH_M / ext[1]
        if s > cap:
            note += f"; handheld: capped to {cap:.4g} so two dimensions fit a {GRASPABLE_WIDTH_M} m gripper"
            s = cap
    note += f"; {why_not}" if why_not else ""
    return s, note + ('' if partnet_mobility.size_normalized(ctx.asset.staged_from or ctx.asset.urdf_path) else unit_warning(s))


def _real_size(ctx: EstimationContext, real: str | None) -> tuple[str | None, str | None]:
    """(note, None) when an input in real units (``real``: why, :func:`~asset2sim.tasks.ingest.declared.real_units`)
    keeps its size: no size asked (no size words, numbers, ``--size`` or ``--scale``) and its largest closed dimension
    plausible for its category by the audit's rule (:func:`~asset2sim.tasks.interpret.size_priors.plausible_largest_dimension`);
    else (None, why it is rescaled, for the size note; None for a normalized input)."""
    if real is None:
        return None, None
    largest = float(np.max(ctx.closed_extents))
    span = plausible_largest_dimension(ctx.category)
    lo, hi = span.low, span.high
    what = f"a typical {ctx.category} is {span.typical:.3g} m" if span.typical is not None else "a household object"
    if ctx.request.size_class is not None:
        return None, f"{real}, rescaled as asked ({ctx.request.size_class})"
    if lo <= largest <= hi:
        return (f"size kept (scale 1): {real}; largest closed dimension {largest:.4g} m is plausible "
                f"({what}; plausible {lo:.3g}-{hi:.3g} m, the audit's rule)"), None
    return None, (f"{real}, but its largest closed dimension {largest:.4g} m is implausible ({what}; plausible "
                  f"{lo:.3g}-{hi:.3g} m): rescaled")


#: Length units an input's numbers are often written in by mistake for metres: metres per unit -> name.
UNIT_MISTAKES = {0.001: "millimetres", 0.01: "centimetres", 0.0254: "inches"}
#: A scale beyond this factor from 1 is reported as a likely unit mistake (sizes within a category span less).
UNIT_WARNING_FACTOR = 5.0


def unit_warning(scale: float) -> str:
    """``"; WARNING: ..."`` when ``scale`` (output / input size) lies beyond :data:`UNIT_WARNING_FACTOR` from 1 and
    within a factor 1.5 of a unit of :data:`UNIT_MISTAKES` (lengths in that unit read as metres); ``""`` otherwise
    (a model drawn at another size is no unit mistake: the size note says how it was scaled)."""
    if 1.0 / UNIT_WARNING_FACTOR <= scale <= UNIT_WARNING_FACTOR:
        return ""
    unit, per = min(((name, m) for m, name in UNIT_MISTAKES.items()), key=lambda u: abs(np.log(scale / u[1])))
    if abs(np.log(scale / per)) >= np.log(1.5):
        return ""
    return (f"; WARNING: the input is {1.0 / scale:.3g}x its category's typical size (its lengths look like {unit} read as "
            f"metres); rescaled by {scale:.4g}")


def plausible_mass_range(ctx: EstimationContext, scale: float) -> tuple[float, float]:
    """Plausible total mass (kg) as sized: the regular mass range scaled (``scale_mass_range``) by f,
    the geometric mean of scaled closed extents / regular dims over the two largest dimensions."""
    target = target_size(ctx.category, ctx.request)
    base = np.sort(np.asarray(target.base_dims, float))[::-1]
    actual = np.sort(np.asarray(ctx.closed_extents, float) * scale)[::-1]
    return scale_mass_range(*target.base_mass_range, float(np.exp(np.mean(np.log(np.maximum(actual[:2], 1e-9) / base[:2])))))


def request_variant(ctx: EstimationContext) -> str | None:
    """The category variant the request names ("office cabinet"), or None."""
    v = find_variant(ctx.category, ctx.request.text)
    return v.name if v is not None else None


def link_material(ctx: EstimationContext, label: str | None, link: str) -> physics.MaterialChoice:
    """The material the request names for ``link``, else the category's prior for ``label``."""
    return physics.material_choice(request_apply.requested_material(ctx, link)
                                   or material_for(ctx.category, label, request_variant(ctx)))


def band_intervals(bands: dict[str, str], intervals: dict[str, tuple[float, float]] | None = None) -> dict[str, tuple[float, float]]:
    """Allowed opening-fraction interval per joint for its band; ``intervals`` (asked numbers or ends) win."""
    return {**{name: BAND_INTERVAL[b] for name, b in bands.items()}, **(intervals or {})}
