"""The MJX learning environment (asset2sim.apps.learn.mjx_env) on a refined output's MJCF export: its shapes, a reward
that follows the task joint, the task's own success rule, and a few iterations of brax's PPO on the CPU."""

from __future__ import annotations

import logging
import sys

import numpy as np
import pytest

pytest.importorskip("brax")
_ROOT_HANDLERS = list(logging.root.handlers)

from absl import logging as absl_logging  # noqa: E402
import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
from brax.training.agents.ppo import train as ppo  # noqa: E402
from mujoco import mjx  # noqa: E402

from asset2sim.apps.learn.mjx_env import ACTION_DIM, OBS_DIM, TaskMjxEnv, build_scene, evaluate, wrap_for_training  # noqa: E402
from asset2sim.apps.learn.task import prepare_task  # noqa: E402

# Importing brax's PPO imports absl, whose handler writes to the stderr of the moment (pytest's capture of this
# collection) and closes that stream when logging's handlers are shut down (uvicorn's logging set-up in the rating app's
# tests does), and whose first log, before any handler exists, calls logging.basicConfig(). Its handler writes to the
# process's stderr instead, which it never closes, and the root logger gets back the handlers it had.
absl_logging.get_absl_handler().python_handler.stream = sys.__stderr__
logging.root.handlers[:] = _ROOT_HANDLERS

# end to end: JAX compiles the environment's step, PPO's training epoch and the evaluation (minutes on 2 cores)
pytestmark = pytest.mark.slow

PROMPT = "a small box with its lid closed"  # the output tests/tasks/publish/test_verify_output.py shares (MJCF export in it)


@pytest.fixture(scope="module")
def env(refine_factory):
    out = refine_factory("box_lid", PROMPT, extras=True, media=False).out
    assert (out / "mjcf" / "mobility.xml").is_file()
    task = prepare_task(out, "close the box lid")
    return TaskMjxEnv(build_scene(out, task), task)


def test_the_scene_is_the_export_at_the_task_start(env):
    assert env.scene.source == "mjcf/mobility.xml"
    assert env.observation_size == OBS_DIM and env.action_size == ACTION_DIM == 3
    f0 = float(env.fraction(jnp.asarray(env.scene.qpos)))
    assert abs(f0 - env.task.start_fraction) < 0.05  # settled near the common start (half open, at most 45 deg)
    f = np.linspace(-0.1, 1.0, 23)
    assert np.array_equal(np.asarray(env.reached(jnp.asarray(f))), [env.task.reached(x) for x in f])


def test_reward_follows_the_task_joint(env):
    s = jax.jit(env.reset)(jax.random.PRNGKey(0))
    assert s.obs.shape == (OBS_DIM,) and s.obs.dtype == jnp.float32
    step = jax.jit(env.step)
    qadr, (qc, direction, rng) = env.scene.qadr, env._closed

    def moved_to(fraction):  # the task joint put at an opening fraction (the gripper with it), then one step, the gripper still
        d = s.pipeline_state
        d = mjx.kinematics(env._mx, d.replace(qpos=d.qpos.at[qadr].set(qc + direction * fraction * rng)))
        p = env._grasp_point(d)
        ep = {**s.info["episode"], "g": p, "p_prev": p}
        return step(s.replace(pipeline_state=d, info={**s.info, "episode": ep}), jnp.zeros(ACTION_DIM))

    f0 = float(s.obs[0])
    closer, farther = moved_to(f0 - 0.1), moved_to(f0 + 0.1)
    assert float(closer.reward) > 0 > float(farther.reward)
    reached = moved_to(env.task.target_fraction)
    assert float(reached.info["episode"]["released"]) == 1.0 and float(reached.done) == 0.0  # released; the hold begins


def test_a_few_ppo_iterations_train_and_evaluate(env):
    make_policy, params, _ = ppo.train(
        env, num_timesteps=64, num_envs=4, episode_length=env.episode_length, wrap_env_fn=wrap_for_training,
        unroll_length=4, batch_size=4, num_minibatches=2, num_updates_per_batch=1, num_evals=2, run_evals=False,
        normalize_observations=True, seed=0)
    ev = evaluate(env, make_policy, params, jax.random.PRNGKey(1), 4)
    assert ev["success"].shape == ev["reached"].shape == (4,)
    assert np.all(np.isfinite(ev["final_fraction"]))
    assert not np.any(ev["success"] & ~ev["reached"])  # success only after reaching the target
