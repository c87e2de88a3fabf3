"""MuJoCo engine under the SPEC's conventions; see :mod:`.base`. The session
compiles, in memory, the MJCF :func:`asset2sim.engines.mjcf.urdf_to_mjcf`
makes of the URDF (what ``asset2sim export --format mjcf`` writes).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from asset2sim.engines.base import (ArrayJoints, ContactPair, HeldJoint, HeldLink, HeldPhysics, SessionDefaults,
                                    SessionOptions, penetration_sum, register_engine, register_file_reader)
from asset2sim.engines.loading import BOX_CORNERS, read_urdf
from asset2sim.engines.mjcf import GROUND, KEYFRAME, lowest_point, urdf_to_mjcf
from asset2sim.engines.mjcf.base import load_mujoco as _mujoco, mesh_vertices, mujoco_call, safe_name
from asset2sim.engines.step_budget import spend
from asset2sim.frames import quat_wxyz_to_xyzw, quat_xyzw_to_wxyz


class MuJoCoSession(ArrayJoints, SessionDefaults):
    """A :class:`~asset2sim.engines.base.SimSession` in MuJoCo, compiled from
    :func:`urdf_to_mjcf` in memory (links without ``<inertial>``: PyBullet's
    default); ``notes``: what the conversion changed (UrdfError, MjcfError)."""

    engine = "mujoco"

    def __init__(self, urdf_path: Path, options: SessionOptions):
        mujoco = _mujoco()
        self._mj = mujoco
        self.options = options
        self.build = urdf_to_mjcf(urdf_path, options, missing_inertial="bullet")
        self.notes = list(self.build.notes)
        self.m = mujoco_call(lambda: mujoco.MjModel.from_xml_string(self.build.xml, assets=self.build.assets()),
                             f"MuJoCo could not compile {urdf_path}")
        self.d = mujoco.MjData(self.m)
        self._use_urdf(read_urdf(urdf_path))
        self.joint_names = list(self.build.joint_names)  # MuJoCo's compiled order
        self.link_names = [mujoco.mj_id2name(self.m, mujoco.mjtObj.mjOBJ_BODY, b) for b in range(1, self.m.nbody)]
        self._body = {n: b + 1 for b, n in enumerate(self.link_names)}
        self._geoms: dict[str, list[int]] = {n: [] for n in self.link_names}
        for g in range(self.m.ngeom):
            b = int(self.m.geom_bodyid[g])
            if b > 0 and (self.m.geom_contype[g] or self.m.geom_conaffinity[g]):
                self._geoms[self.link_names[b - 1]].append(g)
        self._state_sig = mujoco.mjtState.mjSTATE_INTEGRATION
        self._states: dict[int, np.ndarray] = {}
        self._applied = False
        self._drive: dict[str, tuple[float, float]] = {}  # joint -> (target velocity, force limit)
        jids = {n: mujoco.mj_name2id(self.m, mujoco.mjtObj.mjOBJ_JOINT, n) for n in self.joint_names}
        self._qadr = {n: int(self.m.jnt_qposadr[j]) for n, j in jids.items()}
        self._dadr = {n: int(self.m.jnt_dofadr[j]) for n, j in jids.items()}
        self._ground = mujoco.mj_name2id(self.m, mujoco.mjtObj.mjOBJ_GEOM, GROUND) if options.ground else -1
        self._root = self._body[self.urdf.root]
        mujoco.mj_resetDataKeyframe(self.m, self.d, mujoco.mj_name2id(self.m, mujoco.mjtObj.mjOBJ_KEY, KEYFRAME))
        self._forward()

    # ------------------------------------------------------------------ state
    def _joint_q(self) -> np.ndarray:
        return self.d.qpos

    def _joint_qd(self) -> np.ndarray:
        return self.d.qvel

    def _put_joints(self, q: np.ndarray, qd: np.ndarray) -> None:
        self._forward()  # q, qd: MjData's own arrays

    def _forward(self) -> None:
        """``mj_forward`` of the session's data: everything derived from its state."""
        self._mj.mj_forward(self.m, self.d)

    def joint_axis(self, joint: str) -> np.ndarray:
        jid = self._mj.mj_name2id(self.m, self._mj.mjtObj.mjOBJ_JOINT, joint)
        if joint not in self._qadr or jid < 0:
            raise KeyError(joint)
        return np.array(self.m.jnt_axis[jid], float)

    def apply_joint_effort(self, joint: str, effort: float) -> None:
        self.d.qfrc_applied[self._dadr[joint]] += float(effort)
        self._applied = True

    def drive_joint(self, joint: str, velocity: float, max_force: float) -> None:
        """A force-limited velocity drive in ``qfrc_applied`` before each step:
        tau = clip(f_c sign(v) + c v + Q + 0.5 * I_eff * (v - qdot) / dt, +-(max_force + f_c + |c v|))
        (f_c ``frictionloss``, c damping, Q the bias and spring forces of the last step (``qfrc_bias - qfrc_spring``:
        gravity and the spring held, as PyBullet's velocity motor holds them), I_eff = 1 / (M^-1)_ii from ``mj_solveM``:
        half the velocity error removed per step, stable for any inertia)."""
        if joint not in self._dadr:
            raise KeyError(joint)
        self._drive[joint] = (float(velocity), float(max(max_force, 0.0)))

    def release_joint(self, joint: str) -> None:
        if joint not in self._dadr:
            raise KeyError(joint)
        self._drive.pop(joint, None)

    def _apply_drives(self) -> None:
        mj = self._mj
        dt = float(self.m.opt.timestep)
        for joint, (v, fmax) in self._drive.items():
            i = self._dadr[joint]
            e = np.eye(1, self.m.nv, i)  # the unit row of dof i
            x = np.zeros_like(e)
            mj.mj_solveM(self.m, self.d, x, e)
            inertia = 1.0 / max(float(x[0, i]), 1e-12)
            load = float(self.m.dof_frictionloss[i]) * float(np.sign(v)) + float(self.m.dof_damping[i]) * v
            load += float(self.d.qfrc_bias[i] - self.d.qfrc_spring[i])  # gravity and the spring held, as a motor does
            limit = fmax + float(self.m.dof_frictionloss[i]) + abs(float(self.m.dof_damping[i]) * v)
            tau = float(np.clip(load + 0.5 * inertia * (v - float(self.d.qvel[i])) / dt, -limit, limit))
            self.d.qfrc_applied[i] += tau
        self._applied = True

    def set_root_velocity(self, linear, angular) -> None:
        """World-frame velocities (MuJoCo holds the angular one in the body frame)."""
        self._movable_root()
        R = np.zeros(9)
        self._mj.mju_quat2Mat(R, np.array(self.d.qpos[3:7], float))
        self.d.qvel[0:3] = np.asarray(linear, float)
        self.d.qvel[3:6] = R.reshape(3, 3).T @ np.asarray(angular, float)
        self._forward()

    # ------------------------------------------------------------------ links
    def link_frame(self, link: str) -> tuple[np.ndarray, np.ndarray]:
        b = self._body[link]
        self._mj.mj_kinematics(self.m, self.d)
        return np.array(self.d.xpos[b], float), np.array(self.d.xmat[b], float).reshape(3, 3)

    def _geom_points(self, g: int) -> np.ndarray:
        """Mesh vertices (or the corners of the geom's local box) (k, 3), body frame."""
        m = self.m
        if m.geom_type[g] == self._mj.mjtGeom.mjGEOM_MESH:
            v = np.asarray(mesh_vertices(m, g), float)
        else:
            c, h = np.asarray(m.geom_aabb[g][:3], float), np.asarray(m.geom_aabb[g][3:], float)
            v = c + BOX_CORNERS * h
        R = np.zeros(9)
        self._mj.mju_quat2Mat(R, np.asarray(m.geom_quat[g], float))
        return v @ R.reshape(3, 3).T + np.asarray(m.geom_pos[g], float)

    def link_collision_vertices(self, link: str) -> np.ndarray:
        out = [self._geom_points(g) for g in self._geoms[link] if self.m.geom_type[g] == self._mj.mjtGeom.mjGEOM_MESH]
        return np.concatenate(out) if out else np.zeros((0, 3))

    def link_aabb(self, link: str) -> tuple[np.ndarray, np.ndarray]:
        """Bounds of the colliding geoms' points; the body origin when it has none."""
        pts = [self._geom_points(g) for g in self._geoms[link]]
        return self._world_bounds(link, np.concatenate(pts) if pts else np.zeros((0, 3)))

    def link_has_collision(self, link: str) -> bool:
        return bool(self._geoms[link])

    def link_masses(self) -> dict[str, float]:
        return {n: float(self.m.body_mass[b]) for n, b in self._body.items()}

    def link_distances(self, link_a: str, link_b: str, max_distance: float = 0.0) -> list[float]:
        """``mj_geomDistance`` of every pair of the links' colliding geoms."""
        mj = self._mj
        mj.mj_kinematics(self.m, self.d)
        dists = (float(mj.mj_geomDistance(self.m, self.d, ga, gb, max_distance, None))
                 for ga in self._geoms[link_a] for gb in self._geoms[link_b])
        return [d for d in dists if d < max_distance]

    def apply_link_force(self, link: str, force, point) -> None:
        """As force + torque about the body's COM (``xfrc_applied``)."""
        b = self._body[link]
        self._mj.mj_kinematics(self.m, self.d)
        f = np.asarray(force, float)
        r = np.asarray(point, float) - self.d.xipos[b]
        self.d.xfrc_applied[b, :3] += f
        self.d.xfrc_applied[b, 3:] += np.cross(r, f)
        self._applied = True

    def set_root_pose(self, pos, orn_xyzw) -> None:
        """Teleport the root and zero its velocity (EngineUnsupported: fixed base)."""
        self._movable_root()
        self.d.qpos[0:3] = np.asarray(pos, float)
        self.d.qpos[3:7] = quat_xyzw_to_wxyz(orn_xyzw)
        self.d.qvel[0:6] = 0.0
        self._forward()

    def root_pose(self) -> tuple[np.ndarray, np.ndarray]:
        d = self.d
        pos, wxyz = (d.qpos[0:3], d.qpos[3:7]) if not self.options.fixed_base else (d.xpos[self._root], d.xquat[self._root])
        q = quat_wxyz_to_xyzw(wxyz)
        n = np.linalg.norm(q)
        return np.array(pos, float), (q / n if n > 0 else q)

    # ---------------------------------------------------------------- contact
    def self_penetration(self) -> tuple[float, list[ContactPair]]:
        """Phi of each penetrating contact's ``dist`` (m) between two links (the ground's left out)."""
        self._forward()
        points = []
        for c in (self.d.contact[i] for i in range(self.d.ncon)):
            if c.geom1 == self._ground or c.geom2 == self._ground or c.dist >= 0.0:
                continue
            a, b = (self.link_names[int(self.m.geom_bodyid[g]) - 1] for g in (c.geom1, c.geom2))
            points.append((a, b, float(c.dist)))
        return penetration_sum(points)

    def ground_penetration(self) -> float:
        """Deepest point (m) of the collision geoms below z = 0, from the geometry."""
        if self._ground < 0:
            return 0.0
        self._mj.mj_kinematics(self.m, self.d)
        low = lowest_point(self.m, self.d)
        return max(0.0, -low) if math.isfinite(low) else 0.0

    # ------------------------------------------------------------------ state
    def save_state(self) -> int:
        mj = self._mj
        state = np.empty(mj.mj_stateSize(self.m, self._state_sig))
        mj.mj_getState(self.m, self.d, state, self._state_sig)
        return self._keep_state(state)

    def restore_state(self, handle: int) -> None:
        self._mj.mj_setState(self.m, self.d, self._states[handle], self._state_sig)
        self._forward()

    # --------------------------------------------------------------- dynamics
    def step(self, n: int = 1) -> None:
        spend(n)  # the refine's one budget of steps (asset2sim.engines.step_budget)
        mj = self._mj
        for _ in range(int(n)):
            if self._drive:
                self._apply_drives()
            mj.mj_step(self.m, self.d)
            self._clear_applied()

    def _clear_applied(self) -> None:
        """Clear the efforts and forces applied (they act for one step)."""
        if self._applied:
            self.d.qfrc_applied[:] = 0.0
            self.d.xfrc_applied[:] = 0.0
            self._applied = False

    def held_physics(self) -> HeldPhysics:
        return held_physics_of_model(self.m, self.d.qpos, list(self.urdf.links), self.joint_names, source="urdf (converted in memory)")

    def close(self) -> None:
        self.d = None
        self.m = None


def _named(m, kind, name: str) -> int:
    i = _mujoco().mj_name2id(m, kind, name)
    return i if i >= 0 else _mujoco().mj_name2id(m, kind, safe_name(name))


def held_physics_of_model(m, qpos: np.ndarray, links: list[str], joints: list[str], source: str) -> HeldPhysics:
    """Per-body and per-joint physics of a compiled ``mujoco.MjModel`` by URDF
    link and joint name (or its :func:`safe_name`), positions from ``qpos`` (nq,)
    (KeyError: a link or joint has no MuJoCo body or joint of its name)."""
    mujoco = _mujoco()
    held_links = {}
    for name in links:
        b = _named(m, mujoco.mjtObj.mjOBJ_BODY, name)
        if b < 0:
            raise KeyError(f"MuJoCo model has no body for link {name!r}")
        held_links[name] = HeldLink(mass=float(m.body_mass[b]), com=np.array(m.body_ipos[b], float),
                                    principal=np.sort(np.array(m.body_inertia[b], float)))
    held_joints = {}
    for name in joints:
        jid = _named(m, mujoco.mjtObj.mjOBJ_JOINT, name)
        if jid < 0:
            raise KeyError(f"MuJoCo model has no joint {name!r}")
        qa, da = int(m.jnt_qposadr[jid]), int(m.jnt_dofadr[jid])
        lo, hi = (float(m.jnt_range[jid, 0]), float(m.jnt_range[jid, 1])) if m.jnt_limited[jid] else (-math.inf, math.inf)
        k = float(m.jnt_stiffness[jid])
        held_joints[name] = HeldJoint(lower=lo, upper=hi, damping=float(m.dof_damping[da]), friction=float(m.dof_frictionloss[da]),
                                      stiffness=k, reference=float(m.qpos_spring[qa]) if k != 0.0 else None, position=float(qpos[qa]))
    how = {"mass, com, inertia": "body_mass, body_ipos, body_inertia", "limits": "jnt_range (jnt_limited)",
           "damping, friction": "dof_damping, dof_frictionloss", "spring": "jnt_stiffness, qpos_spring", "position": "qpos"}
    return HeldPhysics(engine="mujoco", source=source, links=held_links, joints=held_joints, how=how)


def held_physics_of_mjcf(path: Path, links: list[str], joints: list[str]) -> HeldPhysics:
    """:func:`held_physics_of_model` of an MJCF file, positions from the keyframe
    :data:`KEYFRAME` (``qpos0`` without one) (MjcfError: it does not compile;
    KeyError: a link or joint is not in the model)."""
    mujoco = _mujoco()
    m = mujoco_call(lambda: mujoco.MjModel.from_xml_path(str(path)), f"MuJoCo could not compile {path}")
    kid = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_KEY, KEYFRAME)
    qpos = np.array(m.key_qpos[kid], float) if kid >= 0 else np.array(m.qpos0, float)
    return held_physics_of_model(m, qpos, links, joints, source=f"mjcf ({Path(path).name}, keyframe {KEYFRAME!r})")


register_engine("mujoco", MuJoCoSession)
register_file_reader("mujoco", "mjcf", held_physics_of_mjcf)
