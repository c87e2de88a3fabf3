"""asset2sim.apps.learn.maniskill: refined outputs (and raw inputs) as ManiSkill 3 environments on the CPU backend."""

from __future__ import annotations

import math
import shutil
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("mani_skill", reason="ManiSkill 3 is not installed (pip install 'asset2sim[maniskill]')")
gym = pytest.importorskip("gymnasium", reason="gymnasium is not installed")
torch = pytest.importorskip("torch", reason="torch is not installed (pip install 'asset2sim[maniskill]')")

import asset2sim  # noqa: E402
from asset2sim.apps.learn import maniskill as ams  # noqa: E402
from asset2sim.demo_assets import build_box_with_lid, build_two_drawer_cabinet  # noqa: E402
from asset2sim.engines import physx_engine  # noqa: E402

pytestmark = pytest.mark.physx

#: A held part may move this much (rad) over HOLD_SECONDS (the robust-rest tolerance of the checks).
HOLD_TOL = 0.02
HOLD_SECONDS = 2.0


@pytest.fixture(scope="module")
def outputs(shared_dataset, tmp_path_factory) -> Path:
    """A folder of two refined outputs: the dev stapler 103275 ("a slightly open stapler": its lid held by friction
    and a spring) and a generated box with its lid slightly open."""
    root = tmp_path_factory.mktemp("maniskill") / "outputs"
    asset2sim.refine(shared_dataset / "103275", "a slightly open stapler", root / "stapler", extras=False)
    box = build_box_with_lid(tmp_path_factory.mktemp("maniskill_in") / "box")
    asset2sim.refine(box, "a small box with its lid slightly open", root / "box", extras=False)
    return root


def _make(env_id: str, assets, **kw):
    return gym.make(env_id, assets=assets, num_envs=1, obs_mode="state", render_backend="none", sim_backend="cpu", **kw)


def _reset_and_step(env_id: str, assets, steps: int = 3, **kw) -> None:
    """Make ``env_id`` on ``assets``, reset it and step ``steps`` random actions (an error fails the test)."""
    env = _make(env_id, assets, **kw)
    try:
        env.reset(seed=0)
        for _ in range(steps):
            env.step(env.action_space.sample())
    finally:
        env.close()


@pytest.mark.parametrize("action", ["open", "close"])
def test_each_id_runs_an_episode_on_the_cpu_backend(outputs, action):
    env = _make(ams.ENV_IDS[action], outputs)
    try:
        u = env.unwrapped
        assert sorted(o.folder.name for o in u.objects) == ["box", "stapler"] and not u.skipped
        assert {o.kind for o in u.objects} == {"refined"}
        obs, info = env.reset(seed=1)
        obj = u.env_objects[0]
        assert float(info["fraction"][0]) == pytest.approx(obj.start_fraction, abs=0.02)
        assert not bool(info["success"][0])
        rng = np.random.default_rng(0)
        steps, truncated = 0, False
        while not truncated:
            obs, reward, terminated, truncated, info = env.step(rng.uniform(-1, 1, env.action_space.shape).astype(np.float32))
            steps += 1
            assert torch.isfinite(obs).all() and 0.0 <= float(reward[0]) <= ams.MAX_REWARD
            truncated = bool(truncated[0]) or bool(terminated[0])
        assert steps <= ams.MAX_EPISODE_STEPS
        assert bool(terminated[0]) or steps == ams.MAX_EPISODE_STEPS
    finally:
        env.close()


def test_success_and_reward_follow_the_task_joint(outputs):
    """At the target and at rest: success and the full reward (5; normalized 1); at the start: neither."""
    env = _make(ams.ENV_IDS["open"], [outputs / "stapler"])
    try:
        env.reset(seed=0)
        u = env.unwrapped
        obj = u.env_objects[0]
        assert obj.joint == "joint_1" and obj.action == "open"  # the lid, as the report's task ("close the stapler") names it
        zero = torch.zeros((1,) + env.action_space.shape)
        info = u.evaluate()
        assert not bool(info["success"][0]) and float(u.compute_dense_reward(None, zero, info)[0]) < 3.0
        names = u._joint_names[0]
        q = torch.tensor(obj.start_qpos(names), dtype=torch.float32)[None]
        q[0, names.index(obj.joint)] = obj.q_at(obj.target_fraction)
        u.object.set_qpos(q)
        u.object.set_qvel(torch.zeros_like(q))
        info = u.evaluate()
        assert float(info["fraction"][0]) == pytest.approx(obj.target_fraction, abs=1e-4)
        assert bool(info["success"][0])
        assert float(u.compute_dense_reward(None, zero, info)[0]) == ams.MAX_REWARD
        assert float(u.compute_normalized_dense_reward(None, zero, info)[0]) == pytest.approx(1.0)
        moving = torch.zeros_like(q)
        moving[0, names.index(obj.joint)] = 2.0  # rad/s: not at rest
        u.object.set_qvel(moving)
        assert not bool(u.evaluate()["success"][0])
    finally:
        env.close()


def test_a_raw_input_runs_in_the_same_environment(shared_dataset):
    env = _make(ams.ENV_IDS["open"], [shared_dataset / "103275"])
    try:
        obj = env.unwrapped.objects[0]
        assert obj.kind == "raw" and obj.springs == {}
        env.reset(seed=0)
        for _ in range(10):
            obs, reward, *_ = env.step(np.zeros(env.action_space.shape, np.float32))
        assert torch.isfinite(obs).all()
    finally:
        env.close()


def _plain_loader_drift(out: Path, obj: ams.TaskObject, seconds: float) -> dict[str, float]:
    """The output loaded as ManiSkill's own loading does it (SAPIEN's URDF loader), same scene settings."""
    scene = physx_engine.new_scene()
    scene.add_ground(0.0, render=False)
    loader = scene.create_urdf_loader()
    builder = loader.parse(str(out / "mobility.urdf"))[0][0]
    for lb in builder.link_builders:
        lb.visual_records = []  # no render device needed
    art = builder.build(fix_root_link=obj.fixed_root)
    import sapien

    art.set_root_pose(sapien.Pose(p=[0.0, 0.0, obj.base_z]))
    names = [j.name for j in art.active_joints]
    q0 = np.array([obj.initial_state.get(n, 0.0) for n in names], np.float32)
    art.set_qpos(q0)
    drift = np.zeros(len(names))
    for _ in range(int(seconds * 240)):
        scene.step()
        drift = np.maximum(drift, np.abs(np.asarray(art.get_qpos(), float) - q0))
    return dict(zip(names, drift.tolist()))


def test_a_held_lid_holds_in_maniskill_as_in_pybullet_and_not_through_the_plain_loader(outputs):
    out = outputs / "stapler"
    obj = ams.task_object(out, "close")
    lid = obj.joint
    assert obj.initial_state[lid] != pytest.approx(obj.q_closed, abs=0.1)  # held open, not resting shut
    ms = ams.hold_drift(out, HOLD_SECONDS)[lid]
    pb = asset2sim.load_pybullet(out)
    q0 = pb.joint_positions()[lid]
    pb_drift = 0.0
    for _ in range(int(HOLD_SECONDS * 240) // 12):
        pb.step(12)
        pb_drift = max(pb_drift, abs(pb.joint_positions()[lid] - q0))
    pb.close()
    plain = _plain_loader_drift(out, obj, HOLD_SECONDS)[lid]
    assert ms <= HOLD_TOL, f"ManiSkill: the lid moved {ms:.4f} rad in {HOLD_SECONDS} s"
    assert pb_drift <= HOLD_TOL, f"PyBullet: the lid moved {pb_drift:.4f} rad"
    assert plain > 5 * HOLD_TOL and plain > 5 * ms, f"SAPIEN's plain loader: the lid moved only {plain:.4f} rad"


def test_bad_inputs_name_the_folder_and_a_failed_asset_does_not_stop_the_others(outputs, tmp_path):
    with pytest.raises(ams.ManiSkillAssetError, match="MS_NO_ASSETS") as err:
        _make(ams.ENV_IDS["open"], tmp_path)
    assert err.value.code == "MS_NO_ASSETS" and str(tmp_path) in str(err.value)
    broken = tmp_path / "mix" / "broken"
    broken.mkdir(parents=True)
    (broken / "mobility.urdf").write_text("<robot name='x'><link name='a'/></robot>")  # no movable joint
    shutil.copytree(outputs / "box", tmp_path / "mix" / "box")
    objects, skipped = ams.load_task_objects(tmp_path / "mix", "open")
    assert [o.folder.name for o in objects] == ["box"]
    assert len(skipped) == 1 and skipped[0][0] == broken and "MS_NO_TASK_JOINT" in skipped[0][1]


def test_a_handle_on_a_fixed_joint_is_grasped_on_the_link_that_carries_it(tmp_path):
    """robosuite's door: the handle hangs on ``latch``, welded to the door by a fixed joint; ManiSkill's link merge
    needs a link with a joint of its own, so the grasp point moves onto the door (where the latch carries it)."""
    from tests.tasks.ingest.host_layouts import robosuite_door

    src = robosuite_door(tmp_path / "in" / "robosuite" / "models" / "assets" / "objects" / "door.xml")
    asset2sim.refine(src, "A door.", tmp_path / "door", extras=False)
    objects, skipped = ams.load_task_objects(tmp_path / "door", "open")
    (obj,) = objects
    assert not skipped and obj.model.parent_joint(obj.grasp_link).type != "fixed"
    assert any("which carries it" in n for n in obj.notes), obj.notes
    latch = next(j for j in obj.model.joints if j.type == "fixed" and j.parent == obj.grasp_link)
    assert np.linalg.norm(obj.grasp_point - latch.origin[:3, 3]) < 0.3  # on the handle, not at the door's origin
    _reset_and_step(ams.ENV_IDS["open"], [tmp_path / "door"])


def test_every_joint_gets_the_outputs_friction_damping_and_spring(outputs):
    env = _make(ams.ENV_IDS["close"], [outputs / "stapler"])
    try:
        env.reset(seed=0)
        u = env.unwrapped
        passive, px = u._passive[0], u._physx_arts[0]
        model = u.env_objects[0].model
        for i, name in enumerate(passive.names):
            j = model.joint(name)
            assert passive.friction[i] == j.friction and passive.damping[i] == j.damping
            assert px.active_joints[i].get_force_limit() >= j.friction - 1e-6  # the drive carries the friction
        spring = u.env_objects[0].springs["joint_1"]
        assert spring.stiffness > 0 and passive.stiffness[passive.names.index("joint_1")] == spring.stiffness
        assert not math.isnan(float(u.task_fraction()[0]))
    finally:
        env.close()


@pytest.fixture(scope="module")
def cabinet(tmp_path_factory) -> Path:
    """The generated two-drawer cabinet refined (30 kg, free on the ground, prismatic drawers)."""
    src = build_two_drawer_cabinet(tmp_path_factory.mktemp("maniskill_cab") / "cabinet")
    out = tmp_path_factory.mktemp("maniskill_cab_out") / "cabinet"
    asset2sim.refine(src, "a small two-drawer cabinet, the first drawer closed and the second slightly open", out, extras=False)
    return out


@pytest.mark.parametrize("robot", ["panda", "floating_panda_gripper"])
def test_the_robot_starts_before_the_grasp_point_without_touching_the_object(cabinet, robot):
    """The TCP starts TCP_APPROACH from the grasp point; holding still, neither the cabinet nor its drawer moves."""
    env = _make(ams.ENV_IDS["close"], [cabinet], robot_uids=robot, robot_init_qpos_noise=0.0)
    try:
        obs, info = env.reset(seed=0)
        u = env.unwrapped
        start = info["grasp_pos"] + torch.tensor(ams.TCP_APPROACH, dtype=torch.float32)
        assert float(torch.linalg.norm(u.agent.tcp.pose.p - start, axis=1)[0]) < 0.01
        p0, f0 = u.object.pose.p.clone(), float(info["fraction"][0])
        for _ in range(10):
            obs, reward, terminated, truncated, info = env.step(np.zeros(env.action_space.shape, np.float32))
        assert float(torch.linalg.norm(u.object.pose.p - p0, axis=1)[0]) < 0.005
        assert float(info["fraction"][0]) == pytest.approx(f0, abs=0.01)
    finally:
        env.close()


@pytest.fixture(scope="module")
def task_outputs(shared_dataset, outputs, tmp_path_factory) -> Path:
    """The dev stapler 103275 refined with the manifest's task ("press the stapler", ``refine --task``) beside the
    generated box refined without a task."""
    root = tmp_path_factory.mktemp("maniskill_task") / "outputs"
    asset2sim.refine(shared_dataset / "103275", "I want a slightly open stapler.", root / "103275", extras=False,
                     task="press the stapler")
    shutil.copytree(outputs / "box", root / "box")
    return root


def test_the_manifest_task_id_runs_each_object_on_the_task_its_report_records(task_outputs):
    from asset2sim.apps.learn.task import prepare_task, targets_for
    from asset2sim.tasks.publish.contract import read_report_json

    out = task_outputs / "103275"
    recorded = read_report_json(out).task
    assert recorded == "press the stapler"
    env = _make(ams.ENV_IDS["task"], task_outputs)
    try:
        u = env.unwrapped
        assert [o.folder.name for o in u.objects] == ["103275"]  # the box records no task
        assert len(u.skipped) == 1 and u.skipped[0][0].name == "box" and "MS_NO_TASK:" in u.skipped[0][1]
        obj = u.objects[0]
        lt = prepare_task(out, recorded, start="task")
        assert obj.task == recorded and obj.joint == lt.joint == "joint_1"
        assert obj.action == lt.action == "close"  # "press" closes the lid, in the task's own direction
        assert (obj.target_fraction, obj.reach_fraction) == targets_for("close", obj.start_fraction)
        assert obj.start_fraction == pytest.approx(lt.start_fraction)
        obs, info = env.reset(seed=0)
        assert float(info["fraction"][0]) == pytest.approx(obj.start_fraction, abs=0.02)
        steps, done = 0, False
        rng = np.random.default_rng(0)
        while not done:
            obs, reward, terminated, truncated, info = env.step(rng.uniform(-1, 1, env.action_space.shape).astype(np.float32))
            steps += 1
            assert torch.isfinite(obs).all() and 0.0 <= float(reward[0]) <= ams.MAX_REWARD
            done = bool(terminated[0]) or bool(truncated[0])
        assert steps <= ams.MAX_EPISODE_STEPS
    finally:
        env.close()


def test_a_manifest_row_gives_the_task_where_the_output_records_none(task_outputs, tmp_path):
    """The box (no report task) takes its manifest row's "open the box lid" and succeeds at the open target; the
    stapler keeps its report's "press the stapler" and succeeds at the close target."""
    manifest = tmp_path / "manifest.csv"
    manifest.write_text("id,category,prompt,task\nbox,Box,a small box,open the box lid\n103275,Stapler,x,open the stapler\n")
    objects, skipped = ams.load_task_objects(task_outputs, "task", manifest=manifest)
    assert not skipped
    by_name = {o.folder.name: o for o in objects}
    assert by_name["103275"].action == "close"  # report.json's task comes before the manifest row's
    assert by_name["box"].action == "open" and by_name["box"].task == "open the box lid"
    for name in ("box", "103275"):
        env = _make(ams.ENV_IDS["task"], [task_outputs / name], manifest=manifest)
        try:
            env.reset(seed=0)
            u = env.unwrapped
            obj = u.env_objects[0]
            assert not bool(u.evaluate()["success"][0])
            q = u.start_qpos.clone()
            q[0, u._joint_names[0].index(obj.joint)] = obj.q_at(obj.target_fraction)
            u.object.set_qpos(q)
            u.object.set_qvel(torch.zeros_like(q))
            assert bool(u.evaluate()["success"][0]), f"{name}: {obj.action} to {obj.target_fraction} is not a success"
        finally:
            env.close()
    with pytest.raises(ams.ManiSkillAssetError, match="MS_BAD_MANIFEST"):
        ams.load_task_objects(task_outputs, "task", manifest=tmp_path / "missing.csv")


def test_gensim2_references_build_and_step_in_the_same_environment(shared_dataset, outputs):
    """``reference=True``: the dev folder's reference_gensim2.urdf at its scale is the object; a folder without a
    reference is skipped with MS_NO_REFERENCE; close() removes the written references."""
    from asset2sim.tasks.ingest.partnet_mobility import read_reference

    ref = read_reference(shared_dataset / "103275")
    env = _make(ams.ENV_IDS["close"], [shared_dataset / "103275", outputs / "box"], reference=True)
    try:
        u = env.unwrapped
        assert len(u.objects) == 1 and u.objects[0].kind == "gensim2" and u.objects[0].source == shared_dataset / "103275"
        assert len(u.skipped) == 1 and u.skipped[0][0] == outputs / "box" and "MS_NO_REFERENCE" in u.skipped[0][1]
        obj = u.objects[0]
        written = obj.folder
        assert [j.name for j in obj.model.movable_joints] == ref.task_joints and obj.joint in ref.task_joints
        lo, hi = ref.joint_position_range
        j = obj.model.joint(obj.joint)
        assert (j.lower, j.upper) == (pytest.approx(max(lo, j.lower)), pytest.approx(hi))  # GenSim2's range
        raw = ams.task_object(shared_dataset / "103275", "close")
        extent = [float(np.ptp(ams._world_points(o.model, o.pieces, {}), axis=0).max()) for o in (obj, raw)]
        assert extent[0] == pytest.approx(ref.scale * extent[1], rel=0.05)  # at GenSim2's scale
        obs, info = env.reset(seed=0)
        for _ in range(10):
            obs, *_ = env.step(np.zeros(env.action_space.shape, np.float32))
        assert torch.isfinite(obs).all() and math.isfinite(float(info["fraction"][0]))
    finally:
        env.close()
    assert not written.exists()


def _dev_rows():
    import csv

    from tests.conftest import SHARED

    path = SHARED / "manifest.csv"
    return (SHARED, list(csv.DictReader(path.open()))) if path.is_file() else (SHARED, [])


@pytest.mark.slow  # end to end: every dev row refined, then built and stepped in ManiSkill
@pytest.mark.parametrize("row", _dev_rows()[1], ids=[r["id"] for r in _dev_rows()[1]])
def test_every_dev_output_is_a_maniskill_task_or_a_named_skip(refine_once, row):
    """Each environment takes the output as a task object, or names why not with an MS_* code; the object's own task
    builds on the CPU backend and steps (``benchmarks/bench_maniskill_tasks.py`` prints the table)."""
    shared, _ = _dev_rows()
    res = refine_once(shared / row["id"], row["prompt"], extras=False)
    for action in ("open", "close", "task"):
        objects, skipped = ams.load_task_objects([res.out], action, manifest=shared / "manifest.csv" if action == "task" else None)
        assert len(objects) + len(skipped) == 1
        assert all(error.startswith("MS_") for _, error in skipped), skipped
    _reset_and_step(ams.ENV_IDS["task"], [res.out], manifest=shared / "manifest.csv")
