"""A learning environment in MJX (MuJoCo XLA, JAX) for brax's PPO, the learnability benchmark's where learners train
(extra ``learn-mjx``): the task of :func:`~asset2sim.apps.learn.task.prepare_task` on the object of an output folder's
MJCF export (``mjcf/mobility.xml``), held at the task link's contact point by a floating force- and speed-limited
gripper (the model of :class:`~asset2sim.tasks.check.gripper.BoundedGrasp`, in JAX); action (3,) in [-1, 1] (gripper
velocity in units of the speed limit), observation (13,) float32 (the Gymnasium environment's, less nothing), reward for
progress, stretch, slide/tip and success (:class:`~asset2sim.apps.learn.task.LearnConfig`; docs/design/metrics.md).
Success is the task execution's: the target reached, then released and held ``hold_time`` s without the object sliding
or tipping. One environment is a brax ``Env``; brax vmaps it over any number (thousands on a GPU).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
from brax.envs import training as brax_training
from brax.envs.base import Env, State

from asset2sim.apps.learn.task import LearnConfig, LearnTask
from asset2sim.engines.loading import BOX_CORNERS
from asset2sim.engines.mjcf import mujoco_messages, urdf_to_mjcf
from asset2sim.engines.quiet import quiet_stdout
from asset2sim.engines.registry import open_session
from asset2sim.output_folder import MJCF_DIR
from asset2sim.refined_asset import RefinedAsset
from asset2sim.tasks.check.contact_points import contact_point_rule, joint_frame_axis
from asset2sim.tasks.check.gripper import EFFECTIVE_MASS_SHARE
from asset2sim.urdf import read_urdf

with quiet_stdout():  # mujoco.mjx prints when its optional Warp backend is missing
    from mujoco import mjx

if not hasattr(jax, "device_put_replicated"):  # removed in JAX 0.10; brax 0.14.2's PPO still calls it

    def _device_put_replicated(x, devices):
        """JAX's drop-in (docs.jax.dev, "migrate_pmap"): every leaf stacked once per device, which pmap shards."""
        return jax.tree.map(lambda a: jnp.stack([jnp.asarray(a)] * len(devices)), x)

    jax.device_put_replicated = _device_put_replicated

OBS_DIM = 13  # observation length (module docstring)
ACTION_DIM = 3  # gripper velocity (3,)


@dataclass
class MjxScene:
    """What an environment needs from the host, made once (:func:`build_scene`): ``model`` and the settled start
    ``qpos`` (nq,) / ``qvel`` (nv,); the task joint's addresses and limits (rad or m); the grasped ``body`` and the grasp
    point ``point`` (3,) m in its frame; ``length`` m (the grasp point's lever: its distance from a revolute axis, a
    prismatic joint's range); the grasp spring ``stiffness`` N/m and ``damping`` N s/m; ``z_low`` m, the object's lowest
    point at the start; ``source``: which file the model came from."""

    model: Any  # mujoco.MjModel
    qpos: np.ndarray
    qvel: np.ndarray
    qadr: int
    dadr: int
    limits: tuple[float, float]
    body: int
    point: np.ndarray
    length: float
    stiffness: float
    damping: float
    free_root: bool
    z_low: float
    source: str
    grasp_rule: str = ""


def load_model(folder: Path | str) -> tuple[Any, str]:
    """(``mujoco.MjModel``, what it is) of an output folder: its MJCF export ``mjcf/mobility.xml`` as written; a folder
    without one (a baseline's raw URDF) converted in memory as every engine reads a URDF
    (:func:`asset2sim.engines.mjcf.urdf_to_mjcf`: a link without ``<inertial>`` gets PyBullet's 1 kg and unit inertia,
    the simulators' defaults). Raises FileNotFoundError (no ``mobility.urdf``), UrdfError or MjcfError (unreadable)."""
    asset = RefinedAsset.existing(folder)
    xml = asset.folder / MJCF_DIR / f"{asset.urdf_path.stem}.xml"
    with mujoco_messages():
        if xml.is_file():
            return mujoco.MjModel.from_xml_path(str(xml)), f"{MJCF_DIR}/{xml.name}"
        build = urdf_to_mjcf(asset.urdf_path, asset.session_options(), missing_inertial="bullet")
        return mujoco.MjModel.from_xml_string(build.xml, build.assets()), f"{asset.urdf_name} converted (PyBullet's defaults)"


def build_scene(folder: Path | str, task: LearnTask, config: LearnConfig | None = None) -> MjxScene:
    """The :class:`MjxScene` of ``task`` on the output folder ``folder`` (:func:`load_model`): the task joint at its start
    (``task.start``), settled on the host like the Gymnasium environment (at least ``settle_time``, until joints and
    root rest, at most ``settle_max_time``); the grasp point by the task-execution rule
    (:func:`~asset2sim.tasks.check.contact_points.contact_point_rule`, on the folder's URDF).
    Raises KeyError: the model has no joint or body of the task's names; as :func:`load_model`."""
    cfg = config or LearnConfig()
    m, source = load_model(folder)
    jid = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, task.joint)
    if jid < 0:
        raise KeyError(f"{source} of {folder}: no joint {task.joint!r}")
    d = mujoco.MjData(m)
    mujoco.mj_resetDataKeyframe(m, d, 0)
    qadr, dadr = int(m.jnt_qposadr[jid]), int(m.jnt_dofadr[jid])
    d.qpos[qadr] = task.start_state().get(task.joint, d.qpos[qadr])
    _settle(m, d, cfg)
    with quiet_stdout():
        s = open_session(cfg.engine, task.urdf, task.session_options())
    try:
        link, point, rule = contact_point_rule(s, task.joint, read_urdf(task.urdf, mode="lenient"),
                                               opening_direction=task.closed.direction)
        if task.joint_type == "prismatic":
            length = task.closed.open_range
        else:
            o, a = joint_frame_axis(s, task.joint, s.joint_child[task.joint])
            lo, R = s.link_frame(link)
            r = np.asarray(lo, float) + np.asarray(R, float) @ point - o
            length = float(np.linalg.norm(r - (r @ a) * a))
    finally:
        s.close()
    body = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, link)
    if body < 0:
        raise KeyError(f"{source} of {folder}: no body {link!r}")
    dt = float(m.opt.timestep)
    # BoundedGrasp's spring, capped at half the explicit step's stability limits (asset2sim.tasks.check.gripper)
    m_eff = max(float(m.body_mass[body]) * EFFECTIVE_MASS_SHARE, 1e-4)
    lim = cfg.limits
    mujoco.mj_forward(m, d)
    low = min((float(np.min((d.geom_xpos[g] + (m.geom_aabb[g][:3] + BOX_CORNERS * m.geom_aabb[g][3:])
                             @ d.geom_xmat[g].reshape(3, 3).T)[:, 2]))
               for g in range(m.ngeom) if m.geom_bodyid[g] > 0 and m.geom_contype[g] | m.geom_conaffinity[g]), default=0.0)
    lo_hi = (float(m.jnt_range[jid][0]), float(m.jnt_range[jid][1])) if m.jnt_limited[jid] else (-np.inf, np.inf)
    return MjxScene(model=m, qpos=d.qpos.copy(), qvel=d.qvel.copy(), qadr=qadr, dadr=dadr, limits=lo_hi, body=body,
                    point=np.asarray(point, float), length=max(length, 1e-3),
                    stiffness=min(lim.grasp_stiffness_n_m, m_eff / dt**2), damping=min(lim.grasp_damping_n_s_m, m_eff / dt),
                    free_root=_free_root(m), z_low=low,
                    source=source, grasp_rule=rule)


def _settle(m, d, cfg: LearnConfig) -> None:
    """Step the host data at least ``settle_time``, then in chunks of ``action_repeat`` until the root (free joint)
    moves slower than ``rest_root_speed`` and every joint slower than ``rest_joint_speed``, at most ``settle_max_time``."""
    dt = float(m.opt.timestep)
    n, n_max = int(round(cfg.settle_time / dt)), int(round(cfg.settle_max_time / dt))
    mujoco.mj_step(m, d, nstep=n)
    free = _free_root(m)
    hinge, slide = ([int(m.jnt_dofadr[j]) for j in range(m.njnt) if int(m.jnt_type[j]) == int(kind)]
                    for kind in (mujoco.mjtJoint.mjJNT_HINGE, mujoco.mjtJoint.mjJNT_SLIDE))
    while n < n_max:
        mujoco.mj_step(m, d, nstep=cfg.action_repeat)
        n += cfg.action_repeat
        root_v = float(np.linalg.norm(d.qvel[:3])) if free else 0.0
        if (root_v < cfg.rest_root_speed and np.all(np.abs(d.qvel[hinge]) < cfg.rest_joint_speed[0])
                and np.all(np.abs(d.qvel[slide]) < cfg.rest_joint_speed[1])):
            break


def _free_root(m) -> bool:
    """Whether the model's root is free (its first joint a free joint)."""
    return bool(m.njnt) and int(m.jnt_type[0]) == int(mujoco.mjtJoint.mjJNT_FREE)


def _quat_mat(q: jax.Array) -> jax.Array:
    """Rotation matrix (3, 3) of a unit quaternion (w, x, y, z)."""
    w, x, y, z = q[0], q[1], q[2], q[3]
    return jnp.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                      [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                      [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


class TaskMjxEnv(Env):
    """The learning environment of one :class:`~asset2sim.apps.learn.task.LearnTask` on one :class:`MjxScene` (module
    docstring): :meth:`reset` (a PRNG key) and :meth:`step` (a state, an action (3,)) on one environment, traced by JAX;
    brax's training wrappers vmap them (:func:`wrap_for_training`). An episode's own values live in
    ``state.info["episode"]``; ``state.metrics["success"]`` is 1 on the step that ends an episode in success."""

    def __init__(self, scene: MjxScene, task: LearnTask, config: LearnConfig | None = None) -> None:
        self.scene, self.task, self.config = scene, task, config or LearnConfig()
        cfg = self.config
        with mujoco_messages():
            self._mx = mjx.put_model(scene.model)
            d = mujoco.MjData(scene.model)
            d.qpos[:], d.qvel[:] = scene.qpos, scene.qvel
            self._d0 = mjx.put_data(scene.model, d)
        self.dt = float(scene.model.opt.timestep)
        self.max_steps = max(1, int(round(cfg.episode_time / (self.dt * cfg.action_repeat))))
        self.hold_steps = max(1, int(round(cfg.hold_time / (self.dt * cfg.action_repeat))))
        self.episode_length = self.max_steps + self.hold_steps
        c = task.closed
        self._closed = (float(c.q_closed), float(c.direction), float(c.open_range))
        self._sense = 1.0 if task.action == "close" else -1.0  # reached when sense * (f - reach) <= 0

    @property
    def observation_size(self) -> int:
        return OBS_DIM

    @property
    def action_size(self) -> int:
        return ACTION_DIM

    @property
    def backend(self) -> str:
        return "mjx"

    def fraction(self, qpos: jax.Array) -> jax.Array:
        """Opening fraction of the task joint (the task's closed end, a :class:`ClosedState`; 0 when it cannot open)."""
        qc, direction, rng = self._closed
        return direction * (qpos[self.scene.qadr] - qc) / rng if rng > 0 else jnp.zeros(())

    def reached(self, f: jax.Array) -> jax.Array:
        """The task's reach rule (:meth:`LearnTask.reached`) on fractions ``f``."""
        return self._sense * (f - self.task.reach_fraction) <= 0.0

    def _root_pose(self, qpos: jax.Array) -> tuple[jax.Array, jax.Array]:
        """The root's position (3,) m and rotation (3, 3) at ``qpos`` (the origin and identity when it is not free)."""
        return (qpos[:3], _quat_mat(qpos[3:7])) if self.scene.free_root else (jnp.zeros(3), jnp.eye(3))

    def _grasp_point(self, d) -> jax.Array:
        b = self.scene.body
        return d.xpos[b] + d.xmat[b] @ jnp.asarray(self.scene.point, d.xpos.dtype)

    def reset(self, rng: jax.Array) -> State:
        sc, cfg = self.scene, self.config
        q = jnp.asarray(sc.qpos, self._d0.qpos.dtype)
        dq = jax.random.uniform(rng, (), minval=-1.0, maxval=1.0) * cfg.reset_noise * self._closed[2]
        q = q.at[sc.qadr].set(jnp.clip(q[sc.qadr] + dq, *sc.limits))
        d = mjx.kinematics(self._mx, self._d0.replace(qpos=q))
        p = self._grasp_point(d)
        p0, R0 = self._root_pose(q)
        foot0 = jnp.array([p0[0], p0[1], sc.z_low])
        zero = jnp.zeros(())
        f = self.fraction(q)
        ep = {"g": p, "p_prev": p, "p_reset": p, "released": zero, "hold": zero, "steps": zero, "f_prev": f,
              "f_start": f, "slide": zero, "tilt": zero, "foot0": foot0, "foot_local": R0.T @ (foot0 - p0),
              "up_local": R0.T @ jnp.array([0.0, 0.0, 1.0]), "p0": p0, "R0": R0}
        obs = self._obs(d, ep, zero, jnp.zeros(2))
        return State(pipeline_state=d, obs=obs, reward=zero, done=zero, metrics={"success": zero, "reached": zero},
                     info={"episode": ep})

    def _obs(self, d, ep: dict, tilt: jax.Array, moved_xy: jax.Array) -> jax.Array:
        cfg, sc = self.config, self.scene
        f = self.fraction(d.qpos)
        fd = self._closed[1] * d.qvel[sc.dadr] / self._closed[2] if self._closed[2] > 0 else jnp.zeros(())
        p = self._grasp_point(d)
        o = jnp.concatenate([jnp.stack([f, f - self.task.target_fraction, fd]), (ep["g"] - p) / sc.length,
                             (p - ep["p_reset"]) / sc.length, moved_xy / cfg.slide_tol,
                             jnp.stack([tilt / cfg.tip_tol, ep["steps"] / self.max_steps])])
        return jnp.nan_to_num(o, nan=0.0, posinf=1e3, neginf=-1e3).astype(jnp.float32)

    def step(self, state: State, action: jax.Array) -> State:
        cfg, sc, ep = self.config, self.scene, dict(state.info["episode"])
        lim, dt = cfg.limits, self.dt
        a = jnp.clip(jnp.nan_to_num(action), -1.0, 1.0)
        n = jnp.linalg.norm(a)
        v = jnp.where(n > 1.0, a / jnp.maximum(n, 1e-9), a) * lim.max_speed_m_s
        released = ep["released"] > 0
        k, c, leash = sc.stiffness, sc.damping, lim.max_force_n / sc.stiffness

        def substep(carry, _):
            d, g, p_prev, stretch = carry
            p = self._grasp_point(d)  # at the positions the last step's forward pass used
            s = g + v * dt - p
            sn = jnp.linalg.norm(s)
            g1 = jnp.where(released, p, p + jnp.where(sn > leash, s * leash / jnp.maximum(sn, 1e-12), s))
            force = k * (g1 - p) + c * ((g1 - g) / dt - (p - p_prev) / dt)
            fn = jnp.linalg.norm(force)
            force = jnp.where(released, 0.0, jnp.where(fn > lim.max_force_n, force * lim.max_force_n / jnp.maximum(fn, 1e-12), force))
            wrench = jnp.concatenate([force, jnp.cross(p - d.xipos[sc.body], force)])
            d = mjx.step(self._mx, d.replace(xfrc_applied=d.xfrc_applied.at[sc.body].set(wrench)))
            return (d, g1, p, jnp.linalg.norm(g1 - p)), None

        (d, g, p_prev, stretch), _ = jax.lax.scan(substep, (state.pipeline_state, ep["g"], ep["p_prev"], jnp.zeros(())),
                                                  None, length=cfg.action_repeat)
        steps = ep["steps"] + 1
        f = self.fraction(d.qpos)
        p_root, R = self._root_pose(d.qpos)
        moved_xy = (p_root + R @ ep["foot_local"] - ep["foot0"])[:2]
        tilt_now = jnp.arccos(jnp.clip((R @ ep["up_local"])[2], -1.0, 1.0))
        slide = jnp.maximum(ep["slide"], jnp.linalg.norm(moved_xy))
        tilt = jnp.maximum(ep["tilt"], tilt_now)
        finite = jnp.isfinite(f) & jnp.all(jnp.isfinite(d.qpos))
        moved = (slide > cfg.slide_tol) | (tilt > cfg.tip_tol) | ~finite
        reached = self.reached(f) & finite
        tgt = self.task.target_fraction
        span = jnp.maximum(jnp.abs(ep["f_start"] - tgt), 0.05)
        progress = cfg.progress_weight * (jnp.abs(ep["f_prev"] - tgt) - jnp.abs(f - tgt)) / span
        pull = cfg.stretch_weight * stretch * k / lim.max_force_n
        hold = jnp.where(released, ep["hold"] + 1, 0.0)
        held = hold >= self.hold_steps
        success = released & held & ~moved & (reached | (not self.task.hold_required))
        done = moved | jnp.where(released, held, (steps >= self.max_steps) & ~reached)
        reward = jnp.where(released, 0.0, jnp.nan_to_num(progress - pull)) - cfg.moved_penalty * moved + cfg.success_bonus * success
        ep.update(g=g, p_prev=p_prev, released=(released | (reached & ~moved)).astype(jnp.float32), hold=hold,
                  steps=steps, f_prev=jnp.nan_to_num(f), slide=slide, tilt=tilt)
        obs = self._obs(d, ep, tilt_now, moved_xy)
        one = jnp.ones(())
        return state.replace(pipeline_state=d, obs=obs, reward=reward.astype(jnp.float32),
                             done=jnp.where(done, one, 0.0 * one),
                             metrics={"success": success.astype(jnp.float32), "reached": ep["released"]},
                             info={**state.info, "episode": ep})


class _EpisodeAutoReset(brax_training.AutoResetWrapper):
    """brax's auto-reset, which also restores the episode's own values (``info["episode"]``) of a done environment."""

    def reset(self, rng: jax.Array) -> State:
        state = super().reset(rng)
        state.info["first_episode"] = state.info["episode"]
        return state

    def step(self, state: State, action: jax.Array) -> State:
        state = super().step(state, action)
        done = state.done

        def pick(first, now):
            return jnp.where(jnp.reshape(done, done.shape + (1,) * (now.ndim - done.ndim)), first, now)

        ep = jax.tree.map(pick, state.info["first_episode"], state.info["episode"])
        return state.replace(info={**state.info, "episode": ep})


def wrap_for_training(env: Env, episode_length: int, action_repeat: int = 1, randomization_fn=None) -> Env:
    """brax's training wrappers (vmap, episode length, auto-reset) with the episode's own values reset too: the
    ``wrap_env_fn`` of ``brax.training.agents.ppo.train``. Raises ValueError: a ``randomization_fn`` (not supported)."""
    if randomization_fn is not None:
        raise ValueError("wrap_for_training: domain randomization is not supported")
    return _EpisodeAutoReset(brax_training.EpisodeWrapper(brax_training.VmapWrapper(env), episode_length, action_repeat))


def evaluate(env: TaskMjxEnv, make_policy: Callable, params: Any, key: jax.Array, episodes: int) -> dict[str, Any]:
    """``episodes`` episodes of the deterministic policy ``make_policy(params, deterministic=True)`` (brax's inference
    function: ``policy(obs (n, 13), key) -> (actions (n, 3), extras)``) from resets of ``key``'s split keys, in parallel,
    each until its first end (at most ``env.episode_length`` steps); ``params`` are an argument of the one compiled
    program, so every seed's policy runs the same program. Returns {"success": (episodes,) bool, "reached":
    (episodes,) bool, "final_fraction": (episodes,) float}."""

    def run(params, key):
        policy = make_policy(params, deterministic=True)
        k_reset, k_act = jax.random.split(key)
        s = jax.vmap(env.reset)(jax.random.split(k_reset, episodes))
        off = jnp.zeros(episodes, bool)

        def body(carry, k):
            s, ended, succ, reach, frac = carry
            act, _ = policy(s.obs, k)
            s = jax.vmap(env.step)(s, act)
            now = ~ended & (s.done > 0)
            f = jax.vmap(env.fraction)(s.pipeline_state.qpos)
            return (s, ended | now, succ | (now & (s.metrics["success"] > 0)), reach | (s.metrics["reached"] > 0),
                    jnp.where(ended, frac, f)), None

        init = (s, off, off, off, jnp.zeros(episodes))
        (_, _, succ, reach, frac), _ = jax.lax.scan(body, init, jax.random.split(k_act, env.episode_length))
        return succ, reach, frac

    succ, reach, frac = jax.jit(run)(params, key)
    return {"success": np.asarray(succ), "reached": np.asarray(reach), "final_fraction": np.asarray(frac)}
