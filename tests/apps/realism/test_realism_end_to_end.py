"""Realism end to end on real refine outputs: the planted-defect pair set made by ``asset2sim pairs``' code from
two refined demo objects (a drawer cabinet and a microwave), judged through the model client against the local
fake: a judge that sees the broken copies is calibrated, a coin-flip judge is caught; the people's ratings of the
same set give Bradley-Terry scores."""

from __future__ import annotations

import hashlib
import importlib.util

import pytest

pytest.importorskip("av")

from asset2sim.apps.realism import calibration as C  # noqa: E402
from asset2sim.apps.realism import pairs  # noqa: E402
from asset2sim.apps.realism.defects import DEFECTS  # noqa: E402
from asset2sim.apps.realism.judge import judge_pairs  # noqa: E402
from asset2sim.apps.realism.pair_set import read_pair_set  # noqa: E402
from asset2sim.apps.realism.ratings import RatingStore  # noqa: E402
from asset2sim.apps.realism.scores import realism_scores  # noqa: E402
from asset2sim.tasks.refine import refine_asset  # noqa: E402
from asset2sim.models.config import ClientConfig  # noqa: E402
from tests import fake_openai_server as fake  # noqa: E402
from tests import realism_judge_fixtures as fx  # noqa: E402
from tests.helpers import assert_ready_or_honestly_not_robust  # noqa: E402

pytestmark = [pytest.mark.slow,  # end to end: refined demo objects through the pairs, the judge and the ratings
              # litellm looked up, not imported (about 6 s): collecting the fast tier, which leaves this module out,
              # must not pay for it
              pytest.mark.skipif(importlib.util.find_spec("litellm") is None, reason="litellm is not installed")]

OBJECTS = {"cabinet_2drawer": "A small two-drawer cabinet with both drawers closed.",
           "microwave": "A microwave with its door closed."}


@pytest.fixture(scope="module")
def calibration_set(demo_root, tmp_path_factory):
    root = tmp_path_factory.mktemp("realism")
    outs = []
    for oid, prompt in OBJECTS.items():
        res = refine_asset(demo_root / oid, prompt, root / "refined" / oid, extras=False)
        assert_ready_or_honestly_not_robust(res.report, res.overlay)  # the cabinet's top drawer: a tilt slides it 16 mm
        outs.append(root / "refined" / oid)
    specs, skipped = pairs.specs_from_folders(outs, root / "set", defects=None)
    assert skipped == {} and len(specs) == len(OBJECTS) * len(DEFECTS)
    ps = pairs.build_pair_set(specs, root / "set")
    assert ps.skipped == {} and len(ps.pairs) == len(specs)
    return root / "set"


def test_the_planted_defect_set_is_complete_and_reads_back(calibration_set):
    ps = read_pair_set(calibration_set)
    assert {p.object_id for p in ps.pairs} == set(OBJECTS)
    assert sorted(p.defect for p in ps.pairs) == sorted(list(DEFECTS) * len(OBJECTS))
    assert len({p.pair_id for p in ps.pairs}) == len(ps.pairs)
    for p in ps.pairs:
        assert p.a.method == "asset2sim" and p.b.method == f"defect:{p.defect}" and p.motion == "push_release"
        assert all((calibration_set / f).is_file() for side in (p.a, p.b) for c in side.clips for f in [c.video, c.poster, *c.frames])


def test_a_judge_that_sees_the_defects_is_calibrated_and_a_coin_flip_is_not(calibration_set, tmp_path, monkeypatch):
    monkeypatch.delenv("OPENAI_API_KEY", raising=False)
    ps = read_pair_set(calibration_set)
    # what the broken copy shows and the intact one never does (the first frames of a pair are the same picture)
    intact = {hashlib.sha256((calibration_set / f).read_bytes()).hexdigest() for p in ps.pairs for c in p.a.clips for f in c.frames}
    seen = fx.broken_digests(calibration_set, ps) - intact
    judges = {"sees": fx.good_judge(seen), "coin": fx.coin_flip_judge(5)}
    with fake.FakeOpenAIServer(fx.by_model(judges), lifetime_s=180) as srv:
        configs = [ClientConfig(model=f"openai/{m}", base_url=srv.url, timeout_s=10.0, max_attempts=1, cache_dir=tmp_path / "cache")
                   for m in judges]
        verdicts = judge_pairs(calibration_set, configs, families=["one", "two"], workers=2)
    cal = C.judge_calibration(verdicts)
    sees, coin = cal.model("openai/sees"), cal.model("openai/coin")
    assert sees.defect_pairs == len(ps.pairs) >= C.MIN_DEFECT_PAIRS
    assert sees.sensitivity >= 0.9 and sees.calibrated
    assert coin.sensitivity < 0.9 and not coin.calibrated
    assert len(cal.kappa) == 1 and cal.kappa[0].pairs_both_kept == coin.kept
    assert (calibration_set / "judgements.parquet").is_file()


def test_people_rating_the_set_give_scores_per_method(calibration_set):
    ps = read_pair_set(calibration_set)
    with RatingStore(calibration_set) as store:
        for rater in ("r1", "r2"):
            while (shown := store.next_pair(rater)) is not None:
                intact = "left" if shown.left == "a" else "right"  # the raters see the broken copy and avoid it
                store.record(rater, shown.pair.pair_id, intact)
        assert store.count() == 2 * len(ps.pairs)
    scores = {s.method: s for s in realism_scores(calibration_set)}
    a = scores.pop("asset2sim")
    assert a.wins == a.comparisons == 2 * len(ps.pairs) and set(scores) == {f"defect:{d}" for d in DEFECTS}
    # above the average method for sure, and above every broken copy (4 lost comparisons each: wide intervals)
    assert a.ci_low > 0 and all(a.strength > s.ci_high and s.wins == 0 for s in scores.values())
    assert (calibration_set / "realism_scores.parquet").is_file()
