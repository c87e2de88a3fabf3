"""A gymnasium learning environment per manipulation task (SPEC, "Behavioral fidelity, learning feasibility"): the
task of :func:`~asset2sim.apps.learn.task.prepare_task`, a force- and speed-limited gripper
(:class:`~asset2sim.tasks.check.gripper.BoundedGrasp`) at the task link's contact point; action (4,) in [-1, 1]
(gripper velocity in units of the speed limit, press flag), observation (13,) float32, reward for progress, stretch,
slide/tip and success (definitions: docs/design/metrics.md). ``gymnasium`` is the extra ``gym``; PPO the extra ``learn``.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np

from asset2sim.engines.base import SimSession
from asset2sim.engines.quiet import quiet_stdout
from asset2sim.engines.registry import open_session
from asset2sim.tasks.check.contact_points import contact_point_rule, joint_frame_axis
from asset2sim.tasks.check.gripper import BoundedGrasp
from asset2sim.tasks.check.support import SupportWatch
from asset2sim.tasks.check.task_execution import TaskConfig
from asset2sim.apps.learn.task import LearnConfig, LearnTask
from asset2sim.urdf import UrdfModel, read_urdf

OBS_DIM = 13  # observation length (module docstring)
ACTION_DIM = 4  # action length: gripper velocity (3,), press flag
_UP = np.array([0.0, 0.0, 1.0])  # world up, the direction of a press


class TaskEnv(gym.Env):
    """The learning environment of one :class:`LearnTask` (module docstring); the
    session opens at the first :meth:`reset` and lives until :meth:`close`."""

    metadata = {"render_modes": []}

    def __init__(self, task: LearnTask, config: LearnConfig | None = None) -> None:
        super().__init__()
        self.task = task
        self.config = config or LearnConfig()
        if self.config.action_repeat < 1:
            raise ValueError(f"action_repeat must be >= 1, got {self.config.action_repeat}")
        self.action_space = gym.spaces.Box(-1.0, 1.0, shape=(ACTION_DIM,), dtype=np.float32)
        self.observation_space = gym.spaces.Box(-np.inf, np.inf, shape=(OBS_DIM,), dtype=np.float32)
        self.dt = float(task.conventions.timestep)
        self.max_steps = max(1, int(round(self.config.episode_time / (self.dt * self.config.action_repeat))))
        self._session: SimSession | None = None
        self._snapshot: int | None = None
        self._model: UrdfModel | None = None
        self.grasp: BoundedGrasp | None = None
        self.grasp_rule = ""
        self._length = 1.0
        self._steps = 0
        self._f_prev = 0.0
        self._f_start = 0.0
        self._p_reset = np.zeros(3)
        self._watch: SupportWatch | None = None  # slide and tip since reset
        self.sim_steps = 0  # engine steps since the environment was made (the budget)
        self.episodes = 0  # episodes ended since the environment was made

    # ---------------------------------------------------------------- session
    @property
    def session(self) -> SimSession:
        """The open session; RuntimeError before the first :meth:`reset`."""
        if self._session is None:
            raise RuntimeError("TaskEnv: call reset() first")
        return self._session

    def _open(self) -> None:
        with quiet_stdout():
            s = open_session(self.config.engine, self.task.urdf, self.task.session_options())
        self._session = s
        self._model = read_urdf(self.task.urdf, mode="lenient")
        self._settle(s)
        self._snapshot = s.save_state()

    def _settle(self, s: SimSession) -> None:
        """Step at least ``settle_time`` and until at rest (:attr:`LearnConfig.settle_max_time`)."""
        cfg = self.config
        n = int(round(cfg.settle_time / self.dt))
        s.step(n)
        self.sim_steps += n
        chunk = cfg.action_repeat
        while n < int(round(cfg.settle_max_time / self.dt)):
            p0 = np.asarray(s.root_pose()[0], float)
            s.step(chunk)
            n += chunk
            self.sim_steps += chunk
            root_v = float(np.linalg.norm(np.asarray(s.root_pose()[0], float) - p0)) / (chunk * self.dt)
            fast = [j for j, qd in s.joint_velocities().items()
                    if not abs(qd) < cfg.rest_joint_speed[1 if s.joint_types.get(j) == "prismatic" else 0]]
            if root_v < cfg.rest_root_speed and not fast:
                break

    def close(self) -> None:
        """Release the simulator session."""
        if self._session is not None:
            if self._snapshot is not None:
                self._session.discard_state(self._snapshot)
            self._session.close()
        self._session = None
        self._snapshot = None

    # -------------------------------------------------------------- measures
    def joint_fraction(self) -> tuple[float, float]:
        """(opening fraction, its rate 1/s) of the task joint now."""
        q, qd = self.session.joint_state(self.task.joint)
        return self.task.fraction(q), float(self.task.closed.direction * qd / self.task.closed.open_range)

    def _obs(self) -> np.ndarray:
        f, fd = self.joint_fraction()
        p = self.grasp.grasp_point_world()
        moved, rot = self._watch.current()
        L = self._length
        o = np.concatenate([
            [f, f - self.task.target_fraction, fd],
            (self.grasp.gripper_point - p) / L,
            (p - self._p_reset) / L,
            moved / self.config.slide_tol,
            [rot / self.config.tip_tol, self._steps / self.max_steps],
        ])
        return np.nan_to_num(o, nan=0.0, posinf=1e3, neginf=-1e3).astype(np.float32)

    def _info(self, success: bool = False, failure: str = "") -> dict[str, Any]:
        f, _ = self.joint_fraction()
        return {"fraction": f, "success": success, "failure": failure, "slide_m": self._watch.slide,
                "tip_rad": self._watch.tilt, "peak_force_n": self.grasp.peak_force_n if self.grasp else 0.0,
                "steps": self._steps, "grasp_rule": self.grasp_rule}

    # ------------------------------------------------------------------ gym
    def reset(self, *, seed: int | None = None, options: dict | None = None) -> tuple[np.ndarray, dict]:
        """Restore the settled snapshot, offset the task joint by the reset
        noise, grasp; returns (observation (13,), info)."""
        super().reset(seed=seed)
        if self._session is None:
            self._open()
        s = self.session
        s.restore_state(self._snapshot)
        t = self.task
        if self.config.reset_noise > 0:
            q, _ = s.joint_state(t.joint)
            dq = float(self.np_random.uniform(-1.0, 1.0)) * self.config.reset_noise * t.closed.open_range
            lo, hi = s.joint_limits.get(t.joint, (-np.inf, np.inf))
            s.set_joint_positions({t.joint: float(np.clip(q + dq, lo, hi))})
        link, point, self.grasp_rule = contact_point_rule(s, t.joint, self._model, opening_direction=t.closed.direction)
        self.grasp = BoundedGrasp(s, link, point, self.config.limits)
        p = self.grasp.grasp_point_world()
        self._p_reset = p.copy()
        if t.joint_type == "prismatic":
            length = t.closed.open_range
        else:
            o, a = joint_frame_axis(s, t.joint, s.joint_child[t.joint])
            length = float(np.linalg.norm((p - o) - ((p - o) @ a) * a))
        self._length = max(length, 1e-3)
        self._watch = SupportWatch(s, s.link_names[0])
        self._steps = 0
        self._f_prev, _ = self.joint_fraction()
        self._f_start = self._f_prev
        return self._obs(), self._info()

    def _engine_step(self) -> None:
        self.session.step(1)
        self.sim_steps += 1

    def step(self, action) -> tuple[np.ndarray, float, bool, bool, dict]:
        """Move the gripper for ``action_repeat`` engine steps with ``action`` (4,) (module docstring); returns
        (observation, reward, terminated, truncated, info). Raises ValueError: ``action`` does not have 4 components."""
        cfg = self.config
        a = np.nan_to_num(np.asarray(action, float).reshape(-1), nan=0.0)
        if a.shape != (ACTION_DIM,):
            raise ValueError(f"action must have {ACTION_DIM} components (velocity x, y, z; press), got shape {a.shape}")
        n = float(np.linalg.norm(a[:3]))
        v = (a[:3] / n if n > 1.0 else a[:3]) * cfg.limits.max_speed_m_s
        press = _UP if a[3] > 0 else None
        for _ in range(cfg.action_repeat):
            self.grasp.step_towards(self.grasp.gripper_point + v * self.dt, self.dt, direction=press)
            self._engine_step()
        self._steps += 1
        self._watch.update()
        f, _ = self.joint_fraction()
        t = self.task
        span = max(abs(self._f_start - t.target_fraction), 0.05)
        reward = cfg.progress_weight * (abs(self._f_prev - t.target_fraction) - abs(f - t.target_fraction)) / span
        stretch = float(np.linalg.norm(self.grasp.gripper_point - self.grasp.grasp_point_world()))
        reward -= cfg.stretch_weight * stretch * self.grasp.stiffness / cfg.limits.max_force_n
        self._f_prev = f
        failure = "diverged" if not np.isfinite(f) else self._moved()
        truncated = self._steps >= self.max_steps
        if failure or t.reached(f) or truncated:  # the episode ends
            self.episodes += 1
        if failure:
            return self._obs(), float(reward - cfg.moved_penalty), True, False, self._info(False, failure)
        if t.reached(f):
            ok, why = self._hold()
            if ok:
                reward += cfg.success_bonus
            return self._obs(), float(reward), True, False, self._info(ok, why)
        return self._obs(), float(reward), False, truncated, self._info(False, "time limit" if truncated else "")

    def _moved(self) -> str:
        """Why the object counts as moved since reset ("the object slid", "the object tipped"), else ""."""
        if self._watch.slide > self.config.slide_tol:
            return "the object slid"
        return "the object tipped" if self._watch.tilt > self.config.tip_tol else ""

    def _hold(self) -> tuple[bool, str]:
        """Release and watch :attr:`LearnConfig.hold_time` s: (held, failure)."""
        cfg = self.config
        self.grasp.release()
        for _ in range(int(round(cfg.hold_time / self.dt))):
            self._engine_step()
            self._watch.update()
        f, _ = self.joint_fraction()
        moved = self._moved()
        if moved:
            return False, f"{moved} after release"
        return (False, "target not held after release") if self.task.hold_required and not self.task.reached(f) else (True, "")

    # ------------------------------------------------------------ reference
    def scripted_action(self, speed: float = 0.5, vertical_share: float = TaskConfig.vertical_share) -> np.ndarray:
        """A hand-written policy (the feasibility reference), the task-execution check's motion: along the grasp point's
        path towards the target at ``speed`` x the speed limit plus a stretch correction; a vertical press or lift where
        that path is within acos(``vertical_share``) of vertical. Returns the action (4,): velocity in the unit ball, press
        flag in [-1, 1]."""
        s, t = self.session, self.task
        o, a = joint_frame_axis(s, t.joint, s.joint_child[t.joint])
        q, _ = s.joint_state(t.joint)
        f = t.fraction(q)
        sign = 1.0 if t.closed.direction * (t.target_fraction - f) > 0 else -1.0  # sign of the q change wanted
        p = self.grasp.grasp_point_world()
        if t.joint_type == "prismatic":
            d = a
        else:
            d = np.cross(a, (p - o) - ((p - o) @ a) * a)
            d = d / max(float(np.linalg.norm(d)), 1e-12)
        d = sign * d
        corr = (p - self.grasp.gripper_point) / max(self.config.limits.max_speed_m_s * self.dt * self.config.action_repeat, 1e-9)
        press = abs(float(d[2])) >= vertical_share
        vel = _UP * (speed / float(d[2])) + corr[2] * _UP if press else speed * d + corr
        n = float(np.linalg.norm(vel))
        vel = vel / n if n > 1.0 else vel
        return np.append(vel, 1.0 if press else -1.0)


def run_episode(env: TaskEnv, policy, *, seed: int | None = None) -> dict[str, Any]:
    """One episode of ``policy(obs) -> action (4,)`` (or ``"scripted"``:
    :meth:`TaskEnv.scripted_action`); returns the last info plus ``return``."""
    obs, info = env.reset(seed=seed)
    total = 0.0
    while True:
        act = env.scripted_action() if policy == "scripted" else policy(obs)
        obs, r, term, trunc, info = env.step(act)
        total += r
        if term or trunc:
            break
    return dict(info, **{"return": total})
