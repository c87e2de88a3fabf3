"""The one estimation-context builder (stages 1-4) on real and generated assets:
what it computes, that the caller's extraction and analysis are reused, that
its kinematic session is closed when the ``with`` block ends (errors included),
and that estimators hand back the overlay with the bands as one result."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from asset2sim import demo_assets
from asset2sim.tasks.geometry import analyze
from asset2sim.tasks.ingest import extract
from asset2sim.tasks.synthesize import backends, estimate, estimator
from asset2sim.tasks.interpret.reading import interpret
from asset2sim.tasks.synthesize.context import EstimationContext, build_context
from asset2sim.tasks.synthesize.validate_overlay import validate_overlay
from tests.conftest import SHARED, needs_shared

STAPLER_PROMPT = "I want a slightly open stapler."
LAPTOP_PROMPT = "I want a half-open laptop."


def _check_context(ctx: EstimationContext) -> None:
    movable = {j.name for j in ctx.asset.movable_joints()}
    assert set(ctx.closed) == set(ctx.subtrees) == set(ctx.joint_heights) == movable
    assert ctx.closed_extents.shape == (3,) and np.all(ctx.closed_extents > 0)
    assert set(ctx.geometry) <= set(ctx.hull_points)
    for pts in ctx.hull_points.values():
        assert pts.ndim == 2 and pts.shape[1] == 3
    for name, links in ctx.subtrees.items():
        assert ctx.asset.joint(name).child in links
    for name, cs in ctx.closed.items():
        j = ctx.asset.joint(name)
        if j.lower is not None and j.upper is not None:
            assert j.lower - 1e-9 <= cs.q_closed <= j.upper + 1e-9
    assert ctx.closed_state() == {n: c.q_closed for n, c in ctx.closed.items()}


@needs_shared
@pytest.mark.parametrize("asset_id, category, prompt", [("103275", "Stapler", STAPLER_PROMPT), ("9912", "Laptop", LAPTOP_PROMPT)])
def test_context_of_real_assets(asset_id, category, prompt):
    with build_context(SHARED / asset_id, prompt, category=category) as (ctx, kin):
        _check_context(ctx)
        assert ctx.category == category and ctx.asset.asset_id == asset_id
        assert ctx.request.text == prompt
        result = backends.get_estimator("offline").estimate(ctx, kin)
    assert isinstance(result, estimator.Estimate)
    assert set(result.bands) == {j.name for j in ctx.asset.movable_joints()}
    assert set(result.bands.values()) - {"closed"}, "the request opens a part"
    overlay, _ = validate_overlay(result.overlay, ctx.asset, ctx.geometry)
    assert 0.0 < overlay.scale and overlay.total_mass() > 0


@needs_shared
def test_given_asset_and_geometry_are_reused_and_give_the_same_context():
    src = SHARED / "103275"
    with build_context(src, STAPLER_PROMPT, category="Stapler") as (by_path, kin):
        pass
    asset = extract.extract_asset(src, category="Stapler")
    cache = analyze.MeshCache()
    geometry = analyze.analyze_asset(asset, cache=cache)
    with build_context(asset, STAPLER_PROMPT, category="Stapler", geometry=geometry, cache=cache) as (given, kin):
        assert given.asset is asset and given.geometry is geometry
    assert {n: c.q_closed for n, c in given.closed.items()} == {n: c.q_closed for n, c in by_path.closed.items()}
    np.testing.assert_array_equal(given.closed_extents, by_path.closed_extents)
    assert given.joint_heights == by_path.joint_heights
    assert given.subtrees == by_path.subtrees
    assert (given.category, given.category_reason) == (by_path.category, by_path.category_reason)
    meaning = interpret(asset, STAPLER_PROMPT, "Stapler")
    assert meaning.request == given.request and meaning.category == given.category


def test_demo_cabinet_context_finds_the_closed_drawers_and_orders_them_top_down(tmp_path):
    entry = next(e for e in demo_assets.DEMO_OBJECTS if e.asset_id == "cabinet_2drawer")
    src = demo_assets.build_two_drawer_cabinet(tmp_path / entry.asset_id)
    with build_context(src, entry.prompt, category=entry.category) as (ctx, kin):
        _check_context(ctx)
        result = backends.get_estimator("offline").estimate(ctx, kin)
        bands, _ = estimate.requested_bands(ctx, kin)
    for name, q in entry.closed_positions.items():
        assert ctx.closed[name].q_closed == pytest.approx(q, abs=1e-3)
    # joint_0 moves the top drawer, joint_1 the bottom one: "first ... closed, second slightly open"
    assert ctx.joint_heights["joint_0"] > ctx.joint_heights["joint_1"]
    assert result.bands == bands == {"joint_0": "closed", "joint_1": "slightly_open"}
    assert result.overlay.initial_joint_positions is not None


def test_kinematic_session_is_closed_after_the_block_and_on_errors(tmp_path):
    entry = next(e for e in demo_assets.DEMO_OBJECTS if e.asset_id == "box_lid")
    src = demo_assets.build_box_with_lid(tmp_path / entry.asset_id)
    with build_context(src, entry.prompt) as (ctx, kin):
        session = kin
        session.set_joint_positions(ctx.closed_state())  # usable inside
    assert not any(getattr(ctx, f.name) is kin for f in dataclasses.fields(ctx))  # the context holds values only
    with pytest.raises(Exception):
        session.set_joint_positions(ctx.closed_state())
    with pytest.raises(RuntimeError, match="inside the block"):
        with build_context(src, entry.prompt) as (ctx2, kin2):
            failing = kin2
            raise RuntimeError("inside the block")
    with pytest.raises(Exception):
        failing.set_joint_positions(ctx2.closed_state())


def test_unreadable_asset_raises_the_extraction_error(tmp_path):
    (tmp_path / "empty").mkdir()
    with pytest.raises(extract.AssetError):
        with build_context(tmp_path / "empty", "a box"):
            pass
