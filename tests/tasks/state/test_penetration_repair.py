"""A state band that penetrates everywhere: the state search cannot resolve
it, the collision geometry is repaired by convex decomposition and the search
runs again; the report gives the before and after (issue 16)."""

from __future__ import annotations

import pytest

from asset2sim.schemas.config import RefineConfig
from asset2sim.tasks.check.verdict import UNRESOLVED_PENETRATION_MM
from asset2sim.tasks.refine import refine_asset
from tests.tasks.check.failure_assets import build_interlocked_box

pytest.importorskip("coacd")


def test_band_that_penetrates_everywhere_is_repaired(tmp_path):
    src = build_interlocked_box(tmp_path / "interlocked_box")
    res = refine_asset(src, "A box with its lid closed.", tmp_path / "out", extras=False)
    r = res.report
    st = r.state
    tol = RefineConfig().penetration_tolerance
    assert st.phi_requested > 10 * tol  # before: the latch inside the body's solid hull
    assert "collision pieces improved" in st.method  # the search alone did not resolve it
    assert any("CoACD" in c and "->" in c for c in st.collision_changes)  # before -> after, per link
    assert st.phi_result <= tol  # after
    assert r.opening_fractions["joint_0"] <= 0.03  # still in the requested (closed) band
    assert r.metric("penetration").value <= UNRESOLVED_PENETRATION_MM  # the post-check agrees
    assert r.failure_mode != "unresolved_penetration"
    assert "collision/" in (res.out_dir / "mobility.urdf").read_text()  # the repaired pieces are what the output loads


def test_without_repair_the_band_stays_penetrating(tmp_path):
    src = build_interlocked_box(tmp_path / "interlocked_box")
    cfg = RefineConfig(convex_decomposition=False, max_state_evaluations=120)
    r = refine_asset(src, "A box with its lid closed.", tmp_path / "out", config=cfg, extras=False).report
    assert r.state.phi_result > 10 * cfg.penetration_tolerance  # the state search alone cannot resolve it
    # the sweep's running clearance (tasks.state.clearance) may then squeeze the latch out of the body, but the
    # lid stays locked: without the decomposition the asset is never ready
    assert r.failure_mode in {"unresolved_penetration", "blocked_joint"}
