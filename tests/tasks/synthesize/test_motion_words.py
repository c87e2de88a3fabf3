"""Words about how a part moves: read with the part they name, applied to its joint in the direction they say, echoed
in report.json and the summary, and kept from every later step of the post-check."""

from __future__ import annotations

import pytest

from asset2sim.demo_assets import build_object
from asset2sim.tasks.tune import word_guard
from asset2sim.tasks.interpret.request import parse_request
from asset2sim.tasks.synthesize.context import build_context
from asset2sim.tasks.synthesize.offline import OfflineEstimator


@pytest.mark.parametrize("text, kind, label", [
    ("a microwave with its door half open; the door swings freely", "free", "door"),
    ("a box whose lid stays where it is put", "hold", "lid"),
    ("the lid should stay up on its own", "hold", "lid"),
    ("a lid that does not fall shut on its own", "hold", "lid"),
    ("a kitchen faucet with a stiff handle joint", "stiff", "handle"),
    ("a laptop whose screen is hard to move", "stiff", "screen"),
    ("a loose lid", "free", "lid"),
    ("a stapler that springs back", "spring", None),
    ("a self-closing door", "self_closing", None),
    ("a cabinet whose door has a closer", "self_closing", "door"),
    ("a toilet with a soft-close lid", "soft_close", "lid"),
    ("a trash can; the hinge has low damping", "low_damping", None),
    ("a door with a heavy, well-damped hinge", "high_damping", None),
    ("a cabinet whose drawers run on ball-bearing slides", "slides", "drawer"),
])
def test_each_word_about_motion_is_read_with_the_part_it_names(text, kind, label):
    spec = parse_request(text)
    hit = [m for m in spec.motions if m.kind == kind]
    assert hit and hit[0].label == label, [m.short() for m in spec.motions]
    assert not spec.unused_words or "put" not in spec.unused_words


def test_a_mass_word_is_a_mass_not_a_stiffness():
    """"a heavy 25 kg solid oak door that swings freely": heavy says the mass (the number wins), nothing is stiff, and
    no contradiction between stiff and freely is warned."""
    spec = parse_request("a heavy 25 kg solid oak door that swings freely")
    assert [m.kind for m in spec.motions] == ["free"] and not spec.stiff
    assert not any("stiff" in w for w in spec.warnings)
    assert spec.properties and spec.properties[0].mass == pytest.approx(25.0)


@pytest.fixture(scope="module")
def microwave(tmp_path_factory):
    return build_object("microwave", tmp_path_factory.mktemp("mw") / "microwave")


def _door(folder, prompt: str):
    with build_context(folder, prompt) as (ctx, kin):
        return OfflineEstimator().estimate(ctx, kin).overlay.joints["joint_0"]


@pytest.mark.parametrize("words, changes", [
    ("the door swings freely", {"damping": "lower", "friction": "lower"}),
    ("the door has low damping", {"damping": "lower"}),
    ("the door is well damped", {"damping": "higher"}),
    ("the door is soft-close", {"damping": "higher"}),
    ("the door is stiff", {"friction": "higher"}),
    ("the door stays where it is put", {"friction": "not lower"}),
    ("the door is self-closing", {"stiffness": "higher"}),
    ("the door springs back", {"stiffness": "higher"}),
])
def test_each_word_moves_its_part_the_way_it_says(microwave, words, changes):
    """The demo microwave's door half open, with and without each word: the word moves the door's damping, friction
    or stiffness its way, and its source names the word."""
    base = _door(microwave, "A microwave with its door halfway open.")
    asked = _door(microwave, f"A microwave with its door halfway open; {words}.")
    for param, way in changes.items():
        a, b = getattr(asked, param), getattr(base, param)
        ok = {"lower": a < b, "higher": a > b, "not lower": a >= b}[way]
        assert ok, f"{param}: {b} -> {a} ({words})"
    assert "request '" in asked.source


def test_swings_freely_is_echoed_kept_and_its_conflict_named(microwave, tmp_path, refine_once):
    """"the door swings freely" on a free-standing microwave with its door half open: the door keeps the low friction
    and damping the word gives it (the post-check's escalation does not raise them), the word is echoed in report.json
    with the door's values; the door swings when the object is set down, which robust rest does not grade for a part
    asked to move freely (SPEC), and undisturbed it holds (its hinge is vertical: its weight does not turn it), so no
    conflict is named and the request is met."""
    prompt = "A 14 kg microwave with its door half open; the door swings freely."
    est = _door(microwave, prompt)
    res = refine_once(microwave, prompt, extras=False)
    door = res.overlay.joints["joint_0"]
    assert door.damping <= est.damping * (1 + 1e-9) and door.friction <= est.friction * (1 + 1e-9)
    lines = [p for p in res.report.request.phrases if "swings freely" in p]
    assert lines and "joint_0" in lines[0] and "damping" in lines[0]
    rr = res.report.metric("robust_rest")
    assert rr.passed is True and "joint_0" in rr.details["free_moving"]
    assert max(t["joint_drift"]["joint_0"] for t in rr.details["trials"].values()) > 0.02  # it swung, and came to rest
    assert res.report.metric("state_hold").passed is True and res.report.metric("request_met").passed is True


def test_the_guard_undoes_a_step_against_a_word_and_keeps_the_rest(microwave):
    """``word_guard.keep``: a proposal that raises a free door's damping is set back (a note says so); one that lowers
    it passes; a joint without a word is left as proposed."""
    with build_context(microwave, "A microwave with its door halfway open; the door swings freely.") as (ctx, kin):
        overlay = OfflineEstimator().estimate(ctx, kin).overlay
        guards = word_guard.guards(ctx, overlay)
    assert {(g.parameter, g.way) for g in guards} == {("friction", "max"), ("damping", "max")}
    door = overlay.joints["joint_0"]
    raised = overlay.model_copy(update={"joints": {"joint_0": door.model_copy(update={"damping": door.damping * 3})}})
    kept, notes = word_guard.keep(overlay, raised, guards)
    assert kept.joints["joint_0"] == door and len(notes) == 1 and "'swings freely'" in notes[0]
    lowered = overlay.model_copy(update={"joints": {"joint_0": door.model_copy(update={"damping": door.damping / 2})}})
    assert word_guard.keep(overlay, lowered, guards) == (lowered, [])
