"""The as-asked verdict (asset2sim.tasks.check.as_asked): a request phrase naming a part or a state that was
not applied, or a number missed beyond its tolerance, fails ``request_met``; on constructed inputs."""

from __future__ import annotations

import math

import pytest

from asset2sim.schemas.report import MetricResult
from asset2sim.schemas.request import JointStateRequest, MotionPhrase, QuantityOutcome, RequestFindings, RequestSpec, StateTarget
from asset2sim.tasks.check import as_asked
from asset2sim.tasks.check.verdict import readiness
from asset2sim.tasks.geometry.closed_state import ClosedState
from asset2sim.tasks.interpret.request import parse_request
from asset2sim.tasks.synthesize.request_apply import StateResolution

LID = JointStateRequest(selector="label", label="lid", band="halfway", target=StateTarget(kind="angle", value=math.radians(30)),
                        phrase="lid open 30 degrees")


def _spec(text: str, *states: JointStateRequest, **kw) -> RequestSpec:
    return RequestSpec(text=text, joint_states=list(states), matched=[s.phrase for s in states] or [text], **kw)


def _angle(asked_deg: float, got_deg: float, ok: bool) -> QuantityOutcome:
    return QuantityOutcome(what="joint_2 angle", phrase="lid open 30 degrees", asked=math.radians(asked_deg),
                           achieved=math.radians(got_deg), unit="rad", within_tolerance=ok, kind="state")


def test_a_phrase_not_applied_fails():
    res = StateResolution(bands={}, unapplied=[("lever up", "the request names a 'lever' but no part of this Toaster carries that "
                                                            "label; its moving parts: slider; 'lever up' not applied")])
    lever = JointStateRequest(selector="label", label="lever", band="fully", target=StateTarget(kind="end", end="high"), phrase="lever up")
    m = as_asked.refine_request_met(_spec("A two-slot toaster with its lever up", lever), res, RequestFindings(), {}, {})
    assert m.name == "request_met" and m.passed is False and m.value == 1.0 and m.engine == "none"
    (item,) = m.details["unmet"]
    assert item["phrase"] == "lever up" and item["kind"] == "not_applied" and "'lever up' not applied" in item["text"]
    assert readiness([m]).failure_mode == "request_not_met"


def test_a_numeric_angle_missed_fails_with_its_gap_from_the_closed_end():
    found = RequestFindings(quantities=[_angle(30.0, 20.8, ok=False)])
    m = as_asked.refine_request_met(_spec("a suitcase with the lid open 30 degrees", LID), StateResolution(bands={}), found, {}, {})
    assert m.passed is False
    (item,) = m.details["unmet"]
    assert item["phrase"] == "lid open 30 degrees" and item["joint"] == "joint_2" and item["unit"] == "rad"
    assert item["target"] == pytest.approx(0.5236, abs=1e-4) and item["achieved"] == pytest.approx(0.3630, abs=1e-4)
    assert item["gap"] == pytest.approx(math.radians(9.2), abs=1e-6)
    assert item["tolerance"] == pytest.approx(0.05 * math.radians(30))
    assert item["measured_from"] == "closed end"
    assert "20.8 deg from the closed end, asked 30.0 deg (gap 9.2 deg" in item["text"]


def test_a_met_request_passes():
    closed = {"joint_2": ClosedState("joint_2", q_closed=-0.785, direction=1.0, open_range=2.0, lower=-0.785, upper=1.215)}
    half = JointStateRequest(selector="label", label="lid", band="halfway", phrase="lid half open")
    res = StateResolution(bands={"joint_2": "halfway"}, requests={"joint_2": half})
    found = RequestFindings(quantities=[_angle(30.0, 30.5, ok=True)])
    m = as_asked.refine_request_met(_spec("a suitcase with its lid half open", half), res, found, closed, {"joint_2": -0.785 + 1.0})
    assert m.passed is True and m.value == 0.0 and m.details["unmet"] == [] and m.details["graded"] == 2
    assert readiness([m]).ready


def test_no_request_is_not_measured():
    assert as_asked.refine_request_met(RequestSpec(), None, None, {}, {}).passed is None
    m = as_asked.refine_request_met(RequestSpec(text="bitte schön"), None, None, {}, {})  # nothing understood
    assert m.passed is None and "understood" in m.details["reason"]
    assert readiness([m]).tiers["request"] is None


def test_a_band_missed_by_more_than_the_slack_fails_and_one_inside_passes():
    closed = {"j": ClosedState("j", q_closed=0.0, direction=-1.0, open_range=2.0, lower=-2.0, upper=0.0)}
    half = JointStateRequest(selector="label", label="door", band="halfway", phrase="door half open")
    res = StateResolution(bands={"j": "halfway"}, requests={"j": half})
    m = as_asked.refine_request_met(_spec("the door half open", half), res, RequestFindings(), closed, {"j": -0.2})  # 10 % open
    (item,) = m.details["unmet"]
    assert m.passed is False and item["kind"] == "band" and item["achieved"] == pytest.approx(0.1)
    assert item["gap"] == pytest.approx(0.25) and item["target"] == [0.35, 0.65]
    edge = -(0.35 - as_asked.BAND_SLACK / 2) * 2.0  # inside the slack
    assert as_asked.refine_request_met(_spec("the door half open", half), res, RequestFindings(), closed, {"j": edge}).passed


def test_a_state_naming_no_part_is_the_main_parts_state():
    """"A suitcase, mostly open" sets the lid (the first of a suitcase's task-relevant parts) and the carrying handle:
    the lid at 3 % fails it, whatever the handle's opening; the handle is reported, not graded. Without ranks (no
    part of the category's list) one joint in the band still meets it."""
    closed = {j: ClosedState(j, q_closed=0.0, direction=1.0, open_range=1.0, lower=0.0, upper=1.0) for j in ("lid", "handle")}
    mostly = JointStateRequest(selector="all", band="mostly", phrase="mostly open")
    res = StateResolution(bands={"lid": "mostly", "handle": "mostly"}, requests={"lid": mostly, "handle": mostly})
    spec = _spec("A suitcase, mostly open.", mostly)
    state = {"lid": 0.03, "handle": 0.75}
    m = as_asked.refine_request_met(spec, res, RequestFindings(), closed, state, ranks={"lid": 0, "handle": 1})
    (item,) = m.details["unmet"]
    assert m.passed is False and item["joint"] == "lid" and item["achieved"] == pytest.approx(0.03)
    m = as_asked.refine_request_met(spec, res, RequestFindings(), closed, {"lid": 0.75, "handle": 0.03}, ranks={"lid": 0, "handle": 1})
    assert m.passed is True and [n["joint"] for n in m.details["not_graded"]] == ["handle"]
    assert as_asked.refine_request_met(spec, res, RequestFindings(), closed, state).passed is True


def test_words_the_parser_did_not_use_and_reported_joint_parameters_do_not_fail():
    spec = _spec("a box made of wood, smells nice", ignored=["smells nice"])
    damping = QuantityOutcome(what="joint_0 damping", phrase="damping 0.5", asked=0.5, achieved=2.0, unit="N*m*s/rad",
                              within_tolerance=False, kind="dynamics")
    m = as_asked.refine_request_met(spec, StateResolution(bands={}), RequestFindings(ignored=["smells nice"], quantities=[damping]), {}, {})
    assert m.passed is True


def test_a_phrase_a_later_one_replaced_for_the_same_part_fails():
    spec = parse_request("a fridge with the door open 90 degrees and then the door closed")
    assert spec.overridden == ["door open 90 degrees"]
    m = as_asked.refine_request_met(spec, StateResolution(bands={}), RequestFindings(), {}, {})
    (item,) = m.details["unmet"]
    assert m.passed is False and item["phrase"] == "door open 90 degrees" and "'door closed'" in item["reason"]


def test_a_mass_or_size_missed_fails_and_a_part_property_on_a_missing_part_fails():
    found = RequestFindings(quantities=[
        QuantityOutcome(what="total mass", phrase="2 kg", asked=2.0, achieved=2.5, unit="kg", within_tolerance=False, kind="mass"),
        QuantityOutcome(what="size", phrase="30 cm tall", asked=0.3, achieved=0.3, unit="m", within_tolerance=True, kind="size")])
    m = as_asked.refine_request_met(_spec("a 2 kg box 30 cm tall with a steel drawer"), StateResolution(bands={}), found, {}, {},
                                    [("steel drawer", "names a 'drawer' but this Box has no such part")])
    assert m.passed is False and m.value == 2.0
    mass = next(u for u in m.details["unmet"] if u["kind"] == "mass")
    assert mass["gap"] == pytest.approx(0.5) and "2.5 kg, asked 2 kg" in mass["text"] and "measured_from" not in mass
    assert any(u["phrase"] == "steel drawer" and u["kind"] == "not_applied" for u in m.details["unmet"])


def test_quantities_read_for_people():
    assert as_asked.quantity_text(math.radians(20.8), "rad") == "20.8 deg"
    assert as_asked.quantity_text(0.0125, "m") == "12.5 mm" and as_asked.quantity_text(1.5, "m") == "1.5 m"
    assert as_asked.quantity_text(0.18, "opening fraction") == "18.0 % of the range"
    assert as_asked.quantity_text(None, "kg") == "-"


@pytest.mark.parametrize("kind, phrase, advice", [("stiff", "stiff", "Drop the word"),
                                                  ("hold", "holds its position", "at an end of its range"),
                                                  ("spring", "spring-loaded", "where its spring rests"),
                                                  ("self_closing", "swings shut on its own", "cannot open it against that pull")])
def test_a_word_that_makes_a_part_too_hard_to_work_gets_advice_that_fits_it(kind: str, phrase: str, advice: str) -> None:
    """A part no hand inside its range can work: "stiff" made it so (drop the word; its state does not matter), "holds
    its position" needs friction to hold it where asked (an end of its range needs less), a spring needs friction to
    hold the part away from where the spring rests, and a closer, whose friction the word keeps low, pulls past a hand
    itself where it must outpull the part's weight everywhere to shut it."""
    operability = MetricResult(name="operability", value=1.0, unit="parts", passed=False, engine="pybullet",
                               details={"failing": ["joint_1"]})
    asked = MetricResult(name="request_met", value=0.0, unit="unmet phrases", passed=True, engine="none", details={})
    metrics = as_asked.word_conflicts([operability, asked], [(MotionPhrase(kind=kind, phrase=phrase), ["joint_1"])])
    (item,) = next(m for m in metrics if m.name == "request_met").details["unmet"]
    assert item["kind"] == "conflict" and advice in item["text"]
    assert kind != "stiff" or "end of its range" not in item["text"] and "holding" not in item["text"]
