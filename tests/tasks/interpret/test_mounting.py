"""The mounting prior and the request's override (tasks.interpret.mounting)."""

from __future__ import annotations

import pytest

from asset2sim.tasks.interpret import mounting
from asset2sim.tasks.interpret.categories import resolve_category
from asset2sim.prior_tables import load_priors


def test_every_prior_entry_is_a_known_category_with_a_source():
    table = mounting.load_mounting_priors()
    cats = set(load_priors().categories)
    assert table, "mounting.yaml is empty"
    for cat, prior in table.items():
        assert cat in cats, f"mounting.yaml names {cat!r}, not a category of categories.yaml"
        assert len(prior.source) > 40 and prior.kind in mounting.KINDS


@pytest.mark.parametrize("cat,kind", [("Faucet", "counter-mounted"), ("Door", "hangs-in-frame"), ("Window", "hangs-in-frame"),
                                      ("Switch", "wall-mounted"), ("Toilet", "floor-mounted")])
def test_fixtures_are_mounted_by_default(cat, kind):
    m = mounting.category_mounting(cat)
    assert m.fixed and m.kind == kind and cat in m.source


@pytest.mark.parametrize("cat", ["Laptop", "Box", "Microwave", "Suitcase", "Stapler", "TrashCan", "Table", "Generic", None])
def test_other_categories_stay_free_standing(cat):
    m = mounting.category_mounting(cat)
    assert not m.fixed and m.kind == "free-standing"


@pytest.mark.parametrize("text,cat,fixed,kind", [
    ("A free-standing faucet.", "Faucet", False, "free-standing"),
    ("a freestanding faucet with a stiff handle", "Faucet", False, "free-standing"),
    ("a faucet that is not mounted", "Faucet", False, "free-standing"),
    ("A lamp mounted on the wall.", "Lamp", True, "wall-mounted"),
    ("a wall-mounted faucet", "Faucet", True, "wall-mounted"),
    ("A clock on the wall, hands moving freely.", "Clock", True, "wall-mounted"),
    ("a built-in microwave with the door open", "Microwave", True, "counter-mounted"),
    ("a cabinet bolted to the floor", "StorageFurniture", True, "floor-mounted"),
    ("A mounted faucet.", "Faucet", True, "counter-mounted"),
    ("A mounted display.", "Display", True, "wall-mounted"),
    ("A door in its frame, halfway open.", "Door", True, "hangs-in-frame"),
])
def test_request_overrides_the_prior(text, cat, fixed, kind):
    m = mounting.resolve_mounting(cat, text)
    assert (m.fixed, m.kind) == (fixed, kind)
    assert m.source.startswith("request:")


@pytest.mark.parametrize("text", ["A faucet.", "A small laptop, fully open, with low damping.", "A toaster with everything closed.",
                                  "a door halfway open", "A safe."])
def test_requests_without_mounting_words_use_the_prior(text):
    assert mounting.request_mounting(text) is None


def test_the_last_mention_wins():
    assert not mounting.resolve_mounting("Faucet", "a wall-mounted faucet, no: a free-standing one").fixed
    assert mounting.resolve_mounting("Faucet", "a free-standing faucet, no: a wall-mounted one").fixed


def test_session_options_of_a_declared_root():
    assert mounting.session_root_options(True) == {"fixed_base": True, "ground": False}
    assert mounting.session_root_options(False) == {}


def test_bad_table_is_refused_with_the_category():
    with pytest.raises(mounting.MountingError, match="Faucet"):
        mounting._parse_table({"Faucet": {"kind": "glued", "source": "x"}}, "mounting.yaml")
    with pytest.raises(mounting.MountingError, match="source"):
        mounting._parse_table({"Faucet": {"kind": "wall-mounted", "source": " "}}, "mounting.yaml")


def test_dataset_categories_resolve():
    # the manifest's category column names resolve to the canonical names the prior uses
    assert resolve_category("Faucet") == "Faucet" and resolve_category("Door") == "Door"
