"""Overlay validation: every SPEC rule yields its named issue, fixes are reported."""

from __future__ import annotations

import numpy as np
import pytest

from asset2sim import demo_assets
from asset2sim.schemas.overlay import EstimatorInfo, Inertia, JointDynamics, LinkPhysics, Overlay
from asset2sim.tasks.geometry.analyze import analyze_asset
from asset2sim.tasks.ingest.extract import extract_asset
from asset2sim.tasks.synthesize.validate_overlay import (
    OverlayInvalid,
    inertia_problems,
    validate_overlay,
)


@pytest.fixture(scope="module")
def box(tmp_path_factory):
    src = demo_assets.build_box_with_lid(tmp_path_factory.mktemp("v") / "box")
    asset = extract_asset(src)
    return asset, analyze_asset(asset)


def _good(asset, geometry, scale=0.3):
    ov = Overlay(estimator=EstimatorInfo(name="t"), scale=scale)
    filled, issues = validate_overlay(ov, asset, geometry)
    return filled


def codes(issues):
    return {i.code for i in issues}


def test_complete_overlay_has_no_findings(box):
    asset, geometry = box
    ov = _good(asset, geometry)
    again, issues = validate_overlay(ov, asset, geometry)
    assert issues == []
    assert again == ov


def test_missing_links_and_joints_are_filled_conservatively(box):
    asset, geometry = box
    ov, issues = validate_overlay(Overlay(estimator=EstimatorInfo(name="t"), scale=0.3), asset, geometry)
    assert {"OVL_LINK_MISSING", "OVL_JOINT_MISSING"} <= codes(issues)
    assert all(i.fixed for i in issues)
    for ln in asset.links:
        if ln.has_geometry:
            assert ov.links[ln.name].mass > 0
            assert inertia_problems(ov.links[ln.name].inertia.matrix()) is None
    for j in asset.movable_joints():
        d = ov.joints[j.name]
        assert d.damping > 0 and d.friction > 0 and d.stiffness == 0


@pytest.mark.parametrize("scale", [0.0, -1.0, 1e9])
def test_bad_scale_is_fatal(box, scale):
    asset, geometry = box
    with pytest.raises(OverlayInvalid, match="OVL_SCALE_INVALID"):
        validate_overlay(Overlay(estimator=EstimatorInfo(name="t"), scale=scale), asset, geometry)


def test_non_positive_mass_replaced_from_geometry_or_fatal(box):
    asset, geometry = box
    ov = _good(asset, geometry)
    name = next(iter(geometry))
    ov.links[name] = ov.links[name].model_copy(update={"mass": -2.0})
    fixed, issues = validate_overlay(ov, asset, geometry)
    assert "OVL_MASS_INVALID" in codes(issues) and fixed.links[name].mass > 0
    with pytest.raises(OverlayInvalid, match="OVL_MASS_INVALID"):
        validate_overlay(ov, asset, None)


@pytest.mark.parametrize(
    "inertia, why",
    [
        (Inertia(ixx=1.0, iyy=1.0, izz=3.0), "triangle"),  # 1 + 1 < 3
        (Inertia(ixx=1.0, iyy=-1.0, izz=1.0), "positive definite"),
        (Inertia(ixx=1.0, ixy=2.0, iyy=1.0, izz=1.0), "positive definite"),
    ],
)
def test_invalid_inertia_reported_with_eigenvalues_and_replaced(box, inertia, why):
    asset, geometry = box
    ov = _good(asset, geometry)
    name = next(iter(geometry))
    ov.links[name] = ov.links[name].model_copy(update={"inertia": inertia})
    fixed, issues = validate_overlay(ov, asset, geometry)
    msg = next(i.message for i in issues if i.code == "OVL_INERTIA_INVALID")
    assert why in msg and "eigenvalues" in msg
    assert inertia_problems(fixed.links[name].inertia.matrix()) is None
    assert not np.allclose(fixed.links[name].inertia.matrix(), inertia.matrix())


def test_negative_dynamics_is_fatal(box):
    asset, geometry = box
    ov = _good(asset, geometry)
    j = asset.movable_joints()[0].name
    ov.joints[j] = JointDynamics(damping=-0.1, friction=0.0)
    with pytest.raises(OverlayInvalid, match="OVL_DYNAMICS_NEGATIVE"):
        validate_overlay(ov, asset, geometry)


def test_state_outside_limits_projected_and_unknown_joint_dropped(box):
    asset, geometry = box
    ov = _good(asset, geometry)
    j = asset.movable_joints()[0]
    ov.initial_joint_positions = {j.name: j.upper + 1.0, "joint_does_not_exist": 0.2}
    fixed, issues = validate_overlay(ov, asset, geometry)
    assert fixed.initial_joint_positions == {j.name: j.upper}
    assert {"OVL_STATE_OUT_OF_LIMITS", "OVL_STATE_UNKNOWN_JOINT"} <= codes(issues)


def test_prismatic_state_compared_in_scaled_units(tmp_path):
    src = demo_assets.build_two_drawer_cabinet(tmp_path / "cab")
    asset = extract_asset(src)
    geometry = analyze_asset(asset)
    ov = _good(asset, geometry, scale=0.4)
    upper = asset.joint("joint_0").upper  # input units
    ov.initial_joint_positions = {"joint_0": upper * 0.4 * 0.5}
    _, issues = validate_overlay(ov, asset, geometry)
    assert issues == []  # inside the scaled limits
    ov.initial_joint_positions = {"joint_0": upper * 0.9}  # inside the unscaled range, outside the scaled one
    fixed, issues = validate_overlay(ov, asset, geometry)
    assert "OVL_STATE_OUT_OF_LIMITS" in codes(issues)
    assert fixed.initial_joint_positions["joint_0"] == pytest.approx(upper * 0.4)


def test_spring_without_reference_gets_one(box):
    asset, geometry = box
    ov = _good(asset, geometry)
    j = asset.movable_joints()[0].name
    ov.joints[j] = JointDynamics(damping=0.1, friction=0.0, stiffness=2.0)
    fixed, issues = validate_overlay(ov, asset, geometry)
    assert "OVL_SPRING_REFERENCE" in codes(issues)
    assert fixed.joints[j].spring_reference is not None


def test_a_preloaded_spring_may_refer_beyond_the_travel_and_a_far_one_is_pulled_back(box):
    """A balance's reference lies beyond its joint's travel (a window's sash balance: about 8 ranges from
    mid-travel) and is kept; one more than SPRING_REFERENCE_REACH ranges out is a unit or sign error, reset."""
    asset, geometry = box
    j = asset.movable_joints()[0]
    lo, hi = j.lower, j.upper
    ov = _good(asset, geometry)
    ov.joints[j.name] = JointDynamics(damping=0.1, friction=0.0, stiffness=2.0, spring_reference=hi + 8.0 * (hi - lo))
    fixed, issues = validate_overlay(ov, asset, geometry)
    assert "OVL_SPRING_REFERENCE" not in codes(issues)
    assert fixed.joints[j.name].spring_reference == pytest.approx(hi + 8.0 * (hi - lo))
    ov.joints[j.name] = JointDynamics(damping=0.1, friction=0.0, stiffness=2.0, spring_reference=hi + 11.0 * (hi - lo))
    fixed, issues = validate_overlay(ov, asset, geometry)
    assert "OVL_SPRING_REFERENCE" in codes(issues)
    assert lo <= fixed.joints[j.name].spring_reference <= hi


def test_unknown_link_is_an_error(box):
    asset, geometry = box
    ov = _good(asset, geometry)
    ov.links["ghost"] = LinkPhysics(mass=1.0, inertia=Inertia(ixx=1, iyy=1, izz=1), com=(0, 0, 0))
    with pytest.raises(OverlayInvalid, match="OVL_UNKNOWN_LINK"):
        validate_overlay(ov, asset, geometry)
    assert "ghost" in ov.links  # the input is not modified


def test_non_finite_values_rejected_by_schema():
    with pytest.raises(ValueError):
        Overlay(estimator=EstimatorInfo(name="t"), scale=float("nan"))
    with pytest.raises(ValueError):
        JointDynamics(damping=float("inf"), friction=0.0)


def test_a_raised_light_part_keeps_the_friction_that_holds_it(box):
    """The validator raises a link far lighter than its object to the mass
    floor; the friction (and damping, inertia about the axis) of the joint
    that moves it follow the part's new mass: they were derived from the
    gravity load of the lighter part, which a heavier part exceeds (a toilet's
    30 g flush lever raised to 50 g fell open against the friction set for
    30 g)."""
    asset, geometry = box
    ov = _good(asset, geometry)
    (jd,) = [j for j in asset.movable_joints() if j.child in ov.links]
    lid = jd.child
    before = ov.joints[jd.name].model_copy(update={"friction": 0.01, "damping": 0.002, "inertia_axis": 1e-5})
    ov.joints[jd.name] = before
    ov.links[lid] = ov.links[lid].model_copy(update={"mass": 5e-5})
    fixed, issues = validate_overlay(ov, asset, geometry)
    assert any(i.code == "OVL_MASS_TOO_SMALL" and i.where == lid for i in issues)
    r = fixed.links[lid].mass / 5e-5
    assert r > 10
    after = fixed.joints[jd.name]
    assert after.friction == pytest.approx(before.friction * r, rel=1e-9)
    assert after.damping == pytest.approx(before.damping * r, rel=1e-9)
    assert after.inertia_axis == pytest.approx(before.inertia_axis * r, rel=1e-9)
    assert "mass raised by the validator" in after.source
    # a link raised on a body no joint moves changes no joint
    again, _ = validate_overlay(fixed, asset, geometry)
    assert again.joints[jd.name].friction == pytest.approx(after.friction, rel=1e-12)
