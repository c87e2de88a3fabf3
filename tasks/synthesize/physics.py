"""Physics shared by every estimator: mass and inertia from the scaled geometry,
joint loads from kinematics, joint dynamics from those loads. Formulas (SI):

- mass (SPEC) m = v rho s^3 eta; shell parts eta = min(1, A s^2 t / (v s^3))
  (thin-shell approximation, Roark's Formulas for Stress and Strain, 8th ed.), A/2 for boards (a solid sheet the
  mesh draws with both faces);
- inertia: the geometry's per-kg tensor times m s^2;
- gravity load: tau_g = ((c - p) x M g) . a (revolute), F_g = M g . a (prismatic);
- damping c = 2 zeta sqrt(I k) of I qdd + c qd + k q = 0 (Ogata, System
  Dynamics, 4th ed., ch. 8), k = max(|d tau_g / d q|, spring, I (2 pi f0)^2);
- holding friction f = safety x max |tau_g| over the states to hold; what holds a part when its object is set down
  (the lean, the landings): :mod:`.set_down`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from asset2sim.schemas.asset import LinkGeometry
from asset2sim.schemas.overlay import Inertia, JointDynamics, LinkPhysics
from asset2sim.tasks.synthesize.validate_overlay import geometry_inertia

G = 9.81
"""Standard gravity, m/s^2."""

#: Target damping ratio per requested damping level (dimensionless): underdamped, the textbook 0.7, overdamped.
DAMPING_RATIO = {"low": 0.3, "moderate": 0.7, "high": 1.5}

#: Floor natural frequency f0 (Hz) for joints with no restoring load.
FLOOR_FREQUENCY_HZ = 0.5

#: Safety factor on the gravity load that friction must hold (dimensionless).
HOLD_SAFETY = 1.5


@dataclass
class MaterialChoice:
    """Material of one link as used by :func:`link_physics`."""

    name: str
    density: float
    """kg/m^3"""
    shell: bool
    wall_thickness: float
    """m, real-world wall thickness for shell parts"""
    panel: bool = False
    """a board (``MaterialPrior.panel``)"""

    def describe(self) -> str:
        """``ABS plastic, 1050 kg/m^3, shell t=0.002 m`` (or ``solid``), for the overlay's material notes."""
        return f"{self.name}, {self.density:g} kg/m^3, " + (f"shell t={self.wall_thickness:g} m" if self.shell else "solid")


def material_choice(m) -> MaterialChoice:
    """A prior's material (``MaterialPrior``) as a :class:`MaterialChoice`."""
    return MaterialChoice(name=m.name, density=float(m.density), shell=bool(m.shell), wall_thickness=float(m.wall_thickness),
                          panel=bool(m.panel))


def hollow_fraction(geom: LinkGeometry, scale: float, material: MaterialChoice) -> float | None:
    """eta in m = v rho s^3 eta: 1 solid, min(1, A s^2 t / (v s^3)) shell (A/2 for a board); None for an open shell
    (m = A s^2 t rho)."""
    if "open_shell" in geom.volume_method or geom.volume <= 0.0:  # encloses (almost) nothing: an open bin, a lone plate
        return None
    if not material.shell:
        return 1.0
    v = max(geom.volume * scale**3, 1e-12)
    shell_volume = geom.area / (2 if material.panel else 1) * scale**2 * material.wall_thickness
    return float(min(1.0, max(shell_volume / v, 1e-6)))


def link_physics(geom: LinkGeometry, scale: float, material: MaterialChoice, source: str = "geometry") -> LinkPhysics:
    """Mass (kg), inertia (kg*m^2 about the COM) and COM (m, link frame) of a link from its scale-1
    geometry, the scale and its material (:func:`hollow_fraction`; shell parts take the thin-shell inertia).

    Raises:
        ValueError: non-positive density, or no volume and no area.
    """
    if material.density <= 0:
        raise ValueError(f"link {geom.link!r}: density must be > 0, got {material.density}")
    eta = hollow_fraction(geom, scale, material)
    if eta is None:
        mass = geom.area * scale**2 * material.wall_thickness * material.density
        formula = (
            f"open surface: m = A*s^2*t*rho = {geom.area:.4g} m^2 * {scale:.4g}^2 * {material.wall_thickness:g} m"
            f" * {material.density:g} kg/m^3"
        )
        hollow = True
    else:
        mass = geom.volume * scale**3 * material.density * eta
        formula = f"m = v*rho*s^3*eta = {geom.volume:.4g} m^3 * {material.density:g} kg/m^3 * {scale:.4g}^3 * {eta:.3g}"
        hollow = eta < 0.999
    if not (mass > 0):
        raise ValueError(f"link {geom.link!r}: zero volume and area; cannot compute a mass")
    return LinkPhysics(mass=float(mass), inertia=Inertia.from_matrix(geometry_inertia(geom, mass, scale, hollow)),
                       com=tuple(float(c) * scale for c in geom.com),
                       material=material.name, density=float(material.density), hollow_fraction=None if eta is None else float(eta),
                       source=f"{source}: {formula}")


@dataclass
class JointLoad:
    """Mechanics of one joint's moving subtree at a state: ``mass`` kg; ``inertia_axis`` kg*m^2 or kg;
    ``gravity_load`` N*m or N along the axis (positive pushes q up); ``gravity_stiffness`` |d load / d q|."""

    joint: str
    mass: float
    inertia_axis: float
    gravity_load: float
    gravity_stiffness: float
    lateral_moment: float = 0.0
    """|w_h| of the load per unit gravity w (w . g = ``gravity_load``; kg*m or kg): its part across gravity, which
    a lean of the object turns into load (:func:`lean_load`)."""


def joint_loads(session, links: dict[str, LinkPhysics], state: dict[str, float], scale: float,
                subtrees: dict[str, list[str]], *, root_rotation: np.ndarray | None = None) -> dict[str, JointLoad]:
    """:class:`JointLoad` of every joint of ``subtrees`` at ``state`` (output units). ``session``: a
    fixed-base session of the unscaled input asset, its kinematics scaled by ``scale`` here; ``links``: the
    scaled physics; ``root_rotation`` (3, 3): the resting pose (gravity R^T g in the root frame)."""
    gvec = np.array([0.0, 0.0, -G])
    if root_rotation is not None:
        gvec = np.asarray(root_rotation, float).T @ gvec
    out: dict[str, JointLoad] = {}
    g_hat = gvec / G

    def to_input(st: dict[str, float]) -> dict[str, float]:
        return {n: (v / scale if session.joint_types.get(n) == "prismatic" else v) for n, v in st.items()}

    def load_at(name: str, st: dict[str, float]) -> tuple[float, float, float, float]:
        session.set_joint_positions(to_input(st))
        axis_local = session.joint_axis(name)
        child_pos, child_R = session.link_frame(session.joint_child[name])
        child_pos, axis = child_pos * scale, child_R @ axis_local
        axis = axis / max(np.linalg.norm(axis), 1e-12)
        M, mc, I_axis = 0.0, np.zeros(3), 0.0
        for ln in (ln for ln in subtrees[name] if ln in links):
            lp, (pos, R) = links[ln], session.link_frame(ln)
            c = pos * scale + R @ np.asarray(lp.com, float)
            M += lp.mass
            mc += lp.mass * c
            Iw = R @ lp.inertia.matrix() @ R.T
            r = c - child_pos
            r_perp = r - np.dot(r, axis) * axis
            I_axis += float(axis @ Iw @ axis) + lp.mass * float(r_perp @ r_perp)
        if M <= 0:
            return 0.0, 0.0, 0.0, 0.0
        com = mc / M
        # w: the load per unit gravity, load = w . g ((c - p) x M g . a = M (a x (c - p)) . g)
        prismatic = session.joint_types[name] == "prismatic"
        w = M * axis if prismatic else M * np.cross(axis, com - child_pos)
        lateral = float(np.linalg.norm(w - np.dot(w, g_hat) * g_hat))
        if prismatic:
            return M, M, float(M * np.dot(gvec, axis)), lateral
        return M, I_axis, float(np.dot(np.cross(com - child_pos, M * gvec), axis)), lateral

    for name in [n for n in session.joint_names if n in subtrees]:
        q0 = state.get(name, 0.0)
        prismatic = session.joint_types[name] == "prismatic"
        lo, hi = (x * scale if prismatic else x for x in session.joint_limits[name])
        step = 0.002 if prismatic else 0.02
        M, inertia, load, lateral = load_at(name, state)
        qa = max(q0 - step, lo) if np.isfinite(lo) else q0 - step
        qb = min(q0 + step, hi) if np.isfinite(hi) else q0 + step
        k = abs(load_at(name, {**state, name: qa})[2] - load_at(name, {**state, name: qb})[2]) / (qb - qa) if qb - qa > 0 else 0.0
        out[name] = JointLoad(joint=name, mass=M, inertia_axis=inertia, gravity_load=load, gravity_stiffness=k, lateral_moment=lateral)
    session.set_joint_positions(to_input(state))
    return out


#: Simulator timestep the damping bound is computed for, s (SPEC: 1/240 s).
TIMESTEP = 1.0 / 240.0


def max_stable_damping(inertia_axis: float) -> float:
    """Largest viscous damping (N*m*s/rad or N*s/m) a semi-implicit integrator takes without overshooting
    in one step: c <= I / dt (dt :data:`TIMESTEP`)."""
    return float(max(inertia_axis, 0.0) / TIMESTEP)


#: Largest joint speed Bullet's multibodies allow, rad/s or m/s (``btMultiBody::m_maxCoordinateVelocity`` = 100,
#: bullet3 src/BulletDynamics/Featherstone/btMultiBody.cpp).
MAX_JOINT_SPEED = 100.0
#: Share of the locking bound I v_max / dt that joint friction may take (measured: free at 0.88, locked at
#: 1.06; ``docs/design/metrics.md``).
FRICTION_LOCK_SHARE = 0.8


def max_stable_friction(inertia_axis: float) -> float:
    """Largest joint friction (N*m or N) the engines' friction motor takes without locking the joint:
    FRICTION_LOCK_SHARE * I v_max / dt (I about the axis, kg*m^2, or the moving mass, kg; dt :data:`TIMESTEP`); see
    ``docs/design/metrics.md`` for the measurement."""
    return float(FRICTION_LOCK_SHARE * max(inertia_axis, 0.0) * MAX_JOINT_SPEED / TIMESTEP)


def damping_for(load: JointLoad, zeta: float, stiffness: float = 0.0) -> float:
    """Viscous damping c = 2 zeta sqrt(I k_eff) (N*m*s/rad or N*s/m), with
    k_eff = max(gravity stiffness, spring stiffness, I (2 pi f0)^2), f0 = :data:`FLOOR_FREQUENCY_HZ`."""
    w0 = 2.0 * np.pi * FLOOR_FREQUENCY_HZ
    k_eff = max(load.gravity_stiffness, stiffness, load.inertia_axis * w0 * w0)
    return float(2.0 * zeta * np.sqrt(max(load.inertia_axis, 0.0) * k_eff))


def friction_floor(load: JointLoad, prismatic: bool, free_moving: bool = False) -> float:
    """The least friction of a joint carrying ``load`` (N or N*m): Coulomb coefficient 0.05 on the moving weight
    (prismatic, N; lubricated drawer slides, Engineering ToolBox), that force at a 1 cm pin radius (revolute, N*m); a
    fifth of it for a part asked to move freely."""
    floor = 0.05 * (load.mass * G) * (1.0 if prismatic else 0.01)
    return floor * 0.2 if free_moving else floor


def joint_dynamics(load_at_state: JointLoad, hold_load: float, *, prismatic: bool, damping_level: str = "moderate", stiff: bool = False,
                   free_moving: bool = False, spring: tuple[float, float] | None = None, source: str = "physics",
                   impact: float = 0.0, floor: bool = True, stiff_least: float = 0.0) -> JointDynamics:
    """Damping, friction and stiffness of one joint from its loads.

    Args:
        load_at_state: loads at the initial state (output units).
        hold_load: largest |gravity load| (N*m or N) friction must hold.
        prismatic: joint type (sets units and the friction floor).
        damping_level: "low" | "moderate" | "high" (:data:`DAMPING_RATIO`).
        stiff: a stiff joint is asked for: friction x 2, and x 4 over the floor load, and at least ``stiff_least``.
        free_moving: "moves freely": no extra friction floor.
        spring: (stiffness, reference) when a spring is intended.
        impact: friction (N*m or N) beyond the holding friction that stops the part after its object is set down
            (:func:`~asset2sim.tasks.synthesize.set_down.landing_friction`; 0: none).
        floor: add the friction floor below; False where the mechanism sets its own least friction (a drawer's
            slide, ``joint_dynamics.slide_for``).
        stiff_least: least friction (N*m or N) of a stiff joint, from the hand that operates it
            (:func:`~asset2sim.tasks.synthesize.joint_dynamics.stiff_least`).

    Friction floor: Coulomb coefficient 0.05 on the moving weight (prismatic, N; lubricated drawer slides,
    Engineering ToolBox), that force at a 1 cm pin radius (revolute, N*m). Friction and damping are capped by
    :func:`max_stable_friction` and :func:`max_stable_damping`.
    """
    zeta = DAMPING_RATIO.get(damping_level, DAMPING_RATIO["moderate"])
    k = spring[0] if spring else 0.0
    c = damping_for(load_at_state, zeta, k)
    floor = friction_floor(load_at_state, prismatic, free_moving) if floor else 0.0
    friction = HOLD_SAFETY * abs(hold_load) + floor + max(impact, 0.0)
    if stiff:
        friction = max(friction * 2.0, 4.0 * HOLD_SAFETY * abs(load_at_state.gravity_load) + 4.0 * floor, stiff_least)
        c *= 2.0
    c = min(c, max_stable_damping(load_at_state.inertia_axis))
    if load_at_state.inertia_axis > 0:  # above it the engine's friction motor locks the joint
        friction = min(friction, max_stable_friction(load_at_state.inertia_axis))
    return JointDynamics(
        damping=float(c), friction=float(friction), stiffness=float(k), spring_reference=float(spring[1]) if spring else None,
        inertia_axis=float(load_at_state.inertia_axis),
        source=(
            f"{source}: zeta={zeta} ({damping_level}), I_axis={load_at_state.inertia_axis:.4g}, "
            f"k_g={load_at_state.gravity_stiffness:.4g}, hold load={abs(hold_load):.4g}"
            + (", stiff" if stiff else "")
            + (", spring" if spring else "")
            + (f", set-down impact={impact:.4g}" if impact > 0 else "")
        ),
    )
