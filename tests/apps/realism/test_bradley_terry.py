"""Bradley-Terry scores: closed forms, an independent MM fit (Hunter 2004), the interval against the
pseudo-inverse of the Fisher information, the prior keeping all-wins methods finite, recovery of known
strengths, and the errors."""

from __future__ import annotations

import math
import random

import numpy as np
import pandas as pd
import pytest

from asset2sim.apps.realism.bradley_terry import ELO_PER_UNIT, Z95, fit_bradley_terry


def _by_method(scores):
    return {s.method: s for s in scores}


def test_two_methods_closed_form_without_prior():
    # a beats b 3 times of 4: the MLE odds are 3, so s_a - s_b = ln 3, split evenly about the mean 0;
    # var(s_a - s_b) = 1 / (n p (1 - p)) with n = 4, p = 3/4, and var(s_a) = var(s_a - s_b) / 4.
    scores = _by_method(fit_bradley_terry([("a", "b")] * 3 + [("b", "a")], source="people", prior_games=0))
    assert scores["a"].strength == pytest.approx(math.log(3) / 2, abs=1e-8)
    assert scores["b"].strength == pytest.approx(-math.log(3) / 2, abs=1e-8)
    se = math.sqrt(1 / (4 * 0.75 * 0.25) / 4)
    assert scores["a"].ci_low == pytest.approx(math.log(3) / 2 - Z95 * se, abs=1e-6)
    assert scores["a"].ci_high == pytest.approx(math.log(3) / 2 + Z95 * se, abs=1e-6)
    assert (scores["a"].wins, scores["a"].comparisons, scores["b"].wins, scores["b"].comparisons) == (3, 4, 1, 4)
    assert scores["a"].source == "people"


def _mm_fit(pairs, methods):
    """Hunter (2004) MM iteration for the plain Bradley-Terry MLE: gamma_i <- W_i / sum_j n_ij / (gamma_i + gamma_j)."""
    idx = {m: i for i, m in enumerate(methods)}
    n = len(methods)
    wins = np.zeros((n, n))
    for w, l in pairs:
        wins[idx[w], idx[l]] += 1
    games = wins + wins.T
    gamma = np.ones(n)
    for _ in range(20000):
        new = wins.sum(axis=1) / (games / (gamma[:, None] + gamma[None, :])).sum(axis=1)
        new /= np.exp(np.mean(np.log(new)))
        if np.max(np.abs(new - gamma)) < 1e-13:
            break
        gamma = new
    s = np.log(gamma)
    return s - s.mean(), games, s


def test_matches_hunter_mm_and_the_pseudo_inverse_of_the_information():
    rng = random.Random(3)
    true = {"asset2sim": 0.8, "human": 0.5, "direct": -0.3, "defaults": -1.0}
    methods = sorted(true)
    pairs = []
    for _ in range(400):
        a, b = rng.sample(methods, 2)
        p = 1 / (1 + math.exp(-(true[a] - true[b])))
        pairs.append((a, b) if rng.random() < p else (b, a))
    scores = _by_method(fit_bradley_terry(pairs, source="people", prior_games=0))
    mm, games, _ = _mm_fit(pairs, methods)
    for i, m in enumerate(methods):
        assert scores[m].strength == pytest.approx(mm[i], abs=1e-6)
    # Fisher information of the plain likelihood; its pseudo-inverse is the covariance under sum-to-zero
    p = 1 / (1 + np.exp(-(mm[:, None] - mm[None, :])))
    m_ = games * p * (1 - p)
    info = np.diag(m_.sum(axis=1)) - m_
    se = np.sqrt(np.diag(np.linalg.pinv(info)))
    for i, m in enumerate(methods):
        assert scores[m].ci_high - scores[m].ci_low == pytest.approx(2 * Z95 * se[i], rel=1e-5)
        assert scores[m].elo == pytest.approx(1000 + 400 / math.log(10) * scores[m].strength)
        assert ELO_PER_UNIT == pytest.approx(173.7177927613007)


def test_recovers_known_strengths_within_their_intervals():
    rng = random.Random(11)
    true = {f"m{i}": v for i, v in enumerate([1.2, 0.4, 0.0, -0.5, -1.1])}
    mean = sum(true.values()) / len(true)
    pairs = []
    for _ in range(3000):
        a, b = rng.sample(sorted(true), 2)
        p = 1 / (1 + math.exp(-(true[a] - true[b])))
        pairs.append((a, b) if rng.random() < p else (b, a))
    scores = fit_bradley_terry(pairs, source="people")
    assert [s.method for s in scores] == ["m0", "m1", "m2", "m3", "m4"]  # strongest first
    assert sum(s.strength for s in scores) == pytest.approx(0, abs=1e-9)
    for s in scores:
        assert s.ci_low < true[s.method] - mean < s.ci_high, s
        assert s.ci_high - s.ci_low < 0.35  # 3000 comparisons pin each strength down


def test_the_prior_keeps_all_wins_finite_and_ordered():
    pairs = [("asset2sim", "defaults")] * 10 + [("asset2sim", "human")] * 10 + [("human", "defaults")] * 6 \
        + [("defaults", "human")] * 4
    with pytest.raises(ValueError, match="no finite maximum"):
        fit_bradley_terry(pairs, source="people", prior_games=0)
    scores = fit_bradley_terry(pairs, source="people")
    assert [s.method for s in scores] == ["asset2sim", "human", "defaults"]
    for s in scores:
        assert all(math.isfinite(v) for v in (s.strength, s.ci_low, s.ci_high, s.elo))
    best = scores[0]
    assert best.wins == best.comparisons == 20
    assert best.ci_low > scores[2].ci_high  # 20 of 20 wins: clearly above the worst
    # more virtual games pull strengths toward the mean
    strong = fit_bradley_terry(pairs, source="people", prior_games=10)
    assert abs(strong[0].strength) < abs(best.strength)


def test_dataframe_tuples_and_objects_agree_and_order_does_not_matter():
    pairs = [("a", "b"), ("b", "c"), ("c", "a"), ("a", "c"), ("a", "b"), ("b", "a")]
    ref = fit_bradley_terry(pairs, source="x")
    frame = fit_bradley_terry(pd.DataFrame(pairs, columns=["winner", "loser"]), source="x")
    shuffled = list(pairs)
    random.Random(0).shuffle(shuffled)

    class Row:
        def __init__(self, w, l):
            self.winner, self.loser = w, l

    objs = fit_bradley_terry([Row(w, l) for w, l in shuffled], source="x")
    assert ref == frame
    for a, b in zip(ref, objs):
        assert a.method == b.method
        assert a.strength == pytest.approx(b.strength, abs=1e-9)
        assert a.ci_low == pytest.approx(b.ci_low, abs=1e-9)
    assert ref == fit_bradley_terry(pairs, source="x")  # deterministic


@pytest.mark.parametrize("bad, match", [
    ([], "no comparisons"),
    (pd.DataFrame({"winner": [], "loser": []}), "no comparisons"),
    ([("a", "a")], "cannot beat itself"),
    ([("a", "b", "c")], "expected a \\(winner, loser\\) pair"),
    ([("a", None)], "must be method names"),
    (pd.DataFrame({"won": ["a"], "lost": ["b"]}), "no column"),
])
def test_errors(bad, match):
    with pytest.raises(ValueError, match=match):
        fit_bradley_terry(bad, source="people")


def test_negative_prior_refused():
    with pytest.raises(ValueError, match="prior_games"):
        fit_bradley_terry([("a", "b")], source="people", prior_games=-1)
