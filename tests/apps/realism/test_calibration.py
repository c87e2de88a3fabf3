"""Calibration of model judges (asset2sim.apps.realism.calibration): Cohen's kappa, sensitivity on
planted defects (of all defect pairs and of kept ones), the calibrated verdict, win rates; end to end
against the fake OpenAI server, a scripted good judge is calibrated and a coin-flip judge is not."""

from __future__ import annotations

import importlib.util
import json

import pytest

from asset2sim.schemas.realism import JudgeVerdict
from asset2sim.apps.realism import calibration as C
from asset2sim.apps.realism.judge import judge_pairs
from asset2sim.models.config import ClientConfig
from tests import fake_openai_server as fake
from tests import realism_judge_fixtures as fx

needs_litellm = pytest.mark.skipif(importlib.util.find_spec("litellm") is None, reason="model judges need litellm")


# ----------------------------------------------------------------------------- Cohen's kappa
def test_kappa_of_the_textbook_table():
    # 50 items: yes/yes 20, yes/no 5, no/yes 10, no/no 15 -> p_o 0.7, p_e 0.5, kappa 0.4
    a = ["y"] * 25 + ["n"] * 25
    b = ["y"] * 20 + ["n"] * 5 + ["y"] * 10 + ["n"] * 15
    assert C.cohen_kappa(a, b) == pytest.approx(0.4)


def test_kappa_limits_and_undefined_cases():
    assert C.cohen_kappa(list("abab"), list("abab")) == pytest.approx(1.0)
    assert C.cohen_kappa(list("abab"), list("baba")) == pytest.approx(-1.0)
    assert C.cohen_kappa(list("aabb"), list("abab")) == pytest.approx(0.0)  # independent raters
    assert C.cohen_kappa([], []) is None
    assert C.cohen_kappa(list("aaa"), list("aaa")) is None  # p_e = 1: kappa undefined
    assert C.cohen_kappa(["x", "y", "z"], ["x", "y", "y"]) == pytest.approx(0.5)  # p_o 2/3, p_e 1/3
    with pytest.raises(ValueError, match="one length"):
        C.cohen_kappa(["a"], ["a", "b"])


# ----------------------------------------------------------------------------- from verdicts
def verdict(model: str, i: int, picks: tuple[str | None, str | None], defect: str | None = None, family: str = "f",
            method_b: str = "human") -> JudgeVerdict:
    """A verdict on pair ``p{i}``; ``picks`` the side each order chose (``a``, ``b`` or None)."""
    b = f"defect:{defect}" if defect else method_b
    meth = {"a": "asset2sim", "b": b, None: None}
    kept = picks[0] is not None and picks[0] == picks[1]
    return JudgeVerdict(model=model, family=family, pair_id=f"p{i}", object_id=f"o{i}", method_a="asset2sim", method_b=b,
                        defect=defect, first=meth[picks[0]], second=meth[picks[1]], kept=kept,
                        winner=meth[picks[0]] if kept else None, calls=2, prompt_tokens=10, completion_tokens=3, cost_usd=0.01)


def test_sensitivity_counts_dropped_defect_pairs_as_misses():
    rows = [verdict("m", i, ("a", "a"), defect="mass_x100") for i in range(9)]
    rows += [verdict("m", 9, ("a", "b"), defect="scale_x3"), verdict("m", 10, (None, "a"), defect="scale_x3"),
             verdict("m", 11, ("b", "b"), defect="scale_x3")]
    cal = C.judge_calibration(rows).model("m")
    assert (cal.defect_pairs, cal.defect_kept, cal.defect_caught) == (12, 10, 9)
    assert cal.sensitivity == pytest.approx(9 / 12) and cal.sensitivity_of_kept == pytest.approx(9 / 10)
    assert not cal.calibrated and "9 of 12" in cal.why and "2 dropped" in cal.why
    assert cal.defects["scale_x3"].model_dump() == {"pairs": 3, "kept": 1, "caught": 0}
    assert cal.orders_without_answer == 1
    assert (cal.calls, cal.prompt_tokens, cal.cost_usd) == (24, 120, pytest.approx(0.12))


def test_calibrated_needs_the_threshold_and_enough_defect_pairs():
    ten = [verdict("m", i, ("a", "a"), defect="mass_x100") for i in range(9)] + [verdict("m", 9, ("b", "b"), defect="x")]
    assert C.judge_calibration(ten).model("m").calibrated  # 9 of 10 = 90 %: the criterion holds
    few = [verdict("m", i, ("a", "a"), defect="mass_x100") for i in range(5)]
    c = C.judge_calibration(few).model("m")
    assert c.sensitivity == 1.0 and not c.calibrated and "only 5 defect pairs" in c.why
    none = C.judge_calibration([verdict("m", 0, ("a", "a"))]).model("m")
    assert none.sensitivity is None and not none.calibrated
    assert C.SENSITIVITY_THRESHOLD == 0.9 and C.MIN_DEFECT_PAIRS >= 10


def test_win_rates_and_comparisons_come_from_kept_plain_pairs_only():
    rows = [verdict("m", 0, ("a", "a")), verdict("m", 1, ("b", "b"), method_b="direct"),
            verdict("m", 2, ("a", "a"), method_b="direct"),
            verdict("m", 3, ("a", "b")), verdict("m", 4, ("a", "a"), defect="mass_x100")]
    cal = C.judge_calibration(rows).model("m")
    wins = {k: (w.wins, w.comparisons) for k, w in cal.method_wins.items()}
    assert wins == {"asset2sim": (2, 3), "direct": (1, 2), "human": (0, 1)}
    assert C.kept_comparisons(rows) == [("asset2sim", "human"), ("direct", "asset2sim"), ("asset2sim", "direct")]
    assert C.kept_comparisons(rows, model="other") == []


def test_kappa_between_models_over_pairs_both_kept():
    m1 = [verdict("m1", i, s, family="gpt") for i, s in enumerate([("a", "a"), ("a", "a"), ("b", "b"), ("b", "b"), ("a", "b")])]
    m2 = [verdict("m2", i, s, family="qwen") for i, s in enumerate([("a", "a"), ("b", "b"), ("b", "b"), ("a", "a"), ("a", "a")])]
    (k,) = C.judge_calibration(m1 + m2).kappa
    assert (k.model_1, k.family_1, k.model_2, k.family_2, k.same_family) == ("m1", "gpt", "m2", "qwen", False)
    assert k.pairs_both_kept == 4 and k.agreement == 0.5 and k.kappa == pytest.approx(0.0)
    with pytest.raises(ValueError, match="families"):
        C.judge_calibration(m1 + [verdict("m1", 9, ("a", "a"), family="other")])
    with pytest.raises(ValueError, match="judged pair 'p0' 2 times"):
        C.judge_calibration(m1 + m1[:1])


def test_calibration_file_is_strict_json(tmp_path):
    rows = [verdict("m", i, ("a", "a"), defect="mass_x100") for i in range(3)]
    C.write_calibration(tmp_path, C.judge_calibration(rows))
    data = json.loads((tmp_path / C.CALIBRATION_FILE).read_text())
    assert data["sensitivity_threshold"] == 0.9 and data["models"][0]["sensitivity"] == 1.0 and data["kappa"] == []
    assert C.JudgeCalibration.model_validate(data).model("m").defect_pairs == 3


# ----------------------------------------------------------------------------- end to end
@needs_litellm
@pytest.mark.parametrize("seed", [1, 2, 3])
def test_good_judge_is_calibrated_and_coin_flip_judge_is_not(tmp_path, seed):
    folder = tmp_path / "set"
    ps = fx.write_judge_pair_set(folder, n_defect=12, n_plain=8)
    judges = {"good-judge": fx.good_judge(fx.broken_digests(folder, ps)), "coin": fx.coin_flip_judge(seed)}
    with fake.FakeOpenAIServer(fx.by_model(judges), lifetime_s=120) as srv:
        configs = [ClientConfig(model=f"openai/{m}", base_url=srv.url, timeout_s=5.0, max_attempts=1,
                                cache_dir=tmp_path / "cache") for m in judges]
        verdicts = judge_pairs(folder, configs, families=["qwen", None], workers=2)
    cal = C.judge_calibration(verdicts)
    good, coin = cal.model("openai/good-judge"), cal.model("openai/coin")
    assert good.family == "qwen" and coin.family == "coin"
    assert good.sensitivity >= 0.9 and good.calibrated and good.kept == 20
    assert set(good.defects) == set(fx.DEFECTS) and all(t.caught == 2 for t in good.defects.values())
    assert coin.sensitivity < 0.9 and not coin.calibrated
    assert 0 < coin.kept < 20  # a coin agrees with itself across orders about half the time
    (k,) = cal.kappa
    assert (k.family_1, k.family_2) == ("qwen", "coin") and k.pairs_both_kept == coin.kept
    assert k.kappa is None or k.kappa < 0.6  # a coin does not agree with a judge that sees
    assert good.calls == coin.calls == 40 and good.prompt_tokens == 40 * 1000
    assert sum(w.comparisons for w in good.method_wins.values()) == 2 * 8
