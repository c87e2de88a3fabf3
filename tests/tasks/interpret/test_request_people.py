"""Requests as people write them, applied to real objects at the level of the joints (the parse and
``request_apply.resolve_states``, no refine): part words through the synonym table, parts picked by where
and how big they are, parts the object lacks, clauses kept apart, hedges, quantities and the one frame of
numbers (``docs/guide/requests.md``). Dev objects from ``../shared/datasets/partnet_mobility``; the toaster,
the bottle and the three-drawer cabinet are generated (the dev set has none)."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from asset2sim.commands.refine import summary_lines
from asset2sim.schemas.overlay import EstimatorInfo, Overlay
from asset2sim.tasks.interpret.named_parts import part_boxes
from asset2sim.tasks.interpret.request import parse_request
from asset2sim.tasks.interpret.state_words import LESS_THAN_HALF
from asset2sim.tasks.synthesize import estimate, joint_dynamics, request_apply, request_findings
from asset2sim.tasks.synthesize.context import build_context
from tests.conftest import SHARED, needs_shared
from tests.tasks.interpret.request_assets import build_three_drawer_cabinet
from tests.unseen_assets import (build_bottle, build_desk_fan, build_desk_lamp, build_dispenser, build_double_door_cabinet,
                                 build_printer, build_toaster)


@pytest.fixture(scope="module")
def generated(tmp_path_factory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("people")
    return {"toaster": build_toaster(root / "toaster"), "bottle": build_bottle(root / "bottle"),
            "chest": build_three_drawer_cabinet(root / "chest"), "dispenser": build_dispenser(root / "dispenser"),
            "lamp": build_desk_lamp(root / "lamp"), "fan": build_desk_fan(root / "fan"), "printer": build_printer(root / "printer")}


def resolve(folder: Path, text: str):
    """(resolution, {joint: label}, {joint: box volume m^3}, {joint: height m}, scale, scale note) of ``text`` on ``folder``."""
    with build_context(folder, text) as (ctx, kin):
        s, note = estimate.choose_scale(ctx)
        res = request_apply.resolve_states(ctx, kin, s)
        labels = {j.name: ctx.asset.link(j.child).semantic_label for j in ctx.asset.movable_joints()}
        centers, vols = part_boxes(ctx)
        heights = {n: float(c[2]) for n, c in centers.items()}
        ranges = {n: c.open_range for n, c in ctx.closed.items()}
        return res, labels, vols, heights, (s, note), ranges


def joint_of(labels: dict[str, str], label: str) -> list[str]:
    return sorted(n for n, lab in labels.items() if lab == label)


# ------------------------------------------------------------------ 1. parts named as people name them
def test_a_toasters_lever_is_its_slider(generated):
    res, labels, *_ = resolve(generated["toaster"], "A two-slot toaster with its lever up and a spring-loaded lever.")
    (slider,) = joint_of(labels, "slider")
    assert res.unapplied == [] and slider in res.targets and res.targets[slider].kind == "end"
    assert any("synonym" in n and "'lever' = the 'slider'" in n and slider in n for n in res.notes)


@pytest.mark.parametrize("obj, text, label", [
    ("printer", "A laser printer with its paper tray open.", "drawer"),
    ("lamp", "A desk lamp with its arm raised all the way.", "leg"),
])
def test_a_part_word_names_the_label_its_category_gives_the_part(generated, obj, text, label):
    """A printer's paper tray is the part PartNet-Mobility labels ``drawer`` and a desk lamp's arm its ``leg``
    (``label_synonyms`` of the category): the state reaches that part. Before, each phrase was "no part of this
    Printer / Lamp carries that label" and the request was not met."""
    res, labels, *_ = resolve(generated[obj], text)
    named = joint_of(labels, label)
    assert named and res.unapplied == [] and set(named) & set(res.addressed), (res.unapplied, res.addressed)
    assert any("synonym" in n and f"'{label}'" in n for n in res.notes), res.notes


def test_a_fans_blades_are_its_rotor(generated):
    """"its blades spinning freely" on a fan whose blades are labelled ``rotor``: the motion word reaches the rotor
    (it used to name "a 'blade' but this Fan has no such moving part")."""
    text = "A large pedestal fan with its blades spinning freely."
    with build_context(generated["fan"], text) as (ctx, _):
        (rotor,) = [j.name for j in ctx.asset.movable_joints() if ctx.asset.link(j.child).semantic_label == "rotor"]
        choices, missing = joint_dynamics.motion_choices(ctx, [])
    assert missing == [] and choices[rotor].free_moving


@needs_shared
def test_a_pressed_lever_is_at_its_far_end_and_a_part_lying_flat_is_opened_flat():
    """A flush lever or button pressed is its far end (its spring returns it to the closed end), a stapler's arm
    pressed down its closed end; "its screen lying flat" is the screen's state (opened flat), not the laptop's pose."""
    res, labels, *_ = resolve(SHARED / "102703", "A toilet with the flush lever pressed.")
    (lever,) = joint_of(labels, "lever")
    assert res.unapplied == [] and res.bands[lever] == "fully"
    assert parse_request("A toilet with its flush button pushed in.").joint_states[0].band == "fully"
    assert parse_request("A cabinet with the drawers pushed in.").joint_states[0].band == "closed"
    spec = parse_request("A laptop with its screen lying flat.")
    assert spec.pose_hint is None and [(j.label, j.band) for j in spec.joint_states] == [("screen", "fully")]
    res, labels, *_ = resolve(SHARED / "9748", spec.text)
    assert res.unapplied == [] and [res.bands[j] for j in res.addressed] == ["fully"]
    assert parse_request("A suitcase lying flat with its lid closed.").pose_hint == "lying_flat"


def test_a_pump_pressed_part_of_the_way_is_that_far_from_its_rest(generated):
    """A pump dispenser's pump (PartNet-Mobility's ``pump_lid``) rests up, its closed end, as a push button does
    (``part_priors.push_buttons``): pressed, it is at its far end; pressed halfway, half its travel; pressed a little,
    a little from its rest. "pressed" and "halfway" used to be two states of every part, in contradiction, and the
    pump was no part word: the request was not met. A stapler's arm rests open: pressed, it is closed."""
    (pump,) = joint_of(resolve(generated["dispenser"], "A soap dispenser.")[1], "pump_lid")
    for text, band in [("A soap dispenser with its pump pressed halfway.", "halfway"),
                       ("A lotion dispenser with the pump slightly pressed.", "slightly_open"),
                       ("A soap dispenser with its pump pressed.", "fully"), ("A soap dispenser, halfway pressed.", "halfway")]:
        res, *_ = resolve(generated["dispenser"], text)
        assert res.unapplied == [] and res.bands[pump] == band, (text, res.bands, res.unapplied)
        assert not parse_request(text).warnings, text
    assert [(j.label, j.band) for j in parse_request("A stapler with its arm slightly pressed.").joint_states] == [("arm", "mostly")]
    assert [(j.label, j.band) for j in parse_request("A printer with its button pressed a little.").joint_states] == [
        ("button", "slightly_open")]
    assert [(j.label, j.band) for j in parse_request("A box with its lid pushed half closed.").joint_states] == [("lid", "halfway")]
    with build_context(generated["dispenser"], "A soap dispenser.") as (ctx, _):
        end = ctx.closed[pump]  # the builder's slide points down: pressed is its upper limit, the rest its lower
        assert end.q_closed == pytest.approx(end.lower) and end.direction == 1.0


def test_open_then_closed_for_one_part_is_a_contradiction_in_either_order():
    """A lone "open" gives way quietly only to a more exact opening of the same part ("its door open, halfway");
    followed by "closed" it is a contradiction, warned as "closed" then "open" was. It used to be dropped unwarned."""
    for text, band in [("A microwave with its door open, the door closed.", "closed"),
                       ("A microwave with its door closed, the door open.", "mostly")]:
        spec = parse_request(text)
        assert [(j.label, j.band) for j in spec.joint_states] == [("door", band)]
        assert len(spec.warnings) == 1 and spec.warnings[0].startswith("contradiction"), spec.warnings
    spec = parse_request("A microwave with its door open, halfway.")
    assert [(j.label, j.band) for j in spec.joint_states] == [("door", "halfway")] and not spec.warnings


@needs_shared
def test_a_state_asked_of_a_part_on_a_fixed_joint_says_it_does_not_move():
    """Trash can 102155's wheels are in semantics.txt but on fixed joints: "its wheel fully open" is not applied
    because the wheel does not move, not because the object has no wheel; a part it lacks still says so."""
    res, *_ = resolve(SHARED / "102155", "A trash can with its wheel fully open.")
    ((phrase, why),) = res.unapplied
    assert phrase == "wheel fully open" and "wheel is on a fixed joint (it does not move)" in why and "no part" not in why
    res, *_ = resolve(SHARED / "102155", "A trash can with its drawer open.")
    assert "no part of this TrashCan carries that label" in res.unapplied[0][1]


@needs_shared
def test_a_staplers_arm_is_its_lid():
    res, labels, *_ = resolve(SHARED / "103275", "a heavy 2 lb stapler with a stiff spring-loaded arm pressed down")
    (lid,) = joint_of(labels, "lid")
    assert res.unapplied == [] and lid in res.addressed and res.bands[lid] == "closed"
    assert res.requests[lid].phrase == "arm pressed down"
    (mass,) = [p for p in parse_request("a heavy 2 lb stapler").properties if p.mass is not None]
    assert mass.mass == pytest.approx(2 * 0.45359237)


@needs_shared
def test_a_synonym_never_reaches_a_part_it_does_not_name():
    """A microwave has no lever, slider, switch or handle: "lever up" moves nothing and is reported."""
    res, *_ = resolve(SHARED / "7119", "A microwave with its lever up and the door closed.")
    assert [p for p, _ in res.unapplied] == ["lever up"] and set(res.addressed) == {"joint_0"}


@needs_shared
def test_freezer_door_is_the_smaller_door_and_main_door_the_larger():
    res, labels, vols, *_ = resolve(SHARED / "11178", "a fridge with the freezer door open 90 degrees and the main door closed")
    small, large = sorted(joint_of(labels, "door"), key=vols.get)
    assert vols[small] < 0.95 * vols[large]
    t = res.targets[small]
    assert t.kind == "angle" and t.asked == pytest.approx(math.pi / 2)
    assert res.bands[large] == "closed" and large not in res.targets
    assert not [w for w in parse_request("a fridge with the freezer door open 90 degrees and the main door closed").warnings
                if "contradiction" in w]
    assert any("freezer door" in n and small in n and "smallest of 2" in n for n in res.notes)


def test_middle_drawer_of_three_is_the_middle_one(generated):
    res, labels, _, heights, *_ = resolve(generated["chest"], "a three-drawer cabinet with the middle drawer open")
    top, middle, bottom = sorted(joint_of(labels, "drawer"), key=lambda n: -heights[n])
    assert res.bands[middle] == "mostly" and res.bands[top] == res.bands[bottom] == "closed" and res.unapplied == []


@needs_shared
def test_a_part_the_object_lacks_moves_nothing():
    """"the middle drawer" of a two-drawer cabinet: no drawer opens, the phrase is reported as not applied."""
    res, labels, *_ = resolve(SHARED / "19179", "a three-drawer cabinet with the middle drawer open")
    assert all(res.bands[n] == "closed" for n in joint_of(labels, "drawer")) and not res.addressed
    ((phrase, why),) = res.unapplied
    assert phrase == "middle drawer open" and "2 drawers" in why


def test_top_and_bottom_drawers(generated):
    res, labels, _, heights, *_ = resolve(generated["chest"], "a cabinet with the top drawer open and the bottom drawer half open")
    top, middle, bottom = sorted(joint_of(labels, "drawer"), key=lambda n: -heights[n])
    assert (res.bands[top], res.bands[middle], res.bands[bottom]) == ("mostly", "closed", "halfway")


@needs_shared
def test_one_door_open_and_the_other_shut_opens_exactly_one():
    res, labels, *_ = resolve(SHARED / "11178", "A refrigerator with one door wide open and the other shut.")
    bands = sorted(res.bands[n] for n in joint_of(labels, "door"))
    assert bands == ["closed", "fully"]
    assert not [w for w in res.warnings if "door(s)" in w]  # "one door" is not a count of doors


@needs_shared
def test_seat_and_lid_both_up_moves_both():
    res, labels, *_ = resolve(SHARED / "102703", "A toilet with its seat and lid both up.")
    for label in ("seat", "lid"):
        (j,) = joint_of(labels, label)
        # raised past upright, each rests at the end of its travel: "up" is that end (the evaluation grades a travel end)
        assert res.targets[j].kind == "end" and res.targets[j].fraction == 1.0, (label, res.targets.get(j))
        assert "travel end" in res.targets[j].note


# ------------------------------------------------------------------ 2. clauses and hedges
@needs_shared
def test_a_missing_parts_clause_does_not_leak_into_the_door():
    res, labels, *_ = resolve(SHARED / "7119", "A microwave with its door open about halfway and its shelf pulled out.")
    (door,) = joint_of(labels, "door")
    assert res.bands[door] == "halfway" and door not in res.targets
    assert [p for p, _ in res.unapplied] == ["shelf pulled out"]


@needs_shared
@pytest.mark.parametrize("text,lo,hi", [
    ("A microwave with its door a little less than halfway open", 0.3, 0.49),
    ("A microwave with its door slightly more than halfway open", 0.51, 0.7),
])
def test_comparatives_around_halfway(text, lo, hi):
    res, labels, *_ = resolve(SHARED / "7119", text)
    (door,) = joint_of(labels, "door")
    t = res.targets[door]
    assert t.kind == "fraction" and lo <= t.fraction <= hi
    assert (t.interval[1] < 0.5) if hi < 0.5 else (t.interval[0] > 0.5)  # the whole acceptance interval on its side of half
    assert t.fraction == pytest.approx(LESS_THAN_HALF if hi < 0.5 else 1 - LESS_THAN_HALF)


@needs_shared
@pytest.mark.parametrize("text", ["A trash can with the lid mostly closed", "A trash can with the lid barely open",
                                  "A trash can with its lid almost shut"])
def test_mostly_closed_is_a_small_opening_not_closed(text):
    res, labels, *_ = resolve(SHARED / "102181", text)
    (lid,) = joint_of(labels, "lid")
    assert res.bands[lid] == "slightly_open"


# ------------------------------------------------------------------ 3. quantities
def test_a_bottles_volume_sets_its_size_with_the_reasoning(generated):
    res, _, _, _, (s, note), _ = resolve(generated["bottle"], "a 500 ml plastic water bottle with its cap unscrewed halfway")
    assert "'500 ml'" in note and "convex hull" in note
    with build_context(generated["bottle"], "a 500 ml bottle") as (ctx, kin):
        assert ctx.closed_volume * s ** 3 == pytest.approx(5e-4, rel=1e-6)
        overlay = Overlay(estimator=EstimatorInfo(name="test"), scale=s)
        (q,) = [x for x in request_findings.findings(ctx, {}, {}, {}, overlay).quantities if x.what == "volume"]
        assert q.within_tolerance and q.unit == "m^3"


def test_a_volume_beside_a_length_is_named_as_not_used_and_no_spurious_contradiction(generated):
    text = "a 500 ml plastic water bottle, 20 cm tall, with its cap unscrewed halfway"
    spec = parse_request(text)
    assert [s.dimension for s in spec.sizes] == ["height"] and "ml" not in spec.ignored
    assert any("'500 ml'" in w and "not used" in w for w in spec.warnings)
    assert not [w for w in spec.warnings if "contradiction" in w]
    res, labels, *_ = resolve(generated["bottle"], text)
    (cap,) = joint_of(labels, "lid")  # the bottle's cap is labelled lid
    assert res.bands[cap] == "halfway" and res.unapplied == []


# ------------------------------------------------------------------ 4. one frame
@needs_shared
def test_an_angle_is_measured_from_the_closed_end():
    res, labels, _, _, _, ranges = resolve(SHARED / "101668", "a carry-on suitcase lying flat with the lid open 30 degrees")
    (lid,) = joint_of(labels, "lid")
    t = res.targets[lid]
    assert t.fraction * ranges[lid] == pytest.approx(math.radians(30), rel=1e-9)


def test_the_progress_line_shows_a_number_as_asked_not_as_a_band():
    spec = parse_request("a microwave with the door open 2 inches and the lid at 30 degrees, the drawer 40 % open, the lever up")
    short = [js.short() for js in spec.joint_states]
    assert "door=50.8 mm from closed" in short and "lid=30 deg from closed" in short
    assert "drawer=40 %" in short and "lever=up" in short
    assert not any("halfway" in s for s in short)


@needs_shared
def test_the_words_resolve_as_people_name_the_parts():
    """Refine's one reading of a request (the state, the as-asked tier and an output read back all use it): the
    stapler's arm is its lid, the freezer door the smaller one, a middle drawer of two is none."""
    res, labels, *_ = resolve(SHARED / "103275", "a stapler with its arm pressed down")
    assert [labels[n] for n in res.addressed] == ["lid"] and res.unapplied == []
    res, _, *_ = resolve(SHARED / "19179", "a cabinet with the middle drawer open")
    assert not res.addressed and [p for p, _ in res.unapplied] == ["middle drawer open"]
    res, labels, vols, *_ = resolve(SHARED / "11178", "a fridge with the freezer door open")
    small = min(joint_of(labels, "door"), key=vols.get)
    assert set(res.addressed) == {small} and res.bands[small] == "mostly"


@needs_shared
def test_the_summary_prints_the_amount_from_the_closed_end_beside_what_was_asked(refine_once):
    """One refine of a suitcase lying flat, the lid asked 30 degrees: the summary's state line says "30.0 deg from
    closed (asked 30 deg)" for the lid, with its label."""
    res = refine_once(SHARED / "101668", "a carry-on suitcase lying flat with the lid open 30 degrees", extras=False).result
    (line,) = [ln for ln in summary_lines(res) if ln.startswith("initial state")]
    (lid,) = [part for part in line.split(", joint_") if "(lid)" in part]
    assert "30.0 deg from closed (asked 30 deg)" in lid and "% open" in line
    # each phrase with the part it set, the amount set and the amount asked
    assert res.report.request.phrases == [line.removeprefix("request      ") for line in summary_lines(res) if line.startswith("request      '")]
    (phrase,) = res.report.request.phrases
    assert phrase.startswith("'lid open 30 degrees': joint_2 (lid) 30.0 deg from closed,") and phrase.endswith("(asked 30 deg from closed)")


@needs_shared
def test_a_size_word_without_a_part_noun_picks_among_the_task_relevant_parts():
    """"the freezer open": the smaller door."""
    res, labels, vols, *_ = resolve(SHARED / "11178", "A fridge with the freezer open.")
    small = min(joint_of(labels, "door"), key=vols.get)
    assert set(res.addressed) == {small} and res.bands[small] == "mostly"


def test_none_of_the_parts_negates_the_state():
    (js,) = parse_request("A cabinet with none of the drawers open.").joint_states
    assert (js.label, js.band, js.target) == ("drawer", "closed", None)
    (js,) = parse_request("A fridge with neither of its doors closed.").joint_states
    assert (js.label, js.band) == ("door", "mostly")


def test_smaller_or_main_of_parts_of_one_size_names_none(tmp_path):
    """Two doors of one size (a generated double-door cabinet): "the smaller door" and "the main door" move nothing,
    and say why; "the left door" still picks one."""
    folder = build_double_door_cabinet(tmp_path / "cabinet")
    for text, phrase in (("A cabinet with the smaller door open.", "smaller door open"), ("A cabinet with the main door open.", "main door open")):
        res, *_ = resolve(folder, text)
        assert not res.addressed and [p for p, _ in res.unapplied] == [phrase]
        assert "one size" in res.unapplied[0][1]
    res, *_ = resolve(folder, "A cabinet with the left door open.")
    assert len(res.addressed) == 1


def test_a_toasters_lever_refined_down_is_said_with_its_label_and_phrase(generated, tmp_path, refine_once):
    """End to end on the generated toaster (its lever labelled ``slider``): "lever pushed down" sets the slider's
    lowest end, and the summary names the part and the phrase."""
    res = refine_once(generated["toaster"], "A toaster with its lever pushed down.", extras=False)
    lines = summary_lines(res.result)
    (state,) = [ln for ln in lines if ln.startswith("initial state")]
    assert "joint_0 (slider) = " in state and "(asked 'lever pushed down'), 100 % open" in state
    assert res.report.request.phrases[0].startswith("'lever pushed down': joint_0 (slider)")
    assert res.report.metric("request_met").passed


def test_a_cap_off_is_taken_off_and_on_is_in_place(generated):
    """"the cap off" on a bottle (its cap labelled ``lid``): fully open, not the valve convention's closed."""
    res, labels, *_ = resolve(generated["bottle"], "A bottle with its cap off.")
    (cap,) = joint_of(labels, "lid")
    assert res.targets[cap].kind == "end" and res.targets[cap].fraction == 1.0
    res, *_ = resolve(generated["bottle"], "A bottle with the cap on.")
    assert res.targets[cap].fraction == 0.0


@needs_shared
def test_a_faucet_handle_on_or_off_reads_as_turned_on_or_off():
    """A faucet's handle (label switch) turns flat, so no height tells "on" from "off": "handle off" is its closed end
    and "handle on" its far end, as "turned off" / "turned on" read; neither fails as not applied."""
    for text, fraction in (("a faucet, handle off", 0.0), ("a faucet with the handle on", 1.0)):
        res, *_ = resolve(SHARED / "148", text)
        assert res.unapplied == [] and res.targets["joint_0"].fraction == fraction, text
