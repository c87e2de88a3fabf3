"""State refinement: penetration removed inside the requested band, never outside it."""

from __future__ import annotations

import pytest

from asset2sim.engines.base import SessionOptions, open_session
from asset2sim.schemas.request import BAND_INTERVAL
from asset2sim.tasks.geometry.closed_state import ClosedState
from asset2sim.tasks.ingest.extract import extract_asset
from asset2sim.tasks.state.refine_state import allowed_intervals, path_joints, refine_initial_state
from tests.helpers import write_arm_through_post


@pytest.fixture()
def arm(tmp_path):
    asset = extract_asset(write_arm_through_post(tmp_path / "arm"))
    session = open_session("pybullet", asset.urdf_path, SessionOptions(fixed_base=True, gravity=False, ground=False))
    closed = {"hinge": ClosedState(joint="hinge", q_closed=0.0, direction=1.0, open_range=1.0, lower=-1.0, upper=1.0)}
    yield asset, session, closed
    session.close()


def test_penetration_resolved_inside_the_band(arm):
    asset, session, closed = arm
    band = BAND_INTERVAL["slightly_open"]
    st = refine_initial_state(session, asset, closed, {"hinge": 0.1}, {"hinge": band}, tolerance=1e-6, lam=0.05)
    assert st.phi_requested > 1e-3  # the arm passes through the post at the request
    assert st.phi_result <= 1e-6
    q = st.result["hinge"]
    assert band[0] <= q <= band[1]
    assert 0.15 < q < 0.3  # just far enough to clear the 0.045 m overlap at 0.25 m, not much farther
    assert st.worst_pairs and {st.worst_pairs[0]["link_a"], st.worst_pairs[0]["link_b"]} == {"arm", "post"}


def test_never_leaves_the_band_even_if_penetration_remains(arm):
    asset, session, closed = arm
    band = BAND_INTERVAL["closed"]
    st = refine_initial_state(session, asset, closed, {"hinge": 0.0}, {"hinge": band}, tolerance=1e-6)
    assert band[0] <= st.result["hinge"] <= band[1]
    assert st.phi_result > 0  # honest: the overlap cannot be removed while closed
    assert st.phi_result <= st.phi_requested


def test_requested_state_projected_onto_band(arm):
    asset, session, closed = arm
    box = allowed_intervals(closed, {"hinge": BAND_INTERVAL["halfway"]})
    assert box["hinge"].lo == pytest.approx(0.35) and box["hinge"].hi == pytest.approx(0.65)
    st = refine_initial_state(session, asset, closed, {"hinge": 0.9}, {"hinge": BAND_INTERVAL["halfway"]})
    assert st.requested["hinge"] == pytest.approx(0.65)
    assert st.phi_result == 0.0 and st.evaluations == 1


def test_path_joints_between_links(arm):
    asset, _, _ = arm
    assert path_joints(asset, "arm", "post") == ["hinge"]
    assert path_joints(asset, "body", "post") == []
