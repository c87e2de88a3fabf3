"""Tests of the physical priors (the prior modules of asset2sim.tasks.interpret and asset2sim/priors/*.yaml)."""

from __future__ import annotations

import csv
import json
import shutil
from importlib import resources
from pathlib import Path

import pytest
import yaml
from hypothesis import given, settings
from hypothesis import strategies as st

from asset2sim import prior_tables
from asset2sim.tasks.interpret import categories, part_labels, part_priors, size_priors
from asset2sim.tasks.interpret.request import parse_request
from tests.conftest import NO_SHARED, SHARED as DATASET

ROOT = Path(__file__).resolve().parents[3]
PRIORS_DIR = Path(str(resources.files("asset2sim.priors")))

#: The 46 PartNet-Mobility categories (model_cat values).
PARTNET_MOBILITY = [
    "Bottle", "Box", "Bucket", "Camera", "Cart", "Chair", "Clock", "CoffeeMachine", "Dishwasher",
    "Dispenser", "Display", "Door", "Eyeglasses", "Fan", "Faucet", "FoldingChair", "Globe", "Kettle",
    "Keyboard", "KitchenPot", "Knife", "Lamp", "Laptop", "Lighter", "Microwave", "Mouse", "Oven", "Pen",
    "Phone", "Pliers", "Printer", "Refrigerator", "Remote", "Safe", "Scissors", "Stapler",
    "StorageFurniture", "Suitcase", "Switch", "Table", "Toaster", "Toilet", "TrashCan", "USB",
    "WashingMachine", "Window",
]
SIZES = list(prior_tables.SIZE_CLASSES)


# ----------------------------------------------------------------- the data itself


def test_load_is_cached_and_complete() -> None:
    pri = prior_tables.load_priors()
    assert prior_tables.load_priors() is pri
    assert prior_tables.GENERIC in pri.categories
    for mc in PARTNET_MOBILITY:
        assert categories.resolve_category(mc) == mc, mc
    assert "Bag" in pri.categories


def test_every_entry_has_sources() -> None:
    pri = prior_tables.load_priors()
    for key, m in pri.materials.items():
        for src in (m.density_source, m.wall_thickness_source, m.friction_source):
            assert len(src) > 20, key
    for key, sc in pri.size_classes.items():
        assert len(sc.source) > 10, key
    for name, c in pri.categories.items():
        assert len(c.dims_source) > 20 and len(c.mass_source) > 20 and len(c.material_source) > 20, name
        if c.spring_labels:
            assert len(c.spring_source) > 20, name
        for v in c.variants:
            assert len(v.source) > 20, (name, v.name)
    # the raw yaml too: no entry without a source key
    raw = yaml.safe_load((PRIORS_DIR / "categories.yaml").read_text())
    for name, entry in raw.items():
        assert "dims_source" in entry and "mass_source" in entry, name


def test_densities_are_physically_sane() -> None:
    mats = prior_tables.load_priors().materials
    expected = {  # kg/m^3, handbook values (Engineering ToolBox / MatWeb)
        "steel_sheet": 7850, "stainless_steel": 8000, "aluminium": 2700, "cast_zinc": 6600,
        "brass": 8500, "glass": 2500, "abs_plastic": 1050, "pp_plastic": 905, "polycarbonate": 1200,
    }
    for key, rho in expected.items():
        assert mats[key].density == pytest.approx(rho, rel=0.05), key
    for key, m in mats.items():
        assert 100 <= m.density <= 9000, key
        assert 0.1 <= m.lateral_friction <= 1.0, key
        assert 0 <= m.restitution <= 1, key
        if m.shell:
            assert 0.0003 <= m.wall_thickness <= 0.02, key
    assert mats["pp_plastic"].density < 1000 < mats["abs_plastic"].density  # PP floats, ABS sinks
    for wood in ("particle_board", "mdf", "plywood", "solid_wood"):
        assert 400 <= mats[wood].density <= 900, wood
    metals = [mats[k].density for k in ("aluminium", "cast_zinc", "steel_sheet", "brass")]
    assert metals == sorted(metals)
    vc = mats["vitreous_china"]
    assert vc.shell and vc.wall_thickness >= 0.006  # thick-walled slip-cast ware


def test_category_table_is_consistent() -> None:
    pri = prior_tables.load_priors()
    for name, c in pri.categories.items():
        assert c.name == name
        assert c.dims[0] >= c.dims[1] >= c.dims[2] > 0
        assert 0 < c.mass_range[0] < c.mass_range[1]
        assert c.body_material in pri.materials
        if c.handheld:
            assert size_priors.fits_gripper(c.dims), name
        # regular-size mass is compatible with the size: density between 20 and 8000 kg/m^3 of the box
        box = c.dims[0] * c.dims[1] * c.dims[2]
        assert c.mass_range[1] / box > 20 and c.mass_range[0] / box < 8000, name


def test_gripper_constant() -> None:
    assert prior_tables.GRASPABLE_WIDTH_M == pytest.approx(0.075)
    assert prior_tables.GRASPABLE_WIDTH_M < 0.080  # Franka Hand stroke
    assert size_priors.fits_gripper((0.18, 0.07, 0.045))
    assert not size_priors.fits_gripper((0.33, 0.23, 0.02))
    assert size_priors.gripper_limit_factor((0.3, 0.15, 0.05)) == pytest.approx(0.5)
    with pytest.raises(ValueError):
        size_priors.gripper_limit_factor((0.1, 0.2))


@pytest.mark.parametrize(
    "cat, longest, mass",
    [  # real-world hints: regular size, (longest dim range m), (mass range must overlap, kg)
        ("Stapler", (0.15, 0.21), (0.1, 0.5)),
        ("Microwave", (0.45, 0.55), (8.0, 20.0)),
        ("Toilet", (0.65, 0.8), (25.0, 50.0)),
        ("Laptop", (0.30, 0.36), (1.0, 2.5)),
        ("Suitcase", (0.6, 0.72), (2.5, 5.0)),
        ("Faucet", (0.2, 0.3), (1.0, 2.5)),
        ("Refrigerator", (1.5, 1.9), (60.0, 110.0)),
    ],
)
def test_regular_sizes_match_real_products(cat: str, longest: tuple[float, float], mass: tuple[float, float]) -> None:
    c = categories.category_prior(cat)
    assert longest[0] <= c.dims[0] <= longest[1]
    lo, hi = size_priors.mass_range(cat, "regular")
    assert lo <= mass[1] and hi >= mass[0]


@pytest.mark.parametrize(
    "cat, request_text, longest, variant",
    [
        ("Toilet", "a very small toilet for a baby", (0.35, 0.45), "child potty"),
        ("Suitcase", "a carry-on suitcase", (0.5, 0.58), "carry-on suitcase"),
        ("Refrigerator", "a mini fridge for a dorm room", (0.45, 0.85), "mini fridge"),
        ("Dishwasher", "a compact countertop dishwasher", (0.5, 0.6), "countertop dishwasher"),
        ("Box", "a very small jewelry box", (0.1, 0.25), "jewelry box"),
        ("Box", "a jewelry box", (0.15, 0.25), "jewelry box"),
        ("StorageFurniture", "a very small two-drawer under-desk office cabinet", (0.3, 0.6), "under-desk drawer unit"),
        ("StorageFurniture", "a small bedside cabinet", (0.45, 0.6), "bedside cabinet"),
        ("Door", "a small cabinet-sized door", (0.4, 0.7), "cabinet door"),
        ("TrashCan", "a very small personal trash can", (0.2, 0.35), None),
        ("TrashCan", "a wheelie bin with the lid open", (0.93, 1.1), "wheelie bin"),
        ("Faucet", "a kitchen faucet", (0.2, 0.45), "kitchen faucet"),
        ("Microwave", "a microwave", (0.45, 0.55), None),
    ],
)
def test_target_size_of_requests(cat: str, request_text: str, longest: tuple[float, float], variant: str | None) -> None:
    t = size_priors.target_size(cat, request_text)
    assert t.variant == variant
    assert longest[0] <= t.dims[0] <= longest[1], t
    assert t.mass_range[0] < t.mass_range[1]
    assert t.dims == pytest.approx(tuple(x * t.factor for x in t.base_dims))
    assert t.note


def test_target_size_variant_size_words() -> None:
    # "mini" is already implied by "mini fridge": no double shrinking
    assert size_priors.target_size("Refrigerator", "a mini fridge").factor == pytest.approx(1.0)
    # a smaller word than the variant's own class shrinks it relative to the variant
    assert size_priors.target_size("Box", "a very small jewelry box").factor == pytest.approx(0.5 / 0.75)
    # a regular / small word never enlarges a variant that is smaller than regular
    assert size_priors.target_size("Toilet", "a small potty").factor == pytest.approx(1.0)
    assert size_priors.target_size("Refrigerator", "a standard-size mini fridge").factor == pytest.approx(1.0)
    # no request: the category's regular size
    t = size_priors.target_size("Laptop", None)
    assert t.factor == 1.0 and t.dims == categories.category_prior("Laptop").dims
    # a parsed RequestSpec works the same as text
    spec = parse_request("a large suitcase")
    assert size_priors.target_size("Suitcase", spec) == size_priors.target_size("Suitcase", "a large suitcase")


def test_target_size_warns_when_handheld_gets_too_big() -> None:
    t = size_priors.target_size("Stapler", "a huge stapler")
    assert t.handheld and t.gripper_limit_factor is not None and t.gripper_limit_factor < 1.0
    assert "gripper" in t.note
    assert size_priors.target_size("Stapler", "a stapler").gripper_limit_factor >= 1.0  # type: ignore[operator]


# ----------------------------------------------------------------- masses


@pytest.mark.parametrize("cat", sorted(prior_tables.load_priors().categories))
def test_mass_ranges_are_monotone_in_size_class(cat: str) -> None:
    ranges = [size_priors.mass_range(cat, s) for s in SIZES]
    for lo, hi in ranges:
        assert 0 < lo < hi
    for (lo0, hi0), (lo1, hi1) in zip(ranges, ranges[1:]):
        assert lo1 >= lo0 and hi1 >= hi0
        assert lo1 > lo0 or lo0 == size_priors.MASS_FLOOR_KG
    assert size_priors.mass_range(cat, None) == size_priors.mass_range(cat, "regular") == pytest.approx(
        categories.category_prior(cat).mass_range
    )
    for v in categories.category_prior(cat).variants:
        vr = [size_priors.mass_range(cat, s, variant=v.name) for s in SIZES]
        for (lo0, hi0), (lo1, hi1) in zip(vr, vr[1:]):
            assert lo1 >= lo0 and hi1 >= hi0
        assert size_priors.mass_range(cat, v.size_class, variant=v.name) == pytest.approx(v.mass_range)


def test_mass_range_scaling_rule() -> None:
    lo, hi = size_priors.mass_range("Microwave", "very_small")
    assert lo == pytest.approx(8.0 * 0.5**3) and hi == pytest.approx(20.0 * 0.5**2)
    lo, hi = size_priors.mass_range("Microwave", "large")
    assert lo == pytest.approx(8.0 * 1.3**2) and hi == pytest.approx(20.0 * 1.3**3)
    with pytest.raises(KeyError):
        size_priors.mass_range("Microwave", "gigantic")
    assert size_priors.mass_range("NoSuchThing", "small") == size_priors.mass_range(prior_tables.GENERIC, "small")


@settings(max_examples=200, deadline=None)
@given(
    st.floats(0.001, 100.0),
    st.floats(1.01, 50.0),
    st.floats(0.05, 5.0),
    st.floats(0.05, 5.0),
)
def test_scale_mass_range_properties(lo: float, ratio: float, f1: float, f2: float) -> None:
    hi = lo * ratio
    a = size_priors.scale_mass_range(lo, hi, min(f1, f2))
    b = size_priors.scale_mass_range(lo, hi, max(f1, f2))
    for r in (a, b):
        assert size_priors.MASS_FLOOR_KG <= r[0] < r[1]
    assert b[0] >= a[0] and b[1] >= a[1]
    assert size_priors.scale_mass_range(lo, hi, 1.0) == pytest.approx((max(lo, size_priors.MASS_FLOOR_KG), max(hi, 1.05 * max(lo, size_priors.MASS_FLOOR_KG))))


def test_scale_mass_range_rejects_bad_factor() -> None:
    for f in (0.0, -1.0, float("nan"), float("inf")):
        with pytest.raises(ValueError):
            size_priors.scale_mass_range(1.0, 2.0, f)


# ----------------------------------------------------------------- labels, materials, roles


@pytest.mark.parametrize(
    "raw, canon",
    [
        ("rotation_lid", "lid"), ("lid", "lid"), ("rotation_door", "door"), ("translation_drawer", "drawer"),
        ("drawer", "drawer"), ("stapler_body", "body"), ("stapler_base", "base"), ("door_frame", "frame"),
        ("foot_pad", "foot"), ("rotation_handle", "handle"), ("rotation_tray", "tray"),
        ("suitcase_body", "body"), ("furniture_body", "body"), ("faucet_base", "base"),
        ("surface_board", "board"), ("caster", "wheel"), ("Drawers", "drawer"), ("pump_lid", "button"),
        ("glass_door", "door"), ("toggle_button", "switch"), ("rocker_switch", "switch"), ("pressing_button", "button"), ("mystery_part", "mystery_part"),
        (None, None), ("  ", None),
    ],
)
def test_canonical_label(raw: str | None, canon: str | None) -> None:
    assert part_labels.canonical_label(raw) == canon


@pytest.mark.parametrize(
    "cat, label, key",
    [
        ("Toilet", "toilet_body", "vitreous_china"),
        ("Toilet", "lid", "pp_plastic"),
        ("Toilet", "seat", "pp_plastic"),
        ("Stapler", "stapler_base", "cast_zinc"),
        ("Stapler", "lid", "steel_sheet"),
        ("Microwave", "microwave_body", "steel_sheet"),
        ("Microwave", "rotation_tray", "glass_pane"),  # a pane drawn with both faces
        ("StorageFurniture", "furniture_body", "particle_board"),
        ("StorageFurniture", "drawer", "drawer_box"),  # a drawer box: thinner sides and bottom than the carcass
        ("Bag", "suitcase_body", "leather"),
        ("Faucet", "switch", "brass"),
        ("Laptop", "screen", "electronics_assembly"),
        ("Suitcase", "suitcase_body", "polycarbonate"),
        ("TrashCan", "wheel", "rubber"),
        ("Spaceship", "hull", "abs_plastic"),  # unknown category and label -> generic body material
        ("Spaceship", "drawer", "drawer_box"),  # unknown category, known label -> label default
        ("Microwave", "mystery_part", "steel_sheet"),  # unknown label -> category body material
        ("Microwave", None, "steel_sheet"),
    ],
)
def test_material_for(cat: str, label: str | None, key: str) -> None:
    m = part_priors.material_for(cat, label)
    assert m.key == key
    assert m.density > 0 and m.wall_thickness > 0 and m.name
    assert "density" in m.source


def test_material_for_variants() -> None:
    assert part_priors.material_for("Toilet", "toilet_body", variant="child potty").key == "pp_plastic"
    assert part_priors.material_for("Door", "rotation_door", variant="cabinet door").key == "mdf"
    assert part_priors.material_for("Door", "rotation_door").key == "solid_wood"


def test_roles_and_springs() -> None:
    assert part_priors.part_role("Microwave", "door") == "task"
    assert part_priors.part_role("Microwave", "rotation_tray") == "accessory"
    assert part_priors.part_role("Microwave", "microwave_body") == "body"
    assert part_priors.part_role("TrashCan", "wheel") == "accessory"
    assert part_priors.part_role("Suitcase", "button") == "accessory"
    assert part_priors.part_role("Faucet", "switch") == "task"
    assert part_priors.part_role("Bag", "rotation_handle") == "task"
    assert part_priors.part_role("Generic", "lid") == "task"
    assert part_priors.part_role("Generic", "knob") == "accessory"
    assert part_priors.part_role("Toilet", "pump_lid") == "accessory"
    assert part_priors.part_role("Microwave", None) == "other"
    assert part_priors.task_relevant_rank("Suitcase", "lid") == 0
    assert part_priors.task_relevant_rank("Suitcase", "rotation_handle") == 1
    assert part_priors.task_relevant_rank("Suitcase", "button") is None
    assert part_priors.task_relevant_rank("Spaceship", "rotation_door") == 0
    assert part_priors.spring_expected("Stapler", "lid")
    assert part_priors.spring_expected("Toaster", "slider")
    assert part_priors.spring_expected("Remote", "button")
    assert part_priors.spring_expected("Remote", "push_button")
    assert not part_priors.spring_expected("Switch", "toggle_button")  # a toggle stays where it is flipped
    assert not part_priors.spring_expected("Microwave", "door")
    assert not part_priors.spring_expected("Stapler", "stapler_base")


def test_request_label_matches() -> None:
    assert part_priors.request_label_matches("Faucet", "handle", "switch")
    assert part_priors.request_label_matches("Laptop", "lid", "screen")
    assert part_priors.request_label_matches("Microwave", "door", "rotation_door")
    assert part_priors.request_label_matches("StorageFurniture", "drawers", "drawer")
    assert not part_priors.request_label_matches("Microwave", "door", "rotation_tray")
    assert not part_priors.request_label_matches("Microwave", None, "door")


# ----------------------------------------------------------------- recognition


def _manifest_rows() -> list[dict[str, str]]:
    manifest = DATASET / "manifest.csv"
    if not manifest.exists():
        pytest.skip(NO_SHARED)
    return list(csv.DictReader(manifest.open()))


def _asset(row: dict[str, str]) -> tuple[str, list[str]]:
    d = DATASET / row["id"]
    mc = json.loads((d / "meta.json").read_text())["model_cat"]
    labels = [ln.split()[2] for ln in (d / "semantics.txt").read_text().splitlines() if len(ln.split()) >= 3]
    return mc, labels


def test_recognize_all_manifest_rows() -> None:
    rows = _manifest_rows()
    assert len(rows) == 21
    for row in rows:
        mc, labels = _asset(row)
        m = categories.recognize_category(mc, labels, row["prompt"])
        assert m.name == row["category"], (row["id"], m.reason)
        assert 0.3 <= m.confidence <= 1.0, (row["id"], m.confidence)
        assert m.prior.name == m.name and m.reason


def test_recognize_dataset_quirks() -> None:
    rows = {r["id"]: r for r in _manifest_rows()}
    # Table-filed drawer cabinets: the request's "cabinet" decides; without it model_cat stands
    for aid in ("19179", "20279"):
        mc, labels = _asset(rows[aid])
        assert mc == "Table"
        assert categories.recognize_category(mc, labels, rows[aid]["prompt"]).name == "StorageFurniture"
        assert categories.recognize_category(mc, labels, "").name == "Table"
    # a Suitcase asset requested as a purse: Bag, with reduced confidence
    mc, labels = _asset(rows["101673"])
    m = categories.recognize_category(mc, labels, rows["101673"]["prompt"])
    assert m.name == "Bag" and m.confidence < 0.8 and "Suitcase" in m.reason
    assert categories.recognize_category(mc, labels, "").name == "Suitcase"


def test_recognize_variants() -> None:
    m = categories.recognize_category("Refrigerator", ["door", "refrigerator_body"], "A mini fridge for a dorm room")
    assert m.variant is not None and m.variant.name == "mini fridge"
    assert categories.recognize_category("Refrigerator", ["door"], "").variant is None


def test_recognize_without_model_cat_or_request() -> None:
    assert categories.recognize_category(None, ["drawer", "drawer", "furniture_body"]).name == "StorageFurniture"
    assert categories.recognize_category(None, ["lid", "toilet_body", "seat"]).name == "Toilet"
    assert categories.recognize_category("trash can", []).name == "TrashCan"  # synonym as model_cat
    m = categories.recognize_category("Spaceship", ["hull", "rotation_hatch"], "")
    assert m.name == prior_tables.GENERIC and m.confidence == 0.0 and "Spaceship" in m.reason
    m = categories.recognize_category(None, [], "")
    assert m.name == prior_tables.GENERIC
    m = categories.recognize_category("Spaceship", [None, "hull"], "a shiny thing")  # type: ignore[list-item]
    assert m.name == prior_tables.GENERIC


def test_recognize_conflict_lowers_confidence() -> None:
    agree = categories.recognize_category("Microwave", ["door", "microwave_body"], "a microwave")
    clash = categories.recognize_category("Microwave", ["door", "microwave_body"], "a stapler")
    assert agree.confidence >= 0.95
    assert clash.name == "Stapler" and clash.confidence < 0.6


def test_possessive_parts_are_not_the_object() -> None:
    m = categories.recognize_category(None, [], "I want a microwave with its door halfway open")
    assert m.name == "Microwave" and "Door" not in m.scores
    assert categories.request_category("open the door of a microwave")[0] == "Microwave"
    assert categories.request_category("a desk lamp")[0] == "Lamp"
    assert categories.request_category("a two-drawer under-desk cabinet")[0] == "StorageFurniture"
    assert categories.request_category("nothing here") == (None, None)


def test_category_prior_lookup() -> None:
    assert categories.category_prior("fridge").name == "Refrigerator"
    assert categories.category_prior("Trash Can").name == "TrashCan"
    assert categories.category_prior("unknown-thing").name == prior_tables.GENERIC
    with pytest.raises(KeyError, match="unknown-thing"):
        categories.category_prior("unknown-thing", strict=True)


# ----------------------------------------------------------------- bad data


def _copy(tmp_path: Path) -> Path:
    d = tmp_path / "priors"
    d.mkdir(parents=True)
    for f in ("materials.yaml", "labels.yaml", "size_classes.yaml", "categories.yaml", "slides.yaml"):
        shutil.copy(PRIORS_DIR / f, d / f)
    return d


def _edit(d: Path, fname: str, fn) -> None:  # type: ignore[no-untyped-def]
    data = yaml.safe_load((d / fname).read_text())
    fn(data)
    (d / fname).write_text(yaml.safe_dump(data))


def test_copy_of_the_packaged_tables_loads(tmp_path: Path) -> None:
    pri = prior_tables.load_priors_from(_copy(tmp_path))
    assert pri == prior_tables.load_priors()


@pytest.mark.parametrize(
    "fname, edit, needle",
    [
        ("materials.yaml", lambda d: d["abs_plastic"].__setitem__("density", -3.0), "materials.yaml: abs_plastic.density"),
        ("materials.yaml", lambda d: d["glass"].pop("density_source"), "materials.yaml: glass.density_source"),
        ("materials.yaml", lambda d: d["glass"].__setitem__("colour", "green"), "materials.yaml: glass.colour"),
        ("categories.yaml", lambda d: d["Stapler"].__setitem__("dims", [0.05, 0.2, 0.1]), "categories.yaml: Stapler.dims"),
        ("categories.yaml", lambda d: d["Stapler"].__setitem__("body_material", "unobtainium"), "categories.yaml: Stapler.body_material"),
        ("categories.yaml", lambda d: d["Stapler"].__setitem__("mass_range", [2.0, 1.0]), "categories.yaml: Stapler.mass_range"),
        ("categories.yaml", lambda d: d["Stapler"].__setitem__("dims", [0.3, 0.2, 0.1]), "categories.yaml: Stapler"),
        ("categories.yaml", lambda d: d["Stapler"].__setitem__("task_relevant", ["lidd"]), "categories.yaml: Stapler.task_relevant"),
        ("slides.yaml", lambda d: d["roller"].__setitem__("friction_coefficient", [0.05, 0.01]), "slides.yaml: roller"),
        ("slides.yaml", lambda d: d["wood_runners"].pop("source"), "slides.yaml: wood_runners.source"),
        ("categories.yaml", lambda d: d["Box"]["synonyms"].append("stapler"), "synonyms: 'stapler' is also a synonym of Box"),
        ("categories.yaml", lambda d: d.pop("Generic"), "categories.yaml: the fallback category"),
        ("categories.yaml", lambda d: d["Toaster"].__setitem__("spring_source", ""), "categories.yaml: Toaster"),
        ("labels.yaml", lambda d: d["labels"]["lid"].__setitem__("material", "cheese"), "labels.yaml: labels.lid.material"),
        ("size_classes.yaml", lambda d: d["small"].__setitem__("factor", 1.5), "size_classes.yaml"),
        ("size_classes.yaml", lambda d: d.pop("tiny"), "size_classes.yaml"),
    ],
)
def test_bad_data_names_file_and_key(tmp_path: Path, fname: str, edit, needle: str) -> None:  # type: ignore[no-untyped-def]
    d = _copy(tmp_path)
    _edit(d, fname, edit)
    with pytest.raises(prior_tables.PriorsError) as exc:
        prior_tables.load_priors_from(d)
    assert needle in str(exc.value)


def test_missing_and_malformed_files(tmp_path: Path) -> None:
    d = _copy(tmp_path)
    (d / "materials.yaml").unlink()
    with pytest.raises(prior_tables.PriorsError, match="materials.yaml"):
        prior_tables.load_priors_from(d)
    d = _copy(tmp_path / "b")
    (d / "labels.yaml").write_text("- just\n- a list\n")
    with pytest.raises(prior_tables.PriorsError, match="labels.yaml: top level"):
        prior_tables.load_priors_from(d)
    d = _copy(tmp_path / "c")
    (d / "categories.yaml").write_text("Stapler: [unclosed\n")
    with pytest.raises(prior_tables.PriorsError, match="categories.yaml: not valid YAML"):
        prior_tables.load_priors_from(d)


def test_docs_list_every_category() -> None:
    doc = (ROOT / "docs" / "design" / "priors.md").read_text()
    for name in prior_tables.load_priors().categories:
        assert f"| {name} " in doc, name
    for key in prior_tables.load_priors().materials:
        assert key in doc, key


def _fmt_mass(x: float) -> str:
    """The number format of docs/design/priors.md's mass table."""
    if x >= 100:
        return f"{x:.0f}"
    if x >= 10:
        return f"{x:.1f}"
    if x >= 1:
        return f"{x:.2f}"
    if x >= 0.1:
        return f"{x:.3f}"
    return f"{x:.3g}"


def test_docs_mass_table_equals_mass_range() -> None:
    doc = (ROOT / "docs" / "design" / "priors.md").read_text()
    section = doc.split("## Plausible total mass per category and size class (kg)")[1].split("\n## ")[0]
    rows = {
        cells[0]: cells[1:]
        for line in section.splitlines()
        if line.startswith("| ") and not line.startswith("| category")
        for cells in [[c.strip() for c in line.strip("|").split("|")]]
    }
    assert set(rows) == set(prior_tables.load_priors().categories)
    for name, cells in rows.items():
        expected = [
            f"{_fmt_mass(lo)}-{_fmt_mass(hi)}" for lo, hi in (size_priors.mass_range(name, s) for s in SIZES)
        ]
        assert cells == expected, name
