"""Bounded model calls against the local fake OpenAI server (127.0.0.1): a deadline for the whole reply of an
attempt (a server that trickles its reply a byte at a time ends at the deadline with MODEL_DEADLINE_EXCEEDED),
a reply size cap applied while the reply arrives (MODEL_REPLY_TOO_LARGE), reply parsing without backtracking
or recursion, the judge's verdicts written as they come, and ``asset2sim judge`` failing when no call did.

Every test is bounded: the fake server stops itself after ``lifetime_s`` (which also ends a trickle), and the
parsing checks run in a subprocess with a time-out."""

from __future__ import annotations

import importlib.util
import json
import subprocess
import sys
import time
from pathlib import Path

import pytest

if importlib.util.find_spec("litellm") is None:  # the client imports it on first use
    pytest.skip("model calls need litellm (pip install 'asset2sim[llm]')", allow_module_level=True)

from asset2sim.cli import main  # noqa: E402
from asset2sim.apps.realism import judge as J  # noqa: E402
from asset2sim.models.client import LLMClient  # noqa: E402
from asset2sim.models.config import ClientConfig  # noqa: E402
from asset2sim.models.errors import DeadlineExceeded, ModelCallError, ReplyInvalid, ReplyTooLarge  # noqa: E402
from asset2sim.models.replies import parse_json_strict  # noqa: E402
from tests import fake_openai_server as fake  # noqa: E402
from tests import realism_judge_fixtures as fx  # noqa: E402

ROOT = Path(__file__).resolve().parents[3]
MESSAGES = [{"role": "user", "content": "which is more realistic?"}]


@pytest.fixture(scope="module", autouse=True)
def warm_litellm():
    """One plain call first, so litellm's first-call set-up is not counted against a test's deadline."""
    with fake.FakeOpenAIServer(fake.reply("ok"), lifetime_s=60) as srv:
        LLMClient(ClientConfig(model="openai/warm", base_url=srv.url, timeout_s=30, max_attempts=1)).complete(MESSAGES)


def client(server, tmp_path, **kw) -> LLMClient:
    cfg = dict(model="openai/m", base_url=server.url, timeout_s=1.5, max_attempts=3, backoff_s=0.01, cache_dir=None)
    cfg.update(kw)
    return LLMClient(ClientConfig(**cfg))


@pytest.mark.parametrize("headers_too", [False, True], ids=["body", "headers-and-body"])
def test_a_reply_sent_a_byte_at_a_time_ends_at_the_deadline(tmp_path, headers_too):
    # ~300 bytes at one byte per 0.25 s: 75 s per attempt when only each read is timed (each read gets its byte)
    with fake.FakeOpenAIServer(fake.trickle(interval_s=0.25, headers_too=headers_too), lifetime_s=40) as srv:
        t0 = time.monotonic()
        with pytest.raises(DeadlineExceeded, match="MODEL_DEADLINE_EXCEEDED.*not complete 1.5 s after") as err:
            client(srv, tmp_path).complete(MESSAGES)
        took = time.monotonic() - t0
    assert took < 6.0, took  # the deadline (1.5 s) plus slack, not the whole trickle
    assert err.value.attempts == 1 and srv.n_chat == 1  # a server this slow is not asked again
    assert isinstance(err.value, ModelCallError) and err.value.code == "MODEL_DEADLINE_EXCEEDED"


def test_a_silent_server_is_still_retried_within_the_deadline(tmp_path):
    with fake.FakeOpenAIServer(lifetime_s=40) as srv:
        srv.push(fake.sleep_then(5.0, fake.reply("late")), fake.reply("second"))
        comp = client(srv, tmp_path, timeout_s=1.0).complete(MESSAGES)
    assert comp.content == "second" and comp.usage.attempts == 2


def test_a_200_megabyte_reply_is_refused_while_it_arrives(tmp_path):
    with fake.FakeOpenAIServer(fake.flood(200 << 20), lifetime_s=60) as srv:
        t0 = time.monotonic()
        with pytest.raises(ReplyTooLarge, match="MODEL_REPLY_TOO_LARGE.*1048576 bytes") as err:
            client(srv, tmp_path, timeout_s=30, max_reply_bytes=1 << 20).complete(MESSAGES)
        took = time.monotonic() - t0
    assert err.value.attempts == 1 and srv.n_chat == 1
    assert srv.sent < 48 << 20, srv.sent  # the client hung up after about 1 MB (the rest sat in socket buffers)
    assert took < 20.0, took


def test_parsing_a_reply_nested_100000_deep_is_a_named_error():
    for text in ("[" * 100_000 + "]" * 100_000, '{"a":' * 100_000 + "1" + "}" * 100_000):
        with pytest.raises(ReplyInvalid, match="nested deeper than 64"):
            parse_json_strict(text)
    deep_in_a_string = json.dumps({"reason": "[" * 1000 + '\\"{{{', "more_realistic": "A"})
    assert parse_json_strict(deep_in_a_string)["more_realistic"] == "A"  # brackets inside strings do not count


def test_a_cached_record_nested_100000_deep_is_asked_again(tmp_path):
    with fake.FakeOpenAIServer(fake.reply("fresh"), lifetime_s=60) as srv:
        c = client(srv, tmp_path, cache_dir=tmp_path / "cache")
        key = c.cache_key(MESSAGES, None, c.config.temperature)
        record = tmp_path / "cache" / key[:2] / f"{key}.json"
        record.parent.mkdir(parents=True)
        record.write_text('{"content": ' + "[" * 100_000 + "]" * 100_000 + "}")
        with pytest.warns(Warning, match="rejected"):
            comp = c.complete(MESSAGES)
    assert comp.content == "fresh" and not comp.cached and srv.n_chat == 1


@pytest.mark.parametrize("reply", [
    "'Answer' + ' ' * 2000 + 'x'",
    "'the more realistic one is' + ' \\t\\n' * 100000 + 'x'",
])
def test_a_judge_reply_with_long_runs_of_spaces_is_read_in_linear_time(reply):
    code = ("import time; from asset2sim.apps.realism.judge_reply import read_reply; t = time.monotonic(); "
            f"r = read_reply({reply}); print(r.choice, round(time.monotonic() - t, 3))")
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr[-2000:]
    choice, seconds = out.stdout.split()
    assert choice == "None" and float(seconds) < 2.0


@pytest.fixture
def pair_set(tmp_path):
    folder = tmp_path / "set"
    ps = fx.write_judge_pair_set(folder, n_defect=2, n_plain=2)
    return folder, ps


def _config(server, tmp_path, **kw) -> ClientConfig:
    cfg = dict(model="openai/good-judge", base_url=server.url, timeout_s=5.0, max_attempts=1, backoff_s=0.01,
               cache_dir=tmp_path / "cache")
    cfg.update(kw)
    return ClientConfig(**cfg)


def test_a_reply_nested_100000_deep_is_no_answer_and_the_run_goes_on(pair_set, tmp_path):
    folder, ps = pair_set
    deep = "[" * 100_000 + "]" * 100_000
    with fake.FakeOpenAIServer(fake.reply('{"more_realistic": "A", "reason": "settles"}'), lifetime_s=60) as srv:
        srv.push(fake.reply(deep))
        verdicts = J.judge_pairs(folder, [_config(srv, tmp_path)], workers=1)
    assert len(verdicts) == len(ps.pairs) == len(J.read_judgements(folder))
    assert verdicts[0].first is None and not verdicts[0].kept and verdicts[0].failed_calls == 0
    assert all(v.first is not None for v in verdicts[1:])


def test_verdicts_are_written_as_they_come(pair_set, tmp_path, monkeypatch):
    folder, ps = pair_set
    real = J.judge_pair
    failing = ps.pairs[2].pair_id

    def judge_pair(client, folder, pair, *, family=None):
        if pair.pair_id == failing:
            raise OSError(28, "No space left on device")
        return real(client, folder, pair, family=family)

    monkeypatch.setattr(J, "judge_pair", judge_pair)
    with fake.FakeOpenAIServer(fake.reply('{"more_realistic": "B", "reason": "x"}'), lifetime_s=60) as srv:
        with pytest.raises(OSError, match="No space left"):
            J.judge_pairs(folder, [_config(srv, tmp_path)], workers=1)
    kept = J.read_judgements(folder)
    assert [v.pair_id for v in kept] == [p.pair_id for p in ps.pairs if p.pair_id != failing]


def test_judge_exits_non_zero_when_every_call_failed(pair_set, tmp_path, monkeypatch, capsys):
    folder, ps = pair_set
    monkeypatch.setenv("ASSET2SIM_LLM_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.setenv("ASSET2SIM_LLM_MAX_ATTEMPTS", "2")
    monkeypatch.setenv("ASSET2SIM_LLM_BACKOFF_S", "0")
    with fake.FakeOpenAIServer(fake.status(500), lifetime_s=60) as srv:
        rc = main(["judge", str(folder), "--model", "openai/down", "--base-url", srv.url, "--timeout", "5"])
        assert srv.n_chat == 2 * 2 * len(ps.pairs)  # both orders, both attempts
    captured = capsys.readouterr()
    assert rc == 2, captured
    assert "MODEL_CALLS_FAILED" in captured.err and f"all {2 * len(ps.pairs)} calls failed" in captured.err
    assert "HTTP 500" in captured.err
    assert [v.failed_calls for v in J.read_judgements(folder)] == [2] * len(ps.pairs)  # recorded all the same


def test_judge_succeeds_when_some_calls_failed(pair_set, tmp_path, monkeypatch, capsys):
    folder, ps = pair_set
    monkeypatch.setenv("ASSET2SIM_LLM_CACHE_DIR", str(tmp_path / "cache"))
    with fake.FakeOpenAIServer(fake.reply('{"more_realistic": "A", "reason": "x"}'), lifetime_s=60) as srv:
        srv.push(fake.status(500))
        rc = main(["judge", str(folder), "--model", "openai/half", "--base-url", srv.url, "--jobs", "1"])
    assert rc == 0, capsys.readouterr()


def test_judge_with_a_trickling_server_ends_at_the_deadline(pair_set, tmp_path, monkeypatch, capsys):
    folder, ps = pair_set
    monkeypatch.setenv("ASSET2SIM_LLM_CACHE_DIR", str(tmp_path / "cache"))
    with fake.FakeOpenAIServer(fake.trickle(interval_s=0.5), lifetime_s=60) as srv:
        t0 = time.monotonic()
        rc = main(["judge", str(folder), "--model", "openai/slow", "--base-url", srv.url, "--timeout", "1", "--jobs", "4"])
        took = time.monotonic() - t0
    err = capsys.readouterr().err
    assert rc == 2 and "MODEL_CALLS_FAILED" in err and "MODEL_DEADLINE_EXCEEDED" in err
    assert took < 15.0, took  # 8 questions, 4 at a time, about 1 s each; a trickled reply takes 150 s
    assert srv.n_chat == 2 * len(ps.pairs)  # each asked once


# ------------------------------------------------------------------ compressed replies and faults named by what they are
def _one_sentence(message: str) -> None:
    assert "\n" not in message and "Traceback" not in message and "HTTP 500" not in message, message


def test_a_gzip_bomb_is_refused_by_its_decoded_bytes_in_bounded_memory(tmp_path):
    """A 256 KB gzip body of 256 MiB: the decoded bytes count against the 16 MiB cap, so it ends at the cap, with the
    client's memory (Python allocations, tracemalloc) far under 1 GB (the issue's 1 GiB body: the same path, 4x
    the compression time)."""
    import tracemalloc

    bomb = fake.gzip_bomb(256 << 20)
    with fake.FakeOpenAIServer(fake.encoded(bomb, "gzip"), lifetime_s=60) as srv:
        tracemalloc.start()
        try:
            with pytest.raises(ReplyTooLarge, match="MODEL_REPLY_TOO_LARGE.*16777216 bytes .decoded.") as err:
                client(srv, tmp_path, timeout_s=30).complete(MESSAGES)
            _, peak = tracemalloc.get_traced_memory()
        finally:
            tracemalloc.stop()
        assert srv.requests[0].headers.get("accept-encoding") == "identity"
    assert peak < 128 << 20, peak
    assert err.value.attempts == 1 and srv.n_chat == 1
    _one_sentence(str(err.value))


@pytest.mark.parametrize("encoding, body", [("gzip, gzip", lambda: fake.gzip_bomb(64 << 20, layers=2)), ("br", lambda: b"\x8b\x00")],
                         ids=["gzip-in-gzip", "not-asked-for"])
def test_nested_or_unasked_encodings_are_refused_before_inflating(tmp_path, encoding, body):
    with fake.FakeOpenAIServer(fake.encoded(body(), encoding), lifetime_s=60) as srv:
        with pytest.raises(ModelCallError) as err:
            client(srv, tmp_path).complete(MESSAGES)
    assert err.value.code == "MODEL_REPLY_INVALID" and srv.n_chat == 1, str(err.value)
    _one_sentence(str(err.value))


def test_a_gzip_reply_within_the_cap_is_read_in_every_member():
    import gzip

    body = json.dumps(fake.completion_body("zipped")).encode()
    half = len(body) // 2
    for payload in (gzip.compress(body), gzip.compress(body[:half]) + gzip.compress(body[half:])):
        with fake.FakeOpenAIServer(fake.encoded(payload, "gzip"), lifetime_s=60) as srv:
            comp = client(srv, None).complete(MESSAGES)
        assert comp.content == "zipped"


@pytest.mark.parametrize("behaviour, code", [
    (fake.raw(b"{not json"), "MODEL_REPLY_INVALID"),
    (fake.raw(b"<html>a proxy's page</html>", content_type="text/html"), "MODEL_REPLY_INVALID"),
    # litellm's own pydantic models warn while they read this body; the error that reaches the user is asserted
    pytest.param(fake.raw(json.dumps({"choices": "none"}).encode()), "MODEL_REPLY_INVALID",
                 marks=pytest.mark.filterwarnings("ignore:Pydantic serializer warnings:UserWarning")),
    (fake.status(503), "MODEL_HTTP_ERROR"),
], ids=["malformed", "html", "no-choices", "503"])
def test_model_faults_are_named_by_what_happened_in_one_sentence(tmp_path, behaviour, code):
    with fake.FakeOpenAIServer(behaviour, lifetime_s=60) as srv:
        with pytest.raises(ModelCallError) as err:
            client(srv, tmp_path, max_attempts=2).complete(MESSAGES)
    assert err.value.code == code and code in str(err.value), str(err.value)
    _one_sentence(str(err.value))


def test_a_refused_connection_is_named(tmp_path):
    from tests.helpers import free_port

    cfg = ClientConfig(model="openai/m", base_url=f"http://127.0.0.1:{free_port()}/v1", timeout_s=5, max_attempts=2,
                       backoff_s=0.01, cache_dir=None)
    with pytest.raises(ModelCallError) as err:
        LLMClient(cfg).complete(MESSAGES)
    assert err.value.code == "MODEL_CONNECTION_REFUSED" and "gave up after 2 attempts" in str(err.value), str(err.value)
    _one_sentence(str(err.value))


class _Listener:
    """A TCP listener on 127.0.0.2 that records every connection it gets (and answers nothing): the host a redirect
    names, which must receive no request."""

    def __init__(self):
        import socket
        import threading

        self.sock = socket.socket()
        self.sock.bind(("127.0.0.2", 0))
        self.sock.listen(8)
        self.sock.settimeout(0.2)
        self.port = self.sock.getsockname()[1]
        self.received: list[bytes] = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._serve, daemon=True)
        self._thread.start()

    def _serve(self):
        while not self._stop.is_set():
            try:
                conn, _ = self.sock.accept()
            except OSError:
                continue
            with conn:
                conn.settimeout(1.0)
                try:
                    self.received.append(conn.recv(65536) or b"(connected)")
                except OSError:
                    self.received.append(b"(connected)")

    def close(self):
        self._stop.set()
        self._thread.join(5)
        self.sock.close()


@pytest.mark.parametrize("code", [307, 308, 302])
def test_a_redirect_to_another_host_is_not_followed(tmp_path, code):
    """The server at --base-url (127.0.0.1) answers a redirect to 127.0.0.2: the prompt is sent nowhere else (the
    second listener receives nothing), the call is not retried, and the error says so in one sentence."""
    other = _Listener()
    try:
        to = f"http://127.0.0.2:{other.port}/v1/chat/completions"
        with fake.FakeOpenAIServer(fake.status(code, headers={"Location": to}), lifetime_s=60) as srv:
            with pytest.raises(ModelCallError) as err:
                client(srv, tmp_path, max_attempts=3).complete(MESSAGES)
            asked = srv.n_chat
    finally:
        other.close()
    assert other.received == [] and asked == 1, (other.received, asked)
    assert err.value.code == "MODEL_REDIRECT_REFUSED" and "127.0.0.2" in str(err.value), str(err.value)
    _one_sentence(str(err.value))


def _many_headers(server, req) -> None:
    """An HTTP answer whose 20,000 header lines no client reads: the connection ends before any status is taken."""
    h = req.handler
    try:
        h.wfile.write(b"HTTP/1.1 200 OK\r\n" + b"".join(b"X-Pad-%d: x\r\n" % i for i in range(20_000)) + b"\r\n")
        h.wfile.flush()
    except OSError:
        pass
    h.close_connection = True


def test_a_connection_without_an_http_status_is_not_called_an_http_error(tmp_path):
    with fake.FakeOpenAIServer(_many_headers, lifetime_s=60) as srv:
        with pytest.raises(ModelCallError) as err:
            client(srv, tmp_path, max_attempts=2, timeout_s=20).complete(MESSAGES)
    text = str(err.value)
    assert err.value.code == "MODEL_CONNECTION_FAILED" and err.value.status is None, text
    assert "HTTP 500" not in text and "litellm" not in text and "http" not in text.split(":", 2)[-1], text
    _one_sentence(text)
