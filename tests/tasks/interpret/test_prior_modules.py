"""The prior modules of ``tasks/interpret/`` split by concern (tables, part
labels, categories, part priors, sizes): the request parser depends on them without a cycle."""

from __future__ import annotations

import ast
from importlib import resources
from pathlib import Path

import pytest

from asset2sim.tasks.interpret import categories, part_labels, part_priors, size_priors
from asset2sim import prior_tables
from asset2sim.tasks.interpret.request import parse_request

ROOT = Path(__file__).resolve().parents[3]
HOMES = (prior_tables, part_labels, categories, part_priors, size_priors)


def _own_imports(module: str) -> set[str]:
    path = ROOT / "tasks" / "interpret" / f"{module}.py"
    tree = ast.parse(path.read_text())
    out = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.module and node.module.startswith("asset2sim.tasks.interpret"):
            out.add(node.module.rsplit(".", 1)[-1] if node.module != "asset2sim.tasks.interpret" else node.names[0].name)
    return out


@pytest.mark.parametrize(
    ("module", "allowed"),
    [
        ("part_labels", {"prior_tables"}),
        ("categories", {"prior_tables", "part_labels"}),
        ("request_values", {"part_labels"}),
        ("mounting", set()),
        ("phrase_scan", {"request_values"}),
        ("motion_words", {"request_values", "phrase_scan"}),
        ("state_words", {"request_values", "phrase_scan"}),
        ("request", {"prior_tables", "part_labels", "categories", "request_values", "mounting", "phrase_scan", "motion_words",
                     "state_words"}),
        ("part_priors", {"prior_tables", "part_labels", "categories"}),
        ("size_priors", {"prior_tables", "categories", "request"}),
    ],
)
def test_modules_import_only_the_layers_below(module: str, allowed: set[str]) -> None:
    """tables <- part labels <- categories <- request <- sizes, and the mounting
    words, the phrase scan, the motion and the state words (layers of their own,
    read by the request parser): no way back."""
    assert _own_imports(module) <= allowed


def test_the_prior_tables_import_no_stage() -> None:
    """The tables' loader is core (``asset2sim/prior_tables.py``): every
    stage may read it, it reads none."""
    tree = ast.parse((ROOT / "asset2sim" / "prior_tables.py").read_text())
    own = {n.module for n in ast.walk(tree) if isinstance(n, ast.ImportFrom) and n.module and n.module.startswith("asset2sim")}
    assert own and not {m for m in own if m.startswith(("asset2sim.tasks", "asset2sim.flows"))}, own


def test_body_label_tokens_name_the_object() -> None:
    assert part_labels.body_label_tokens("suitcase_body") == ["suitcase"]
    assert part_labels.body_label_tokens("door_frame") == ["door"]
    assert part_labels.body_label_tokens("rotation_lid") == []
    assert part_labels.body_label_tokens("body") == []
    assert part_labels.canonical_label("stapler_body") in part_labels.BODY_LABELS


def test_target_size_parses_text_as_the_parser_does() -> None:
    for cat in ("Refrigerator", "Box", "Suitcase", "Generic"):
        for text in ("a mini fridge", "a very small box with its lid open", "a huge carry-on", ""):
            assert size_priors.target_size(cat, text) == size_priors.target_size(cat, parse_request(text))


def test_tables_load_from_the_packaged_folder_as_cached() -> None:
    folder = Path(str(resources.files("asset2sim.priors")))
    assert prior_tables.load_priors_from(folder) == prior_tables.load_priors()


def test_category_mentions_feed_the_request_parser() -> None:
    text = "a small purse with its zipper closed"
    hint, head = categories.request_category(text)
    spec = parse_request(text)
    assert spec.category_hint == hint == categories.resolve_category("bag")
    assert head is not None and head.phrase in spec.matched
