"""The network side of model calls: litellm imported on first use (refused in a
forbidden version), faults classified as retryable or not, and the wait a
server asks for. The retry loop is ``LLMClient.complete``."""

from __future__ import annotations

import email.utils
import os
import threading
import time

from asset2sim.tasks.synthesize.llm_errors import LLMUnavailable

#: litellm version that must never be used (reported compromised).
FORBIDDEN_LITELLM = {"1.107.0"}

#: HTTP statuses worth retrying (rate limit, overload, transient server faults).
RETRYABLE_STATUS = {408, 409, 425, 429, 500, 502, 503, 504, 529}

#: Placeholder key for local servers that need none (the OpenAI SDK refuses an empty key).
NO_KEY = "no-key-needed"

_LITELLM_LOCK = threading.Lock()


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
    """The message of ``exc`` on one line, cut to ``limit`` characters."""
    s = str(exc).replace("\n", " ")
    return s if len(s) <= limit else s[:limit] + "..."
