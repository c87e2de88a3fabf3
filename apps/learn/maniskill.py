"""Refined objects as ManiSkill 3 tasks (``pip install 'asset2sim[maniskill]'``).

``import asset2sim.apps.learn.maniskill`` registers three environments with ManiSkill's
``register_env`` (and so with ``gymnasium``)::

    import gymnasium as gym
    import asset2sim.apps.learn.maniskill  # noqa: F401  (registers the ids)

    env = gym.make("Asset2Sim-OpenArticulation-v1", assets="out/", obs_mode="state", num_envs=1)
    obs, info = env.reset(seed=0)

- ``Asset2Sim-OpenArticulation-v1``: open the object's task part (a lid, a
  door, a drawer) from its closed end to the learnability target (opening
  fraction >= 0.55, target 0.6);
- ``Asset2Sim-CloseArticulation-v1``: close it from the common start (half
  open, a revolute part at most 45 degrees) to fraction <= 0.05;
- ``Asset2Sim-ManifestTask-v1``: each object's own task in its verb's
  direction (``report.json``'s task as ``asset2sim refine --task`` recorded
  it, else the ``manifest`` row's ``task`` column): "press the stapler" closes
  the lid, "open the drawer" opens it, in the same environment.

``assets`` is an asset2sim output folder (``asset2sim refine`` /
``asset2sim demo --out``), an unrefined input folder (``mobility.urdf``, no
``report.json``: baselines run in the same environment), a folder holding such
folders, or a list of any of these. With ``reference=True`` each folder is a
PartNet-Mobility input and the object is GenSim2's reference of it
(``reference_gensim2.urdf`` at ``reference_gensim2.json``'s scale and joint
range, as the learnability benchmark's ``human`` method writes it), so
GenSim2's hand-curated assets run in the same environment. Each parallel sub-scene holds one object
(different links and joints per sub-scene, as ManiSkill's
``OpenCabinetDrawer-v1`` builds them: an articulation builder per scene index);
with fewer sub-scenes than objects, each reconfiguration draws one per sub-scene.

Every object is built as asset2sim verified it (:mod:`asset2sim.engines.physx_engine`,
the builder :func:`asset2sim.load_sapien` uses): the output's convex collision
pieces and inertia, self-collision between links that are not parent and child,
the root welded to the world when ``initial_state.json`` declares it fixed (a
mounted door) and free on the ground otherwise, and each movable joint's
friction, damping and spring (``mobility.urdf`` ``<dynamics>``, ``overlay.json``)
applied every simulation step by
:class:`~asset2sim.engines.passive_joints.PassiveJoints`. The scene keeps
ManiSkill's solver settings (TGS, 15 position iterations; asset2sim's checks
use PGS) and steps at 240 Hz, 12 steps per control step. SAPIEN's own URDF loader,
which ManiSkill uses, drops the friction: a lid that holds open falls shut.

The task joint, its closed end and the target are those of
:func:`asset2sim.apps.learn.task.prepare_task` (the learnability
benchmark's task definition) for the output's ``report.json`` task turned to
the environment's direction, with the closed end ``report.json`` records.
Success (``evaluate``): the target reached and the joint at rest (|qdot| <=
1 rad/s or 0.1 m/s, ManiSkill's ``OpenCabinetDrawer-v1`` thresholds). Dense
reward as ``OpenCabinetDrawer-v1``'s: reaching the grasp point (up to 1, 2
once the part moves) + 2 x progress toward the target, 3 once reached, 5 on
success; ``normalized_dense`` divides by 5.

Robots: ManiSkill's Panda (default, ``robot_uids="panda"``) or its floating
Panda gripper (``"floating_panda_gripper"``), placed on the object's -x side so
that the gripper starts :data:`TCP_APPROACH` from the grasp point, touching
nothing. Observations: ``state`` (the robot's, the grasp point,
the task joint's opening fraction and velocity, the target) and ``pointcloud``
(one camera, needs a render device). ``sim_backend="cpu"`` is what the tests
run; on ``"gpu"`` the friction is a constant force limit and damping and springs
are joint forces (the same model, not run by the tests: no GPU in CI).
"""

from __future__ import annotations

import math
import shutil
import tempfile
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np

from asset2sim.extras import MissingExtra, install_hint

try:
    import sapien
    import torch
    from mani_skill.envs.sapien_env import BaseEnv
    from mani_skill.sensors.camera import CameraConfig
    from mani_skill.utils import common, sapien_utils
    from mani_skill.utils.building.articulation_builder import ArticulationBuilder
    from mani_skill.utils.building.ground import build_ground
    from mani_skill.utils.geometry.geometry import transform_points
    from mani_skill.utils.registration import register_env
    from mani_skill.utils.structs import Articulation, Link, Pose
    from mani_skill.utils.structs.types import SceneConfig, SimConfig
    from sapien.wrapper.articulation_builder import LinkBuilder
except ImportError as exc:  # ManiSkill, torch or SAPIEN not installed: one line naming the extra
    raise MissingExtra(f"asset2sim.apps.learn.maniskill: {install_hint(exc)}", name=getattr(exc, "name", None)) from exc

from asset2sim.apps.learn.task_objects import (ManiSkillAssetError, TaskObject, _world_points, find_assets,  # noqa: F401
                                               gensim2_reference, load_task_objects, read_manifest_tasks, task_object)
from asset2sim.engines.passive_joints import FRICTION_DRIVE_DAMPING, PassiveJoints
from asset2sim.engines.physx_engine import (attach_collision_shapes, configure_articulation,
                                            fill_articulation_builder)

#: The environments' ids and the action each asks for (``task``: each object's own task, its verb's direction).
ENV_IDS = {"open": "Asset2Sim-OpenArticulation-v1", "close": "Asset2Sim-CloseArticulation-v1",
           "task": "Asset2Sim-ManifestTask-v1"}
#: Episode length, control steps (ManiSkill's OpenCabinetDrawer-v1: 100).
MAX_EPISODE_STEPS = 100
#: Simulation and control rates, Hz: asset2sim's checks step PhysX at 1/240 s; 12 steps per action as the
#: PyBullet learnability environment.
SIM_FREQ, CONTROL_FREQ = 240, 20
#: The task joint counts as at rest at or below this speed (rad/s, m/s): OpenCabinetDrawer-v1's link thresholds.
REST_SPEED = {"revolute": 1.0, "continuous": 1.0, "prismatic": 0.1}
#: The dense reward's maximum (``compute_normalized_dense_reward`` divides by it).
MAX_REWARD = 5.0
#: Where the TCP starts relative to the grasp point, m: in front of it along -x and above it (no contact at the start).
TCP_APPROACH = np.array([-0.10, 0.0, 0.05])
#: The TCP in the robot's base frame at its start keyframe (ManiSkill 3.0.1: Panda ``rest``, the floating gripper
#: ``open_facing_side``), m.
TCP_AT_START = {"panda": np.array([0.615, 0.0, 0.170]), "floating_panda_gripper": np.array([0.1034, 0.0, 0.0])}
#: The Panda's base stays this far (m) behind the object's -x face.
ROBOT_CLEARANCE = 0.25
SUPPORTED_ROBOTS = ["panda", "floating_panda_gripper"]


class _VerifiedLinkBuilder(LinkBuilder):
    """SAPIEN's link builder with the output's convex collision pieces attached as asset2sim's PhysX session cooks
    them (:func:`~asset2sim.engines.physx_engine.attach_collision_shapes`)."""

    def __init__(self, index, parent, obj: TaskObject):
        super().__init__(index, parent)
        self._obj = obj

    def build_physx_component(self, link_parent=None):
        comp = super().build_physx_component(link_parent)
        attach_collision_shapes(comp, self._obj.model, self._obj.pieces.get(self.name, []), self._obj.urdf, self._obj.notes)
        return comp


class _VerifiedArticulationBuilder(ArticulationBuilder):
    """ManiSkill's articulation builder (scene indices, batched build) making :class:`_VerifiedLinkBuilder` links,
    self-collision kept (ManiSkill's ``disable_self_collisions`` off)."""

    def __init__(self, obj: TaskObject):
        super().__init__()
        self._obj = obj

    def create_link_builder(self, parent: LinkBuilder = None):
        if self.link_builders:
            assert parent and parent in self.link_builders
        builder = _VerifiedLinkBuilder(len(self.link_builders), parent, self._obj)
        self.link_builders.append(builder)
        return builder

    def add_visuals(self) -> None:
        """The URDF's visual meshes and primitives on each link (for cameras and point clouds)."""
        for lb in self.link_builders:
            for v in self._obj.model.links[lb.name].visuals:
                pose = sapien.Pose(v.origin.astype(np.float32))
                if v.kind == "mesh" and v.path is not None and v.path.is_file():
                    lb.add_visual_from_file(str(v.path), pose=pose, scale=v.scale)
                elif v.kind == "box":
                    lb.add_box_visual(pose=pose, half_size=np.asarray(v.size, float) / 2)
                elif v.kind == "sphere":
                    lb.add_sphere_visual(pose=pose, radius=float(v.radius))


def build_object(scene, obj: TaskObject, scene_idx: int, name: str) -> Articulation:
    """Build ``obj`` into sub-scene ``scene_idx`` of a ManiSkill ``scene`` as asset2sim verified it (links, joints,
    inertia, collision pieces, the root as declared; visuals when the scene renders) and give its joints their
    passive drives. Returns ManiSkill's ``Articulation``. Raises ManiSkillAssetError ``MS_BUILD``."""
    builder = _VerifiedArticulationBuilder(obj).set_scene(scene)
    try:
        fill_articulation_builder(builder, obj.model, obj.urdf, fixed_base=obj.fixed_root, notes=obj.notes)
        if scene.can_render():
            builder.add_visuals()
        builder.set_scene_idxs([scene_idx])
        builder.initial_pose = sapien.Pose(p=[0.0, 0.0, obj.base_z])
        art = builder.build(name=name, fix_root_link=obj.fixed_root)
    except (RuntimeError, ValueError) as exc:
        raise ManiSkillAssetError("MS_BUILD", f"{obj.folder}: SAPIEN cannot build it ({exc})") from exc
    for px in art._objs:
        configure_articulation(px)
    return art


def _bare(name: str, prefix: str) -> str:
    return name[len(prefix):] if name.startswith(prefix) else name


class _ArticulationTaskEnv(BaseEnv):
    """The environment of :data:`ENV_IDS` (see the module's docstring); ``action`` set by the subclass.

    Args (beyond ManiSkill's ``BaseEnv``'s ``num_envs``, ``obs_mode``, ``reward_mode``, ``control_mode``,
    ``sim_backend``, ``render_mode`` ...):
        assets: output or input folders (:func:`find_assets`); objects that cannot become a task are left out
            (``skipped``: folder and error); ManiSkillAssetError ``MS_NO_ASSETS`` when none can.
        task: the task text for every object ("close the laptop", turned to the environment's direction), or
            per folder (``str(folder)`` -> text); default: each output's ``report.json`` task (an input's: its category's part).
        manifest: a ``manifest.csv``: the row whose ``id`` is a folder's name gives its task (``task`` column) and
            category where its ``report.json`` records no task (raw inputs, outputs refined without ``--task``).
        reference: build GenSim2's reference of each PartNet-Mobility folder (``reference_gensim2.urdf`` and
            ``.json``, as the benchmark's ``human`` method) instead of the folder's own ``mobility.urdf``; folders
            without one are skipped (``MS_NO_REFERENCE``). The references are written to a temporary folder removed
            by ``close()``.
        robot_uids: ``panda`` (default) or ``floating_panda_gripper``.
        robot_init_qpos_noise: standard deviation (rad) of the robot's start joint positions.
        reconfiguration_freq: ManiSkill's; default: every reset with one sub-scene and several objects, else never.
    """

    SUPPORTED_ROBOTS = SUPPORTED_ROBOTS
    action_kind: str = ""

    def __init__(self, *args, assets: str | Path | Sequence[str | Path] = (), task: str | Mapping[str, str] | None = None,
                 manifest: str | Path | None = None, reference: bool = False, robot_uids: str = "panda",
                 robot_init_qpos_noise: float = 0.02, reconfiguration_freq: int | None = None, num_envs: int = 1, **kwargs):
        self._reference_dir = Path(tempfile.mkdtemp(prefix="asset2sim-gensim2-")) if reference else None
        try:
            self.objects, self.skipped = load_task_objects(assets, self.action_kind, task, manifest=manifest,
                                                           reference=reference, reference_dir=self._reference_dir)
        except BaseException:
            self._remove_references()
            raise
        self.robot_init_qpos_noise = robot_init_qpos_noise
        self._robot = robot_uids
        if reconfiguration_freq is None:
            reconfiguration_freq = 1 if (num_envs == 1 and len(self.objects) > 1) else 0
        super().__init__(*args, robot_uids=robot_uids, reconfiguration_freq=reconfiguration_freq, num_envs=num_envs, **kwargs)

    def _remove_references(self) -> None:
        if getattr(self, "_reference_dir", None) is not None:
            shutil.rmtree(self._reference_dir, ignore_errors=True)
            self._reference_dir = None

    def close(self):
        """ManiSkill's ``close``, and the GenSim2 references written for ``reference=True`` removed."""
        try:
            return super().close()
        finally:
            self._remove_references()

    # ------------------------------------------------------------------ configs
    @property
    def _default_sim_config(self):
        return SimConfig(sim_freq=SIM_FREQ, control_freq=CONTROL_FREQ, spacing=5,
                         scene_config=SceneConfig(solver_position_iterations=15, solver_velocity_iterations=1))

    @property
    def _default_sensor_configs(self):
        pose = sapien_utils.look_at(eye=[-1.2, -0.5, 1.1], target=[0.0, 0.0, 0.35])
        return [CameraConfig("base_camera", pose=pose, width=128, height=128, fov=1.2, near=0.01, far=10)]

    @property
    def _default_human_render_camera_configs(self):
        pose = sapien_utils.look_at(eye=[-1.6, -1.0, 1.4], target=[0.0, 0.0, 0.35])
        return CameraConfig("render_camera", pose=pose, width=512, height=512, fov=1.0, near=0.01, far=100)

    # ------------------------------------------------------------------ loading
    def _load_agent(self, options: dict):
        super()._load_agent(options, sapien.Pose(p=[-1.0, 0.0, 0.0]))

    def _load_scene(self, options: dict):
        self.ground = build_ground(self.scene)
        n = self.num_envs
        if n >= len(self.objects):
            picks = [i % len(self.objects) for i in range(n)]
        else:
            picks = [int(k) for k in self._batched_episode_rng.randint(0, len(self.objects))]
        self.env_objects: list[TaskObject] = [self.objects[k] for k in picks]
        arts, links, self._passive, self._task_index, self._physx_arts, self._joint_names = [], [], [], [], [], []
        for i, obj in enumerate(self.env_objects):
            name = f"object-{i}"
            art = build_object(self.scene, obj, i, name)
            self.remove_from_state_dict_registry(art)
            prefix = f"scene-{i}-{name}_"
            px = art._objs[0]
            names = [_bare(j.name, prefix) for j in px.active_joints]
            passive = PassiveJoints.from_urdf(obj.model, obj.springs, names)
            passive.configure(px.active_joints)
            self._passive.append(passive)
            self._physx_arts.append(px)
            self._joint_names.append(names)
            self._task_index.append(names.index(obj.joint))
            links.append(next(lk for lk in art.links if _bare(lk._objs[0].name, prefix) == obj.grasp_link))
            arts.append(art)
        self.object = Articulation.merge(arts, name="object")
        self.add_to_state_dict_registry(self.object)
        self.grasp_link = Link.merge(links, name="grasp_link")
        with torch.device(self.device):
            objs = self.env_objects
            self.task_index = torch.tensor(self._task_index, dtype=torch.long)
            self.grasp_point_local = torch.tensor(np.array([o.grasp_point for o in objs]), dtype=torch.float32)
            for k in ("q_closed", "direction", "open_range", "start_fraction", "target_fraction", "reach_fraction", "base_z"):
                setattr(self, k, torch.tensor([getattr(o, k) for o in objs], dtype=torch.float32))
            self.opens = torch.tensor([o.action == "open" for o in objs], dtype=torch.bool)
            self.rest_speed = torch.tensor([REST_SPEED.get(o.joint_type, 1.0) for o in objs], dtype=torch.float32)
            start = np.zeros((len(objs), self.object.max_dof))
            for i, o in enumerate(objs):
                q = o.start_qpos(self._joint_names[i])
                start[i, :len(q)] = q
            self.start_qpos = torch.tensor(start, dtype=torch.float32)
            self.robot_base = torch.tensor(np.array([self._robot_base(o, self._joint_names[i], self._robot)
                                                     for i, o in enumerate(objs)]),
                                           dtype=torch.float32)
        if self.gpu_sim_enabled:
            self._gpu_passive_tables()

    @staticmethod
    def _robot_base(obj: TaskObject, names: list[str], robot: str = "panda") -> np.ndarray:
        """The robot's base position (3,) m for ``obj`` (joints ``names``) at the episode's start: the TCP
        :data:`TCP_APPROACH` from the grasp point; a Panda's base at least :data:`ROBOT_CLEARANCE` behind the object's
        -x face and not below the floor."""
        q0 = dict(zip(names, obj.start_qpos(names)))
        t = obj.model.link_poses(q0)[obj.grasp_link]
        g = t[:3, :3] @ obj.grasp_point + t[:3, 3] + np.array([0.0, 0.0, obj.base_z])
        base = g + TCP_APPROACH - TCP_AT_START.get(robot, TCP_AT_START["panda"])
        if robot == "panda":
            pts = _world_points(obj.model, obj.pieces, q0)
            if len(pts):
                base[0] = min(base[0], float(pts[:, 0].min()) - ROBOT_CLEARANCE)
            base[2] = max(base[2], 0.0)
        return base

    # ------------------------------------------------------------------ episodes
    def _initialize_episode(self, env_idx: torch.Tensor, options: dict):
        with torch.device(self.device):
            b = len(env_idx)
            p = torch.zeros((b, 3))
            p[:, 2] = self.base_z[env_idx]
            self.object.set_pose(Pose.create_from_pq(p=p))
            self.object.set_qpos(self.start_qpos[env_idx])
            self.object.set_qvel(torch.zeros_like(self.start_qpos[env_idx]))
            key = self.agent.keyframes.get("rest") or self.agent.keyframes["open_facing_side"]
            rest = torch.tensor(key.qpos, dtype=torch.float32)
            qpos = rest.repeat(b, 1) + torch.randn((b, rest.numel())) * self.robot_init_qpos_noise
            self.agent.reset(qpos)
            self.agent.robot.set_pose(Pose.create_from_pq(p=self.robot_base[env_idx]))

    # ------------------------------------------------------------------ passive joints
    def _before_simulation_step(self):
        if self.gpu_sim_enabled:
            self._gpu_passive_forces()
            return
        for px, passive in zip(self._physx_arts, self._passive):
            if passive.damped:
                for joint, limit in zip(px.active_joints, passive.force_limits(px.get_qvel())):
                    joint.set_drive_properties(0.0, FRICTION_DRIVE_DAMPING, float(limit), "force")
            if passive.sprung:
                px.set_qf(passive.joint_forces(px.get_qpos()).astype(np.float32))

    def _gpu_passive_tables(self) -> None:
        tabs = np.zeros((4, self.num_envs, self.object.max_dof))
        for i, p in enumerate(self._passive):
            n = len(p.names)
            tabs[0, i, :n], tabs[1, i, :n], tabs[2, i, :n] = p.damping, p.stiffness, p.reference
        self._gpu_damping, self._gpu_stiffness, self._gpu_reference = (common.to_tensor(t, device=self.device).float() for t in tabs[:3])
        self._gpu_sprung = bool(np.any(tabs[:2]))

    def _gpu_passive_forces(self) -> None:
        """GPU: damping and springs as joint forces (friction stays the drives' constant force limit); catches
        are not applied. Written for the GPU backend; not run by the tests (no GPU there)."""
        if self._gpu_sprung:
            self.scene.px.gpu_fetch_articulation_qpos()
            self.scene.px.gpu_fetch_articulation_qvel()
            qf = -self._gpu_damping * self.object.qvel - self._gpu_stiffness * (self.object.qpos - self._gpu_reference)
            self.object.set_qf(qf)
            self.scene.px.gpu_apply_articulation_qf()

    # ------------------------------------------------------------------ task
    def task_fraction(self) -> torch.Tensor:
        """The task joint's opening fraction per sub-scene (b,)."""
        q = self.object.qpos.gather(1, self.task_index[:, None])[:, 0]
        return self.direction * (q - self.q_closed) / self.open_range

    def task_speed(self) -> torch.Tensor:
        """The task joint's |qdot| per sub-scene (b,), rad/s or m/s."""
        return self.object.qvel.gather(1, self.task_index[:, None])[:, 0].abs()

    def grasp_positions(self) -> torch.Tensor:
        """The grasp point in the world per sub-scene (b, 3) m."""
        return transform_points(self.grasp_link.pose.to_transformation_matrix().clone(), self.grasp_point_local)

    def evaluate(self) -> dict:
        f = self.task_fraction()
        reached = torch.where(self.opens, f >= self.reach_fraction, f <= self.reach_fraction)
        span = self.reach_fraction - self.start_fraction
        progress = torch.clamp((f - self.start_fraction) / torch.where(span.abs() > 1e-9, span, torch.ones_like(span)), 0.0, 1.0)
        return {"success": reached & (self.task_speed() <= self.rest_speed), "reached": reached, "fraction": f,
                "progress": progress, "grasp_pos": self.grasp_positions()}

    def _get_obs_extra(self, info: dict):
        obs = dict(tcp_pose=self.agent.tcp.pose.raw_pose)
        if "state" in self.obs_mode:
            obs.update(grasp_pos=info["grasp_pos"], tcp_to_grasp_pos=info["grasp_pos"] - self.agent.tcp.pose.p,
                       task_fraction=info["fraction"][:, None], task_speed=self.task_speed()[:, None],
                       target_fraction=self.reach_fraction[:, None])
        return obs

    def compute_dense_reward(self, obs: Any, action: torch.Tensor, info: dict):
        reaching = 1 - torch.tanh(5 * torch.linalg.norm(self.agent.tcp.pose.p - info["grasp_pos"], axis=1))
        progress = info["progress"]
        reaching = torch.where(progress > 1e-3, torch.full_like(reaching, 2.0), reaching)
        reward = reaching + torch.where(info["reached"], torch.full_like(progress, 3.0), 2 * progress)
        return torch.where(info["success"], torch.full_like(reward, MAX_REWARD), reward)

    def compute_normalized_dense_reward(self, obs: Any, action: torch.Tensor, info: dict):
        return self.compute_dense_reward(obs=obs, action=action, info=info) / MAX_REWARD


@register_env(ENV_IDS["open"], max_episode_steps=MAX_EPISODE_STEPS)
class OpenArticulationEnv(_ArticulationTaskEnv):
    """Open the task part of an asset2sim output (or a raw input) to opening fraction >= 0.55 and leave it at rest."""

    action_kind = "open"


@register_env(ENV_IDS["close"], max_episode_steps=MAX_EPISODE_STEPS)
class CloseArticulationEnv(_ArticulationTaskEnv):
    """Close the task part of an asset2sim output (or a raw input) from the common start to opening fraction <= 0.05."""

    action_kind = "close"


@register_env(ENV_IDS["task"], max_episode_steps=MAX_EPISODE_STEPS)
class ManifestTaskEnv(_ArticulationTaskEnv):
    """Each object's own task, in its verb's direction: the ``report.json`` task ``asset2sim refine --task`` recorded
    (or the ``manifest`` row's ``task`` column, or ``task=``), "press the stapler" closing its lid from the common
    start to <= 0.05, "open the drawer" opening it from closed to >= 0.55. Objects with no task are skipped
    (``MS_NO_TASK``)."""

    action_kind = "task"


def hold_drift(folder: str | Path, seconds: float = 2.0, *, sim_backend: str = "cpu") -> dict[str, float]:
    """Largest |q(t) - q(0)| (rad or m) of each movable joint of the object in ``folder`` over ``seconds`` of
    simulated time in :data:`ENV_IDS` ``close``'s environment, started at the output's initial state, nobody
    touching it (the robot held at its rest pose, away from the object). What a held lid does in ManiSkill."""
    import gymnasium as gym

    env = gym.make(ENV_IDS["close"], assets=[folder], num_envs=1, obs_mode="state", sim_backend=sim_backend,
                   render_backend="none", robot_init_qpos_noise=0.0, control_mode="pd_joint_delta_pos")
    try:
        env.reset(seed=0)
        u = env.unwrapped
        obj = u.env_objects[0]
        names = u._joint_names[0]
        q0 = np.array([obj.initial_state.get(n, 0.0) for n in names], np.float32)
        u.object.set_qpos(torch.tensor(q0)[None])
        u.object.set_qvel(torch.zeros((1, len(q0))))
        u.agent.robot.set_pose(Pose.create_from_pq(p=torch.tensor([[-3.0, 0.0, 0.0]])))
        still = np.zeros(env.action_space.shape, np.float32)  # pd_joint_delta_pos: hold the arm where it is
        drift = np.zeros(len(names))
        for _ in range(int(math.ceil(seconds * CONTROL_FREQ))):
            env.step(still)
            drift = np.maximum(drift, np.abs(np.asarray(u.object.qpos[0, :len(names)], float) - q0))
        return {n: float(d) for n, d in zip(names, drift)}
    finally:
        env.close()
