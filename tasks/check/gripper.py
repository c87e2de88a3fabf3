"""A floating, force- and speed-limited parallel gripper as a bounded-force attachment.

Grasping in physics simulation is commonly modelled not by finger contacts
but by an attachment between the gripper and the grasped part: a weld
constraint, a kinematic "sticky" grasp, or a spring-damper whose force is
bounded (ManiSkill's and robosuite's grasp checks, PyBullet's
``createConstraint`` with ``maxForce``, MuJoCo ``weld`` equality constraints
with soft ``solref``). This module uses the bounded spring-damper form, the one
that keeps the gripper's force limit physical: the gripper point ``g`` (the
point between the fingers) is moved by the arm no faster than
``max_speed_m_s``; the grasped part is pulled towards it by

    F = clip_{|F| <= F_max}( k (g - p) + c (v_g - v_p) )

applied at the grasp point ``p`` (a point fixed in the grasped link, moved
with it), ``k`` = ``grasp_stiffness_n_m``, ``c`` = ``grasp_damping_n_s_m``,
``F_max`` = ``max_force_n``, ``v_p`` the grasp point's velocity (finite
difference of its world position between calls), ``v_g`` the gripper point's.
A part that resists more than ``F_max`` (a lid too stiff, an object whose
body slides) makes the gripper stall: ``g`` is kept within ``F_max / k`` of
``p`` (the spring cannot stretch further at the force limit), as an
impedance-controlled arm stops advancing when its force saturates.

A push or pull along one direction (``step_towards(..., direction=d)``: the
force projected on d, the finger sliding along the part across it) models a
fingertip pressing on a surface instead of a grasp.

The gripper is floating (no arm kinematics, no reaction on a robot base) and
talks to physics only through the engine protocol
(:class:`asset2sim.engines.base.SimSession`: ``link_frame``,
``apply_link_force``, ``link_masses``, ``joint_axis``, ``joint_types``; the
contact point reads the URDF's collision geometry when the model is given,
else ``link_collision_vertices`` / ``link_aabb``); it never steps the session
itself: call :meth:`BoundedGrasp.step_towards` once per engine step, then
``session.step(1)``.

Integration bound: the spring acts explicitly on the engine's step ``dt``, so
the stiffness and damping used are capped at ``m_eff / dt^2`` and
``m_eff / dt`` (omega dt <= 1 and c dt / m <= 1: half of the stability
limits of an explicit step, omega dt < 2 for a harmonic oscillator under the
symplectic Euler / Stormer-Verlet step, Hairer, Lubich & Wanner, *Geometric
Numerical Integration*, 2nd ed. 2006, ch. I, and c dt / m < 2 for explicit
Euler on viscous damping) with
``m_eff`` one third of the grasped link's mass (the effective mass of a
uniform plate at the far edge of its hinge, m L^2/3 / L^2). The cap is
recorded (:attr:`BoundedGrasp.stiffness`).
"""

from __future__ import annotations

import functools
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from asset2sim.mesh_io import MeshReadError, read_mesh
from asset2sim.tasks.interpret.part_labels import canonical_label
from asset2sim.urdf import UrdfGeometry, UrdfModel

#: Canonical part labels a gripper grasps when a link carries a geometry element so named.
HANDLE_LABELS: frozenset[str] = frozenset({"handle", "knob", "lever", "button"})

#: Share of the largest distance from the axis within which collision
#: vertices count as the far edge (their mean is the contact point).
FAR_EDGE_SHARE = 0.9

#: A side of a joint whose lowest point is this much (m) below the other's carries the object (:func:`grasp_side`).
SUPPORT_TOL = 0.003

#: Effective mass at the grasp point as a share of the link's mass (a uniform
#: plate at its far edge: I / L^2 = m / 3).
EFFECTIVE_MASS_SHARE = 1.0 / 3.0


@dataclass(frozen=True)
class GripperLimits:
    """Force and speed limits of a robot gripper and arm (SI units).

    Defaults and their sources:

    - ``max_force_n`` = 70 N: the Franka Emika Panda hand's continuous grasp
      force (70 N, 140 N maximum; Franka Emika, *Panda Datasheet*, 2019,
      "Hand"); a two-finger friction grasp with finger friction 0.5 transmits
      at most 2 * 0.5 * 70 N = 70 N tangentially. It lies within the
      Robotiq 2F-85's grip force range (20-235 N; Robotiq, *2F-85 & 2F-140
      Instruction Manual*, specifications) and below the 140 N quasi-static
      limit for hands and fingers of ISO/TS 15066:2016, Table A.2.
    - ``max_speed_m_s`` = 0.25 m/s: the reduced speed of collaborative
      operation, tool centre point at most 250 mm/s (ISO 10218-1:2011,
      clause 5.6); the Panda's Cartesian limit is 1.7 m/s (datasheet).
    - ``grasp_stiffness_n_m`` = 2000 N/m, ``grasp_damping_n_s_m`` = 40 N s/m:
      an estimate in the range of Cartesian impedance control of
      collaborative arms (translational stiffness of order 10^2 - 3 * 10^3 N/m
      in Franka's ``franka_ros`` Cartesian impedance example and KUKA LBR iiwa
      Cartesian impedance mode, whose limit is 5000 N/m; KUKA Sunrise.OS
      manual); damping about critical for a 0.2 kg part (2 sqrt(k m) = 40 N s/m).
    """

    max_force_n: float = 70.0
    max_speed_m_s: float = 0.25
    grasp_stiffness_n_m: float = 2000.0
    grasp_damping_n_s_m: float = 40.0

    def __post_init__(self) -> None:
        for name in ("max_force_n", "max_speed_m_s", "grasp_stiffness_n_m"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v > 0):
                raise ValueError(f"GripperLimits.{name} must be > 0, got {v!r}")
        if not (np.isfinite(self.grasp_damping_n_s_m) and self.grasp_damping_n_s_m >= 0):
            raise ValueError(f"GripperLimits.grasp_damping_n_s_m must be >= 0, got {self.grasp_damping_n_s_m!r}")


class BoundedGrasp:
    """A grasp of ``link`` at ``point_link`` by a floating gripper (module docstring).

    Args:
        session: a :class:`asset2sim.engines.base.SimSession`.
        link: the grasped link (any link of the session).
        point_link: grasp point (3,) m in the link's URDF frame.
        limits: the gripper's limits.

    The gripper point starts at the grasp point (the fingers close on it).

    Raises:
        KeyError: unknown link.
        ValueError: ``point_link`` is not 3 finite numbers.
    """

    def __init__(self, session, link: str, point_link: np.ndarray, limits: GripperLimits) -> None:
        p = np.asarray(point_link, float).reshape(-1)
        if p.shape != (3,) or not np.all(np.isfinite(p)):
            raise ValueError(f"link {link!r}: grasp point must be 3 finite numbers (m), got {point_link!r}")
        if link not in session.link_names:
            raise KeyError(f"link {link!r} is not a link of the session")
        self.session = session
        self.link = link
        self.point_link = p
        self.limits = limits
        dt = float(session.options.conventions.timestep)
        m_eff = max(float(session.link_masses().get(link, 0.0)) * EFFECTIVE_MASS_SHARE, 1e-4)
        self.stiffness = float(min(limits.grasp_stiffness_n_m, m_eff / dt**2))
        """spring constant used, N/m (the limits' value, capped for stable integration)"""
        self.damping = float(min(limits.grasp_damping_n_s_m, m_eff / dt))
        """damping used, N s/m (capped likewise)"""
        self._p_prev = self.grasp_point_world()
        self.gripper_point = self._p_prev.copy()
        """world position (3,) m of the gripper point"""
        self._released = False
        self._peak = 0.0
        self.last_force = np.zeros(3)
        """the force (3,) N applied at the last call"""

    # ------------------------------------------------------------------ state
    def grasp_point_world(self) -> np.ndarray:
        """The grasp point moved with the link, world (3,) m."""
        o, R = self.session.link_frame(self.link)
        return np.asarray(o, float) + np.asarray(R, float) @ self.point_link

    @property
    def peak_force_n(self) -> float:
        """Largest |F| applied so far, N."""
        return self._peak

    @property
    def released(self) -> bool:
        """Whether :meth:`release` was called."""
        return self._released

    # ---------------------------------------------------------------- control
    def step_towards(self, target_world: np.ndarray, dt: float, direction: np.ndarray | None = None) -> np.ndarray:
        """Move the gripper point towards ``target_world`` (3,) m by at most
        ``max_speed_m_s * dt`` and apply the bounded spring-damper force on
        the grasped link for the next engine step.

        Args:
            target_world: where the gripper should go, world (3,) m.
            dt: the time until the next call, s (the engine's timestep when
                called every step).
            direction: None: the full attachment (force in any direction);
                a vector (3,): a push or pull along it only (a fingertip
                pressing on a surface it slides along: the force is the
                attachment's force projected on the unit direction, and the
                gripper point keeps up with the grasp point across it).

        Returns:
            The force (3,) N applied at the grasp point (|F| <= ``max_force_n``).

        Raises:
            RuntimeError: the grasp was released.
            ValueError: ``dt`` <= 0 or a non-finite target.
        """
        if self._released:
            raise RuntimeError(f"grasp of link {self.link!r} was released")
        if not dt > 0:
            raise ValueError(f"dt must be > 0 s, got {dt!r}")
        target = np.asarray(target_world, float).reshape(3)
        if not np.all(np.isfinite(target)):
            raise ValueError(f"gripper target must be finite, got {target_world!r}")
        lim = self.limits
        p = self.grasp_point_world()
        v_p = (p - self._p_prev) / dt
        self._p_prev = p
        g0 = self.gripper_point
        step = target - g0
        n = float(np.linalg.norm(step))
        vmax = lim.max_speed_m_s * dt
        if n > vmax:
            step *= vmax / n
        g = g0 + step
        d = None
        if direction is not None:
            d = np.asarray(direction, float).reshape(3)
            nd = float(np.linalg.norm(d))
            if not (np.isfinite(nd) and nd > 0):
                raise ValueError(f"push direction must be a non-zero finite vector, got {direction!r}")
            d = d / nd
            g = p + float((g - p) @ d) * d  # the finger slides with the part across d
        # Stall at the force limit: the spring cannot stretch beyond F_max / k.
        stretch = g - p
        s = float(np.linalg.norm(stretch))
        leash = lim.max_force_n / self.stiffness
        if s > leash:
            g = p + stretch * (leash / s)
        v_g = (g - g0) / dt
        self.gripper_point = g
        force = self.stiffness * (g - p) + self.damping * (v_g - v_p)
        if d is not None:
            force = float(force @ d) * d
        fn = float(np.linalg.norm(force))
        if fn > lim.max_force_n:
            force *= lim.max_force_n / fn
            fn = lim.max_force_n
        if np.all(np.isfinite(force)):
            self.session.apply_link_force(self.link, force, p)
        else:
            force = np.zeros(3)
            fn = 0.0
        self._peak = max(self._peak, fn)
        self.last_force = force
        return force

    def release(self) -> None:
        """Open the fingers: no force from now on."""
        self._released = True
        self.last_force = np.zeros(3)


# ------------------------------------------------------------------ contact point
_ELEMENT_SUFFIX = re.compile(r"[-_]?\d+$")


def element_label(name: str | None) -> str | None:
    """Canonical part label of a URDF geometry element's name
    (PartNet-Mobility names elements ``<part>-<id>``: ``handle-18`` ->
    ``handle``), or None."""
    if not name:
        return None
    return canonical_label(_ELEMENT_SUFFIX.sub("", name.strip()))


@functools.lru_cache(maxsize=256)
def _mesh_vertices(path: str) -> np.ndarray:
    """Finite vertices (n, 3) of a mesh file, file units (read-only; (0, 3) when unreadable)."""
    try:
        v, _, _ = read_mesh(Path(path))
    except MeshReadError:
        return np.zeros((0, 3))
    v = np.asarray(v, float)
    v = v[np.all(np.isfinite(v), axis=1)]
    v.setflags(write=False)
    return v


def geometry_points(g: UrdfGeometry) -> np.ndarray:
    """Points (k, 3) m of a geometry element in its link's frame: a mesh's
    vertices (scaled), a box's corners, a sphere's or cylinder's centre;
    k = 0 when unreadable."""
    if g.kind == "mesh" and g.path is not None:
        v = _mesh_vertices(str(g.path)) * g.scale
    elif g.kind == "box" and g.size is not None:
        h = 0.5 * np.asarray(g.size, float)
        v = np.array([[x, y, z] for x in (-h[0], h[0]) for y in (-h[1], h[1]) for z in (-h[2], h[2])])
    elif g.kind in ("sphere", "cylinder") and g.radius is not None:
        v = np.zeros((1, 3))
    else:
        return np.zeros((0, 3))
    return v @ g.origin[:3, :3].T + g.origin[:3, 3]


def rigid_group(model: UrdfModel, link: str, exclude: str | None = None) -> list[str]:
    """``link`` and every link joined to it by fixed joints (up and down the
    tree), never entering ``exclude`` (a link whose subtree is left out)."""
    out, stack = [], [link]
    while stack:
        name = stack.pop()
        if name in out or name == exclude:
            continue
        out.append(name)
        stack.extend(j.child for j in model.children(name) if j.type == "fixed")
        pj = model.parent_joint(name)
        if pj is not None and pj.type == "fixed":
            stack.append(pj.parent)
    return out


def link_points(model: UrdfModel, link: str) -> np.ndarray:
    """Collision points (k, 3) m of ``link`` in its own frame (visual
    points where it has no collision element), from the URDF's geometry."""
    ln = model.links.get(link)
    if ln is None:
        return np.zeros((0, 3))
    pts = [geometry_points(g) for g in (ln.collisions or ln.visuals)]
    pts = [p for p in pts if len(p)]
    return np.concatenate(pts) if pts else np.zeros((0, 3))


def handle_points(model: UrdfModel, link: str) -> np.ndarray:
    """Points (k, 3) m, in ``link``'s frame, of the geometry elements of
    ``link`` named as a handle (:data:`HANDLE_LABELS`, :func:`element_label`):
    collision elements so named, else visual elements so named
    (PartNet-Mobility names visuals only); k = 0 when there is none.

    Raises:
        KeyError: ``link`` is not in the model.
    """
    if link not in model.links:
        raise KeyError(f"link {link!r} is not in the URDF {model.path or model.name!r}")
    ln = model.links[link]
    els = [g for g in ln.collisions if element_label(g.name) in HANDLE_LABELS] or \
          [g for g in ln.visuals if element_label(g.name) in HANDLE_LABELS]
    pts = [p for p in (geometry_points(g) for g in els) if len(p)]
    return np.concatenate(pts) if pts else np.zeros((0, 3))


def _session_points(session, link: str) -> np.ndarray:
    """The engine's collision vertices (k, 3) of ``link`` (the protocol says
    link frame), else the corners of its engine AABB in the link frame."""
    v = np.asarray(session.link_collision_vertices(link), float).reshape(-1, 3)
    if len(v):
        return v
    lo, hi = session.link_aabb(link)
    o, R = session.link_frame(link)
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
    return (corners - np.asarray(o, float)) @ np.asarray(R, float)


def side_links(session, joint: str, model: UrdfModel | None, side: str) -> list[str]:
    """Links of the session that move rigidly with one side of ``joint``:
    ``child`` its child link and the links fixed to it; ``parent`` its parent
    link and the links fixed to that (without the child's side). Without a
    model: the child link alone (``parent`` raises).

    Raises:
        ValueError: ``side`` is not child / parent, or ``parent`` without a model.
    """
    if side not in ("child", "parent"):
        raise ValueError(f"side must be 'child' or 'parent', got {side!r}")
    child = session.joint_child[joint]
    if model is None or child not in model.links:
        if side == "parent":
            raise ValueError(f"joint {joint!r}: the parent side needs the URDF model")
        return [child]
    if side == "child":
        return [ln for ln in rigid_group(model, child) if ln in session.link_names]
    parent = model.joint(joint).parent
    return [ln for ln in rigid_group(model, parent, exclude=child) if ln in session.link_names]


def contact_point_rule(session, joint: str, model: UrdfModel | None = None, *, opening_direction: float = 1.0,
                       side: str = "child") -> tuple[str, np.ndarray, str]:
    """Where a gripper grasps the part that ``joint`` moves.

    Rules (re-derivable; ``docs/metrics.md``), over the links of the grasped
    side (:func:`side_links`: the child link and the links fixed to it, or
    the parent's side when the child carries the object):

    1. A handle: a geometry element of one of them named as a handle
       (:func:`handle_points`; needs ``model``): the centre of the handle's
       bounding box.
    2. Else a revolute joint: the mean of the side's collision points whose
       distance from the joint axis is at least :data:`FAR_EDGE_SHARE` of the
       largest (the middle of the far edge of a lid or door: the point of the
       moving link farthest from the axis, where the lever is longest), on
       the link holding the farthest point.
    3. Else a prismatic joint: the centre of the link's points' bounding box
       moved along the axis to the link's extreme in the opening direction
       (the front of a drawer).

    Points come from the URDF's collision geometry when ``model`` is given
    (exact, in the link frame), else from the engine
    (``link_collision_vertices``, else the link's AABB corners). The joint
    axis passes through the child link's frame origin (URDF).

    Args:
        session: a :class:`asset2sim.engines.base.SimSession`.
        joint: a movable joint of the session.
        model: the session's URDF model, or None.
        opening_direction: +1 / -1, the sign of q that opens the joint (rule 3).
        side: ``child`` or ``parent`` (needs ``model``).

    Returns:
        ``(link, point_link (3,) m in that link's frame, rule)`` with rule
        ``handle``, ``far edge`` or ``front``.

    Raises:
        KeyError: ``joint`` is not a movable joint of the session.
        ValueError: the side has no geometry to grasp; bad ``side``.
    """
    if joint not in session.joint_child:
        raise KeyError(f"joint {joint!r} is not a movable joint of the session")
    links = side_links(session, joint, model, side)
    if model is not None:
        for ln in links:
            if ln in model.links:
                h = handle_points(model, ln)
                if len(h):
                    return ln, 0.5 * (h.min(axis=0) + h.max(axis=0)), "handle"
    o, Rj = session.link_frame(session.joint_child[joint])
    a = np.asarray(Rj, float) @ np.asarray(session.joint_axis(joint), float)
    a = a / max(float(np.linalg.norm(a)), 1e-12)
    o = np.asarray(o, float)
    best: tuple[float, str, np.ndarray, np.ndarray] | None = None  # (reach, link, local points, world points)
    for ln in links:
        v = link_points(model, ln) if model is not None else _session_points(session, ln)
        if not len(v):
            continue
        lo, R = session.link_frame(ln)
        w = v @ np.asarray(R, float).T + np.asarray(lo, float)
        if session.joint_types[joint] == "prismatic":
            reach = float(np.max((w - o) @ a * (1.0 if opening_direction >= 0 else -1.0)))
        else:
            rel = w - o
            reach = float(np.max(np.linalg.norm(rel - np.outer(rel @ a, a), axis=1)))
        if best is None or reach > best[0]:
            best = (reach, ln, v, w)
    if best is None:
        raise ValueError(f"joint {joint!r}: links {links} have no collision geometry to grasp")
    _, link, v, w = best
    _, R = session.link_frame(link)
    a_l = np.asarray(R, float).T @ a  # the axis in the grasped link's frame
    o_l = np.asarray(R, float).T @ (o - np.asarray(session.link_frame(link)[0], float))
    if session.joint_types[joint] == "prismatic":
        sgn = 1.0 if opening_direction >= 0 else -1.0
        c = 0.5 * (v.min(axis=0) + v.max(axis=0))
        c = c + a_l * sgn * (float((v @ a_l * sgn).max()) - sgn * float(c @ a_l))
        return link, c, "front"
    rel = v - o_l
    r = np.linalg.norm(rel - np.outer(rel @ a_l, a_l), axis=1)
    far = v[r >= FAR_EDGE_SHARE * float(r.max())]
    return link, far.mean(axis=0), "far edge"


def contact_point(session, joint: str, model: UrdfModel | None = None, *, opening_direction: float = 1.0
                  ) -> tuple[str, np.ndarray]:
    """``(link, point_link (3,) m)`` of :func:`contact_point_rule` on the
    joint's child side (same arguments and errors), without the rule's name."""
    link, point, _ = contact_point_rule(session, joint, model, opening_direction=opening_direction)
    return link, point


def lowest_point(session, links: list[str], model: UrdfModel | None) -> float:
    """Lowest world z (m) of the collision points of ``links`` at the
    session's state (URDF geometry when ``model`` is given, else the engine's
    AABBs); +inf when none has geometry."""
    z = float("inf")
    for ln in links:
        v = link_points(model, ln) if model is not None else np.zeros((0, 3))
        if len(v):
            o, R = session.link_frame(ln)
            z = min(z, float(np.min(v @ np.asarray(R, float)[2] + float(o[2]))))
        elif session.link_has_collision(ln):
            z = min(z, float(session.link_aabb(ln)[0][2]))
    return z


def grasp_side(session, joint: str, model: UrdfModel | None, *, root_fixed: bool = False,
               support_tol: float = SUPPORT_TOL) -> str:
    """Which side of ``joint`` the gripper moves: ``child`` (the part the
    joint moves: a lid, a door, a drawer), or ``parent`` when the child's
    side carries the object (its lowest point within ``support_tol`` m of
    the object's lowest point while the parent's side is higher by more than
    ``support_tol``): a stapler whose base plate is the URDF child is pressed
    by its top, a laptop whose base is the child is closed by its screen; the
    joint's relative motion is the same. A mounted object (root fixed) and a
    session without a model: always ``child``."""
    if root_fixed or model is None:
        return "child"
    child = side_links(session, joint, model, "child")
    sub = set()
    stack = [session.joint_child[joint]]
    while stack:  # the child's whole subtree rests with it
        n = stack.pop()
        if n in sub:
            continue
        sub.add(n)
        stack.extend(j.child for j in model.children(n))
    z_child = lowest_point(session, [ln for ln in session.link_names if ln in sub] or child, model)
    z_rest = lowest_point(session, [ln for ln in session.link_names if ln not in sub], model)
    if not np.isfinite(z_child) or not np.isfinite(z_rest):
        return "child"
    return "parent" if z_child + support_tol < z_rest else "child"
