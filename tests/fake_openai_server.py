"""A small OpenAI-compatible chat-completions server for tests (127.0.0.1 only).

``FakeOpenAIServer`` listens on ``127.0.0.1:<free port>`` and answers
``POST /v1/chat/completions``. Each request consumes the next scripted
*behaviour* from its queue (:meth:`FakeOpenAIServer.push`); with an empty queue
it answers with ``default`` (by default :func:`valid_reply`, a reply that
follows the reply schema for whatever asset the request describes).

Behaviours (plain callables ``behaviour(server, request) -> None`` that write the
HTTP answer, built by the helpers below): :func:`reply` (any message content,
finish reason, refusal), :func:`status` (an HTTP error with headers),
:func:`sleep_then` (answer late: a timeout), :func:`drop` (close the
connection without answering), :func:`raw` (arbitrary bytes, e.g. a 10 MB body),
:func:`trickle` (a valid reply sent a byte at a time, slowly) and :func:`flood`
(a body of any size, generated while it is sent, never held whole), :func:`encoded` (a body under any
``Content-Encoding``, e.g. :func:`gzip_bomb`).

Bounded by construction: at most ``max_requests`` requests are served (later
ones get 503), the server shuts itself down after ``lifetime_s`` seconds, and
leaving the ``with`` block stops it. Every request is recorded in
``requests`` (parsed JSON body, headers, arrival time).
"""

from __future__ import annotations

import functools
import json
import re
import socket
import threading
import time
from collections import deque
from dataclasses import dataclass, field
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from typing import Any, Callable

import pytest

Behaviour = Callable[["FakeOpenAIServer", "Request"], None]

PROPOSAL_MARK = "STALLED STATE SEARCH (JSON):"
"""Line that precedes the state-search summary of a joint-proposal request
(``asset2sim.tasks.synthesize.llm_estimator.PROPOSAL_MARK``)."""

DESCRIPTION_MARK = "ASSET DESCRIPTION (JSON):"
"""Line that precedes the structured description in the user message (see
``asset2sim.tasks.synthesize.llm_estimator.DESCRIPTION_MARK``)."""


INTENT_MARK = "REQUEST TO PARSE:"
"""Line that precedes the request text of a request-parse call
(``asset2sim.tasks.interpret.reading.INTENT_MARK``)."""


@dataclass
class Request:
    """One received request."""

    path: str
    headers: dict[str, str]
    body: dict[str, Any]
    t: float
    handler: BaseHTTPRequestHandler = field(repr=False)

    # ---- helpers for tests
    def texts(self) -> list[str]:
        """Every text part of every message, in order."""
        out = []
        for m in self.body.get("messages", []):
            c = m.get("content")
            if isinstance(c, str):
                out.append(c)
            elif isinstance(c, list):
                out += [p.get("text", "") for p in c if p.get("type") == "text"]
        return out

    def image_urls(self) -> list[str]:
        """Every image_url part of every message."""
        out = []
        for m in self.body.get("messages", []):
            c = m.get("content")
            if isinstance(c, list):
                for p in c:
                    if p.get("type") == "image_url":
                        iu = p["image_url"]
                        out.append(iu["url"] if isinstance(iu, dict) else iu)
        return out

    def request_text(self) -> str | None:
        """The request text of a request-parse call (after :data:`INTENT_MARK`), else None."""
        for t in self.texts():
            if t.startswith(INTENT_MARK + "\n"):
                return t[len(INTENT_MARK) + 1:]
        return None

    def stalled_search(self) -> dict[str, Any] | None:
        """The state-search summary of a joint-proposal request, or None."""
        for t in self.texts():
            i = t.find(PROPOSAL_MARK)
            if i >= 0:
                return json.JSONDecoder().raw_decode(t[i + len(PROPOSAL_MARK):].strip())[0]
        return None

    def description(self) -> dict[str, Any] | None:
        """The structured asset description sent after :data:`DESCRIPTION_MARK`."""
        for t in self.texts():
            i = t.find(DESCRIPTION_MARK)
            if i >= 0:
                blob = t[i + len(DESCRIPTION_MARK):].strip()
                return json.JSONDecoder().raw_decode(blob)[0]
        return None


class FakeOpenAIServer:
    """Context manager; ``url`` is the ``/v1`` base URL to give clients."""

    def __init__(self, default: Behaviour | None = None, *, max_requests: int = 500, lifetime_s: float = 900.0):
        self.default = default or valid_reply()
        self.max_requests = max_requests
        self.lifetime_s = lifetime_s
        self.requests: list[Request] = []
        self.sent = 0  # bytes written by trickle / flood
        self._queue: deque[Behaviour] = deque()
        self._lock = threading.Lock()
        self._stop = threading.Event()
        outer = self

        class Handler(BaseHTTPRequestHandler):
            protocol_version = "HTTP/1.1"

            def log_message(self, *args):  # keep test output clean
                pass

            def do_POST(self):  # noqa: N802
                n = int(self.headers.get("Content-Length") or 0)
                data = self.rfile.read(n) if n else b""
                try:
                    body = json.loads(data or b"{}")
                except ValueError:
                    body = {"_unparsed": data[:200].decode("latin-1")}
                req = Request(self.path, {k.lower(): v for k, v in self.headers.items()}, body, time.monotonic(), self)
                with outer._lock:
                    outer.requests.append(req)
                    over = len(outer.requests) > outer.max_requests
                    beh = outer._queue.popleft() if outer._queue else outer.default
                if over:
                    status(503, {"error": {"message": "fake server request budget exhausted"}})(outer, req)
                    return
                if not self.path.rstrip("/").endswith("/chat/completions"):
                    status(404, {"error": {"message": f"no route {self.path}"}})(outer, req)
                    return
                beh(outer, req)

        self._server = ThreadingHTTPServer(("127.0.0.1", 0), Handler)
        self._server.daemon_threads = True
        self._thread = threading.Thread(target=self._server.serve_forever, kwargs={"poll_interval": 0.05}, daemon=True)
        self._timer = threading.Timer(lifetime_s, self.stop)
        self._timer.daemon = True

    @property
    def port(self) -> int:
        return self._server.server_address[1]

    @property
    def url(self) -> str:
        return f"http://127.0.0.1:{self.port}/v1"

    def push(self, *behaviours: Behaviour) -> "FakeOpenAIServer":
        """Queue behaviours for the next requests (in order)."""
        with self._lock:
            self._queue.extend(behaviours)
        return self

    def start(self) -> "FakeOpenAIServer":
        self._thread.start()
        self._timer.start()
        return self

    def stop(self) -> None:
        """Stop serving (idempotent); sleeping behaviours wake up."""
        if self._stop.is_set():
            return
        self._stop.set()
        self._timer.cancel()
        self._server.shutdown()
        self._server.server_close()

    def __enter__(self) -> "FakeOpenAIServer":
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()

    @property
    def n_chat(self) -> int:
        """Number of chat-completion requests received."""
        return sum(1 for r in self.requests if r.path.rstrip("/").endswith("/chat/completions"))


# ------------------------------------------------------------------ behaviours
def _send(req: Request, code: int, payload: bytes, headers: dict[str, str] | None = None, content_type: str = "application/json") -> None:
    h = req.handler
    try:
        h.send_response(code)
        h.send_header("Content-Type", content_type)
        h.send_header("Content-Length", str(len(payload)))
        for k, v in (headers or {}).items():
            h.send_header(k, v)
        h.end_headers()
        h.wfile.write(payload)
        h.wfile.flush()
    except (BrokenPipeError, ConnectionResetError):
        pass  # the client gave up (timeout test)


def completion_body(content: str | None, *, model: str = "m", finish_reason: str = "stop", refusal: str | None = None,
                    usage: dict[str, int] | None = None) -> dict[str, Any]:
    """An OpenAI chat-completion response object."""
    msg: dict[str, Any] = {"role": "assistant", "content": content}
    if refusal is not None:
        msg["refusal"] = refusal
    return {
        "id": "chatcmpl-fake",
        "object": "chat.completion",
        "created": int(time.time()),
        "model": model,
        "choices": [{"index": 0, "message": msg, "finish_reason": finish_reason}],
        "usage": usage or {"prompt_tokens": 1000, "completion_tokens": 200, "total_tokens": 1200},
    }


def reply(content: str | None, *, finish_reason: str = "stop", refusal: str | None = None) -> Behaviour:
    """Answer 200 with ``content`` as the assistant message."""

    def b(server: FakeOpenAIServer, req: Request) -> None:
        body = completion_body(content, model=req.body.get("model", "m"), finish_reason=finish_reason, refusal=refusal)
        _send(req, 200, json.dumps(body).encode())

    return b


def status(code: int, body: Any = None, headers: dict[str, str] | None = None) -> Behaviour:
    """Answer HTTP ``code`` with a JSON error body and ``headers`` (e.g. Retry-After)."""

    def b(server: FakeOpenAIServer, req: Request) -> None:
        payload = json.dumps(body if body is not None else {"error": {"message": f"fake error {code}", "type": "fake", "code": code}}).encode()
        _send(req, code, payload, headers)

    return b


def sleep_then(seconds: float, then: Behaviour | None = None) -> Behaviour:
    """Wait ``seconds`` (or until the server stops), then behave like ``then``
    (default: a valid reply); a client with a shorter timeout gives up first."""

    def b(server: FakeOpenAIServer, req: Request) -> None:
        server._stop.wait(seconds)
        (then or valid_reply())(server, req)

    return b


def drop() -> Behaviour:
    """Close the connection without sending anything."""

    def b(server: FakeOpenAIServer, req: Request) -> None:
        h = req.handler
        h.close_connection = True
        try:
            h.connection.shutdown(socket.SHUT_RDWR)
        except OSError:
            pass

    return b


def raw(payload: bytes, code: int = 200, content_type: str = "application/json") -> Behaviour:
    """Answer with arbitrary bytes."""

    def b(server: FakeOpenAIServer, req: Request) -> None:
        _send(req, code, payload, content_type=content_type)

    return b


def trickle(payload: bytes | None = None, interval_s: float = 0.5, *, headers_too: bool = False) -> Behaviour:
    """Send a 200 reply (``payload``, default a valid JSON completion) one byte every ``interval_s`` seconds
    until it is sent, the client hangs up or the server stops; ``headers_too`` trickles the status line and
    headers as well. ``server.sent`` counts the bytes written."""

    def b(server: FakeOpenAIServer, req: Request) -> None:
        body = payload if payload is not None else json.dumps(completion_body('{"more_realistic": "A", "reason": "x"}')).encode()
        head = (f"HTTP/1.1 200 OK\r\nContent-Type: application/json\r\nContent-Length: {len(body)}\r\n\r\n").encode()
        h = req.handler
        h.close_connection = True
        data, start = head + body, 0
        try:
            if not headers_too:
                h.wfile.write(head)
                h.wfile.flush()
                start = len(head)
            for i in range(start, len(data)):
                if server._stop.wait(interval_s):
                    return
                h.wfile.write(data[i:i + 1])
                h.wfile.flush()
                server.sent += 1
        except (BrokenPipeError, ConnectionResetError, OSError):
            pass

    return b


def flood(total_bytes: int, chunk_bytes: int = 1 << 20) -> Behaviour:
    """Answer 200 with a JSON completion whose content is ``total_bytes`` of ``x`` (Content-Length set), generated
    chunk by chunk while it is sent; stops when the client hangs up. ``server.sent`` counts the bytes written."""

    def b(server: FakeOpenAIServer, req: Request) -> None:
        pre = b'{"id": "f", "object": "chat.completion", "created": 0, "model": "m", "choices": [{"index": 0, ' \
              b'"finish_reason": "stop", "message": {"role": "assistant", "content": "'
        post = b'"}}]}'
        h = req.handler
        h.close_connection = True
        try:
            h.send_response(200)
            h.send_header("Content-Type", "application/json")
            h.send_header("Content-Length", str(len(pre) + total_bytes + len(post)))
            h.end_headers()
            h.wfile.write(pre)
            left, chunk = total_bytes, b"x" * chunk_bytes
            while left > 0 and not server._stop.is_set():
                piece = chunk[:min(left, chunk_bytes)]
                h.wfile.write(piece)
                server.sent += len(piece)
                left -= len(piece)
            h.wfile.write(post)
            h.wfile.flush()
        except (BrokenPipeError, ConnectionResetError, OSError):
            pass

    return b


def encoded(payload: bytes, encoding: str, code: int = 200) -> Behaviour:
    """Answer ``code`` with ``payload`` sent as it is under ``Content-Encoding: encoding`` (already compressed by the
    caller: a gzip bomb, gzip inside gzip), whatever the request's ``Accept-Encoding`` asked."""

    def b(server: FakeOpenAIServer, req: Request) -> None:
        _send(req, code, payload, {"Content-Encoding": encoding})

    return b


@functools.lru_cache(maxsize=4)
def gzip_bomb(decoded_bytes: int, layers: int = 1) -> bytes:
    """A gzip body of ``decoded_bytes`` zero bytes (about 1 MB per GiB), compressed ``layers`` times; made in 1 MiB
    steps, never held decoded (kept for the process: 1 GiB takes about 2 s to compress)."""
    import zlib

    comp = zlib.compressobj(9, zlib.DEFLATED, 16 + zlib.MAX_WBITS)
    block, out, left = b"\0" * (1 << 20), [], decoded_bytes
    while left > 0:
        out.append(comp.compress(block[:min(left, len(block))]))
        left -= len(block)
    data = b"".join(out) + comp.flush()
    for _ in range(layers - 1):
        data = zlib.compress(data, 9, wbits=16 + zlib.MAX_WBITS)
    return data


# ------------------------------------------------------------- a valid answer
def valid_reply_content(desc: dict[str, Any], *, scale: float | None = None, band: str | None = None) -> dict[str, Any]:
    """A reply that follows the reply schema for the described asset.

    Scale: the largest closed extent becomes ``typical_dims_m``'s largest
    dimension (or 0.4 m); every link ABS plastic shell; every joint in the band
    the parsed request suggests (``band`` overrides), moderate damping.
    """
    ext = max(desc.get("closed_extents_m") or [1.0])
    target = max(desc.get("typical_dims_m") or [0.4])
    s = scale if scale is not None else target / max(ext, 1e-6)
    links = []
    for ln in desc.get("links", []):
        if not ln.get("volume_m3") and not ln.get("area_m2"):
            continue
        links.append(
            {
                "link": ln["name"],
                "material": "ABS plastic",
                "density": 1050.0,
                "shell": True,
                "wall_thickness": 0.0025,
                "mass": {"value": 0.5, "std": 0.2},
            }
        )
    joints = []
    for j in desc.get("joints", []):
        b = band or j.get("requested_band") or "closed"
        joints.append(
            {
                "joint": j["name"],
                "band": b,
                "position": {"value": float(j.get("closed_position", 0.0)), "std": 0.1},
                "damping_level": "moderate",
                "holds_position": False,
                "spring": False,
                "stiff": False,
                "free_moving": False,
                "damping": {"value": 0.05, "std": 0.02},
                "friction": {"value": 0.02, "std": 0.01},
                "stiffness": {"value": 0.0, "std": 0.01},
            }
        )
    return {
        "category": desc.get("category") or "Generic",
        "scale": {"value": s, "std": 0.1 * s},
        "lateral_friction": 0.5,
        "restitution": 0.1,
        "links": links,
        "joints": joints,
        "notes": {"size": "largest extent matched to the typical size", "material": "molded plastic", "mass_arithmetic": "from geometry"},
    }


def valid_reply(mutate: Callable[[dict[str, Any]], Any] | None = None, **kw) -> Behaviour:
    """Answer with :func:`valid_reply_content` for the request's description;
    ``mutate(content_dict)`` may alter it first (for out-of-range tests)."""

    def b(server: FakeOpenAIServer, req: Request) -> None:
        stalled = req.stalled_search()
        if stalled is not None:  # a joint-proposal request: open every joint to the top of its interval
            joints = [{"name": j["name"], "value": float(j["allowed"][1])} for j in stalled.get("joints", [])]
            reply(json.dumps({"proposals": [{"joints": joints, "reason": "fake: widest allowed opening"}]}))(server, req)
            return
        desc = req.description()
        if desc is None:
            status(400, {"error": {"message": "fake server: no asset description in the request"}})(server, req)
            return
        content = valid_reply_content(desc, **kw)
        if mutate is not None:
            mutate(content)
        reply(json.dumps(content))(server, req)

    return b


def text_reply(text: str) -> Behaviour:
    """Answer with the given text (prose, truncated JSON, duplicate keys ...)."""
    return reply(text)


def json_with_nan() -> Behaviour:
    """A valid reply whose scale is written as a bare ``NaN``."""

    def b(server: FakeOpenAIServer, req: Request) -> None:
        content = valid_reply_content(req.description() or {})
        s = json.dumps(content)
        s = re.sub(r'"scale": \{"value": [^,]+,', '"scale": {"value": NaN,', s, count=1)
        reply(s)(server, req)

    return b


def intent_reply(make: Callable[[str], Any]) -> Behaviour:
    """Answer a request-parse call with ``make(request text)`` as JSON (a typed intent, or anything to test
    validation); a call without a request text gets HTTP 400."""

    def b(server: FakeOpenAIServer, req: Request) -> None:
        text = req.request_text()
        if text is None:
            _send(req, 400, json.dumps({"error": {"message": "not a request-parse call", "type": "fake", "code": 400}}).encode())
            return
        reply(json.dumps(make(text)))(server, req)

    return b


#: The environment variables litellm reads a provider's key from.
MODEL_KEYS = ("OPENAI_API_KEY", "GEMINI_API_KEY", "GOOGLE_API_KEY", "ANTHROPIC_API_KEY")


@pytest.fixture(autouse=True)
def no_keys(monkeypatch):
    """No provider key in the environment (no test reaches a real model); a conftest that imports it
    makes it autouse for its folder."""
    for k in MODEL_KEYS:
        monkeypatch.delenv(k, raising=False)


@pytest.fixture
def server():
    """A fake OpenAI-compatible server for the test (its ``url``, the requests it saw)."""
    with FakeOpenAIServer(lifetime_s=300) as srv:
        yield srv
