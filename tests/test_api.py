"""The public Python API (``import asset2sim``): names, refine, configuration
files, validate, evaluate, export and the engine loaders, on a real
PartNet-Mobility stapler (103275, a spring on its lid) and generated assets."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

import asset2sim
from asset2sim.output_folder import URDF_NAME
from asset2sim.tasks.check import robust_rest


def _files(folder: Path) -> dict[str, tuple[int, int]]:
    return {str(p.relative_to(folder)): (p.stat().st_mtime_ns, p.stat().st_size) for p in sorted(folder.rglob("*")) if p.is_file()}


@pytest.fixture(scope="module")
def stapler(shared_dataset, tmp_path_factory):
    """103275 refined through the API, "a slightly open stapler" (no extras)."""
    out = tmp_path_factory.mktemp("api") / "stapler"
    result = asset2sim.refine(shared_dataset / "103275", "a slightly open stapler", out, extras=False)
    return result


def test_import_is_light_and_lends_the_api_names():
    code = ("import sys, asset2sim; assert 'asset2sim.api' not in sys.modules and 'pybullet' not in sys.modules; "
            "f = asset2sim.refine; assert 'asset2sim.api' in sys.modules; print(f.__module__)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "asset2sim.api"
    assert set(asset2sim.__all__) <= set(dir(asset2sim))
    for name in asset2sim.__all__:
        assert getattr(asset2sim, name).__doc__, name
    with pytest.raises(AttributeError, match="no attribute 'no_such_name'"):
        asset2sim.no_such_name  # noqa: B018
    from asset2sim import atomic  # submodules still import as usual
    assert atomic.__name__ == "asset2sim.atomic"


def test_refine_returns_a_result_that_serializes(stapler):
    assert stapler.ready is (stapler.report.failure_mode == "none")
    data = json.loads(stapler.to_json())
    assert data["out_dir"] == str(stapler.out_dir) and data["ready"] == stapler.ready
    assert data["report"]["asset_id"] == "103275"
    assert data["overlay"]["joints"]["joint_1"]["stiffness"] > 0  # the lid's spring
    assert asset2sim.RefineResult is type(stapler)


def test_refine_again_is_skipped_unless_forced(stapler, shared_dataset):
    before = _files(stapler.out_dir)
    again = asset2sim.refine(shared_dataset / "103275", "a slightly open stapler", stapler.out_dir, extras=False)
    assert again.skipped and again.report.failure_mode == stapler.report.failure_mode
    assert _files(stapler.out_dir) == before


def test_config_from_a_yaml_file_and_its_errors(tmp_path):
    good = tmp_path / "good.yaml"
    good.write_text("estimator: offline\nmax_decompositions: 3\nsim:\n  timestep: 0.002\n")
    cfg = asset2sim.load_config(good)
    assert cfg.max_decompositions == 3 and cfg.sim.timestep == 0.002
    assert asset2sim.load_config({"seed": 2}).seed == 2 and asset2sim.load_config(None) == asset2sim.RefineConfig()
    bad = tmp_path / "bad.yaml"
    bad.write_text("max_decompositons: 3\n")
    with pytest.raises(ValueError, match=r"bad\.yaml.*max_decompositons"):
        asset2sim.load_config(bad)
    listed = tmp_path / "list.yaml"
    listed.write_text("- 1\n- 2\n")
    with pytest.raises(ValueError, match=r"list\.yaml: expected a mapping"):
        asset2sim.load_config(listed)
    with pytest.raises(FileNotFoundError):
        asset2sim.load_config(tmp_path / "missing.yaml")


def test_refine_refuses_an_invalid_config_before_any_work(shared_dataset, tmp_path):
    with pytest.raises(ValueError, match="max_decompositions"):
        asset2sim.refine(shared_dataset / "103275", "", tmp_path / "out", config={"max_decompositions": -1})
    assert not (tmp_path / "out").exists()


def test_validate_names_the_missing_mesh(shared_dataset, tmp_path):
    asset = tmp_path / "stapler"
    shutil.copytree(shared_dataset / "103275", asset)
    assert not [f for f in asset2sim.validate(asset) if f.severity == "error"]
    urdf = (asset / "mobility.urdf").read_text()
    first_mesh = urdf.split('filename="', 1)[1].split('"', 1)[0]
    (asset / first_mesh).unlink()
    errors = [f for f in asset2sim.validate(asset) if f.severity == "error"]
    assert errors and any(first_mesh.split("/")[-1] in (f.message + f.where + (f.file or "")) for f in errors)


def test_evaluate_writes_nothing_unless_asked(stapler, tmp_path):
    before = _files(stapler.out_dir)
    ev = asset2sim.evaluate(stapler.out_dir, probes=False)
    assert isinstance(ev, asset2sim.Evaluation)
    assert {m.name for m in ev.metrics} >= {"penetration", "rest_stability", "oscillation"}
    assert _files(stapler.out_dir) == before
    ev2 = asset2sim.evaluate(stapler.out_dir, probes=False, write_to=tmp_path / "ev")
    assert (tmp_path / "ev" / "evaluation.json").is_file() and (tmp_path / "ev" / "report.html").is_file()
    assert json.loads((tmp_path / "ev" / "evaluation.json").read_text())["asset_id"] == ev2.asset_id


def test_export_mjcf_and_errors(stapler, tmp_path):
    pytest.importorskip("mujoco")
    copy = tmp_path / "copy"
    shutil.copytree(stapler.out_dir, copy)
    path = asset2sim.export(copy, "mjcf")
    assert path.is_file() and path.suffix == ".xml" and path.is_relative_to(copy)
    with pytest.raises(ValueError, match="unknown export format 'obj'"):
        asset2sim.export(copy, "obj")
    with pytest.raises(ValueError, match="not an asset2sim output folder"):
        asset2sim.export(tmp_path, "mjcf")


def _trials(session) -> dict:
    """Every robust-rest trial of the product's check, run on ``session``."""
    return {t.name: {"d_pos": t.d_pos, "d_ori": t.d_ori, "topple": t.topple, "joint_drift": t.joint_drift, "passed": t.passed}
            for t in robust_rest.run_trials(session, dict(session.options.initial_state))}


def test_load_pybullet_into_a_users_client_gives_the_checks_robust_rest_numbers(stapler):
    import pybullet as p

    cid = p.connect(p.DIRECT)
    try:
        p.setGravity(0, 0, -9.81, physicsClientId=cid)
        p.setTimeStep(1 / 240, physicsClientId=cid)
        session = asset2sim.load_pybullet(stapler.out_dir, cid)
        assert session.cid == cid and session.options.springs["joint_1"].stiffness > 0
        state = json.loads((Path(stapler.out_dir) / "initial_state.json").read_text())["initial_joint_positions"]
        assert session.joint_positions() == pytest.approx(state, abs=1e-9)
        [metric] = [m for m in stapler.report.metrics if m.name == "robust_rest"]
        ours = _trials(session)
        for name, trial in ours.items():
            reported = metric.details["trials"][name]
            for key in ("d_pos", "d_ori", "topple", "passed"):
                assert trial[key] == reported[key], (name, key)
            assert trial["joint_drift"] == reported["joint_drift"], name
        session.close()
        assert p.isConnected(cid) and p.getNumBodies(physicsClientId=cid) == 0  # the body and plane removed, the client kept
    finally:
        p.disconnect(cid)


def test_load_pybullet_without_the_plane_still_rests_on_z0(stapler):
    import pybullet as p

    cid = p.connect(p.DIRECT)
    try:
        own = asset2sim.load_pybullet(stapler.out_dir)
        lowest = min(p.getAABB(own.body, i, physicsClientId=own.cid)[0][2] for i in range(-1, p.getNumJoints(own.body, physicsClientId=own.cid)))
        z_own = own.root_pose()[0][2]
        own.close()
        mine = asset2sim.load_pybullet(stapler.out_dir, cid, ground=False)
        assert p.getNumBodies(physicsClientId=cid) == 1  # no plane added to the caller's world
        assert mine.root_pose()[0][2] == pytest.approx(z_own, abs=1e-9)
        assert lowest == pytest.approx(-0.0, abs=0.02)
        mine.close()
    finally:
        p.disconnect(cid)


def test_load_mujoco_has_the_spring_and_the_state(stapler):
    mujoco = pytest.importorskip("mujoco")
    session = asset2sim.load_mujoco(stapler.out_dir)
    try:
        jid = mujoco.mj_name2id(session.m, mujoco.mjtObj.mjOBJ_JOINT, "joint_1")
        spring = session.options.springs["joint_1"]
        assert session.m.jnt_stiffness[jid] == pytest.approx(spring.stiffness)
        assert session.joint_positions()["joint_1"] == pytest.approx(session.options.initial_state["joint_1"], abs=1e-9)
    finally:
        session.close()


def test_loaders_refuse_a_folder_that_is_not_an_output(tmp_path):
    with pytest.raises(ValueError, match=f"has no {URDF_NAME}"):
        asset2sim.load_pybullet(tmp_path)


def test_load_sapien_into_a_users_scene_gives_the_same_robust_rest_as_its_own(stapler):
    pytest.importorskip("sapien")
    from asset2sim.engines import physx_engine

    own = asset2sim.load_sapien(stapler.out_dir)
    expected = _trials(own)
    own.close()
    scene = physx_engine.new_scene()  # the checks' settings, as a user would make the scene
    session = asset2sim.load_sapien(stapler.out_dir, scene)
    assert session.scene is scene and session.options.springs["joint_1"].stiffness > 0
    assert _trials(session) == expected
    session.close()
    assert scene.get_entities() == []  # the articulation and the plane removed, the scene kept


def _sapien_own_articulation(scene, urdf: Path):
    """``urdf`` built by SAPIEN's own URDF loader into ``scene``, root fixed, visuals left out (no render device)."""
    loader = scene.create_urdf_loader()
    loader.fixed_root_link = True
    builder = loader.load_file_as_articulation_builder(str(urdf))
    for link in builder.link_builders:
        link.visual_records = []
    return builder.build(fix_root_link=True)


def _sapien_own_lid(folder: Path, declared: bool, steps: int = 720) -> float:
    """The contract asset's lid (rad) after ``steps`` in a scene of the checks' settings, the articulation built by
    SAPIEN's own URDF loader (root fixed), given the declared physics or not."""
    from asset2sim.engines import physx_engine

    scene = physx_engine.new_scene()
    art = _sapien_own_articulation(scene, folder / URDF_NAME)
    names = [j.get_name() for j in art.get_active_joints()]
    qpos = art.get_qpos()
    qpos[names.index("lid_hinge")] = 0.6
    art.set_qpos(qpos)
    physics = asset2sim.declare_physics(art, folder) if declared else None
    for _ in range(steps):
        if physics is not None:
            physics.before_step()
        scene.step()
    return float(art.get_qpos()[names.index("lid_hinge")])


def test_declare_physics_gives_a_users_own_sapien_articulation_the_declared_friction(tmp_path):
    """SAPIEN's own URDF loader takes the lid's 0.5 N*m as PhysX's unitless coefficient and the lid, loaded by
    0.16 N*m of gravity, falls shut; one call gives the same articulation the declared friction and it stays open;
    declared 0.1 N*m, it falls as the files say."""
    pytest.importorskip("sapien")
    from tests.contract_asset import write_contract_asset

    held = write_contract_asset(tmp_path / "held", lid_angle=0.6, lid_friction=0.5, lid_damping=0.02)
    assert _sapien_own_lid(held.urdf.parent, declared=False) < 0.1
    assert _sapien_own_lid(held.urdf.parent, declared=True) == pytest.approx(0.6, abs=5e-3)
    weak = write_contract_asset(tmp_path / "weak", lid_angle=0.6, lid_friction=0.1, lid_damping=0.02)
    assert _sapien_own_lid(weak.urdf.parent, declared=True) < 0.1


def test_declare_physics_refuses_another_files_articulation(tmp_path):
    pytest.importorskip("sapien")
    from asset2sim.engines import physx_engine
    from tests.contract_asset import write_contract_asset

    a = write_contract_asset(tmp_path / "a")
    other = tmp_path / "b"
    shutil.copytree(a.urdf.parent, other)
    (other / URDF_NAME).write_text((other / URDF_NAME).read_text().replace("lid_hinge", "door_hinge"))
    scene = physx_engine.new_scene()  # kept alive while its articulation is
    art = _sapien_own_articulation(scene, other / URDF_NAME)
    with pytest.raises(ValueError, match="not the file's movable joints"):
        asset2sim.declare_physics(art, a.urdf.parent)
