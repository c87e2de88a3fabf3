"""An angle or a distance asked stays that opening from the closed end when the output's closed end or range
moves (asset2sim.tasks.synthesize.request_apply.retarget): the suitcase whose 30 degree lid became 20.8 degrees."""

from __future__ import annotations

import math

import pytest

from asset2sim.tasks.geometry.closed_state import ClosedState
from asset2sim.tasks.synthesize.request_apply import JointTarget, retarget


def _cs(q_closed: float, rng: float) -> ClosedState:
    return ClosedState("j", q_closed=q_closed, direction=1.0, open_range=rng, lower=q_closed, upper=q_closed + rng)


def test_an_angle_keeps_its_opening_when_the_range_is_clipped():
    f = math.radians(30) / math.pi
    t = JointTarget(joint="j", band="quarter", fraction=f, interval=(f * 0.95, f * 1.05), kind="angle", asked=math.radians(30),
                    phrase="lid open 30 degrees")
    new = _cs(-0.785, math.radians(119))
    (moved,) = retarget({"j": t}, {"j": _cs(-0.785, math.pi)}, {"j": new}).values()
    assert moved.fraction * new.open_range == pytest.approx(math.radians(30))
    lo, hi = moved.interval
    assert lo < moved.fraction < hi and (hi - lo) / 2 == pytest.approx(0.05 * moved.fraction)
    assert moved.asked == t.asked and moved.phrase == t.phrase and "moved" in moved.note


def test_fractions_ends_and_unmoved_joints_keep_their_target():
    old, new = {"j": _cs(0.0, 2.0)}, {"j": _cs(0.1, 1.5)}
    frac = JointTarget(joint="j", band="halfway", fraction=0.5, interval=(0.475, 0.525), kind="fraction", asked=0.5)
    assert retarget({"j": frac}, old, new)["j"] is frac
    angle = JointTarget(joint="j", band="halfway", fraction=0.5, interval=(0.475, 0.525), kind="angle", asked=1.0)
    assert retarget({"j": angle}, old, dict(old))["j"] is angle
    beyond = retarget({"j": angle}, old, {"j": _cs(0.0, 0.5)})["j"]  # the new range is shorter than the opening: its end
    assert beyond.fraction == 1.0 and beyond.interval[1] == 1.0
