"""PyBullet (Bullet) engine under the SPEC's conventions; see :mod:`.base`.
Coulomb friction is a zero-target-velocity motor of force ``<dynamics friction>``;
Bullet applies ``<dynamics damping>`` itself. Its collision world and viewer: :mod:`.pybullet_worlds`.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from asset2sim.engines.base import (ContactPair, EngineTraits, HeldJoint, HeldLink, HeldPhysics, SessionDefaults, SessionOptions,
                                    penetration_sum, register_engine, register_shape_world, register_viewer)
from asset2sim.engines import pybullet_clients
from asset2sim.engines.pybullet_worlds import (
    BULLET_JOINT_TYPES, BoundClient, PyBulletShapeWorld, PyBulletViewer, body_link_frame, bullet, joint_infos,
)
from asset2sim.engines.quiet import quiet_stdout
from asset2sim.engines.step_budget import spend


class PyBulletSession(SessionDefaults):
    """A :class:`~asset2sim.engines.base.SimSession` in PyBullet: its own DIRECT client (new, or with
    ``options.files_key`` one an earlier session of that key left idle: :mod:`.pybullet_clients`), or (``client``)
    the caller's, whose gravity and time step are left as they are; ``ground`` False: no plane is added to the
    caller's world (the object is still put with its lowest point on z = 0)."""

    engine = "pybullet"
    traits = EngineTraits(reference=True, conservative_aabb=True, springs_by_torque=True, incremental_penetration=True)

    def __init__(self, urdf_path: Path, options: SessionOptions, client: int | None = None, ground: bool = True):
        p = self._bullet = bullet()
        self.options = options
        self._root_hold: int | None = None  # hold_root's constraint
        conv = options.conventions
        # step 1: a physics client (taken from the pool, or the caller's)
        self._owns_client = client is None
        self.cid = pybullet_clients.take(p, options.files_key) if client is None else int(client)
        self._p = p = BoundClient(p, self.cid)
        self.body = None
        # step 2: time step, gravity, the ground plane; load the URDF without its visual shapes
        try:
            if self._owns_client:
                p.setTimeStep(conv.timestep)
                p.setGravity(0, 0, conv.gravity if options.gravity else 0.0)
            self.plane = None
            if options.ground and ground:
                self.plane = self._add_plane()
            # visual shapes are never drawn here: not loading them saves most of loadURDF
            flags = (p.URDF_USE_SELF_COLLISION | p.URDF_USE_SELF_COLLISION_EXCLUDE_PARENT | p.URDF_USE_INERTIA_FROM_FILE
                     | p.URDF_IGNORE_VISUAL_SHAPES)
            with quiet_stdout():
                self.body = p.loadURDF(str(urdf_path), useFixedBase=options.fixed_base, flags=flags)
        except Exception as exc:
            self._release()
            raise RuntimeError(f"PyBullet could not load {urdf_path}: {exc}") from exc
        # step 3: the movable joints, their limits and child links; each joint's Coulomb friction as a motor
        self.base_link = p.getBodyInfo(self.body)[0].decode()
        self._link_by_index: dict[int, str] = {-1: self.base_link}
        self._has_collision: dict[int, bool] = {}
        self._teleported = False  # a teleport since the last contact detection (:meth:`_forget_contacts`)
        self._index: dict[str, int] = {}
        self._friction: dict[str, float] = {}
        self.joint_types: dict[str, str] = {}
        self.joint_limits: dict[str, tuple[float, float]] = {}
        self.joint_child: dict[str, str] = {}
        for j, info in enumerate(joint_infos(p, self.body)):
            name = info[1].decode()
            self._link_by_index[j] = info[12].decode()
            jtype = BULLET_JOINT_TYPES.get(info[2], "other")
            if jtype not in ("revolute", "prismatic"):
                continue
            lo, hi = float(info[8]), float(info[9])
            if lo > hi:  # continuous joint: Bullet reports lower=0, upper=-1
                jtype, lo, hi = "continuous", -np.inf, np.inf
            self._index[name] = j
            self.joint_types[name] = jtype
            self.joint_limits[name] = (lo, hi)
            self.joint_child[name] = self._link_by_index[j]
            self._friction[name] = float(info[7])
            self.release_joint(name)  # Coulomb friction: the motor at rest
        self.joint_names = list(self._index)
        self.link_names: list[str] = list(self._link_by_index.values())
        self._link_index = {name: idx for idx, name in reversed(list(self._link_by_index.items()))}
        # step 4: the initial state, the object placed on the ground
        self.set_joint_positions(options.initial_state)
        if options.ground and not options.fixed_base:
            if self.plane is None:  # the caller's floor: a plane only while the exact distances are measured
                self.plane = self._add_plane()
                try:
                    self.place_on_ground()
                finally:
                    p.removeBody(self.plane)
                    self.plane = None
            else:
                self.place_on_ground()

    def _add_plane(self) -> int:
        p = self._p
        return p.createMultiBody(0, p.createCollisionShape(p.GEOM_PLANE))

    # ------------------------------------------------------------------ state
    def set_joint_positions(self, q: dict[str, float]) -> None:
        """Each joint of ``q`` (rad or m) at rest there. A joint already there at rest is left as it is: Bullet's
        ``resetJointState`` moves every link of the body each call, so a whole state set again costs a call per joint
        for nothing (a keyboard's 108 keys: 108 passes over 109 links)."""
        p = self._p
        named = [(self._index[n], float(v)) for n, v in q.items() if n in self._index]
        now = p.getJointStates(self.body, [j for j, _ in named]) if len(named) > 1 else None
        for k, (j, value) in enumerate(named):
            if now is None or now[k][0] != value or now[k][1] != 0.0:
                p.resetJointState(self.body, j, value, 0.0)
        self._teleported = True

    def _forget_contacts(self) -> None:
        """Drop the contacts Bullet cached before a teleport (:meth:`set_joint_positions`, :meth:`set_root_pose`,
        :meth:`restore_state`), so that the next detection finds them anew.

        Bullet keeps a link pair's contact manifold across a teleport (``restoreState`` too keeps the manifolds its
        snapshot lacks) and refreshes the cached points at the new poses (``btPersistentManifold::
        refreshContactPoints``): a point cached where two links touched, one of them since turned along the
        contact normal, reads as a penetration no closest-point query finds (11.8 mm between a wardrobe's closed
        doors after one door's sweep), and the solver pushes the links apart on it. Re-adding a link's collider
        with the filter Bullet's URDF import gave it (``setCollisionFilterGroupMask``: a fixed base static, group 2
        and every mask bit but static; every other link group 1, mask all) removes its broadphase pairs and their
        manifolds. Nothing to do when there was no teleport since the last call.
        """
        if not self._teleported:
            return
        for i, link in self._link_by_index.items():
            if self.link_has_collision(link):
                static = i == -1 and self.options.fixed_base
                self._p.setCollisionFilterGroupMask(self.body, i, 2 if static else 1, -1 ^ 2 if static else -1)
        self._teleported = False

    def _joint_field(self, k: int) -> dict[str, float]:
        """Field ``k`` (0 position, 1 velocity) of every movable joint's state."""
        if not self._index:
            return {}
        states = self._p.getJointStates(self.body, list(self._index.values()))
        return {name: float(s[k]) for name, s in zip(self._index, states)}

    def joint_positions(self) -> dict[str, float]:
        return self._joint_field(0)

    def joint_velocities(self) -> dict[str, float]:
        return self._joint_field(1)

    def joint_state(self, joint: str) -> tuple[float, float]:
        s = self._p.getJointState(self.body, self._index[joint])
        return float(s[0]), float(s[1])

    def joint_axis(self, joint: str) -> np.ndarray:
        # getJointInfo's axis is in the child's local inertial frame, which Bullet
        # turns to the principal axes of a non-diagonal inertia tensor: back to the link frame.
        idx = self._index[joint]
        info = self._p.getJointInfo(self.body, idx)
        orn = self._p.getDynamicsInfo(self.body, idx)[4]
        R = np.array(self._p.getMatrixFromQuaternion(orn), float).reshape(3, 3)
        return R @ np.array(info[13], float)

    # ------------------------------------------------------------------ links
    def link_frame(self, link: str) -> tuple[np.ndarray, np.ndarray]:
        return body_link_frame(self._p, self.body, self.link_index(link))

    def link_aabb(self, link: str) -> tuple[np.ndarray, np.ndarray]:
        lo, hi = self._p.getAABB(self.body, self.link_index(link))
        return np.array(lo, float), np.array(hi, float)

    def link_has_collision(self, link: str) -> bool:
        idx = self.link_index(link)
        if idx not in self._has_collision:
            self._has_collision[idx] = bool(self._p.getCollisionShapeData(self.body, idx))
        return self._has_collision[idx]

    def link_collision_vertices(self, link: str) -> np.ndarray:
        """``getMeshData`` of the link, link frame (empty when Bullet returns none). Bullet prints a ``?`` line on
        stdout for each primitive shape (box, capsule) it has no mesh of: kept out of the product's output."""
        try:
            with quiet_stdout():
                n, verts = self._p.getMeshData(self.body, self.link_index(link))
        except Exception:
            n = 0
        return np.asarray(verts, float) if n else np.zeros((0, 3))

    def link_masses(self) -> dict[str, float]:
        return {name: float(self._p.getDynamicsInfo(self.body, idx)[0]) for idx, name in self._link_by_index.items()}

    def link_distances(self, link_a: str, link_b: str, max_distance: float = 0.0) -> list[float]:
        pts = self._p.getClosestPoints(self.body, self.body, max_distance, self.link_index(link_a), self.link_index(link_b))
        return [pt[8] for pt in pts]

    def apply_link_force(self, link: str, force, point) -> None:
        p = self._p
        p.applyExternalForce(self.body, self.link_index(link), np.asarray(force, float).tolist(), np.asarray(point, float).tolist(),
                             p.WORLD_FRAME)

    def root_pose(self) -> tuple[np.ndarray, np.ndarray]:
        pos, orn = self._p.getBasePositionAndOrientation(self.body)
        return np.array(pos, float), np.array(orn, float)

    def set_root_pose(self, pos, orn) -> None:
        self._p.resetBasePositionAndOrientation(self.body, list(pos), list(orn))
        self._p.resetBaseVelocity(self.body, [0, 0, 0], [0, 0, 0])
        self._teleported = True

    def place_on_ground(self) -> float:
        """Translate the root so the lowest collision point touches z = 0;
        returns the vertical shift (m): by the AABBs, then refined by the closest
        points to the plane (Bullet's AABBs of rotated hulls are loose)."""
        p = self._p
        lo = min(p.getAABB(self.body, link)[0][2] for link in self._link_by_index)
        pos, orn = self.root_pose()
        shift = -lo
        self.set_root_pose(pos + np.array([0.0, 0.0, shift]), orn)
        if self.plane is not None:
            p.performCollisionDetection()
            hi = max(p.getAABB(self.body, link)[1][2] for link in self._link_by_index)
            pts = p.getClosestPoints(self.body, self.plane, max(hi, 0.0) + 0.05)
            if pts:
                dmin = min(pt[8] for pt in pts)
                pos, orn = self.root_pose()
                self.set_root_pose(pos - np.array([0.0, 0.0, dmin]), orn)
                shift -= dmin
        return float(shift)

    # ---------------------------------------------------------------- contact
    def self_penetration(self) -> tuple[float, list[ContactPair]]:
        p = self._p
        self._forget_contacts()
        p.performCollisionDetection()
        return self._penetration_of(p.getContactPoints(self.body, self.body))

    def _penetration_of(self, points) -> tuple[float, list[ContactPair]]:
        """Phi of Bullet contact/closest points (fields 3/4: link indices, 8: signed distance)."""
        names = self._link_by_index
        return penetration_sum((names[pt[3]], names[pt[4]], pt[8]) for pt in points)

    def self_penetration_fresh(self) -> tuple[float, list[ContactPair]]:
        """Phi (m) like :meth:`self_penetration`, from ``getClosestPoints`` per
        non-adjacent link pair, so it cannot depend on contacts Bullet cached
        at earlier states of the session."""
        p = self._p
        cache = getattr(self, "_pairs_cache", None)
        if cache is None:
            with_shape = [i for i in self._link_by_index if p.getCollisionShapeData(self.body, i)]
            parent = {j: info[16] for j, info in enumerate(joint_infos(p, self.body))}
            cache = [(a, b) for a in with_shape for b in with_shape if a < b and parent.get(b) != a and parent.get(a) != b]
            self._pairs_cache = cache
        return self._penetration_of([pt for a, b in cache
                                     for pt in p.getClosestPoints(self.body, self.body, 0.0, a, b)])

    def ground_penetration(self, detect: bool = True) -> float:
        if self.plane is None:
            return 0.0
        if detect:
            self._forget_contacts()
            self._p.performCollisionDetection()
        pts = self._p.getContactPoints(self.body, self.plane)
        return float(max([0.0] + [-pt[8] for pt in pts]))

    def step_ground_penetration(self) -> float:
        """The last step's contacts (a new detection would refresh Bullet's manifolds)."""
        return self.ground_penetration(detect=False)

    # --------------------------------------------------------------- dynamics
    def step(self, n: int = 1) -> None:
        spend(n)  # the refine's one budget of steps (asset2sim.engines.step_budget)
        self._forget_contacts()
        for _ in range(n):
            self.apply_passive_forces()
            self._p.stepSimulation()

    def apply_passive_forces(self) -> None:
        """Each joint spring's torque ``-k (q - q_ref)`` (:meth:`Spring.force`) for the next ``stepSimulation``."""
        p = self._p
        springs = self.options.springs
        if not springs:
            return
        q = self.joint_positions()
        sprung = [(self._index[name], spring.force(q[name])) for name, spring in springs.items() if name in self._index]
        if sprung:  # one call for every spring (a keyboard's 108 keys: 108 calls a step otherwise)
            p.setJointMotorControlArray(self.body, [j for j, _ in sprung], p.TORQUE_CONTROL, forces=[tau for _, tau in sprung])

    def apply_joint_effort(self, name: str, effort: float) -> None:
        self._p.setJointMotorControl2(self.body, self._index[name], self._p.TORQUE_CONTROL, force=float(effort))

    def _motor(self, name: str, velocity: float, force: float) -> None:
        self._p.setJointMotorControl2(self.body, self._index[name], self._p.VELOCITY_CONTROL, targetVelocity=velocity,
                                      force=force)

    def drive_joint(self, name: str, velocity: float, max_force: float) -> None:
        """The passive friction motor gets target ``velocity`` and force ``max_force + friction``."""
        self._motor(name, float(velocity), float(max(max_force, 0.0) + self._friction[name]))

    def release_joint(self, name: str) -> None:
        self._motor(name, 0.0, self._friction[name])

    def hold_root(self, max_force: float) -> None:
        """A ``JOINT_FIXED`` constraint to the world at the current pose, every row bounded by ``max_force``."""
        if self.options.fixed_base:
            return
        self.release_root()
        p = self._p
        pos, orn = p.getBasePositionAndOrientation(self.body)
        self._root_hold = p.createConstraint(self.body, -1, -1, -1, p.JOINT_FIXED, [0, 0, 0], [0, 0, 0], list(pos),
                                             childFrameOrientation=list(orn))
        p.changeConstraint(self._root_hold, maxForce=float(max(max_force, 0.0)))

    def release_root(self) -> None:
        if self._root_hold is not None:
            self._p.removeConstraint(self._root_hold)
            self._root_hold = None

    def set_root_velocity(self, linear, angular) -> None:
        self._movable_root()
        self._p.resetBaseVelocity(self.body, [float(v) for v in linear], [float(v) for v in angular])

    def save_state(self) -> int:
        return self._p.saveState()

    def restore_state(self, handle: int) -> None:
        self._p.restoreState(stateId=handle)
        self._teleported = True

    def discard_state(self, handle: int) -> None:
        self._p.removeState(handle)

    def link_index(self, link_name: str) -> int:
        """Bullet's link index (-1 for the root) of a link (KeyError: unknown link)."""
        return self._link_index[link_name]

    def held_physics(self) -> HeldPhysics:
        p = self._p
        links = {}
        for idx, name in self._link_by_index.items():
            info = p.getDynamicsInfo(self.body, idx)
            links[name] = HeldLink(mass=float(info[0]), com=np.array(info[3], float), principal=np.sort(np.array(info[2], float)))
        q = self.joint_positions()
        joints = {}
        for name, j in self._index.items():
            info = p.getJointInfo(self.body, j)
            lo, hi = self.joint_limits[name]
            s = self.options.springs.get(name)
            joints[name] = HeldJoint(lower=lo, upper=hi, damping=float(info[6]), friction=float(info[7]),
                                     stiffness=s.stiffness if s else 0.0, reference=s.reference if s else None,
                                     position=q[name])
        how = {"mass, com, inertia": "getDynamicsInfo [0], [3], [2]", "limits, damping, friction": "getJointInfo [8:10], [6], [7]",
               "spring": "session torque -k (q - q_s) (Bullet has no joint spring)", "position": "getJointState"}
        welded = [self.base_link] if self.options.fixed_base else []
        return HeldPhysics(engine=self.engine, source="urdf", links=links, joints=joints, how=how, welded_to_world=welded)

    def close(self) -> None:
        """Disconnect its own client; in a caller's, remove what the session added."""
        if self.cid is not None:
            try:
                self._release()
            finally:
                self.cid = None

    def _release(self) -> None:
        p = self._p
        if self._owns_client:
            pybullet_clients.give_back(self._bullet, self.cid, self.options.files_key)
            return
        self.release_root()
        for body in (self.body, self.plane):
            if body is not None:
                p.removeBody(body)

    def __del__(self):  # pragma: no cover - best effort
        try:
            if getattr(self, "cid", None) is not None and self._owns_client:
                self._bullet.disconnect(self.cid)
        except Exception:
            pass


register_engine("pybullet", PyBulletSession)
register_shape_world("pybullet", PyBulletShapeWorld)
register_viewer("pybullet", PyBulletViewer)
