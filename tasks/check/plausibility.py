"""Every declared value of one asset judged against the product's estimates, and the physics a patch writes:
the declared value where plausible, the estimate where implausible or not declared (``docs/guide/audit.md``).

Estimates are made at the size the file declares (scale 1): the geometry's mass, inertia and center of mass
for the part's material (:func:`asset2sim.tasks.synthesize.physics.link_physics`), joint dynamics from the
loads of the patched masses (:func:`asset2sim.tasks.synthesize.joint_dynamics.joint_dynamics_for`), operating
forces from ``operating_forces.yaml``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from asset2sim.engines.base import SimSession
from asset2sim.schemas.audit import ValueVerdict
from asset2sim.schemas.overlay import EstimatorInfo, Inertia, JointDynamics, LinkPhysics, Overlay, RootMount
from asset2sim.tasks.check import plausibility_bands as bands
from asset2sim.tasks.check.contact_points import off_axis
from asset2sim.tasks.ingest.mesh_checks import box_corners
from asset2sim.tasks.interpret import operating_forces
from asset2sim.tasks.ingest.declared import DeclaredJoint, DeclaredLink, DeclaredPhysics
from asset2sim.tasks.interpret import size_priors
from asset2sim.tasks.interpret.part_labels import canonical_label
from asset2sim.tasks.synthesize import physics
from asset2sim.tasks.synthesize.context import EstimationContext
from asset2sim.tasks.synthesize.estimate import link_material, plausible_mass_range
from asset2sim.tasks.synthesize.joint_dynamics import JointChoice, joint_dynamics_for
from asset2sim.tasks.synthesize.validate_overlay import geometry_inertia, solid_volume

__all__ = ["Judgement", "judge"]


@dataclass(frozen=True)
class Judgement:
    """The verdicts on one asset and the two sets of physics they imply: ``declared`` (what a simulator loading
    the file uses; estimates only where the file leaves a value to nobody) and ``patched``."""

    values: list[ValueVerdict]
    declared: Overlay
    patched: Overlay
    notes: list[str] = field(default_factory=list)


def joint_unit(jtype: str, what: str) -> str:
    """The unit of a joint's ``what`` (``damping``, ``friction``, ``stiffness``, ``position``) for a joint of type
    ``jtype`` (prismatic: linear; else rotational)."""
    units = {"damping": ("N*m*s/rad", "N*s/m"), "friction": ("N*m", "N"), "stiffness": ("N*m/rad", "N/m"),
             "position": ("rad", "m")}
    return units[what][jtype == "prismatic"]


def _link_physics(mass: float, inertia: np.ndarray, com: np.ndarray, source: str, material: str = "") -> LinkPhysics:
    return LinkPhysics(mass=float(mass), inertia=Inertia.from_matrix(inertia), com=tuple(float(c) for c in com), material=material,
                       source=source)


def _judge_link(ctx: EstimationContext, dl: DeclaredLink, label: str | None, out: list[ValueVerdict]) -> tuple[LinkPhysics, LinkPhysics] | None:
    """Verdicts on one link (appended to ``out``); (declared physics, patched physics), None without geometry."""
    geom = ctx.geometry.get(dl.name)
    if geom is None:
        return None
    where = f"link {dl.name}"
    mat = link_material(ctx, label, dl.name)
    est = physics.link_physics(geom, 1.0, mat, source="audit estimate")
    vol = solid_volume(geom, 1.0)
    alternatives = ([vol * mat.density] if vol else []) + ([geom.area * mat.wall_thickness * mat.density] if mat.shell else [])
    what = f"{mat.name} ({label or 'unlabelled part'})"
    mass_v = bands.mass_verdict(where, dl.mass, est.mass, alternatives, what)
    out.append(mass_v)
    density_ok = True
    if vol and dl.mass is not None:
        direct = dl.how == "inferred" and dl.density is not None
        dens_v = bands.density_verdict(where, dl.density if direct else dl.mass / vol, mat.name, mat.density, direct)
        out.append(dens_v)
        density_ok = dens_v.verdict == "plausible"
    per_kg = [np.asarray(geom.inertia_shell, float), np.asarray(geom.inertia_solid, float)]
    inertia_v = bands.inertia_verdict(where, dl.inertia, dl.mass, per_kg, dl.written_moments)
    com_v = bands.com_verdict(where, dl.com, np.asarray(geom.bbox_min), np.asarray(geom.bbox_max), np.asarray(geom.com))
    out += [inertia_v, com_v]
    keep_mass = mass_v.verdict == "plausible" and density_ok
    mass = dl.mass if keep_mass else est.mass
    if inertia_v.verdict == "plausible" and dl.inertia is not None and dl.mass:
        inertia = np.asarray(dl.inertia, float) * (mass / dl.mass)
    else:
        inertia = geometry_inertia(geom, mass, 1.0, (est.hollow_fraction or 0.0) < 0.999)
    com = np.asarray(dl.com, float) if com_v.verdict == "plausible" and dl.com is not None else np.asarray(est.com, float)
    if not keep_mass:
        mass_v.patched = float(mass)
    if not keep_mass or inertia_v.verdict != "plausible":
        inertia_v.patched = float(np.trace(inertia))
    if com_v.verdict != "plausible":
        com_v.patched = float(np.linalg.norm(com - np.asarray(geom.com)))
    patched = _link_physics(mass, inertia, com, "audit: " + ("declared" if keep_mass else "estimate"), mat.name)
    if dl.mass is None:
        declared = _link_physics(est.mass, est.inertia.matrix(), np.asarray(est.com), "not declared: the product's estimate", mat.name)
    else:
        tensor = np.asarray(dl.inertia if dl.inertia is not None else np.zeros((3, 3)), float)
        declared = _link_physics(dl.mass, tensor, np.asarray(dl.com if dl.com is not None else est.com), f"declared ({dl.how})", mat.name)
    return declared, patched


def _operable(ctx: EstimationContext, j: DeclaredJoint, label: str | None) -> float | None:
    """The highest force (N, prismatic) or torque (N*m, revolute) a hand operates the part with."""
    rng, _ = operating_forces.operating_range(ctx.category, label)
    if j.type == "prismatic":
        return rng.force_n[1] if rng.force_n else None
    if rng.torque_nm:
        return rng.torque_nm[1]
    geom = ctx.geometry.get(j.child)
    if not rng.force_n or geom is None:
        return None
    # the lever a hand pushing the part's far edge has: the largest distance (m) of the child link's geometry box
    # corners from the joint axis (through the child link frame's origin)
    axis = np.asarray(ctx.asset.joint(j.name).axis, float)
    axis = axis / max(np.linalg.norm(axis), 1e-12)
    lever = float(off_axis(box_corners(np.asarray(geom.bbox_min, float), np.asarray(geom.bbox_max, float)), 0.0, axis).max())
    return rng.force_n[1] * lever if lever > 0 else None


def _judge_joints(ctx: EstimationContext, kin: SimSession, dp: DeclaredPhysics, labels: dict[str, str | None],
                  links: dict[str, LinkPhysics], out: list[ValueVerdict]) -> tuple[dict[str, JointDynamics], dict[str, JointDynamics]]:
    state = ctx.closed_state()
    loads = physics.joint_loads(kin, links, state, 1.0, ctx.subtrees)
    choices = {n: JointChoice(spring=bool(j.stiffness)) for n, j in dp.joints.items()}
    est = joint_dynamics_for(ctx, kin, links, state, 1.0, choices, source="audit estimate")
    largest = float(np.max(ctx.closed_extents))
    declared, patched = {}, {}
    w0 = 2.0 * math.pi * physics.FLOOR_FREQUENCY_HZ
    for name, j in dp.joints.items():
        if name not in loads or name not in est:
            continue
        where, ld, e = f"joint {name}", loads[name], est[name]
        k = float(j.stiffness or 0.0)
        du = joint_unit(j.type, "damping")
        operable = _operable(ctx, j, labels.get(j.child))
        travel = (j.upper - j.lower) if j.lower is not None and j.upper is not None else 2 * math.pi
        c_op = bands.operating_damping(operable, travel)
        damping = 0.0 if j.damping is None else j.damping  # what simulators use when the file gives none
        friction = 0.0 if j.friction is None else j.friction
        if k > 0:
            c_est = physics.damping_for(ld, physics.DAMPING_RATIO["moderate"], k)
            damp_v = bands.spring_damping_verdict(where, damping, ld.inertia_axis, k, c_est, du, c_op)
        else:
            k_eff = max(ld.gravity_stiffness, ld.inertia_axis * w0 * w0)
            damp_v = bands.damping_verdict(where, damping, ld.inertia_axis, k_eff, e.damping, friction, du, c_op)
        fric_v = bands.friction_verdict(where, friction, e.friction, operable, joint_unit(j.type, "friction"))
        for v, given in ((damp_v, j.damping), (fric_v, j.friction)):
            if given is None:
                v.reason = "not declared (simulators take 0); " + v.reason
        out += [damp_v, fric_v]
        if k > 0:
            ref = float(j.reference or 0.0)
            ends = [v for v in (j.lower, j.upper) if v is not None]
            far = max(ends, key=lambda v: abs(v - ref), default=ref)
            travel = abs(far - ref)
            weight = physics.joint_loads(kin, links, {**state, name: far}, 1.0,
                                         {name: ctx.subtrees[name]})[name].gravity_load
            carried = abs(weight) if weight * (ref - far) < 0 else 0.0  # the spring pulls against the weight there
            out.append(bands.stiffness_verdict(where, k, travel, operable, joint_unit(j.type, "stiffness"), carried))
        out.append(bands.limits_verdict(where, j.type, j.lower, j.upper, largest))
        c = damping if damp_v.verdict == "plausible" else (c_est if k > 0 else e.damping)
        f = friction if fric_v.verdict == "plausible" else e.friction
        if damp_v.verdict != "plausible":
            damp_v.patched = float(c)
        if fric_v.verdict != "plausible":
            fric_v.patched = float(f)
        spring = {"stiffness": k, "spring_reference": ref} if k > 0 else {}
        declared[name] = JointDynamics(damping=float(damping), friction=float(friction), inertia_axis=ld.inertia_axis,
                                       source="declared", **spring)
        patched[name] = JointDynamics(damping=float(c), friction=float(f), inertia_axis=ld.inertia_axis, source="audit", **spring)
    return declared, patched


def judge(ctx: EstimationContext, kin: SimSession, dp: DeclaredPhysics, mounting: RootMount) -> Judgement:
    """Judge every declared value of ``dp`` (the asset of ``ctx``, at scale 1; part labels those of ``ctx.asset``:
    ``semantics.txt``'s, else read from the link names by the context builder); ``kin``, the input's kinematics
    session, is posed for the joints' loads.

    Returns:
        :class:`Judgement`: the verdicts in the order scale, then per link (mass, density, inertia, center of
        mass), then per movable joint (damping, friction, stiffness, limits); the declared and patched
        overlays (scale 1, ``mounting`` as given) the simulation checks load.
    """
    labels = {ln.name: canonical_label(ln.semantic_label) for ln in ctx.asset.links}
    values: list[ValueVerdict] = []
    typical = size_priors.plausible_largest_dimension(ctx.category).typical  # refine keeps a real size by the same rule
    values.append(bands.scale_verdict(float(np.max(ctx.closed_extents)), typical, ctx.category))
    declared_links, patched_links = {}, {}
    for name, dl in dp.links.items():
        pair = _judge_link(ctx, dl, labels.get(name), values)
        if pair is not None:
            declared_links[name], patched_links[name] = pair
    masses = [dl.mass for n, dl in dp.links.items() if n in declared_links]
    lo, hi = plausible_mass_range(ctx, 1.0)
    values.insert(1, bands.total_mass_verdict(float(sum(masses)) if masses and None not in masses else None, lo, hi, ctx.category))
    notes = (["the object's size is implausible for its category: every value is judged at the size the file declares, and "
              "the patch keeps that size (asset2sim refine rescales)"] if values[0].verdict == "implausible" else [])
    declared_joints, patched_joints = _judge_joints(ctx, kin, dp, labels, patched_links, values)
    info = EstimatorInfo(name="audit")

    def overlay(links, joints) -> Overlay:
        return Overlay(estimator=info, scale=1.0, category=ctx.category, links=links, joints=joints, mounting=mounting)

    return Judgement(values=values, declared=overlay(declared_links, declared_joints), patched=overlay(patched_links, patched_joints),
                     notes=notes)
