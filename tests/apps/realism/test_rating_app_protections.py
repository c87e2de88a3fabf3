"""The rating app as a web app on a shared machine: Host and Origin checked, a form token, bodies capped before
they are read (through a live uvicorn server and raw sockets), text from pairs.json escaped on the terminal, a
damaged ratings.sqlite reported with a way out and the answers kept. Every socket has a time-out."""

from __future__ import annotations

import hashlib
import json
import shutil
import socket
import threading
import time

import pandas as pd
import pytest
from fastapi.testclient import TestClient

from asset2sim.cli import main
from asset2sim.apps.realism.rating_app import MAX_FORM_BYTES, create_app, form_token
from asset2sim.apps.realism.ratings import RatingsDatabaseError, RatingStore
from tests.realism_fixtures import write_pair_set

OWN = "http://127.0.0.1:8765"


@pytest.fixture(scope="module")
def pair_folder(tmp_path_factory):
    folder = tmp_path_factory.mktemp("pairs")
    write_pair_set(folder, 6)
    return folder


def _client(app, base_url=OWN) -> TestClient:
    return TestClient(app, base_url=base_url)


def _shown(client, rater) -> int:
    page = client.get(f"/rate/{rater}").text
    return int(page.split('name="pair" value="')[1].split('"')[0])


def _post(client, rater, index, *, token=None, headers=None):
    token = form_token(client.app.state.store.form_secret(), rater) if token is None else token
    return client.post(f"/rate/{rater}/answer", data={"pair": str(index), "choice": "left", "score": "", "comment": "",
                                                      "token": token}, headers=headers, follow_redirects=False)


def test_an_answer_posted_from_another_origin_is_refused(folder):
    client = _client(create_app(folder))
    index = _shown(client, "ann")
    for origin in ("http://evil.example", "null", "http://127.0.0.1:9999", "https://127.0.0.1:8765"):
        r = _post(client, "ann", index, headers={"Origin": origin})
        assert r.status_code == 403 and "another site" in r.text, origin
    assert RatingStore(folder).count() == 0
    assert _post(client, "ann", index, headers={"Origin": OWN}).status_code == 303  # the app's own page
    assert RatingStore(folder).count() == 1


def test_a_request_naming_another_host_is_refused(folder):
    app = create_app(folder)
    for rebound in ("http://evil.example:8765", "http://attacker.test", "http://127.0.0.2:8765"):
        c = _client(app, rebound)
        assert c.get("/").status_code == 400, rebound
        assert c.get("/rate/ann").status_code == 400 and RatingStore(folder).count() == 0
    for own in (OWN, "http://localhost:8765", "http://[::1]:8765"):
        assert _client(app, own).get("/").status_code == 200, own
    lan = create_app(folder, host="0.0.0.0", allowed_hosts=["rating-box.lan"])
    assert _client(lan, "http://rating-box.lan:8765").get("/").status_code == 200
    assert _client(lan, "http://0.0.0.0:8765").get("/").status_code == 400  # "every interface" is no host name
    served = create_app(folder, host="192.0.2.7")
    assert _client(served, "http://192.0.2.7:8765").get("/").status_code == 200


def test_an_answer_without_this_apps_form_token_is_refused(folder):
    client = _client(create_app(folder))
    page = client.get("/rate/ann").text
    token = form_token(client.app.state.store.form_secret(), "ann")
    assert f'name="token" value="{token}"' in page
    index = _shown(client, "ann")
    for bad in ("", "0" * 64, form_token(client.app.state.store.form_secret(), "bob"), form_token(b"other secret", "ann")):
        r = _post(client, "ann", index, token=bad)
        assert r.status_code == 403 and "reload the page" in r.text
    assert RatingStore(folder).count() == 0
    assert _post(client, "ann", index).status_code == 303
    again = _client(create_app(folder))  # a restart keeps the secret: an open form still posts
    assert form_token(again.app.state.store.form_secret(), "ann") == token


@pytest.fixture
def live(folder):
    """The app served by uvicorn on 127.0.0.1 (a free port) in a thread; yields (port, folder)."""
    import uvicorn

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    server = uvicorn.Server(uvicorn.Config(create_app(folder), host="127.0.0.1", port=port, log_level="error",
                                           lifespan="on", access_log=False))
    thread = threading.Thread(target=server.run, daemon=True)
    thread.start()
    deadline = time.monotonic() + 30
    while not server.started and time.monotonic() < deadline:
        time.sleep(0.05)
    assert server.started
    yield port, folder
    server.should_exit = True
    thread.join(15)


def _response(sock) -> bytes:
    """What the server answers before it closes or goes quiet for 10 s (the socket's time-out)."""
    got = b""
    try:
        while b"\r\n\r\n" not in got:
            chunk = sock.recv(65536)
            if not chunk:
                break
            got += chunk
    except (socket.timeout, ConnectionResetError):
        pass
    return got


def test_a_body_declared_too_large_is_refused_unread(live):
    port, folder = live
    with socket.create_connection(("127.0.0.1", port), timeout=10) as sock:
        sock.sendall((f"POST /rate/ann/answer HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\n"
                      "Content-Type: application/x-www-form-urlencoded\r\nContent-Length: 300000000\r\n\r\n"
                      "pair=0&choice=left").encode())
        t0 = time.monotonic()
        got = _response(sock)
    assert got.startswith(b"HTTP/1.1 413"), got[:200]  # answered at once, without waiting for 300 MB
    assert time.monotonic() - t0 < 5.0
    assert RatingStore(folder).count() == 0


def test_a_chunked_body_is_read_only_up_to_the_cap(live):
    port, folder = live
    chunk = b"x" * 4096
    with socket.create_connection(("127.0.0.1", port), timeout=10) as sock:
        sock.sendall((f"POST /rate/ann/answer HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\n"
                      "Content-Type: application/x-www-form-urlencoded\r\nTransfer-Encoding: chunked\r\n\r\n").encode())
        for _ in range(MAX_FORM_BYTES // len(chunk) + 4):  # past the cap, and never the final empty chunk
            sock.sendall(b"%x\r\n" % len(chunk) + chunk + b"\r\n")
        got = _response(sock)
    assert got.startswith(b"HTTP/1.1 413"), got[:200]


def test_a_method_named_like_terminal_markup_is_printed_as_written(folder, capsys):
    data = json.loads((folder / "pairs.json").read_text())
    for pair in data["pairs"]:
        for s in ("a", "b"):
            if pair[s]["method"] == "human":
                pair[s]["method"] = "[/]"
            elif pair[s]["method"] == "direct":
                pair[s]["method"] = "[bold red]x"
    (folder / "pairs.json").write_text(json.dumps(data))
    with RatingStore(folder) as store:
        for rater in ("r1", "r2"):
            while (shown := store.next_pair(rater)) is not None:
                store.record(rater, shown.pair.pair_id, "left")
    assert main(["rate", str(folder), "--scores"]) == 0
    out = capsys.readouterr().out
    assert "[/]" in out and "[bold red]x" in out


def _answered(folder, n=3):
    with RatingStore(folder) as store:
        for _ in range(n):
            shown = store.next_pair("ann")
            store.record("ann", shown.pair.pair_id, "right")
            store.sync_parquet()  # as the app does after every answer


def test_a_damaged_database_is_a_clear_error_and_its_answers_come_back(folder, capsys):
    _answered(folder)
    db = folder / "ratings.sqlite"
    for side in ("-wal", "-shm"):
        (folder / f"ratings.sqlite{side}").unlink(missing_ok=True)
    db.write_bytes(b"this is no database, it was overwritten" * 100)
    damaged = hashlib.sha256(db.read_bytes()).hexdigest()
    parquet = hashlib.sha256((folder / "ratings.parquet").read_bytes()).hexdigest()
    assert main(["rate", str(folder), "--scores"]) == 1
    err = capsys.readouterr().err
    assert "RATINGS_DATABASE_DAMAGED" in err and str(db) in err and "Move it aside" in err and "ratings.parquet" in err
    with pytest.raises(RatingsDatabaseError, match="not a readable ratings database"):
        create_app(folder)
    assert hashlib.sha256(db.read_bytes()).hexdigest() == damaged  # left as it is
    assert hashlib.sha256((folder / "ratings.parquet").read_bytes()).hexdigest() == parquet  # the copy kept
    shutil.move(db, folder / "ratings.sqlite.damaged")  # what the message says to do
    with RatingStore(folder) as store:
        assert store.count() == 3 and store.progress("ann") == (3, len(store.pairs))
    assert len(pd.read_parquet(folder / "ratings.parquet")) == 3
    assert main(["rate", str(folder), "--scores"]) == 0


def test_a_truncated_database_is_a_clear_error(folder, capsys):
    _answered(folder)
    db = folder / "ratings.sqlite"
    with RatingStore(folder):  # fold the write-ahead log into the file, then cut the file
        pass
    data = db.read_bytes()
    db.write_bytes(data[:100] + b"\0" * (len(data) - 100))
    assert main(["rate", str(folder), "--scores"]) == 1
    assert "RATINGS_DATABASE_DAMAGED" in capsys.readouterr().err
