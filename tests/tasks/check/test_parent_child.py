"""Refine's post-check measures parent-child penetration with the pair
collided (the pairs the self-contact Phi skips), in the engine's own query,
and grades it by its depth beyond the modelled pose, as the readiness verdict
does: refine, evaluate and audit tell one story about one penetration."""

from __future__ import annotations

import pytest

from asset2sim.engines.source import UrdfFile
from asset2sim.schemas.config import RefineConfig
from asset2sim.tasks.check import postcheck
from asset2sim.tasks.check.parent_child import parent_child_penetration
from asset2sim.tasks.check.verdict import readiness
from asset2sim.schemas.overlay import EstimatorInfo, JointDynamics, Overlay
from asset2sim.tasks.geometry.analyze import analyze_asset
from asset2sim.tasks.ingest.extract import extract_asset
from asset2sim.tasks.assemble.write import write_output
from asset2sim.tasks.synthesize.validate_overlay import validate_overlay
from tests.tasks.assemble.test_collision_geometry import _asset, _box


def _nested(tmp_path):
    """A body (slab + thin post) and a lid whose hull holds the post 20 mm deep."""
    slab, post = _box([0, 0, 0], [0.1, 0.1, 0.01]), _box([0.045, 0.045, 0.01], [0.055, 0.055, 0.04])
    return _asset(tmp_path, [slab, post], [_box([0.02, 0.02, 0.02], [0.08, 0.08, 0.05])])


@pytest.mark.parametrize("engine", ["pybullet", "mujoco"])
def test_input_nested_in_its_parent_reads_its_depth(tmp_path, engine):
    if engine == "mujoco":
        pytest.importorskip("mujoco")
    m = parent_child_penetration(UrdfFile(_nested(tmp_path) / "mobility.urdf"), {"hinge": 0.0}, engine)
    assert m.value == pytest.approx(20.0, abs=0.05)  # the post's top 20 mm into the lid's hull, margins removed
    assert m.details["pairs"] == {"body/lid": m.value}
    assert m.engine == engine
    assert m.details["modelled"] == m.details["pairs"] and m.details["beyond_modelled_mm"] == 0.0  # at 0, as modelled
    assert m.passed is True  # drawn inside its parent, as robosuite draws a latch inside its door: as the asset says


def test_a_lid_swung_into_a_bar_of_its_body_reads_its_depth_beyond_the_modelled_pose(tmp_path):
    """A lid clear of a bar of its body as modelled (20 mm below it), swung
    0.5 rad up into it: all of its depth is beyond the modelled pose; the
    nested lid opened 0.3 rad is shallower than as modelled (nothing beyond)."""
    slab, bar = _box([0, 0, 0], [0.1, 0.1, 0.01]), _box([0.0, 0.0, 0.07], [0.1, 0.06, 0.09])
    barred = _asset(tmp_path / "barred", [slab, bar], [_box([0.02, 0.02, 0.02], [0.08, 0.08, 0.05])])
    m = parent_child_penetration(UrdfFile(barred / "mobility.urdf"), {"hinge": 0.5})
    assert m.value > 10.0 and m.details["modelled"] == {} and m.details["beyond_modelled_mm"] == m.value
    assert m.passed is False and readiness([m]).tiers["penetration"] is False  # the metric and the verdict agree
    m = parent_child_penetration(UrdfFile(_nested(tmp_path / "nested") / "mobility.urdf"), {"hinge": 0.3})
    assert 0.0 < m.value < 20.0 and m.details["beyond_modelled_mm"] == 0.0


def test_post_check_reports_the_metric_on_the_written_output(tmp_path):
    asset = extract_asset(_nested(tmp_path))
    ov = Overlay(estimator=EstimatorInfo(name="test"), scale=1.0,
                 joints={j.name: JointDynamics(damping=0.1, friction=0.01) for j in asset.movable_joints()})
    ov, _ = validate_overlay(ov, asset, analyze_asset(asset))
    out = write_output(asset, ov, tmp_path / "out", {"hinge": 0.0})
    check = postcheck.run_post_check(postcheck.overlay_object(UrdfFile(out.urdf), {"hinge": 0.0}, ov, RefineConfig().sim),
                                     RefineConfig(engines=["pybullet"]))
    m = check.metric("parent_child_penetration")
    assert m.passed and m.value <= 2.0
