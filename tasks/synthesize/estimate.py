"""Overlay synthesis (SPEC stage 2): the estimator protocol, its registry, and
the offline estimator (the default; needs no network).

An estimator turns an :class:`~asset2sim.tasks.synthesize.context.EstimationContext`
(the extracted asset, its mesh analysis, the parsed request, the recognised
category and the geometric closed states; built by
:func:`asset2sim.tasks.synthesize.context.build_context`) into an
:class:`Estimate`: the :class:`~asset2sim.schemas.overlay.Overlay` and the
state band of every movable joint. Whatever produced it, the overlay is then
validated mechanically (:mod:`asset2sim.tasks.synthesize.validate_overlay`).

The offline estimator's knowledge is per category, per part label and per
word of the request (``asset2sim/priors/*.yaml`` through
:mod:`asset2sim.tasks.interpret.priors`); the physics is in :mod:`asset2sim.tasks.synthesize.physics`.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass, field
from typing import Callable, Protocol

import numpy as np

from asset2sim import __version__
from asset2sim.schemas.overlay import (
    ContactMaterial,
    EstimatorInfo,
    JointDynamics,
    LinkPhysics,
    Overlay,
    ValidationNotes,
)
from asset2sim.schemas.request import BAND_INTERVAL, BAND_TARGET
from asset2sim.tasks.geometry.closed_state import ClosedState
from asset2sim.tasks.interpret import priors, request_apply
from asset2sim.tasks.synthesize import physics
from asset2sim.tasks.synthesize.context import EstimationContext


@dataclass
class Estimate:
    """What an estimator returns: the overlay, the state band it chose for
    every movable joint, and notes on how it read the request.

    ``bands``: joint name -> band name (:data:`asset2sim.schemas.request.BAND_TARGET`),
    every movable joint present; the refine stage turns them into the
    requested state (:func:`state_from_bands`) and the allowed intervals of
    the state search (:func:`band_intervals`).
    """

    overlay: Overlay
    bands: dict[str, str]
    notes: list[str] = field(default_factory=list)
    targets: dict[str, request_apply.JointTarget] = field(default_factory=dict)
    """joint -> a number or end the request asked ("30 degrees", "lever up"),
    resolved (:mod:`asset2sim.tasks.interpret.request_apply`); its interval
    replaces the band's in the state search."""


class Estimator(Protocol):
    """Produces an overlay from a context."""

    name: str

    def estimate(self, ctx: EstimationContext) -> Estimate:
        """Return the overlay (validated afterwards by the caller) and the bands."""


_REGISTRY: dict[str, Callable[..., Estimator]] = {}


def register_estimator(name: str, factory: Callable[..., Estimator]) -> None:
    """Register ``factory(**settings) -> Estimator`` under ``name``."""
    _REGISTRY[name] = factory


def get_estimator(name: str, **settings) -> Estimator:
    """Instantiate the estimator registered as ``name``.

    Raises:
        KeyError: unknown name (the message lists the known ones).
    """
    if name not in _REGISTRY:
        # model backends register on import (litellm itself is imported only when a client is made)
        importlib.import_module("asset2sim.tasks.synthesize.llm_estimator")
    if name not in _REGISTRY:
        raise KeyError(f"unknown estimator {name!r}; known: {sorted(_REGISTRY)}")
    return _REGISTRY[name](**settings)


# --------------------------------------------------------------------- helpers
def task_relevant_joints(ctx: EstimationContext) -> list[str]:
    """Movable joints whose moving part is what tasks manipulate (lid, door,
    drawer, screen ...; ``priors.part_role`` == "task"), ordered by the
    category's priority; every non-accessory movable joint when none
    qualifies, and all movable joints when even that is empty
    (:func:`asset2sim.tasks.interpret.request_apply.task_relevant_joints`)."""
    return request_apply.task_relevant_joints(ctx)


def requested_bands(ctx: EstimationContext, scale: float | None = None) -> tuple[dict[str, str], list[str]]:
    """Band per movable joint from the request (joint -> band name), and notes
    (warnings first): :func:`asset2sim.tasks.interpret.request_apply.resolve_states`
    at ``scale`` (default :func:`choose_scale`). Joints not addressed are closed."""
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
    """Uniform scale s so that the closed object's extents match the target
    real-world dimensions (``priors.target_size``: the category's or the named
    variant's typical dimensions times the request's size factor).

    s is the geometric mean of the ratios of the two largest sorted dimensions
    (the smallest is the least reliable: thickness of lids, screens); a
    handheld category is then capped so that at least two dimensions fit a
    parallel gripper (second-largest <= ``priors.GRASPABLE_WIDTH_M``). Sizes in
    numbers ("30 cm tall") decide alone
    (:func:`asset2sim.tasks.interpret.request_apply.scale_from_sizes`).
    """
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
    return s, note


def plausible_mass_range(ctx: EstimationContext, scale: float) -> tuple[float, float]:
    """Plausible total mass (kg) for the object *as sized*: the category's (or
    the named variant's) regular mass range scaled to the actual size factor
    f = geometric mean of (scaled closed extents / regular dims) over the two
    largest dimensions (``priors.scale_mass_range``: f^2..f^3)."""
    target = priors.target_size(ctx.category, ctx.request)
    cat = priors.category_prior(ctx.category)
    var = cat.variant(target.variant) if target.variant else None
    base_lo, base_hi = var.mass_range if var is not None else cat.mass_range
    base = np.sort(np.asarray(target.base_dims, float))[::-1]
    actual = np.sort(np.asarray(ctx.closed_extents, float) * scale)[::-1]
    f = float(np.exp(np.mean(np.log(np.maximum(actual[:2], 1e-9) / base[:2]))))
    return priors.scale_mass_range(base_lo, base_hi, f)


def _variant(ctx: EstimationContext) -> str | None:
    v = priors.find_variant(ctx.category, ctx.request.text) if ctx.request.text else None
    return v.name if v is not None else None


def _material(ctx: EstimationContext, label: str | None, link: str | None = None) -> physics.MaterialChoice:
    m = (request_apply.requested_material(ctx, link) if link is not None else None) or priors.material_for(ctx.category, label, _variant(ctx))
    return physics.MaterialChoice(
        name=m.name,
        density=float(m.density),
        shell=bool(m.shell),
        wall_thickness=float(m.wall_thickness),
        source=m.source,
    )


@dataclass
class JointChoice:
    """Qualitative dynamics choices for one joint (from request words, priors
    or a model reply); :func:`joint_dynamics_for` turns them into numbers."""

    damping_level: str = "moderate"
    holds_position: bool = False
    spring: bool = False
    stiff: bool = False
    free_moving: bool = False


def joint_dynamics_for(
    ctx: EstimationContext,
    links: dict[str, LinkPhysics],
    state: dict[str, float],
    scale: float,
    choices: dict[str, JointChoice],
    *,
    source: str,
) -> dict[str, JointDynamics]:
    """Damping, friction and stiffness of every movable joint from the scaled
    masses and the kinematics at ``state`` (output units), shaped by the
    qualitative ``choices`` (see ``docs/refine.md``, "Joint dynamics").

    Friction holds the largest gravity load within 5 % of the range around the
    state, or over the whole range when the joint must hold its position, and
    the load at :data:`CLOSED_HOLD_FRACTIONS` where gravity pushes the part
    open there (a closed part stays closed); a
    spring gets k = max(3 x 1.5 x hold / range, 2 k_g) and the reference
    q_s = q - tau_g / k so that it holds the state (equilibrium of
    -k (q - q_s) + tau_g = 0), friction then only 10 % of the load.
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
        # A part stays shut once closed: where gravity pushes it open near its
        # closed end (a lever hanging open), friction holds that too; a load
        # towards the closed end rests on the stop.
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
        out[name] = physics.joint_dynamics(
            loads[name],
            hold,
            prismatic=name in prismatic,
            damping_level=ch.damping_level,
            stiff=ch.stiff,
            free_moving=ch.free_moving,
            spring=spring,
            source=source,
        )
    return out


#: Opening fractions near the closed end where friction also holds a joint
#: that gravity pushes open (:func:`joint_dynamics_from_loads`): a part closed
#: by a hand (the probes release a closed part at f <= 0.10) stays closed.
CLOSED_HOLD_FRACTIONS = (0.0, 0.05, 0.10)


# ------------------------------------------------------------ offline estimator
class OfflineEstimator:
    """Physical priors (data with sources) + geometry + kinematics; no network."""

    name = "offline"

    def __init__(self, **settings):
        self.settings = settings

    def estimate(self, ctx: EstimationContext) -> Estimate:
        """The overlay from priors, geometry and kinematics, and the parsed
        request's bands (:func:`requested_bands`)."""
        s, size_note = choose_scale(ctx)
        # ---- links
        links: dict[str, LinkPhysics] = {}
        mat_notes = []
        for ln in ctx.asset.links:
            geom = ctx.geometry.get(ln.name)
            if geom is None:
                continue
            mat = _material(ctx, ln.semantic_label, ln.name)
            links[ln.name] = physics.link_physics(geom, s, mat, source=f"geometry + {mat.name} prior")
            mat_notes.append(f"{ln.name} ({ln.semantic_label or 'unlabelled'}): {mat.name}, {mat.density:g} kg/m^3, {'shell t=' + format(mat.wall_thickness, 'g') + ' m' if mat.shell else 'solid'}")
        total = sum(lp.mass for lp in links.values())
        mass_note = " + ".join(f"{lp.mass:.4g}" for lp in links.values()) + f" = {total:.4g} kg"
        lo, hi = plausible_mass_range(ctx, s)
        links, req_mass_notes, mass_asked = request_apply.apply_masses(ctx, links, (lo, hi))
        if req_mass_notes:
            total = sum(lp.mass for lp in links.values())
            mass_note += "; request: " + "; ".join(req_mass_notes) + f"; total {total:.4g} kg"
        if total > 0 and not mass_asked and (total < lo or total > hi):
            # into the plausible range, a margin inside its ends (10 %)
            target = lo * 1.1 if total < lo else hi * 0.9
            f = target / total
            for name, lp in list(links.items()):
                links[name] = lp.model_copy(
                    update={
                        "mass": lp.mass * f,
                        "inertia": lp.inertia.model_copy(update={k: getattr(lp.inertia, k) * f for k in ("ixx", "ixy", "ixz", "iyy", "iyz", "izz")}),
                        "source": lp.source + f"; x{f:.3g} to the category's plausible total mass",
                    }
                )
            mass_note += f"; outside the plausible {lo:g}-{hi:g} kg for {ctx.category} ({ctx.request.size_class or 'regular'}): every link scaled by {f:.3g} to {target:g} kg"
        # ---- state
        prismatic = {j.name for j in ctx.asset.movable_joints() if j.type == "prismatic"}
        resolved = request_apply.resolve_states(ctx, s)
        bands, band_notes = resolved.bands, resolved.warnings + resolved.notes + request_apply.unmatched_properties(ctx)
        state = request_apply.state_with_targets(ctx, state_from_bands(ctx.closed, bands, s, prismatic), resolved, s)
        # ---- dynamics
        relevant = set(task_relevant_joints(ctx))
        choices = {}
        for j in ctx.asset.movable_joints():
            rel = j.name in relevant
            label = ctx.asset.link(j.child).semantic_label
            choices[j.name] = JointChoice(
                damping_level=ctx.request.damping if rel else "moderate",
                holds_position=ctx.request.holds_position and rel,
                spring=rel and (ctx.request.spring or priors.spring_expected(ctx.category, label)),
                stiff=ctx.request.stiff and rel,
                free_moving=ctx.request.free_moving and rel,
            )
        joints = joint_dynamics_for(ctx, links, state, s, choices, source="offline physics")
        joints, dyn_notes = request_apply.apply_dynamics_values(ctx, joints, [n for n in task_relevant_joints(ctx)], state)
        band_notes += dyn_notes
        body_prior = priors.material_for(ctx.category, None, _variant(ctx))
        body_mat = _material(ctx, None)
        friction_coeff = float(body_prior.lateral_friction)
        asked_state = bool(ctx.request.joint_states)
        overlay = Overlay(
            estimator=EstimatorInfo(name=self.name, model=None, version=__version__, queries=0),
            scale=s,
            category=ctx.category,
            contact_material=ContactMaterial(
                lateral_friction=friction_coeff,
                restitution=float(body_prior.restitution),
                note=f"{body_mat.name}: {body_prior.friction_source}",
            ),
            links=links,
            joints=joints,
            initial_joint_positions=state if asked_state else None,
            notes=ValidationNotes(
                size=size_note,
                material="; ".join(mat_notes),
                mass_arithmetic=mass_note,
                other=[f"category: {ctx.category} ({ctx.category_reason})"]
                + ["requested bands: " + ", ".join(f"{k}={v}" for k, v in bands.items())]
                + band_notes
                + ([] if asked_state else ["the request asks for no state: every joint starts at its geometric closed end"]),
            ),
        )
        return Estimate(overlay=overlay, bands=bands, notes=band_notes, targets=resolved.targets)


register_estimator("offline", OfflineEstimator)


def band_intervals(bands: dict[str, str], intervals: dict[str, tuple[float, float]] | None = None) -> dict[str, tuple[float, float]]:
    """Allowed opening-fraction interval per joint for its band; ``intervals``
    (a number or end the request asked, :attr:`Estimate.intervals`) win."""
    out = {name: BAND_INTERVAL[b] for name, b in bands.items()}
    out.update(intervals or {})
    return out
