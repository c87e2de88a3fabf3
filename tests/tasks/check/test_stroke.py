"""The stroke runner every hand of the checks runs (tasks/check/stroke.py), on the fake engine:
its drive moves a joint kinematically, so steps, readings and stops are exact."""

from __future__ import annotations

import pytest

from asset2sim.engines.base import SessionOptions
from asset2sim.engines.registry import open_session
from asset2sim.tasks.check.stroke import reach_stroke, run_stroke
from tests.contract_asset import write_contract_asset

DT = 1.0 / 240.0


@pytest.fixture()
def session(tmp_path):
    a = write_contract_asset(tmp_path, lid_angle=0.0, post_height=0.0)
    with open_session("fake", a.urdf, SessionOptions(initial_state={"lid_hinge": 0.0, "post_slide": 0.0},
                                                     fixed_base=True, gravity=False)) as s:
        yield s


def test_a_stroke_reads_drives_holds_steps_and_records_each_step(session):
    seen, drives = [], []
    session.drive_joint = lambda j, v, f: drives.append((j, v, f))  # what the runner asks of the engine
    end = run_stroke(session, "lid_hinge", 5, law=lambda k, q, qd: session.drive_joint("lid_hinge", 1.0, 9.0),
                     record=lambda k, q, qd: seen.append(k), held=["post_slide"], hold_force=50.0)
    assert end.steps == 5 and session.steps == 5 and seen == [1, 2, 3, 4, 5]
    assert drives == [("lid_hinge", 1.0, 9.0), ("post_slide", 0.0, 50.0)] * 5


def test_the_law_or_the_record_ends_a_stroke(session):
    end = run_stroke(session, "lid_hinge", 10, law=lambda k, q, qd: k == 3)
    assert end.steps == 3 and session.steps == 3  # the law stops it before the fourth step
    end = run_stroke(session, "lid_hinge", 10, record=lambda k, q, qd: k == 2)
    assert end.steps == 2 and session.steps == 5


@pytest.mark.parametrize("sign, target", [(1.0, 0.5), (-1.0, 0.2)])
def test_a_reach_stroke_stops_at_its_target_and_keeps_the_farthest_fraction(session, sign, target):
    """The lid (0..2 rad) driven at 1 rad/s from 1 rad: opening it passes 50 % at once; closing it
    passes 20 % after 0.6 rad, 144 steps."""
    session.set_joint_positions({"lid_hinge": 1.0})
    r = reach_stroke(session, "lid_hinge", (0.0, 1.0, 2.0), target, sign, 1.0,
                     lambda k, q, qd: session.drive_joint("lid_hinge", sign, 10.0))
    assert r.limit == 240 and not r.diverged
    if sign > 0:
        assert r.steps == 0 and r.far == pytest.approx(0.5) and r.fractions == [pytest.approx(0.5)]
    else:
        assert r.steps == pytest.approx(144, abs=1) and r.far == pytest.approx(0.2, abs=0.01)
        assert len(r.fractions) == r.steps + 1 and r.fractions[0] == pytest.approx(0.5)


def test_a_reach_stroke_that_runs_out_is_not_reached(session):
    r = reach_stroke(session, "lid_hinge", (0.0, 1.0, 2.0), 0.95, 1.0, 0.5,
                     lambda k, q, qd: session.drive_joint("lid_hinge", 1.0, 10.0))
    assert r.steps is None and r.far == pytest.approx(0.25, abs=0.01) and len(r.fractions) == r.limit == 120
