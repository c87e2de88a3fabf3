"""The rating app through FastAPI's TestClient: double-blind pages and media, paths never taken from the
request, every pair once per rater, answers validated and idempotent, many raters at once, restarts."""

from __future__ import annotations

import inspect
import json
import re
import shutil
import socket
import threading

import pandas as pd
import pytest
from fastapi.testclient import TestClient

from asset2sim.commands import rate as rate_command
from asset2sim.apps.realism.rating_app import create_app, form_token, serve
from asset2sim.apps.realism.ratings import PairSetError, RatingStore, read_pair_set, side
from tests.realism_fixtures import write_pair_set

METHODS = ("asset2sim", "human", "direct", "defaults")
N_PAIRS = 8


@pytest.fixture(scope="module")
def pair_folder(tmp_path_factory):
    folder = tmp_path_factory.mktemp("pairs")
    write_pair_set(folder, N_PAIRS, methods=METHODS)
    return folder


def _pair_index(page: str) -> int:
    return int(re.search(r'name="pair" value="(\d+)"', page).group(1))


def _client(app) -> TestClient:
    """A test client that names the app's own host (the app refuses others) and sends no Origin."""
    return TestClient(app, base_url="http://127.0.0.1:8765")


def _answer(client, rater, index, choice="left", score="", comment="", token=None, headers=None):
    token = form_token(client.app.state.store.form_secret(), rater) if token is None else token
    return client.post(f"/rate/{rater}/answer", data={"pair": str(index), "choice": choice, "score": score,
                                                      "comment": comment, "token": token},
                       headers=headers, follow_redirects=False)


def _assert_blind(page: str):
    low = page.lower()
    for method in METHODS:
        assert method not in low, method
    for leak in ("clips/", ".webm", ".png", "pair_id"):
        assert leak not in low, leak


def test_pages_are_blind_and_media_match_the_layout(folder):
    pair_set = read_pair_set(folder)
    client = _client(create_app(folder))
    pages = [client.get("/").text, client.get("/rate?rater=bad id").text]
    start = client.get("/rate?rater=alice", follow_redirects=False)
    assert start.status_code == 303 and start.headers["location"] == "/rate/alice"
    seen = []
    while True:
        page = client.get("/rate/alice")
        assert page.status_code == 200 and page.headers["cache-control"] == "no-store"
        pages.append(page.text)
        if 'id="done"' in page.text:
            break
        index = _pair_index(page.text)
        seen.append(index)
        pair = pair_set.pairs[index]
        shown = RatingStore(folder).showing("alice", pair.pair_id)
        assert "Which behaves more like the real object?" in page.text
        for tag in re.findall(r"<video[^>]*>", page.text):
            assert all(attr in tag for attr in ("autoplay", "loop", "muted", "playsinline", "controls", "poster="))
        assert len(re.findall(r"<video", page.text)) == 2 * len(pair.a.clips)  # both views of both sides
        for position, slot in (("left", shown.left), ("right", shown.right)):
            for v, clip in enumerate(side(pair, slot).clips):
                video = client.get(f"/media/alice/{index}/{position}/{v}/video")
                assert video.status_code == 200 and video.headers["content-type"] == "video/webm"
                assert video.content == (folder / clip.video).read_bytes()
                assert f"/media/alice/{index}/{position}/{v}/video" in page.text
                poster = client.get(f"/media/alice/{index}/{position}/{v}/poster")
                assert poster.headers["content-type"] == "image/png" and poster.content == (folder / clip.poster).read_bytes()
        pages.append(_answer(client, "alice", index, "right" if index % 2 else "left", score="5" if index % 3 == 0 else "").text)
    assert sorted(seen) == list(range(N_PAIRS))
    assert "rated all 8 pairs" in pages[-1]
    pages.append(_answer(client, "alice", 0, "right", score="1").text)  # a conflicting re-post: an error page
    for page in pages:
        _assert_blind(page)


def test_media_paths_come_from_pairs_json_only(folder):
    client = _client(create_app(folder))
    secret = (folder / "pairs.json").read_text()
    for url in ["/media/alice/0/left/0/../../../pairs.json", "/media/alice/0/left/0/..%2F..%2Fpairs.json",
                "/media/alice/0/a/0/video", "/media/alice/0/b/0/video", "/media/alice/0/left/5/video",
                "/media/alice/99/left/0/video", "/media/alice/-1/left/0/video", "/media/alice/0/left/0/frames",
                "/media/..%2F..%2Fetc/0/left/0/video", "/media/alice/0/left/0/%2e%2e", "/clips/human/front.webm",
                "/pairs.json", "/ratings.sqlite", "/media/alice/0/left/x/video"]:
        r = client.get(url)
        assert r.status_code in (404, 422), url
        assert "pair_id" not in r.text and secret[:40] not in r.text


def test_a_pair_set_naming_files_outside_is_refused(folder, tmp_path):
    data = json.loads((folder / "pairs.json").read_text())
    data["pairs"][0]["a"]["clips"][0]["video"] = "../outside.webm"
    (tmp_path / "outside.webm").write_bytes(b"x")
    (folder / "pairs.json").write_text(json.dumps(data))
    with pytest.raises(PairSetError, match="leaves the folder"):
        create_app(folder)
    data["pairs"][0]["a"]["clips"][0]["video"] = "clips/gone.webm"
    (folder / "pairs.json").write_text(json.dumps(data))
    with pytest.raises(PairSetError, match="gone.webm: missing"):
        create_app(folder)


def test_answers_validated_and_reposts_idempotent(folder):
    client = _client(create_app(folder))
    index = _pair_index(client.get("/rate/bob").text)
    other = (index + 1) % N_PAIRS
    assert _answer(client, "bob", index, "up").status_code == 400
    assert _answer(client, "bob", index, "left", score="9").status_code == 400
    assert _answer(client, "bob", index, "left", score="two").status_code == 400
    assert _answer(client, "bob", other, "left").status_code == 409  # not the pair shown
    assert _answer(client, "bob", 99, "left").status_code == 404
    assert client.post("/rate/bob/answer", content=b"pair=0&choice=left&comment=" + b"x" * 20000,
                       headers={"content-type": "application/x-www-form-urlencoded"}).status_code == 413
    assert client.get("/rate/b%20ob").status_code == 400
    assert RatingStore(folder).count() == 0
    ok = _answer(client, "bob", index, "left", score="2", comment="lid bounces")
    assert ok.status_code == 303 and ok.headers["location"] == "/rate/bob"
    assert _answer(client, "bob", index, "left", score="2", comment="lid bounces").status_code == 303  # re-post
    assert _answer(client, "bob", index, "right", score="2", comment="lid bounces").status_code == 409
    table = pd.read_parquet(folder / "ratings.parquet")  # synced after the answer
    assert len(table) == 1 and table.loc[0, "score"] == 2 and table.loc[0, "comment"] == "lid bounces"
    assert _pair_index(client.get("/rate/bob").text) != index


def test_many_raters_at_once(folder):
    app = create_app(folder)
    errors, seen = [], {}

    def work(rater):
        try:
            client = _client(app)
            mine = []
            for _ in range(N_PAIRS + 2):
                page = client.get(f"/rate/{rater}").text
                if 'id="done"' in page:
                    break
                index = _pair_index(page)
                mine.append(index)
                r = _answer(client, rater, index, "left")
                assert r.status_code == 303, r.text
            seen[rater] = mine
        except Exception as exc:  # noqa: BLE001 - reported below
            errors.append(f"{rater}: {exc!r}")

    threads = [threading.Thread(target=work, args=(f"r{i}",)) for i in range(6)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert errors == []
    assert all(sorted(v) == list(range(N_PAIRS)) for v in seen.values()) and len(seen) == 6
    table = pd.read_parquet(folder / "ratings.parquet")
    assert len(table) == 6 * N_PAIRS and not table.duplicated(["rater", "pair_id"]).any()


def test_restart_keeps_everything(folder):
    with _client(create_app(folder)) as client:  # the lifespan: syncs and closes the store at shutdown
        answered = []
        for _ in range(3):
            index = _pair_index(client.get("/rate/carol").text)
            answered.append(index)
            _answer(client, "carol", index, "right")
        pending = _pair_index(client.get("/rate/carol").text)
    assert len(pd.read_parquet(folder / "ratings.parquet")) == 3
    with _client(create_app(folder)) as client:
        assert _pair_index(client.get("/rate/carol").text) == pending  # the shown, unanswered pair again
        assert re.search(r'pair <span id="progress">4</span>\s+of 8', client.get("/rate/carol").text)
        rest = []
        while 'id="done"' not in (page := client.get("/rate/carol").text):
            rest.append(_pair_index(page))
            _answer(client, "carol", rest[-1], "left")
    assert sorted(answered + rest) == list(range(N_PAIRS))
    assert len(pd.read_parquet(folder / "ratings.parquet")) == N_PAIRS


def test_listens_on_loopback_by_default():
    assert inspect.signature(serve).parameters["host"].default == "127.0.0.1"
    import argparse

    parser = argparse.ArgumentParser()
    rate_command.add_arguments(parser)
    args = parser.parse_args(["somewhere"])
    assert (args.host, args.port, args.scores) == ("127.0.0.1", 8765, False)


def test_command_finds_the_pair_set_of_an_output_folder(folder, tmp_path):
    run = tmp_path / "run"
    shutil.copytree(folder, run / "realism")
    assert rate_command.pair_set_folder(run) == run / "realism"
    assert rate_command.pair_set_folder(folder) == folder
    with pytest.raises(rate_command.CommandError) as err:
        rate_command.pair_set_folder(tmp_path / "empty")
    assert err.value.code == "PAIRS_MISSING" and err.value.status == 1


def test_command_statuses(folder, tmp_path, capsys):
    from asset2sim.cli import main

    assert main(["rate", str(tmp_path / "empty")]) == 1
    assert "PAIRS_MISSING" in capsys.readouterr().err
    assert main(["rate", str(folder), "--port", "0"]) == 2
    assert main(["rate", str(folder), "--tracking-uri", "sqlite:///x.db"]) == 2
    assert main(["rate", str(folder), "--scores"]) == 3
    assert "NOT_RATED" in capsys.readouterr().err and not (folder / "realism_scores.parquet").exists()
    with socket.socket() as taken:  # the port in use: status 4, nothing served
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        assert main(["rate", str(folder), "--port", str(taken.getsockname()[1])]) == 4
    assert "PORT_UNAVAILABLE" in capsys.readouterr().err
    bad = tmp_path / "bad"
    bad.mkdir()
    (bad / "pairs.json").write_text('{"pairs": 3}')
    assert main(["rate", str(bad)]) == 1
    assert "PAIRS_INVALID" in capsys.readouterr().err
    store = RatingStore(folder)
    s = store.next_pair("dana")
    store.record("dana", s.pair.pair_id, "left")
    store.close()
    assert main(["rate", str(folder), "--scores"]) == 0
    out = capsys.readouterr().out
    assert "Bradley-Terry" in out and "realism_scores.parquet" in out
    assert len(pd.read_parquet(folder / "realism_scores.parquet")) == 2
