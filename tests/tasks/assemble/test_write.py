"""Writer: output contract on generated assets (scale baked in, inertials,
dynamics, relative mesh paths, atomic files, input untouched)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from asset2sim import demo_assets
from asset2sim.engines.base import SessionOptions
from asset2sim.engines.registry import open_session
from asset2sim.schemas.overlay import EstimatorInfo, JointDynamics, Overlay
from asset2sim.tasks.geometry.analyze import analyze_asset
from asset2sim.tasks.ingest.extract import extract_asset
from asset2sim.tasks.synthesize.validate_overlay import inertia_problems, validate_overlay
from asset2sim.tasks.assemble.write import OutputError, build_urdf, write_output
from tests.helpers import tree_hashes


def _overlay(asset, geometry, scale):
    ov = Overlay(
        estimator=EstimatorInfo(name="test"),
        scale=scale,
        joints={j.name: JointDynamics(damping=0.1 + i, friction=0.01 * (i + 1)) for i, j in enumerate(asset.movable_joints())},
    )
    filled, _ = validate_overlay(ov, asset, geometry)  # fills every link from geometry
    return filled


@pytest.fixture()
def cabinet(tmp_path):
    src = demo_assets.build_two_drawer_cabinet(tmp_path / "cabinet")
    asset = extract_asset(src)
    return asset, analyze_asset(asset)


def _extent(folder):
    from asset2sim.tasks.geometry.closed_state import object_extents

    asset = extract_asset(folder)
    s = open_session("pybullet", asset.urdf_path, SessionOptions(fixed_base=True, gravity=False, ground=False))
    try:
        return object_extents(s, {}, asset), s.joint_limits
    finally:
        s.close()


def test_scale_is_baked_in_and_loads_at_scale_one(cabinet, tmp_path):
    asset, geometry = cabinet
    s = 0.37
    ov = _overlay(asset, geometry, s)
    out = write_output(asset, ov, tmp_path / "out", {"joint_0": 0.0, "joint_1": 0.05})
    ext_in, lim_in = _extent(asset.source_dir)
    ext_out, lim_out = _extent(out.root)
    assert np.allclose(ext_out, ext_in * s, rtol=1e-6)  # Bullet keeps link poses in float32
    for name, (lo, hi) in lim_in.items():
        assert lim_out[name][0] == pytest.approx(lo * s)
        assert lim_out[name][1] == pytest.approx(hi * s)


def test_every_link_with_geometry_has_inertial_and_joints_dynamics(cabinet, tmp_path):
    import yourdfpy

    asset, geometry = cabinet
    ov = _overlay(asset, geometry, 0.5)
    out = write_output(asset, ov, tmp_path / "out", {})
    model = yourdfpy.URDF.load(str(out.urdf), build_scene_graph=False, load_meshes=False)
    for link in model.robot.links:
        if link.visuals or link.collisions:
            assert link.inertial is not None and link.inertial.mass > 0
            assert inertia_problems(link.inertial.inertia) is None
            assert link.inertial.mass == ov.links[link.name].mass  # full precision round trip
    for joint in model.robot.joints:
        if joint.type in ("revolute", "prismatic", "continuous"):
            assert joint.dynamics is not None
            assert float(joint.dynamics.damping) == ov.joints[joint.name].damping
            assert float(joint.dynamics.friction) == ov.joints[joint.name].friction
    text = out.urdf.read_text()
    assert "initial_state.json" in text and "overlay.json" in text


def test_mesh_paths_relative_inside_output_and_copied(cabinet, tmp_path):
    asset, geometry = cabinet
    out = write_output(asset, _overlay(asset, geometry, 0.5), tmp_path / "out", {})
    fresh = extract_asset(out.root)
    for ln in fresh.links:
        for g in ln.visuals + ln.collisions:
            if g.kind == "mesh":
                assert not g.filename.startswith("/") and ".." not in g.filename
                assert g.path.is_file() and out.root.resolve() in g.path.resolve().parents


def test_state_and_overlay_json_written(cabinet, tmp_path):
    asset, geometry = cabinet
    ov = _overlay(asset, geometry, 0.5)
    out = write_output(asset, ov, tmp_path / "out", {"joint_0": 0.01})
    assert json.loads(out.initial_state.read_text()) == {
        "initial_joint_positions": {"joint_0": 0.01},
        # the root declaration: no mounting in the overlay -> free-standing
        "root": {"fixed": False, "mounting": "free-standing", "pose": None, "source": ""},
    }
    back = Overlay.model_validate_json(out.overlay.read_text())
    assert back == ov


def test_input_never_written_and_output_inside_input_refused(cabinet, tmp_path):
    asset, geometry = cabinet
    before = tree_hashes(asset.source_dir)
    ov = _overlay(asset, geometry, 0.5)
    write_output(asset, ov, tmp_path / "out", {})
    assert tree_hashes(asset.source_dir) == before
    with pytest.raises(OutputError):
        write_output(asset, ov, asset.source_dir, {})
    with pytest.raises(OutputError):
        write_output(asset, ov, asset.source_dir / "sub", {})
    assert tree_hashes(asset.source_dir) == before


def test_incomplete_overlay_refused(cabinet):
    asset, geometry = cabinet
    ov = _overlay(asset, geometry, 0.5)
    ov.joints.pop("joint_0")
    with pytest.raises(OutputError, match="joint_0"):
        build_urdf(asset, ov)


def test_no_temporary_files_left(cabinet, tmp_path):
    asset, geometry = cabinet
    out = write_output(asset, _overlay(asset, geometry, 0.5), tmp_path / "out", {})
    assert not [p for p in out.root.rglob("*") if p.name.endswith(".tmp")]
    assert math.isfinite(json.loads(out.overlay.read_text())["scale"])


def test_mesh_reached_through_a_symlink_keeps_its_material(tmp_path):
    """The URDF names ``textured_objs/a.obj``, a symlink to
    ``meshes/base.obj`` whose ``mtllib base.mtl`` (and its texture) lie beside
    the real file. The output's copy at ``textured_objs/a.obj`` finds its MTL
    and texture as written (before: the MTL was not copied, no warning);
    validate says where the input's material is (info), and an edit of that
    MTL changes the input hash."""
    from asset2sim import mesh_io
    from asset2sim.tasks.ingest.validate_input import validate_asset
    from asset2sim.tasks.assemble import copied_meshes
    from tests import corpus_builder as cb

    src = cb.build_valid(tmp_path / "in")
    (src / "textured_objs").mkdir()
    (src / "textured_objs" / "a.obj").symlink_to("../meshes/base.obj")
    urdf = src / "mobility.urdf"
    urdf.write_text(urdf.read_text().replace('"meshes/base.obj"', '"textured_objs/a.obj"'))
    assert not mesh_io.obj_material_files(src / "textured_objs" / "a.obj")  # the input's loaders miss it
    found = validate_asset(src)
    assert not [f.describe() for f in found if f.severity == "error"]
    (hint,) = [f for f in found if f.code == "MESH_MATERIAL_BESIDE_TARGET"]
    assert hint.severity == "info" and "textured_objs" in hint.message and "meshes/base.mtl" in hint.message
    asset = extract_asset(src)
    out = tmp_path / "out"
    copied_meshes.copy_meshes(asset, out)
    obj = out / "textured_objs" / "a.obj"
    assert obj.is_file() and not obj.is_symlink()
    deps = mesh_io.obj_material_files(obj)  # as a loader of the output looks for them
    assert [p.relative_to(out.resolve()).as_posix() for p in deps] == ["textured_objs/base.mtl", "images/tex.png"]
    assert deps[0].read_bytes() == (src / "meshes" / "base.mtl").read_bytes()
    assert deps[1].read_bytes() == (src / "images" / "tex.png").read_bytes()
    h0 = asset.input_hash
    (src / "meshes" / "base.mtl").write_text(cb.MTL + "Ks 0.1 0.1 0.1\n")
    assert extract_asset(src).input_hash != h0, "the MTL beside the real file is part of the input"
