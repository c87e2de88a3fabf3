"""Tests of the evaluation's context, request matching and closed ends
(asset2sim.tasks.evaluation.eval_context, the request matched by tasks/interpret, closed_ends) on a
real PartNet-Mobility object and the generated demo assets, and of the
Evaluation hand-over model (asset2sim.schemas.evaluation)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from asset2sim.schemas.evaluation import Evaluation
from asset2sim.schemas.report import MetricResult
from asset2sim.tasks.check.asset_files import EvaluationError, JointInfo, clip_to_limits
from asset2sim.tasks.evaluation.closed_ends import ClosedEnd, closed_fallback, compute_closed
from asset2sim.tasks.evaluation.eval_context import build_context, task_joints
from asset2sim.tasks.interpret.named_parts import labelled_joints
from asset2sim.tasks.interpret.request import parse_prompt
from asset2sim.tasks.interpret.size_priors import scaled_mass_range, size_mass_prior
from asset2sim.tasks.interpret.part_priors import request_label_matches
from asset2sim.urdf import read_urdf
from tests.conftest import SHARED, needs_shared

STAPLER_PROMPT = "I want a slightly open stapler."


@needs_shared
def test_reference_state_is_the_range_lower_end_clipped_to_the_reference_limits(shared_dataset):
    folder = shared_dataset / "103275"
    ctx = build_context(folder, reference=folder, prompt=STAPLER_PROMPT)
    ref_json = json.loads((folder / "reference_gensim2.json").read_text())
    ref_joints = {j.name: j for j in read_urdf(folder / "reference_gensim2.urdf", mode="lenient").joints}
    assert ctx.reference_scale == pytest.approx(ref_json["scale"])
    assert ctx.reference_state, "the stapler's reference names a task joint"
    for name, q in ctx.reference_state.items():
        lim = ref_joints[name].limit
        assert ref_joints[name].type == "revolute"  # no scale applied to an angle
        assert q == pytest.approx(clip_to_limits(ref_json["joint_position_range"][0], lim.lower, lim.upper))
    assert "joint_position_range" in ctx.reference_rule
    # the raw folder states no scale: it is measured against the raw mobility.urdf, itself
    assert ctx.scale_source.startswith("geometry")
    assert ctx.scale == pytest.approx(1.0, rel=1e-6)
    assert ctx.category == "Stapler" and ctx.request is not None and ctx.request_error is None
    tj, rule = task_joints(ctx.joints, ctx.reference_dir, [])
    assert tj == list(ctx.reference_state) and "reference_gensim2" in rule


def test_missing_reference_folder_is_an_evaluation_error(demo_root, tmp_path):
    with pytest.raises(EvaluationError, match="no such folder"):
        build_context(demo_root / "box_lid", reference=tmp_path / "nowhere")


@needs_shared
def test_without_reference_or_named_part_the_task_joints_are_refines_own(tmp_path):
    """A stapler folder evaluated without its reference: the category's
    task-relevant part (the lid) by its semantics.txt label, the joint
    refine's post-check operates; with no labels, every movable joint."""
    from asset2sim.tasks.ingest.extract import extract_asset
    from asset2sim.tasks.interpret import priors

    ctx = build_context(SHARED / "103275")
    tj, rule = task_joints(ctx.joints, None, [], ctx.category, ctx.semantics)
    asset = extract_asset(SHARED / "103275")
    refine_rule = priors.task_relevant_joints(ctx.category, [(j.name, asset.link(j.child).semantic_label) for j in asset.movable_joints()])
    assert (tj, rule) == refine_rule
    assert tj == ["joint_1"] and ctx.semantics[ctx.joints["joint_1"].child][1] == "lid" and "category prior" in rule
    assert task_joints(ctx.joints, None, [], ctx.category, {}) == (ctx.movable, "every movable joint")


def test_initial_state_defaults_to_zero_clipped_and_task_joints_to_every_movable_joint(demo_root):
    ctx = build_context(demo_root / "box_lid")
    assert ctx.initial_state_source.startswith("none")
    for n in ctx.movable:
        j = ctx.joints[n]
        assert ctx.initial_state[n] == clip_to_limits(0.0, j.lower, j.upper)
    tj, rule = task_joints(ctx.joints, None, [])
    assert tj == ctx.movable and rule == "every movable joint"
    assert ctx.reference_state == {} and ctx.reference_scale is None and ctx.scale is None


def test_request_words_name_links_through_the_category_synonyms(demo_root):
    assert request_label_matches("Laptop", "lid", "screen")  # a laptop's lid is its screen
    assert not request_label_matches("Generic", "lid", "screen")
    assert not request_label_matches("Generic", "lid", None) and not request_label_matches("Generic", None, "lid")
    ctx = build_context(demo_root / "box_lid", prompt="A box with its lid slightly open.")
    named = labelled_joints(ctx.request, ctx.joints, ctx.semantics, ctx.category)
    assert named and all(request_label_matches(ctx.category, "lid", ctx.semantics[ctx.joints[n].child][1]) for n in named)
    assert {ctx.semantics[ctx.joints[n].child][1] for n in named} == {"rotation_lid"}
    assert labelled_joints(None, ctx.joints, ctx.semantics) == []


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
    ctx = build_context(demo_root / "box_lid")
    ext: list = []
    closed, notes = compute_closed(ctx.urdf, ctx.joints, ctx.movable, extents_out=ext)
    assert not notes and set(closed) == set(ctx.movable)
    for n, c in closed.items():
        j = ctx.joints[n]
        assert c.source.startswith("geometry")
        assert j.lower - 1e-9 <= c.q_closed <= j.upper + 1e-9 and abs(c.q_closed) < 0.05  # closed near 0
        assert c.open_range > 0
        assert c.fraction(c.q_closed) == pytest.approx(0.0)
        assert c.fraction(c.q_closed + c.direction * c.open_range) == pytest.approx(1.0)
    assert len(ext) == 1 and ext[0].shape == (3,) and np.all(ext[0] > 0)
    assert compute_closed(ctx.urdf, ctx.joints, []) == ({}, [])


def test_closed_fallback_is_the_limit_nearest_zero():
    j = JointInfo("j", "revolute", "a", "b", -0.2, 1.5, None, None)
    assert closed_fallback(j) == ClosedEnd(-0.2, 1.0, pytest.approx(1.7), "fallback: the limit nearest 0")
    j = JointInfo("j", "prismatic", "a", "b", -0.4, 0.1, None, None)
    c = closed_fallback(j)
    assert (c.q_closed, c.direction) == (0.1, -1.0)
    c = closed_fallback(JointInfo("j", "continuous", "a", "b", None, None, None, None))
    assert (c.q_closed, c.open_range) == (0.0, math.pi)


def test_evaluation_model_keeps_runs_out_of_the_json():
    m = MetricResult(name="scale_deviation", value=0.1, unit="%", engine="none")
    p = MetricResult(name="penetration", value=1.0, unit="mm", engine="pybullet")
    ev = Evaluation(asset_id="a", urdf="a/mobility.urdf", metrics=[p, m])
    ev._runs = {"pybullet": object()}
    data = json.loads(ev.model_dump_json())
    assert "_runs" not in data and "_context" not in data and data["version"] == "1"
    assert ev.metric("penetration", "pybullet") is p and ev.metric("penetration", "mujoco") is None
    assert ev.metric("scale_deviation", "mujoco") is m  # engine-free metrics match any engine
    assert Evaluation.model_validate(data).metrics == [p, m]
