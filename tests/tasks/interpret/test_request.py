"""Tests of asset2sim.tasks.interpret.request.parse_request."""

from __future__ import annotations

import csv
import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from asset2sim.schemas.request import BAND_TARGET, RequestSpec
from asset2sim.tasks.interpret.size_priors import size_factor
from asset2sim.tasks.interpret.request import parse_request
from tests.conftest import NO_SHARED, SHARED as DATASET


def states(spec: RequestSpec) -> list[tuple[str, str | None, int | None, str]]:
    return [(j.selector, j.label, j.ordinal, j.band) for j in spec.joint_states]


# Expected values written by reading each manifest prompt.
# id: (prompt, category_hint, size_class, joint states, damping, holds, spring, stiff, free, pose)
MANIFEST_EXPECTED = {
    "103275": ("I want a slightly open stapler.",
               "Stapler", None, [("all", None, None, "slightly_open")], "moderate", False, False, False, False, None),
    "100221": ("A very small jewelry box or treasure chest with a slightly open rotational lid. Low damping for smooth hinge behavior.",
               "Box", "very_small", [("label", "lid", None, "slightly_open")], "low", False, False, False, False, None),
    "7236": ("I want a microwave with its door halfway open. Low damping for hinge-like behavior.",
             "Microwave", None, [("label", "door", None, "halfway")], "low", False, False, False, False, None),
    "102703": ("I want a very small toilet for a baby, with its lid fully open. Low damping for hinge-like behavior.",
               "Toilet", "very_small", [("label", "lid", None, "fully")], "low", False, False, False, False, None),
    "9912": ("I want a slightly open laptop. Low damping for smooth operation.",
             "Laptop", None, [("all", None, None, "slightly_open")], "low", False, False, False, False, None),
    "101673": ("I want a small purse or handbag with the handle moving freely, resting sideways.",
               "Bag", "small", [], "low", False, False, False, True, "sideways"),
    "19179": ("I want a very small two-drawer under-desk office cabinet, with the first drawer closed and the second slightly open, with low damping sliding joints.",
              "StorageFurniture", "very_small",
              [("label", "drawer", 0, "closed"), ("label", "drawer", 1, "slightly_open")],
              "low", False, False, False, False, None),
    "103755": ("I want a small business suitcase with its lid slightly open and a low damping hinge.",
               "Suitcase", "small", [("label", "lid", None, "slightly_open")], "low", False, False, False, False, None),
    "102181": ("A very small personal trash can with its lid slightly open. The hinge has low damping and holds its position.",
               "TrashCan", "very_small", [("label", "lid", None, "slightly_open")], "low", True, False, False, False, None),
    "47645": ("A small box with slightly open rotational lid. Low damping for a smooth hinge behavior.",
              "Box", "small", [("label", "lid", None, "slightly_open")], "low", False, False, False, False, None),
    "9748": ("I want a slightly open laptop. Low damping for smooth operation.",
             "Laptop", None, [("all", None, None, "slightly_open")], "low", False, False, False, False, None),
    "7119": ("I want a microwave opening its door halfway. Low damping for hinge-like behavior.",
             "Microwave", None, [("label", "door", None, "halfway")], "low", False, False, False, False, None),
    "102990": ("I want a slightly open stapler, with spring behavior in its joint for pressing/stapling.",
               "Stapler", None, [("all", None, None, "slightly_open")], "moderate", False, True, False, False, None),
    "102622": ("I want a very small toilet for a baby, with its lid open all the way. Low damping for hinge-like behavior.",
               "Toilet", "very_small", [("label", "lid", None, "fully")], "low", False, False, False, False, None),
    "102155": ("A very small, personal trash can with its lid slightly open. The lid hinge has low damping and holds its position.",
               "TrashCan", "very_small", [("label", "lid", None, "slightly_open")], "low", True, False, False, False, None),
    "20279": ("A small bedside cabinet with every drawer closed. Smooth, low damping drawer slides.",
              "StorageFurniture", "small", [("label", "drawer", None, "closed")], "low", False, False, False, False, None),
    "101668": ("A carry-on suitcase lying flat with its lid half open.",
               "Suitcase", "small", [("label", "lid", None, "halfway")], "moderate", False, False, False, False, "lying_flat"),
    "12085": ("A compact countertop dishwasher with its door slightly open. The door hinge holds its position.",
              "Dishwasher", "small", [("label", "door", None, "slightly_open")], "moderate", True, False, False, False, None),
    "11178": ("A mini fridge for a dorm room with its door a quarter open.",
              "Refrigerator", "small", [("label", "door", None, "quarter")], "moderate", False, False, False, False, None),
    "8877": ("A small cabinet-sized door in its frame, closed, with a heavy, well-damped hinge.",
             "Door", "small", [("label", "door", None, "closed")], "high", False, False, True, False, None),
    "148": ("A kitchen faucet with its handle turned off and a stiff handle joint.",
            "Faucet", None, [("label", "handle", None, "closed")], "moderate", False, False, True, False, None),
}


@pytest.mark.parametrize("asset_id", sorted(MANIFEST_EXPECTED))
def test_manifest_prompts(asset_id: str) -> None:
    prompt, cat, size, js, damping, holds, spring, stiff, free, pose = MANIFEST_EXPECTED[asset_id]
    spec = parse_request(prompt)
    assert spec.text == prompt
    assert spec.category_hint == cat
    assert spec.size_class == size
    assert spec.size_factor == pytest.approx(size_factor(size))
    assert states(spec) == js
    assert spec.damping == damping
    assert spec.holds_position is holds
    assert spec.spring is spring
    assert spec.stiff is stiff
    assert spec.free_moving is free
    assert spec.pose_hint == pose
    for j in spec.joint_states:
        assert j.phrase, "every joint state keeps the words it came from"
        assert j.phrase.split()[-1] in " ".join(spec.matched) or j.phrase in prompt.lower()


def test_manifest_prompts_match_the_dataset() -> None:
    manifest = DATASET / "manifest.csv"
    if not manifest.exists():
        pytest.skip(NO_SHARED)
    rows = {r["id"]: r["prompt"] for r in csv.DictReader(manifest.open())}
    assert set(rows) == set(MANIFEST_EXPECTED)
    for asset_id, (prompt, *_rest) in MANIFEST_EXPECTED.items():
        assert rows[asset_id] == prompt


def test_matched_lists_the_recognised_phrases() -> None:
    spec = parse_request(MANIFEST_EXPECTED["102181"][0])
    assert spec.matched == [
        "very small", "personal", "trash can", "slightly open", "low damping", "holds its position",
    ]
    assert spec.size_phrase == "very small, personal"
    spec = parse_request(MANIFEST_EXPECTED["8877"][0])
    assert "cabinet-sized" in spec.matched and "well-damped" in spec.matched and "heavy" in spec.matched


# ----------------------------------------------------------------- state words


@pytest.mark.parametrize(
    "text, band",
    [
        ("a box with its lid closed", "closed"),
        ("a box with its lid shut", "closed"),
        ("the lid is fully closed", "closed"),
        ("a faucet with its handle switched off", "closed"),
        ("the lid is not open", "closed"),
        ("a box with its lid slightly open", "slightly_open"),
        ("a box with its lid ajar", "slightly_open"),
        ("a box with its lid a bit open", "slightly_open"),
        ("a box with its lid cracked open", "slightly_open"),
        ("a box with its lid opened slightly", "slightly_open"),
        ("the lid not quite closed", "slightly_open"),
        ("a fridge with its door a quarter open", "quarter"),
        ("a fridge with its door quarter-open", "quarter"),
        ("a fridge with its door open a quarter of the way", "quarter"),
        ("a microwave with its door halfway open", "halfway"),
        ("a microwave with its door half open", "halfway"),
        ("a microwave with its door half-open", "halfway"),
        ("a microwave with its door open halfway", "halfway"),
        ("a microwave with its door partially open", "halfway"),
        ("a box whose lid is not closed", "halfway"),
        ("a laptop with its screen mostly open", "mostly"),
        ("a laptop with its screen almost fully open", "mostly"),
        ("a laptop with its screen three quarters open", "mostly"),
        ("a laptop with its screen not fully open", "mostly"),
        ("a laptop with its screen open", "mostly"),
        ("a laptop with its screen fully open", "fully"),
        ("a laptop with its screen open all the way", "fully"),
        ("a laptop with its screen all the way open", "fully"),
        ("a laptop with its screen wide open", "fully"),
        ("a faucet with its handle turned on", "fully"),
    ],
)
def test_state_bands(text: str, band: str) -> None:
    spec = parse_request(text)
    assert [j.band for j in spec.joint_states] == [band], spec.joint_states


def test_closed_and_open_are_not_confused() -> None:
    # "closed" contains no "open"; "not open" is closed; "open" alone is not "closed"
    assert [j.band for j in parse_request("the lid closed").joint_states] == ["closed"]
    assert [j.band for j in parse_request("the lid open").joint_states] == ["mostly"]
    assert [j.band for j in parse_request("the lid isn't open").joint_states] == ["closed"]
    spec = parse_request("a cabinet with the top drawer open and the bottom drawer closed")
    assert states(spec) == [("label", "drawer", 0, "mostly"), ("label", "drawer", -1, "closed")]


def test_half_versus_halfway() -> None:
    # "half" alone is not a state; "half the size" is a size
    spec = parse_request("a laptop half the size of a normal one, screen halfway")
    assert spec.size_class == "very_small"
    assert states(spec) == [("label", "screen", None, "halfway")]
    assert parse_request("cut in half").joint_states == []
    assert [j.band for j in parse_request("the lid half open").joint_states] == ["halfway"]


def test_open_as_a_verb_is_not_a_state() -> None:
    assert parse_request("open the door of a regular microwave").joint_states == []
    assert parse_request("I want the door to open smoothly").joint_states == []
    assert parse_request("a box that is easy to open").joint_states == []
    assert parse_request("a microwave").joint_states == []


# ----------------------------------------------------------------- per-joint phrases


@pytest.mark.parametrize(
    "word, ordinal",
    [("first", 0), ("second", 1), ("third", 2), ("fourth", 3), ("fifth", 4),
     ("1st", 0), ("2nd", 1), ("3rd", 2), ("4th", 3), ("5th", 4),
     ("top", 0), ("upper", 0), ("bottom", -1), ("lowest", -1), ("last", -1)],
)
def test_ordinals(word: str, ordinal: int) -> None:
    spec = parse_request(f"a dresser with the {word} drawer slightly open")
    assert states(spec) == [("label", "drawer", ordinal, "slightly_open")]
    assert spec.joint_states[0].phrase == f"{word} drawer slightly open"


def test_elided_noun_inherits_the_label() -> None:
    spec = parse_request("the third drawer three quarters open and the fifth fully open")
    assert states(spec) == [("label", "drawer", 2, "mostly"), ("label", "drawer", 4, "fully")]


def test_enumerated_and_numbered_ordinals() -> None:
    spec = parse_request("a cabinet with the first, second and third drawers closed")
    assert states(spec) == [("label", "drawer", i, "closed") for i in range(3)]
    spec = parse_request("a cabinet with drawers 1 and 2 closed")
    assert states(spec) == [("label", "drawer", 0, "closed"), ("label", "drawer", 1, "closed")]
    spec = parse_request("drawer #3 half open")
    assert states(spec) == [("label", "drawer", 2, "halfway")]


@pytest.mark.parametrize("quant", ["every drawer", "all drawers", "all the drawers", "both drawers", "each drawer"])
def test_quantifiers_select_every_joint_with_the_label(quant: str) -> None:
    spec = parse_request(f"a cabinet with {quant} closed")
    assert states(spec) == [("label", "drawer", None, "closed")]


def test_quantifier_then_exception() -> None:
    spec = parse_request("a dresser with all drawers closed except the top drawer which is slightly open")
    assert states(spec) == [("label", "drawer", None, "closed"), ("label", "drawer", 0, "slightly_open")]


def test_two_parts_one_state_and_two_states() -> None:
    spec = parse_request("a cabinet with the lid and the door slightly open")
    assert states(spec) == [("label", "lid", None, "slightly_open"), ("label", "door", None, "slightly_open")]
    spec = parse_request("a box with its lid open and the drawer closed")
    assert states(spec) == [("label", "lid", None, "mostly"), ("label", "drawer", None, "closed")]


def test_part_words_are_canonicalised() -> None:
    assert states(parse_request("a bin with its cover ajar")) == [("label", "lid", None, "slightly_open")]
    assert states(parse_request("a dishwasher with its rack pulled all the way out")) == [
        ("label", "shelf", None, "fully")
    ]
    assert states(parse_request("a laptop with its display half open")) == [("label", "screen", None, "halfway")]


def test_hyphenated_compounds_are_not_parts() -> None:
    spec = parse_request("a two-drawer cabinet, slightly open")
    assert states(spec) == [("all", None, None, "slightly_open")]


def test_no_state_words_gives_no_joint_states() -> None:
    for text in ["", "a stapler", "a heavy door with a stiff hinge", "I want a microwave. Low damping."]:
        assert parse_request(text).joint_states == []


# ----------------------------------------------------------------- size, dynamics, pose, category


@pytest.mark.parametrize(
    "text, size",
    [
        ("a tiny stapler", "tiny"),
        ("a miniature microwave", "tiny"),
        ("a very small box", "very_small"),
        ("an extra-small box", "very_small"),
        ("a toilet for a baby", "very_small"),
        ("a toy oven", "very_small"),
        ("a small box", "small"),
        ("a mini fridge", "small"),
        ("a compact dishwasher", "small"),
        ("a personal trash can", "small"),
        ("a carry-on suitcase", "small"),
        ("a cabinet-sized door", "small"),
        ("a chair for a child", "small"),
        ("a little box", "small"),
        ("a regular microwave", "regular"),
        ("a standard microwave", "regular"),
        ("a normal-sized microwave", "regular"),
        ("a microwave of normal size", "regular"),
        ("a large suitcase", "large"),
        ("a big suitcase", "large"),
        ("a huge suitcase", "very_large"),
        ("a very large suitcase", "very_large"),
        ("a suitcase", None),
        ("a box that is not small", None),
    ],
)
def test_size_words(text: str, size: str | None) -> None:
    spec = parse_request(text)
    assert spec.size_class == size
    assert spec.size_factor == pytest.approx(size_factor(size))


def test_size_factors_are_ordered() -> None:
    seq = ["a tiny box", "a very small box", "a small box", "a box", "a large box", "a huge box"]
    facs = [parse_request(t).size_factor for t in seq]
    assert facs == sorted(facs) and len(set(facs)) == len(facs)
    assert parse_request("a box").size_factor == 1.0


def test_weak_size_words_need_a_category_after_them() -> None:
    spec = parse_request("a box with the lid a little open")
    assert spec.size_class is None
    assert states(spec) == [("label", "lid", None, "slightly_open")]
    spec = parse_request("a normal hinge on a box")
    assert spec.size_class is None


def test_the_most_extreme_size_word_wins() -> None:
    assert parse_request("a small, very small box").size_class == "very_small"
    assert parse_request("a very small, personal trash can").size_class == "very_small"


@pytest.mark.parametrize(
    "text, damping, free",
    [
        ("a box with low damping", "low", False),
        ("a box with a low-damping hinge", "low", False),
        ("a smooth hinge", "low", False),
        ("the handle moving freely", "low", True),
        ("a door that swings freely", "low", True),
        ("a well-damped hinge", "high", False),
        ("a heavily damped lid", "high", False),
        ("high damping", "high", False),
        ("a heavy hinge", "high", False),
        ("smooth but well-damped", "high", False),
        ("well-damped yet smooth", "high", False),
        ("a box", "moderate", False),
        ("moderate damping", "moderate", False),
    ],
)
def test_damping_words(text: str, damping: str, free: bool) -> None:
    spec = parse_request(text)
    assert spec.damping == damping
    assert spec.free_moving is free


def test_holds_spring_stiff() -> None:
    for t in ["the lid holds its position", "the lid stays where it is", "a lid that holds its state",
              "a door that does not fall under its own weight"]:
        assert parse_request(t).holds_position, t
    for t in ["a springy lid", "a spring-loaded lever", "a lid that returns to closed",
              "spring behavior in its joint", "a self-closing door"]:
        assert parse_request(t).spring, t
    for t in ["a lid without a spring", "no spring in the hinge", "a stapler"]:
        assert not parse_request(t).spring, t
    assert parse_request("a stiff handle joint").stiff
    assert parse_request("a door with heavy hinges").stiff  # heavy before a joint word: stiff
    assert not parse_request("a heavy door").stiff and parse_request("a heavy door").mass_level == "heavy"  # a mass
    assert not parse_request("a door that is not stiff").stiff
    assert "no spring" in parse_request("no spring in the hinge").matched


@pytest.mark.parametrize(
    "text, pose",
    [
        ("a suitcase lying flat", "lying_flat"),
        ("a laptop laid flat on the table", "lying_flat"),
        ("a bag resting sideways", "sideways"),
        ("a trash can lying on its side", "sideways"),
        ("a bottle on its side", "sideways"),
        ("a suitcase standing upright", "upright"),
        ("a bag whose handle swings sideways", None),
        ("a suitcase", None),
    ],
)
def test_pose_words(text: str, pose: str | None) -> None:
    assert parse_request(text).pose_hint == pose


def test_upright_after_a_part_is_that_parts_state() -> None:
    """"the handle upright" is the handle at its raised end, not the object's resting pose."""
    spec = parse_request("A handbag with the handle upright.")
    assert spec.pose_hint is None
    assert [(j.label, j.band, j.target.end, j.phrase) for j in spec.joint_states] == [("handle", "fully", "high", "handle upright")]
    assert parse_request("a suitcase standing upright with the handle up").pose_hint == "upright"


@pytest.mark.parametrize(
    "text, cat",
    [
        ("a small purse", "Bag"),
        ("a handbag", "Bag"),
        ("a jewelry box", "Box"),
        ("a treasure chest", "Box"),
        ("a drawer cabinet", "StorageFurniture"),
        ("a bedside cabinet with every drawer closed", "StorageFurniture"),
        ("a fridge", "Refrigerator"),
        ("a mini-fridge", "Refrigerator"),
        ("a trash bin", "TrashCan"),
        ("a garbage can", "TrashCan"),
        ("a kitchen tap", "Faucet"),
        ("a microwave oven", "Microwave"),
        ("an oven", "Oven"),
        ("a desk lamp", "Lamp"),
        ("a desk", "Table"),
        ("a two-drawer under-desk office cabinet", "StorageFurniture"),
        ("a small cabinet-sized door in its frame", "Door"),
        ("a dishwasher with its door slightly open", "Dishwasher"),
        ("open the door of a microwave", "Microwave"),
        ("a folding chair", "FoldingChair"),
        ("a washing machine", "WashingMachine"),
        ("a usb stick", "USB"),
        ("a spaceship with a hatch", None),
        ("", None),
    ],
)
def test_category_hint(text: str, cat: str | None) -> None:
    assert parse_request(text).category_hint == cat


def test_non_string_is_a_type_error() -> None:
    with pytest.raises(TypeError):
        parse_request(None)  # type: ignore[arg-type]


@settings(max_examples=150, deadline=None)
@given(st.text(alphabet=st.sampled_from(list("abcdefghilmnoprstuvwy -,.'0123456789")), max_size=120))
def test_parse_never_raises_and_is_well_formed(text: str) -> None:
    spec = parse_request(text)
    assert spec.size_factor > 0
    for j in spec.joint_states:
        assert j.band in BAND_TARGET
        assert j.ordinal is None or -1 <= j.ordinal <= 98
        assert (j.selector == "label") == (j.label is not None)


@settings(max_examples=60, deadline=None)
@given(
    st.sampled_from(["lid", "door", "drawer", "screen", "seat"]),
    st.sampled_from(["closed", "slightly open", "a quarter open", "halfway open", "mostly open", "fully open"]),
    st.sampled_from(["a box", "a cabinet", "a toilet", "a fridge", "a laptop", "a thing"]),
)
def test_composed_phrases(part: str, state: str, obj: str) -> None:
    band = {"closed": "closed", "slightly open": "slightly_open", "a quarter open": "quarter",
            "halfway open": "halfway", "mostly open": "mostly", "fully open": "fully"}[state]
    spec = parse_request(f"I want {obj} with its {part} {state}.")
    assert states(spec) == [("label", part, None, band)]


# ------------------------------------------------------------------ length cap and linear time


def test_request_over_the_cap_is_refused_with_a_named_error() -> None:
    from asset2sim.tasks.interpret.request import MAX_REQUEST_CHARS, RequestTooLong

    parse_request("a" * MAX_REQUEST_CHARS)  # at the cap: parsed
    with pytest.raises(RequestTooLong) as err:
        parse_request("a" * (MAX_REQUEST_CHARS + 1))
    assert err.value.code == "REQUEST_TOO_LONG" and err.value.length == MAX_REQUEST_CHARS + 1
    assert isinstance(err.value, ValueError) and "REQUEST_TOO_LONG" in str(err.value)


def test_a_long_request_parses_like_its_sentence() -> None:
    """A request repeated to 32 KiB gives the same reading as once (timings:
    benchmarks/bench_request.py, not a timed test)."""
    sentence = ("I want a very small two-drawer cabinet, with the first drawer closed and the second slightly open; "
                "its door halfway open, low damping and a lid that holds its position. ")
    once = parse_request(sentence)
    many = parse_request(sentence * (32768 // len(sentence)))
    assert (many.size_class, many.damping, many.holds_position, many.category_hint) == (
        once.size_class, once.damping, once.holds_position, once.category_hint)
    assert states(many) == states(once)


@settings(max_examples=300, deadline=None)
@given(st.text(alphabet="abcits' .,;:!?()-\n", max_size=60), st.integers(0, 60))
def test_words_before_a_mention_read_backwards_match_the_split(text: str, i: int) -> None:
    import re

    from asset2sim.tasks.interpret.categories import _last_words

    i = min(i, len(text))
    expected = re.findall(r"[a-z']+", re.split(r"[.,;:!?()]", text[:i])[-1])[-2:]
    assert _last_words(text[::-1], len(text) - i) == expected


def test_unused_words_are_reported_and_a_foreign_request_is_not_understood():
    """Nothing silently ignored: words no rule used are listed (function words,
    part labels, category names and joint selectors excepted); a request with
    no recognised word is marked not understood."""
    from asset2sim.tasks.interpret.request import parse_request

    toaster = parse_request("A two-slot toaster with its lever up and a spring-loaded lever.")
    # "up" after a part noun is a state now (the lever's highest end); "two-slot" a count of parts
    assert toaster.understood and toaster.unused_words == [] and toaster.ignored == [] and toaster.part_counts == {"slot": 2}
    duck = parse_request("A microwave with a rubber duck on top, painted blue.")
    assert duck.ignored == ["rubber duck", "painted blue"]
    assert [(js.label, js.target.end) for js in toaster.joint_states] == [("lever", "high")]
    drawers = parse_request("A small cabinet with the first drawer closed and the second slightly open.")
    assert drawers.unused_words == []
    german = parse_request("Ein kleiner Kasten mit leicht geöffnetem Deckel")
    assert not german.understood and german.matched == []
    assert german.unused_words[:2] == ["ein", "kleiner"]
    assert parse_request("").understood and parse_request("   ").unused_words == []


def test_mounting_words_are_understood_not_reported_unused():
    """"free-standing", "mounted on the wall", "wall-mounted", "built-in" set the
    root's mounting (tasks.interpret.mounting); they were listed as words not
    understood (a warning on stderr for every mounting request) although the
    mounting was applied. Words beside them are still reported."""
    from asset2sim.tasks.interpret.mounting import request_mounting

    for text, kind in (("A free-standing faucet.", "free-standing"), ("A faucet mounted on the wall.", "wall-mounted"),
                       ("A wall-mounted switch, turned on.", "wall-mounted"), ("A built-in oven with its door closed.", "counter-mounted")):
        spec = parse_request(text)
        assert spec.unused_words == [], text
        assert request_mounting(text).kind == kind
        assert any(kind.split("-")[0] in m or "built" in m for m in spec.matched), (text, spec.matched)
    assert parse_request("A free-standing faucet, painted blue.").ignored == ["painted blue"]


def test_a_named_variant_is_understood_not_ignored():
    spec = parse_request("A kitchen faucet with its handle turned off and a stiff handle joint.")
    assert spec.ignored == [] and "kitchen faucet" in spec.matched
    assert parse_request("A mini fridge with its door open.").ignored == []
    # a word near the category that is no variant is still reported
    assert parse_request("A purple faucet.").ignored == ["purple"]


@pytest.mark.parametrize("text, band", [("A trash can with the lid wide open, held open.", "fully"),
                                        ("a trash can with the lid open, wide open", "fully"),
                                        ("a laptop with the screen open 45 degrees and propped open", "halfway")])
def test_a_lone_open_beside_a_more_exact_opening_of_the_part_is_no_contradiction(text: str, band: str) -> None:
    """"held open", "propped open" or a bare "open" says less than "wide open" or "45 degrees" for the same part: the
    exact one is kept, nothing is warned or overridden (the request tier would fail the phrase as not applied)."""
    spec = parse_request(text)
    assert [j.band for j in spec.joint_states] == [band] and spec.warnings == []
    assert "contradiction" in " ".join(parse_request("a trash can with the lid closed, held open").warnings)


@pytest.mark.parametrize("text, label", [("A 1.5 kg laptop with the screen at a right angle.", "screen"),
                                         ("a laptop with its screen open at right angles", "screen"),
                                         ("a door open perpendicular to the wall", "door")])
def test_a_right_angle_is_90_degrees(text: str, label: str) -> None:
    (js,) = parse_request(text).joint_states
    assert js.label == label and js.target.kind == "angle" and js.target.value == pytest.approx(math.pi / 2)


def test_the_turntable_free_to_spin_names_the_tray_not_the_task_part() -> None:
    """"the turntable free to spin": a word about the turntable's motion (label tray), not the door's."""
    spec = parse_request("A microwave with the door closed and the turntable free to spin.")
    assert [(m.kind, m.label, m.phrase) for m in spec.motions] == [("free", "tray", "free to spin")]
    assert "spin" not in spec.ignored


@pytest.mark.parametrize("text", ["A 45 cm wide dishwasher with the rack halfway out.", "a drawer pulled halfway out"])
def test_halfway_out_is_one_state_phrase(text: str) -> None:
    spec = parse_request(text)
    assert [j.band for j in spec.joint_states] == ["halfway"] and spec.joint_states[0].phrase.endswith("halfway out")
    assert spec.ignored == []


@pytest.mark.parametrize("text, degrees", [("A laptop with the screen tilted back 120 degrees.", 120),
                                           ("a lid open halfway 90 degrees", 90)])
def test_state_words_right_before_a_number_are_one_state_with_it(text: str, degrees: float) -> None:
    """"tilted back 120 degrees": the number says how far; not a second state of the screen ("tilted back": fully)
    that the request tier would fail as overridden."""
    spec = parse_request(text)
    (js,) = spec.joint_states
    assert js.target.value == pytest.approx(math.radians(degrees)) and spec.warnings == [] and spec.ignored == []


def test_a_place_word_of_the_pose_is_not_the_next_parts_ordinal() -> None:
    """"lying on its back with the lid open": "back" is where the case lies, not which lid (on an object with a front
    and a back lid it would pick the back one); "with" starts the part's own phrase."""
    (js,) = parse_request("A suitcase lying on its back with the lid open 30 degrees.").joint_states
    assert (js.label, js.ordinal, js.phrase) == ("lid", None, "lid open 30 degrees")
    (js,) = parse_request("a fridge with the left door open").joint_states
    assert (js.ordinal, js.order) == (0, "left_right")


def test_a_later_phrase_that_says_the_earlier_one_more_exactly_is_no_contradiction() -> None:
    """"the handle turned on halfway": "turned on" (fully) is the start of "turned on halfway"; one state, not two."""
    spec = parse_request("A faucet with the handle turned on halfway; the handle stays where it is put.")
    assert [(j.label, j.band) for j in spec.joint_states] == [("handle", "halfway")] and spec.warnings == []


@pytest.mark.parametrize("text, kind, state, all_read", [
    # a closer, not a state: neither overriding the state asked nor adding one
    ("A door half open that swings shut on its own.", "self_closing", ("door", "halfway"), True),
    ("a door that shuts by itself", "self_closing", None, True),
    ("A microwave with its door open 45 degrees; the door swings shut on its own.", "self_closing", ("door", "halfway"), True),
    ("A cabinet with the door ajar, and the door swings shut.", "self_closing", ("door", "slightly_open"), True),
    # how the part closes (a soft close), not the door asked shut with "never slams" ignored
    ("A door that never slams shut.", "soft_close", None, True),
    ("A door half open that never slams shut.", "soft_close", ("door", "halfway"), True),
    ("A cabinet door that closes without slamming.", "soft_close", None, True),
    # how the part moves (freely), not that it is open; a state said apart ("wide open") stays
    ("A microwave with a door that swings open easily.", "free", None, False),
    ("A box whose lid flips open freely, closed.", "free", ("lid", "closed"), False),
    ("A cabinet whose doors swing wide open freely.", "free", ("door", "fully"), False),
])
def test_an_end_word_inside_a_phrase_about_motion_sets_no_state(text: str, kind: str, state, all_read: bool) -> None:
    """"swings shut on its own", "never slams shut", "swings open easily" say how a part moves or closes: the end word
    inside them set a state ("the door open 45 degrees; the door swings shut on its own" was read as a door asked shut;
    "a lid that flips open freely, closed" read two states in contradiction)."""
    spec = parse_request(text)
    assert [m.kind for m in spec.motions] == [kind] and spec.overridden == [] and (spec.ignored == [] or not all_read)
    assert [(js.label, js.band) for js in spec.joint_states] == ([state] if state else [])
