"""Joint sweep on generated assets built to pass and to fail it, in every installed engine."""

from __future__ import annotations

import pytest

from asset2sim.engines.base import available_engines
from asset2sim.engines.fake import write_contract_asset
from asset2sim.tasks.check.sweep import joint_subtrees, run_sweep, sweep_metric
from asset2sim.urdf import read_urdf

# closed ends of the contract asset (lid hinge 0..2 rad, post 0..0.05 m; 0 closed)
CLOSED = {"lid_hinge": (0.0, 1.0, 2.0), "post_slide": (0.0, 1.0, 0.05)}
ENGINES = [e for e in ("pybullet", "physx", "mujoco") if e in available_engines()]


@pytest.mark.parametrize("engine", ENGINES)
def test_free_lid_and_post_sweep_through_their_ranges(tmp_path, engine):
    a = write_contract_asset(tmp_path, lid_angle=0.4, post_height=0.0)
    run = run_sweep(engine, a.urdf, CLOSED, {"lid_hinge": 0.4, "post_slide": 0.0})
    m = sweep_metric(run)
    assert m.passed, m.details["failures"]
    for j in run.joints:
        assert j.reached_open >= 0.95 and j.reached_closed <= 0.05
        assert j.max_penetration < 0.005


@pytest.mark.parametrize("engine", ENGINES)
def test_a_post_in_the_way_keeps_the_lid_from_shutting(tmp_path, engine):
    """The raised post pokes into the closed lid: the lid cannot be driven
    shut without pushing into it (blocked, or > 5 mm self-penetration)."""
    a = write_contract_asset(tmp_path, lid_angle=0.4, post_height=0.03)
    run = run_sweep(engine, a.urdf, CLOSED, {"lid_hinge": 0.4, "post_slide": 0.03})
    m = sweep_metric(run)
    assert m.passed is False
    assert "lid_hinge" in m.details["failing"]
    lid = m.details["joints"]["lid_hinge"]
    assert lid["reached_closed"] > 0.05 or lid["max_penetration"] >= 0.005


def test_a_joint_limit_beyond_the_geometry_fails(tmp_path):
    """The post's limit (5 cm) runs into the closed lid, held by its friction
    (a stiff hinge): the far end is not reached without pushing into the lid."""
    a = write_contract_asset(tmp_path, lid_angle=0.0, post_height=0.0, lid_friction=50.0)
    run = run_sweep("pybullet", a.urdf, {"post_slide": (0.0, 1.0, 0.05)}, {"lid_hinge": 0.0, "post_slide": 0.0})
    post = run.joints[0]
    assert not post.passed and (post.reached_open < 0.95 or post.max_penetration >= 0.005)


def test_subtrees_follow_the_kinematic_tree(tmp_path):
    a = write_contract_asset(tmp_path)
    sub = joint_subtrees(read_urdf(a.urdf))
    assert sub == {"lid_hinge": ["lid"], "post_slide": ["post"]}


def test_metric_without_joints_is_not_graded(tmp_path):
    a = write_contract_asset(tmp_path)
    run = run_sweep("pybullet", a.urdf, {}, {})
    assert sweep_metric(run).passed is None
