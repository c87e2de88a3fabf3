"""What model calls return and cost: :class:`Completion`, :class:`Answer`, :class:`Usage`."""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Generic, TypeVar

from pydantic import BaseModel

M = TypeVar("M", bound=BaseModel)


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
        """Add ``other``'s counts, tokens, cost and time to these."""
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
        """One line: calls, attempts, cache hits, tokens, cost, seconds."""
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
