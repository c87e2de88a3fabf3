"""PyBullet (Bullet) engine under the SPEC's conventions; see :mod:`.base`.

Each session owns its own DIRECT-mode physics client, so sessions are
independent and can live side by side in one process.

Verified behaviour of PyBullet 3.2.7 that this module relies on (see
``tests/asset2sim/test_engines.py``): ``<dynamics damping>`` from the URDF is
applied by Bullet as viscous joint damping; every joint starts with a velocity
motor of non-zero force, which we replace by a zero-target-velocity motor whose
force is ``<dynamics friction>`` (Coulomb friction, SPEC).
"""

from __future__ import annotations

import os
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from asset2sim.engines.base import ContactPair, SessionOptions, register_engine

_TYPES = {0: "revolute", 1: "prismatic", 2: "spherical", 3: "planar", 4: "fixed"}


@contextmanager
def _quiet_stdout():
    """Silence Bullet's C-level prints (b3Warning ...) on fd 1 during loading."""
    try:
        fd = os.dup(1)
    except OSError:  # no stdout
        yield
        return
    devnull = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(devnull, 1)
        yield
    finally:
        os.dup2(fd, 1)
        os.close(fd)
        os.close(devnull)


def _bullet():
    import pybullet

    return pybullet


class PyBulletSession:
    """A :class:`~asset2sim.engines.base.SimSession` in PyBullet DIRECT mode."""

    engine = "pybullet"

    def __init__(self, urdf_path: Path, options: SessionOptions):
        p = _bullet()
        self._p = p
        self.options = options
        conv = options.conventions
        with _quiet_stdout():
            self.cid = p.connect(p.DIRECT)
        try:
            p.setTimeStep(conv.timestep, physicsClientId=self.cid)
            p.setGravity(0, 0, conv.gravity if options.gravity else 0.0, physicsClientId=self.cid)
            self.plane = None
            if options.ground:
                shape = p.createCollisionShape(p.GEOM_PLANE, physicsClientId=self.cid)
                self.plane = p.createMultiBody(0, shape, physicsClientId=self.cid)
            flags = (
                p.URDF_USE_SELF_COLLISION
                | p.URDF_USE_SELF_COLLISION_EXCLUDE_PARENT
                | p.URDF_USE_INERTIA_FROM_FILE
            )
            with _quiet_stdout():
                self.body = p.loadURDF(
                    str(urdf_path),
                    useFixedBase=options.fixed_base,
                    flags=flags,
                    physicsClientId=self.cid,
                )
        except Exception as exc:
            p.disconnect(self.cid)
            raise RuntimeError(f"PyBullet could not load {urdf_path}: {exc}") from exc
        self.base_link = p.getBodyInfo(self.body, physicsClientId=self.cid)[0].decode()
        self.link_names: dict[int, str] = {-1: self.base_link}
        self._index: dict[str, int] = {}
        self.joint_names: list[str] = []
        self.joint_types: dict[str, str] = {}
        self.joint_limits: dict[str, tuple[float, float]] = {}
        self.joint_child: dict[str, str] = {}
        for j in range(p.getNumJoints(self.body, physicsClientId=self.cid)):
            info = p.getJointInfo(self.body, j, physicsClientId=self.cid)
            name = info[1].decode()
            self.link_names[j] = info[12].decode()
            jtype = _TYPES.get(info[2], "other")
            if jtype not in ("revolute", "prismatic"):
                continue
            lo, hi = float(info[8]), float(info[9])
            if lo > hi:  # continuous joint: Bullet reports lower=0, upper=-1
                jtype, lo, hi = "continuous", -np.inf, np.inf
            self.joint_names.append(name)
            self._index[name] = j
            self.joint_types[name] = jtype
            self.joint_limits[name] = (lo, hi)
            self.joint_child[name] = info[12].decode()
            # Coulomb friction: zero-target-velocity motor with max force = <dynamics friction>.
            p.setJointMotorControl2(
                self.body,
                j,
                p.VELOCITY_CONTROL,
                targetVelocity=0.0,
                force=float(info[7]),
                physicsClientId=self.cid,
            )
        self.set_joint_positions(options.initial_state)
        if options.ground and not options.fixed_base:
            self.place_on_ground()

    # ------------------------------------------------------------------ state
    def set_joint_positions(self, q: dict[str, float], zero_velocity: bool = True) -> None:
        p = self._p
        for name, value in q.items():
            j = self._index.get(name)
            if j is None:
                continue
            vel = 0.0 if zero_velocity else p.getJointState(self.body, j, physicsClientId=self.cid)[1]
            p.resetJointState(self.body, j, float(value), vel, physicsClientId=self.cid)

    def joint_positions(self) -> dict[str, float]:
        p = self._p
        if not self._index:
            return {}
        states = p.getJointStates(self.body, list(self._index.values()), physicsClientId=self.cid)
        return {name: float(s[0]) for name, s in zip(self._index, states)}

    def joint_velocities(self) -> dict[str, float]:
        p = self._p
        if not self._index:
            return {}
        states = p.getJointStates(self.body, list(self._index.values()), physicsClientId=self.cid)
        return {name: float(s[1]) for name, s in zip(self._index, states)}

    def root_pose(self) -> tuple[np.ndarray, np.ndarray]:
        pos, orn = self._p.getBasePositionAndOrientation(self.body, physicsClientId=self.cid)
        return np.array(pos, float), np.array(orn, float)

    def set_root_pose(self, pos, orn) -> None:
        self._p.resetBasePositionAndOrientation(self.body, list(pos), list(orn), physicsClientId=self.cid)
        self._p.resetBaseVelocity(self.body, [0, 0, 0], [0, 0, 0], physicsClientId=self.cid)

    def place_on_ground(self) -> float:
        """Translate the root so the lowest collision point touches z = 0.

        Returns the vertical shift applied (m).
        """
        p = self._p
        lo = min(
            p.getAABB(self.body, link, physicsClientId=self.cid)[0][2] for link in self.link_names
        )
        pos, orn = self.root_pose()
        shift = -lo
        self.set_root_pose(pos + np.array([0.0, 0.0, shift]), orn)
        # Refine with exact signed distances to the plane: Bullet's AABBs of
        # rotated hulls are loose (up to tens of cm above the true lowest point).
        if self.plane is not None:
            p.performCollisionDetection(physicsClientId=self.cid)
            hi = max(p.getAABB(self.body, link, physicsClientId=self.cid)[1][2] for link in self.link_names)
            pts = p.getClosestPoints(self.body, self.plane, max(hi, 0.0) + 0.05, physicsClientId=self.cid)
            if pts:
                dmin = min(pt[8] for pt in pts)
                pos, orn = self.root_pose()
                self.set_root_pose(pos - np.array([0.0, 0.0, dmin]), orn)
                shift -= dmin
        return float(shift)

    # ---------------------------------------------------------------- contact
    def self_penetration(self) -> tuple[float, list[ContactPair]]:
        p = self._p
        p.performCollisionDetection(physicsClientId=self.cid)
        return self._penetration_of(p.getContactPoints(self.body, self.body, physicsClientId=self.cid))

    def _penetration_of(self, points) -> tuple[float, list[ContactPair]]:
        """Phi (m) and per-pair sums of Bullet contact/closest points (fields 3/4:
        link indices, 8: signed distance)."""
        pairs: dict[tuple[str, str], ContactPair] = {}
        total = 0.0
        for pt in points:
            d = pt[8]
            if d >= 0.0:
                continue
            a, b = self.link_names[pt[3]], self.link_names[pt[4]]
            key = (a, b) if a <= b else (b, a)
            cp = pairs.get(key)
            if cp is None:
                cp = pairs[key] = ContactPair(key[0], key[1], 0.0, 0.0, 0)
            cp.depth += -d
            cp.max_depth = max(cp.max_depth, -d)
            cp.points += 1
            total += -d
        return total, sorted(pairs.values(), key=lambda c: -c.depth)

    def self_penetration_fresh(self) -> tuple[float, list[ContactPair]]:
        """Phi (m) like :meth:`self_penetration`, but from ``getClosestPoints``
        per link pair (parent-child pairs excluded, as the SPEC's flags do), so
        the value cannot depend on contact points Bullet cached at earlier
        states of the same session (its persistent manifolds do). Equal to
        :meth:`self_penetration` in a fresh session; used by searches that
        query many states in one session."""
        p = self._p
        cache = self.__dict__.setdefault("_pairs_cache", None)
        if cache is None:
            with_shape = [i for i in self.link_names if p.getCollisionShapeData(self.body, i, physicsClientId=self.cid)]
            parent = {j: p.getJointInfo(self.body, j, physicsClientId=self.cid)[16] for j in range(p.getNumJoints(self.body, physicsClientId=self.cid))}
            cache = [
                (a, b)
                for a in with_shape
                for b in with_shape
                if a < b and parent.get(b) != a and parent.get(a) != b
            ]
            self._pairs_cache = cache
        points = []
        for a, b in cache:
            points.extend(p.getClosestPoints(self.body, self.body, 0.0, a, b, physicsClientId=self.cid))
        return self._penetration_of(points)

    def ground_penetration(self) -> float:
        if self.plane is None:
            return 0.0
        p = self._p
        p.performCollisionDetection(physicsClientId=self.cid)
        pts = p.getContactPoints(self.body, self.plane, physicsClientId=self.cid)
        return float(max([0.0] + [-pt[8] for pt in pts]))

    # --------------------------------------------------------------- dynamics
    def step(self, n: int = 1) -> None:
        p = self._p
        springs = self.options.springs
        for _ in range(n):
            if springs:
                q = self.joint_positions()
                for name, spring in springs.items():
                    j = self._index.get(name)
                    if j is None:
                        continue
                    tau = -spring.stiffness * (q[name] - spring.reference)
                    p.setJointMotorControl2(
                        self.body, j, p.TORQUE_CONTROL, force=tau, physicsClientId=self.cid
                    )
            p.stepSimulation(physicsClientId=self.cid)

    def apply_joint_effort(self, name: str, effort: float) -> None:
        """Apply a generalized force (N*m or N) to a joint for the next step."""
        self._p.setJointMotorControl2(
            self.body, self._index[name], self._p.TORQUE_CONTROL, force=float(effort), physicsClientId=self.cid
        )

    def link_index(self, link_name: str) -> int:
        for idx, name in self.link_names.items():
            if name == link_name:
                return idx
        raise KeyError(link_name)

    def close(self) -> None:
        if self.cid is not None:
            try:
                self._p.disconnect(self.cid)
            finally:
                self.cid = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def __del__(self):  # pragma: no cover - best effort
        try:
            if getattr(self, "cid", None) is not None:
                self._p.disconnect(self.cid)
        except Exception:
            pass


def _open(urdf_path: Path, options: SessionOptions) -> PyBulletSession:
    return PyBulletSession(urdf_path, options)


register_engine("pybullet", _open)
