"""Operable friction: escalation holds a state through robust rest only with
friction the probe can still overcome (tasks/check/operating.py), on the
generated demo laptop whose screen needs escalation to hold through a 2 cm
drop."""

from __future__ import annotations

import json

import numpy as np
import pytest

from asset2sim import demo_assets
from asset2sim.tasks.check import operating
from asset2sim.tasks.check.probes import ProbeConfig
from asset2sim.tasks.geometry.analyze import analyze_asset
from asset2sim.tasks.ingest.extract import extract_asset
from asset2sim.tasks.refine import refine_asset


@pytest.fixture(scope="module")
def laptop(tmp_path_factory):
    src = demo_assets.build_laptop(tmp_path_factory.mktemp("src") / "laptop")
    out = tmp_path_factory.mktemp("out") / "laptop"
    res = refine_asset(src, "I want a slightly open laptop. Low damping for smooth operation.", out, extras=False)
    return src, out, res


def test_push_lever_is_the_far_corner_and_the_cap_leaves_the_probe_a_margin(laptop):
    src, _, res = laptop
    asset = extract_asset(src)
    geometry = analyze_asset(asset)
    ov = res.overlay
    (name,) = [j.name for j in asset.movable_joints()]
    child = geometry[asset.joint(name).child]
    corners = np.array([[x, y, z] for x in (child.bbox_min[0], child.bbox_max[0])
                        for y in (child.bbox_min[1], child.bbox_max[1]) for z in (child.bbox_min[2], child.bbox_max[2])])
    a = np.asarray(asset.joint(name).axis, float)
    far = np.linalg.norm(corners - np.outer(corners @ a, a), axis=1).max() * ov.scale
    assert operating.push_lever(ov, asset, name, geometry) == pytest.approx(far)
    total = sum(lp.mass for lp in ov.links.values())
    f_max = max(ProbeConfig().min_force, ProbeConfig().force_factor * total * operating.GRAVITY)
    assert operating.operating_effort(ov, asset, name, geometry) == pytest.approx(f_max * far)
    cap = operating.friction_caps(ov, ov, asset, geometry)[name]
    load = ov.links[asset.joint(name).child].mass * operating.GRAVITY * operating.com_lever(ov, asset, name)
    assert cap == pytest.approx(max(operating.OPERABLE_SHARE * f_max * far - load, ov.joints[name].friction))
    # the cap never lowers a friction that is already above it
    assert operating.friction_caps(ov, ov.model_copy(update={"joints": {name: ov.joints[name].model_copy(
        update={"friction": 10 * cap})}}), asset, geometry)[name] == pytest.approx(10 * cap)


def test_escalated_laptop_holds_through_robust_rest_and_still_opens(laptop):
    src, out, res = laptop
    asset = extract_asset(src)
    geometry = analyze_asset(asset)
    (name,) = [j.name for j in asset.movable_joints()]
    report = json.loads((out / "report.json").read_text())
    assert len(report["escalation"]) > 1, "the screen needs escalation to hold through the drop"
    cap = operating.friction_caps(res.overlay, res.overlay, asset, geometry)[name]
    assert res.overlay.joints[name].friction <= cap * (1 + 1e-9)
    tiers = {m["name"]: m["passed"] for m in report["metrics"]}
    assert tiers["robust_rest"] is True and tiers["joint_sweep"] is True
    assert report["failure_mode"] == "none", report["readiness"]


def test_tilt_floor_adds_the_tilts_gravity_load(laptop, tmp_path):
    src, _, res = laptop
    asset = extract_asset(src)
    ov = res.overlay
    (name,) = [j.name for j in asset.movable_joints()]
    tilt = np.radians(5.0)
    m = ov.links[asset.joint(name).child].mass
    want = ov.joints[name].friction + operating.TILT_MARGIN * m * operating.GRAVITY * operating.com_lever(ov, asset, name) * np.sin(tilt)
    assert operating.tilt_floors(ov, ov, asset, tilt)[name] == pytest.approx(want)
    assert operating.tilt_floors(ov, ov, asset, 0.0)[name] == pytest.approx(ov.joints[name].friction)
    # a sliding drawer: its weight times sin(tilt), whatever its lever
    cab = demo_assets.build_two_drawer_cabinet(tmp_path / "cab")
    cres = refine_asset(cab, "A small two-drawer cabinet with both drawers closed.", tmp_path / "out", extras=False)
    casset = extract_asset(cab)
    floors = operating.tilt_floors(cres.overlay, cres.overlay, casset, tilt)
    for j in casset.movable_joints():
        assert j.type == "prismatic"
        mass = cres.overlay.links[j.child].mass
        assert floors[j.name] == pytest.approx(cres.overlay.joints[j.name].friction
                                               + operating.TILT_MARGIN * mass * operating.GRAVITY * np.sin(tilt))
