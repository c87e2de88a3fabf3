"""Requests generated from structured intents (:mod:`tests.tasks.interpret.request_generated`): the parse of each
rendering gives its intent back (parts, which one, state and amount, size, mass; no contradiction)."""

from __future__ import annotations

import dataclasses
from collections import Counter

from hypothesis import given, settings
from hypothesis import strategies as st

from asset2sim.tasks.interpret.request import parse_request
from tests.tasks.interpret.request_generated import generate, mismatch

INTENTS = generate(600)


def test_600_generated_requests_parse_back_to_their_intents():
    misses = [(i, m) for i in INTENTS if (m := mismatch(i, parse_request(i.text)))]
    total = Counter(p for i in INTENTS for p in i.phenomena)
    missed = Counter(p for i, _ in misses for p in i.phenomena)
    print("generated requests per phenomenon: " + ", ".join(f"{p} {n - missed[p]}/{n}" for p, n in sorted(total.items())))
    for i, m in misses:
        print("MISS", repr(i.text), m)
    assert {"synonym", "ordinal", "compound", "negation", "fraction", "unit", "hedge", "quantifier", "distractor"} <= set(total)
    assert 1 - len(misses) / len(INTENTS) >= 0.98, [m for _, m in misses]


@settings(max_examples=150, deadline=None)
@given(st.integers(min_value=0, max_value=2**31))
def test_parse_of_a_rendered_intent_is_the_intent(seed):
    (intent,) = generate(1, seed)
    assert mismatch(intent, parse_request(intent.text)) == "", intent.text


def test_a_changed_intent_is_a_mismatch():
    intent = INTENTS[0]
    wrong = dataclasses.replace(intent, states=intent.states[:-1] + ["door#1=fully"])
    assert "states" in mismatch(wrong, parse_request(intent.text))
