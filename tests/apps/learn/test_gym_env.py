"""The learnability environment (asset2sim.apps.learn.gym_env) on
generated assets: spaces and shapes, the task instance, reward sign,
success and failure flags. No PPO training here (benchmarks/bench_learnability.py)."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("gymnasium")

from asset2sim import demo_assets  # noqa: E402
from asset2sim.tasks.check.gripper import GripperLimits  # noqa: E402
from asset2sim.apps.learn.gym_env import (  # noqa: E402
    ACTION_DIM,
    OBS_DIM,
    LearnConfig,
    TaskEnv,
    run_episode,
)
from asset2sim.apps.learn.task import (  # noqa: E402
    START_FRACTION,
    START_MAX_ANGLE,
    common_start,
    prepare_task,
    targets_for,
)


@pytest.fixture(scope="module")
def cabinet(tmp_path_factory):
    return demo_assets.build_two_drawer_cabinet(tmp_path_factory.mktemp("learn") / "cabinet")


@pytest.fixture(scope="module")
def box(tmp_path_factory):
    return demo_assets.build_box_with_lid(tmp_path_factory.mktemp("learn") / "box")


def test_task_instance_from_text(cabinet, box):
    t = prepare_task(cabinet, "close the drawer")
    assert t.action == "close" and t.joint in ("joint_0", "joint_1") and t.joint_type == "prismatic"
    assert t.start_fraction == START_FRACTION["close"]
    assert (t.target_fraction, t.reach_fraction) == targets_for("close", 0.5)
    assert t.reached(0.05) and not t.reached(0.3)
    o = prepare_task(box, "open the box lid")
    assert o.action == "open" and o.joint == "joint_0" and o.start_fraction == 0.0
    assert o.reached(0.6) and not o.reached(0.3)
    with pytest.raises(ValueError):
        prepare_task(box, "open the box lid", start="nowhere")


def test_spaces_shapes_and_budget_counter(box):
    env = TaskEnv(prepare_task(box, "close the box lid"))
    try:
        obs, info = env.reset(seed=0)
        assert obs.shape == (OBS_DIM,) and obs.dtype == np.float32
        assert env.observation_space.contains(obs)
        assert env.action_space.shape == (ACTION_DIM,)
        assert abs(info["fraction"] - env.task.start_fraction) <= env.config.reset_noise + 0.02  # settled at the start
        settled = env.sim_steps
        assert round(env.config.settle_time * 240) <= settled <= round(env.config.settle_max_time * 240)
        obs2, r, term, trunc, info2 = env.step(np.zeros(ACTION_DIM, np.float32))
        assert obs2.shape == (OBS_DIM,) and isinstance(r, float) and not term and not trunc
        assert env.sim_steps == settled + env.config.action_repeat
        with pytest.raises(ValueError, match="4 components"):
            env.step(np.zeros(3))
        # the gripper starts on the grasp point: no stretch in the observation
        assert np.linalg.norm(obs[3:6]) < 1e-6
    finally:
        env.close()


def test_reward_follows_progress_towards_the_target(cabinet):
    env = TaskEnv(prepare_task(cabinet, "close the drawer"))
    try:
        env.reset(seed=0)
        towards = [env.step(env.scripted_action())[1] for _ in range(3)]
        f_towards = env.joint_fraction()[0]
        env.reset(seed=0)
        away = [env.step(env.scripted_action() * np.array([-1.0, -1.0, -1.0, 1.0]))[1] for _ in range(3)]
        f_away = env.joint_fraction()[0]
    finally:
        env.close()
    assert all(r > 0 for r in towards) and sum(towards) > 0.5
    assert all(r < 0 for r in away)
    assert f_towards < 0.5 < f_away


def test_scripted_close_succeeds_and_is_held(cabinet):
    env = TaskEnv(prepare_task(cabinet, "close the drawer"))
    try:
        out = run_episode(env, lambda o: env.scripted_action(0.5), seed=1)
    finally:
        env.close()
    assert out["success"] and out["failure"] == ""
    assert out["fraction"] <= 0.10 and out["slide_m"] <= 0.005 and out["tip_rad"] <= 0.05
    assert 0 < out["peak_force_n"] <= GripperLimits().max_force_n


def test_doing_nothing_fails_by_time_limit(cabinet):
    env = TaskEnv(prepare_task(cabinet, "close the drawer"))
    try:
        out = run_episode(env, lambda o: np.zeros(ACTION_DIM), seed=2)
    finally:
        env.close()
    assert not out["success"] and out["failure"] == "time limit"
    assert out["steps"] == env.max_steps


def test_object_that_slides_fails(cabinet):
    # A gripper that pulls the drawer's front sideways at full speed with a
    # large force drags the light (1 kg-per-link default) cabinet along.
    env = TaskEnv(prepare_task(cabinet, "close the drawer"),
                  LearnConfig(limits=GripperLimits(max_force_n=200.0, max_speed_m_s=1.0)))
    try:
        env.reset(seed=0)
        a = env.scripted_action()
        assert a.shape == (ACTION_DIM,) and a[3] < 0  # a drawer is pulled, not pressed
        side = np.cross(a[:3], [0.0, 0.0, 1.0])
        side = np.append(side / np.linalg.norm(side), -1.0)
        for _ in range(env.max_steps):
            _, r, term, trunc, info = env.step(side)
            if term or trunc:
                break
    finally:
        env.close()
    assert term and not info["success"]
    assert info["failure"] in ("the object slid", "the object tipped")
    assert r < 0


def test_common_start_keeps_a_wide_hinge_below_vertical():
    # half of a 183 deg box lid would stand it near vertical: at most 45 deg open instead
    assert abs(common_start("close", "revolute", 3.2) * 3.2 - START_MAX_ANGLE) < 1e-12
    assert common_start("close", "revolute", 1.0) == START_FRACTION["close"]  # a 57 deg range: half open is 29 deg
    assert common_start("close", "prismatic", 3.2) == START_FRACTION["close"]
    assert common_start("open", "revolute", 3.2) == 0.0
    with pytest.raises(ValueError, match="close' or 'open"):
        common_start("twist", "revolute", 1.0)


def test_scripted_close_of_a_lid_presses_down(box):
    env = TaskEnv(prepare_task(box, "close the box lid"))
    try:
        env.reset(seed=0)
        a = env.scripted_action()
        assert a[3] > 0 and a[2] < 0 and np.allclose(a[:2], 0.0)  # a vertical press, not a sideways push
        out = run_episode(env, lambda o: env.scripted_action(0.5), seed=3)
    finally:
        env.close()
    assert out["success"], out
