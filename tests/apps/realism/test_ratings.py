"""The ratings store: reading pairs.json, clip paths kept inside the folder, rater ids, the order and layout
of pairs (never twice, spread over raters, blinded per rater and pair), answers validated and idempotent,
many raters at once, restarts, ratings.parquet, and the scores written from it."""

from __future__ import annotations

import json
import os
import stat
import threading
from collections import Counter

import pandas as pd
import pytest

from asset2sim.schemas.realism import MethodScore
from asset2sim.apps.realism.ratings import (
    PairSetError,
    RatingError,
    RatingStore,
    check_rater,
    left_slot,
    read_pair_set,
    read_ratings,
    side,
)
from asset2sim.apps.realism.pair_set import media_path
from asset2sim.apps.realism.scores import SCORES_FILE, NotRated, read_scores, realism_scores, write_scores
from tests.realism_fixtures import write_pair_set


@pytest.fixture(scope="module")
def pair_folder(tmp_path_factory):
    folder = tmp_path_factory.mktemp("pairs")
    write_pair_set(folder, 12)
    return folder


def test_read_pair_set_and_its_errors(folder, tmp_path):
    pairs = read_pair_set(folder)
    assert len(pairs.pairs) == 12 and pairs.pairs[0].a.method == "asset2sim"
    with pytest.raises(FileNotFoundError) as missing:
        read_pair_set(tmp_path / "nowhere")
    assert missing.value.filename == str(tmp_path / "nowhere" / "pairs.json")
    bad = tmp_path / "bad"
    bad.mkdir()
    (bad / "pairs.json").write_text("{not json")
    with pytest.raises(PairSetError, match=r"bad/pairs.json: not UTF-8 JSON"):
        read_pair_set(bad)
    (bad / "pairs.json").write_text(json.dumps({"pairs": [{"pair_id": "x"}]}))
    with pytest.raises(PairSetError, match=r"bad/pairs.json: not a valid pair set: pairs.0"):
        read_pair_set(bad)
    data = json.loads((folder / "pairs.json").read_text())
    data["pairs"][1]["pair_id"] = data["pairs"][0]["pair_id"]
    (bad / "pairs.json").write_text(json.dumps(data))
    with pytest.raises(PairSetError, match="appears more than once"):
        read_pair_set(bad)


def test_media_paths_stay_inside_the_folder(folder, tmp_path):
    assert media_path(folder, "clips/human/front.webm") == (folder / "clips/human/front.webm").resolve()
    outside = tmp_path / "secret.webm"
    outside.write_bytes(b"x")
    (folder / "clips" / "link.webm").symlink_to(outside)
    for bad in ("../secret.webm", "/etc/passwd", "clips/../../secret.webm", "clips/link.webm", "", "clips\\x.webm"):
        with pytest.raises(PairSetError):
            media_path(folder, bad)
    with pytest.raises(PairSetError, match="missing"):
        media_path(folder, "clips/human/none.webm")
    with pytest.raises(PairSetError, match="not a regular file"):
        media_path(folder, "clips/human")


@pytest.mark.parametrize("rater", ["alice", "r1", "A.b_c-9", "x" * 32])
def test_valid_rater_ids(rater):
    assert check_rater(rater) == rater


@pytest.mark.parametrize("rater", ["", " alice", "a b", "../x", "-x", "x" * 33, "é", "a/b", "a\nb", None])
def test_invalid_rater_ids(rater):
    with pytest.raises(RatingError, match="rater id") as err:
        check_rater(rater)
    assert err.value.code == "RATER_INVALID"


def _answer_all(store, rater, choose=lambda showing: "left"):
    seen = []
    while (showing := store.next_pair(rater)) is not None:
        seen.append(showing.pair.pair_id)
        store.record(rater, showing.pair.pair_id, choose(showing))
    return seen


def test_every_pair_once_then_none(folder):
    with RatingStore(folder) as store:
        seen = _answer_all(store, "alice")
        assert sorted(seen) == sorted(p.pair_id for p in store.pairs)
        assert store.next_pair("alice") is None
        assert store.progress("alice") == (12, 12)
        assert store.count() == 12


def test_a_shown_pair_stays_until_answered(folder):
    with RatingStore(folder) as store:
        first = store.next_pair("alice", now=100.0)
        again = store.next_pair("alice", now=200.0)
        assert first == again
        rating = store.record("alice", first.pair.pair_id, "right", now=130.5).rating
        assert (rating.shown_at, rating.answered_at, rating.seconds) == (100.0, 130.5, 30.5)  # first showing counts
        assert store.next_pair("alice").pair.pair_id != first.pair.pair_id


def test_pairs_spread_over_raters(folder):
    with RatingStore(folder) as store:
        shown = []
        for _ in range(6):  # two raters take turns: each is shown pairs nobody has seen yet
            for rater in ("r1", "r2"):
                s = store.next_pair(rater)
                shown.append(s.pair.pair_id)
                store.record(rater, s.pair.pair_id, "left")
        assert len(set(shown)) == 12
        orders = [[p for p in _answer_all(store, r)] for r in ("r3", "r4")]
        assert orders[0] != orders[1]  # the hash tie-break gives each rater its own order


def test_layout_is_a_hash_of_rater_and_pair(folder):
    with RatingStore(folder) as store:
        pair_id = store.pairs[0].pair_id
        s = store.showing("alice", pair_id)
        assert s.left == left_slot("alice", pair_id) and {s.left, s.right} == {"a", "b"}
    with RatingStore(folder) as again:
        assert again.showing("alice", pair_id) == s  # the same after a restart
    lefts = Counter(left_slot(f"rater{i}", f"pair{j}") for i in range(20) for j in range(20))
    assert 160 < lefts["a"] < 240  # balanced over raters and pairs
    assert len({left_slot(f"rater{i}", pair_id) for i in range(10)}) == 2  # raters differ


def test_record_maps_choice_to_methods(folder):
    with RatingStore(folder) as store:
        s = store.next_pair("alice")
        left = side(s.pair, s.left).method
        right = side(s.pair, s.right).method
        rating = store.record("alice", s.pair.pair_id, "right", score=4, comment="  swings too freely  ").rating
        assert (rating.left, rating.right, rating.winner, rating.loser) == (left, right, right, left)
        assert (rating.choice, rating.score, rating.comment) == ("right", 4, "swings too freely")
        assert rating.object_id == s.pair.object_id


def test_record_validates_and_is_idempotent(folder):
    with RatingStore(folder) as store:
        s = store.next_pair("alice")
        pid = s.pair.pair_id
        unshown = next(p.pair_id for p in store.pairs if p.pair_id != pid)
        for kwargs in [dict(choice="middle"), dict(choice="left", score=6), dict(choice="left", score=0),
                       dict(choice="left", score=True), dict(choice="left", comment="x" * 2001)]:
            with pytest.raises(RatingError) as err:
                store.record("alice", pid, **kwargs)
            assert err.value.code == "ANSWER_INVALID"
        with pytest.raises(RatingError) as err:
            store.record("alice", unshown, "left")
        assert err.value.code == "PAIR_NOT_SHOWN"
        with pytest.raises(RatingError) as err:
            store.record("alice", "nope", "left")
        assert err.value.code == "PAIR_UNKNOWN"
        assert store.count() == 0
        first = store.record("alice", pid, "left", score=3)
        repeat = store.record("alice", pid, "left", score=3)
        assert first.created and not repeat.created and repeat.rating == first.rating
        with pytest.raises(RatingError) as err:
            store.record("alice", pid, "right", score=3)
        assert err.value.code == "ANSWER_CONFLICT"
        assert store.count() == 1 and store.ratings()[0].choice == "left"


def test_many_raters_at_once(folder):
    errors = []
    with RatingStore(folder) as store:
        def work(rater):
            try:
                _answer_all(store, rater, choose=lambda s: "right")
                store.sync_parquet()
            except Exception as exc:  # noqa: BLE001 - reported below
                errors.append(repr(exc))

        threads = [threading.Thread(target=work, args=(f"rater{i}",)) for i in range(8)]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
        assert errors == []
        ratings = store.ratings()
        assert len(ratings) == 8 * 12
        assert len({(r.rater, r.pair_id) for r in ratings}) == 8 * 12
        store.sync_parquet()
    table = pd.read_parquet(folder / "ratings.parquet")
    assert len(table) == 96 and table.groupby("rater").pair_id.nunique().eq(12).all()


def test_a_second_store_on_the_same_folder_sees_the_answers(folder):
    # two processes (here two stores) on one database: SQLite locking keeps them consistent
    with RatingStore(folder) as one, RatingStore(folder) as two:
        s = one.next_pair("alice")
        assert two.next_pair("alice") == s
        two.record("alice", s.pair.pair_id, "left")
        assert one.record("alice", s.pair.pair_id, "left").created is False


def test_restart_keeps_everything_and_rebuilds_parquet(folder):
    with RatingStore(folder) as store:
        first = [store.next_pair("alice") for _ in range(1)][0]
        store.record("alice", first.pair.pair_id, "left")
        second = store.next_pair("alice")  # shown, not answered
    (folder / "ratings.parquet").unlink(missing_ok=True)
    with RatingStore(folder) as store:
        assert (folder / "ratings.parquet").is_file()  # rebuilt on opening
        assert [r.pair_id for r in read_ratings(folder / "ratings.parquet")] == [first.pair.pair_id]
        assert store.next_pair("alice") == second  # the pending pair comes back
        rest = _answer_all(store, "alice")
        assert first.pair.pair_id not in rest and len(rest) == 11


def test_parquet_rows_are_ratings_and_group_readable(folder):
    old = os.umask(0o077)
    try:
        with RatingStore(folder) as store:
            _answer_all(store, "alice")
            path = store.sync_parquet()
    finally:
        os.umask(old)
    assert os.stat(path).st_mode & stat.S_IRGRP
    back = read_ratings(path)
    with RatingStore(folder) as store:
        assert back == store.ratings()
    assert not [p for p in folder.iterdir() if p.name.endswith(".tmp")]


def test_scores_from_ratings_and_other_sources_kept(folder):
    with pytest.raises(NotRated, match="not rated"):
        realism_scores(folder)
    prefer = ["asset2sim", "human", "direct", "defaults"]
    with RatingStore(folder) as store:
        for rater in ("r1", "r2", "r3"):
            _answer_all(store, rater, choose=lambda s: "left" if prefer.index(side(s.pair, s.left).method)
                        < prefer.index(side(s.pair, s.right).method) else "right")
    judge = MethodScore(source="judge:model-x", method="human", strength=0.1, ci_low=-1, ci_high=1, elo=1017,
                        comparisons=3, wins=2)
    write_scores(folder / SCORES_FILE, [judge])
    scores = {s.method: s for s in realism_scores(folder)}
    assert list(scores) == prefer  # strongest first
    assert scores["asset2sim"].ci_low > scores["defaults"].ci_high
    assert scores["asset2sim"].wins == scores["asset2sim"].comparisons == 3 * 6
    stored = read_scores(folder / SCORES_FILE)
    assert judge in stored and {s.source for s in stored} == {"people", "judge:model-x"} and len(stored) == 5
    realism_scores(folder)  # again: the people's rows replaced, not doubled
    assert len(read_scores(folder / SCORES_FILE)) == 5
