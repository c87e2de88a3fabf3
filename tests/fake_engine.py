"""The fake engine for fast tests (pure numpy): :class:`FakeSession`, a
deterministic :class:`~asset2sim.engines.base.SimSession` without physics whose
joints and root follow closed-form trajectories set by a :class:`FakeBehaviour`,
so tests can be made to pass or fail on purpose. Units SI, radians.

``tests/conftest.py`` registers it as the engine ``"fake"``.
"""

from __future__ import annotations

import contextlib
import math
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Callable, Iterator

import numpy as np

from asset2sim.engines.base import (ContactPair, EngineUnsupported, HeldJoint, HeldLink, HeldPhysics, SessionDefaults,
                                    SessionOptions, principal_moments)
from asset2sim.engines.loading import BOX_CORNERS, BULLET_DEFAULT_INERTIA, BULLET_DEFAULT_MASS, collision_pieces, read_urdf
from asset2sim.frames import quat_wxyz_matrix


@dataclass
class FakeBehaviour:
    """What a :class:`FakeSession` does, closed-form in the time t (s) since a joint was set:
    ``penetration`` Phi (m, or a function of the joint positions) on ``pair``
    (default: the first two links that are not parent and child); a constant
    root drift ``root_velocity`` (3,) m/s and ``root_yaw_rate`` rad/s (none
    with ``fixed_base``); ``joint_drift`` joint -> rad/s or m/s and
    ``joint_oscillation`` joint -> (amplitude rad or m, frequency Hz) (``"*"``:
    all joints); ``ground_penetration`` m; with ``springs_pull`` a sprung joint
    relaxes to its reference (time constant ``spring_time_constant`` s).
    Positions are clipped to the joint limits.
    """

    penetration: float | Callable[[dict[str, float]], float] = 0.0
    pair: tuple[str, str] | None = None
    root_velocity: tuple[float, float, float] = (0.0, 0.0, 0.0)
    root_yaw_rate: float = 0.0
    joint_drift: dict[str, float] = field(default_factory=dict)
    joint_oscillation: dict[str, tuple[float, float]] = field(default_factory=dict)
    ground_penetration: float = 0.0
    springs_pull: bool = True
    spring_time_constant: float = 0.2


_DEFAULT_BEHAVIOUR = FakeBehaviour()


@contextlib.contextmanager
def fake_behaviour(behaviour: FakeBehaviour | None = None, **changes) -> Iterator[FakeBehaviour]:
    """Within the block, sessions opened with ``open_session("fake", ...)`` use
    ``behaviour`` (or the default with ``changes`` applied)."""
    global _DEFAULT_BEHAVIOUR
    old = _DEFAULT_BEHAVIOUR
    _DEFAULT_BEHAVIOUR = replace(behaviour or FakeBehaviour(), **changes)
    try:
        yield _DEFAULT_BEHAVIOUR
    finally:
        _DEFAULT_BEHAVIOUR = old


class FakeSession(SessionDefaults):
    """A session without physics (see the module docstring; UrdfError: the URDF cannot be read)."""

    engine = "fake"

    def __init__(self, urdf_path: Path, options: SessionOptions, behaviour: FakeBehaviour | None = None):
        self.model = read_urdf(urdf_path)
        self.options = options
        self.behaviour = behaviour or _DEFAULT_BEHAVIOUR
        self.dt = options.conventions.timestep
        self._use_urdf(self.model)
        self.link_names = self.model.tree_order()
        self.steps = 0
        self._anchor = {n: (0.0, 0) for n in self.joint_names}  # value, step when set
        self._driven: dict[str, float] = {}  # joint -> drive velocity (drive_joint)
        self.set_joint_positions(options.initial_state)
        self._root0 = np.zeros(3)
        self._root_q0: np.ndarray | None = None  # xyzw set by set_root_pose
        self._points: dict[str, np.ndarray] | None = None
        self._states: dict[int, tuple] = {}

    def _t(self, name: str, steps: int | None = None) -> float:
        return ((self.steps if steps is None else steps) - self._anchor[name][1]) * self.dt

    def _value(self, name: str, steps: int | None = None) -> float:
        b = self.behaviour
        q0, _ = self._anchor[name]
        t = self._t(name, steps)
        spring = self.options.springs.get(name)
        if name in self._driven:
            q = q0 + self._driven[name] * t
        elif spring is not None and b.springs_pull and spring.stiffness > 0:
            q = spring.reference + (q0 - spring.reference) * math.exp(-t / b.spring_time_constant)
        else:
            q = q0 + b.joint_drift.get(name, b.joint_drift.get("*", 0.0)) * t
        osc = b.joint_oscillation.get(name, b.joint_oscillation.get("*"))
        if osc is not None:
            q += osc[0] * math.sin(2 * math.pi * osc[1] * t)
        lo, hi = self.joint_limits[name]
        return float(min(max(q, lo), hi))

    def set_joint_positions(self, q: dict[str, float]) -> None:
        for name, v in q.items():
            if name in self._anchor:
                self._anchor[name] = (float(v), self.steps)

    def joint_positions(self) -> dict[str, float]:
        return {n: self._value(n) for n in self.joint_names}

    def joint_state(self, joint: str) -> tuple[float, float]:
        """Position and the backward difference over the last step (0 right after a set)."""
        q = self._value(joint)
        if self.steps - self._anchor[joint][1] < 1:
            return q, 0.0
        return q, (q - self._value(joint, self.steps - 1)) / self.dt

    def joint_velocities(self) -> dict[str, float]:
        return {n: self.joint_state(n)[1] for n in self.joint_names}

    def joint_axis(self, joint: str) -> np.ndarray:
        if joint not in self.joint_child:
            raise KeyError(joint)
        return np.asarray(self.model.parent_joint(self.joint_child[joint]).axis, float).copy()

    def apply_joint_effort(self, joint: str, effort: float) -> None:
        raise EngineUnsupported("fake: no dynamics; joint efforts are not modelled")

    def drive_joint(self, joint: str, velocity: float, max_force: float) -> None:
        """Kinematic: from now the joint moves at ``velocity`` (clipped at its limits); ``max_force`` is not modelled."""
        if joint not in self._anchor:
            raise KeyError(joint)
        self._anchor[joint] = (self._value(joint), self.steps)
        self._driven[joint] = float(velocity)

    def release_joint(self, joint: str) -> None:
        if joint not in self._anchor:
            raise KeyError(joint)
        self._anchor[joint] = (self._value(joint), self.steps)
        self._driven.pop(joint, None)

    def set_root_velocity(self, linear, angular) -> None:
        raise EngineUnsupported("fake: no dynamics; root velocities are not modelled")

    def apply_link_force(self, link: str, force, point) -> None:
        raise EngineUnsupported("fake: no dynamics; external forces are not modelled")

    # ------------------------------------------------------------------ links
    def link_frame(self, link: str) -> tuple[np.ndarray, np.ndarray]:
        if link not in self.model.links:
            raise KeyError(link)
        pos, orn = self.root_pose()
        root = np.eye(4)
        root[:3, :3] = quat_wxyz_matrix([orn[3], orn[0], orn[1], orn[2]])
        root[:3, 3] = pos
        t = self.model.link_poses(self.joint_positions(), root)[link]
        return t[:3, 3].copy(), t[:3, :3].copy()

    def _local_points(self, link: str) -> np.ndarray:
        """Collision points (k, 3) of a link in its frame: hull vertices and
        the corners of the primitives' boxes."""
        if self._points is None:
            pieces, _ = collision_pieces(self.model)
            self._points = {}
            for name, plist in pieces.items():
                pts = []
                for p in plist:
                    if p.kind == "hull":
                        v = np.asarray(p.points, float)
                    else:
                        h = (np.asarray(p.size, float) / 2 if p.kind == "box"
                             else np.array([p.radius, p.radius, p.radius if p.kind == "sphere" else p.length / 2]))
                        v = BOX_CORNERS * h
                    pts.append(v @ p.origin[:3, :3].T + p.origin[:3, 3])
                self._points[name] = np.concatenate(pts) if pts else np.zeros((0, 3))
        if link not in self.model.links:
            raise KeyError(link)
        return self._points.get(link, np.zeros((0, 3)))

    def link_collision_vertices(self, link: str) -> np.ndarray:
        return self._local_points(link).copy()

    def link_aabb(self, link: str) -> tuple[np.ndarray, np.ndarray]:
        pos, R = self.link_frame(link)
        v = self._local_points(link)
        if not len(v):
            return pos.copy(), pos.copy()
        w = v @ R.T + pos
        return w.min(axis=0), w.max(axis=0)

    def link_has_collision(self, link: str) -> bool:
        return bool(self.model.links[link].collisions)

    def link_masses(self) -> dict[str, float]:
        """The file's masses; PyBullet's 1 kg for a link without ``<inertial>``."""
        links = self.model.links
        return {n: BULLET_DEFAULT_MASS if links[n].inertial is None else float(links[n].inertial.mass) for n in self.link_names}

    def link_distances(self, link_a: str, link_b: str, max_distance: float = 0.0) -> list[float]:
        """The behaviour's penetration, for its pair only: [-Phi] or []."""
        for ln in (link_a, link_b):
            if ln not in self.model.links:
                raise KeyError(ln)
        phi, pairs = self.self_penetration()
        if pairs and {link_a, link_b} == {pairs[0].link_a, pairs[0].link_b} and -phi < max_distance:
            return [-phi]
        return []

    def _pair(self) -> tuple[str, str]:
        if self.behaviour.pair is not None:
            return self.behaviour.pair
        names = self.model.tree_order()
        adj = self.model.adjacent_pairs()
        for i, a in enumerate(names):
            for b in names[i + 1:]:
                if frozenset((a, b)) not in adj:
                    return (a, b) if a <= b else (b, a)
        return (names[0], names[-1])

    def self_penetration(self) -> tuple[float, list[ContactPair]]:
        pen = self.behaviour.penetration
        phi = float(pen(self.joint_positions()) if callable(pen) else pen)
        phi = max(0.0, phi)
        if phi <= 0:
            return 0.0, []
        a, b = self._pair()
        return phi, [ContactPair(a, b, phi, phi, 1)]

    def ground_penetration(self) -> float:
        return float(self.behaviour.ground_penetration)

    def root_pose(self) -> tuple[np.ndarray, np.ndarray]:
        if self.options.fixed_base:
            q = np.array([0.0, 0.0, 0.0, 1.0]) if self._root_q0 is None else self._root_q0.copy()
            return self._root0.copy(), q
        t = self.steps * self.dt
        pos = self._root0 + np.asarray(self.behaviour.root_velocity, float) * t
        half = 0.5 * self.behaviour.root_yaw_rate * t
        yaw = np.array([0.0, 0.0, math.sin(half), math.cos(half)])
        if self._root_q0 is None:
            return pos, yaw
        return pos, _yawed(self._root_q0, yaw[2], yaw[3])  # yaw (about world z) after the set orientation

    def set_root_pose(self, pos, orn) -> None:
        """The behaviour's drift continues from here."""
        t = 0.0 if self.options.fixed_base else self.steps * self.dt
        self._root0 = np.asarray(pos, float) - np.asarray(self.behaviour.root_velocity, float) * t
        q = np.asarray(orn, float)
        self._root_q0 = q / np.linalg.norm(q)
        if not self.options.fixed_base and self.behaviour.root_yaw_rate:
            half = 0.5 * self.behaviour.root_yaw_rate * t  # undo the yaw already accumulated
            self._root_q0 = _yawed(self._root_q0, -math.sin(half), math.cos(half))

    def save_state(self) -> int:
        handle = max(self._states, default=0) + 1
        self._states[handle] = (self.steps, dict(self._anchor), self._root0.copy(),
                                None if self._root_q0 is None else self._root_q0.copy())
        return handle

    def restore_state(self, handle: int) -> None:
        steps, anchor, root0, rq = self._states[handle]
        self.steps, self._anchor, self._root0 = steps, dict(anchor), root0.copy()
        self._root_q0 = None if rq is None else rq.copy()

    def discard_state(self, handle: int) -> None:
        self._states.pop(handle, None)

    def step(self, n: int = 1) -> None:
        self.steps += int(n)

    def held_physics(self) -> HeldPhysics:
        """The file's values (PyBullet's default without ``<inertial>``), the options' springs."""
        links = {}
        for name in self.link_names:
            ine = self.model.links[name].inertial
            if ine is None or ine.mass is None:
                links[name] = HeldLink(BULLET_DEFAULT_MASS, np.zeros(3), np.sort(np.array(BULLET_DEFAULT_INERTIA, float)))
            else:
                links[name] = HeldLink(float(ine.mass), np.asarray(ine.com(), float), principal_moments(ine.inertia_in_link_axes()))
        q = self.joint_positions()
        joints = {}
        for j in self.model.movable_joints:
            s = self.options.springs.get(j.name)
            joints[j.name] = HeldJoint(j.lower, j.upper, float(j.damping), float(j.friction), s.stiffness if s else 0.0,
                                       s.reference if s else None, q[j.name])
        return HeldPhysics(engine=self.engine, source="urdf", links=links, joints=joints, how={"all": "the URDF as read"})

    def close(self) -> None:
        pass


def _yawed(q: np.ndarray, sz: float, cz: float) -> np.ndarray:
    """Quaternion ``q`` (xyzw) turned about world z by twice the angle of sine ``sz``, cosine ``cz``."""
    x, y, z, w = q
    return np.array([cz * x - sz * y, cz * y + sz * x, cz * z + sz * w, cz * w - sz * z])


__all__ = ["FakeBehaviour", "FakeSession", "fake_behaviour"]
