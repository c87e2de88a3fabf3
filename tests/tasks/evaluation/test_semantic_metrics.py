"""Semantic-accuracy metrics: the pure definitions, and end to end on a
generated box with a lid (request parsing and category priors)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

from asset2sim.schemas.request import StateTarget
from asset2sim.tasks.evaluation import semantic_metrics as sem
from asset2sim.tasks.evaluation.evaluate import evaluate_asset

# ------------------------------------------------------------------ pure definitions


def test_scale_deviation_is_relative_to_the_reference_in_percent():
    m = sem.scale_deviation(0.13, 0.1, scale_source="overlay.json")
    assert m.value == pytest.approx(30.0) and m.unit == "%" and m.passed is None
    assert sem.scale_deviation(0.07, 0.1).value == pytest.approx(30.0)
    assert sem.scale_deviation(0.1, 0.1).value == 0.0
    assert sem.scale_deviation(0.1, None).value is None
    assert sem.scale_deviation(None, 0.1).details["reason"].startswith("scale of the evaluated")


def test_initial_joint_deviation_means_over_task_joints_and_keeps_units():
    m = sem.initial_joint_deviation({"a": 0.5, "b": 0.1}, {"a": 0.2, "b": 0.3}, ["a", "b"], {"a": "revolute", "b": "revolute"})
    assert m.value == pytest.approx((0.3 + 0.2) / 2) and m.unit == "rad"
    m = sem.initial_joint_deviation({"d": 0.05}, {"d": 0.0}, ["d", "missing"], {"d": "prismatic"})
    assert m.value == pytest.approx(0.05) and m.unit == "m" and m.details["skipped"] == ["missing"]
    assert sem.initial_joint_deviation({}, {}, ["x"], {}).value is None


def test_mass_plausibility_pass_fail_and_no_prior():
    assert sem.mass_plausibility(1.0, (0.5, 2.0)).passed is True
    assert sem.mass_plausibility(4.0, (0.5, 2.0)).passed is False
    assert sem.mass_plausibility(0.1, (0.5, 2.0)).passed is False
    m = sem.mass_plausibility(1.0, None)
    assert m.passed is None and m.value == 1.0 and m.unit == "kg"
    with pytest.raises(ValueError):
        sem.mass_plausibility(1.0, (2.0, 1.0))
    with pytest.raises(ValueError):
        sem.mass_plausibility(float("nan"), (1.0, 2.0))


@pytest.mark.parametrize("extent, score", [(0.2, 1.0), (0.29, 1.0), (0.14, 1.0), (0.40, 0.5), (0.1, 0.5), (0.5, 0.0), (0.05, 0.0)])
def test_size_score_bands(extent, score):
    # target 0.2 m (typical 0.4 m x factor 0.5): within x1.5 scores 1, within x2.25 0.5
    size = sem.size_score(extent, 0.4, 0.5)
    assert size.score == score, size.reason
    assert size.ratio == pytest.approx(extent / 0.2)
    assert size.ratio > 0 and "ratio" in size.reason


def test_size_score_rejects_bad_input():
    with pytest.raises(ValueError):
        sem.size_score(0.0, 0.3)


@pytest.mark.parametrize("fraction, band, score", [
    (0.2, "slightly_open", 1.0), (0.0, "closed", 1.0), (0.5, "halfway", 1.0), (1.0, "fully", 1.0),
    (0.40, "slightly_open", 0.5), (0.0, "slightly_open", 0.5), (0.6, "slightly_open", 0.0), (0.5, "closed", 0.0),
])
def test_band_score(fraction, band, score):
    assert sem.band_score(fraction, band)[0] == score


def test_prompt_alignment_halves_and_missing_parts():
    checks = [sem.JointStateCheck("j", "slightly_open", 0.2, "lid")]
    m = sem.prompt_alignment(size_requested=True, largest_extent=0.2, typical_largest=0.2, size_factor=1.0,
                             joint_checks=checks, state_requested=True)
    assert m.value == 1.0
    m = sem.prompt_alignment(size_requested=True, largest_extent=0.6, typical_largest=0.2, size_factor=1.0,
                             joint_checks=checks, state_requested=True)
    assert m.value == 0.5 and m.details["size"]["score"] == 0.0
    # no state asked: the size half alone
    m = sem.prompt_alignment(size_requested=False, largest_extent=0.2, typical_largest=0.2, size_factor=1.0,
                             joint_checks=[], state_requested=False)
    assert m.value == 1.0 and m.details["joint_state_score"] is None
    # a state asked for a part that does not exist is not understood for this object: listed, not counted
    m = sem.prompt_alignment(size_requested=False, largest_extent=0.2, typical_largest=0.2, size_factor=1.0,
                             joint_checks=[], state_requested=True, unmatched_requests=["its drawer closed"])
    assert m.value == 1.0 and m.details["joint_state_score"] is None
    assert m.details["not_counted"] == [{"phrase": "its drawer closed", "reason": "names no part of this object"}]
    m = sem.prompt_alignment(size_requested=False, largest_extent=0.2, typical_largest=0.2, size_factor=1.0,
                             joint_checks=checks, state_requested=True, unmatched_requests=["its drawer closed"])
    assert m.value == 1.0  # the lid's state counts, the drawer's does not
    # a request of which nothing was understood is not aligned, whatever the object's size
    m = sem.prompt_alignment(size_requested=False, largest_extent=0.2, typical_largest=0.2, size_factor=1.0,
                             joint_checks=[], state_requested=False, understood=False, warnings=["no word understood"])
    assert m.value == 0.0 and m.details["warnings"] == ["no word understood"]
    # neither measurable
    m = sem.prompt_alignment(size_requested=False, largest_extent=None, typical_largest=None, size_factor=1.0,
                             joint_checks=[], state_requested=False)
    assert m.value is None


# ------------------------------------------------------------------ end to end


def _lidded_box(folder: Path, q0: float, *, scale: float = 1.0, body_mass: float = 1.0) -> Path:
    """A box 0.2625 x 0.1875 x 0.1 m (a 'small' Box in the priors) with a lid
    hinged at the back top edge, closed at q = 0, opening to 1.5 rad."""
    pytest.importorskip("asset2sim.tasks.interpret.request")
    pytest.importorskip("asset2sim.tasks.interpret.size_priors")
    folder.mkdir(parents=True, exist_ok=True)
    L, W, H = 0.2625 * scale, 0.1875 * scale, 0.1 * scale
    t = 0.01 * scale

    def box(x, y, z, o=(0, 0, 0)):
        orig = f'<origin xyz="{o[0]} {o[1]} {o[2]}"/>'
        g = f'<geometry><box size="{x} {y} {z}"/></geometry>'
        return f"<collision>{orig}{g}</collision><visual>{orig}{g}</visual>"

    def inertial(m, o=(0, 0, 0)):
        return (f'<inertial><origin xyz="{o[0]} {o[1]} {o[2]}"/><mass value="{m}"/>'
                '<inertia ixx="0.001" iyy="0.001" izz="0.001" ixy="0" ixz="0" iyz="0"/></inertial>')

    (folder / "mobility.urdf").write_text(
        '<?xml version="1.0"?><robot name="box">'
        f'<link name="body">{inertial(body_mass)}{box(L, W, H)}</link>'
        f'<link name="lid">{inertial(0.2, (L / 2, 0, 0))}{box(L, W, t, (L / 2, 0, t / 2 + 0.001))}</link>'
        f'<joint name="hinge" type="revolute"><parent link="body"/><child link="lid"/><origin xyz="{-L / 2} 0 {H / 2}"/>'
        '<axis xyz="0 -1 0"/><limit lower="0" upper="1.5" effort="10" velocity="5"/><dynamics damping="0.1" friction="1.0"/></joint>'
        "</robot>"
    )
    (folder / "semantics.txt").write_text("body free box_body\nlid hinge lid\n")
    (folder / "initial_state.json").write_text(json.dumps({"initial_joint_positions": {"hinge": q0}}))
    return folder


PROMPT = "A small box with its lid slightly open."


def test_prompt_alignment_full_score_for_matching_size_and_state(tmp_path):
    ev = evaluate_asset(_lidded_box(tmp_path / "b", 0.3), prompt=PROMPT, category="Box", probes=False)
    m = ev.metric("prompt_alignment")
    assert ev.closed_positions["hinge"]["q_closed"] == pytest.approx(0.0, abs=0.05)
    (j,) = m.details["joints"]
    assert j["joint"] == "hinge" and j["band"] == "slightly_open" and j["score"] == 1.0
    assert j["fraction"] == pytest.approx(0.2, abs=0.04)
    assert m.details["size"]["score"] == 1.0
    assert m.value == 1.0


def test_prompt_alignment_penalises_wrong_state_and_size(tmp_path):
    m = evaluate_asset(_lidded_box(tmp_path / "b", 1.2), prompt=PROMPT, category="Box", probes=False).metric("prompt_alignment")
    assert m.details["joints"][0]["score"] == 0.0 and m.value == 0.5
    m = evaluate_asset(_lidded_box(tmp_path / "c", 0.3 * 1.0, scale=2.0), prompt=PROMPT, category="Box",
                       probes=False).metric("prompt_alignment")
    assert m.details["size"]["score"] == 0.5  # twice the requested size: a near miss
    assert m.details["size"]["ratio"] == pytest.approx(2.0, rel=0.05)


def test_total_mass_plausibility_for_the_category_at_the_asset_size(tmp_path):
    ok = evaluate_asset(_lidded_box(tmp_path / "b", 0.3), category="Box", probes=False).metric("total_mass")
    assert ok.value == pytest.approx(1.2) and ok.passed is True
    lo, hi = ok.details["range_kg"]
    assert lo < 1.2 < hi
    heavy = evaluate_asset(_lidded_box(tmp_path / "h", 0.3, body_mass=50.0), category="Box", probes=False).metric("total_mass")
    assert heavy.passed is False and heavy.value == pytest.approx(50.2)


def test_scale_and_initial_deviation_against_a_reference_folder(tmp_path):
    ref = tmp_path / "ref"
    _lidded_box(ref, 0.0)
    (ref / "reference_gensim2.urdf").write_text((ref / "mobility.urdf").read_text())
    (ref / "reference_gensim2.json").write_text(json.dumps({"scale": 0.25, "joint_position_range": [0.1, 0.8]}))
    out = _lidded_box(tmp_path / "out", 0.4)
    (out / "overlay.json").write_text(json.dumps({"scale": 0.3, "estimator": {"name": "test"}}))
    ev = evaluate_asset(out, reference=ref, prompt=PROMPT, category="Box", probes=False)
    assert ev.metric("scale_deviation").value == pytest.approx(20.0)
    assert ev.scale_source == "overlay.json"
    m = ev.metric("initial_joint_deviation")
    # reference state: the lower end of joint_position_range (0.1 rad)
    assert m.value == pytest.approx(0.3) and m.details["joints"]["hinge"]["q_ref"] == pytest.approx(0.1)
    assert ev.task_joints == ["hinge"]


def test_scale_is_inferred_from_geometry_when_no_sidecar_states_it(tmp_path):
    ref = tmp_path / "ref"
    _lidded_box(ref, 0.0)
    (ref / "reference_gensim2.json").write_text(json.dumps({"scale": 2.0}))
    out = _lidded_box(tmp_path / "out", 0.0, scale=2.0)
    ev = evaluate_asset(out, reference=ref, probes=False)
    assert ev.scale == pytest.approx(2.0, rel=0.02) and ev.scale_source.startswith("geometry")
    assert ev.metric("scale_deviation").value == pytest.approx(0.0, abs=2.0)
    assert not math.isnan(ev.metric("scale_deviation").value)


@pytest.mark.parametrize("kind, value, fraction, opening, jtype, score", [
    ("angle", math.radians(30), 0.33, math.radians(30.9), "revolute", 1.0),   # 3 % off
    ("angle", math.radians(30), 0.35, math.radians(32.5), "revolute", 0.5),   # 8 % off
    ("angle", math.radians(30), 0.5, math.radians(45), "revolute", 0.0),
    ("distance", 0.10, 0.3, 0.104, "prismatic", 1.0),
    ("distance", 0.10, 0.3, 0.13, "prismatic", 0.0),
    ("fraction", 0.6, 0.61, None, "revolute", 1.0),
    ("fraction", 0.6, 0.5, None, "revolute", 0.0),
    ("angle", 0.5, 0.5, 0.05, "prismatic", 0.0),                               # an angle on a slider
])
def test_target_score_grades_numbers_within_five_percent(kind, value, fraction, opening, jtype, score):
    c = sem.JointStateCheck("j", "halfway", fraction, target=StateTarget(kind=kind, value=value), opening=opening,
                            joint_type=jtype)
    assert sem.target_score(c)[0] == score


def test_target_score_end_and_hinge_distance():
    up = StateTarget(kind="end", end="high")
    assert sem.target_score(sem.JointStateCheck("j", "fully", 1.0, target=up))[0] == 1.0
    assert sem.target_score(sem.JointStateCheck("j", "fully", 0.0, target=up))[0] == 1.0
    assert sem.target_score(sem.JointStateCheck("j", "fully", 0.5, target=up))[0] == 0.0
    gap = StateTarget(kind="distance", value=0.05)
    score, why = sem.target_score(sem.JointStateCheck("j", "halfway", 0.3, target=gap, opening=0.4))
    assert score is None and "hinge" in why
    # an ungraded joint leaves the joint half out rather than scoring it 0
    m = sem.prompt_alignment(size_requested=False, largest_extent=0.2, typical_largest=0.2, size_factor=1.0,
                             joint_checks=[sem.JointStateCheck("j", "halfway", 0.3, target=gap, opening=0.4)],
                             state_requested=True)
    assert m.value == 1.0 and m.details["joint_state_score"] is None


