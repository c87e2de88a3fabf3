"""Typed overrides (``--mass 12kg``, ``--state lid=30deg`` ...): parsed with
their units, checked against the asset, merged into the request so they win
over its words; through the API, the command line and a configuration file."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import pytest
from pydantic import ValidationError

import asset2sim
from asset2sim.schemas.config import RefineConfig
from asset2sim.schemas.request import RequestOverrides, StateOverride
from asset2sim.tasks.ingest.extract import extract_asset
from asset2sim.tasks.interpret.mounting import resolve_mounting
from asset2sim.tasks.interpret.overrides import OverrideError, apply_overrides
from asset2sim.tasks.interpret.request import parse_request

BIN = Path(sys.executable).parent


@pytest.mark.parametrize("text,kind,value", [
    ("30deg", "angle", math.radians(30)), ("30 °", "angle", math.radians(30)), ("0.5rad", "angle", 0.5),
    ("2cm", "distance", 0.02), ("15 mm", "distance", 0.015), ("0.1m", "distance", 0.1), ("0.4", "fraction", 0.4),
    (0.25, "fraction", 0.25), ("halfway", "band", None), ("slightly-open", "band", None), ("open", "band", None),
])
def test_a_state_is_read_with_its_unit(text, kind, value):
    st = StateOverride.parse(text)
    assert st.kind == kind
    if value is not None:
        assert st.value == pytest.approx(value)


@pytest.mark.parametrize("text,message", [
    ("30", "unit missing"), ("2 ft", "unknown unit 'ft'"), ("-0.2", "negative"), ("ajar", "neither a band"),
])
def test_a_bad_state_says_what_is_wrong(text, message):
    with pytest.raises(ValueError, match=message):
        StateOverride.parse(text, "state lid")


def test_mass_and_size_carry_units_and_plain_numbers_are_si():
    ov = RequestOverrides(mass="500 g", size="30cm")
    assert ov.mass == pytest.approx(0.5) and ov.size == pytest.approx(0.3)
    assert RequestOverrides(mass=12, size=0.5).mass == 12.0
    for bad, msg in ((dict(mass="12"), "unit missing"), (dict(size="2 ft"), "unknown unit"), (dict(mass=-1), "greater than 0"),
                     (dict(mount="wall"), "'fixed' or 'free'"), (dict(colour="red"), "Extra inputs")):
        with pytest.raises(ValidationError, match=msg):
            RequestOverrides(**bad)
    assert not RequestOverrides() and RequestOverrides(scale=2).given() == ["--scale 2"]


@pytest.fixture(scope="module")
def stapler(shared_dataset):
    return extract_asset(shared_dataset / "103275")


def test_overrides_win_over_the_words(stapler):
    spec = parse_request("a heavy 2 kg stapler, 30 cm long, fully open")
    ov = RequestOverrides(mass="0.6kg", size="0.2m", state={"joint_1": "20deg"}, mount="fixed", material="steel_sheet")
    out = apply_overrides(spec, ov, stapler)
    masses = [p.mass for p in out.properties if p.label is None and p.mass is not None]
    assert masses == [0.6] and out.mass_level is None
    assert [p.material for p in out.properties if p.label is None and p.material] == ["steel_sheet"]
    assert [(s.dimension, s.value) for s in out.sizes] == [("largest", 0.2)]
    last = out.joint_states[-1]
    assert (last.selector, last.joint, last.target.kind) == ("joint", "joint_1", "angle")
    assert last.target.value == pytest.approx(math.radians(20))
    assert out.mount == "fixed" and "--mass 0.6 kg" in out.overrides and "--state joint_1=20deg" in out.overrides
    assert spec.properties != out.properties  # the input spec is not changed
    scaled = apply_overrides(spec, RequestOverrides(scale=1.5, size=0.2), stapler)
    assert scaled.scale == 1.5 and scaled.sizes == []  # scale wins over size
    by_label = apply_overrides(spec, RequestOverrides(state={"lid": 0.3}), stapler).joint_states[-1]
    assert (by_label.selector, by_label.label, by_label.target.kind, by_label.band) == ("label", "lid", "fraction", "quarter")


def test_an_override_that_does_not_fit_the_asset_is_refused(stapler, demo_root):
    spec = parse_request("")
    with pytest.raises(OverrideError, match=r"no movable joint or part named 'drawer' \(joints: joint_0, joint_1; parts: lid, stapler_body\)") as exc:
        apply_overrides(spec, RequestOverrides(state={"drawer": 0.5}), stapler)
    assert exc.value.code == "OVERRIDE_UNKNOWN_JOINT"
    with pytest.raises(OverrideError, match="beyond joint 'joint_1'") as exc:
        apply_overrides(spec, RequestOverrides(state={"joint_1": "400deg"}), stapler)
    assert exc.value.code == "OVERRIDE_OUT_OF_LIMITS"
    with pytest.raises(OverrideError, match="is revolute: give an angle") as exc:
        apply_overrides(spec, RequestOverrides(state={"lid": "2cm"}), stapler)
    assert exc.value.code == "OVERRIDE_WRONG_KIND"
    cabinet = extract_asset(demo_root / "cabinet_2drawer")
    with pytest.raises(OverrideError, match="is prismatic: give a distance"):
        apply_overrides(spec, RequestOverrides(state={"drawer": "30deg"}), cabinet)
    with pytest.raises(OverrideError, match="not a known material") as exc:
        apply_overrides(spec, RequestOverrides(material="unobtainium"), stapler)
    assert exc.value.code == "OVERRIDE_UNKNOWN_MATERIAL"


def test_mount_override_wins_over_words_and_prior():
    assert resolve_mounting("Faucet", "a faucet", "free").fixed is False
    fixed = resolve_mounting("Stapler", "a free-standing stapler", "fixed")
    assert fixed.fixed and "given by the user" in fixed.source
    assert resolve_mounting("Faucet", "a faucet", None).fixed  # the prior when no override


def test_refine_applies_overrides_through_the_api(shared_dataset, tmp_path):
    r = asset2sim.refine(shared_dataset / "103275", "a slightly open stapler", tmp_path / "out", extras=False,
                         overrides={"mass": "0.6kg", "scale": 1.5, "mount": "fixed", "state": {"joint_1": "20deg"}})
    assert r.overlay.scale == pytest.approx(1.5, rel=1e-12)
    assert r.overlay.total_mass() == pytest.approx(0.6, rel=0.05)
    state = json.loads((r.out_dir / "initial_state.json").read_text())
    assert state["root"]["fixed"] is True and "given by the user" in state["root"]["source"]
    assert {"given by the user: --mass 0.6 kg", "given by the user: --scale 1.5", "given by the user: --mount fixed",
            "given by the user: --state joint_1=20deg"} <= set(r.report.request.asked)
    [angle] = [q for q in r.report.request.quantities if q.phrase == "--state joint_1=20deg"]
    assert angle.asked == pytest.approx(math.radians(20)) and angle.unit == "rad"
    with pytest.raises(asset2sim.RefineError, match="no movable joint or part named 'door'") as exc:
        asset2sim.refine(shared_dataset / "103275", "", tmp_path / "bad", overrides={"state": {"door": "halfway"}})
    assert exc.value.codes == ["OVERRIDE_UNKNOWN_JOINT"] and not (tmp_path / "bad").exists()
    with pytest.raises(ValueError, match="unit missing"):
        asset2sim.refine(shared_dataset / "103275", "", tmp_path / "bad", overrides={"mass": "3"})


def _cli(*args, cwd=None) -> subprocess.CompletedProcess:
    return subprocess.run([str(BIN / "asset2sim"), "refine", *map(str, args)], capture_output=True, text=True, cwd=cwd)


@pytest.mark.slow  # end to end: the command line
def test_the_command_line_and_a_config_file(demo_root, tmp_path):
    box = demo_root / "box_lid"
    cfg = tmp_path / "refine.yaml"
    cfg.write_text("overrides:\n  mass: 3kg\n  state:\n    rotation_lid: 0.3\n")
    done = _cli(box, "-p", "a light box", "--out", tmp_path / "a", "--config", cfg, "--mass", "2kg", "--no-extras", "-q")
    assert done.returncode in (0, 3), done.stderr
    overlay = json.loads((tmp_path / "a" / "overlay.json").read_text())
    assert sum(lp["mass"] for lp in overlay["links"].values()) == pytest.approx(2.0, rel=0.05)  # the flag wins over the file
    report = json.loads((tmp_path / "a" / "report.json").read_text())
    assert "given by the user: --state rotation_lid=0.3" in report["request"]["asked"]  # the file's state kept
    for args, code, words in (
        (("--mass", "12"), "OVERRIDE_INVALID", "unit missing"),
        (("--state", "joint_0"), "OVERRIDE_INVALID", "write NAME=VALUE"),
        (("--state", "door=0.5"), "OVERRIDE_UNKNOWN_JOINT", "no movable joint or part named 'door'"),
        (("--config", tmp_path / "missing.yaml"), "CONFIG_INVALID", "missing.yaml"),
    ):
        bad = _cli(box, "--out", tmp_path / "b", *args)
        assert bad.returncode == 2, (args, bad.stderr)
        assert code in bad.stderr and words in bad.stderr, bad.stderr
        assert not (tmp_path / "b").exists()
    assert RefineConfig(overrides={"mass": "3kg"}).config_hash() != RefineConfig().config_hash()


def test_a_number_without_a_unit_is_suggested_with_plausible_units():
    """``--size 30`` is 30 cm or 30 mm, not 30 m; ``--mass 5000`` is 5000 g (a number given as a number is SI)."""
    with pytest.raises(ValidationError) as size:
        RequestOverrides(size="30")
    assert "30cm (0.3 m) or 30mm (0.03 m)" in str(size.value) and "30m " not in str(size.value)
    with pytest.raises(ValidationError) as mass:
        RequestOverrides(mass="5000")
    assert "5000g (5 kg)" in str(mass.value) and "5000kg" not in str(mass.value)
    assert RequestOverrides(size=30).size == 30.0
