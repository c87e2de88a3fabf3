"""Physical reasoning shared by every estimator: mass from geometry, inertia
from the scaled geometry, joint loads from kinematics, and joint dynamics
derived from those loads.

Formulas and their sources:

- Mass (SPEC): m = v * rho * s^3 * eta, with v the enclosed volume at scale 1
  (m^3), rho the material density (kg/m^3), s the uniform scale and eta the
  hollow fraction. For shell parts (molded plastic, sheet metal) the material
  volume is the surface area times the wall thickness t, so
  eta = min(1, A s^2 t / (v s^3)) (thin-shell approximation, e.g. Roark's
  Formulas for Stress and Strain, 8th ed., thin-walled members).
- Inertia: the per-kg inertia tensor of the geometry (solid or thin shell)
  times m times s^2 (inertia scales with mass x length^2).
- Gravity load on a joint: tau_g = ((c - p) x (M g)) . a for a revolute joint
  (c: subtree COM, p: a point on the axis, a: unit axis), F_g = M g . a for a
  prismatic one (Newton-Euler statics).
- Damping for a target damping ratio zeta of the joint treated as a
  second-order system I qdd + c qd + k q = 0: c = 2 zeta sqrt(I k)
  (e.g. Ogata, System Dynamics, 4th ed., ch. 8), with k the larger of the
  gravity stiffness |d tau_g / d q|, the spring stiffness and I w0^2, where
  w0 = 2 pi f0 is a floor frequency (joints without a restoring load still get
  damping proportional to their inertia).
- Friction that holds a state against gravity: f = safety x max |tau_g| over
  the states to hold (Coulomb friction must exceed the static load).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from asset2sim.schemas.asset import AssetDescription, LinkGeometry
from asset2sim.schemas.overlay import Inertia, JointDynamics, LinkPhysics
from asset2sim.tasks.synthesize.validate_overlay import geometry_inertia

G = 9.81
"""Standard gravity, m/s^2."""

#: Target damping ratio per requested damping level (dimensionless). "low" is
#: clearly underdamped but settles within a few cycles; "moderate" near the
#: textbook 0.7 compromise; "high" overdamped ("heavy, well-damped hinge").
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
    source: str = ""


def is_open_shell(geom: LinkGeometry) -> bool:
    """True when the link's surface encloses (almost) no volume (an open bin,
    a lone plate): its material volume is area x wall thickness whatever the
    material (see ``tasks.analyze``: ``volume_method`` ends in ``open_shell``)."""
    return "open_shell" in geom.volume_method or geom.volume <= 0.0


def hollow_fraction(geom: LinkGeometry, scale: float, material: MaterialChoice) -> float | None:
    """eta in m = v rho s^3 eta: 1 for solid parts, min(1, A s^2 t / (v s^3))
    for shell parts (dimensionless, in (0, 1]); None for an open shell (no
    enclosed volume: m = A s^2 t rho)."""
    if is_open_shell(geom):
        return None
    if not material.shell:
        return 1.0
    v = max(geom.volume * scale**3, 1e-12)
    shell_volume = geom.area * scale**2 * material.wall_thickness
    return float(min(1.0, max(shell_volume / v, 1e-6)))


def link_physics(geom: LinkGeometry, scale: float, material: MaterialChoice, source: str = "geometry") -> LinkPhysics:
    """Mass (kg), inertia (kg*m^2 about the COM) and COM (m, link frame) of a
    link from its scale-1 geometry, the scale and its material.

    Closed surfaces: m = v rho s^3 eta (SPEC), eta from :func:`hollow_fraction`.
    Open surfaces (no enclosed volume): m = A s^2 t rho, the thin-shell mass.
    Shell parts use the thin-shell inertia, solid parts the filled-solid one.

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

    inertia = geometry_inertia(geom, mass, scale, hollow)
    return LinkPhysics(
        mass=float(mass),
        inertia=Inertia.from_matrix(inertia),
        com=tuple(float(c) * scale for c in geom.com),
        material=material.name,
        density=float(material.density),
        hollow_fraction=None if eta is None else float(eta),
        source=f"{source}: {formula}",
    )


@dataclass
class JointLoad:
    """Mechanics of one joint's moving subtree at a state (output units).

    ``mass`` kg; ``inertia_axis`` kg*m^2 (revolute) or kg (prismatic) about /
    along the axis; ``gravity_load`` N*m or N (signed along the joint axis,
    i.e. positive pushes q up); ``gravity_stiffness`` |d load / d q| (N*m/rad or
    N/m).
    """

    joint: str
    mass: float
    inertia_axis: float
    gravity_load: float
    gravity_stiffness: float


def joint_loads(
    session,
    asset: AssetDescription,
    links: dict[str, LinkPhysics],
    state: dict[str, float],
    scale: float,
    subtrees: dict[str, list[str]],
    *,
    gravity: float = -G,
    dq: float | None = None,
    root_rotation: np.ndarray | None = None,
) -> dict[str, JointLoad]:
    """Gravity load, gravity stiffness and inertia about the axis of every
    movable joint at ``state`` (output units: prismatic positions in metres).

    ``session`` is a fixed-base PyBullet session of the *unscaled* input asset
    (root at the origin, z up); its kinematics are scaled by ``scale`` here.
    ``links`` holds the scaled physics (COM in the scaled link frame).
    ``root_rotation`` (3, 3): the resting-pose rotation the output will carry
    (gravity is expressed in the input's root frame as R^T g).
    """
    gvec = np.array([0.0, 0.0, gravity])
    if root_rotation is not None:
        gvec = np.asarray(root_rotation, float).T @ gvec
    out: dict[str, JointLoad] = {}

    def to_input(st: dict[str, float]) -> dict[str, float]:
        return {
            n: (v / scale if session.joint_types.get(n) == "prismatic" else v) for n, v in st.items()
        }

    def load_at(name: str, st: dict[str, float]) -> tuple[float, float, float]:
        session.set_joint_positions(to_input(st))
        axis_local = session.joint_axis(name)
        child_pos, child_R = session.link_frame(session.joint_child[name])
        child_pos = child_pos * scale
        axis = child_R @ axis_local
        axis = axis / max(np.linalg.norm(axis), 1e-12)
        M = 0.0
        mc = np.zeros(3)
        I_axis = 0.0
        for ln in subtrees[name]:
            lp = links.get(ln)
            if lp is None:
                continue
            pos, R = session.link_frame(ln)
            c = pos * scale + R @ np.asarray(lp.com, float)
            M += lp.mass
            mc += lp.mass * c
            Iw = R @ lp.inertia.matrix() @ R.T
            r = c - child_pos
            r_perp = r - np.dot(r, axis) * axis
            I_axis += float(axis @ Iw @ axis) + lp.mass * float(r_perp @ r_perp)
        if M <= 0:
            return 0.0, 0.0, 0.0
        com = mc / M
        if session.joint_types[name] == "prismatic":
            load = float(M * np.dot(gvec, axis))
            inertia = M
        else:
            load = float(np.dot(np.cross(com - child_pos, M * gvec), axis))
            inertia = I_axis
        return M, inertia, load

    for name in [n for n in session.joint_names if n in subtrees]:
        q0 = state.get(name, 0.0)
        lo, hi = session.joint_limits[name]
        if session.joint_types[name] == "prismatic":
            lo, hi = lo * scale, hi * scale
        step = dq if dq is not None else (0.02 if session.joint_types[name] != "prismatic" else 0.002)
        M, inertia, load = load_at(name, state)
        qa = max(q0 - step, lo) if np.isfinite(lo) else q0 - step
        qb = min(q0 + step, hi) if np.isfinite(hi) else q0 + step
        if qb - qa > 0:
            _, _, la = load_at(name, {**state, name: qa})
            _, _, lb = load_at(name, {**state, name: qb})
            k = abs(lb - la) / (qb - qa)
        else:
            k = 0.0
        out[name] = JointLoad(joint=name, mass=M, inertia_axis=inertia, gravity_load=load, gravity_stiffness=k)
    session.set_joint_positions(to_input(state))
    return out


#: Simulator timestep the damping bound is computed for, s (SPEC: 1/240 s).
TIMESTEP = 1.0 / 240.0


def max_stable_damping(inertia_axis: float, timestep: float = TIMESTEP) -> float:
    """Largest viscous damping (N*m*s/rad or N*s/m) a semi-implicit integrator
    takes without overshooting in one step: c dt / I <= 1, i.e. c <= I / dt
    (the velocity decay factor of one step stays in [0, 1]). Higher values
    make light parts explode in PyBullet."""
    return float(max(inertia_axis, 0.0) / timestep)


#: Largest joint speed Bullet's multibodies allow, rad/s or m/s
#: (``btMultiBody::m_maxCoordinateVelocity`` = 100 in its constructor,
#: bullet3 src/BulletDynamics/Featherstone/btMultiBody.cpp; PyBullet's
#: ``changeDynamics(maxJointVelocity=...)``).
MAX_JOINT_SPEED = 100.0
#: Share of the locking bound I v_max / dt that joint friction may take
#: (:func:`max_stable_friction`): the joint moved freely at 0.88 of it and
#: locked at 1.06 (measurements in that function's docstring).
FRICTION_LOCK_SHARE = 0.8


def max_stable_friction(inertia_axis: float, timestep: float = TIMESTEP) -> float:
    """Largest joint friction (N*m or N) the engines' friction motor takes
    without locking the joint: FRICTION_LOCK_SHARE * I v_max / dt (I the
    inertia about the axis, kg*m^2, or the moving mass, kg; v_max =
    :data:`MAX_JOINT_SPEED`; dt the timestep, s).

    PyBullet models Coulomb joint friction as a zero-target-velocity motor
    whose impulse per step is at most F dt; when F dt / I exceeds the joint
    speed clamp v_max, the motor holds the joint against any effort.
    Measured on the 47 g handle of suitcase 103755 (I = 4.7e-5 kg*m^2,
    dt = 1/240 s; bound I v_max / dt = 1.13 N*m): locked at friction 1.2 and
    1.48 N*m under efforts up to 100 N*m, free at 1.0 N*m under an effort of
    1.5 N*m. Escalation therefore never raises friction above this (a light
    handle whose friction escalated to 1.48 N*m could not be opened by any
    force)."""
    return float(FRICTION_LOCK_SHARE * max(inertia_axis, 0.0) * MAX_JOINT_SPEED / timestep)


def damping_for(load: JointLoad, zeta: float, stiffness: float = 0.0, floor_hz: float = FLOOR_FREQUENCY_HZ) -> float:
    """Viscous damping c = 2 zeta sqrt(I k_eff) (N*m*s/rad or N*s/m), with
    k_eff = max(gravity stiffness, spring stiffness, I (2 pi f0)^2)."""
    w0 = 2.0 * np.pi * floor_hz
    k_eff = max(load.gravity_stiffness, stiffness, load.inertia_axis * w0 * w0)
    return float(2.0 * zeta * np.sqrt(max(load.inertia_axis, 0.0) * k_eff))


def joint_dynamics(
    load_at_state: JointLoad,
    hold_load: float,
    *,
    prismatic: bool,
    damping_level: str = "moderate",
    stiff: bool = False,
    free_moving: bool = False,
    spring: tuple[float, float] | None = None,
    source: str = "physics",
) -> JointDynamics:
    """Damping, friction and stiffness of one joint from its loads.

    Args:
        load_at_state: loads at the initial state (output units).
        hold_load: largest |gravity load| (N*m or N) friction must hold.
        prismatic: joint type (sets units and the friction floor).
        damping_level: "low" | "moderate" | "high" (:data:`DAMPING_RATIO`).
        stiff: a stiff joint is asked for: friction x 4 over the floor load.
        free_moving: "moves freely": no extra friction floor.
        spring: (stiffness, reference) when a spring is intended.

    The friction floor is a Coulomb coefficient of 0.05 on the moving mass's
    weight (prismatic, N; typical of drawer slides, e.g. Engineering ToolBox
    friction coefficients for lubricated sliding) or that force at a 1 cm pin
    radius (revolute, N*m). Friction never exceeds :func:`max_stable_friction`
    (the engine's friction motor would lock the joint), damping never
    :func:`max_stable_damping`.
    """
    zeta = DAMPING_RATIO.get(damping_level, DAMPING_RATIO["moderate"])
    k = spring[0] if spring else 0.0
    c = damping_for(load_at_state, zeta, k)
    c_max = max_stable_damping(load_at_state.inertia_axis)
    weight = load_at_state.mass * G
    floor = 0.05 * weight if prismatic else 0.05 * weight * 0.01
    if free_moving:
        floor *= 0.2
    friction = HOLD_SAFETY * abs(hold_load) + floor
    if stiff:
        friction = max(friction * 2.0, 4.0 * HOLD_SAFETY * abs(load_at_state.gravity_load) + 4.0 * floor)
        c *= 2.0
    c = min(c, c_max)
    if load_at_state.inertia_axis > 0:  # above it the engine's friction motor locks the joint
        friction = min(friction, max_stable_friction(load_at_state.inertia_axis))
    return JointDynamics(
        damping=float(c),
        friction=float(friction),
        stiffness=float(k),
        spring_reference=float(spring[1]) if spring else None,
        inertia_axis=float(load_at_state.inertia_axis),
        source=(
            f"{source}: zeta={zeta} ({damping_level}), I_axis={load_at_state.inertia_axis:.4g}, "
            f"k_g={load_at_state.gravity_stiffness:.4g}, hold load={abs(hold_load):.4g}"
            + (", stiff" if stiff else "")
            + (", spring" if spring else "")
        ),
    )
