"""PhysX engine (SAPIEN 3 on the CPU, physics only) under the SPEC's
conventions, built from the URDF reading every engine shares
(:mod:`asset2sim.engines.loading`); how each convention is met and what stays
different: ``docs/design/simulators.md``.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from asset2sim.engines.quiet import startup_quiet

with startup_quiet():
    import sapien
    from sapien import physx

from asset2sim.engines.base import (ArrayJoints, ContactPair, HeldJoint, HeldLink, HeldPhysics, SessionDefaults, SessionOptions,
                                    penetration_sum, register_engine, unsupported)
from asset2sim.engines.loading import (BULLET_DEFAULT_INERTIA, BULLET_DEFAULT_MASS, CONTACT_FRICTION, collision_pieces,
                                       link_friction, principal_axes, read_urdf)
from asset2sim.frames import matrix_quat_wxyz, quat_wxyz_to_xyzw, quat_xyzw_to_wxyz, rigid_matrix
from asset2sim.engines.passive_joints import FRICTION_DRIVE_DAMPING, PassiveJoints
from asset2sim.engines.step_budget import spend

#: Bullet's default linear and angular velocity damping of multibody links (1/s).
BULLET_LINK_DAMPING = 0.04
#: PGS, not SAPIEN's default TGS (``docs/design/simulators.md``).
ENABLE_TGS = False
#: Solver iterations (position, velocity): ManiSkill 3's default ``SceneConfig``.
SOLVER_ITERATIONS = (15, 1)
#: Contact offset (m) of every link's shapes while the contacts are probed (:meth:`PhysXSession.self_penetration`): a
#: penetration is a negative separation, which PhysX finds at any offset, while at SAPIEN's default 0.01 m, larger
#: than the shapes, its contacts between a generated lighter's 4 mm flint-wheel pieces and its lid's 1 mm walls read
#: -15 mm that PyBullet and the geometry do not have (``docs/design/simulators.md``); PhysX asks only that the
#: contact offset exceed the rest offset (0 here; PhysX 5 guide, "Advanced Collision Detection").
PROBE_CONTACT_OFFSET = 0.001


class PhysXError(RuntimeError):
    """SAPIEN/PhysX cannot build the asset (names the file and the part)."""


def _pose(t: np.ndarray) -> "sapien.Pose":
    t = np.asarray(t, float)
    return sapien.Pose(p=t[:3, 3].astype(np.float32), q=matrix_quat_wxyz(t[:3, :3]).astype(np.float32))


def _axis_frame(axis: np.ndarray) -> np.ndarray:
    """(4, 4) rotation whose x axis is ``axis`` (PhysX joints move along/about x)."""
    a = np.asarray(axis, float)
    a = a / np.linalg.norm(a)
    ref = np.array([0.0, 0.0, 1.0]) if abs(a[0]) > 0.9 else np.array([1.0, 0.0, 0.0])
    b = np.cross(a, ref)
    b /= np.linalg.norm(b)
    return rigid_matrix(np.column_stack([a, b, np.cross(a, b)]))


def _hull_vertices(shape, pose: np.ndarray) -> np.ndarray:
    """Vertices (k, 3) m of a cooked convex mesh ``shape``, scaled, in the frame where its pose is ``pose`` (4, 4)."""
    v = np.asarray(shape.get_vertices(), float) * np.asarray(shape.get_scale(), float)
    return v @ pose[:3, :3].T + pose[:3, 3]


def new_scene(gravity: float = -9.81, timestep: float = 1.0 / 240.0) -> "sapien.Scene":
    """A SAPIEN scene of its own CPU PhysX system: ``gravity`` m/s^2 along z,
    PGS, time step ``timestep`` s (SAPIEN's global configuration kept)."""
    old = physx.get_scene_config()
    cfg = physx.PhysxSceneConfig()
    cfg.gravity = np.array([0.0, 0.0, gravity], np.float32)
    cfg.enable_tgs = ENABLE_TGS
    physx.set_scene_config(cfg)
    try:
        system = physx.PhysxCpuSystem()
    finally:
        physx.set_scene_config(old)
    scene = sapien.Scene([system])
    scene.set_timestep(timestep)
    return scene


def link_inertia(urdf, name: str, urdf_path: Path, notes: list[str]):
    """Mass (kg), COM pose on the principal axes and principal moments (3,)
    kg*m^2 of link ``name`` of ``urdf`` (PyBullet's default without ``<inertial>``,
    noted in ``notes``). Raises PhysXError: a mass or principal moment not positive."""
    ine = urdf.links[name].inertial
    if ine is None:
        notes.append(f"link {name!r} has no <inertial>: given PyBullet's {BULLET_DEFAULT_MASS} kg, unit inertia")
        return BULLET_DEFAULT_MASS, sapien.Pose(), np.array(BULLET_DEFAULT_INERTIA)
    moments, axes = principal_axes(ine.inertia_in_link_axes())
    if ine.mass <= 0 or moments.min() <= 0:
        raise PhysXError(f"{urdf_path}: link {name!r} has mass {ine.mass} and principal moments {moments}: not positive")
    return ine.mass, _pose(rigid_matrix(axes, ine.com())), moments


def fill_articulation_builder(builder, urdf, urdf_path: Path, *, fixed_base: bool, notes: list[str]):
    """Add every link of ``urdf`` (an :class:`~asset2sim.urdf.UrdfModel` read from ``urdf_path``) to a SAPIEN
    (or ManiSkill) articulation ``builder`` in tree order: its joint (PhysX's x axis along the URDF axis, the
    URDF limits, no joint friction or damping: :class:`PassiveJoints` carries them), its mass and inertia
    (:func:`link_inertia`), the root fixed or free. Collision shapes are attached to the built components
    (:func:`attach_collision_shapes`). Returns ``builder``."""
    link_builders = {}
    for name in urdf.tree_order():
        pj = urdf.parent_joint(name)
        lb = builder.create_link_builder(link_builders[pj.parent] if pj else None)
        link_builders[name] = lb
        lb.set_name(name)
        lb.set_joint_name(pj.name if pj else "")
        if pj is None:
            lb.set_joint_properties("fixed" if fixed_base else "undefined", [], sapien.Pose(), sapien.Pose())
        else:
            ax = _axis_frame(pj.axis)
            kind = {"revolute": "revolute_unwrapped", "continuous": "revolute", "prismatic": "prismatic", "fixed": "fixed"}[pj.type]
            limits = [] if pj.type == "fixed" else [[pj.lower, pj.upper]]
            lb.set_joint_properties(kind, limits, _pose(pj.origin @ ax), _pose(ax), 0.0, 0.0)
        mass, com_pose, moments = link_inertia(urdf, name, urdf_path, notes)
        lb.set_mass_and_inertia(float(mass), com_pose, np.asarray(moments, np.float32))
    return builder


def attach_collision_shapes(comp, urdf, pieces: list, urdf_path: Path, notes: list[str]) -> None:
    """Cook a link's collision pieces (:func:`~asset2sim.engines.loading.collision_pieces`) into its PhysX
    component ``comp`` (named as the URDF link) with PyBullet's contact friction and link damping; an uncookable
    piece is skipped with a note. Raises PhysXError: none of the link's pieces could be cooked."""
    name = comp.name
    lmu = link_friction(urdf, name)
    mat = physx.PhysxMaterial(lmu, lmu, 0.0)
    cooked = 0
    for p in pieces:
        local = p.origin
        try:
            if p.kind == "hull":
                shape = physx.PhysxCollisionShapeConvexMesh(np.asarray(p.points, np.float32), np.ones(3, np.float32), mat)
            elif p.kind == "box":
                shape = physx.PhysxCollisionShapeBox(np.asarray(p.size, np.float32) / 2, mat)
            elif p.kind == "sphere":
                shape = physx.PhysxCollisionShapeSphere(float(p.radius), mat)
            else:  # cylinder: URDF axis z, PhysX axis x
                shape = physx.PhysxCollisionShapeCylinder(float(p.radius), float(p.length) / 2, mat)
                local = p.origin @ _axis_frame(np.array([0.0, 0.0, 1.0]))
        except RuntimeError as exc:  # PhysX could not cook the hull
            notes.append(f"link {name!r} collision {p.collision} group {p.group}: PhysX could not cook it ({exc}); skipped")
            continue
        shape.local_pose = _pose(local)
        shape.set_collision_groups([1, 1, 0, 0])
        shape.set_rest_offset(0.0)
        comp.attach(shape)
        cooked += 1
    if pieces and not cooked:
        raise PhysXError(f"{urdf_path}: no collision shape of link {name!r} could be cooked by PhysX")
    comp.set_linear_damping(BULLET_LINK_DAMPING)
    comp.set_angular_damping(BULLET_LINK_DAMPING)


def configure_articulation(art) -> None:
    """A built ``PhysxArticulation`` as the checks step it: never asleep, :data:`SOLVER_ITERATIONS`."""
    art.set_sleep_threshold(0.0)
    art.set_solver_position_iterations(SOLVER_ITERATIONS[0])
    art.set_solver_velocity_iterations(SOLVER_ITERATIONS[1])


class PhysXSession(ArrayJoints, SessionDefaults):
    """A :class:`~asset2sim.engines.base.SimSession` in PhysX through SAPIEN 3:
    a CPU scene of its own, or (``scene``) the caller's, left as it is
    (``ground`` False: no plane added to it); ``notes``: what had to change
    (UrdfError; PhysXError: a mass or moment not positive, a link with no cookable shape)."""

    engine = "physx"

    def __init__(self, urdf_path: Path, options: SessionOptions, scene=None, ground: bool = True):
        self.options = options
        self.dt = options.conventions.timestep
        self._use_urdf(read_urdf(urdf_path))
        pieces, self.notes = collision_pieces(self.urdf)
        self._owns_scene = scene is None
        if scene is None:
            self.scene = new_scene(options.conventions.gravity if options.gravity else 0.0, self.dt)
            self.system = self.scene.physx_system
        else:
            self.scene, self.system, self.dt = scene, scene.physx_system, float(scene.get_timestep())
        self.ground = self._add_ground() if options.ground and (self._owns_scene or ground) else None
        builder = fill_articulation_builder(self.scene.create_articulation_builder(), self.urdf, urdf_path,
                                            fixed_base=options.fixed_base, notes=self.notes)
        self._add_articulation(builder, pieces, urdf_path)
        self.link_names = list(self.links)
        self._states: dict[int, tuple] = {}
        self._effort = None
        self._passive_drives(urdf_path)
        self.set_joint_positions(options.initial_state)
        if options.ground and not options.fixed_base:
            self.place_on_ground()

    # --------------------------------------------------------------- building
    def _add_ground(self):
        """The static ground plane z = 0 (its component), contact friction 0.25."""
        ent = sapien.Entity()
        ent.name = "ground"
        comp = physx.PhysxRigidStaticComponent()
        plane = physx.PhysxCollisionShapePlane(physx.PhysxMaterial(CONTACT_FRICTION, CONTACT_FRICTION, 0.0))
        # PhysX planes face +x; turn the normal to +z.
        plane.local_pose = sapien.Pose(q=[math.sqrt(0.5), 0.0, -math.sqrt(0.5), 0.0])
        comp.attach(plane)
        ent.add_component(comp)
        self.scene.add_entity(ent)
        self._ground_entity = ent
        return comp

    def _add_articulation(self, builder, pieces: dict, urdf_path: Path) -> None:
        """Build the articulation with its collision shapes into the scene (``links``, ``art``)."""
        entities = builder.build_entities(fix_root_link=self.options.fixed_base)
        self.links = {}
        for ent in entities:
            comp = ent.find_component_by_type(physx.PhysxArticulationLinkComponent)
            self.links[comp.name] = comp
            attach_collision_shapes(comp, self.urdf, pieces[comp.name], urdf_path, self.notes)
        for ent in entities:
            self.scene.add_entity(ent)
        self._entities = list(entities)
        self.art = next(iter(self.links.values())).articulation
        configure_articulation(self.art)

    def _passive_drives(self, urdf_path: Path) -> None:
        """Joint tables and each movable joint's passive zero-velocity drive
        (PhysXError: PhysX built other joints than the URDF's movable ones)."""
        active = [j.name for j in self.art.active_joints]
        if sorted(active) != sorted(self.joint_names):
            raise PhysXError(f"{urdf_path}: PhysX built joints {active}, the URDF has {self.joint_names}")
        self._index = self._qadr = self._dadr = {n: i for i, n in enumerate(active)}
        self._joints = list(self.art.active_joints)
        self._passive = PassiveJoints.from_urdf(self.urdf, self.options.springs, active)
        self._passive.configure(self._joints)
        self._drive: dict[int, tuple[float, float]] = {}  # joint index -> (target velocity, force limit beyond friction)

    # ------------------------------------------------------------------ state
    def _joint_q(self) -> np.ndarray:
        return np.asarray(self.art.get_qpos(), np.float32).copy()

    def _joint_qd(self) -> np.ndarray:
        return np.asarray(self.art.get_qvel(), np.float32).copy()

    def _put_joints(self, q: np.ndarray, qd: np.ndarray) -> None:
        self.art.set_qpos(q)
        self.art.set_qvel(qd)

    def joint_axis(self, joint: str) -> np.ndarray:
        """The URDF axis (3,) (PhysX's joint x axis is built on it)."""
        if joint not in self._index:
            raise KeyError(joint)
        return self.urdf.joint(joint).axis

    def apply_joint_effort(self, joint: str, effort: float) -> None:
        """Added to the spring forces of the next step."""
        if self._effort is None:
            self._effort = np.zeros(len(self._joints))
        self._effort[self._index[joint]] += float(effort)

    def drive_joint(self, joint: str, velocity: float, max_force: float) -> None:
        """The passive drive gets target ``velocity``, force limit ``max_force + friction (+ damping * |qdot|)``."""
        i = self._index[joint]
        self._drive[i] = (float(velocity), float(max(max_force, 0.0)))
        self._set_drive(i, abs(float(self.art.get_qvel()[i])))

    def release_joint(self, joint: str) -> None:
        i = self._index[joint]
        self._drive.pop(i, None)
        self._set_drive(i, abs(float(self.art.get_qvel()[i])))

    def _set_drive(self, i: int, qd_abs: float) -> None:
        v, extra = self._drive.get(i, (0.0, 0.0))
        p = self._passive
        self._joints[i].set_drive_properties(0.0, FRICTION_DRIVE_DAMPING, float(p.friction[i] + p.damping[i] * qd_abs + extra), "force")
        self._joints[i].set_drive_velocity_target(v)

    def set_root_velocity(self, linear, angular) -> None:
        self._movable_root()
        self.art.set_root_linear_velocity(np.asarray(linear, np.float32))
        self.art.set_root_angular_velocity(np.asarray(angular, np.float32))

    # ------------------------------------------------------------------ links
    def link_frame(self, link: str) -> tuple[np.ndarray, np.ndarray]:
        t = self.links[link].get_pose().to_transformation_matrix().astype(float)
        return t[:3, 3].copy(), t[:3, :3].copy()

    def link_collision_vertices(self, link: str) -> np.ndarray:
        """Vertices (k, 3) m of the link's cooked convex meshes, link frame."""
        out = [_hull_vertices(shape, shape.get_local_pose().to_transformation_matrix())
               for shape in self.links[link].get_collision_shapes() if isinstance(shape, physx.PhysxCollisionShapeConvexMesh)]
        return np.concatenate(out) if out else np.zeros((0, 3))

    def link_aabb(self, link: str) -> tuple[np.ndarray, np.ndarray]:
        """Bounds of the cooked hull vertices (PhysX's tight box for primitives)."""
        comp = self.links[link]
        v = self.link_collision_vertices(link)
        lo, hi = self._world_bounds(link, v) if len(v) else (np.full(3, np.inf), np.full(3, -np.inf))
        if any(not isinstance(sh, physx.PhysxCollisionShapeConvexMesh) for sh in comp.get_collision_shapes()):
            box = comp.compute_global_aabb_tight()
            lo, hi = np.minimum(lo, np.asarray(box[0], float)), np.maximum(hi, np.asarray(box[1], float))
        return (lo, hi) if np.all(np.isfinite(lo)) else self._world_bounds(link, ())

    def link_has_collision(self, link: str) -> bool:
        return bool(self.links[link].get_collision_shapes())

    def link_masses(self) -> dict[str, float]:
        return {name: float(comp.get_mass()) for name, comp in self.links.items()}

    link_distances = unsupported("physx: no closest-point query between links (use pybullet or mujoco)")

    def apply_link_force(self, link: str, force, point) -> None:
        self.links[link].add_force_at_point(np.asarray(force, np.float32), np.asarray(point, np.float32))

    def root_pose(self) -> tuple[np.ndarray, np.ndarray]:
        pose = self.art.get_root_pose()
        return np.array(pose.p, float), quat_wxyz_to_xyzw(pose.q)

    def set_root_pose(self, pos, orn_xyzw) -> None:
        self.art.set_root_pose(sapien.Pose(p=np.asarray(pos, np.float32), q=quat_xyzw_to_wxyz(orn_xyzw).astype(np.float32)))
        self.art.set_root_linear_velocity(np.zeros(3, np.float32))
        self.art.set_root_angular_velocity(np.zeros(3, np.float32))

    def lowest_point(self) -> float:
        """Lowest z (m) of the articulation's cooked collision shapes (+inf if none)."""
        low = math.inf
        for comp in self.links.values():
            link_pose = comp.get_pose().to_transformation_matrix()
            for shape in comp.get_collision_shapes():
                if isinstance(shape, physx.PhysxCollisionShapeConvexMesh):
                    t = link_pose @ shape.get_local_pose().to_transformation_matrix()
                    low = min(low, float(_hull_vertices(shape, t)[:, 2].min()))
                else:
                    aabb = comp.compute_global_aabb_tight()
                    low = min(low, float(aabb[0][2]))
        return low

    def place_on_ground(self) -> float:
        """Lift the root so the lowest collision point touches z = 0; returns the shift (m)."""
        low = self.lowest_point()
        if not math.isfinite(low):
            return 0.0
        pos, orn = self.root_pose()
        self.set_root_pose(pos + np.array([0.0, 0.0, -low]), orn)
        return float(-low)

    # ---------------------------------------------------------------- contact
    def _probe_contacts(self):
        """Contacts at the current state (PhysX makes them only in a step): one step with every link's shapes at
        :data:`PROBE_CONTACT_OFFSET`, then the state and the offsets restored."""
        state = self._state()
        shapes = [sh for comp in self.links.values() for sh in comp.collision_shapes]
        offsets = [sh.get_contact_offset() for sh in shapes]
        for sh in shapes:
            sh.set_contact_offset(PROBE_CONTACT_OFFSET)
        try:
            self.art.set_qf(np.zeros(len(state[3]), np.float32))
            self.scene.step()
            contacts = self.system.get_contacts()
        finally:
            for sh, offset in zip(shapes, offsets):
                sh.set_contact_offset(offset)
            self._set_state(state)
        return contacts

    def _link_name(self, comp) -> str | None:
        return next((name for name, c in self.links.items() if c is comp), None)

    def self_penetration(self) -> tuple[float, list[ContactPair]]:
        points = []
        for c in self._probe_contacts():
            a, b = self._link_name(c.bodies[0]), self._link_name(c.bodies[1])
            if a is None or b is None:
                continue  # the ground or another object
            points.extend((a, b, float(pt.separation)) for pt in c.points)
        return penetration_sum(points)

    def ground_penetration(self) -> float:
        """Deepest point (m) of the cooked shapes below z = 0, from the geometry (no step)."""
        if self.ground is None:
            return 0.0
        low = self.lowest_point()
        return max(0.0, -low) if math.isfinite(low) else 0.0

    # ------------------------------------------------------------------ state
    def save_state(self) -> int:
        return self._keep_state(self._state())

    def restore_state(self, handle: int) -> None:
        self._set_state(self._states[handle])

    def _state(self) -> tuple:
        """Root pose, root velocities, joint positions, velocities and forces (float32 copies), pending efforts."""
        a = self.art
        arrays = (a.get_root_linear_velocity, a.get_root_angular_velocity, a.get_qpos, a.get_qvel, a.get_qf)
        return (a.get_root_pose(), *(np.asarray(get(), np.float32).copy() for get in arrays),
                None if self._effort is None else self._effort.copy())

    def _set_state(self, state: tuple) -> None:
        a = self.art
        for put, value in zip((a.set_root_pose, a.set_root_linear_velocity, a.set_root_angular_velocity, a.set_qpos, a.set_qvel, a.set_qf),
                              state):
            put(value)
        self._effort = None if state[6] is None else state[6].copy()

    # --------------------------------------------------------------- dynamics
    def step(self, n: int = 1) -> None:
        spend(n)  # the refine's one budget of steps (asset2sim.engines.step_budget)
        springs = self._passive.sprung
        for _ in range(int(n)):
            self.apply_passive_forces()
            if self._effort is not None:
                base = np.asarray(self.art.get_qf(), float) if springs else np.zeros(len(self._joints))
                self.art.set_qf((base + self._effort).astype(np.float32))
                self.scene.step()
                self._effort = None
                if not springs:
                    self.art.set_qf(np.zeros(len(self._joints), np.float32))
                continue
            self.scene.step()

    def apply_passive_forces(self) -> None:
        """For the next ``scene.step()``: each drive's force limit (friction +
        damping * |qdot|) and the springs' joint forces ``-k (q - q_ref)``."""
        if self._passive.damped or self._drive:
            qd = np.abs(np.asarray(self.art.get_qvel(), float))
            for i in range(len(self._joints)):
                if self._passive.damping[i] > 0 or i in self._drive:
                    self._set_drive(i, float(qd[i]))
        if self._passive.sprung:
            self.art.set_qf(self._passive.joint_forces(np.asarray(self.art.get_qpos(), float)).astype(np.float32))

    def held_physics(self) -> HeldPhysics:
        """Links and joints from PhysX's getters; friction is the drive's force limit at rest."""
        links = {name: HeldLink(mass=float(comp.get_mass()), com=np.array(comp.get_cmass_local_pose().p, float),
                                principal=np.sort(np.array(comp.get_inertia(), float))) for name, comp in self.links.items()}
        q = self.art.get_qpos()
        joints = {}
        coeff = []
        for name, i in self._index.items():
            joint = self._joints[i]
            lim = np.array(joint.get_limits(), float).reshape(-1, 2)
            limited = len(lim) and self.joint_types[name] != "continuous"
            lo, hi = (float(lim[0, 0]), float(lim[0, 1])) if limited else (-np.inf, np.inf)
            p = self._passive
            ref = float(p.reference[i]) if name in self.options.springs else None
            joints[name] = HeldJoint(lower=lo, upper=hi, damping=float(p.damping[i]), friction=float(joint.get_force_limit()),
                                     stiffness=float(p.stiffness[i]), reference=ref, position=float(q[i]))
            coeff.append(float(joint.get_friction()))
        how = {"mass, com, inertia": "get_mass, get_cmass_local_pose().p, get_inertia",
               "limits": "PhysxArticulationJoint.get_limits", "friction": "drive force limit at rest (get_force_limit)",
               "damping": "session: added to the drive's force limit each step",
               "spring": "session joint force (qf) each step", "position": "get_qpos",
               "physx joint friction coefficient": f"max {max(coeff, default=0.0):g} (0: not used)"}
        return HeldPhysics(engine=self.engine, source="urdf", links=links, joints=joints, how=how)

    def close(self) -> None:
        """Drop its own scene; from a caller's, remove what the session added."""
        if getattr(self, "scene", None) is not None:
            if not self._owns_scene:
                for ent in [*getattr(self, "_entities", []), getattr(self, "_ground_entity", None)]:
                    if ent is not None:
                        self.scene.remove_entity(ent)
            self.scene = self.system = self.art = None
            self.links = {}


register_engine("physx", PhysXSession)
