"""The network side of model calls: litellm imported on first use (refused in a
forbidden version) and given a bounded HTTP transport, faults classified as
retryable or not, and the wait a server asks for. The retry loop is
``LLMClient.complete``.

Bounds of one attempt (:func:`call_bounds`): httpx's time-out is per read, so a
server that sends one byte a second never trips it, and a reply is read whole
before anything looks at its size. The transport litellm is given
(``litellm.client_session`` for OpenAI-compatible providers,
``litellm.sync_transport`` for the others) wraps httpcore's network backend so
that every connect, write and read of the calling thread gets at most the time
left to the attempt's deadline, and counts the bytes read: past the deadline or
past the size cap the socket read raises at once and the attempt is recorded as
``deadline`` or ``size`` (:class:`CallBounds`), which the client turns into
:class:`~asset2sim.tasks.synthesize.llm_errors.DeadlineExceeded` or
:class:`~asset2sim.tasks.synthesize.llm_errors.ReplyTooLarge`. Memory stays
bounded by the cap; calls outside :func:`call_bounds` pass through unchanged.

The reply's body is decoded here, not by httpx (:class:`DecodedTransport`): every request asks for
``Accept-Encoding: identity``; a body the server compresses anyway (one ``gzip`` or ``deflate``) is inflated in
steps that never hold more than the cap, the *decoded* bytes counted against it (a 1 MB gzip body of 1 GiB is
refused once 16 MiB are out, ``size``), and a body in any other or in several encodings (gzip inside gzip) is
refused before it is inflated (``invalid``). What happened is recorded on the attempt's :class:`CallBounds`
(``failure``: the code and one sentence; ``status``: the HTTP status the server sent), so the client names a
fault by what it was (an invalid reply, too large, the deadline, a refused connection) whatever exception
litellm wraps it in.
"""

from __future__ import annotations

import email.utils
import math
import os
import threading
import time
import urllib.request
import zlib
from contextlib import contextmanager
from typing import Iterator

from asset2sim.inert import one_line
from asset2sim.tasks.synthesize.llm_errors import LLMUnavailable

#: litellm version that must never be used (reported compromised).
FORBIDDEN_LITELLM = {"1.107.0"}

#: HTTP statuses worth retrying (rate limit, overload, transient server faults).
RETRYABLE_STATUS = {408, 409, 425, 429, 500, 502, 503, 504, 529}

#: Placeholder key for local servers that need none (the OpenAI SDK refuses an empty key).
NO_KEY = "no-key-needed"

_LITELLM_LOCK = threading.Lock()
_BOUNDS = threading.local()


class CallBounds:
    """The bounds of one HTTP attempt of the calling thread: ``deadline_s`` (s, from entering
    :func:`call_bounds`) for connecting, sending and every read, ``max_bytes`` read in all. ``received``: bytes
    read so far; ``tripped``: ``"deadline"`` or ``"size"`` once a bound stopped the attempt, else None."""

    def __init__(self, deadline_s: float, max_bytes: int):
        self.deadline_s = float(deadline_s)
        self.max_bytes = int(max_bytes)
        self.start = time.monotonic()
        self.received = 0
        self.tripped: str | None = None
        #: the HTTP status of the last response of this attempt (None before one arrives)
        self.status: int | None = None
        #: (code, one sentence) of what went wrong at the transport (a refused connection, an undecodable body)
        self.failure: tuple[str, str] | None = None

    def left(self) -> float:
        """Seconds left before the deadline (<= 0: passed)."""
        return self.deadline_s - (time.monotonic() - self.start)

    def elapsed(self) -> float:
        """Seconds since the attempt began."""
        return time.monotonic() - self.start


@contextmanager
def call_bounds(deadline_s: float, max_bytes: int) -> Iterator[CallBounds]:
    """Bound the model calls the calling thread makes inside the block (see the module docstring)."""
    if not (deadline_s > 0 and math.isfinite(deadline_s)):
        raise ValueError(f"deadline must be a finite number of seconds > 0, got {deadline_s}")
    bounds = CallBounds(deadline_s, max_bytes)
    previous = getattr(_BOUNDS, "current", None)
    _BOUNDS.current = bounds
    try:
        yield bounds
    finally:
        _BOUNDS.current = previous


def _bounded_time(timeout: float | None, bounds: CallBounds, httpcore, error) -> float:
    """The time a network operation may take: ``timeout`` cut to the time left (``error`` raised when none is)."""
    left = bounds.left()
    if left <= 0:
        bounds.tripped = bounds.tripped or "deadline"
        raise error(f"the deadline of {bounds.deadline_s:g} s for the whole reply passed ({bounds.received} bytes received)")
    return left if timeout is None else min(timeout, left)


def _bounder():
    """A function that makes an httpx transport's connections obey :func:`call_bounds` (module docstring)."""
    import httpcore

    class BoundedStream(httpcore.NetworkStream):
        def __init__(self, inner):
            self._inner = inner

        def read(self, max_bytes: int, timeout: float | None = None) -> bytes:
            bounds = getattr(_BOUNDS, "current", None)
            if bounds is None:
                return self._inner.read(max_bytes, timeout)
            t = _bounded_time(timeout, bounds, httpcore, httpcore.ReadTimeout)
            try:
                data = self._inner.read(min(max_bytes, max(1, bounds.max_bytes - bounds.received + 1)), t)
            except httpcore.ReadTimeout:
                if timeout is None or t < timeout:  # the deadline, not httpx's own per-read time-out, ended the wait
                    bounds.tripped = bounds.tripped or "deadline"
                raise
            bounds.received += len(data)
            if bounds.received > bounds.max_bytes:
                bounds.tripped = "size"
                raise httpcore.ReadError(f"the reply is larger than {bounds.max_bytes} bytes")
            return data

        def write(self, buffer: bytes, timeout: float | None = None) -> None:
            bounds = getattr(_BOUNDS, "current", None)
            if bounds is None:
                return self._inner.write(buffer, timeout)
            t = _bounded_time(timeout, bounds, httpcore, httpcore.WriteTimeout)
            try:
                return self._inner.write(buffer, t)
            except httpcore.WriteTimeout:
                if timeout is None or t < timeout:
                    bounds.tripped = bounds.tripped or "deadline"
                raise

        def close(self) -> None:
            self._inner.close()

        def start_tls(self, ssl_context, server_hostname=None, timeout=None):
            bounds = getattr(_BOUNDS, "current", None)
            if bounds is not None:
                timeout = _bounded_time(timeout, bounds, httpcore, httpcore.ConnectTimeout)
            return BoundedStream(self._inner.start_tls(ssl_context, server_hostname, timeout))

        def get_extra_info(self, info: str):
            return self._inner.get_extra_info(info)

    class BoundedBackend(httpcore.NetworkBackend):
        def __init__(self, inner):
            self._inner = inner

        def _timeout(self, timeout):
            bounds = getattr(_BOUNDS, "current", None)
            return timeout if bounds is None else _bounded_time(timeout, bounds, httpcore, httpcore.ConnectTimeout)

        def connect_tcp(self, host, port, timeout=None, local_address=None, socket_options=None):
            return BoundedStream(self._inner.connect_tcp(host, port, self._timeout(timeout), local_address, socket_options))

        def connect_unix_socket(self, path, timeout=None, socket_options=None):
            return BoundedStream(self._inner.connect_unix_socket(path, self._timeout(timeout), socket_options))

        def sleep(self, seconds: float) -> None:
            self._inner.sleep(seconds)

    def bound(transport) -> None:
        pool = getattr(transport, "_pool", None)  # httpx keeps its httpcore pool here (httpx 0.28)
        if not isinstance(pool, httpcore.ConnectionPool) or not hasattr(pool, "_network_backend"):
            raise RuntimeError("httpx/httpcore changed: the bounded model transport cannot be installed")
        if not isinstance(pool._network_backend, BoundedBackend):
            pool._network_backend = BoundedBackend(pool._network_backend)

    return bound


#: Content codings a body may arrive in although the request asked for ``identity`` (inflated with a bounded output).
INFLATED = {"gzip": 16 + zlib.MAX_WBITS, "x-gzip": 16 + zlib.MAX_WBITS, "deflate": zlib.MAX_WBITS}
#: Bytes of compressed input handed to the decompressor at a time.
_INFLATE_STEP = 64 << 10


class BodyRefused(Exception):
    """A reply body the transport would not hand on (its :class:`CallBounds` says why)."""


def _codings(headers) -> list[str]:
    """The content codings of a response, outermost last (``identity`` left out)."""
    values = headers.get_list("content-encoding", split_commas=True) if hasattr(headers, "get_list") else []
    return [v.strip().lower() for v in values if v.strip() and v.strip().lower() != "identity"]


def decode_body(chunks, codings: list[str], bounds: CallBounds) -> bytes:
    """The decoded body of a response sent as ``chunks`` (raw bytes, as on the wire) in ``codings``, at most
    ``bounds.max_bytes`` decoded bytes ever held. Raises :class:`BodyRefused` (``bounds.failure`` and
    ``bounds.tripped`` set): ``size`` past the cap, ``invalid`` for several codings, one not in :data:`INFLATED` or a
    body that does not inflate."""
    if len(codings) > 1:
        bounds.tripped, bounds.failure = "invalid", ("MODEL_REPLY_INVALID", f"the reply's body is in nested encodings "
                                                     f"({', '.join(codings)}), which asset2sim does not inflate")
        raise BodyRefused(bounds.failure[1])
    if codings and codings[0] not in INFLATED:
        bounds.tripped, bounds.failure = "invalid", ("MODEL_REPLY_INVALID", f"the reply's body is encoded as {codings[0]!r}, "
                                                     "which asset2sim did not ask for (it asks for identity)")
        raise BodyRefused(bounds.failure[1])
    wbits = INFLATED[codings[0]] if codings else None
    inflate = zlib.decompressobj(wbits) if wbits is not None else None
    out, size = [], 0

    def keep(piece: bytes) -> None:
        nonlocal size
        size += len(piece)
        if size > bounds.max_bytes:
            bounds.tripped = "size"
            bounds.failure = ("MODEL_REPLY_TOO_LARGE", f"the decoded reply is larger than {bounds.max_bytes} bytes")
            raise BodyRefused(bounds.failure[1])
        out.append(piece)

    def feed(data: bytes) -> None:
        nonlocal inflate
        while data:
            keep(inflate.decompress(data, bounds.max_bytes - size + 1))  # never more than the cap out at once
            if inflate.eof:  # a gzip body may hold several members, one after another
                data = inflate.unused_data if wbits != zlib.MAX_WBITS else b""
                if data:
                    inflate = zlib.decompressobj(wbits)
            else:
                data = inflate.unconsumed_tail

    try:
        for chunk in chunks:
            if inflate is None:
                keep(chunk)
                continue
            for i in range(0, len(chunk), _INFLATE_STEP):
                feed(chunk[i:i + _INFLATE_STEP])
        if inflate is not None and not inflate.eof:
            keep(inflate.flush())
    except zlib.error as exc:
        bounds.tripped, bounds.failure = "invalid", ("MODEL_REPLY_INVALID", f"the reply's {codings[0]} body does not inflate ({exc})")
        raise BodyRefused(bounds.failure[1]) from None
    return b"".join(out)


def _decoded_transport(inner):
    """``inner`` (an httpx transport) wrapped so that, within :func:`call_bounds`, requests ask for
    ``Accept-Encoding: identity`` and responses come back decoded and bounded (:func:`decode_body`), the status and
    a refused connection recorded on the attempt's :class:`CallBounds` (module docstring)."""
    import httpx

    class DecodedTransport(httpx.BaseTransport):
        def __init__(self, wrapped):
            self.wrapped = wrapped

        def handle_request(self, request):
            bounds = getattr(_BOUNDS, "current", None)
            if bounds is None:
                return self.wrapped.handle_request(request)
            request.headers["Accept-Encoding"] = "identity"
            try:
                response = self.wrapped.handle_request(request)
            except httpx.ConnectError as exc:
                if bounds.failure is None:
                    bounds.failure = ("MODEL_CONNECTION_REFUSED", f"no connection to {request.url.scheme}://{request.url.host}"
                                      f":{request.url.port or ''} ({first_line(exc) or 'refused'})")
                raise
            bounds.status = response.status_code
            try:
                body = decode_body(response.stream, _codings(response.headers), bounds)
            except BodyRefused as exc:
                response.close()
                raise httpx.DecodingError(str(exc), request=request) from None
            finally:
                response.close()
            headers = [(k, v) for k, v in response.headers.multi_items() if k.lower() not in ("content-encoding", "content-length",
                                                                                                 "transfer-encoding")]
            return httpx.Response(response.status_code, headers=headers, content=body, request=request,
                                  extensions={k: v for k, v in response.extensions.items() if k != "network_stream"})

        def close(self) -> None:
            self.wrapped.close()

    return DecodedTransport(inner)


def bounded_client():
    """An ``httpx.Client`` (redirects followed, proxies and certificates from the environment as httpx reads
    them) whose every transport obeys :func:`call_bounds` and decodes bodies itself (:func:`decode_body`)."""
    import httpx

    client = httpx.Client(follow_redirects=True)
    bound = _bounder()
    for transport in [client._transport, *client._mounts.values()]:  # the proxies' transports too
        if transport is not None:
            bound(transport)
    client._transport = _decoded_transport(client._transport)
    client._mounts = {pattern: None if t is None else _decoded_transport(t) for pattern, t in client._mounts.items()}
    return client


def bounded_transport():
    """An httpx transport whose connections obey :func:`call_bounds` and whose bodies are decoded and bounded here
    (module docstring)."""
    import httpx

    transport = httpx.HTTPTransport()
    _bounder()(transport)
    return _decoded_transport(transport)


def _install_bounded_transport(litellm) -> None:
    """Give litellm bounded connections (unless the user set ``client_session`` / ``sync_transport``). The
    providers litellm reaches through its own HTTP handler take one transport for every URL, which would
    drop the proxies of the environment: with ``HTTP(S)_PROXY`` / ``ALL_PROXY`` set they keep httpx's
    per-read time-out only."""
    if getattr(litellm, "client_session", None) is None:
        litellm.client_session = bounded_client()
    if getattr(litellm, "sync_transport", None) is None and not [k for k in urllib.request.getproxies() if k != "no"]:
        litellm.sync_transport = bounded_transport()


def import_litellm():
    """Import and quiet litellm (local cost table, no debug prints); LLMUnavailable when missing or forbidden."""
    with _LITELLM_LOCK:
        os.environ.setdefault("LITELLM_LOCAL_MODEL_COST_MAP", "True")  # no network fetch of the cost table
        try:
            from importlib.metadata import PackageNotFoundError, version

            try:
                v = version("litellm")
            except PackageNotFoundError:
                v = None
            if v in FORBIDDEN_LITELLM:
                raise LLMUnavailable(f"litellm {v} is installed; that version must not be used (reported compromised). Install asset2sim[llm] (litellm==1.100.5).")
            import litellm
        except ImportError as exc:
            raise LLMUnavailable("model backends need litellm: pip install 'asset2sim[llm]' (litellm==1.100.5)") from exc
        litellm.suppress_debug_info = True
        litellm.set_verbose = False
        _install_bounded_transport(litellm)
        return litellm


def retry_after_s(exc: BaseException) -> float | None:
    """Seconds a litellm / OpenAI SDK exception's server asked to wait (``retry-after-ms``, or ``Retry-After``
    in seconds or as an HTTP date), or None."""
    headers = (getattr(exc, "litellm_response_headers", None) or getattr(exc, "headers", None)
               or getattr(getattr(exc, "response", None), "headers", None))
    if not headers:
        return None
    get = getattr(headers, "get", None)
    if get is None:
        return None
    ms = get("retry-after-ms") or get("Retry-After-Ms")
    if ms:
        try:
            return max(0.0, float(ms) / 1000.0)
        except ValueError:
            pass
    ra = get("retry-after") or get("Retry-After")
    if not ra:
        return None
    try:
        return max(0.0, float(ra))
    except ValueError:
        pass
    try:
        when = email.utils.parsedate_to_datetime(ra)
    except (TypeError, ValueError):
        return None
    return max(0.0, when.timestamp() - time.time())


def status_of(exc: BaseException) -> int | None:
    """HTTP status of an exception (``status_code`` on it or its ``response``), or None."""
    s = getattr(exc, "status_code", None)
    if isinstance(s, int):
        return s
    resp = getattr(exc, "response", None)
    s = getattr(resp, "status_code", None)
    return s if isinstance(s, int) else None


def classify(exc: BaseException, litellm=None) -> tuple[bool, int | None, str]:
    """(retryable, HTTP status or None, short kind) of an exception raised by a call."""
    name = type(exc).__name__
    status = status_of(exc)
    if litellm is not None:
        if isinstance(exc, getattr(litellm, "Timeout", ())):
            return True, status, "timeout"
        if isinstance(exc, getattr(litellm, "APIConnectionError", ())):
            return True, status, "connection error"
        if isinstance(exc, getattr(litellm, "ContextWindowExceededError", ())):
            return False, status, "context window exceeded"
        if isinstance(exc, getattr(litellm, "ContentPolicyViolationError", ())):
            return False, status, "content policy violation"
        if isinstance(exc, (getattr(litellm, "AuthenticationError", ()), getattr(litellm, "PermissionDeniedError", ()))):
            return False, status, "authentication error"
    if isinstance(exc, (TimeoutError, ConnectionError)):
        return True, status, "connection error"
    if status is not None:
        return status in RETRYABLE_STATUS, status, f"HTTP {status}"
    return False, None, name


def short_error(exc: BaseException, limit: int = 300) -> str:
    """The first line of ``exc``'s message, no traceback (litellm puts one in some messages), control characters
    escaped, cut to ``limit`` characters (:func:`asset2sim.inert.one_line`)."""
    return one_line(exc, limit)


def first_line(exc: BaseException) -> str:
    """:func:`short_error` at 160 characters."""
    return one_line(exc, 160)
