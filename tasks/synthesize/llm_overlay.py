"""A model's reply turned into an overlay: the reply is a prior, not the answer.
The model's scale, materials, bands and qualitative dynamics go through the
same physics and validator as the offline estimator
(``docs/design/model_backends.md``)."""

from __future__ import annotations

from dataclasses import dataclass

from asset2sim import __version__
from asset2sim.models.errors import ReplyInvalid
from asset2sim.models.usage import Usage
from asset2sim.schemas.model_reply import ModelReply
from asset2sim.schemas.overlay import ContactMaterial, EstimatorInfo, LinkPhysics, Overlay, ValidationNotes
from asset2sim.tasks.interpret.part_priors import material_for
from asset2sim.tasks.synthesize import estimate, joint_dynamics, physics, request_apply, validate_overlay
from asset2sim.engines.base import SimSession
from asset2sim.tasks.synthesize.context import EstimationContext
from asset2sim.tasks.synthesize.estimator import Estimate

MASS_AGREEMENT = 3.0
"""Largest factor between the geometric total mass and the model's own
estimate before the links are rescaled to the nearer bound (dimensionless)."""


def check_reply_names(ctx: EstimationContext, reply: ModelReply) -> list[str]:
    """Problems with the names in a reply: unknown or duplicated links and joints."""
    movable = {j.name for j in ctx.asset.movable_joints()}
    return (_name_errors("links.{}.link", [lr.link for lr in reply.links], {ln.name for ln in ctx.asset.links},
                         f"is not a link of the asset; links are {sorted(ctx.geometry)}")
            + _name_errors("joints.{}.joint", [jr.joint for jr in reply.joints], movable,
                           f"is not a movable joint of the asset; movable joints are {sorted(movable)}"))


def _name_errors(where: str, names: list[str], known: set[str], unknown: str) -> list[str]:
    """One error per name not in ``known`` (``unknown`` says why) and per repeated name; ``where`` has a slot for the index."""
    return [f"{where.format(i)}: {n!r} " + (unknown if n not in known else "appears twice")
            for i, n in enumerate(names) if n not in known or n in names[:i]]


def overlay_from_reply(ctx: EstimationContext, kin: SimSession, reply: ModelReply, *, name: str = "llm",
                       model: str | None = None) -> Estimate:
    """The overlay, band per movable joint and notes from a model reply, validated; links and joints the reply
    misses get the offline prior's material and the parser's band and words (noted). No usage info yet. ``kin``,
    the input's kinematics session, is posed for the joints' loads.

    Raises:
        ReplyInvalid: unknown or duplicated names, a link without a computable mass, a rejected overlay.
    """
    if errors := check_reply_names(ctx, reply):
        raise ReplyInvalid(errors)
    s = float(reply.scale.value)
    by_link = {lr.link: lr for lr in reply.links}
    read = _link_physics(ctx, by_link, s)
    notes = [f"the model gave no material for {read.missing}; offline priors used"] if read.missing else []
    links, mass_note = _within_model_mass(read.links, by_link)
    bands, band_notes = _bands(ctx, kin, reply)
    notes += band_notes
    state = estimate.state_from_bands(ctx.closed, bands, s, ctx.prismatic)
    joints = joint_dynamics.joint_dynamics_for(ctx, kin, links, state, s, _joint_choices(ctx, reply), source=f"{name} physics (model choices)")
    asked_state = bool(ctx.request.joint_states) or any(b != "closed" for b in bands.values())
    if reply.category.strip().lower() != str(ctx.category).lower():
        notes.append(f"the model calls it {reply.category!r}; the pipeline's category {ctx.category!r} is kept")
    overlay = Overlay(
        estimator=EstimatorInfo(name=name, model=model, version=__version__), scale=s, category=ctx.category,
        contact_material=ContactMaterial(lateral_friction=reply.lateral_friction, restitution=reply.restitution, note=f"model ({name})"),
        links=links, joints=joints, initial_joint_positions=state if asked_state else None,
        notes=ValidationNotes(
            size=f"model: s = {s:.4g} +- {reply.scale.std:.3g}; {reply.notes.size}",
            material="; ".join(read.material_notes) + (f" | model: {reply.notes.material}" if reply.notes.material else ""),
            mass_arithmetic=mass_note + (f" | model: {reply.notes.mass_arithmetic}" if reply.notes.mass_arithmetic else ""),
            other=[f"category: {ctx.category} ({ctx.category_reason})", "bands (model): " + ", ".join(f"{k}={v}" for k, v in bands.items())] + notes,
        ),
    )
    try:
        validate_overlay.validate_overlay(overlay, ctx.asset, ctx.geometry)
    except validate_overlay.OverlayInvalid as exc:
        raise ReplyInvalid(exc.errors) from None
    return Estimate(overlay, bands, notes)


@dataclass(frozen=True, slots=True)
class _ReplyLinks:
    """The links' physics from a reply (:func:`_link_physics`): ``links`` (link -> physics), ``material_notes``
    (one line per link) and ``missing`` (the links the reply has no entry for)."""

    links: dict[str, LinkPhysics]
    material_notes: list[str]
    missing: list[str]


def _link_physics(ctx: EstimationContext, by_link: dict, s: float) -> _ReplyLinks:
    """The links at scale ``s``: geometry with the model's material, else the offline prior's; ReplyInvalid for a
    link whose mass cannot be computed."""
    links: dict[str, LinkPhysics] = {}
    mat_notes, missing, errors = [], [], []
    for ln in ctx.asset.links:
        if (geom := ctx.geometry.get(ln.name)) is None:
            continue
        lr = by_link.get(ln.name)
        if lr is None:
            mat = physics.material_choice(material_for(ctx.category, ln.semantic_label))
            missing.append(ln.name)
        else:
            mat = physics.MaterialChoice(name=lr.material, density=lr.density, shell=lr.shell, wall_thickness=lr.wall_thickness)
        try:
            links[ln.name] = physics.link_physics(geom, s, mat, source=f"geometry + {mat.name} "
                                                  + ("(offline prior; no model entry)" if lr is None else "(model)"))
        except ValueError as exc:
            errors.append(f"links: {exc}")
            continue
        mat_notes.append(f"{ln.name}: {mat.describe()}")
    if errors:
        raise ReplyInvalid(errors)
    return _ReplyLinks(links, mat_notes, missing)


def _within_model_mass(links: dict[str, LinkPhysics], by_link: dict) -> tuple[dict[str, LinkPhysics], str]:
    """The links scaled to within :data:`MASS_AGREEMENT` of the model's own mass estimate for the links it
    names (unchanged when within), and the mass arithmetic note (kg)."""
    geo_total = sum(lp.mass for lp in links.values())
    model_total = sum(by_link[n].mass.value for n in links if n in by_link)
    geo_known = sum(links[n].mass for n in links if n in by_link)
    mass_note = " + ".join(f"{lp.mass:.4g}" for lp in links.values()) + f" = {geo_total:.4g} kg from the geometry (m = v*rho*s^3*eta)"
    if model_total > 0 and geo_known > 0:
        ratio = geo_known / model_total
        mass_note += f"; the model estimated {model_total:.4g} kg for those links (ratio {ratio:.3g})"
        if ratio > MASS_AGREEMENT or ratio < 1.0 / MASS_AGREEMENT:
            f = model_total * (MASS_AGREEMENT if ratio > MASS_AGREEMENT else 1.0 / MASS_AGREEMENT) / geo_known
            links = {n: request_apply.scaled_link(lp, f, f"; x{f:.3g} to within {MASS_AGREEMENT:g}x of the model's mass estimate") for n, lp in links.items()}
            mass_note += f"; more than {MASS_AGREEMENT:g}x apart: every link scaled by {f:.3g}"
    return links, mass_note


def _bands(ctx: EstimationContext, kin: SimSession, reply: ModelReply) -> tuple[dict[str, str], list[str]]:
    """The model's band per movable joint (the request parser's without a model entry), and notes where
    the two differ or the model gave none."""
    parsed, _ = estimate.requested_bands(ctx, kin)
    by_joint = {jr.joint: jr for jr in reply.joints}
    bands: dict[str, str] = {}
    notes = []
    for j in ctx.asset.movable_joints():
        jr, read = by_joint.get(j.name), parsed.get(j.name, "closed")
        bands[j.name] = jr.band if jr is not None else read
        if jr is None:
            notes.append(f"{j.name}: no model entry; the request parser's band {read!r} and dynamics words used")
        elif jr.band != read:
            notes.append(f"{j.name}: the model chose band {jr.band!r}, the request parser read {read!r}; the model's band used")
    return bands, notes


def _joint_choices(ctx: EstimationContext, reply: ModelReply) -> dict[str, joint_dynamics.JointChoice]:
    """The model's qualitative dynamics per movable joint, with the request's own words about each part kept (they win
    where they speak); without a model entry the words alone (:func:`~asset2sim.tasks.synthesize.joint_dynamics.motion_choices`)."""
    by_joint = {jr.joint: jr for jr in reply.joints}
    parsed, _ = joint_dynamics.motion_choices(ctx, request_apply.task_relevant_joints(ctx))
    # the model's choices, and the request's own words about each part kept: a word wins where it speaks
    return {n: words if (jr := by_joint.get(n)) is None else joint_dynamics.JointChoice(
        words.damping_level if any(w.kind in joint_dynamics.WORD_DAMPING for w in words.words) else jr.damping_level,
        jr.holds_position or words.holds_position, jr.spring or words.spring, jr.stiff or words.stiff,
        jr.free_moving or words.free_moving, words.self_closing, words.words) for n, words in parsed.items()}


def estimator_info(name: str, model: str, usage: Usage) -> EstimatorInfo:
    """The overlay's estimator record: name, model, package version and what ``usage`` cost."""
    return EstimatorInfo(name=name, model=model, version=__version__, queries=usage.calls, tokens=usage.total_tokens,
                         cost_usd=usage.cost_usd, seconds=round(usage.seconds, 3))
