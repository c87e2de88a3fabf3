"""The offline estimator (the default; needs no network): physical priors
(data with sources) + geometry + kinematics; registered as ``offline``."""

from __future__ import annotations

from dataclasses import replace

from asset2sim import __version__
from asset2sim.schemas.overlay import ContactMaterial, EstimatorInfo, LinkPhysics, Overlay, ValidationNotes
from asset2sim.tasks.interpret.part_priors import material_for
from asset2sim.tasks.synthesize import physics, request_apply
from asset2sim.engines.base import SimSession
from asset2sim.tasks.synthesize.context import EstimationContext
from asset2sim.tasks.synthesize.estimate import choose_scale, link_material, plausible_mass_range, request_variant, state_from_bands
from asset2sim.tasks.synthesize.joint_dynamics import joint_dynamics_for, motion_choices
from asset2sim.tasks.synthesize.estimator import Estimate, register_estimator

__all__ = ["OfflineEstimator"]


class OfflineEstimator:
    """Physical priors (data with sources) + geometry + kinematics; no network."""

    name = "offline"

    def __init__(self, **settings):
        """``settings`` (a ``model``, a ``base_url``) are accepted and unused: no model is asked."""

    def estimate(self, ctx: EstimationContext, kin: SimSession) -> Estimate:
        """The overlay from priors, geometry and kinematics (``kin``: the input's kinematics session, posed
        for ordinals, ends and the joints' loads), and the parsed request's bands (:func:`requested_bands`)."""
        s, size_note = choose_scale(ctx)
        # ---- links
        links: dict[str, LinkPhysics] = {}
        mat_notes = []
        for ln in ctx.asset.links:
            if (geom := ctx.geometry.get(ln.name)) is None:
                continue
            mat = link_material(ctx, ln.semantic_label, ln.name)
            links[ln.name] = physics.link_physics(geom, s, mat, source=f"geometry + {mat.name} prior")
            mat_notes.append(f"{ln.name} ({ln.semantic_label or 'unlabelled'}): {mat.describe()}")
        total = sum(lp.mass for lp in links.values())
        mass_note = " + ".join(f"{lp.mass:.4g}" for lp in links.values()) + f" = {total:.4g} kg"
        lo, hi = plausible_mass_range(ctx, s)
        asked = request_apply.apply_masses(ctx, links, (lo, hi))
        links = asked.links
        if asked.notes:
            total = sum(lp.mass for lp in links.values())
            mass_note += "; request: " + "; ".join(asked.notes) + f"; total {total:.4g} kg"
        if total > 0 and not asked.total_asked and (total < lo or total > hi):
            # into the plausible range, a margin inside its ends (10 %)
            target = lo * 1.1 if total < lo else hi * 0.9
            f = target / total
            links = {name: request_apply.scaled_link(lp, f, f"; x{f:.3g} to the category's plausible total mass")
                     for name, lp in links.items()}
            mass_note += f"; outside the plausible {lo:g}-{hi:g} kg for {ctx.category} ({ctx.request.size_class or 'regular'}): every link scaled by {f:.3g} to {target:g} kg"
        # ---- state
        prismatic = ctx.prismatic
        resolved = request_apply.resolve_states(ctx, kin, s)
        bands, band_notes = resolved.bands, resolved.warnings + resolved.notes + request_apply.unmatched_properties(ctx)
        state = state_from_bands(ctx.closed, bands, s, prismatic)  # then every resolved target's position
        state.update({n: ctx.closed[n].position(t.fraction) * (s if n in prismatic else 1.0)
                      for n, t in resolved.targets.items()})
        # ---- dynamics
        relevant = request_apply.task_relevant_joints(ctx)
        choices, _ = motion_choices(ctx, relevant)
        choices = {n: replace(c, state_asked=n in resolved.addressed) if c.free_moving else c for n, c in choices.items()}
        joints = joint_dynamics_for(ctx, kin, links, state, s, choices, source="offline physics")
        joints, dyn_notes = request_apply.apply_dynamics_values(ctx, joints, relevant, state)
        band_notes += dyn_notes
        body_prior = material_for(ctx.category, None, request_variant(ctx))
        asked_state = bool(ctx.request.joint_states)
        overlay = Overlay(
            estimator=EstimatorInfo(name=self.name, model=None, version=__version__, queries=0), scale=s, category=ctx.category,
            contact_material=ContactMaterial(lateral_friction=float(body_prior.lateral_friction), restitution=float(body_prior.restitution),
                                             note=f"{body_prior.name}: {body_prior.friction_source}"),
            links=links, joints=joints, initial_joint_positions=state if asked_state else None,
            notes=ValidationNotes(
                size=size_note, material="; ".join(mat_notes), mass_arithmetic=mass_note,
                other=[f"category: {ctx.category} ({ctx.category_reason})"]
                + [w.strip() for w in size_note.split(";") if w.strip().startswith("WARNING:")]
                + ["requested bands: " + ", ".join(f"{k}={v}" for k, v in bands.items())]
                + band_notes
                + ([] if asked_state else ["the request asks for no state: every joint starts at its geometric closed end"
                                       + (", a part asked to move freely where its weight leaves it" if ctx.request.free_moving else "")]),
            ),
        )
        return Estimate(overlay=overlay, bands=bands, notes=band_notes, targets=resolved.targets)


register_estimator("offline", OfflineEstimator)
