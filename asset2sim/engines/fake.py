"""The fake engine: a simulator without physics for fast tests.

Two things live here, pure numpy (no simulator is imported); what every
engine loads from a URDF is in :mod:`asset2sim.engines.loading`.

1. :class:`FakeSession`: a deterministic :class:`~asset2sim.engines.base.SimSession`
   without physics. Joints and root follow closed-form trajectories set by a
   :class:`FakeBehaviour` (constant drift, sinusoidal oscillation, a
   penetration that may depend on the joint positions), so metric and pipeline
   tests run in milliseconds and can be made to pass or fail on purpose.
2. :func:`write_contract_asset`: writes a small asset that satisfies the SPEC's
   output contract (URDF + OBJ meshes, an ``<inertial>`` on every link,
   ``<dynamics>`` on every movable joint, ``initial_state.json`` and
   ``overlay.json``) for tests of engines, export and parity.

Units: SI, radians; poses are 4x4 homogeneous matrices (m) unless stated.
"""

from __future__ import annotations

import contextlib
import math
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Callable, Iterator

import numpy as np

from asset2sim import atomic
from asset2sim.engines.base import (
    ContactPair,
    EngineUnsupported,
    HeldJoint,
    HeldLink,
    HeldPhysics,
    NoRootHold,
    SessionOptions,
    principal_moments,
    register_engine,
)
from asset2sim.engines.loading import BULLET_DEFAULT_INERTIA, BULLET_DEFAULT_MASS, collision_pieces, read_urdf
from asset2sim.frames import quat_wxyz_matrix, translation_matrix
from asset2sim.urdf import (
    UrdfDynamics,
    UrdfGeometry,
    UrdfInertial,
    UrdfJoint,
    UrdfLimit,
    UrdfLink,
    UrdfModel,
    write_urdf,
)
from asset2sim.output_folder import OVERLAY_NAME, STATE_NAME, URDF_NAME


@dataclass
class FakeBehaviour:
    """What a :class:`FakeSession` does, all closed-form in time t (s) since
    the joint was last set.

    - ``penetration``: Phi (m), a constant or a function of the joint positions
      (dict -> m), attributed to ``pair`` (default: the first two links that
      are not parent and child, else the first two links).
    - ``root_velocity`` (3,) m/s and ``root_yaw_rate`` rad/s: constant drift
      of the root (zero with ``fixed_base``).
    - ``joint_drift``: joint -> rad/s or m/s (``"*"`` for all joints).
    - ``joint_oscillation``: joint -> (amplitude, frequency): q += a sin(2 pi f t),
      a in rad or m (half the peak-to-peak), f in Hz (``"*"`` for all joints).
    - ``ground_penetration`` m.
    - ``springs_pull``: when True (default) a joint with a spring relaxes to its
      reference with time constant ``spring_time_constant`` s instead of drifting.
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


class FakeSession(NoRootHold):
    """A :class:`~asset2sim.engines.base.SimSession` without physics (see the
    module docstring). Deterministic: the same calls give the same numbers.

    Raises (constructor):
        UrdfError: the URDF cannot be read.
    """

    engine = "fake"

    def __init__(self, urdf_path: Path, options: SessionOptions, behaviour: FakeBehaviour | None = None):
        self.model = read_urdf(urdf_path)
        self.options = options
        self.behaviour = behaviour or _DEFAULT_BEHAVIOUR
        self.dt = options.conventions.timestep
        self.joint_names = [j.name for j in self.model.movable_joints]
        self.joint_types = {j.name: j.type for j in self.model.movable_joints}
        self.joint_limits = {j.name: (j.lower, j.upper) for j in self.model.movable_joints}
        self.joint_child = {j.name: j.child for j in self.model.movable_joints}
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

    def set_joint_positions(self, q: dict[str, float], zero_velocity: bool = True) -> None:
        for name, v in q.items():
            if name in self._anchor:
                self._anchor[name] = (float(v), self.steps)

    def joint_positions(self) -> dict[str, float]:
        return {n: self._value(n) for n in self.joint_names}

    def joint_state(self, joint: str) -> tuple[float, float]:
        """Position and the backward difference over the last step (0 right
        after the joint was set)."""
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
        """Raises :class:`EngineUnsupported`: the fake has no dynamics."""
        raise EngineUnsupported("fake: no dynamics; joint efforts are not modelled")

    def drive_joint(self, joint: str, velocity: float, max_force: float) -> None:
        """Kinematic drive: from now the joint moves at ``velocity`` (rad/s or
        m/s, clipped at its limits) instead of the behaviour's drift; the fake
        has no forces, so ``max_force`` is not modelled."""
        if joint not in self._anchor:
            raise KeyError(joint)
        self._anchor[joint] = (self._value(joint), self.steps)
        self._driven[joint] = float(velocity)

    def release_joint(self, joint: str) -> None:
        """The joint follows the behaviour again from where it is."""
        if joint not in self._anchor:
            raise KeyError(joint)
        self._anchor[joint] = (self._value(joint), self.steps)
        self._driven.pop(joint, None)

    def set_root_velocity(self, linear, angular) -> None:
        """Raises :class:`EngineUnsupported`: the fake has no dynamics."""
        raise EngineUnsupported("fake: no dynamics; root velocities are not modelled")

    def apply_link_force(self, link: str, force, point) -> None:
        """Raises :class:`EngineUnsupported`: the fake has no dynamics."""
        raise EngineUnsupported("fake: no dynamics; external forces are not modelled")

    # ------------------------------------------------------------------ links
    def link_frame(self, link: str) -> tuple[np.ndarray, np.ndarray]:
        """Forward kinematics of the URDF at the current joint positions and root pose."""
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
                        v = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)]) * h
                    pts.append(v @ p.origin[:3, :3].T + p.origin[:3, 3])
                self._points[name] = np.concatenate(pts) if pts else np.zeros((0, 3))
        if link not in self.model.links:
            raise KeyError(link)
        return self._points.get(link, np.zeros((0, 3)))

    def link_collision_vertices(self, link: str) -> np.ndarray:
        return self._local_points(link).copy()

    def link_aabb(self, link: str) -> tuple[np.ndarray, np.ndarray]:
        """Bounds of the link's collision points at the current state (its
        origin when it has none)."""
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
        return {
            name: BULLET_DEFAULT_MASS if link.inertial is None else float(link.inertial.mass)
            for name, link in ((n, self.model.links[n]) for n in self.link_names)
        }

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

    def step_ground_penetration(self) -> float:
        return self.ground_penetration()

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
        x, y, z, w = self._root_q0  # yaw (about world z) after the set orientation
        sz, cz = yaw[2], yaw[3]
        return pos, np.array([cz * x - sz * y, cz * y + sz * x, cz * z + sz * w, cz * w - sz * z])

    def set_root_pose(self, pos, orn) -> None:
        """Put the root at ``pos`` (3,) m, ``orn`` (4,) xyzw now; the behaviour's
        drift continues from there."""
        t = 0.0 if self.options.fixed_base else self.steps * self.dt
        self._root0 = np.asarray(pos, float) - np.asarray(self.behaviour.root_velocity, float) * t
        q = np.asarray(orn, float)
        self._root_q0 = q / np.linalg.norm(q)
        if not self.options.fixed_base and self.behaviour.root_yaw_rate:
            half = 0.5 * self.behaviour.root_yaw_rate * t  # undo the yaw already accumulated
            x, y, z, w = self._root_q0
            sz, cz = -math.sin(half), math.cos(half)
            self._root_q0 = np.array([cz * x - sz * y, cz * y + sz * x, cz * z + sz * w, cz * w - sz * z])

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
        """The file's values (the fake engine holds the URDF it read; links
        without ``<inertial>``: PyBullet's 1 kg, unit inertia), springs from
        the options, positions the current ones."""
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

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def _open(urdf_path: Path, options: SessionOptions) -> FakeSession:
    return FakeSession(urdf_path, options)


register_engine("fake", _open)


# ------------------------------------------------------ contract test asset
def _box_obj(boxes: list[tuple[tuple[float, float, float], tuple[float, float, float]]], groups: bool = True) -> str:
    """OBJ text of axis-aligned boxes given as (min corner, max corner), one
    ``o`` group each (or one group for all when ``groups`` is False)."""
    faces = [(0, 1, 3), (0, 3, 2), (4, 6, 7), (4, 7, 5), (0, 4, 5), (0, 5, 1), (2, 3, 7), (2, 7, 6), (0, 2, 6), (0, 6, 4), (1, 5, 7), (1, 7, 3)]
    lines, off = [], 1
    for k, (lo, hi) in enumerate(boxes):
        if groups or k == 0:
            lines.append(f"o piece_{k}")
        for i in range(8):
            x = hi[0] if i & 4 else lo[0]
            y = hi[1] if i & 2 else lo[1]
            z = hi[2] if i & 1 else lo[2]
            lines.append(f"v {x!r} {y!r} {z!r}")
        lines.extend(f"f {a + off} {b + off} {c + off}" for a, b, c in faces)
        off += 8
    return "\n".join(lines) + "\n"


def _box_inertia(mass: float, lo, hi) -> tuple[np.ndarray, np.ndarray]:
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    d = hi - lo
    return (lo + hi) / 2, mass / 12.0 * np.diag([d[1] ** 2 + d[2] ** 2, d[0] ** 2 + d[2] ** 2, d[0] ** 2 + d[1] ** 2])


def _combine(parts: list[tuple[float, np.ndarray, np.ndarray]]) -> tuple[float, np.ndarray, np.ndarray]:
    """Mass, COM (3,), inertia about the COM (3, 3) of point-mass-shifted parts."""
    m = sum(p[0] for p in parts)
    com = sum(p[0] * p[1] for p in parts) / m
    inertia = np.zeros((3, 3))
    for mi, ci, ii in parts:
        d = ci - com
        inertia += ii + mi * (np.dot(d, d) * np.eye(3) - np.outer(d, d))
    return m, com, inertia


@dataclass
class ContractAsset:
    """Paths and facts of an asset written by :func:`write_contract_asset`."""

    root: Path
    urdf: Path
    initial_state: dict[str, float]
    masses: dict[str, float]
    lid_mass: float
    lid_com_radius: float
    """distance (m) of the lid's COM from the hinge axis, in the lid plane"""
    post_overlap_at: float
    """post position (m) above which the post's top pokes into the closed lid"""


def write_contract_asset(
    out_dir: Path,
    *,
    lid_angle: float = 0.0,
    post_height: float = 0.0,
    lid_damping: float = 0.02,
    lid_friction: float = 0.02,
    lid_stiffness: float = 0.0,
    lid_spring_reference: float | None = None,
    post_damping: float = 1.0,
    post_friction: float = 2.0,
    base_inertial: bool = True,
    body_mass: float = 1.5,
    lid_mass: float = 0.2,
    latch: bool = False,
) -> ContractAsset:
    """Write a small box-with-lid asset that satisfies the SPEC output contract.

    Links: ``base`` (root, a fixed joint to ``body``; an ``<inertial>`` only
    when ``base_inertial``), ``body`` (an open box 0.30 x 0.20 x 0.12 m whose
    five walls are five ``o`` groups of one OBJ), ``lid`` (0.30 x 0.20 x 0.01 m
    plate on a revolute hinge along -x at the top back edge; ``lid_angle`` rad,
    positive opens; limits [0, 2.0]) and ``post`` (a 0.02 x 0.02 x 0.10 m
    square post standing in the box on a prismatic joint along +z, limits
    [0, 0.05] m; at ``post_height`` > ``post_overlap_at`` its top pokes into
    the closed lid, which is a sibling, so the two collide). With ``latch``
    a ``latch`` link (a 0.30 x 0.03 x 0.01 m bar, 0.02 kg) is fixed to the
    body across its front edge 1 mm above the closed lid: the lid is held
    shut by geometry rigid with its parent (a blocked joint that no other
    joint's position frees; a sibling link, since engines do not collide a
    child with its own parent).

    Masses kg, damping N*m*s/rad (lid) / N*s/m (post), friction N*m / N,
    stiffness N*m/rad. Files: ``mobility.urdf``, ``textured_objs/*.obj``,
    ``initial_state.json``, ``overlay.json``. Returns a :class:`ContractAsset`.
    """
    out = Path(out_dir)
    L, W, H, t = 0.30, 0.20, 0.12, 0.01
    walls = [
        ((-L / 2, -W / 2, 0.0), (L / 2, W / 2, t)),
        ((-L / 2, -W / 2, t), (-L / 2 + t, W / 2, H)),
        ((L / 2 - t, -W / 2, t), (L / 2, W / 2, H)),
        ((-L / 2 + t, -W / 2, t), (L / 2 - t, -W / 2 + t, H)),
        ((-L / 2 + t, W / 2 - t, t), (L / 2 - t, W / 2, H)),
    ]
    # The lid frame sits on the hinge at the top back edge (y = +W/2, z = H);
    # the plate extends towards -y, 0.5 mm above the walls, and the hinge axis
    # is -x so that positive angles lift its front edge.
    lid_lo, lid_hi = (-L / 2, -W, 0.0005), (L / 2, 0.0, 0.0005 + t)
    post_lo, post_hi = (-0.01, -0.01, t), (0.01, 0.01, t + 0.10)
    latch_lo, latch_hi = (-L / 2, -W / 2, H + 0.0015 + t), (L / 2, -W / 2 + 0.03, H + 0.0115 + t)
    gap = H + 0.0005 - post_hi[2]  # post top to lid underside at q=0
    atomic.write_text(out / "textured_objs" / "body.obj", _box_obj(walls))
    atomic.write_text(out / "textured_objs" / "lid.obj", _box_obj([(lid_lo, lid_hi)]))
    atomic.write_text(out / "textured_objs" / "post.obj", _box_obj([(post_lo, post_hi)]))
    if latch:
        atomic.write_text(out / "textured_objs" / "latch.obj", _box_obj([(latch_lo, latch_hi)]))

    vol = [np.prod(np.subtract(hi, lo)) for lo, hi in walls]
    body = _combine([(body_mass * v / sum(vol), *_box_inertia(body_mass * v / sum(vol), lo, hi)) for v, (lo, hi) in zip(vol, walls)])
    lid = (lid_mass, *_box_inertia(lid_mass, lid_lo, lid_hi))
    post_mass = 0.05
    post = (post_mass, *_box_inertia(post_mass, post_lo, post_hi))
    base = (0.01, np.zeros(3), np.diag([1e-5, 1e-5, 1e-5]))
    latch_part = (0.02, *_box_inertia(0.02, latch_lo, latch_hi))

    def link(name: str, parts, with_mesh: bool = True) -> UrdfLink:
        ln = UrdfLink(name=name)
        if parts is not None:
            m, com, inertia = parts
            ln.inertial = UrdfInertial(mass=float(m), origin=translation_matrix(com), inertia=np.asarray(inertia, float))
        if with_mesh:
            mesh = dict(kind="mesh", filename=f"textured_objs/{name}.obj", mesh_scale=np.ones(3))
            ln.visuals.append(UrdfGeometry(**mesh))
            ln.collisions.append(UrdfGeometry(**mesh))
        return ln

    def moving(name, jtype, child, origin, axis, upper, damping, friction) -> UrdfJoint:
        return UrdfJoint(
            name=name, type=jtype, parent="body", child=child, origin=translation_matrix(origin), axis_xyz=np.asarray(axis, float),
            limit=UrdfLimit(lower=0.0, upper=upper, effort=1000.0, velocity=1000.0),
            dynamics=UrdfDynamics(damping=float(damping), friction=float(friction)),
        )

    model = UrdfModel(
        name="contract_box",
        links={
            "base": link("base", base if base_inertial else None, with_mesh=False),
            "body": link("body", body),
            "lid": link("lid", lid),
            "post": link("post", post),
        },
        joints=[
            UrdfJoint(name="root_fixed", type="fixed", parent="base", child="body"),
            moving("lid_hinge", "revolute", "lid", (0.0, W / 2, H), (-1.0, 0.0, 0.0), 2.0, lid_damping, lid_friction),
            moving("post_slide", "prismatic", "post", (0.0, 0.0, 0.0), (0.0, 0.0, 1.0), 0.05, post_damping, post_friction),
        ],
    )
    if latch:
        model.links["latch"] = link("latch", latch_part)
        model.joints.append(UrdfJoint(name="latch_fixed", type="fixed", parent="body", child="latch"))
    urdf_text = write_urdf(model, comment=" initial joint positions: initial_state.json ")
    urdf_path = atomic.write_bytes(out / URDF_NAME, urdf_text)
    state = {"lid_hinge": float(lid_angle), "post_slide": float(post_height)}
    atomic.write_json(out / STATE_NAME, {"initial_joint_positions": state})

    def link_entry(m, com, inertia):
        return {
            "mass": float(m),
            "inertia": {k: float(inertia[i, j]) for k, (i, j) in {"ixx": (0, 0), "ixy": (0, 1), "ixz": (0, 2), "iyy": (1, 1), "iyz": (1, 2), "izz": (2, 2)}.items()},
            "com": [float(c) for c in com],
            "source": "geometry",
        }

    links = {"body": link_entry(*body), "lid": link_entry(*lid), "post": link_entry(*post)}
    if latch:
        links["latch"] = link_entry(*latch_part)
    if base_inertial:
        links["base"] = link_entry(*base)
    overlay = {
        "schema_version": "1.0",
        "estimator": {"name": "test-fixture", "queries": 0},
        "scale": 1.0,
        "links": links,
        "joints": {
            "lid_hinge": {
                "damping": float(lid_damping),
                "friction": float(lid_friction),
                "stiffness": float(lid_stiffness),
                "spring_reference": None if lid_spring_reference is None else float(lid_spring_reference),
            },
            "post_slide": {"damping": float(post_damping), "friction": float(post_friction), "stiffness": 0.0, "spring_reference": None},
        },
        "initial_joint_positions": state,
    }
    atomic.write_json(out / OVERLAY_NAME, overlay)
    masses = {"body": float(body[0]), "lid": float(lid[0]), "post": float(post[0])}
    if latch:
        masses["latch"] = float(latch_part[0])
    if base_inertial:
        masses["base"] = float(base[0])
    return ContractAsset(
        root=out,
        urdf=urdf_path,
        initial_state=state,
        masses=masses,
        lid_mass=lid_mass,
        lid_com_radius=W / 2,
        post_overlap_at=float(gap),
    )


__all__ = ["ContractAsset", "FakeBehaviour", "FakeSession", "fake_behaviour", "write_contract_asset"]
