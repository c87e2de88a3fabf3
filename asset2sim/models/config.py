"""Settings of a model client (:class:`ClientConfig`), from code or ``ASSET2SIM_LLM_*``
variables."""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field, fields
from pathlib import Path


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


#: The fields ``from_env`` reads from ``ASSET2SIM_LLM_<FIELD>`` (a number, its default the field's).
_ENV_KNOBS = ("timeout_s", "max_attempts", "backoff_s", "max_backoff_s", "max_retry_after_s", "max_reply_chars",
              "max_reply_bytes", "max_tokens")


def default_cache_dir() -> Path:
    """``$ASSET2SIM_LLM_CACHE_DIR``, else ``$XDG_CACHE_HOME/asset2sim/llm``, else
    ``~/.cache/asset2sim/llm``."""
    env = os.environ.get("ASSET2SIM_LLM_CACHE_DIR")
    if env:
        return Path(env).expanduser()
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "asset2sim" / "llm"


@dataclass(frozen=True)
class ClientConfig:
    """Settings of one ``LLMClient``: ``model`` (litellm ``provider/name``), ``base_url`` (a local
    server), ``api_key`` (else the provider's variable; never hashed), ``timeout_s`` the deadline of
    one HTTP attempt (connecting, sending and every read of the whole reply), ``max_attempts`` HTTP
    tries per call, ``backoff_s`` doubling up to ``max_backoff_s``, the longest ``Retry-After``
    honoured (``max_retry_after_s``), ``max_reply_chars`` (the message), ``max_reply_bytes`` (the
    whole HTTP reply, refused while it arrives), ``max_tokens``, ``temperature`` (None: the
    provider's), ``cache_dir`` (None: no cache) and the ``render_size`` of the views (pixels).
    Times in s. A copy with fields replaced: ``dataclasses.replace``.
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
    max_reply_bytes: int = 16 << 20
    max_tokens: int = 16384
    temperature: float | None = 0.0
    cache_dir: Path | None = None
    render_size: tuple[int, int] = (384, 384)

    def __post_init__(self):
        if not self.model or not isinstance(self.model, str):
            raise ValueError("a model string is required (e.g. gemini/gemini-2.5-flash)")
        if self.max_attempts < 1:
            raise ValueError(f"max_attempts must be >= 1, got {self.max_attempts}")
        if not (self.timeout_s > 0) or not math.isfinite(self.timeout_s):
            raise ValueError(f"timeout_s must be a finite number > 0, got {self.timeout_s}")
        if self.max_reply_bytes < 1024:
            raise ValueError(f"max_reply_bytes must be >= 1024, got {self.max_reply_bytes}")

    @classmethod
    def from_env(cls, model: str, base_url: str | None = None, **overrides) -> "ClientConfig":
        """Config for ``model`` with knobs from ``ASSET2SIM_LLM_*`` variables (:data:`_ENV_KNOBS`: the field's
        name in upper case, e.g. ``ASSET2SIM_LLM_TIMEOUT_S``, its default the field's; ``ASSET2SIM_LLM_RENDER_SIZE``;
        ``ASSET2SIM_LLM_CACHE_DIR=off`` disables the cache); keyword ``overrides`` win.

        Raises:
            ValueError: a malformed environment value.
        """
        cache_env = os.environ.get("ASSET2SIM_LLM_CACHE_DIR", "")
        size = max(int(_env_float("ASSET2SIM_LLM_RENDER_SIZE", 384)), 16)
        knobs = {f.name: type(f.default)(_env_float(f"ASSET2SIM_LLM_{f.name.upper()}", f.default))
                 for f in fields(cls) if f.name in _ENV_KNOBS}
        cache_dir = None if cache_env.lower() in ("off", "none", "0") else default_cache_dir()
        return cls(**{"model": model, "base_url": base_url, **knobs, "cache_dir": cache_dir, "render_size": (size, size),
                      **overrides})
