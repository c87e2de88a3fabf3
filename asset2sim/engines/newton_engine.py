"""Newton engine (NVIDIA Warp, on the CPU, solver Kamino) under the SPEC's
conventions, built from the URDF reading every engine shares
(:mod:`asset2sim.engines.loading`; ``docs/design/simulators.md``). The
queries the rest-stability, oscillation and breakaway checks need are answered
(joint efforts through ``Control.joint_f``, state snapshots); drives, link
distances, external forces and root velocities raise
:class:`~asset2sim.engines.base.EngineUnsupported`. Kamino holds the URDF's
Coulomb joint friction as a bounded constraint row per DOF (``joint_friction``,
N*m or N; Tsounis et al. 2025, arXiv:2504.19771). A fixed root and the links fixed
to it are welded to the world (static shapes); ``full_model``, every link a body,
answers the contact and mass queries. newton and warp (an optional
extra) are imported when a session opens or a USD is read back.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from asset2sim.engines.base import (ArrayJoints, ContactPair, HeldJoint, HeldLink, HeldPhysics, SessionDefaults,
                                    SessionOptions, penetration_sum, principal_moments, register_engine, register_file_reader,
                                    unsupported)
from asset2sim.engines.loading import (BOX_CORNERS, BULLET_DEFAULT_INERTIA, BULLET_DEFAULT_MASS, CONTACT_FRICTION, CollisionPiece,
                                       collision_pieces, read_urdf, transform_points)
from asset2sim.frames import matrix_quat_wxyz, quat_wxyz_matrix, quat_wxyz_to_xyzw, quat_xyzw_to_wxyz, translation_matrix
from asset2sim.mesh_io import convex_hull_mesh
from asset2sim.urdf import MOVABLE
from asset2sim.engines.step_budget import spend

#: Newton's default limit magnitude for an unlimited DOF (``ModelBuilder``'s 1e6) and above: read back as unlimited.
NEWTON_UNLIMITED = 1e6


def import_newton():
    """``(warp, newton)``, warp told to be quiet (ImportError: either is missing)."""
    import warp as wp

    wp.config.quiet = True
    import newton

    return wp, newton


class NewtonSession(ArrayJoints, SessionDefaults):
    """A :class:`~asset2sim.engines.base.SimSession` in Newton on the CPU;
    ``notes``: flat pieces made slabs (UrdfError: the URDF or a mesh cannot be read)."""

    engine = "newton"

    def __init__(self, urdf_path: Path, options: SessionOptions):
        wp, newton = import_newton()
        self._wp, self._nt = wp, newton
        self.options = options
        conv = options.conventions
        self.dt = conv.timestep
        self._use_urdf(read_urdf(urdf_path))
        pieces, self.notes = collision_pieces(self.urdf)
        self.link_names = self.urdf.tree_order()
        self._fixed = bool(options.fixed_base)
        poses = self._placed_poses(pieces)
        b = newton.ModelBuilder(gravity=(0.0, 0.0, conv.gravity if options.gravity else 0.0))
        # density 0: Newton would add each shape's mass to its body's
        cfg = newton.ModelBuilder.ShapeConfig(mu=CONTACT_FRICTION, density=0.0)
        self._add_bodies(b, pieces, poses, cfg)
        self._add_joints(b, poses)
        if options.ground:
            b.add_ground_plane(cfg=newton.ModelBuilder.ShapeConfig(mu=CONTACT_FRICTION))
        # every link a body: the model the contact and mass queries read (Phi between welded links included)
        self.full_model = b.finalize(device="cpu")
        self._full_body = dict(self._body)
        self._welded = self._weld_fixed_root(b, poses)
        self.model = b.finalize(device="cpu") if self._welded else self.full_model
        self._init_state()
        self._query = newton.CollisionPipeline(self.full_model, publish_capacity=False)  # sized from the initial contacts
        self._query_contacts = self._query.contacts()
        self._query_state = self.full_model.state()
        self._query.collide(self._full_state(), self._query_contacts)
        self._capacity = _capacity_for(int(self._query_contacts.rigid_contact_count.numpy()[0]))
        self.rebuilds = 0
        self._build_solver()
        self._ground_shape = self.full_model.shape_count - 1 if options.ground else -1
        self._shape_body = self.full_model.shape_body.numpy()
        self._link_of = {v: k for k, v in self._full_body.items()}

    # ------------------------------------------------------------- building
    def _placed_poses(self, pieces: dict[str, list[CollisionPiece]]) -> dict[str, np.ndarray]:
        """Every link's pose (4, 4) at the initial state, a free root lifted so
        the lowest collision vertex is on z = 0; sets ``_points`` (k, 3) per link."""
        poses = self.urdf.link_poses(self.options.initial_state)
        self._points = {name: np.vstack([self._piece_points(p) for p in pieces.get(name, [])] or [np.zeros((0, 3))])
                        for name in self.link_names}
        lows = [] if self._fixed else [transform_points(poses[n], v)[:, 2].min() for n, v in self._points.items() if len(v)]
        lift = -min(lows) if lows else 0.0
        return self.urdf.link_poses(self.options.initial_state, translation_matrix([0.0, 0.0, lift]))

    def _add_bodies(self, b, pieces: dict[str, list[CollisionPiece]], poses: dict[str, np.ndarray], cfg) -> None:
        """One body per link with the file's inertial and its shapes; sets ``_body`` (link -> index)."""
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
        """The root joint, every URDF joint (damping and spring as a drive) and
        the articulation; sets ``_joint_index`` (movable joint -> Newton index)."""
        wp, root = self._wp, self.urdf.root
        root_kw = dict(parent_xform=_wp_transform(wp, poses[root]), label="root")
        joints = [b.add_joint_fixed(-1, self._body[root], **root_kw) if self._fixed else b.add_joint_free(self._body[root], **root_kw)]
        self._joint_index: dict[str, int] = {}
        for j in self.urdf.joints:
            kw = dict(parent_xform=_wp_transform(wp, j.origin), label=j.name)
            parent, child = self._body[j.parent], self._body[j.child]
            if j.type in MOVABLE:
                spring = self.options.springs.get(j.name)
                lo, hi = j.lower, j.upper
                add = b.add_joint_prismatic if j.type == "prismatic" else b.add_joint_revolute
                idx = add(parent, child, **kw, axis=wp.vec3(*map(float, j.axis)), friction=float(j.friction), target_kd=float(j.damping),
                          target_ke=float(spring.stiffness) if spring else 0.0, target_pos=float(spring.reference) if spring else 0.0,
                          target_vel=0.0, limit_lower=float(lo) if np.isfinite(lo) else None,
                          limit_upper=float(hi) if np.isfinite(hi) else None)
                self._joint_index[j.name] = idx
            else:
                idx = b.add_joint_fixed(parent, child, **kw)
            joints.append(idx)
        b.add_articulation(joints)
        self._joint_ids = {j.name: idx for j, idx in zip(self.urdf.joints, joints[1:])}

    def _weld_fixed_root(self, b, poses: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        """A fixed root: the root and every link fixed to it, through fixed joints, merged into the world
        (``ModelBuilder.collapse_fixed_joints``; the other fixed joints kept), as a reduced-coordinate engine
        holds a fixed base. Kamino simulates every body in maximal coordinates and would hold the welds as
        constraint rows solved iteratively, which a chain world -> root link -> mounted body does not keep
        rigid under a part's load: the mounted body tilts and the parts on it slide (``docs/design/simulators.md``,
        Newton; ``benchmarks/newton_fixed_root_sag.py``). Remaps ``_body`` and ``_joint_index`` to the welded
        model; returns the welded links' poses (link -> (4, 4)), empty with a free root or where no body would
        remain."""
        if not self._fixed:
            return {}
        welded = {self.urdf.root}
        for name in self.link_names:  # the tree order: a parent before its children
            pj = self.urdf.parent_joint(name)
            if pj is not None and pj.type not in MOVABLE and pj.parent in welded:
                welded.add(name)
        if len(welded) == len(self.link_names):
            return {}
        keep = [self._joint_ids[j.name] for j in self.urdf.joints if j.type not in MOVABLE and j.child not in welded]
        info = b.collapse_fixed_joints(joints_to_keep=keep)
        self._body = {n: info["body_remap"][i] for n, i in self._body.items() if n not in welded}
        self._joint_index = {n: info["joint_remap"][i] for n, i in self._joint_index.items()}
        names = [n for n in self.link_names if n in welded]
        self.notes.append(f"fixed root: {', '.join(names)} welded to the world (collapse_fixed_joints), "
                          "not simulated as bodies held by fixed-joint rows")
        return {n: poses[n] for n in names}

    def _init_state(self) -> None:
        """Joint addresses (``_qadr``, ``_dadr``), initial positions, states, control and body poses."""
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
        self._effort = np.zeros(self.model.joint_dof_count, dtype=np.float32)  # N*m or N per DOF, the next step's
        self._applied = False
        self._states: dict[int, tuple[dict[str, np.ndarray], np.ndarray, bool]] = {}
        self._nt.eval_fk(self.model, self.model.joint_q, self.model.joint_qd, self.state0)

    def _build_solver(self) -> None:
        """The stepping collision pipeline and the Kamino solver for ``_capacity`` contacts."""
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
            return transform_points(o, piece.points)
        if piece.kind == "box":
            return transform_points(o, BOX_CORNERS * (0.5 * np.asarray(piece.size, float)))
        r = float(piece.radius)
        if piece.kind == "sphere":
            return transform_points(o, np.array([[0, 0, -r], [0, 0, r], [r, 0, 0], [-r, 0, 0], [0, r, 0], [0, -r, 0]], float))
        hl = 0.5 * float(piece.length)
        ang = np.linspace(0, 2 * np.pi, 16, endpoint=False)
        ring = np.column_stack([r * np.cos(ang), r * np.sin(ang), np.zeros_like(ang)])
        return transform_points(o, np.vstack([ring + [0, 0, hl], ring - [0, 0, hl]]))

    def _add_shape(self, b, body: int, piece: CollisionPiece, cfg) -> None:
        xf = _wp_transform(self._wp, piece.origin)
        if piece.kind == "hull":
            v, t = convex_hull_mesh(piece.points)
            b.add_shape_convex_hull(body, xform=xf, mesh=self._nt.Mesh(v.astype(np.float32), t.ravel().astype(np.int32)), cfg=cfg)
        elif piece.kind == "box":
            hx, hy, hz = (0.5 * float(s) for s in piece.size)
            b.add_shape_box(body, xform=xf, hx=hx, hy=hy, hz=hz, cfg=cfg)
        elif piece.kind == "sphere":
            b.add_shape_sphere(body, xform=xf, radius=float(piece.radius), cfg=cfg)
        elif piece.kind == "cylinder":
            b.add_shape_cylinder(body, xform=xf, radius=float(piece.radius), half_height=0.5 * float(piece.length), cfg=cfg)

    # ------------------------------------------------------------------ joints
    def _joint_q(self) -> np.ndarray:
        return self.state0.joint_q.numpy()

    def _joint_qd(self) -> np.ndarray:
        return self.state0.joint_qd.numpy()

    def _put_joints(self, jq: np.ndarray, jd: np.ndarray) -> None:
        """Set the state's joint coordinates and velocities, and the bodies' poses."""
        self.state0.joint_q.assign(jq)
        self.state0.joint_qd.assign(jd)
        self._nt.eval_fk(self.model, self.state0.joint_q, self.state0.joint_qd, self.state0)

    def joint_axis(self, joint: str) -> np.ndarray:
        if joint not in self._qadr:
            raise KeyError(joint)
        return self.urdf.joint(joint).axis

    # ------------------------------------------------------------------- links
    def link_frame(self, link: str) -> tuple[np.ndarray, np.ndarray]:
        if link in self._welded:
            pose = self._welded[link]
            return pose[:3, 3].copy(), pose[:3, :3].copy()
        return _body_frame(self.state0.body_q.numpy()[self._body[link]])

    def link_collision_vertices(self, link: str) -> np.ndarray:
        return self._points[link].copy()

    def link_aabb(self, link: str) -> tuple[np.ndarray, np.ndarray]:
        return self._world_bounds(link, self._points[link])

    def link_has_collision(self, link: str) -> bool:
        return len(self._points[link]) > 0

    def link_masses(self) -> dict[str, float]:
        m = self.full_model.body_mass.numpy()
        return {n: float(m[i]) for n, i in self._full_body.items()}

    # -------------------------------------------------------------------- root
    def root_pose(self) -> tuple[np.ndarray, np.ndarray]:
        if self.urdf.root in self._welded:
            pos, rot = self.link_frame(self.urdf.root)
            return pos, quat_wxyz_to_xyzw(matrix_quat_wxyz(rot))
        t = self.state0.body_q.numpy()[self._body[self.urdf.root]]
        q = np.array(t[3:7], float)
        n = np.linalg.norm(q)
        return np.array(t[:3], float), (q / n if n > 0 else q)

    def set_root_pose(self, pos, orn_xyzw) -> None:
        """Teleport the root and zero its velocity (EngineUnsupported: fixed root)."""
        self._movable_root()
        jq, jd = self._joint_q(), self._joint_qd()
        jq[0:3] = np.asarray(pos, float)
        jq[3:7] = np.asarray(orn_xyzw, float)
        jd[0:6] = 0.0
        self._put_joints(jq, jd)

    # ----------------------------------------------------------------- contact
    def self_penetration(self) -> tuple[float, list[ContactPair]]:
        """Phi from Newton's narrow phase: separation n . (p1 - p0) - (margin0 + margin1) per point."""
        c = self._query_contacts
        state = self._full_state()
        self._query.collide(state, c)
        count = int(c.rigid_contact_count.numpy()[0])
        s0, s1, p0, p1, nrm, m0, m1 = (getattr(c, f"rigid_contact_{field}").numpy()[:count]
                                       for field in ("shape0", "shape1", "point0", "point1", "normal", "margin0", "margin1"))
        bq = state.body_q.numpy()
        points = []
        for k in range(count):
            if self._ground_shape in (int(s0[k]), int(s1[k])):
                continue
            ba, bb = int(self._shape_body[s0[k]]), int(self._shape_body[s1[k]])
            if ba < 0 or bb < 0:
                continue
            d = float(np.dot(nrm[k], _body_point(bq[bb], p1[k]) - _body_point(bq[ba], p0[k]))) - float(m0[k]) - float(m1[k])
            points.append((self._link_of[ba], self._link_of[bb], d))
        return penetration_sum(points)

    def _full_state(self):
        """A state of :attr:`full_model` with every link's body where the session's link is (welded ones included)."""
        if self.full_model is self.model:
            return self.state0
        bq = np.zeros((len(self._full_body), 7), np.float32)
        for name, i in self._full_body.items():
            p, r = self.link_frame(name)
            bq[i] = (*p, *quat_wxyz_to_xyzw(matrix_quat_wxyz(r)))
        self._query_state.body_q.assign(bq)
        return self._query_state

    def ground_penetration(self) -> float:
        """Deepest collision vertex below z = 0 (m), from the geometry."""
        lows = [float(self.link_aabb(name)[0][2]) for name, pts in self._points.items() if len(pts)]
        return max(0.0, -min(lows)) if self.options.ground and lows else 0.0

    # ----------------------------------------------------------------- dynamics
    def apply_joint_effort(self, joint: str, effort: float) -> None:
        """Generalized force (N*m or N) on a movable joint for the next step only: Newton's ``Control.joint_f``
        at the joint's DOF, which Kamino adds to the joint's dynamics as ``tau_j`` (KeyError: not a movable joint).
        Efforts on one joint before a step add up, as in the other engines."""
        self._effort[self._dadr[joint]] += float(effort)
        self._applied = True

    def save_state(self) -> int:
        """Snapshot every array of the current ``newton.State``: joint and body coordinates and velocities, and the
        arrays Kamino keeps on the state between steps (previous joint coordinates, the joint constraints'
        multipliers that warm-start the next solve, the total body wrenches); the pending joint efforts too."""
        return self._keep_state(({k: v.numpy().copy() for k, v in _state_arrays(self.state0, self._wp).items()},
                                 self._effort.copy(), self._applied))

    def restore_state(self, handle: int) -> None:
        """Return to a snapshot of :meth:`save_state` (KeyError: an unknown or discarded handle)."""
        arrays, effort, applied = self._states[handle]
        current = _state_arrays(self.state0, self._wp)
        for k, v in arrays.items():
            if k in current and current[k].numpy().shape == v.shape:  # (n, 7) of a (n,) transform array
                current[k].assign(v)
        self._effort[:] = effort
        self._applied = applied

    def step(self, n: int = 1) -> None:
        """Advance ``n`` steps of :attr:`dt` s; efforts of :meth:`apply_joint_effort` act on the first only."""
        spend(n)  # the refine's one budget of steps (asset2sim.engines.step_budget)
        for _ in range(int(n)):
            if self._applied:
                self.control.joint_f.assign(self._effort)
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
            if self._applied:  # efforts act for one step
                self._effort[:] = 0.0
                self.control.joint_f.zero_()
                self._applied = False

    def held_physics(self) -> HeldPhysics:
        dofs = {n: (self._qadr[n], self._dadr[n]) for n in self._qadr}
        held = held_physics_of_model(self.model, self.state0.joint_q.numpy(), self._body, dofs, source="urdf")
        if self._welded:  # as built, before the weld: not simulated
            held.links.update(_held_links(self.full_model, {n: self._full_body[n] for n in self._welded}))
            held.welded_to_world = list(self._welded)
        return held

    def close(self) -> None:
        self.solver = None
        self.model = self.full_model = None


for _query in ("drive_joint", "release_joint", "link_distances", "apply_link_force", "set_root_velocity"):
    setattr(NewtonSession, _query, unsupported(f"newton: {_query} is not implemented"))

#: Smallest rigid-contact capacity of the stepping pipeline and solver (Kamino's CPU cost grows with the
#: capacity); the session sizes it at CONTACT_CAPACITY_HEADROOM x the initial contacts and grows it
#: (rebuilding the solver) whenever a step fills it, so no contact is dropped.
CONTACT_CAPACITY_MIN = 64
CONTACT_CAPACITY_HEADROOM = 4


def _capacity_for(n_contacts: int) -> int:
    """Headroom x ``n_contacts``, rounded up to a power of two, at least :data:`CONTACT_CAPACITY_MIN`."""
    need = max(CONTACT_CAPACITY_MIN, CONTACT_CAPACITY_HEADROOM * int(n_contacts))
    return 1 << (need - 1).bit_length()


def _state_arrays(state, wp) -> dict:
    """Name -> warp array of every array a ``newton.State`` holds, the attributes a solver adds to it included
    (Kamino: ``joint_q_prev``, ``joint_lambdas``, ``joint_lambdas_f``, ...)."""
    return {k: v for k, v in vars(state).items() if isinstance(v, wp.array)}


def _body_frame(t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Position (3,) m and rotation (3, 3) of a Warp transform (7,) p, x, y, z, w."""
    return np.array(t[:3], float), np.array(quat_wxyz_matrix(quat_xyzw_to_wxyz(t[3:7])))


def _body_point(t: np.ndarray, p: np.ndarray) -> np.ndarray:
    pos, rot = _body_frame(t)
    return rot @ np.asarray(p, float) + pos


def _wp_transform(wp, pose: np.ndarray):
    return wp.transform(wp.vec3(*map(float, pose[:3, 3])), wp.quat(*quat_wxyz_to_xyzw(matrix_quat_wxyz(pose[:3, :3]))))


def _held_links(model, bodies: dict[str, int]) -> dict[str, HeldLink]:
    """Mass, COM and principal moments of the bodies (link -> body index) of a finalized ``newton.Model``."""
    mass, com, inertia = model.body_mass.numpy(), model.body_com.numpy(), model.body_inertia.numpy()
    return {n: HeldLink(mass=float(mass[i]), com=np.array(com[i], float), principal=principal_moments(inertia[i]))
            for n, i in bodies.items()}


def held_physics_of_model(model, joint_q: np.ndarray, bodies: dict[str, int], dofs: dict[str, tuple[int, int]],
                          source: str) -> HeldPhysics:
    """Per-body and per-joint physics of a finalized ``newton.Model`` (limits
    of +-:data:`NEWTON_UNLIMITED` or more read as unlimited; reference None
    without stiffness). ``bodies``: link -> body index; ``dofs``: joint ->
    (q index, dof index)."""
    links = _held_links(model, bodies)
    lo, hi = model.joint_limit_lower.numpy(), model.joint_limit_upper.numpy()
    kd, fr, ke = model.joint_target_kd.numpy(), model.joint_friction.numpy(), model.joint_target_ke.numpy()
    tp = model.joint_target_q.numpy()  # per coordinate, like joint_q
    joints = {}
    for n, (qa, da) in dofs.items():
        lo_v = float(lo[da]) if abs(float(lo[da])) < NEWTON_UNLIMITED else -np.inf
        hi_v = float(hi[da]) if abs(float(hi[da])) < NEWTON_UNLIMITED else np.inf
        k = float(ke[da])
        joints[n] = HeldJoint(lower=lo_v, upper=hi_v, damping=float(kd[da]), friction=float(fr[da]), stiffness=k,
                              reference=float(tp[qa]) if k != 0.0 else None, position=float(joint_q[qa]))
    how = {"mass, com, inertia": "Model.body_mass, body_com, body_inertia", "limits": "joint_limit_lower/upper",
           "damping, friction, spring": "joint_target_kd, joint_friction, joint_target_ke / joint_target_q",
           "position": "joint_q"}
    return HeldPhysics(engine="newton", source=source, links=links, joints=joints, how=how)


def held_physics_of_usd(path: Path, links: list[str] | None = None, joints: list[str] | None = None) -> HeldPhysics:
    """Load a USD of ``asset2sim export --format usd`` with Newton's importer
    (``ModelBuilder.add_usd``) and read back what it holds, by the URDF names
    stored in ``asset2sim:name`` (``links`` and ``joints`` are not needed).

    Raises:
        ImportError: newton or usd-core is missing.
        ValueError: a body or joint of the model has no ``asset2sim:name``.
    """
    from pxr import Usd

    wp, newton = import_newton()
    stage = Usd.Stage.Open(str(path))
    names = {str(prim.GetPath()): str(a.Get()) for prim in stage.Traverse()
             if (a := prim.GetAttribute("asset2sim:name")) and a.HasAuthoredValue()}
    b = newton.ModelBuilder()
    b.add_usd(str(path))
    model = b.finalize(device="cpu")

    def urdf_name(label: str, what: str) -> str:
        if label not in names:
            raise ValueError(f"{path}: Newton {what} {label!r} has no asset2sim:name")
        return names[label]

    bodies = {urdf_name(lab, "body"): i for i, lab in enumerate(b.body_label)}
    qs, ds, jt = model.joint_q_start.numpy(), model.joint_qd_start.numpy(), model.joint_type.numpy()
    movable = {int(newton.JointType.REVOLUTE), int(newton.JointType.PRISMATIC)}
    dofs = {urdf_name(lab, "joint"): (int(qs[i]), int(ds[i])) for i, lab in enumerate(b.joint_label) if int(jt[i]) in movable}
    return held_physics_of_model(model, model.joint_q.numpy(), bodies, dofs, source=f"usd ({Path(path).name}, add_usd)")


register_engine("newton", NewtonSession)
register_file_reader("newton", "usd", held_physics_of_usd)
