"""The one place that calls model APIs (through litellm): :class:`LLMClient` with timeouts,
network faults retried here only (litellm's own retries off), an on-disk reply cache whose records
carry their key and digest, strict reply parsing and re-asking, and accounting. litellm is imported
on first use; API keys come from the providers' environment variables and are never stored or
hashed. Why the retry loop and the cache are not litellm's (``num_retries``, ``litellm.Cache``):
``docs/design/model_backends.md``, "Faults, retries, re-asks" and "Cache and accounting".
"""

from __future__ import annotations

import hashlib
import json
import math
import threading
import time
from pathlib import Path
from typing import Any, Callable

from asset2sim import array_cache, atomic
from asset2sim.inert import one_line
from asset2sim.output_paths import exception_chain
from asset2sim.models.config import ClientConfig
from asset2sim.models.errors import (ConnectionRefused, DeadlineExceeded, MissingCredentials,
                                     ModelCallError, ReplyError, ReplyInvalid, ReplyTooLarge,
                                     ReplyUnreadable)
from asset2sim.models.replies import excerpt, parse_reply, reask_text
from asset2sim.models.transport import NO_KEY, call_bounds, classify, import_litellm, retry_after_s
from asset2sim.models.usage import Answer, Completion, M, T, Usage

CACHE_FORMAT = 2

#: Slack (bytes) of a reply record beyond its content: key, digest, model, finish reason.
RECORD_OVERHEAD_BYTES = 64 << 10


def _code(message: str) -> str | None:
    """The ``MODEL_*`` code a failure message starts with, or None."""
    head = message.split(":", 1)[0]
    return head if head.startswith("MODEL_") and head.replace("_", "").isalpha() else None


def _json_sha256(obj: Any) -> str:
    """sha256 (hex) of ``obj`` as canonical JSON (keys sorted, no spaces)."""
    return hashlib.sha256(json.dumps(obj, sort_keys=True, separators=(",", ":")).encode()).hexdigest()


def record_digest(key: str, model: Any, content: Any, finish_reason: Any) -> str:
    """sha256 (hex) of a reply record's key, model, content and finish reason as canonical JSON."""
    return _json_sha256({"key": key, "model": model, "content": content, "finish_reason": finish_reason})


class LLMClient:
    """Calls one model through litellm (see the module docstring); ``sleep`` waits between retries.
    Thread-safe: cache writes are atomic, ``usage`` is updated under a lock."""

    def __init__(self, config: ClientConfig, *, sleep: Callable[[float], None] = time.sleep):
        self.config = config
        self.usage = Usage()
        self._sleep = sleep
        self._lock = threading.Lock()

    def check_credentials(self) -> None:
        """Fail early when the provider needs a key that is not set (none with ``base_url``).

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
                f"model {cfg.model!r}: litellm cannot tell the provider; write it as "
                "provider/model (e.g. gemini/gemini-2.5-flash, openai/gpt-4o, "
                f"anthropic/claude-sonnet-4-5, ollama/llava) ({exc})") from None
        if cfg.base_url or cfg.api_key:
            return
        env = litellm.validate_environment(model=cfg.model)
        if not env.get("keys_in_environment", False):
            missing = " or ".join(k for k in env.get("missing_keys", []) if k) or "the provider key"
            raise MissingCredentials(
                f"model {cfg.model!r} needs an API key: set {missing} in the environment "
                "(or give --base-url for a local server that needs none)")

    # ------------------------------------------------------------------ the reply cache
    def cache_key(self, messages: list[dict[str, Any]], schema: dict[str, Any] | None,
                  temperature: float | None, schema_name: str = "reply") -> str:
        """sha256 (hex) of everything that decides a reply: the model, the server (base URL), the
        messages, the schema and its name, and the sampling parameters (never the API key)."""
        return _json_sha256({"format": CACHE_FORMAT, "model": self.config.model, "base_url": self.config.base_url,
                             "messages": messages, "schema": schema, "schema_name": schema_name,
                             "temperature": temperature, "max_tokens": self.config.max_tokens})

    def _cache_path(self, key: str) -> Path | None:
        """The record's path; None without a cache folder, or when it lies inside an input or output
        folder of the run (:func:`asset2sim.array_cache.kept_out`, as the array cache: a
        ``CacheWarning``, the cache off there)."""
        d = self.config.cache_dir
        if d is None or array_cache.kept_out(d, "asset2sim reply cache"):
            return None
        return Path(d) / key[:2] / f"{key}.json"

    def cache_record_cap(self) -> int:
        """Largest reply record read back, bytes: 12 bytes per character of ``max_reply_chars`` (an
        escaped surrogate pair) plus :data:`RECORD_OVERHEAD_BYTES`."""
        return 12 * self.config.max_reply_chars + RECORD_OVERHEAD_BYTES

    def cache_get(self, key: str) -> dict[str, Any] | None:
        """The cached reply record for ``key``, or None when missing or rejected (too large,
        unreadable, another format or key, digest mismatch); a rejected record is deleted with a
        ``CacheWarning``."""
        p = self._cache_path(key)
        if p is None or not p.is_file():
            return None
        try:  # NaN anywhere: rejected, asked again
            rec = array_cache.finite_json(atomic.read_regular(p, self.cache_record_cap()))
        except FileNotFoundError:  # deleted since: a miss
            return None
        except (OSError, ValueError, RecursionError) as exc:  # too large, not a file, nor JSON ...
            why = f"unreadable ({type(exc).__name__}: {exc})"
        else:
            if not (isinstance(rec, dict) and rec.get("format") == CACHE_FORMAT
                    and isinstance(rec.get("content"), str)):
                why = "not a reply record of this version"
            elif not isinstance(rec.get("finish_reason"), (str, type(None))):
                why = "its finish reason is not text"
            elif rec.get("key") != key:
                why = "it carries no key, or another key's (copied or moved between keys)"
            elif rec.get("sha256") != record_digest(key, rec.get("model"), rec["content"],
                                                    rec.get("finish_reason")):
                why = "its reply does not match its digest (altered)"
            else:
                return rec
        return array_cache.reject(p, f"asset2sim reply cache: record {p} rejected: {why}; asking again")

    def cache_put(self, key: str, completion: Completion) -> None:
        """Store a reply atomically (nothing without a cache folder); OSError when it cannot be
        written."""
        p = self._cache_path(key)
        if p is not None:
            model, content, finish = self.config.model, completion.content, completion.finish_reason
            atomic.write_json(p, {"format": CACHE_FORMAT, "key": key, "sha256": record_digest(key, model, content, finish),
                                  "model": model, "content": content, "finish_reason": finish,
                                  "created": time.time(), "tokens": completion.usage.total_tokens})

    # ------------------------------------------------------------------ calls
    def _call_kwargs(self, litellm, messages: list[dict[str, Any]], schema: dict[str, Any] | None,
                     schema_name: str, temperature: float | None) -> dict[str, Any]:
        """The arguments of one ``litellm.completion`` call (litellm's, the SDK's retries off)."""
        cfg = self.config
        kwargs: dict[str, Any] = dict(model=cfg.model, messages=messages, timeout=cfg.timeout_s,
                                      max_retries=0, num_retries=0, max_tokens=cfg.max_tokens,
                                      drop_params=True)
        if cfg.base_url:
            kwargs["api_base"] = cfg.base_url
        if cfg.api_key:
            kwargs["api_key"] = cfg.api_key
        elif cfg.base_url:
            env = litellm.validate_environment(model=cfg.model)
            if not env.get("keys_in_environment", False):
                kwargs["api_key"] = NO_KEY
        if temperature is not None:
            kwargs["temperature"] = temperature
        if schema is not None:
            kwargs["response_format"] = {"type": "json_schema", "json_schema": {
                "name": schema_name, "schema": schema, "strict": True}}
        return kwargs

    def complete(self, messages: list[dict[str, Any]], *, schema: dict[str, Any] | None = None,
                 schema_name: str = "reply",
                 temperature: float | None | str = "config") -> Completion:
        """One model reply for ``messages`` (OpenAI chat format), from the cache when present.
        ``schema`` goes as a strict ``json_schema`` response format; ``temperature`` "config" is
        the config's.

        Each attempt is bounded (``asset2sim/models/transport.py``): ``timeout_s`` for connecting,
        sending and the whole reply, ``max_reply_bytes`` for the reply. Retried: timeouts, dropped
        connections, retryable HTTP statuses, after ``backoff_s`` doubling to ``max_backoff_s`` and
        at least the server's ``Retry-After``.

        Raises:
            LLMUnavailable: litellm missing.
            DeadlineExceeded: the server was still sending at the deadline (not retried).
            ReplyTooLarge: the reply grew past ``max_reply_bytes`` (not retried).
            ModelCallError: a non-retryable error, or every attempt failed.
        """
        temp = self.config.temperature if temperature == "config" else temperature
        key = self.cache_key(messages, schema, temp, schema_name)
        rec = self.cache_get(key)
        if rec is not None:
            u = Usage(cached=1)
            with self._lock:
                self.usage.add(u)
            return Completion(rec["content"], rec.get("finish_reason"), None, True, key, u)
        litellm = import_litellm()
        cfg = self.config
        kwargs = self._call_kwargs(litellm, messages, schema, schema_name, temp)
        t0 = time.monotonic()
        u = Usage()
        last, cls, status = "", ModelCallError, None
        try:
            for attempt in range(1, cfg.max_attempts + 1):
                u.attempts += 1
                try:
                    with call_bounds(cfg.timeout_s, cfg.max_reply_bytes) as bounds:
                        resp = litellm.completion(**kwargs)
                except Exception as exc:  # classified by what happened; bugs are not retried
                    if bounds.tripped == "size":
                        raise ReplyTooLarge(
                            f"model {cfg.model}: MODEL_REPLY_TOO_LARGE: the reply grew past "
                            f"{cfg.max_reply_bytes} bytes (decoded) and was refused while it "
                            "arrived (ASSET2SIM_LLM_MAX_REPLY_BYTES raises the cap)", u.attempts,
                            bounds.status) from None
                    if bounds.tripped == "deadline" and bounds.received:
                        raise DeadlineExceeded(
                            f"model {cfg.model}: MODEL_DEADLINE_EXCEEDED: the reply was not "
                            f"complete {cfg.timeout_s:g} s after the attempt began "
                            f"({bounds.received} bytes arrived); a server this slow is not asked "
                            "again", u.attempts, None) from None
                    if bounds.tripped == "invalid" and bounds.failure is not None:
                        raise ReplyUnreadable(f"model {cfg.model}: MODEL_REPLY_INVALID: "
                                              f"{bounds.failure[1]} (not retried)", u.attempts,
                                              bounds.status) from None
                    retryable, status, kind = classify(exc, litellm)
                    cls, detail = ModelCallError, one_line(exc, 200)
                    failure, said = bounds.failure or (None, "")
                    if bounds.tripped == "deadline":
                        retryable, detail = True, f"{cfg.timeout_s:g} s"
                        kind = "MODEL_DEADLINE_EXCEEDED: timeout, no reply within the deadline"
                    elif failure == "MODEL_REDIRECT_REFUSED":
                        retryable, detail, kind = False, "", f"{failure}: {said}"
                    elif failure == "MODEL_CONNECTION_REFUSED":
                        cls, retryable, detail, kind = ConnectionRefused, True, "", f"{failure}: {said}"
                    elif bounds.requests and bounds.status is None:  # no HTTP status arrived: what the network said
                        retryable, status, detail = True, None, one_line(exception_chain(exc)[-1], 200)
                        kind = ("MODEL_CONNECTION_FAILED: the connection to the server ended before an HTTP "
                                "status arrived")
                    elif bounds.status is not None and 200 <= bounds.status < 300:
                        cls, retryable, status = ReplyUnreadable, True, bounds.status
                        kind = (f"MODEL_REPLY_INVALID: the server answered HTTP {bounds.status} "
                                "with a body that is not a chat completion")
                        detail = "not JSON, or without choices"
                    elif status is not None and bounds.status is not None:
                        kind = f"MODEL_HTTP_ERROR: HTTP {bounds.status}"
                    last = f"{kind} ({detail})" if detail else kind
                    if not retryable:
                        raise cls(f"model {cfg.model}: {last} (not retried)", u.attempts, status,
                                  _code(last)) from None
                    if attempt >= cfg.max_attempts:
                        break
                    wait = min(cfg.backoff_s * (2 ** (attempt - 1)), cfg.max_backoff_s)
                    ra = retry_after_s(exc)
                    if ra is not None and ra > cfg.max_retry_after_s:
                        raise ModelCallError(
                            f"model {cfg.model}: {last}; the server asks to retry after "
                            f"{ra:.0f} s, more than the {cfg.max_retry_after_s:.0f} s allowed",
                            u.attempts, status) from None
                    self._sleep(wait if ra is None else max(wait, ra))
                    continue
                return self._completion_from(resp, key, u, litellm)
            raise cls(f"model {cfg.model}: {last}; gave up after {u.attempts} attempts", u.attempts,
                      status, _code(last))
        finally:
            u.seconds = time.monotonic() - t0
            with self._lock:
                self.usage.add(u)

    def _completion_from(self, resp: Any, key: str, u: Usage, litellm) -> Completion:
        """The reply of a litellm response, its tokens and cost (litellm's cost table) added to
        ``u``."""
        u.calls += 1
        try:
            choice = resp.choices[0]
            msg = choice.message
        except (AttributeError, IndexError, TypeError):
            return Completion("", None, None, False, key, u)
        content = getattr(msg, "content", None) or ""
        if not isinstance(content, str):  # some providers return parts
            content = "".join(p.get("text", "") if isinstance(p, dict) else str(p) for p in content)
        refusal = getattr(msg, "refusal", None)
        psf = getattr(msg, "provider_specific_fields", None) or {}
        if refusal is None and isinstance(psf, dict):
            refusal = psf.get("refusal")
        usage = getattr(resp, "usage", None)
        for k in ("prompt_tokens", "completion_tokens", "total_tokens"):
            setattr(u, k, getattr(u, k) + int(getattr(usage, k, 0) or 0))
        try:
            cost = float(litellm.completion_cost(completion_response=resp))
            u.cost_usd = cost if math.isfinite(cost) else None
        except Exception:  # litellm raises when the model is not in its cost table
            u.cost_usd = None
        return Completion(content, getattr(choice, "finish_reason", None), refusal, False, key, u)

    def _problems(self, comp: Completion, reply_model: type[M]) -> tuple[M | None, list[str]]:
        """The reply of ``comp`` parsed into ``reply_model``, or None with what is wrong with it."""
        content, limit = comp.content, self.config.max_reply_chars
        if comp.refusal:
            return None, [f"the model refused: {str(comp.refusal)[:300]}"]
        if comp.finish_reason == "content_filter":
            return None, ["the reply was blocked by the provider's content filter"]
        if len(content) > limit:
            return None, [f"the reply has {len(content)} characters, more than the {limit} "
                          "allowed; answer with the compact JSON object only"]
        if not content.strip():
            return None, ["the reply is empty"]
        try:
            return parse_reply(content, reply_model), []
        except ReplyInvalid as exc:
            if comp.finish_reason == "length":
                return None, ["the reply was cut off at the token limit (finish_reason=length); "
                              "answer more compactly", *exc.errors]
            return None, list(exc.errors)

    def ask(self, messages: list[dict[str, Any]], reply_model: type[M], *,
            schema: dict[str, Any] | None = None, schema_name: str = "reply",
            accept: Callable[[M], T] | None = None, max_reasks: int = 2,
            temperature: float | None | str = "config") -> Answer[M, T]:
        """Ask until a reply parses strictly into ``reply_model`` and ``accept(reply)`` returns (it
        raises :class:`ReplyInvalid` to reject), re-asking at most ``max_reasks`` times with the
        problems. Only a reply that parsed and was accepted is cached (keyed by everything that
        decides it, :meth:`cache_key`): a rejected one is asked again on a rerun.

        Raises:
            ModelCallError: the network failed (see :meth:`complete`).
            ReplyError: every reply was unusable (message lists the problems).
        """
        msgs = list(messages)
        history: list[list[str]] = []
        total = Usage()
        for attempt in range(max_reasks + 1):
            comp = self.complete(msgs, schema=schema, schema_name=schema_name,
                                 temperature=temperature)
            total.add(comp.usage)
            reply, errors = self._problems(comp, reply_model)
            if reply is not None:
                try:
                    value = reply if accept is None else accept(reply)
                except ReplyInvalid as exc:
                    errors = list(exc.errors)
                else:
                    if not comp.cached:
                        self.cache_put(comp.key, comp)
                    return Answer(reply, value, history, total)  # type: ignore[arg-type]
            history.append(errors)
            if attempt < max_reasks:
                said = excerpt(comp.content or (comp.refusal or ""), 4000)
                msgs = msgs + [{"role": "assistant", "content": said},
                               {"role": "user", "content": reask_text(errors)}]
        summary = " | ".join(f"reply {i + 1}: " + "; ".join(e[:3]) for i, e in enumerate(history))
        raise ReplyError(f"model {self.config.model}: no usable reply after {len(history)} replies "
                         f"({summary})", history)


def model_string(estimator: str, model: str | None) -> str:
    """litellm model string for an estimator name (``openai`` prefixes ``openai/``); ValueError
    without a model."""
    if not model:
        raise ValueError(f"--estimator {estimator} needs --model (a litellm model string, e.g. "
                         "gemini/gemini-2.5-flash)")
    if estimator == "openai" and not model.startswith("openai/"):
        return "openai/" + model
    return model


def make_client(estimator: str = "llm", model: str | None = None, base_url: str | None = None, *,
                check: bool = True, **overrides) -> LLMClient:
    """A client for ``estimator`` (``llm`` or ``openai``), knobs from the environment and
    ``overrides``.

    Raises:
        ValueError: no model.
        LLMUnavailable: litellm missing.
        MissingCredentials: ``check`` and the provider's key is not set.
    """
    client = LLMClient(ClientConfig.from_env(model_string(estimator, model), base_url, **overrides))
    if check:
        client.check_credentials()
    return client
