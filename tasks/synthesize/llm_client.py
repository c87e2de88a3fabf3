"""The one place that calls model APIs (through litellm).

Everything a model backend needs from the network lives here:

- **calls** through ``litellm.completion`` (any provider: ``gemini/...``,
  ``openai/...``, ``anthropic/...``, a local OpenAI-compatible server through
  ``base_url``), each with a timeout; litellm's and the OpenAI SDK's own
  retries are switched off (``max_retries=0``, ``num_retries=0``) so that
- **network faults are retried here and only here**: timeouts, dropped
  connections, HTTP 408/409/425/429/5xx/529 are retried up to
  ``max_attempts`` tries per call with exponential backoff
  (``backoff_s * 2**k``, capped at ``max_backoff_s``) that honours the
  server's ``Retry-After`` / ``retry-after-ms`` header (waiting at least that
  long; a wait longer than ``max_retry_after_s`` fails at once). Other errors
  (400, 401, 403, 404, ...) fail at once.
- **an on-disk reply cache** keyed by the sha256 of (model, messages with
  their images, JSON schema, sampling parameters): a rerun makes no calls.
  Only replies that parsed into the reply schema are stored (a transient
  garbled reply is asked again on the next run).
- **strict JSON parsing** (:func:`parse_json_strict`): non-finite numbers
  (``NaN``, ``Infinity``, ``1e999``), duplicate keys and anything but one JSON
  object are rejected; the schema model then rejects extra and missing fields
  and out-of-range values.
- **re-asking** (:meth:`LLMClient.ask`): an unusable reply (prose, truncated,
  refused, too large, failing the schema or the caller's validator) is asked
  again with the list of problems, at most ``max_reasks`` (2) times.
- **accounting** (:class:`Usage`): calls, HTTP attempts, cache hits, tokens,
  cost in USD when litellm's cost table knows the model, wall time.

litellm is imported only inside the functions that need it; the package
imports without it. Settings come from :class:`ClientConfig` (environment
variables ``ASSET2SIM_LLM_*`` for operational knobs, see
:meth:`ClientConfig.from_env`). API keys are read from the providers' usual
environment variables by litellm and are never stored, logged or hashed.
"""

from __future__ import annotations

import email.utils
import hashlib
import json
import math
import os
import threading
import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Callable, Generic, TypeVar

from pydantic import BaseModel, ValidationError

from asset2sim import atomic

#: litellm version that must never be used (reported compromised).
FORBIDDEN_LITELLM = {"1.107.0"}

#: HTTP statuses worth retrying (rate limit, overload, transient server faults).
RETRYABLE_STATUS = {408, 409, 425, 429, 500, 502, 503, 504, 529}

#: Placeholder key for local servers that need none (the OpenAI SDK refuses an
#: empty key even when the server ignores it).
NO_KEY = "no-key-needed"

CACHE_FORMAT = 1


# ---------------------------------------------------------------------- errors
class LLMError(RuntimeError):
    """Base class of model-backend errors (the message says what and why)."""


class LLMUnavailable(LLMError):
    """litellm is not installed, or is a forbidden version."""


class MissingCredentials(LLMError):
    """The provider needs an API key that is not in the environment."""


class ModelCallError(LLMError):
    """A call failed: a non-retryable API error, or retries exhausted.
    ``attempts`` HTTP tries were made; ``status`` is the last HTTP status or None."""

    def __init__(self, message: str, attempts: int, status: int | None = None):
        super().__init__(message)
        self.attempts = attempts
        self.status = status


class ReplyInvalid(LLMError):
    """One reply is unusable; ``errors`` lists the problems (sent back to the
    model when re-asking)."""

    def __init__(self, errors: list[str]):
        self.errors = [str(e) for e in errors] or ["unusable reply"]
        super().__init__("; ".join(self.errors[:10]) + (f" (+{len(self.errors) - 10} more)" if len(self.errors) > 10 else ""))


class ReplyError(LLMError):
    """Every reply (first answer and re-asks) was unusable; ``history`` holds
    the problems of each attempt."""

    def __init__(self, message: str, history: list[list[str]]):
        super().__init__(message)
        self.history = history


# --------------------------------------------------------------------- config
def _env_float(name: str, default: float) -> float:
    v = os.environ.get(name)
    if v is None or v == "":
        return default
    try:
        x = float(v)
    except ValueError as exc:
        raise ValueError(f"environment variable {name}={v!r} is not a number") from exc
    if not math.isfinite(x) or x < 0:
        raise ValueError(f"environment variable {name}={v!r} must be a finite number >= 0")
    return x


def default_cache_dir() -> Path:
    """``$ASSET2SIM_LLM_CACHE_DIR``, else ``$XDG_CACHE_HOME/asset2sim/llm``,
    else ``~/.cache/asset2sim/llm``."""
    env = os.environ.get("ASSET2SIM_LLM_CACHE_DIR")
    if env:
        return Path(env).expanduser()
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "asset2sim" / "llm"


@dataclass(frozen=True)
class ClientConfig:
    """Settings of one :class:`LLMClient`.

    Attributes:
        model: litellm model string, ``provider/name`` (``gemini/gemini-2.5-flash``).
        base_url: API base of an OpenAI-compatible or local server (no key needed).
        api_key: explicit key (else the provider's environment variable is used;
            with ``base_url`` and no key a placeholder is sent). Never hashed.
        timeout_s: per-attempt timeout, s.
        max_attempts: HTTP tries per call (1 + retries), >= 1.
        backoff_s: delay before the first retry, s (doubled each retry).
        max_backoff_s: cap on the computed backoff, s.
        max_retry_after_s: longest server-requested wait that is honoured, s;
            a longer ``Retry-After`` fails the call at once.
        max_reply_chars: longest reply accepted, characters.
        max_tokens: completion token limit sent with each call.
        temperature: sampling temperature (None: the provider's default).
        cache_dir: reply cache folder; None disables the cache.
        render_size: (width, height) pixels of the views sent to the model.
    """

    model: str
    base_url: str | None = None
    api_key: str | None = field(default=None, repr=False)
    timeout_s: float = 120.0
    max_attempts: int = 4
    backoff_s: float = 2.0
    max_backoff_s: float = 60.0
    max_retry_after_s: float = 300.0
    max_reply_chars: int = 1_000_000
    max_tokens: int = 16384
    temperature: float | None = 0.0
    cache_dir: Path | None = None
    render_size: tuple[int, int] = (384, 384)

    def __post_init__(self):
        if not self.model or not isinstance(self.model, str):
            raise ValueError("a model string is required (e.g. gemini/gemini-2.5-flash)")
        if self.max_attempts < 1:
            raise ValueError(f"max_attempts must be >= 1, got {self.max_attempts}")
        if not (self.timeout_s > 0):
            raise ValueError(f"timeout_s must be > 0, got {self.timeout_s}")

    @classmethod
    def from_env(cls, model: str, base_url: str | None = None, **overrides) -> "ClientConfig":
        """Config for ``model`` with knobs from the environment:
        ``ASSET2SIM_LLM_TIMEOUT_S`` (120), ``ASSET2SIM_LLM_MAX_ATTEMPTS`` (4),
        ``ASSET2SIM_LLM_BACKOFF_S`` (2), ``ASSET2SIM_LLM_MAX_BACKOFF_S`` (60),
        ``ASSET2SIM_LLM_MAX_RETRY_AFTER_S`` (300), ``ASSET2SIM_LLM_MAX_REPLY_CHARS``
        (1e6), ``ASSET2SIM_LLM_MAX_TOKENS`` (16384), ``ASSET2SIM_LLM_RENDER_SIZE``
        (384), ``ASSET2SIM_LLM_CACHE_DIR`` (:func:`default_cache_dir`; ``off``
        disables the cache). Keyword ``overrides`` win.

        Raises:
            ValueError: a malformed environment value.
        """
        cache_env = os.environ.get("ASSET2SIM_LLM_CACHE_DIR", "")
        size = int(_env_float("ASSET2SIM_LLM_RENDER_SIZE", 384))
        kw: dict[str, Any] = dict(
            model=model,
            base_url=base_url,
            timeout_s=_env_float("ASSET2SIM_LLM_TIMEOUT_S", 120.0),
            max_attempts=int(_env_float("ASSET2SIM_LLM_MAX_ATTEMPTS", 4)),
            backoff_s=_env_float("ASSET2SIM_LLM_BACKOFF_S", 2.0),
            max_backoff_s=_env_float("ASSET2SIM_LLM_MAX_BACKOFF_S", 60.0),
            max_retry_after_s=_env_float("ASSET2SIM_LLM_MAX_RETRY_AFTER_S", 300.0),
            max_reply_chars=int(_env_float("ASSET2SIM_LLM_MAX_REPLY_CHARS", 1_000_000)),
            max_tokens=int(_env_float("ASSET2SIM_LLM_MAX_TOKENS", 16384)),
            cache_dir=None if cache_env.lower() in ("off", "none", "0") else default_cache_dir(),
            render_size=(max(size, 16), max(size, 16)),
        )
        kw.update(overrides)
        return cls(**kw)


# ------------------------------------------------------------------- litellm
_LITELLM_LOCK = threading.Lock()


def import_litellm():
    """Import and quiet litellm (local cost table, no debug prints).

    Raises:
        LLMUnavailable: litellm is missing or a forbidden version.
    """
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


# ------------------------------------------------------------- strict parsing
class _Reject(ValueError):
    pass


def _no_duplicates(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for k, v in pairs:
        if k in out:
            raise _Reject(f"duplicate key {k!r}")
        out[k] = v
    return out


def _no_constant(name: str) -> Any:
    raise _Reject(f"non-finite number {name} is not allowed")


def _finite_float(text: str) -> float:
    x = float(text)
    if not math.isfinite(x):
        raise _Reject(f"number {text} overflows to a non-finite value")
    return x


def _strip_fence(text: str) -> str:
    """Remove one Markdown code fence around the whole text (```json ... ```),
    which many models add although asked not to; anything else is kept."""
    t = text.strip()
    if t.startswith("```") and t.endswith("```") and len(t) >= 6:
        first_nl = t.find("\n")
        if first_nl > 0 and t[3:first_nl].strip().lower() in ("", "json"):
            return t[first_nl + 1 : -3].strip()
    return t


def parse_json_strict(text: str) -> dict[str, Any]:
    """Parse one JSON object strictly.

    Rejects: anything but a single JSON object (prose, several values, a
    truncated document), duplicate keys at any depth, ``NaN`` / ``Infinity`` /
    numbers that overflow to infinity. One Markdown code fence around the whole
    reply is tolerated.

    Raises:
        ReplyInvalid: with one message naming the problem and its position.
    """
    t = _strip_fence(text)
    dec = json.JSONDecoder(object_pairs_hook=_no_duplicates, parse_constant=_no_constant, parse_float=_finite_float)
    try:
        obj, end = dec.raw_decode(t)
    except _Reject as exc:
        raise ReplyInvalid([f"invalid JSON: {exc}"]) from None
    except json.JSONDecodeError as exc:
        what = "the reply is not JSON" if exc.pos == 0 else "invalid or truncated JSON"
        raise ReplyInvalid([f"{what}: {exc.msg} at line {exc.lineno} column {exc.colno} (character {exc.pos} of {len(t)})"]) from None
    except ValueError as exc:  # e.g. an integer with too many digits
        raise ReplyInvalid([f"invalid JSON: {exc}"]) from None
    if t[end:].strip():
        raise ReplyInvalid([f"extra text after the JSON object at character {end} of {len(t)}"])
    if not isinstance(obj, dict):
        raise ReplyInvalid([f"the reply must be one JSON object, got {type(obj).__name__}"])
    return obj


M = TypeVar("M", bound=BaseModel)


def pydantic_errors(exc: ValidationError, limit: int = 30) -> list[str]:
    """One line per error: ``path.to.field: message (got value)``."""
    out = []
    for e in exc.errors()[:limit]:
        loc = ".".join(str(p) for p in e.get("loc", ())) or "(top level)"
        got = e.get("input")
        got_s = "" if isinstance(got, (dict, list)) else f" (got {json.dumps(got)[:60] if _jsonable(got) else repr(got)[:60]})"
        out.append(f"{loc}: {e.get('msg', 'invalid')}{got_s}")
    if len(exc.errors()) > limit:
        out.append(f"... and {len(exc.errors()) - limit} more errors")
    return out


def _jsonable(x: Any) -> bool:
    try:
        json.dumps(x)
        return True
    except (TypeError, ValueError):
        return False


def parse_reply(text: str, model_cls: type[M]) -> M:
    """Strictly parse ``text`` into ``model_cls`` (strict JSON, then the pydantic
    model in strict mode: no type coercion, extra fields forbidden by the model).

    Raises:
        ReplyInvalid: every problem found.
    """
    obj = parse_json_strict(text)
    try:
        return model_cls.model_validate(obj, strict=True)
    except ValidationError as exc:
        raise ReplyInvalid(pydantic_errors(exc)) from None


# ----------------------------------------------------------------- accounting
@dataclass
class Usage:
    """What calls cost. ``calls``: model replies received over the network
    (re-asks included, cache hits and failed HTTP tries excluded);
    ``attempts``: HTTP tries; ``cached``: replies served from the cache;
    tokens as reported by the API (0 when unknown); ``cost_usd``: sum of the
    costs litellm knows (None when it knows none); ``seconds``: wall time in
    calls, retries and backoff included."""

    calls: int = 0
    attempts: int = 0
    cached: int = 0
    prompt_tokens: int = 0
    completion_tokens: int = 0
    total_tokens: int = 0
    cost_usd: float | None = None
    seconds: float = 0.0

    def add(self, other: "Usage") -> None:
        self.calls += other.calls
        self.attempts += other.attempts
        self.cached += other.cached
        self.prompt_tokens += other.prompt_tokens
        self.completion_tokens += other.completion_tokens
        self.total_tokens += other.total_tokens
        if other.cost_usd is not None:
            self.cost_usd = (self.cost_usd or 0.0) + other.cost_usd
        self.seconds += other.seconds

    def snapshot(self) -> "Usage":
        """A copy (to measure a span of calls with :meth:`since`)."""
        return replace(self)

    def since(self, before: "Usage") -> "Usage":
        """What was added after the snapshot ``before`` (cost None when none known)."""
        cost = None
        if self.cost_usd is not None:
            cost = self.cost_usd - (before.cost_usd or 0.0)
        return Usage(
            calls=self.calls - before.calls,
            attempts=self.attempts - before.attempts,
            cached=self.cached - before.cached,
            prompt_tokens=self.prompt_tokens - before.prompt_tokens,
            completion_tokens=self.completion_tokens - before.completion_tokens,
            total_tokens=self.total_tokens - before.total_tokens,
            cost_usd=cost,
            seconds=self.seconds - before.seconds,
        )

    def summary(self) -> str:
        cost = "unknown" if self.cost_usd is None else f"${self.cost_usd:.4f}"
        return (
            f"{self.calls} model calls ({self.attempts} HTTP attempts, {self.cached} cached replies), "
            f"{self.total_tokens} tokens ({self.prompt_tokens} prompt + {self.completion_tokens} completion), "
            f"cost {cost}, {self.seconds:.2f} s"
        )


@dataclass
class Completion:
    """One reply: ``content`` (text, "" when none), ``finish_reason``,
    ``refusal`` text if the model refused, ``cached`` True when served from
    disk, ``key`` the cache key, ``usage`` of this call."""

    content: str
    finish_reason: str | None
    refusal: str | None
    cached: bool
    key: str
    usage: Usage


T = TypeVar("T")


@dataclass
class Answer(Generic[M, T]):
    """Result of :meth:`LLMClient.ask`: the parsed ``reply``, what the caller's
    ``accept`` made of it (``value``), the problems of the rejected attempts
    (``history``) and the ``usage`` of the whole exchange."""

    reply: M
    value: T
    history: list[list[str]]
    usage: Usage


# ----------------------------------------------------------------------- client
def _retry_after_s(exc: BaseException) -> float | None:
    """Seconds the server asked to wait (``retry-after-ms`` or ``Retry-After``
    in seconds or as an HTTP date), from a litellm / OpenAI SDK exception."""
    headers = None
    for attr in ("litellm_response_headers", "headers"):
        h = getattr(exc, attr, None)
        if h:
            headers = h
            break
    if headers is None:
        resp = getattr(exc, "response", None)
        headers = getattr(resp, "headers", None)
    if not headers:
        return None
    try:
        get = headers.get
    except AttributeError:
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
    if when is None:
        return None
    return max(0.0, when.timestamp() - time.time())


def _status_of(exc: BaseException) -> int | None:
    s = getattr(exc, "status_code", None)
    if isinstance(s, int):
        return s
    resp = getattr(exc, "response", None)
    s = getattr(resp, "status_code", None)
    return s if isinstance(s, int) else None


def classify(exc: BaseException, litellm=None) -> tuple[bool, int | None, str]:
    """(retryable, HTTP status or None, short kind) of an exception raised by a call."""
    name = type(exc).__name__
    status = _status_of(exc)
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


class LLMClient:
    """Calls one model through litellm with retries, timeouts, a reply cache and
    accounting (see the module docstring).

    ``sleep`` is the function used to wait between retries (tests may pass a
    recording one). Thread-safe for concurrent calls (the cache writes are
    atomic; ``usage`` is updated under a lock).
    """

    def __init__(self, config: ClientConfig, *, sleep: Callable[[float], None] = time.sleep):
        self.config = config
        self.usage = Usage()
        self._sleep = sleep
        self._lock = threading.Lock()

    # ---------------------------------------------------------- credentials
    def check_credentials(self) -> None:
        """Fail early when the provider needs a key that is not set.

        With ``base_url`` (a local or self-hosted server) no key is needed.
        Otherwise litellm's ``validate_environment`` names the provider's
        variables (``GEMINI_API_KEY``/``GOOGLE_API_KEY``, ``OPENAI_API_KEY``,
        ``ANTHROPIC_API_KEY`` ...).

        Raises:
            LLMUnavailable: litellm missing.
            MissingCredentials: no provider in the model string, or its key is missing.
        """
        litellm = import_litellm()
        cfg = self.config
        try:
            litellm.get_llm_provider(cfg.model, api_base=cfg.base_url)
        except Exception as exc:
            raise MissingCredentials(
                f"model {cfg.model!r}: litellm cannot tell the provider; write it as provider/model "
                f"(e.g. gemini/gemini-2.5-flash, openai/gpt-4o, anthropic/claude-sonnet-4-5, ollama/llava) ({exc})"
            ) from None
        if cfg.base_url or cfg.api_key:
            return
        env = litellm.validate_environment(model=cfg.model)
        if not env.get("keys_in_environment", False):
            missing = [k for k in env.get("missing_keys", []) if k]
            raise MissingCredentials(
                f"model {cfg.model!r} needs an API key: set {' or '.join(missing) or 'the provider key'} in the environment "
                "(or give --base-url for a local server that needs none)"
            )

    # -------------------------------------------------------------- caching
    def cache_key(self, messages: list[dict[str, Any]], schema: dict[str, Any] | None, temperature: float | None) -> str:
        """sha256 (hex) of the model, the messages (text and image data), the
        schema and the sampling parameters. The key and base URL are not part
        of it."""
        blob = json.dumps(
            {
                "format": CACHE_FORMAT,
                "model": self.config.model,
                "messages": messages,
                "schema": schema,
                "temperature": temperature,
                "max_tokens": self.config.max_tokens,
            },
            sort_keys=True,
            separators=(",", ":"),
        ).encode()
        return hashlib.sha256(blob).hexdigest()

    def _cache_path(self, key: str) -> Path | None:
        d = self.config.cache_dir
        return None if d is None else Path(d) / key[:2] / f"{key}.json"

    def cache_get(self, key: str) -> dict[str, Any] | None:
        """The cached reply record for ``key``, or None (missing or unreadable)."""
        p = self._cache_path(key)
        if p is None or not p.is_file():
            return None
        try:
            rec = json.loads(p.read_text())
        except (OSError, ValueError):
            return None
        if not isinstance(rec, dict) or rec.get("format") != CACHE_FORMAT or not isinstance(rec.get("content"), str):
            return None
        return rec

    def cache_put(self, key: str, completion: Completion) -> None:
        """Store a reply (atomically); does nothing without a cache folder.

        Raises:
            OSError: the cache folder cannot be written.
        """
        p = self._cache_path(key)
        if p is None:
            return
        atomic.write_json(
            p,
            {
                "format": CACHE_FORMAT,
                "model": self.config.model,
                "content": completion.content,
                "finish_reason": completion.finish_reason,
                "created": time.time(),
                "tokens": completion.usage.total_tokens,
            },
        )

    # ----------------------------------------------------------------- calls
    def complete(
        self,
        messages: list[dict[str, Any]],
        *,
        schema: dict[str, Any] | None = None,
        schema_name: str = "reply",
        temperature: float | None | str = "config",
    ) -> Completion:
        """One model reply for ``messages`` (OpenAI chat format, images as
        ``image_url`` data URLs), from the cache when present.

        ``schema`` is sent as ``response_format`` ``json_schema`` (strict);
        ``temperature`` "config" uses :attr:`ClientConfig.temperature`.

        Raises:
            LLMUnavailable: litellm missing.
            ModelCallError: a non-retryable error, or every attempt failed.
        """
        temp = self.config.temperature if temperature == "config" else temperature
        key = self.cache_key(messages, schema, temp)
        rec = self.cache_get(key)
        if rec is not None:
            u = Usage(cached=1)
            with self._lock:
                self.usage.add(u)
            return Completion(rec["content"], rec.get("finish_reason"), None, True, key, u)
        litellm = import_litellm()
        cfg = self.config
        kwargs: dict[str, Any] = dict(
            model=cfg.model,
            messages=messages,
            timeout=cfg.timeout_s,
            max_retries=0,
            num_retries=0,
            max_tokens=cfg.max_tokens,
            drop_params=True,
        )
        if cfg.base_url:
            kwargs["api_base"] = cfg.base_url
        if cfg.api_key:
            kwargs["api_key"] = cfg.api_key
        elif cfg.base_url:
            env = litellm.validate_environment(model=cfg.model)
            if not env.get("keys_in_environment", False):
                kwargs["api_key"] = NO_KEY
        if temp is not None:
            kwargs["temperature"] = temp
        if schema is not None:
            kwargs["response_format"] = {"type": "json_schema", "json_schema": {"name": schema_name, "schema": schema, "strict": True}}
        t0 = time.monotonic()
        u = Usage()
        last: str = ""
        status: int | None = None
        try:
            for attempt in range(1, cfg.max_attempts + 1):
                u.attempts += 1
                try:
                    resp = litellm.completion(**kwargs)
                except Exception as exc:  # classified below; non-API bugs are not retried
                    retryable, status, kind = classify(exc, litellm)
                    last = f"{kind}: {_short_error(exc)}"
                    if not retryable:
                        raise ModelCallError(f"model {cfg.model}: {last} (not retried)", u.attempts, status) from None
                    if attempt >= cfg.max_attempts:
                        break
                    wait = min(cfg.backoff_s * (2 ** (attempt - 1)), cfg.max_backoff_s)
                    ra = _retry_after_s(exc)
                    if ra is not None:
                        if ra > cfg.max_retry_after_s:
                            raise ModelCallError(
                                f"model {cfg.model}: {last}; the server asks to retry after {ra:.0f} s, more than the {cfg.max_retry_after_s:.0f} s allowed",
                                u.attempts,
                                status,
                            ) from None
                        wait = max(wait, ra)
                    self._sleep(wait)
                    continue
                comp = self._completion_from(resp, key, u, litellm)
                return comp
            raise ModelCallError(f"model {cfg.model}: {last}; gave up after {u.attempts} attempts", u.attempts, status)
        finally:
            u.seconds = time.monotonic() - t0
            with self._lock:
                self.usage.add(u)

    def _completion_from(self, resp: Any, key: str, u: Usage, litellm) -> Completion:
        u.calls += 1
        try:
            choice = resp.choices[0]
            msg = choice.message
        except (AttributeError, IndexError, TypeError):
            return Completion("", None, None, False, key, u)
        content = getattr(msg, "content", None)
        if content is None:
            content = ""
        if not isinstance(content, str):  # some providers return parts
            content = "".join(p.get("text", "") if isinstance(p, dict) else str(p) for p in content)
        refusal = getattr(msg, "refusal", None)
        psf = getattr(msg, "provider_specific_fields", None) or {}
        if refusal is None and isinstance(psf, dict):
            refusal = psf.get("refusal")
        finish = getattr(choice, "finish_reason", None)
        usage = getattr(resp, "usage", None)
        if usage is not None:
            u.prompt_tokens += int(getattr(usage, "prompt_tokens", 0) or 0)
            u.completion_tokens += int(getattr(usage, "completion_tokens", 0) or 0)
            u.total_tokens += int(getattr(usage, "total_tokens", 0) or 0)
        try:
            cost = float(litellm.completion_cost(completion_response=resp))
            u.cost_usd = cost if math.isfinite(cost) else None
        except Exception:  # litellm raises when the model is not in its cost table
            u.cost_usd = None
        return Completion(content, finish, refusal, False, key, u)

    # ------------------------------------------------------------- asking
    def ask(
        self,
        messages: list[dict[str, Any]],
        reply_model: type[M],
        *,
        schema: dict[str, Any] | None = None,
        schema_name: str = "reply",
        accept: Callable[[M], T] | None = None,
        max_reasks: int = 2,
        temperature: float | None | str = "config",
    ) -> Answer[M, T]:
        """Ask until a reply parses strictly into ``reply_model`` and
        ``accept(reply)`` returns (it raises :class:`ReplyInvalid` to reject);
        re-ask at most ``max_reasks`` times, each time with the problems found.

        Replies that parse into ``reply_model`` are cached (also when
        ``accept`` rejects them, so a rerun replays the same exchange).

        Raises:
            ModelCallError: the network failed (see :meth:`complete`).
            ReplyError: every reply was unusable (message lists the problems).
        """
        msgs = list(messages)
        history: list[list[str]] = []
        total = Usage()
        for attempt in range(max_reasks + 1):
            comp = self.complete(msgs, schema=schema, schema_name=schema_name, temperature=temperature)
            total.add(comp.usage)
            errors: list[str] = []
            reply = None
            content = comp.content
            if comp.refusal:
                errors = [f"the model refused: {str(comp.refusal)[:300]}"]
            elif comp.finish_reason == "content_filter":
                errors = ["the reply was blocked by the provider's content filter"]
            elif len(content) > self.config.max_reply_chars:
                errors = [f"the reply has {len(content)} characters, more than the {self.config.max_reply_chars} allowed; answer with the compact JSON object only"]
            elif not content.strip():
                errors = ["the reply is empty"]
            else:
                try:
                    reply = parse_reply(content, reply_model)
                except ReplyInvalid as exc:
                    errors = list(exc.errors)
                    if comp.finish_reason == "length":
                        errors.insert(0, "the reply was cut off at the token limit (finish_reason=length); answer more compactly")
            if reply is not None:
                if not comp.cached:
                    self.cache_put(comp.key, comp)
                try:
                    value = accept(reply) if accept is not None else reply  # type: ignore[assignment]
                    return Answer(reply, value, history, total)
                except ReplyInvalid as exc:
                    errors = list(exc.errors)
            history.append(errors)
            if attempt < max_reasks:
                msgs = msgs + [
                    {"role": "assistant", "content": _excerpt(content or (comp.refusal or ""), 4000)},
                    {"role": "user", "content": reask_text(errors)},
                ]
        summary = " | ".join(f"reply {i + 1}: " + "; ".join(e[:3]) for i, e in enumerate(history))
        raise ReplyError(f"model {self.config.model}: no usable reply after {len(history)} replies ({summary})", history)


def reask_text(errors: list[str]) -> str:
    """The follow-up message listing a reply's problems."""
    lines = "\n".join(f"- {e}" for e in errors[:30])
    return (
        "Your previous reply could not be used:\n"
        f"{lines}\n"
        "Answer again with exactly one JSON object that follows the schema: every field present, "
        "no other fields, finite numbers within the stated ranges, names exactly as in the description. "
        "No prose, no Markdown."
    )


def _excerpt(text: str, limit: int) -> str:
    if len(text) <= limit:
        return text
    return text[:limit] + f"... [{len(text) - limit} more characters omitted]"


def _short_error(exc: BaseException, limit: int = 300) -> str:
    s = str(exc).replace("\n", " ")
    return s if len(s) <= limit else s[:limit] + "..."


def with_overrides(config: ClientConfig, **kw) -> ClientConfig:
    """A copy of ``config`` with fields replaced."""
    return replace(config, **kw)
