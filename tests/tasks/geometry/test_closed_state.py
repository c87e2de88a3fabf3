"""Closed-state detection on generated assets with known closed ends and on real objects."""

from __future__ import annotations

import math

import numpy as np
import pytest

from asset2sim import demo_assets
from asset2sim.engines.base import SessionOptions
from asset2sim.engines.registry import open_session
from asset2sim.tasks.geometry.closed_state import closed_positions, object_extents
from asset2sim.tasks.ingest.extract import extract_asset
from asset2sim.engines.source import UrdfFile
from tests.conftest import SHARED, needs_shared


def _closed(folder):
    asset = extract_asset(folder)
    s = open_session("pybullet", asset.urdf_path, SessionOptions(fixed_base=True, gravity=False, ground=False))
    try:
        return asset, closed_positions(s, asset), s.joint_limits
    finally:
        s.close()


@pytest.mark.parametrize("entry", demo_assets.DEMO_OBJECTS, ids=lambda e: e.asset_id)
def test_closed_end_found_from_geometry(entry, demo_root):
    asset, closed, limits = _closed(demo_root / entry.asset_id)
    for joint, truth in entry.closed_positions.items():
        cs = closed[joint]
        lo, hi = limits[joint]
        tol = 0.03 * (hi - lo)
        assert abs(cs.q_closed - truth) <= tol, (entry.asset_id, joint, cs.q_closed, truth)
        # the opening side is the farther limit
        far = hi if (hi - truth) >= (truth - lo) else lo
        assert math.copysign(1.0, far - truth) == cs.direction
        assert cs.open_range == pytest.approx(abs(far - cs.q_closed), rel=1e-9)
        assert cs.fraction(cs.q_closed) == pytest.approx(0.0)
        assert cs.fraction(cs.position(0.5)) == pytest.approx(0.5)


def test_zero_pose_open_laptop_is_not_taken_as_closed(demo_root):
    # the laptop's zero pose is open by 105 degrees; closed is the lower limit
    _, closed, limits = _closed(demo_root / "laptop")
    cs = closed["joint_1"]
    assert abs(cs.q_closed - 0.0) > 1.0
    assert cs.q_closed == pytest.approx(limits["joint_1"][0], abs=0.06)


@needs_shared
@pytest.mark.parametrize(
    "obj, joint, expected",
    [
        # closed ends checked by looking at renders of each state
        ("9748", "joint_0", -2.0923),  # laptop screen modelled open at zero; closed = folded, lower limit
        ("100221", "joint_0", -1.047),  # chest lid half open at zero, closed at the lower limit
        ("101668", "joint_2", -0.785),  # briefcase lid open 45 deg at zero
        ("103755", "joint_1", -1.047),  # briefcase lid open 60 deg at zero
        ("7236", "joint_0", 0.0),  # microwave door
        ("102622", "joint_0", 0.0),  # toilet lid resting on the seat despite hull overlap
        ("102703", "joint_2", 0.0),  # toilet lid modelled slightly sloped, resting on the seat
        ("20279", "joint_0", -0.188),  # desk drawer pushed home at the lower limit
    ],
)
def test_real_objects_closed_end(obj, joint, expected):
    _, closed, _ = _closed(SHARED / obj)
    assert closed[joint].q_closed == pytest.approx(expected, abs=0.05)


def test_object_extents_closed_smaller_than_open(demo_root):
    asset = extract_asset(demo_root / "box_lid")
    s = open_session("pybullet", asset.urdf_path, SessionOptions(fixed_base=True, gravity=False, ground=False))
    try:
        closed = closed_positions(s, asset)
        e_closed = object_extents(s, {k: v.q_closed for k, v in closed.items()}, asset)
        e_open = object_extents(s, {k: v.position(1.0) for k, v in closed.items()}, asset)
    finally:
        s.close()
    assert e_closed.prod() < e_open.prod()
    assert (e_closed > 0).all()


def test_closed_ends_are_kinematic_and_follow_the_limits(tmp_path):
    """measure_closed_ends is kinematic: a rewrite of the joints' friction and
    damping only (an escalation round) measures what a fresh session does and
    what was measured before; another limit moves the closed end's range."""
    from asset2sim import urdf as urdf_mod
    from tests.contract_asset import write_contract_asset
    from asset2sim.tasks.geometry import urdf_closed

    a = write_contract_asset(tmp_path / "a", lid_angle=0.4)
    first = urdf_closed.measure_closed_ends(UrdfFile(a.urdf))
    model = urdf_mod.read_urdf(a.urdf)
    for j in model.movable_joints:
        j.dynamics = urdf_mod.UrdfDynamics(damping=3.0, friction=0.7)
    a.urdf.write_bytes(urdf_mod.write_urdf(model))
    again = urdf_closed.measure_closed_ends(UrdfFile(a.urdf))
    with urdf_closed.closed_session(UrdfFile(a.urdf)) as fresh:
        assert again.closed == fresh.closed == first.closed
    np.testing.assert_array_equal(again.extents, first.extents)
    lid = model.joint("lid_hinge")
    lid.limit.upper = 0.5 * float(lid.limit.upper)
    a.urdf.write_bytes(urdf_mod.write_urdf(model))
    shorter = urdf_closed.measure_closed_ends(UrdfFile(a.urdf))
    assert shorter.closed["lid_hinge"].upper == lid.limit.upper != first.closed["lid_hinge"].upper


def test_a_motion_that_leaves_the_object_as_compact_closes_at_the_modelled_pose(tmp_path):
    """Sashes sliding past each other in their frame: the object is as
    compact at every opening, so the geometry has no closed end and the
    limit nearest the modelled pose 0 is used (the window as modelled,
    closed), not the far limit the tie rule picked (0.5: "fully open" was
    then the modelled closed window). A lid, whose opening changes the box,
    is still found from the geometry (the other tests here)."""
    from asset2sim.tasks.geometry.urdf_closed import closed_session
    from tests.unseen_assets import build_sliding_window

    src = build_sliding_window(tmp_path / "window")
    with closed_session(UrdfFile(src / "mobility.urdf")) as m:
        for j in ("joint_0", "joint_1"):
            c = m.closed[j]
            assert (c.q_closed, c.direction) == (0.0, 1.0) and c.open_range == pytest.approx(0.5)
            assert c.compactness_ratio < 1.03 and "modelled pose" in c.notes[0]


@needs_shared
def test_suitcase_buttons_close_unpressed():
    """101668's two lock buttons (prismatic 0-12 mm into the body) change
    nothing of the suitcase's box: closed is the modelled, unpressed 0 (the
    tie rule put them 6.9 mm in)."""
    from asset2sim.tasks.geometry.urdf_closed import closed_session

    with closed_session(UrdfFile(SHARED / "101668" / "mobility.urdf")) as m:
        for j in ("joint_0", "joint_1"):
            assert m.closed[j].q_closed == 0.0 and m.closed[j].open_range == pytest.approx(0.012, abs=1e-4)
        assert m.closed["joint_2"].compactness_ratio > 1.5  # the lid: found from the geometry


@needs_shared
def test_a_model_in_memory_is_described_and_closed_as_its_file(tmp_path):
    """A refine hands its candidate's model to the closed-end measurement
    (no file read back): describe_model gives extract_asset's geometry and
    joints for the same URDF (labels aside), and the closed ends measured from
    the model equal those measured from the file, memo off."""
    from asset2sim import urdf as urdf_mod
    from asset2sim.tasks.geometry import urdf_closed
    from asset2sim.tasks.ingest.extract import describe_model

    urdf = SHARED / "101668" / "mobility.urdf"
    from_file = extract_asset(urdf)
    model = urdf_mod.read_urdf(urdf)
    described = describe_model(model)
    assert described.joints == from_file.joints and described.root_link == from_file.root_link
    assert [(ln.name, ln.visuals, ln.collisions) for ln in described.links] == \
        [(ln.name, ln.visuals, ln.collisions) for ln in from_file.links]
    with urdf_closed.closed_session(UrdfFile(urdf)) as by_file, urdf_closed.closed_session(UrdfFile(model)) as by_model:
        assert by_model.closed == by_file.closed and by_model.closed["joint_2"].open_range > 0
    nameless = urdf_mod.clone_model(model)
    nameless.path = None
    with pytest.raises(urdf_mod.UrdfError, match="no file an engine could load"):
        urdf_mod.path_of(nameless)


def test_push_buttons_close_where_they_rest_out_of_their_body(tmp_path):
    """A remote's four buttons (prismatic 0-8 mm down into its top, its own height 2.8 cm) are a sixth of the object's
    height: pressed in, the object's box is smallest, so compactness alone closed every button pressed in (a keyboard
    had every key down). A push button rests where its spring returns it, standing out of its body
    (``part_priors.push_buttons``): its closed end is the unpressed 0, and it opens (is pressed) toward 8 mm; a part of
    the same geometry that no spring returns keeps the compact end."""
    from asset2sim.tasks.geometry.urdf_closed import closed_session
    from asset2sim.tasks.interpret.part_priors import push_buttons
    from tests.unseen_assets import build_remote

    src = build_remote(tmp_path / "remote")
    asset = extract_asset(src)
    urdf = asset.urdf_path
    pushed = push_buttons(asset, "Remote")
    assert pushed == {j.name for j in asset.movable_joints()} and len(pushed) == 4
    with closed_session(UrdfFile(urdf), pushed=pushed) as m:
        rest = dict(m.closed)
    with closed_session(UrdfFile(urdf)) as m:
        compact = dict(m.closed)
    for j in pushed:
        assert rest[j].q_closed == rest[j].lower == 0.0 and rest[j].direction == 1.0 and "rests" in rest[j].notes[0]
        assert compact[j].q_closed == pytest.approx(compact[j].upper)  # the most compact end: pressed in
