"""Tests of how the evaluation reads a folder (asset2sim.tasks.evaluation.evaluate: the object as the checks simulate
it, its closed ends, its task joints and GenSim2's reference state) on a real PartNet-Mobility object and the
generated demo assets, the request matched by tasks/interpret, and the Evaluation hand-over model
(asset2sim.schemas.evaluation)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from asset2sim.refined_asset import RefinedAsset
from asset2sim.schemas.evaluation import Evaluation
from asset2sim.schemas.report import MetricResult
from asset2sim.tasks.evaluation.folder_reading import EvaluationError, closed_ends, reference_state, sim_object, task_joints
from asset2sim.tasks.ingest import partnet_mobility
from asset2sim.tasks.ingest.extract import extract_asset
from asset2sim.tasks.interpret.named_parts import labelled_joints
from asset2sim.tasks.interpret.part_priors import request_label_matches
from asset2sim.tasks.interpret.request import parse_prompt
from asset2sim.tasks.interpret.size_priors import scaled_mass_range, size_mass_prior
from asset2sim.urdf import read_urdf
from tests.conftest import SHARED, needs_shared


@needs_shared
def test_reference_state_is_the_range_lower_end_clipped_to_the_reference_limits(shared_dataset):
    folder = shared_dataset / "103275"
    ref = partnet_mobility.read_reference(folder)
    state, rule = reference_state(ref, read_urdf(folder / "mobility.urdf", mode="lenient"), 1.0)
    ref_json = json.loads((folder / "reference_gensim2.json").read_text())
    ref_joints = {j.name: j for j in read_urdf(folder / "reference_gensim2.urdf", mode="lenient").joints}
    assert ref.scale == pytest.approx(ref_json["scale"])
    assert state, "the stapler's reference names a task joint"
    for name, q in state.items():
        lim = ref_joints[name].limit
        assert ref_joints[name].type == "revolute"  # no scale applied to an angle
        assert q == pytest.approx(float(np.clip(ref_json["joint_position_range"][0], lim.lower, lim.upper)))
    assert "joint_position_range" in rule
    tj, how = task_joints(extract_asset(folder), "Stapler", folder)
    assert tj == list(state) and "reference_gensim2" in how


def test_an_unreadable_reference_is_an_evaluation_error(demo_root, tmp_path):
    (tmp_path / "reference_gensim2.json").write_text("{not json")
    with pytest.raises(EvaluationError, match="reference"):
        task_joints(extract_asset(demo_root / "box_lid"), "Box", tmp_path)


@needs_shared
def test_without_reference_the_task_joints_are_refines_own():
    """A stapler folder evaluated without its reference: the category's task-relevant part (the lid) by its
    semantics.txt label, the joint refine's post-check operates; with no labels, every movable joint."""
    from asset2sim.tasks.interpret.part_priors import task_relevant_joints

    asset = extract_asset(SHARED / "103275")
    tj, rule = task_joints(asset, "Stapler")
    assert (tj, rule) == task_relevant_joints("Stapler", [(j.name, asset.link(j.child).semantic_label)
                                                                 for j in asset.movable_joints()])
    assert tj == ["joint_1"] and asset.link(asset.joint("joint_1").child).semantic_label == "lid" and "category prior" in rule
    bare = asset.model_copy(update={"links": [ln.model_copy(update={"semantic_label": None}) for ln in asset.links]})
    assert task_joints(bare, "Stapler")[0] == [j.name for j in asset.movable_joints()]


def test_a_folder_without_state_is_at_zero_clipped_free_on_the_ground(demo_root):
    obj, source = sim_object(RefinedAsset(demo_root / "box_lid"))
    model = read_urdf(demo_root / "box_lid" / "mobility.urdf", mode="lenient")
    assert source.startswith("none") and not obj.fixed_base and dict(obj.springs) == {}
    assert dict(obj.state) == {j.name: float(np.clip(0.0, j.lower, j.upper)) for j in model.movable_joints}


def test_request_words_name_links_through_the_category_synonyms(demo_root):
    assert request_label_matches("Laptop", "lid", "screen")  # a laptop's lid is its screen
    assert not request_label_matches("Generic", "lid", "screen")
    assert not request_label_matches("Generic", "lid", None) and not request_label_matches("Generic", None, "lid")
    asset = extract_asset(demo_root / "box_lid")
    spec, _ = parse_prompt("A box with its lid slightly open.")
    named = labelled_joints(spec, asset, "Box")
    assert named and {asset.link(asset.joint(n).child).semantic_label for n in named} == {"rotation_lid"}
    assert labelled_joints(None, asset) == []


def test_prompt_and_priors_degrade_to_empty_not_to_errors():
    assert parse_prompt(None) == (None, None)
    assert size_mass_prior(None) == {}
    prior = size_mass_prior("Stapler")
    assert prior["category"] == "Stapler" and prior["base_mass_range"][0] < prior["base_mass_range"][1]
    rng, f = scaled_mass_range(prior, None)
    assert f == 1.0 and rng[0] <= prior["base_mass_range"][0] * 1.0001 and rng[1] >= prior["base_mass_range"][1] * 0.9999
    bigger, f2 = scaled_mass_range(prior, 2.0 * np.asarray(prior["base_dims"]))
    assert f2 == pytest.approx(2.0) and bigger[0] > rng[0] and bigger[1] > rng[1]
    assert scaled_mass_range({}, None) == (None, 1.0)


def test_closed_end_of_the_demo_lid_comes_from_geometry(demo_root):
    closed, how = closed_ends(RefinedAsset(demo_root / "box_lid"))
    model = read_urdf(demo_root / "box_lid" / "mobility.urdf", mode="lenient")
    assert how.startswith("geometry") and set(closed) == {j.name for j in model.movable_joints}
    for n, c in closed.items():
        j = model.joint(n)
        assert j.lower - 1e-9 <= c.q_closed <= j.upper + 1e-9 and abs(c.q_closed) < 0.05  # closed near 0
        assert c.open_range > 0
        assert c.fraction(c.q_closed) == pytest.approx(0.0)
        assert c.fraction(c.q_closed + c.direction * c.open_range) == pytest.approx(1.0)


def test_a_joint_that_does_not_open_is_closed_at_its_limit_nearest_zero(tmp_path, demo_root):
    """A joint whose geometry cannot say where it closes (here: no mesh file readable) falls back to its limit nearest 0,
    a continuous one to 0 with a range of pi."""
    from asset2sim.tasks.evaluation.folder_reading import _closed_fallback

    model = read_urdf(demo_root / "box_lid" / "mobility.urdf", mode="lenient")
    j = model.movable_joints[0]
    c = _closed_fallback(j)
    assert c.q_closed == (j.lower if abs(j.lower) <= abs(j.upper) else j.upper) and c.open_range == pytest.approx(j.upper - j.lower)
    j.type, j.limit = "continuous", None
    c = _closed_fallback(j)
    assert (c.q_closed, c.open_range) == (0.0, math.pi)


def test_evaluation_model_keeps_runs_out_of_the_json():
    m = MetricResult(name="scale_deviation", value=0.1, unit="%", engine="none")
    p = MetricResult(name="penetration", value=1.0, unit="mm", engine="pybullet")
    ev = Evaluation(asset_id="a", urdf="a/mobility.urdf", metrics=[p, m], failure_mode="none")
    ev._runs = {"pybullet": object()}
    data = json.loads(ev.model_dump_json())
    assert "_runs" not in data and "_context" not in data and data["version"] == "1" and data["failure_mode"] == "none"
    assert ev.metric("penetration", "pybullet") is p and ev.metric("penetration", "mujoco") is None
    assert ev.metric("scale_deviation", "mujoco") is m  # engine-free metrics match any engine
    assert Evaluation.model_validate(data).metrics == [p, m]
