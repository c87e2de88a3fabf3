"""Joint sweep on generated assets built to pass and to fail it, in every installed engine."""

from __future__ import annotations

import pytest

from asset2sim.engines.base import available_engines
from asset2sim.engines.fake import write_contract_asset
from asset2sim.tasks.check.sweep import SweepConfig, blocked_positions, joint_subtrees, run_sweep, sweep_metric, sweep_score
from asset2sim.urdf import read_urdf

# closed ends of the contract asset (lid hinge 0..2 rad, post 0..0.05 m; 0 closed)
CLOSED = {"lid_hinge": (0.0, 1.0, 2.0), "post_slide": (0.0, 1.0, 0.05)}
ENGINES = [e for e in ("pybullet", "physx", "mujoco") if e in available_engines()]


@pytest.mark.parametrize("engine", ENGINES)
def test_free_lid_and_post_sweep_through_their_ranges(tmp_path, engine):
    """The lid is held at 1 rad while the post is swept (the other joints are
    held): the raised post clears it (at 0.4 rad it would touch the lid at
    about 4.9 cm, see test_a_held_lid_cuts_the_post_range)."""
    a = write_contract_asset(tmp_path, lid_angle=1.0, post_height=0.0)
    run = run_sweep(engine, a.urdf, CLOSED, {"lid_hinge": 1.0, "post_slide": 0.0})
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


def test_a_held_part_in_the_way_cuts_the_range_only_when_held(tmp_path):
    """The post's limit (5 cm) runs into the closed lid. With the other
    joints held (the definition) the lid is a part in the way in this state,
    not a defect of the post: its range is cut where it meets the lid (about
    8.6 mm, said in ``range_note``) and the sweep passes. Left passive
    (``hold_others=False``) the lid, held by its friction (a stiff hinge),
    keeps the post from its far end: it fails."""
    a = write_contract_asset(tmp_path, lid_angle=0.0, post_height=0.0, lid_friction=50.0)
    state = {"lid_hinge": 0.0, "post_slide": 0.0}
    post = run_sweep("pybullet", a.urdf, {"post_slide": (0.0, 1.0, 0.05)}, state).joints[0]
    assert post.passed and 0.0 < post.q_far < 0.02 and "lid" in post.range_note
    passive = run_sweep("pybullet", a.urdf, {"post_slide": (0.0, 1.0, 0.05)}, state, config=SweepConfig(hold_others=False)).joints[0]
    assert not passive.passed and (passive.reached_open < 0.95 or passive.max_penetration >= 0.005)


def test_subtrees_follow_the_kinematic_tree(tmp_path):
    a = write_contract_asset(tmp_path)
    sub = joint_subtrees(read_urdf(a.urdf))
    assert sub == {"lid_hinge": ["lid"], "post_slide": ["post"]}


def test_metric_without_joints_is_not_graded(tmp_path):
    a = write_contract_asset(tmp_path)
    run = run_sweep("pybullet", a.urdf, {}, {})
    assert sweep_metric(run).passed is None


def test_a_held_lid_cuts_the_post_range(tmp_path):
    """The other joints are held while one is swept: a light, free-swinging
    lid at 0.4 rad no longer yields to the post, which touches it just below
    its 5 cm limit; the range is cut there (4.6-4.9 cm) and the sweep passes;
    left passive (``hold_others=False``) the lid is pushed away."""
    a = write_contract_asset(tmp_path, lid_angle=0.4, post_height=0.0)
    state = {"lid_hinge": 0.4, "post_slide": 0.0}
    post = {"post_slide": CLOSED["post_slide"]}
    held = run_sweep("pybullet", a.urdf, post, state).joints[0]
    assert held.passed and 0.045 < held.q_far < 0.0495 and "lid" in held.range_note
    free = run_sweep("pybullet", a.urdf, post, state, config=SweepConfig(hold_others=False)).joints[0]
    assert free.passed and free.q_far == 0.05 and free.range_note == ""


def test_blocked_positions_and_score_of_a_blocked_post(tmp_path):
    """The post, the stiff closed lid passive, stops short: blocked_positions
    names where (inside its range, below the 5 cm limit); a passing run
    scores better than the blocked one."""
    a = write_contract_asset(tmp_path, lid_angle=0.0, post_height=0.0, lid_friction=50.0)
    state = {"lid_hinge": 0.0, "post_slide": 0.0}
    blocked = sweep_metric(run_sweep("pybullet", a.urdf, {"post_slide": (0.0, 1.0, 0.05)}, state, config=SweepConfig(hold_others=False)))
    where = blocked_positions(blocked)
    assert set(where) == {"post_slide"} and 0.0 <= where["post_slide"] < 0.95 * 0.05
    free = sweep_metric(run_sweep("pybullet", a.urdf, {"lid_hinge": (0.0, 1.0, 2.0)}, state))
    assert free.passed and blocked_positions(free) == {}
    assert sweep_score(free) < sweep_score(blocked)
