"""Newton engine (NVIDIA Warp, runs on the CPU) under the SPEC's conventions;
see :mod:`.base`.

The session builds Newton bodies from the one reading of the URDF every
engine shares (:func:`asset2sim.engines.loading.read_urdf`,
:func:`~asset2sim.engines.loading.collision_pieces`), as the PhysX and MuJoCo
engines do, so Newton collides the same convex pieces:

- bodies: the file's mass, COM and inertia tensor (links without
  ``<inertial>``: PyBullet's 1 kg and unit inertia, as the other engines);
- shapes: one convex hull per piece (``add_shape_convex_hull``), boxes,
  spheres and cylinders as themselves, with density 0 (Newton's default
  adds 1000 kg/m^3 of shape mass to each body); contact friction 0.25 on
  every shape and the ground (the other engines' 0.25);
- joints: revolute / prismatic with the URDF limits and Coulomb friction
  (``friction``, N*m or N), viscous damping and springs as a drive
  (``target_kd`` = damping, ``target_ke`` = stiffness, ``target_pos`` = the
  spring reference), fixed joints welded; the root free (``add_joint_free``)
  or fixed to the world, the parent-child pairs filtered;
- solver: :class:`newton.solvers.SolverKamino` (joint friction and limits as
  constraints; why not Newton's other solvers: ``docs/design/simulators.md``), timestep 1/240 s;
- placement: the root free, lowest collision vertex on z = 0.

Only the queries the SPEC's rest-stability and oscillation tests need are
answered (joints, root pose, stepping, penetration from Newton's contacts,
ground penetration from the geometry); the others raise
:class:`~asset2sim.engines.base.EngineUnsupported`. newton and warp are
looked up at the end of this module to register the engine, imported when a
session opens (an optional extra: ``pip install 'asset2sim[newton]'``).
"""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np

from asset2sim.engines.base import (
    ContactPair,
    EngineUnsupported,
    HeldPhysics,
    NoRootHold,
    SessionOptions,
    penetration_sum,
    register_engine,
    register_file_reader,
)
from asset2sim.engines.loading import (
    BULLET_DEFAULT_FRICTION,
    BULLET_DEFAULT_INERTIA,
    BULLET_DEFAULT_MASS,
    BULLET_PLANE_FRICTION,
    CollisionPiece,
    collision_pieces,
    joint_tables,
    read_urdf,
)
from asset2sim.engines.newton_model import held_physics_of_model, held_physics_of_usd, import_newton
from asset2sim.engines.session_defaults import SessionDefaults
from asset2sim.frames import matrix_quat_wxyz, quat_wxyz_matrix
from asset2sim.mesh_io import convex_hull_mesh

#: Contact friction coefficient on every shape and the ground (PyBullet's
#: 0.5 x 0.5 product, what the other engines use).
CONTACT_FRICTION = BULLET_DEFAULT_FRICTION * BULLET_PLANE_FRICTION


class NewtonSession(SessionDefaults, NoRootHold):
    """A :class:`~asset2sim.engines.base.SimSession` in Newton on the CPU.

    ``notes``: what the reading of the URDF changed (flat pieces made slabs).

    Raises (constructor):
        UrdfError: the URDF or a collision mesh cannot be read.
    """

    engine = "newton"

    def __init__(self, urdf_path: Path, options: SessionOptions):
        wp, newton = import_newton()
        self._wp, self._nt = wp, newton
        self.options = options
        conv = options.conventions
        self.dt = conv.timestep
        self.urdf = read_urdf(urdf_path)
        pieces, notes = collision_pieces(self.urdf)
        self.notes = list(notes)
        self.joint_names, self.joint_types, self.joint_limits, self.joint_child = joint_tables(self.urdf)
        self.link_names = self.urdf.tree_order()
        self._fixed = bool(options.fixed_base)
        poses = self._placed_poses(pieces)
        b = newton.ModelBuilder(gravity=(0.0, 0.0, conv.gravity if options.gravity else 0.0))
        # density 0: Newton adds each shape's mass (default 1000 kg/m^3) to its body's; the file's inertials are the truth
        cfg = newton.ModelBuilder.ShapeConfig(mu=CONTACT_FRICTION, density=0.0)
        self._add_bodies(b, pieces, poses, cfg)
        self._add_joints(b, poses)
        if options.ground:
            b.add_ground_plane(cfg=newton.ModelBuilder.ShapeConfig(mu=CONTACT_FRICTION))
        self.model = b.finalize(device="cpu")
        self._init_state()
        self._size_contacts()
        self.rebuilds = 0
        self._build_solver()
        self._ground_shape = self.model.shape_count - 1 if options.ground else -1
        self._shape_body = self.model.shape_body.numpy()
        self._link_of = {v: k for k, v in self._body.items()}

    # ------------------------------------------------------------- building
    def _placed_poses(self, pieces: dict[str, list[CollisionPiece]]) -> dict[str, np.ndarray]:
        """Every link's pose (4, 4), m, at the initial state, the root free
        lifted so the lowest collision vertex is on z = 0 (fixed: where the
        file puts it); sets ``_points``, each link's collision vertices (k, 3) m."""
        poses = self.urdf.link_poses(self.options.initial_state)
        self._points: dict[str, np.ndarray] = {}
        for name in self.link_names:
            pts = [self._piece_points(p) for p in pieces.get(name, [])]
            self._points[name] = np.vstack(pts) if pts else np.zeros((0, 3))
        lift = 0.0
        if not self._fixed:
            lows = [(_apply(poses[n], v)[:, 2].min()) for n, v in self._points.items() if len(v)]
            lift = -min(lows) if lows else 0.0
        root_pose = np.eye(4)
        root_pose[2, 3] = lift
        return self.urdf.link_poses(self.options.initial_state, root_pose)

    def _add_bodies(self, b, pieces: dict[str, list[CollisionPiece]], poses: dict[str, np.ndarray], cfg) -> None:
        """One body per link at its pose with the file's mass, COM and inertia
        (PyBullet's default without ``<inertial>``) and its collision shapes;
        sets ``_body`` (link -> body index)."""
        wp = self._wp
        self._body: dict[str, int] = {}
        for name in self.link_names:
            link = self.urdf.links[name]
            if link.inertial is not None and link.inertial.mass is not None:
                mass, com, inertia = float(link.inertial.mass), link.inertial.com(), link.inertial.inertia_in_link_axes()
            else:
                mass, com, inertia = BULLET_DEFAULT_MASS, np.zeros(3), np.diag(BULLET_DEFAULT_INERTIA)
                self.notes.append(f"link {name!r} has no <inertial>: PyBullet's default 1 kg, unit inertia")
            body = b.add_link(xform=_wp_transform(wp, poses[name]), com=wp.vec3(*map(float, com)),
                              inertia=wp.mat33(*map(float, np.asarray(inertia, float).ravel())), mass=mass, label=name)
            self._body[name] = body
            for piece in pieces.get(name, []):
                self._add_shape(b, body, piece, cfg)

    def _add_joints(self, b, poses: dict[str, np.ndarray]) -> None:
        """The root joint (fixed to the world or free), every URDF joint
        (movable: limits, Coulomb friction, damping and spring as a drive;
        fixed: welded) and the articulation; sets ``_joint_index`` (movable
        joint -> Newton joint index)."""
        wp = self._wp
        joints = []
        root = self.urdf.root
        if self._fixed:
            joints.append(b.add_joint_fixed(-1, self._body[root], parent_xform=_wp_transform(wp, poses[root]), label="root"))
        else:
            joints.append(b.add_joint_free(self._body[root], parent_xform=_wp_transform(wp, poses[root]), label="root"))
        self._joint_index: dict[str, int] = {}
        for j in self.urdf.joints:
            kw = dict(parent_xform=_wp_transform(wp, j.origin), label=j.name)
            parent, child = self._body[j.parent], self._body[j.child]
            if j.type in ("revolute", "continuous", "prismatic"):
                spring = self.options.springs.get(j.name)
                lo, hi = j.lower, j.upper
                dof = dict(
                    axis=wp.vec3(*map(float, j.axis)),
                    friction=float(j.friction),
                    target_kd=float(j.damping),
                    target_ke=float(spring.stiffness) if spring else 0.0,
                    target_pos=float(spring.reference) if spring else 0.0,
                    target_vel=0.0,
                    limit_lower=float(lo) if np.isfinite(lo) else None,
                    limit_upper=float(hi) if np.isfinite(hi) else None,
                )
                add = b.add_joint_prismatic if j.type == "prismatic" else b.add_joint_revolute
                idx = add(parent, child, **kw, **dof)
                self._joint_index[j.name] = idx
            else:
                idx = b.add_joint_fixed(parent, child, **kw)
            joints.append(idx)
        b.add_articulation(joints)

    def _init_state(self) -> None:
        """The movable joints' coordinate and DOF addresses (``_qadr``,
        ``_dadr``), the initial joint positions, the two states, the control
        and the bodies' poses (forward kinematics)."""
        qs = self.model.joint_q_start.numpy()
        ds = self.model.joint_qd_start.numpy()
        self._qadr = {n: int(qs[i]) for n, i in self._joint_index.items()}
        self._dadr = {n: int(ds[i]) for n, i in self._joint_index.items()}
        q = self.model.joint_q.numpy()
        for n, v in self.options.initial_state.items():
            if n in self._qadr:
                q[self._qadr[n]] = float(v)
        self.model.joint_q.assign(q)
        self.state0, self.state1 = self.model.state(), self.model.state()
        self.control = self.model.control()
        self._nt.eval_fk(self.model, self.model.joint_q, self.model.joint_qd, self.state0)

    def _size_contacts(self) -> None:
        """The query collision pipeline and ``_capacity``, sized from the
        contacts at the initial state (see :data:`CONTACT_CAPACITY_MIN`)."""
        self._query = self._nt.CollisionPipeline(self.model, publish_capacity=False)
        self._query_contacts = self._query.contacts()
        self._query.collide(self.state0, self._query_contacts)
        self._capacity = _capacity_for(int(self._query_contacts.rigid_contact_count.numpy()[0]))

    def _build_solver(self) -> None:
        """The stepping collision pipeline and the Kamino solver, both sized
        for ``self._capacity`` rigid contacts."""
        newton = self._nt
        self.model.rigid_contact_max = self._capacity
        self._pipeline = newton.CollisionPipeline(self.model, rigid_contact_max=self._capacity)
        self.contacts = self._pipeline.contacts()
        self.solver = newton.solvers.SolverKamino(self.model)

    @staticmethod
    def _piece_points(piece: CollisionPiece) -> np.ndarray:
        """The piece's vertices (k, 3) in the link frame, m."""
        o = piece.origin
        if piece.kind == "hull":
            return _apply(o, piece.points)
        if piece.kind == "box":
            h = 0.5 * np.asarray(piece.size, float)
            corners = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)]) * h
            return _apply(o, corners)
        r = float(piece.radius)
        if piece.kind == "sphere":
            return _apply(o, np.array([[0, 0, -r], [0, 0, r], [r, 0, 0], [-r, 0, 0], [0, r, 0], [0, -r, 0]], float))
        hl = 0.5 * float(piece.length)
        ang = np.linspace(0, 2 * np.pi, 16, endpoint=False)
        ring = np.column_stack([r * np.cos(ang), r * np.sin(ang), np.zeros_like(ang)])
        return _apply(o, np.vstack([ring + [0, 0, hl], ring - [0, 0, hl]]))

    def _add_shape(self, b, body: int, piece: CollisionPiece, cfg) -> None:
        wp, newton = self._wp, self._nt
        xf = _wp_transform(wp, piece.origin)
        if piece.kind == "hull":
            v, t = convex_hull_mesh(piece.points)
            b.add_shape_convex_hull(body, xform=xf, mesh=newton.Mesh(v.astype(np.float32), t.ravel().astype(np.int32)), cfg=cfg)
        elif piece.kind == "box":
            hx, hy, hz = (0.5 * float(s) for s in piece.size)
            b.add_shape_box(body, xform=xf, hx=hx, hy=hy, hz=hz, cfg=cfg)
        elif piece.kind == "sphere":
            b.add_shape_sphere(body, xform=xf, radius=float(piece.radius), cfg=cfg)
        elif piece.kind == "cylinder":
            b.add_shape_cylinder(body, xform=xf, radius=float(piece.radius), half_height=0.5 * float(piece.length), cfg=cfg)

    # ------------------------------------------------------------------ joints
    def _refresh(self) -> None:
        self._nt.eval_fk(self.model, self.state0.joint_q, self.state0.joint_qd, self.state0)

    def set_joint_positions(self, q: dict[str, float], zero_velocity: bool = True) -> None:
        jq, jd = self.state0.joint_q.numpy(), self.state0.joint_qd.numpy()
        for name, v in q.items():
            if name in self._qadr:
                jq[self._qadr[name]] = float(v)
                if zero_velocity:
                    jd[self._dadr[name]] = 0.0
        self.state0.joint_q.assign(jq)
        self.state0.joint_qd.assign(jd)
        self._refresh()

    def joint_positions(self) -> dict[str, float]:
        jq = self.state0.joint_q.numpy()
        return {n: float(jq[a]) for n, a in self._qadr.items()}

    def joint_velocities(self) -> dict[str, float]:
        jd = self.state0.joint_qd.numpy()
        return {n: float(jd[a]) for n, a in self._dadr.items()}

    def joint_state(self, joint: str) -> tuple[float, float]:
        return float(self.state0.joint_q.numpy()[self._qadr[joint]]), float(self.state0.joint_qd.numpy()[self._dadr[joint]])

    def joint_axis(self, joint: str) -> np.ndarray:
        """The URDF axis (3,) in the child frame (the joint frame is the child's)."""
        if joint not in self._qadr:
            raise KeyError(joint)
        return np.asarray(self.urdf.joint(joint).axis, float)

    def apply_joint_effort(self, joint: str, effort: float) -> None:
        raise EngineUnsupported("newton: apply_joint_effort is not implemented")

    def drive_joint(self, joint: str, velocity: float, max_force: float) -> None:
        raise EngineUnsupported("newton: drive_joint is not implemented")

    def release_joint(self, joint: str) -> None:
        raise EngineUnsupported("newton: release_joint is not implemented")

    # ------------------------------------------------------------------- links
    def link_frame(self, link: str) -> tuple[np.ndarray, np.ndarray]:
        """The body's pose: Newton's body frame is the URDF link frame."""
        t = self.state0.body_q.numpy()[self._body[link]]
        x, y, z, w = (float(v) for v in t[3:7])
        return np.array(t[:3], float), np.array(quat_wxyz_matrix([w, x, y, z]))

    def link_collision_vertices(self, link: str) -> np.ndarray:
        return self._points[link].copy()

    def link_aabb(self, link: str) -> tuple[np.ndarray, np.ndarray]:
        pts = self._points[link]
        if not len(pts):
            p, _ = self.link_frame(link)
            return p.copy(), p.copy()
        p, r = self.link_frame(link)
        w = pts @ r.T + p
        return w.min(axis=0), w.max(axis=0)

    def link_has_collision(self, link: str) -> bool:
        return len(self._points[link]) > 0

    def link_masses(self) -> dict[str, float]:
        m = self.model.body_mass.numpy()
        return {n: float(m[i]) for n, i in self._body.items()}

    def link_distances(self, link_a: str, link_b: str, max_distance: float = 0.0) -> list[float]:
        raise EngineUnsupported("newton: link_distances is not implemented")

    def apply_link_force(self, link: str, force, point) -> None:
        raise EngineUnsupported("newton: apply_link_force is not implemented")

    # -------------------------------------------------------------------- root
    def root_pose(self) -> tuple[np.ndarray, np.ndarray]:
        t = self.state0.body_q.numpy()[self._body[self.urdf.root]]
        q = np.array(t[3:7], float)
        n = np.linalg.norm(q)
        return np.array(t[:3], float), (q / n if n > 0 else q)

    def set_root_pose(self, pos, orn_xyzw) -> None:
        """Teleport the root (free joint) and zero its velocity.

        Raises:
            EngineUnsupported: the root is fixed.
        """
        if self._fixed:
            raise EngineUnsupported("newton: the root of a fixed-base session cannot be moved")
        jq, jd = self.state0.joint_q.numpy(), self.state0.joint_qd.numpy()
        jq[0:3] = np.asarray(pos, float)
        jq[3:7] = np.asarray(orn_xyzw, float)
        jd[0:6] = 0.0
        self.state0.joint_q.assign(jq)
        self.state0.joint_qd.assign(jd)
        self._refresh()

    def set_root_velocity(self, linear, angular) -> None:
        raise EngineUnsupported("newton: set_root_velocity is not implemented")

    # ----------------------------------------------------------------- contact
    def self_penetration(self) -> tuple[float, list[ContactPair]]:
        """Phi from Newton's narrow phase at the current state: separation
        n . (p1 - p0) - (thickness0 + thickness1) per contact point."""
        c = self._query_contacts
        self._query.collide(self.state0, c)
        count = int(c.rigid_contact_count.numpy()[0])
        s0 = c.rigid_contact_shape0.numpy()[:count]
        s1 = c.rigid_contact_shape1.numpy()[:count]
        p0 = c.rigid_contact_point0.numpy()[:count]
        p1 = c.rigid_contact_point1.numpy()[:count]
        nrm = c.rigid_contact_normal.numpy()[:count]
        m0 = c.rigid_contact_margin0.numpy()[:count]
        m1 = c.rigid_contact_margin1.numpy()[:count]
        bq = self.state0.body_q.numpy()
        points = []
        for k in range(count):
            if self._ground_shape in (int(s0[k]), int(s1[k])):
                continue
            ba, bb = int(self._shape_body[s0[k]]), int(self._shape_body[s1[k]])
            if ba < 0 or bb < 0:
                continue
            wa = _body_point(bq[ba], p0[k])
            wb = _body_point(bq[bb], p1[k])
            d = float(np.dot(nrm[k], wb - wa)) - float(m0[k]) - float(m1[k])
            points.append((self._link_of[ba], self._link_of[bb], d))
        return penetration_sum(points)

    def ground_penetration(self) -> float:
        """Deepest collision vertex below z = 0 (m), from the geometry."""
        if not self.options.ground:
            return 0.0
        low = np.inf
        for name, pts in self._points.items():
            if len(pts):
                p, r = self.link_frame(name)
                low = min(low, float((pts @ r.T + p)[:, 2].min()))
        return max(0.0, -low) if np.isfinite(low) else 0.0

    # ---------------------------------------------------------------- snapshots
    def save_state(self) -> int:
        raise EngineUnsupported("newton: save_state is not implemented")

    def restore_state(self, handle: int) -> None:
        raise EngineUnsupported("newton: restore_state is not implemented")

    def discard_state(self, handle: int) -> None:
        raise EngineUnsupported("newton: discard_state is not implemented")

    # ----------------------------------------------------------------- dynamics
    def step(self, n: int = 1) -> None:
        for _ in range(int(n)):
            self.state0.clear_forces()
            self._pipeline.collide(self.state0, self.contacts)
            n_contacts = int(self.contacts.rigid_contact_count.numpy()[0])
            if n_contacts >= self._capacity:  # full: contacts may have been dropped; grow and redo
                self._capacity = _capacity_for(n_contacts)
                self.rebuilds += 1
                self._build_solver()
                self._pipeline.collide(self.state0, self.contacts)
            self.solver.step(self.state0, self.state1, self.control, self.contacts, self.dt)
            self.state0, self.state1 = self.state1, self.state0

    def held_physics(self) -> HeldPhysics:
        """What Newton's finalized model holds (:func:`held_physics_of_model`),
        joint positions from the current state."""
        dofs = {n: (self._qadr[n], self._dadr[n]) for n in self._qadr}
        return held_physics_of_model(self.model, self.state0.joint_q.numpy(), self._body, dofs, source="urdf")

    def close(self) -> None:
        self.solver = None
        self.model = None


#: Smallest rigid-contact capacity of the stepping pipeline and solver: Kamino's CPU cost grows with the
#: capacity, not with the contacts made (``docs/design/simulators.md``). The session sizes the capacity at
#: CONTACT_CAPACITY_HEADROOM times the contacts at the initial state (at least this), and grows it
#: (rebuilding the solver) whenever a step fills it, so no contact is ever dropped.
CONTACT_CAPACITY_MIN = 64
CONTACT_CAPACITY_HEADROOM = 4


def _capacity_for(n_contacts: int) -> int:
    """Rigid-contact capacity for ``n_contacts`` contacts: headroom x the
    count, rounded up to a power of two, at least :data:`CONTACT_CAPACITY_MIN`."""
    need = max(CONTACT_CAPACITY_MIN, CONTACT_CAPACITY_HEADROOM * int(n_contacts))
    return 1 << (need - 1).bit_length()


def _apply(pose: np.ndarray, pts: np.ndarray) -> np.ndarray:
    return np.asarray(pts, float) @ pose[:3, :3].T + pose[:3, 3]


def _body_point(t: np.ndarray, p: np.ndarray) -> np.ndarray:
    x, y, z, w = (float(v) for v in t[3:7])
    return np.array(quat_wxyz_matrix([w, x, y, z])) @ np.asarray(p, float) + np.asarray(t[:3], float)


def _wp_transform(wp, pose: np.ndarray):
    w, x, y, z = (float(v) for v in matrix_quat_wxyz(pose[:3, :3]))
    return wp.transform(wp.vec3(*map(float, pose[:3, 3])), wp.quat(x, y, z, w))


def _open(urdf_path: Path, options: SessionOptions) -> NewtonSession:
    return NewtonSession(urdf_path, options)


# Registering needs the packages: without them this module raises ImportError
# and the registry reports the engine as unavailable (an optional extra).
# Looked up, not imported: importing newton and warp takes seconds, and
# ``available_engines()`` asks every engine.
def _installed(package: str) -> bool:
    try:
        return importlib.util.find_spec(package) is not None
    except ValueError:  # sys.modules[package] is None: blocked
        return False


for _package in ("newton", "warp", "scipy"):
    if not _installed(_package):
        raise ImportError(f"No module named {_package!r} (pip install 'asset2sim[newton]')")

register_engine("newton", _open)
register_file_reader("newton", "usd", held_physics_of_usd)
