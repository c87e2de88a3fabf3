"""Overlay synthesis (SPEC stage 2): the helpers every estimator shares (scale,
state bands, plausible mass, joint dynamics from loads). The protocol and
registry are :mod:`.estimator`, the physics :mod:`.physics`."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from asset2sim.schemas.overlay import JointDynamics, LinkPhysics
from asset2sim.schemas.request import BAND_INTERVAL, BAND_TARGET
from asset2sim.tasks.geometry.closed_state import ClosedState
from asset2sim.tasks.ingest import partnet_mobility
from asset2sim.tasks.interpret import priors
from asset2sim.tasks.synthesize import physics, request_apply
from asset2sim.tasks.synthesize.context import EstimationContext


def task_relevant_joints(ctx: EstimationContext) -> list[str]:
    """Movable joints whose moving part tasks manipulate (:func:`request_apply.task_relevant_joints`)."""
    return request_apply.task_relevant_joints(ctx)


def requested_bands(ctx: EstimationContext, scale: float | None = None) -> tuple[dict[str, str], list[str]]:
    """(joint -> band, notes with warnings first) from the request at ``scale`` (default :func:`choose_scale`)."""
    res = request_apply.resolve_states(ctx, choose_scale(ctx)[0] if scale is None else scale)
    return res.bands, res.warnings + res.notes


def state_from_bands(closed: dict[str, ClosedState], bands: dict[str, str], scale: float, prismatic: set[str]) -> dict[str, float]:
    """Joint positions (output units) at each band's target opening fraction."""
    out = {}
    for name, cs in closed.items():
        q = cs.position(BAND_TARGET[bands.get(name, "closed")])
        out[name] = q * scale if name in prismatic else q
    return out


def choose_scale(ctx: EstimationContext) -> tuple[float, str]:
    """(uniform scale s, note): sizes in numbers decide alone; else s is the geometric mean of the ratios
    of the two largest sorted target dimensions (``priors.target_size``) to the closed extents, capped for
    handheld categories so two dimensions fit ``priors.GRASPABLE_WIDTH_M``."""
    sized = request_apply.scale_from_sizes(ctx)
    if sized is not None:
        return sized
    target = priors.target_size(ctx.category, ctx.request)
    dims = np.sort(np.asarray(target.dims, float))[::-1]
    ext = np.maximum(np.sort(np.asarray(ctx.closed_extents, float))[::-1], 1e-9)
    ratios = dims[:2] / ext[:2]
    s = float(np.exp(np.mean(np.log(ratios))))
    note = (
        f"closed extents at scale 1 {np.round(ext, 4).tolist()}; target {np.round(dims, 4).tolist()} m ({target.note})"
        f" -> s = geometric mean of the two largest ratios = {s:.4g}"
    )
    if target.handheld:
        cap = priors.GRASPABLE_WIDTH_M / ext[1]
        if s > cap:
            note += f"; handheld: capped to {cap:.4g} so two dimensions fit a {priors.GRASPABLE_WIDTH_M} m gripper"
            s = cap
    return s, note + ('' if partnet_mobility.size_normalized(ctx.asset.staged_from or ctx.asset.urdf_path) else unit_warning(s))


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
    guess = f"its lengths look like {unit} read as metres"
    return f"; WARNING: the input is {1.0 / scale:.3g}x its category's typical size ({guess}); rescaled by {scale:.4g}"


def plausible_mass_range(ctx: EstimationContext, scale: float) -> tuple[float, float]:
    """Plausible total mass (kg) as sized: the regular mass range scaled (``priors.scale_mass_range``) by f,
    the geometric mean of scaled closed extents / regular dims over the two largest dimensions."""
    target = priors.target_size(ctx.category, ctx.request)
    cat = priors.category_prior(ctx.category)
    var = cat.variant(target.variant) if target.variant else None
    base_lo, base_hi = var.mass_range if var is not None else cat.mass_range
    base = np.sort(np.asarray(target.base_dims, float))[::-1]
    actual = np.sort(np.asarray(ctx.closed_extents, float) * scale)[::-1]
    f = float(np.exp(np.mean(np.log(np.maximum(actual[:2], 1e-9) / base[:2]))))
    return priors.scale_mass_range(base_lo, base_hi, f)


def request_variant(ctx: EstimationContext) -> str | None:
    """The category variant the request names ("office cabinet"), or None."""
    v = priors.find_variant(ctx.category, ctx.request.text) if ctx.request.text else None
    return v.name if v is not None else None


def link_material(ctx: EstimationContext, label: str | None, link: str | None = None) -> physics.MaterialChoice:
    """The material the request names for ``link``, else the category's prior for ``label``."""
    m = (request_apply.requested_material(ctx, link) if link is not None else None) or priors.material_for(ctx.category, label, request_variant(ctx))
    return physics.material_choice(m)


@dataclass
class JointChoice:
    """Qualitative dynamics choices for one joint; :func:`joint_dynamics_for` turns them into numbers."""

    damping_level: str = "moderate"
    holds_position: bool = False
    spring: bool = False
    stiff: bool = False
    free_moving: bool = False


def joint_dynamics_for(ctx: EstimationContext, links: dict[str, LinkPhysics], state: dict[str, float], scale: float,
                       choices: dict[str, JointChoice], *, source: str) -> dict[str, JointDynamics]:
    """Damping, friction and stiffness of every movable joint from the scaled masses and the kinematics at
    ``state`` (output units), shaped by ``choices`` (``docs/design/refine.md``, "Joint dynamics").

    Friction holds the largest gravity load within 5 % of the range around the state (the whole range when
    holding position) and where gravity pushes the part open at :data:`CLOSED_HOLD_FRACTIONS`; a spring gets
    k = max(3 x 1.5 x hold / range, 2 k_g), reference q_s = q - tau_g / k, and friction 10 % of the load.
    """
    prismatic = {j.name for j in ctx.asset.movable_joints() if j.type == "prismatic"}
    rot = ctx.root_rotation
    loads = physics.joint_loads(ctx.session, ctx.asset, links, state, scale, ctx.subtrees, root_rotation=rot)
    out: dict[str, JointDynamics] = {}
    for j in ctx.asset.movable_joints():
        name = j.name
        ch = choices.get(name, JointChoice())
        cs = ctx.closed[name]
        unit = scale if name in prismatic else 1.0
        if ch.holds_position:
            fr = np.linspace(0.0, 1.0, 11)
        else:
            f0 = cs.fraction(state[name] / unit)
            fr = np.clip([f0 - 0.05, f0, f0 + 0.05], 0.0, 1.0)
        hold = 0.0
        for f in fr:
            st = {**state, name: cs.position(float(f)) * unit}
            ld = physics.joint_loads(ctx.session, ctx.asset, links, st, scale, {name: ctx.subtrees[name]}, root_rotation=rot)
            hold = max(hold, abs(ld[name].gravity_load))
        # a part stays shut once closed: friction also holds a load pushing it open near its closed end
        for f in CLOSED_HOLD_FRACTIONS:
            st = {**state, name: cs.position(float(f)) * unit}
            ld = physics.joint_loads(ctx.session, ctx.asset, links, st, scale, {name: ctx.subtrees[name]}, root_rotation=rot)
            if ld[name].gravity_load * cs.direction > 0:
                hold = max(hold, abs(ld[name].gravity_load))
        spring = None
        if ch.spring:
            load = loads[name]
            k = max(3.0 * physics.HOLD_SAFETY * max(hold, 1e-6) / max(cs.open_range * unit, 1e-6), load.gravity_stiffness * 2.0)
            ref = float(np.clip(state[name] - load.gravity_load / k, cs.lower * unit, cs.upper * unit))
            spring = (k, ref)
            hold = 0.1 * hold  # the spring carries the load; friction only adds feel
        out[name] = physics.joint_dynamics(loads[name], hold, prismatic=name in prismatic, damping_level=ch.damping_level, stiff=ch.stiff,
                                           free_moving=ch.free_moving, spring=spring, source=source)
    return out


#: Opening fractions near the closed end where friction also holds a joint gravity pushes open (probes release at <= 0.10).
CLOSED_HOLD_FRACTIONS = (0.0, 0.05, 0.10)


def band_intervals(bands: dict[str, str], intervals: dict[str, tuple[float, float]] | None = None) -> dict[str, tuple[float, float]]:
    """Allowed opening-fraction interval per joint for its band; ``intervals`` (asked numbers or ends) win."""
    out = {name: BAND_INTERVAL[b] for name, b in bands.items()}
    out.update(intervals or {})
    return out
