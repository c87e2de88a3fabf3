"""Fixtures are mounted: a tall, thin faucet tips over when free-standing and
passes every check with its root fixed as the asset declares."""

from __future__ import annotations

import json

import pytest

from asset2sim.engines.source import UrdfFile
from asset2sim.schemas.config import RefineConfig
from asset2sim.tasks.check import postcheck
from asset2sim.refined_asset import RefinedAsset
from asset2sim.tasks.evaluation.folder_reading import sim_object
from asset2sim.tasks.assemble import write
from tests.tasks.check.failure_assets import build_tall_faucet


@pytest.fixture()
def mounted(refine_once):
    return refine_once(build_tall_faucet, "A faucet.", extras=True)


@pytest.fixture()
def free_standing(refine_once):
    return refine_once(build_tall_faucet, "A free-standing faucet.", extras=False)


def test_mounted_fixture_passes_every_check_with_a_fixed_root(mounted):
    r = mounted.report
    assert r.failure_mode == "none"
    assert r.mounting is not None and r.mounting.fixed and r.mounting.kind == "counter-mounted"
    for m in r.metrics:
        if m.engine != "none":  # every simulated check (the request's own tier simulates nothing)
            assert m.details.get("root") == "fixed (mounted)", m.name
    assert any(n.startswith("root: mounted (counter-mounted)") for n in r.notes)


def test_mounted_output_declares_the_root(mounted):
    out = mounted.out_dir
    state = json.loads((out / "initial_state.json").read_text())
    assert state["root"]["fixed"] is True and state["root"]["mounting"] == "counter-mounted"
    assert state["root"]["pose"] == {"xyz": [0.0, 0.0, 0.0], "quat_xyzw": [0.0, 0.0, 0.0, 1.0]}
    assert "Mounted (counter-mounted)" in (out / "mobility.urdf").read_text()
    assert write.read_root(out).fixed


def test_mounted_mjcf_has_no_free_joint(mounted):
    pytest.importorskip("mujoco")
    xml = (mounted.out_dir / "mjcf" / "mobility.xml").read_text()
    assert "freejoint" not in xml and 'type="free"' not in xml
    assert "Mounted asset" in xml


def test_evaluation_runs_with_the_root_as_declared(mounted):
    ev = json.loads((mounted.out_dir / "evaluation.json").read_text())
    assert all(m["details"]["root"] == "fixed (mounted)" for m in ev["metrics"] if m["name"] in ("rest_stability", "state_hold"))
    obj, _ = sim_object(RefinedAsset(mounted.out_dir))
    assert obj.fixed_base
    _, run = postcheck.measure_rest_test("pybullet", obj)
    assert float(abs(run.root_series).max()) == pytest.approx(0.0, abs=1e-9)  # held at the file's origin


def test_the_same_fixture_tips_when_free_standing(free_standing):
    res = free_standing
    r = res.report
    assert r.mounting is not None and not r.mounting.fixed
    assert r.failure_mode == "unstable"
    assert r.metric("settle_tilt").passed is False and r.metric("settle_tilt").details["root"] == "free (on the ground)"
    assert json.loads((res.out_dir / "initial_state.json").read_text())["root"] == {
        "fixed": False, "mounting": "free-standing", "pose": None, "source": "request: 'free-standing' -> free-standing"}


def test_post_check_follows_the_overlay_root(mounted):
    out = mounted.out_dir
    ov = mounted.overlay
    state = json.loads((out / "initial_state.json").read_text())["initial_joint_positions"]
    fixed = postcheck.run_post_check(postcheck.overlay_object(UrdfFile(out / "mobility.urdf"), state, ov, RefineConfig().sim), RefineConfig())
    free = postcheck.run_post_check(postcheck.overlay_object(UrdfFile(out / "mobility.urdf"), state, ov.model_copy(update={"mounting": None}),
                                                             RefineConfig().sim), RefineConfig())
    assert fixed.stable and fixed.recording.fixed_base
    assert not free.stable and not free.recording.fixed_base


def test_mjcf_check_refuses_a_free_joint_on_a_mounted_asset(free_standing, tmp_path):
    pytest.importorskip("mujoco")
    from asset2sim.formats.mjcf.export import ExportError, check_mjcf, export_mjcf

    out = free_standing.copy_to(tmp_path / "free")  # the export writes into the folder
    xml = export_mjcf(out)
    assert "freejoint" in xml.read_text() or 'type="free"' in xml.read_text()
    state = json.loads((out / "initial_state.json").read_text())["initial_joint_positions"]
    check_mjcf(xml, out / "mobility.urdf", state)  # free asset: fine
    with pytest.raises(ExportError, match="free joint"):
        check_mjcf(xml, out / "mobility.urdf", state, fixed_base=True)
