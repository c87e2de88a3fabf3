"""The evaluation's ``request_met`` (asset2sim.tasks.evaluation.metric_defs, as asked): measured on the output itself,
on the generated demo box (its lid hinge, closed at q = 0 here, opening towards +q over 1.9 rad) with the closed end
set by hand, so no simulator runs."""

from __future__ import annotations

import math

import pytest

from asset2sim.tasks.evaluation.closed_ends import ClosedEnd
from asset2sim.tasks.evaluation.eval_context import build_context
from asset2sim.tasks.evaluation.metric_defs import METRICS


def _measure(demo_root, prompt: str | None, q: float = 0.0):
    ctx = build_context(demo_root / "box_lid", prompt=prompt)
    ctx.task_joints = list(ctx.movable)
    ctx.closed = {"joint_0": ClosedEnd(0.0, 1.0, 1.9, "set by the test")}
    ctx.initial_state = {"joint_0": q}
    (m,) = METRICS["request_met"].fn(ctx, {})
    return m


def test_a_lid_at_the_asked_angle_meets_the_request(demo_root):
    m = _measure(demo_root, "A box with its lid open 30 degrees.", math.radians(30.5))
    assert m.passed is True and m.value == 0.0 and m.details["graded"] == 1


def test_an_angle_missed_beyond_its_tolerance_fails_with_the_gap(demo_root):
    m = _measure(demo_root, "A box with its lid open 30 degrees.", math.radians(20.8))
    assert m.passed is False
    (item,) = m.details["unmet"]
    assert item["phrase"] == "lid open 30 degrees" and item["joint"] == "joint_0" and item["unit"] == "rad"
    assert item["target"] == pytest.approx(math.radians(30)) and item["achieved"] == pytest.approx(math.radians(20.8))
    assert item["gap"] == pytest.approx(math.radians(9.2)) and item["measured_from"] == "closed end"


def test_a_part_the_object_lacks_fails_and_free_text_does_not(demo_root):
    m = _measure(demo_root, "A box made of wood with its drawer open.")
    assert m.passed is False
    (item,) = m.details["unmet"]
    assert item["phrase"] == "drawer open" and item["kind"] == "not_applied" and "names no part of this Box" in item["reason"]
    assert _measure(demo_root, "A lovely box made of wood, with its lid closed.").passed is True


def test_a_band_missed_fails(demo_root):
    m = _measure(demo_root, "A box with its lid fully open.", 0.3)  # 16 % open
    (item,) = m.details["unmet"]
    assert m.passed is False and item["kind"] == "band" and item["gap"] == pytest.approx(0.85 - 0.3 / 1.9)


def test_no_request_is_not_measured(demo_root):
    for prompt in (None, ""):
        m = _measure(demo_root, prompt)
        assert m.passed is None and m.value is None and m.details["reason"] == "no request"
