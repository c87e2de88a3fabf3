"""Resting pose: static margin of the support polygon, laying objects on a stable face."""

from __future__ import annotations

import numpy as np
import pytest

from asset2sim.engines.base import SessionOptions
from asset2sim.engines.registry import open_session
from asset2sim.schemas.overlay import Inertia, LinkPhysics
from asset2sim.tasks.state import pose
from asset2sim.tasks.geometry.closed_state import link_hull_points
from asset2sim.tasks.ingest.extract import extract_asset
from tests.helpers import write_standing_slab_with_arm


@pytest.fixture()
def slab(tmp_path):
    asset = extract_asset(write_standing_slab_with_arm(tmp_path / "slab"))
    s = open_session("pybullet", asset.urdf_path, SessionOptions(fixed_base=True, gravity=False, ground=False))
    yield asset, s, link_hull_points(asset)
    s.close()


def _links(arm_mass):
    I = Inertia(ixx=0.01, iyy=0.01, izz=0.01)
    return {
        "slab": LinkPhysics(mass=1.0, inertia=I, com=(0.0, 0.0, 0.3)),
        "arm": LinkPhysics(mass=arm_mass, inertia=I, com=(0.15, 0.0, 0.0)),
    }


def test_static_margin_matches_geometry(slab):
    asset, s, hull = slab
    # light arm: COM x = (0 * 1 + 0.18 * 0.01) / 1.01 -> margin = 0.02 - 0.00178
    m, size = pose.static_margin(s, asset, _links(0.01), {"hinge": 0.0}, 1.0, hull, np.eye(3))
    assert size == pytest.approx(0.6, abs=0.02)
    assert m == pytest.approx(0.02 - 0.18 * 0.01 / 1.01, abs=1e-4)
    # heavy arm: COM far outside the 0.04 m wide footprint
    m, _ = pose.static_margin(s, asset, _links(2.0), {"hinge": 0.0}, 1.0, hull, np.eye(3))
    assert m < -0.05


def test_tipping_object_laid_on_a_stable_face(slab):
    asset, s, hull = slab
    R, note = pose.most_stable_rotation(s, asset, _links(2.0), {"hinge": 0.0}, 1.0, hull, ["arm"], exclude_modelled=True)
    assert R is not None and "rests" in note
    m, size = pose.static_margin(s, asset, _links(2.0), {"hinge": 0.0}, 1.0, hull, R)
    assert m > pose.MIN_MARGIN_FRACTION * size
    # the thin axis (x) ends up vertical
    assert abs((R @ np.array([1.0, 0, 0]))[2]) == pytest.approx(1.0)


def test_lying_flat_puts_the_smallest_extent_vertical_moving_part_up(slab):
    asset, s, hull = slab
    R, note = pose.resting_rotation(s, asset, {"hinge": 0.0}, hull, ["arm"])
    assert abs((R @ np.array([1.0, 0, 0]))[2]) == pytest.approx(1.0)
    # the arm (at +x of the slab) is on top
    assert (R @ np.array([1.0, 0, 0]))[2] > 0
