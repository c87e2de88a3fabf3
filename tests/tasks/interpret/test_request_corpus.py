"""The request corpus (``tests/data/request_corpus.yaml``, >= 200 requests over
the dev objects, the demo assets and a generated toaster), each with its
expected parse and, for many, the expected outcome of refining.

- The parse of every entry runs in the normal test run (pure parser, well
  under a second) and at least 95 % must match; the misses are printed.
- Outcomes: the entries over the demo assets and the generated toaster with a
  fast subset (:data:`FAST_OUTCOMES`) in the normal run, every other entry with
  an outcome under ``-m slow`` (dev objects included; every entry:
  ``benchmarks/bench_request.py --outcomes``).
"""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.conftest import needs_shared
from tests.tasks.interpret.request_corpus import (PHENOMENA, apply_misses, load_corpus, parse_misses, phenomena_of, rates_by_phenomenon,
                                                  run_outcome)

ENTRIES = load_corpus()
WITH_OUTCOME = [e for e in ENTRIES if "outcome" in e]
#: Outcome entries checked in the normal run: one per kind of check, on the
#: demo assets and the generated toaster (a few seconds each).
FAST_OUTCOMES = [
    "A two-slot toaster with its lever up and a spring-loaded lever.",
    "A toaster with its lever down.",
    "A microwave with the door at 30 degrees.",
    "A cabinet with the top drawer open 8 cm.",
    "A cabinet with the top drawer open and the others closed.",
    "A box 30 cm tall.",
    "A microwave with a metal door on a plastic body.",
    "A trash can of 3 kg.",
    "A microwave with the door at 150 degrees.",
    "A box with damping 0.05 N m s/rad.",
]


def test_corpus_is_large_and_covers_every_kind_of_request():
    assert len(ENTRIES) >= 200
    kinds = {k for e in ENTRIES for k in (e.get("parse") or {})}
    assert {"states", "size", "sizes", "props", "mass_level", "damping", "flags", "dyn", "warnings", "ignored"} <= kinds
    objects = {e["object"] for e in ENTRIES}
    assert sum(o.startswith("demo:") for o in objects) == 5 and "gen:toaster" in objects
    assert sum(not o.startswith(("demo:", "gen:")) for o in objects) >= 20
    assert len(WITH_OUTCOME) >= 60


def test_corpus_parses_match_at_least_95_percent():
    misses = parse_misses(ENTRIES)
    rate = 1.0 - len(misses) / len(ENTRIES)
    print(f"request corpus: {len(ENTRIES) - len(misses)}/{len(ENTRIES)} parses match ({rate:.1%})")
    for m in misses:
        print("MISS", m)
    assert rate >= 0.95, "\n".join(misses)


def test_a_wrong_expectation_is_a_miss():
    """The comparison can fail: a changed expected band is reported."""
    entry = dict(ENTRIES[0])
    entry["parse"] = {**entry["parse"], "states": ["door=fully"]}
    assert parse_misses([entry]) and "states" in parse_misses([entry])[0]


def _by_text(texts: list[str]) -> list[dict]:
    out = [e for e in WITH_OUTCOME if e["text"] in texts and e["object"].startswith(("demo:", "gen:"))]
    assert len(out) == len(texts)
    return out


@pytest.mark.parametrize("entry", _by_text(FAST_OUTCOMES), ids=lambda e: e["id"])
def test_corpus_outcome_fast_subset(entry: dict, tmp_path_factory) -> None:
    scratch = tmp_path_factory.getbasetemp() / "request_corpus"
    scratch.mkdir(exist_ok=True)
    misses = run_outcome(entry, Path(scratch))
    assert not misses, f"{entry['id']} {entry['text']!r}: {misses}"


@pytest.mark.slow
@needs_shared
def test_corpus_outcomes_all_at_least_95_percent(tmp_path_factory) -> None:
    """Every outcome entry but the fast subset (each a test of its own above, in the same suite): at least 95 %
    of all outcome entries must match, the fast subset counted as matching (a miss there fails its own test)."""
    scratch = tmp_path_factory.mktemp("request_corpus_all")
    rest = [e for e in WITH_OUTCOME if e["text"] not in FAST_OUTCOMES or not e["object"].startswith(("demo:", "gen:"))]
    assert len(WITH_OUTCOME) - len(rest) == len(FAST_OUTCOMES)
    missed = []
    for e in rest:
        m = run_outcome(e, scratch)
        if m:
            missed.append(f"{e['id']} {e['object']} {e['text']!r}: {m}")
    rate = 1.0 - len(missed) / len(WITH_OUTCOME)
    print(f"request corpus outcomes: {len(rest) - len(missed)}/{len(rest)} beside the fast subset ({rate:.1%} of all)")
    for m in missed:
        print("MISS", m)
    assert rate >= 0.95, "\n".join(missed)


WITH_APPLY = [e for e in ENTRIES if "apply" in e]


def test_hand_written_entries_cover_every_phenomenon():
    assert len(WITH_APPLY) >= 40
    assert set(PHENOMENA) <= {ph for e in WITH_APPLY for ph in phenomena_of(e)}
    assert all(e.get("phenomena") for e in WITH_APPLY)


@pytest.mark.slow  # end to end: the request corpus refined on dev objects
@needs_shared
def test_hand_written_entries_apply_to_the_right_joints(tmp_path_factory) -> None:
    """Every entry with an ``apply`` expectation: the request resolved on its object names the joints and amounts
    expected, and the phrases applied to nothing are the expected ones (every one must match)."""
    scratch = tmp_path_factory.mktemp("request_corpus_apply")
    missed = [f"{e['id']} {e['object']} {e['text']!r}: {m}" for e in WITH_APPLY if (m := apply_misses(e, scratch))]
    rates = rates_by_phenomenon(WITH_APPLY, scratch)
    print("per phenomenon: " + ", ".join(f"{k} {a}/{n}" for k, (a, n) in sorted(rates.items())))
    assert not missed, "\n".join(missed)


@needs_shared
def test_an_apply_expectation_can_fail(tmp_path_factory) -> None:
    """The comparison can fail: the stapler's arm expected on the wrong joint, a phrase expected unapplied."""
    entry = next(e for e in WITH_APPLY if e["text"].startswith("a heavy 2 lb stapler"))
    wrong = {**entry, "apply": {"joints": {"joint_1": "fully", "joint_0": "end:high"}, "unapplied": ["arm pressed down"]}}
    misses = apply_misses(wrong, tmp_path_factory.mktemp("request_corpus_wrong"))
    assert len(misses) == 3, misses
