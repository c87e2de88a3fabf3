"""PhysX engine (SAPIEN 3 on the CPU, physics only) under the SPEC's conventions.

The articulation is built from the same reading of the URDF as the MuJoCo
engine (:func:`asset2sim.engines.loading.read_urdf`): the same inertials (a link
without ``<inertial>`` gets PyBullet's 1 kg and unit inertia, as in the
reference engine), the same joint frames, and the same convex collision pieces
(one hull per OBJ group, as PyBullet builds them). No render system is created
and no visual shape is loaded (SAPIEN's renderer needs a Vulkan GPU).

Conventions and how PhysX is made to follow them (``docs/design/simulators.md`` lists
what stays different):

- timestep 1/240 s, gravity -9.81 m/s^2 along z, a static plane at z = 0;
- self-collision on; PhysX never collides a link with its parent (the same
  rule as ``URDF_USE_SELF_COLLISION_EXCLUDE_PARENT``);
- the root free, placed so the lowest point of its cooked hulls touches z = 0;
- passive joints: one zero-target-velocity joint drive per joint, stiff
  (damping :data:`FRICTION_DRIVE_DAMPING`) and force-limited to
  ``friction + damping * |qdot|`` (re-set before every step). It stops the
  joint when it can, so it never pushes it backwards: Coulomb friction
  ``<dynamics friction>`` plus viscous damping ``<dynamics damping>`` that stays
  stable however large the damping is relative to the inertia (an explicit
  torque -c*qdot diverges once c*dt/I > 2). PhysX's own joint "friction" is a
  coefficient on the joint's constraint force and is set to 0;
- springs -k (q - q_s) as explicit joint forces each step (what PyBullet does);
- contact friction 0.25 for every pair (PyBullet multiplies the link's 0.5 by
  the plane's 0.5), restitution 0; link velocity damping 0.04 (Bullet's
  default); no sleeping; PGS with ManiSkill 3's solver iterations
  (:data:`SOLVER_ITERATIONS`).

sapien is imported only here; without it the registry reports the engine as
unavailable.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from asset2sim.engines.quiet import startup_quiet

with startup_quiet():
    import sapien
    from sapien import physx

from asset2sim.engines.base import (
    ContactPair,
    EngineUnsupported,
    HeldJoint,
    HeldLink,
    HeldPhysics,
    NoRootHold,
    SessionOptions,
    penetration_sum,
    register_engine,
)
from asset2sim.engines.loading import (
    BULLET_DEFAULT_FRICTION,
    BULLET_DEFAULT_INERTIA,
    BULLET_DEFAULT_MASS,
    BULLET_PLANE_FRICTION,
    collision_pieces,
    joint_tables,
    principal_axes,
    read_urdf,
)
from asset2sim.engines.session_defaults import SessionDefaults
from asset2sim.frames import matrix_quat_wxyz

#: Damping (N*m*s/rad or N*s/m) of the zero-velocity drive that carries the
#: passive joint forces: large enough that the drive acts as a velocity
#: constraint clamped at its force limit (friction + damping * |qdot|).
FRICTION_DRIVE_DAMPING = 1.0e6
#: Bullet's default linear and angular velocity damping of multibody links (1/s).
BULLET_LINK_DAMPING = 0.04
#: PhysX solver: PGS, as SAPIEN's default TGS lets joints held by a force-limited
#: drive creep under load when the root is free; PGS holds them, as Bullet's motors do (``docs/design/simulators.md``).
ENABLE_TGS = False
#: Solver iterations of every articulation (position, velocity): ManiSkill 3's default ``SceneConfig``; with
#: SAPIEN's own (10, 1) a free object resting on the plane creeps (``docs/design/simulators.md``).
SOLVER_ITERATIONS = (15, 1)


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
    c = np.cross(a, b)
    t = np.eye(4)
    t[:3, 0], t[:3, 1], t[:3, 2] = a, b, c
    return t


def new_scene(gravity: float = -9.81, timestep: float = 1.0 / 240.0) -> "sapien.Scene":
    """A SAPIEN scene of its own CPU PhysX system as asset2sim's checks make
    it: ``gravity`` m/s^2 along z, PGS (:data:`ENABLE_TGS`), time step
    ``timestep`` s. SAPIEN's global scene configuration is left as it was."""
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


class PhysXSession(SessionDefaults, NoRootHold):
    """A :class:`~asset2sim.engines.base.SimSession` in PhysX through SAPIEN 3:
    a CPU scene of its own, or (``scene``) the caller's ``sapien.Scene``,
    whose gravity, time step and solver are left as they are; ``ground``
    False: no plane is added to the caller's scene.

    ``notes``: what had to change for this asset (flat hulls, missing
    inertials, shapes PhysX could not cook).

    Raises (constructor):
        UrdfError: the URDF cannot be read.
        PhysXError: an inertia tensor is not positive definite or a link
            ends up without any shape PhysX can cook while it has collisions.
    """

    engine = "physx"

    def __init__(self, urdf_path: Path, options: SessionOptions, missing_inertial: str = "bullet", scene=None, ground: bool = True):
        self.options = options
        self.dt = options.conventions.timestep
        self.urdf = read_urdf(urdf_path)
        pieces, notes = collision_pieces(self.urdf)
        self.notes = list(notes)
        self._owns_scene = scene is None
        if scene is None:
            self._make_scene()
        else:
            self.scene, self.system, self.dt = scene, scene.physx_system, float(scene.get_timestep())
        self.ground = self._add_ground() if options.ground and (self._owns_scene or ground) else None
        self._add_articulation(self._articulation_builder(urdf_path, missing_inertial), pieces, urdf_path)
        self.joint_names, self.joint_types, self.joint_limits, self.joint_child = joint_tables(self.urdf)
        self.link_names = list(self.links)
        self._states: dict[int, tuple] = {}
        self._effort = None
        self._passive_drives(urdf_path)
        self.set_joint_positions(options.initial_state)
        if options.ground and not options.fixed_base:
            self.place_on_ground()

    # --------------------------------------------------------------- building
    def _make_scene(self) -> None:
        """``system`` and ``scene``: :func:`new_scene` with the session's gravity."""
        conv = self.options.conventions
        self.scene = new_scene(conv.gravity if self.options.gravity else 0.0, self.dt)
        self.system = self.scene.physx_system

    def _add_ground(self):
        """The static ground plane z = 0 (its component), contact friction 0.25."""
        mu = BULLET_DEFAULT_FRICTION * BULLET_PLANE_FRICTION
        ent = sapien.Entity()
        ent.name = "ground"
        comp = physx.PhysxRigidStaticComponent()
        plane = physx.PhysxCollisionShapePlane(physx.PhysxMaterial(mu, mu, 0.0))
        # PhysX planes face +x; turn the normal to +z.
        plane.local_pose = sapien.Pose(q=[math.sqrt(0.5), 0.0, -math.sqrt(0.5), 0.0])
        comp.attach(plane)
        ent.add_component(comp)
        self.scene.add_entity(ent)
        self._ground_entity = ent
        return comp

    def _articulation_builder(self, urdf_path: Path, missing_inertial: str):
        """SAPIEN's articulation builder with every link in tree order: its
        joint (x along the URDF axis, the root free or fixed) and inertia."""
        builder = self.scene.create_articulation_builder()
        link_builders = {}
        for name in self.urdf.tree_order():
            pj = self.urdf.parent_joint(name)
            lb = builder.create_link_builder(link_builders[pj.parent] if pj else None)
            link_builders[name] = lb
            lb.set_name(name)
            lb.set_joint_name(pj.name if pj else "")
            if pj is None:
                lb.set_joint_properties("fixed" if self.options.fixed_base else "undefined", [], sapien.Pose(), sapien.Pose())
            else:
                ax = _axis_frame(pj.axis)
                kind = {"revolute": "revolute_unwrapped", "continuous": "revolute", "prismatic": "prismatic", "fixed": "fixed"}[pj.type]
                limits = [] if pj.type == "fixed" else [[pj.lower, pj.upper]]
                lb.set_joint_properties(kind, limits, _pose(pj.origin @ ax), _pose(ax), 0.0, 0.0)
            mass, com_pose, moments = self._link_inertia(name, urdf_path, missing_inertial)
            lb.set_mass_and_inertia(float(mass), com_pose, np.asarray(moments, np.float32))
        return builder

    def _add_articulation(self, builder, pieces: dict, urdf_path: Path) -> None:
        """Build the articulation, cook each link's collision pieces and add it
        to the scene; sets ``links`` (link -> component, tree order) and ``art``
        (no sleeping, :data:`SOLVER_ITERATIONS`)."""
        entities = builder.build_entities(fix_root_link=self.options.fixed_base)
        self.links = {}
        for ent in entities:
            comp = ent.find_component_by_type(physx.PhysxArticulationLinkComponent)
            self.links[comp.name] = comp
            self._attach_shapes(comp, pieces[comp.name], urdf_path)
        for ent in entities:
            self.scene.add_entity(ent)
        self._entities = list(entities)
        self.art = entities[0].find_component_by_type(physx.PhysxArticulationLinkComponent).articulation
        self.art.set_sleep_threshold(0.0)
        self.art.set_solver_position_iterations(SOLVER_ITERATIONS[0])
        self.art.set_solver_velocity_iterations(SOLVER_ITERATIONS[1])

    def _link_inertia(self, name: str, urdf_path: Path, missing_inertial: str):
        """Mass (kg), COM pose with the principal axes (link frame) and
        principal moments (3,) kg*m^2 of a link; without ``<inertial>``
        PyBullet's 1 kg and unit inertia (``missing_inertial="bullet"``).

        Raises:
            PhysXError: no ``<inertial>`` (other ``missing_inertial``), or a
                mass or principal moment that is not positive.
        """
        ine = self.urdf.links[name].inertial
        if ine is None:
            if missing_inertial != "bullet":
                raise PhysXError(f"{urdf_path}: link {name!r} has no <inertial> (PhysX needs a mass)")
            self.notes.append(f"link {name!r} has no <inertial>: given PyBullet's {BULLET_DEFAULT_MASS} kg, unit inertia")
            return BULLET_DEFAULT_MASS, sapien.Pose(), np.array(BULLET_DEFAULT_INERTIA)
        moments, axes = principal_axes(ine.inertia_in_link_axes())
        if ine.mass <= 0 or moments.min() <= 0:
            raise PhysXError(f"{urdf_path}: link {name!r} has mass {ine.mass} and principal moments {moments}: not positive")
        t = np.eye(4)
        t[:3, :3] = axes
        t[:3, 3] = ine.com()
        return ine.mass, _pose(t), moments

    def _attach_shapes(self, comp, pieces: list, urdf_path: Path) -> None:
        """Cook a link's collision pieces into its component (a piece PhysX
        cannot cook is skipped with a note), contact friction the link's
        lateral friction x the plane's; Bullet's link velocity damping.

        Raises:
            PhysXError: the link has pieces and none could be cooked.
        """
        name = comp.name
        lat = self.urdf.links[name].lateral_friction
        lmu = (BULLET_DEFAULT_FRICTION if lat is None else lat) * BULLET_PLANE_FRICTION
        mat = physx.PhysxMaterial(lmu, lmu, 0.0)
        cooked = 0
        for p in pieces:
            try:
                if p.kind == "hull":
                    shape = physx.PhysxCollisionShapeConvexMesh(
                        np.asarray(p.points, np.float32), np.ones(3, np.float32), mat
                    )
                    local = p.origin
                elif p.kind == "box":
                    shape = physx.PhysxCollisionShapeBox(np.asarray(p.size, np.float32) / 2, mat)
                    local = p.origin
                elif p.kind == "sphere":
                    shape = physx.PhysxCollisionShapeSphere(float(p.radius), mat)
                    local = p.origin
                else:  # cylinder: URDF axis z, PhysX axis x
                    shape = physx.PhysxCollisionShapeCylinder(float(p.radius), float(p.length) / 2, mat)
                    local = p.origin @ _axis_frame(np.array([0.0, 0.0, 1.0]))
            except RuntimeError as exc:  # PhysX could not cook the hull
                self.notes.append(f"link {name!r} collision {p.collision} group {p.group}: PhysX could not cook it ({exc}); skipped")
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

    def _passive_drives(self, urdf_path: Path) -> None:
        """Joint index tables and each movable joint's passive zero-velocity
        drive (force limit = Coulomb friction, N*m or N), its damping and spring.

        Raises:
            PhysXError: PhysX built other joints than the URDF's movable ones.
        """
        active = [j.name for j in self.art.active_joints]
        if sorted(active) != sorted(self.joint_names):
            raise PhysXError(f"{urdf_path}: PhysX built joints {active}, the URDF has {self.joint_names}")
        self._index = {n: i for i, n in enumerate(active)}
        self._joints = list(self.art.active_joints)
        self._friction = np.zeros(len(active))
        self._damping = np.zeros(len(active))
        self._stiffness = np.zeros(len(active))
        self._drive: dict[int, tuple[float, float]] = {}
        """joint index -> (target velocity, force limit beyond friction) of :meth:`drive_joint`"""
        self._reference = np.zeros(len(active))
        for pj in self.urdf.movable_joints:
            i = self._index[pj.name]
            self._damping[i] = pj.damping
            self._friction[i] = pj.friction
            joint = self._joints[i]
            joint.set_friction(0.0)
            joint.set_drive_properties(0.0, FRICTION_DRIVE_DAMPING, float(pj.friction), "force")
            joint.set_drive_target(0.0)
            joint.set_drive_velocity_target(0.0)
            sp = self.options.springs.get(pj.name)
            if sp is not None:
                self._stiffness[i] = sp.stiffness
                self._reference[i] = sp.reference

    # ------------------------------------------------------------------ state
    def set_joint_positions(self, q: dict[str, float], zero_velocity: bool = True) -> None:
        qpos = np.asarray(self.art.get_qpos(), np.float32).copy()
        qvel = np.asarray(self.art.get_qvel(), np.float32).copy()
        for name, v in q.items():
            i = self._index.get(name)
            if i is None:
                continue
            qpos[i] = float(v)
            if zero_velocity:
                qvel[i] = 0.0
        self.art.set_qpos(qpos)
        self.art.set_qvel(qvel)

    def joint_positions(self) -> dict[str, float]:
        qpos = self.art.get_qpos()
        return {n: float(qpos[i]) for n, i in self._index.items()}

    def joint_velocities(self) -> dict[str, float]:
        qvel = self.art.get_qvel()
        return {n: float(qvel[i]) for n, i in self._index.items()}

    def joint_state(self, joint: str) -> tuple[float, float]:
        i = self._index[joint]
        return float(self.art.get_qpos()[i]), float(self.art.get_qvel()[i])

    def joint_axis(self, joint: str) -> np.ndarray:
        """The URDF axis (3,) of the joint (PhysX moves the joint along/about
        the x axis of a frame built on it)."""
        if joint not in self._index:
            raise KeyError(joint)
        return np.asarray(self.urdf.parent_joint(self.joint_child[joint]).axis, float).copy()

    def apply_joint_effort(self, joint: str, effort: float) -> None:
        """Generalized force (N*m or N) on a joint for the next step (added to
        the spring forces)."""
        if self._effort is None:
            self._effort = np.zeros(len(self._joints))
        self._effort[self._index[joint]] += float(effort)

    def drive_joint(self, joint: str, velocity: float, max_force: float) -> None:
        """The passive zero-velocity drive gets velocity target ``velocity``
        and force limit ``max_force + friction (+ damping * |qdot|)``."""
        i = self._index[joint]
        self._drive[i] = (float(velocity), float(max(max_force, 0.0)))
        self._set_drive(i, abs(float(self.art.get_qvel()[i])))

    def release_joint(self, joint: str) -> None:
        """Back to the passive drive (velocity target 0)."""
        i = self._index[joint]
        self._drive.pop(i, None)
        self._set_drive(i, abs(float(self.art.get_qvel()[i])))

    def _set_drive(self, i: int, qd_abs: float) -> None:
        """Drive i's force limit and velocity target (passive or driven)."""
        v, extra = self._drive.get(i, (0.0, 0.0))
        self._joints[i].set_drive_properties(0.0, FRICTION_DRIVE_DAMPING, float(self._friction[i] + self._damping[i] * qd_abs + extra), "force")
        self._joints[i].set_drive_velocity_target(v)

    def set_root_velocity(self, linear, angular) -> None:
        """Root linear and angular velocity (world frame).

        Raises:
            EngineUnsupported: fixed base."""
        if self.options.fixed_base:
            raise EngineUnsupported("physx: the root of a fixed-base session cannot be moved")
        self.art.set_root_linear_velocity(np.asarray(linear, np.float32))
        self.art.set_root_angular_velocity(np.asarray(angular, np.float32))

    # ------------------------------------------------------------------ links
    def link_frame(self, link: str) -> tuple[np.ndarray, np.ndarray]:
        """The link component's pose: PhysX builds each link in its URDF frame
        (the child frame of its joint), the center of mass separately."""
        t = self.links[link].get_pose().to_transformation_matrix().astype(float)
        return t[:3, 3].copy(), t[:3, :3].copy()

    def link_collision_vertices(self, link: str) -> np.ndarray:
        """Vertices (k, 3) m of the link's cooked convex meshes, link frame."""
        out = []
        for shape in self.links[link].get_collision_shapes():
            if isinstance(shape, physx.PhysxCollisionShapeConvexMesh):
                t = shape.get_local_pose().to_transformation_matrix()
                v = np.asarray(shape.get_vertices(), float) * np.asarray(shape.get_scale(), float)
                out.append(v @ t[:3, :3].T + t[:3, 3])
        return np.concatenate(out) if out else np.zeros((0, 3))

    def link_aabb(self, link: str) -> tuple[np.ndarray, np.ndarray]:
        """Bounds of the cooked hull vertices at the current pose (PhysX's own
        tight box for boxes, spheres and cylinders)."""
        comp = self.links[link]
        lo, hi = np.full(3, np.inf), np.full(3, -np.inf)
        v = self.link_collision_vertices(link)
        if len(v):
            pos, R = self.link_frame(link)
            w = v @ R.T + pos
            lo, hi = w.min(axis=0), w.max(axis=0)
        if any(not isinstance(sh, physx.PhysxCollisionShapeConvexMesh) for sh in comp.get_collision_shapes()):
            box = comp.compute_global_aabb_tight()
            lo, hi = np.minimum(lo, np.asarray(box[0], float)), np.maximum(hi, np.asarray(box[1], float))
        if not np.all(np.isfinite(lo)):
            pos, _ = self.link_frame(link)
            return pos.copy(), pos.copy()
        return lo, hi

    def link_has_collision(self, link: str) -> bool:
        return bool(self.links[link].get_collision_shapes())

    def link_masses(self) -> dict[str, float]:
        return {name: float(comp.get_mass()) for name, comp in self.links.items()}

    def link_distances(self, link_a: str, link_b: str, max_distance: float = 0.0) -> list[float]:
        """Not available: SAPIEN exposes no closest-point query between the
        shapes of an articulation (its contacts come only from a step and skip
        parent-child pairs).

        Raises:
            EngineUnsupported: always.
        """
        raise EngineUnsupported("physx: no closest-point query between links (use pybullet or mujoco)")

    def apply_link_force(self, link: str, force, point) -> None:
        """``add_force_at_point`` (world frame); PhysX clears it after the step."""
        self.links[link].add_force_at_point(np.asarray(force, np.float32), np.asarray(point, np.float32))

    def root_pose(self) -> tuple[np.ndarray, np.ndarray]:
        pose = self.art.get_root_pose()
        w, x, y, z = (float(v) for v in pose.q)
        return np.array(pose.p, float), np.array([x, y, z, w], float)

    def set_root_pose(self, pos, orn_xyzw) -> None:
        x, y, z, w = (float(v) for v in orn_xyzw)
        self.art.set_root_pose(sapien.Pose(p=np.asarray(pos, np.float32), q=[w, x, y, z]))
        self.art.set_root_linear_velocity(np.zeros(3, np.float32))
        self.art.set_root_angular_velocity(np.zeros(3, np.float32))

    def lowest_point(self) -> float:
        """Lowest z (m) of the articulation's cooked collision shapes (+inf if none)."""
        low = math.inf
        for comp in self.links.values():
            link_pose = comp.get_pose().to_transformation_matrix()
            for shape in comp.get_collision_shapes():
                t = link_pose @ shape.get_local_pose().to_transformation_matrix()
                if isinstance(shape, physx.PhysxCollisionShapeConvexMesh):
                    v = np.asarray(shape.get_vertices(), float) * np.asarray(shape.get_scale(), float)
                    low = min(low, float((v @ t[:3, :3].T + t[:3, 3])[:, 2].min()))
                else:
                    aabb = comp.compute_global_aabb_tight()
                    low = min(low, float(aabb[0][2]))
        return low

    def place_on_ground(self) -> float:
        """Translate the root so the lowest collision point touches z = 0; returns the shift (m)."""
        low = self.lowest_point()
        if not math.isfinite(low):
            return 0.0
        pos, orn = self.root_pose()
        self.set_root_pose(pos + np.array([0.0, 0.0, -low]), orn)
        return float(-low)

    # ---------------------------------------------------------------- contact
    def _probe_contacts(self):
        """Contacts PhysX generates at the current state, without changing it:
        PhysX reports contacts only from a simulation step, and generates them
        from the poses at the start of the step, so the state is saved, one
        step is taken, the contacts read and the state restored."""
        state = self._state()
        self.art.set_qf(np.zeros(len(state[3]), np.float32))
        self.scene.step()
        contacts = self.system.get_contacts()
        self._set_state(state)
        return contacts

    def _link_name(self, comp) -> str | None:
        for name, c in self.links.items():
            if c is comp:
                return name
        return None

    def self_penetration(self) -> tuple[float, list[ContactPair]]:
        return penetration_sum(self._contact_separations())

    def _contact_separations(self):
        for c in self._probe_contacts():
            a, b = self._link_name(c.bodies[0]), self._link_name(c.bodies[1])
            if a is None or b is None:
                continue  # the ground or another object
            for pt in c.points:
                yield a, b, float(pt.separation)

    def ground_penetration(self) -> float:
        """Deepest point (m) of the cooked collision shapes below z = 0, from
        the geometry itself (exact for hulls on a plane; no simulation step)."""
        if self.ground is None:
            return 0.0
        low = self.lowest_point()
        return max(0.0, -low) if math.isfinite(low) else 0.0

    # ------------------------------------------------------------------ state
    def save_state(self) -> int:
        """Snapshot root pose and velocities, joint positions, velocities and
        forces, and the pending joint efforts (PhysX keeps no contact cache
        across ``set_qpos``)."""
        handle = max(self._states, default=0) + 1
        self._states[handle] = self._state()
        return handle

    def restore_state(self, handle: int) -> None:
        self._set_state(self._states[handle])

    def _state(self) -> tuple:
        """Root pose, root velocities, joint positions, velocities and forces (float32 copies), pending efforts."""
        return (
            self.art.get_root_pose(),
            np.asarray(self.art.get_root_linear_velocity(), np.float32).copy(),
            np.asarray(self.art.get_root_angular_velocity(), np.float32).copy(),
            np.asarray(self.art.get_qpos(), np.float32).copy(),
            np.asarray(self.art.get_qvel(), np.float32).copy(),
            np.asarray(self.art.get_qf(), np.float32).copy(),
            None if self._effort is None else self._effort.copy(),
        )

    def _set_state(self, state: tuple) -> None:
        """Return to a :meth:`_state`."""
        pose, lin, ang, qpos, qvel, qf, effort = state
        self.art.set_root_pose(pose)
        self.art.set_root_linear_velocity(lin)
        self.art.set_root_angular_velocity(ang)
        self.art.set_qpos(qpos)
        self.art.set_qvel(qvel)
        self.art.set_qf(qf)
        self._effort = None if effort is None else effort.copy()

    def discard_state(self, handle: int) -> None:
        self._states.pop(handle, None)

    # --------------------------------------------------------------- dynamics
    def step(self, n: int = 1) -> None:
        """Advance n steps: before each, :meth:`apply_passive_forces`."""
        springs = bool(np.any(self._stiffness))
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
        """For the next ``scene.step()``: each joint drive's force limit
        (friction + damping * |qdot|, N or N*m) and the springs' joint forces
        ``-k (q - q_ref)`` (PhysX has no joint spring or viscous joint
        friction of this form; :meth:`step` calls this before every step)."""
        if bool(np.any(self._damping)) or self._drive:
            qd = np.abs(np.asarray(self.art.get_qvel(), float))
            for i, _joint in enumerate(self._joints):
                if self._damping[i] > 0 or i in self._drive:
                    self._set_drive(i, float(qd[i]))
        if bool(np.any(self._stiffness)):
            q = np.asarray(self.art.get_qpos(), float)
            self.art.set_qf((-self._stiffness * (q - self._reference)).astype(np.float32))

    def held_physics(self) -> HeldPhysics:
        """What PhysX holds: each link's ``get_mass``, ``get_cmass_local_pose``
        (COM in the link frame) and ``get_inertia`` (principal moments); each
        joint's ``get_limits``, its drive's force limit at rest (the Coulomb
        friction, see the module notes), the damping the session adds to
        that limit (``friction + damping * |qdot|``), the spring the session
        applies as a joint force and ``get_qpos``. PhysX's own joint friction
        coefficient (``get_friction``) is reported under ``how`` (0 here)."""
        links = {}
        for name, comp in self.links.items():
            links[name] = HeldLink(mass=float(comp.get_mass()), com=np.array(comp.get_cmass_local_pose().p, float),
                                   principal=np.sort(np.array(comp.get_inertia(), float)))
        q = self.art.get_qpos()
        joints = {}
        coeff = []
        for name, i in self._index.items():
            joint = self._joints[i]
            lim = np.array(joint.get_limits(), float).reshape(-1, 2)
            lo, hi = (float(lim[0, 0]), float(lim[0, 1])) if len(lim) else (-np.inf, np.inf)
            if self.joint_types[name] == "continuous":
                lo, hi = -np.inf, np.inf
            ref = float(self._reference[i]) if name in self.options.springs else None
            joints[name] = HeldJoint(lower=lo, upper=hi, damping=float(self._damping[i]), friction=float(joint.get_force_limit()),
                                     stiffness=float(self._stiffness[i]), reference=ref, position=float(q[i]))
            coeff.append(float(joint.get_friction()))
        how = {"mass, com, inertia": "get_mass, get_cmass_local_pose().p, get_inertia",
               "limits": "PhysxArticulationJoint.get_limits", "friction": "drive force limit at rest (get_force_limit)",
               "damping": "session: added to the drive's force limit each step",
               "spring": "session joint force (qf) each step", "position": "get_qpos",
               "physx joint friction coefficient": f"max {max(coeff, default=0.0):g} (0: not used)"}
        return HeldPhysics(engine=self.engine, source="urdf", links=links, joints=joints, how=how)

    def close(self) -> None:
        """Drop the session's own scene; from a caller's scene, remove what
        the session added (the articulation, its ground)."""
        if getattr(self, "scene", None) is not None:
            if not self._owns_scene:
                for ent in [*getattr(self, "_entities", []), getattr(self, "_ground_entity", None)]:
                    if ent is not None:
                        self.scene.remove_entity(ent)
            self.scene = None
            self.system = None
            self.art = None
            self.links = {}


def _open(urdf_path: Path, options: SessionOptions, scene=None, ground: bool = True) -> PhysXSession:
    return PhysXSession(urdf_path, options, scene=scene, ground=ground)


register_engine("physx", _open)
