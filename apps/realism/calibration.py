"""How far a model judge of realism can be trusted: its sensitivity on planted
defects, its kept rate, the agreement between judges of different families
(Cohen's kappa), and the win rate of each method among its kept verdicts.

A calibration pair shows an intact copy (side ``a``) against a deliberately
broken one (side ``b``, ``pair.defect``: mass x100, zero damping on a door,
friction that stops a drawer, 10 mm penetration, scale x3, a spring that slams
a lid). A judge worth listening to picks the intact side; its *sensitivity* is
the fraction of defect pairs where its kept verdict did, dropped verdicts
counted as misses. The protocol: ``docs/guide/realism.md``.
"""

from __future__ import annotations

from collections import Counter, defaultdict
from itertools import combinations
from pathlib import Path
from typing import Hashable, Sequence

from asset2sim.schemas import Strict
from asset2sim import atomic
from asset2sim.schemas.realism import JudgeVerdict
from asset2sim.apps.realism.judge import RUBRIC_VERSION

#: A judge is calibrated when it catches at least this fraction of the planted defects (of all defect
#: pairs, dropped verdicts as misses): the 90 % criterion ("pairs where one side is a
#: deliberately broken copy ... must lose at least 90 % of their comparisons").
SENSITIVITY_THRESHOLD = 0.9

#: Fewest defect pairs a calibration may rest on. With 10, the 90 % criterion means at least 9 caught, one
#: pair moves the rate by 10 points, and a coin-flip judge (a defect caught with probability 1/4: both
#: orders agree 1/2, on the intact side 1/2) passes with probability below 3e-5 (binomial tail
#: P(X >= 9 | n = 10, p = 1/4)); with fewer pairs one lucky pair decides too much. Six defect kinds, two
#: pairs each (12), is the smallest balanced set above it.
MIN_DEFECT_PAIRS = 10

CALIBRATION_FILE = "judge_calibration.json"


def cohen_kappa(a: Sequence[Hashable], b: Sequence[Hashable]) -> float | None:
    """Cohen's kappa of two raters' labels of the same items: (p_o - p_e) / (1 - p_e), p_o the observed
    agreement, p_e the agreement expected from each rater's label frequencies (Cohen, J. 1960, "A
    coefficient of agreement for nominal scales", Educational and Psychological Measurement 20(1), 37-46).
    1 is perfect agreement, 0 chance level, negative below chance.

    Returns None when undefined: no items, or p_e = 1 (both raters used one and the same label throughout).

    Raises:
        ValueError: ``a`` and ``b`` differ in length.
    """
    if len(a) != len(b):
        raise ValueError(f"cohen_kappa needs two label lists of one length, got {len(a)} and {len(b)}")
    n = len(a)
    if n == 0:
        return None
    p_o = sum(x == y for x, y in zip(a, b)) / n
    ca, cb = Counter(a), Counter(b)
    p_e = sum(ca[k] * cb[k] for k in ca.keys() | cb.keys()) / (n * n)
    return None if p_e >= 1.0 else (p_o - p_e) / (1.0 - p_e)


class DefectTally(Strict):
    """One kind of planted defect: ``pairs`` asked, ``kept`` order-consistent, ``caught`` kept on the intact side."""

    pairs: int = 0
    kept: int = 0
    caught: int = 0


class MethodWins(Strict):
    """A method's kept verdicts on plain (non-defect) pairs: ``comparisons`` it took part in, ``wins``."""

    comparisons: int = 0
    wins: int = 0
    win_rate: float | None = None


class ModelCalibration(Strict):
    """One judge model: ``pairs`` asked (each in both orders), ``kept`` order-consistent verdicts and their
    rate, ``orders_without_answer`` (refusals, unusable prose, failed calls); on defect pairs the
    ``sensitivity`` (caught / defect pairs, the headline) and ``sensitivity_of_kept`` (caught / kept),
    per defect kind; ``calibrated`` with ``why``; win rates per method on plain pairs; usage summed."""

    model: str
    family: str
    pairs: int
    kept: int
    kept_rate: float | None
    orders_without_answer: int
    defect_pairs: int
    defect_kept: int
    defect_caught: int
    sensitivity: float | None
    sensitivity_of_kept: float | None
    calibrated: bool
    why: str
    defects: dict[str, DefectTally] = {}
    method_wins: dict[str, MethodWins] = {}
    calls: int = 0
    prompt_tokens: int = 0
    completion_tokens: int = 0
    cost_usd: float = 0.0


class KappaReport(Strict):
    """Agreement of two judge models over the pairs both kept (labels: the winning side, ``a`` or ``b``):
    ``agreement`` the observed fraction, ``kappa`` Cohen's kappa (None: undefined)."""

    model_1: str
    family_1: str
    model_2: str
    family_2: str
    same_family: bool
    pairs_both_kept: int
    agreement: float | None
    kappa: float | None


class JudgeCalibration(Strict):
    """``judge_calibration.json``: the criteria and every judge's calibration and pairwise agreement."""

    rubric_version: str = RUBRIC_VERSION
    sensitivity_threshold: float = SENSITIVITY_THRESHOLD
    min_defect_pairs: int = MIN_DEFECT_PAIRS
    models: list[ModelCalibration] = []
    kappa: list[KappaReport] = []

    def model(self, name: str) -> ModelCalibration:
        """The calibration of model ``name`` (KeyError when absent)."""
        for m in self.models:
            if m.model == name:
                return m
        raise KeyError(f"no judge model {name!r} in this calibration (have: {', '.join(m.model for m in self.models)})")


def _ratio(num: int, den: int) -> float | None:
    return num / den if den else None


def kept_side(v: JudgeVerdict) -> str | None:
    """The winning side of a kept verdict (``a`` / ``b``; None when not kept)."""
    if not v.kept or v.winner is None:
        return None
    return "a" if v.winner == v.method_a else "b"


def kept_comparisons(verdicts: Sequence[JudgeVerdict], model: str | None = None) -> list[tuple[str, str]]:
    """(winner, loser) methods of every kept verdict on a plain (non-defect) pair, of ``model`` or of all
    models: the comparisons a Bradley-Terry fit takes."""
    return [(v.winner, v.method_b if kept_side(v) == "a" else v.method_a) for v in verdicts
            if v.defect is None and (model is None or v.model == model) and kept_side(v) is not None]


def judge_calibration(verdicts: Sequence[JudgeVerdict], *, threshold: float = SENSITIVITY_THRESHOLD,
                      min_defect_pairs: int = MIN_DEFECT_PAIRS) -> JudgeCalibration:
    """Calibration of every judge model among ``verdicts`` (models in first-seen order) and Cohen's kappa
    (:func:`cohen_kappa`) of every two of them over the pairs both kept.

    A model is ``calibrated`` iff it saw at least ``min_defect_pairs`` defect pairs and its sensitivity
    (kept verdicts on the intact side / all defect pairs) is at least ``threshold``
    (:data:`SENSITIVITY_THRESHOLD`, :data:`MIN_DEFECT_PAIRS`).

    Raises:
        ValueError: one model given two families, or one pair judged twice by one model.
    """
    by_model: dict[str, list[JudgeVerdict]] = {}
    family: dict[str, str] = {}
    for v in verdicts:
        if family.setdefault(v.model, v.family) != v.family:
            raise ValueError(f"model {v.model!r} appears with families {family[v.model]!r} and {v.family!r}")
        by_model.setdefault(v.model, []).append(v)
    models = []
    for model, rows in by_model.items():
        ids = Counter(v.pair_id for v in rows)
        twice = [p for p, n in ids.items() if n > 1]
        if twice:
            raise ValueError(f"model {model!r} judged pair {twice[0]!r} {ids[twice[0]]} times")
        kept = [v for v in rows if kept_side(v) is not None]
        defects: dict[str, DefectTally] = defaultdict(DefectTally)
        for v in rows:
            if v.defect is not None:
                t = defects[v.defect]
                t.pairs += 1
                t.kept += kept_side(v) is not None
                t.caught += kept_side(v) == "a"
        n_def = sum(t.pairs for t in defects.values())
        n_def_kept = sum(t.kept for t in defects.values())
        caught = sum(t.caught for t in defects.values())
        sens = _ratio(caught, n_def)
        if n_def < min_defect_pairs:
            ok, why = False, f"only {n_def} defect pairs; at least {min_defect_pairs} are needed to calibrate"
        elif sens is not None and sens >= threshold:
            ok, why = True, f"caught {caught} of {n_def} planted defects ({100 * sens:.0f} % >= {100 * threshold:.0f} %)"
        else:
            ok, why = False, (f"caught {caught} of {n_def} planted defects ({100 * (sens or 0):.0f} % < {100 * threshold:.0f} %; "
                              f"{n_def - n_def_kept} dropped as order-inconsistent or unanswered)")
        wins: dict[str, MethodWins] = defaultdict(MethodWins)
        for winner, loser in kept_comparisons(rows):
            wins[winner].comparisons += 1
            wins[winner].wins += 1
            wins[loser].comparisons += 1
        for w in wins.values():
            w.win_rate = _ratio(w.wins, w.comparisons)
        models.append(ModelCalibration(
            model=model, family=family[model], pairs=len(rows), kept=len(kept), kept_rate=_ratio(len(kept), len(rows)),
            orders_without_answer=sum((v.first is None) + (v.second is None) for v in rows),
            defect_pairs=n_def, defect_kept=n_def_kept, defect_caught=caught, sensitivity=sens,
            sensitivity_of_kept=_ratio(caught, n_def_kept), calibrated=ok, why=why,
            defects=dict(sorted(defects.items())), method_wins=dict(sorted(wins.items())),
            calls=sum(v.calls for v in rows), prompt_tokens=sum(v.prompt_tokens for v in rows),
            completion_tokens=sum(v.completion_tokens for v in rows), cost_usd=sum(v.cost_usd for v in rows)))
    kappas = []
    for m1, m2 in combinations(by_model, 2):
        s1, s2 = ({v.pair_id: kept_side(v) for v in by_model[m] if kept_side(v) is not None} for m in (m1, m2))
        both = [p for p in s1 if p in s2]
        l1, l2 = [s1[p] for p in both], [s2[p] for p in both]
        kappas.append(KappaReport(model_1=m1, family_1=family[m1], model_2=m2, family_2=family[m2],
                                  same_family=family[m1] == family[m2], pairs_both_kept=len(both),
                                  agreement=_ratio(sum(x == y for x, y in zip(l1, l2)), len(both)), kappa=cohen_kappa(l1, l2)))
    return JudgeCalibration(sensitivity_threshold=threshold, min_defect_pairs=min_defect_pairs, models=models, kappa=kappas)


def write_calibration(folder: Path | str, calibration: JudgeCalibration) -> Path:
    """``folder/judge_calibration.json``, written atomically. Raises OSError."""
    return atomic.write_json(Path(folder) / CALIBRATION_FILE, calibration.model_dump(mode="json"))
