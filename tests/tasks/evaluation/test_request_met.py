"""The as-asked tier read once (asset2sim.tasks.check.as_asked.as_asked_tier): the request resolved on the parts of the
generated demo box (its lid hinge, closed at q = 0 here, opening towards +q over 1.9 rad, the closed end set by
hand) and graded at a state, as a refine's final attempt and ``asset2sim evaluate`` grade it; no simulator runs."""

from __future__ import annotations

import math

import pytest

from asset2sim.tasks.check.as_asked import as_asked_tier
from asset2sim.tasks.evaluation.folder_reading import file_overlay
from asset2sim.tasks.geometry.closed_state import ClosedState
from asset2sim.tasks.synthesize.context import build_context
from asset2sim.urdf import read_urdf


def _measure(demo_root, prompt: str | None, q: float = 0.0):
    folder = demo_root / "box_lid"
    overlay = file_overlay(read_urdf(folder / "mobility.urdf", mode="lenient"))
    with build_context(folder, prompt or "") as (ctx, kin):
        asked = as_asked_tier(ctx, kin, overlay, {"joint_0": q}, {"joint_0": ClosedState("joint_0", 0.0, 1.0, 1.9, -0.1, 1.8)}, [])
    (m,) = [m for m in asked.metrics if m.name == "request_met"]
    return m, asked


def test_a_lid_at_the_asked_angle_meets_the_request(demo_root):
    m, asked = _measure(demo_root, "A box with its lid open 30 degrees.", math.radians(30.5))
    assert m.passed is True and m.value == 0.0 and m.details["graded"] >= 1
    assert list(asked.resolution.requests) == ["joint_0"]  # the phrase set the lid, and the lid is graded


def test_an_angle_missed_beyond_its_tolerance_fails_with_the_gap(demo_root):
    m, _ = _measure(demo_root, "A box with its lid open 30 degrees.", math.radians(20.8))
    assert m.passed is False
    (item,) = m.details["unmet"]
    assert item["phrase"] == "lid open 30 degrees" and item["joint"] == "joint_0" and item["unit"] == "rad"
    assert item["target"] == pytest.approx(math.radians(30)) and item["achieved"] == pytest.approx(math.radians(20.8))
    assert item["gap"] == pytest.approx(math.radians(9.2)) and item["measured_from"] == "closed end"


def test_a_part_the_object_lacks_fails_and_free_text_does_not(demo_root):
    m, _ = _measure(demo_root, "A box made of wood with its drawer open.")
    assert m.passed is False
    (item,) = m.details["unmet"]
    assert item["phrase"] == "drawer open" and item["kind"] == "not_applied"
    assert _measure(demo_root, "A lovely box made of wood, with its lid closed.")[0].passed is True


def test_a_band_missed_fails(demo_root):
    m, _ = _measure(demo_root, "A box with its lid fully open.", 0.3)  # 16 % open
    (item,) = m.details["unmet"]
    assert m.passed is False and item["kind"] == "band" and item["gap"] == pytest.approx(0.85 - 0.3 / 1.9)


def test_no_request_is_not_measured(demo_root):
    for prompt in (None, ""):
        m, _ = _measure(demo_root, prompt)
        assert m.passed is None and m.value is None and m.details["reason"] == "no request"
