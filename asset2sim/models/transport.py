"""The network side of model calls: litellm imported on first use (refused in a forbidden version)
and given a bounded HTTP transport, faults classified as retryable or not, and the wait a server
asks for. The retry loop is ``LLMClient.complete``.

Bounds of one attempt (:func:`call_bounds`): httpx's time-out is per read, so a server that sends
one byte a second never trips it, and a reply is read whole before anything looks at its size. The
transport litellm is given (``litellm.client_session`` for OpenAI-compatible providers,
``litellm.sync_transport`` for the others) wraps httpcore's network backend so that every connect,
write and read of the calling thread gets at most the time left to the attempt's deadline, and
counts the bytes read: past the deadline or past the size cap the socket read raises at once and
the attempt is recorded as ``deadline`` or ``size`` (:class:`CallBounds`), which the client turns
into :class:`~asset2sim.models.errors.DeadlineExceeded` or
:class:`~asset2sim.models.errors.ReplyTooLarge`. Memory stays bounded by the cap; calls outside
:func:`call_bounds` pass through unchanged.

The reply's body is decoded here, not by httpx (``DecodedTransport``): every request asks for
``Accept-Encoding: identity``; a body the server compresses anyway (one ``gzip`` or ``deflate``) is
inflated in steps that never hold more than the cap, the *decoded* bytes counted against it (a
1 MB gzip body of 1 GiB is refused once 16 MiB are out, ``size``), and a body in any other or in
several encodings (gzip inside gzip) is refused before it is inflated (``invalid``). What happened
is recorded on the attempt's :class:`CallBounds` (``failure``: the code and one sentence;
``status``: the HTTP status the server sent), so the client names a fault by what it was (an
invalid reply, too large, the deadline, a refused connection, a connection that never got an HTTP
status) whatever exception litellm wraps it in. A redirect is never followed: the request (the
prompt, the part names) goes to the server the user named and nowhere else
(``MODEL_REDIRECT_REFUSED``, ``docs/design/trust.md``).
"""

from __future__ import annotations

import email.utils
import importlib.metadata
import math
import os
import threading
import time
import urllib.request
import zlib
from contextlib import contextmanager
from typing import Iterator

from asset2sim.inert import one_line
from asset2sim.models.errors import LLMUnavailable

#: litellm version that must never be used (reported compromised).
FORBIDDEN_LITELLM = {"1.107.0"}

#: HTTP statuses worth retrying (rate limit, overload, transient server faults).
RETRYABLE_STATUS = {408, 409, 425, 429, 500, 502, 503, 504, 529}

#: Placeholder key for local servers that need none (the OpenAI SDK refuses an empty key).
NO_KEY = "no-key-needed"

#: Content codings a body may arrive in although the request asked for ``identity`` (inflated with
#: a bounded output).
INFLATED = {"gzip": 16 + zlib.MAX_WBITS, "x-gzip": 16 + zlib.MAX_WBITS, "deflate": zlib.MAX_WBITS}
#: Bytes of compressed input handed to the decompressor at a time.
_INFLATE_STEP = 64 << 10

_LITELLM_LOCK = threading.Lock()
_BOUNDS = threading.local()


class CallBounds:
    """The bounds of one HTTP attempt of the calling thread: ``deadline_s`` (s, from entering
    :func:`call_bounds`) for connecting, sending and every read, ``max_bytes`` read in all.
    ``received``: bytes read so far; ``tripped``: ``"deadline"``, ``"size"`` or ``"invalid"`` once
    a bound stopped the attempt, else None; ``status``: the HTTP status of the attempt's last
    response (None before one arrives); ``requests``: requests sent through the bounded transport;
    ``failure``: (code, one sentence) of what went wrong at the transport (a refused connection, a
    redirect, an undecodable body)."""

    def __init__(self, deadline_s: float, max_bytes: int):
        self.deadline_s = float(deadline_s)
        self.max_bytes = int(max_bytes)
        self.start = time.monotonic()
        self.received = 0
        self.tripped: str | None = None
        self.status: int | None = None
        self.requests = 0
        self.failure: tuple[str, str] | None = None

    def left(self) -> float:
        """Seconds left before the deadline (<= 0: passed)."""
        return self.deadline_s - (time.monotonic() - self.start)

    def refuse(self, tripped: str, code: str, sentence: str) -> "BodyRefused":
        """Record why a body is refused (``tripped``, ``failure``); the exception that says so."""
        self.tripped, self.failure = tripped, (code, sentence)
        return BodyRefused(sentence)


def _current() -> CallBounds | None:
    """The bounds of the calling thread's attempt (None outside :func:`call_bounds`)."""
    return getattr(_BOUNDS, "current", None)


@contextmanager
def call_bounds(deadline_s: float, max_bytes: int) -> Iterator[CallBounds]:
    """Bound the model calls the calling thread makes inside the block (see the module docstring).
    ValueError for a deadline that is not a finite number of seconds > 0."""
    if not (deadline_s > 0 and math.isfinite(deadline_s)):
        raise ValueError(f"deadline must be a finite number of seconds > 0, got {deadline_s}")
    bounds = CallBounds(deadline_s, max_bytes)
    previous = _current()
    _BOUNDS.current = bounds
    try:
        yield bounds
    finally:
        _BOUNDS.current = previous


def _bounded_time(timeout: float | None, bounds: CallBounds, error) -> float:
    """The time a network operation may take: ``timeout`` cut to the time left (``error`` raised
    when none is)."""
    left = bounds.left()
    if left <= 0:
        bounds.tripped = bounds.tripped or "deadline"
        raise error(f"the deadline of {bounds.deadline_s:g} s for the whole reply passed "
                    f"({bounds.received} bytes received)")
    return left if timeout is None else min(timeout, left)


def _within_deadline(bounds: CallBounds | None, timeout: float | None, timeout_error: type[Exception], call):
    """``call(t)`` with ``t`` the time it may take (:func:`_bounded_time`; ``timeout`` itself without ``bounds``); its
    ``timeout_error`` after the attempt's deadline, not httpx's per-operation time-out, records the attempt as
    ``deadline``."""
    if bounds is None:  # outside call_bounds: httpx's own time-out
        return call(timeout)
    t = _bounded_time(timeout, bounds, timeout_error)
    try:
        return call(t)
    except timeout_error:
        if timeout is None or t < timeout:
            bounds.tripped = bounds.tripped or "deadline"
        raise


def _bounder():
    """A function that makes an httpx transport's connections obey :func:`call_bounds` (module
    docstring)."""
    import httpcore

    def connect_time(timeout):
        """The time a connection or TLS handshake may take within :func:`call_bounds` (``timeout`` outside)."""
        bounds = _current()
        return timeout if bounds is None else _bounded_time(timeout, bounds, httpcore.ConnectTimeout)

    class BoundedStream(httpcore.NetworkStream):
        def __init__(self, inner):
            self._inner = inner

        def read(self, max_bytes: int, timeout: float | None = None) -> bytes:
            bounds = _current()
            if bounds is None:
                return self._inner.read(max_bytes, timeout)
            room = max(1, bounds.max_bytes - bounds.received + 1)
            data = _within_deadline(bounds, timeout, httpcore.ReadTimeout, lambda t: self._inner.read(min(max_bytes, room), t))
            bounds.received += len(data)
            if bounds.received > bounds.max_bytes:
                bounds.tripped = "size"
                raise httpcore.ReadError(f"the reply is larger than {bounds.max_bytes} bytes")
            return data

        def write(self, buffer: bytes, timeout: float | None = None) -> None:
            return _within_deadline(_current(), timeout, httpcore.WriteTimeout, lambda t: self._inner.write(buffer, t))

        def close(self) -> None:
            self._inner.close()

        def start_tls(self, ssl_context, server_hostname=None, timeout=None):
            return BoundedStream(self._inner.start_tls(ssl_context, server_hostname, connect_time(timeout)))

        def get_extra_info(self, info: str):
            return self._inner.get_extra_info(info)

    class BoundedBackend(httpcore.NetworkBackend):
        def __init__(self, inner):
            self._inner = inner

        def connect_tcp(self, host, port, timeout=None, local_address=None, socket_options=None):
            return BoundedStream(self._inner.connect_tcp(host, port, connect_time(timeout),
                                                         local_address, socket_options))

        def connect_unix_socket(self, path, timeout=None, socket_options=None):
            return BoundedStream(self._inner.connect_unix_socket(path, connect_time(timeout),
                                                                 socket_options))

        def sleep(self, seconds: float) -> None:
            self._inner.sleep(seconds)

    def bound(transport) -> None:
        pool = getattr(transport, "_pool", None)  # httpx keeps its httpcore pool here (httpx 0.28)
        if not isinstance(pool, httpcore.ConnectionPool) or not hasattr(pool, "_network_backend"):
            raise RuntimeError("httpx/httpcore changed: the bounded model transport cannot be "
                               "installed")
        if not isinstance(pool._network_backend, BoundedBackend):
            pool._network_backend = BoundedBackend(pool._network_backend)

    return bound


class BodyRefused(Exception):
    """A reply body the transport would not hand on (its :class:`CallBounds` says why)."""


def _codings(headers) -> list[str]:
    """The content codings of a response, outermost last (``identity`` left out)."""
    if not hasattr(headers, "get_list"):
        return []
    values = headers.get_list("content-encoding", split_commas=True)
    return [c for v in values if (c := v.strip().lower()) not in ("", "identity")]


def decode_body(chunks, codings: list[str], bounds: CallBounds) -> bytes:
    """The decoded body of a response sent as ``chunks`` (raw bytes, as on the wire) in ``codings``,
    at most ``bounds.max_bytes`` decoded bytes ever held. Raises :class:`BodyRefused`
    (``bounds.failure`` and ``bounds.tripped`` set): ``size`` past the cap, ``invalid`` for several
    codings, one not in :data:`INFLATED` or a body that does not inflate."""
    invalid = "MODEL_REPLY_INVALID"
    if len(codings) > 1:
        raise bounds.refuse("invalid", invalid, f"the reply's body is in nested encodings "
                            f"({', '.join(codings)}), which asset2sim does not inflate")
    if codings and codings[0] not in INFLATED:
        raise bounds.refuse("invalid", invalid, f"the reply's body is encoded as {codings[0]!r}, "
                            "which asset2sim did not ask for (it asks for identity)")
    wbits = INFLATED[codings[0]] if codings else None
    inflate = zlib.decompressobj(wbits) if codings else None
    out, size = [], 0

    def keep(piece: bytes) -> None:
        nonlocal size
        size += len(piece)
        if size > bounds.max_bytes:
            raise bounds.refuse("size", "MODEL_REPLY_TOO_LARGE",
                                f"the decoded reply is larger than {bounds.max_bytes} bytes")
        out.append(piece)

    def feed(data: bytes) -> None:
        nonlocal inflate
        while data:
            keep(inflate.decompress(data, bounds.max_bytes - size + 1))  # never more than the cap
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
        raise bounds.refuse("invalid", invalid,
                            f"the reply's {codings[0]} body does not inflate ({exc})") from None
    return b"".join(out)


def _decoded_transport(inner):
    """``inner`` (an httpx transport) wrapped so that, within :func:`call_bounds`, requests ask for
    ``Accept-Encoding: identity`` and responses come back decoded and bounded
    (:func:`decode_body`), the status and a refused connection recorded on the attempt's
    :class:`CallBounds` (module docstring)."""
    import httpx

    class DecodedTransport(httpx.BaseTransport):
        def __init__(self, wrapped):
            self.wrapped = wrapped

        def handle_request(self, request):
            bounds = _current()
            if bounds is None:
                return self.wrapped.handle_request(request)
            request.headers["Accept-Encoding"] = "identity"
            bounds.requests += 1
            url = request.url
            server = f"{url.scheme}://{url.host}:{url.port or ''}"
            try:
                response = self.wrapped.handle_request(request)
            except httpx.ConnectError as exc:
                if bounds.failure is None:
                    why = one_line(exc, 160) or "refused"
                    bounds.failure = ("MODEL_CONNECTION_REFUSED", f"no connection to {server} ({why})")
                raise
            bounds.status = response.status_code
            if response.has_redirect_location:  # never sent on: the user named one server
                response.close()
                to = response.headers.get("location", "")
                bounds.failure = ("MODEL_REDIRECT_REFUSED", f"the server at {server} "
                                  f"answered HTTP {response.status_code} with a redirect to {one_line(to, 160)!r}, not "
                                  "followed (give that address as --base-url to use it)")
                raise httpx.TransportError(bounds.failure[1], request=request)
            try:
                body = decode_body(response.stream, _codings(response.headers), bounds)
            except BodyRefused as exc:
                raise httpx.DecodingError(str(exc), request=request) from None
            finally:
                response.close()
            dropped = ("content-encoding", "content-length", "transfer-encoding")
            headers = [kv for kv in response.headers.multi_items() if kv[0].lower() not in dropped]
            extensions = {k: v for k, v in response.extensions.items() if k != "network_stream"}
            return httpx.Response(response.status_code, headers=headers, content=body,
                                  request=request, extensions=extensions)

        def close(self) -> None:
            self.wrapped.close()

    return DecodedTransport(inner)


def _install_bounded_transport(litellm) -> None:
    """Give litellm bounded connections that decode bodies themselves (:func:`decode_body`), unless
    the user set ``client_session`` / ``sync_transport``: an ``httpx.Client`` (redirects not followed,
    proxies and certificates from the environment as httpx reads them, every proxy's transport
    bounded too) and a plain transport. The providers litellm reaches through its own HTTP handler
    take one transport for every URL, which would drop the proxies of the environment: with
    ``HTTP(S)_PROXY`` / ``ALL_PROXY`` set they keep httpx's per-read time-out only."""
    import httpx

    bound = _bounder()

    def bounded(transport):
        bound(transport)
        return _decoded_transport(transport)

    if getattr(litellm, "client_session", None) is None:
        client = httpx.Client(follow_redirects=False)
        client._transport = bounded(client._transport)
        client._mounts = {pattern: None if t is None else bounded(t) for pattern, t in client._mounts.items()}
        litellm.client_session = client
    proxies = [k for k in urllib.request.getproxies() if k != "no"]
    if getattr(litellm, "sync_transport", None) is None and not proxies:
        litellm.sync_transport = bounded(httpx.HTTPTransport())


def import_litellm():
    """Import and quiet litellm (local cost table, no debug prints); LLMUnavailable when missing or
    forbidden."""
    with _LITELLM_LOCK:
        os.environ.setdefault("LITELLM_LOCAL_MODEL_COST_MAP", "True")  # no fetch of the table
        try:
            try:
                v = importlib.metadata.version("litellm")
            except importlib.metadata.PackageNotFoundError:
                v = None
            if v in FORBIDDEN_LITELLM:
                raise LLMUnavailable(f"litellm {v} is installed; that version must not be used "
                                     "(reported compromised). Install asset2sim[llm] "
                                     "(litellm==1.100.5).")
            import litellm
        except ImportError as exc:
            raise LLMUnavailable("model backends need litellm: pip install 'asset2sim[llm]' "
                                 "(litellm==1.100.5)") from exc
        litellm.suppress_debug_info = True
        litellm.set_verbose = False
        _install_bounded_transport(litellm)
        return litellm


def retry_after_s(exc: BaseException) -> float | None:
    """Seconds a litellm / OpenAI SDK exception's server asked to wait (``retry-after-ms``, or
    ``Retry-After`` in seconds or as an HTTP date), or None."""
    headers = (getattr(exc, "litellm_response_headers", None) or getattr(exc, "headers", None)
               or getattr(getattr(exc, "response", None), "headers", None))
    get = getattr(headers, "get", None) if headers else None
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


def classify(exc: BaseException, litellm=None) -> tuple[bool, int | None, str]:
    """(retryable, HTTP status or None, short kind) of an exception raised by a call; the status is
    ``status_code`` on the exception or on its ``response``."""
    status = getattr(exc, "status_code", None)
    if not isinstance(status, int):
        status = getattr(getattr(exc, "response", None), "status_code", None)
        status = status if isinstance(status, int) else None
    if litellm is not None:
        kinds = [("Timeout", True, "timeout"), ("APIConnectionError", True, "connection error"),
                 ("ContextWindowExceededError", False, "context window exceeded"),
                 ("ContentPolicyViolationError", False, "content policy violation"),
                 ("AuthenticationError", False, "authentication error"),
                 ("PermissionDeniedError", False, "authentication error")]
        for name, retryable, kind in kinds:
            if isinstance(exc, getattr(litellm, name, ())):
                return retryable, status, kind
    if isinstance(exc, (TimeoutError, ConnectionError)):
        return True, status, "connection error"
    if status is not None:
        return status in RETRYABLE_STATUS, status, f"HTTP {status}"
    return False, None, type(exc).__name__
