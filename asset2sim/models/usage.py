"""What model calls return and cost: :class:`Completion`, :class:`Answer`, :class:`Usage`."""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Generic, TypeVar

from pydantic import BaseModel

M = TypeVar("M", bound=BaseModel)
T = TypeVar("T")

_COUNTS = ("calls", "attempts", "cached", "prompt_tokens", "completion_tokens", "total_tokens")


@dataclass
class Usage:
    """What calls cost: ``calls`` replies received over the network (re-asks included, cache hits
    not), ``attempts`` HTTP tries, ``cached`` cache hits, tokens as the API reports them,
    ``cost_usd`` as far as litellm's cost table knows (None: unknown), ``seconds`` of wall time,
    retries included."""

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
        for k in _COUNTS:
            setattr(self, k, getattr(self, k) + getattr(other, k))
        if other.cost_usd is not None:
            self.cost_usd = (self.cost_usd or 0.0) + other.cost_usd
        self.seconds += other.seconds

    def snapshot(self) -> "Usage":
        """A copy (to measure a span of calls with :meth:`since`)."""
        return replace(self)

    def since(self, before: "Usage") -> "Usage":
        """What was added after the snapshot ``before`` (cost None when none known)."""
        cost = None if self.cost_usd is None else self.cost_usd - (before.cost_usd or 0.0)
        counts = {k: getattr(self, k) - getattr(before, k) for k in _COUNTS}
        return Usage(**counts, cost_usd=cost, seconds=self.seconds - before.seconds)

    def summary(self) -> str:
        """One line: calls, attempts, cache hits, tokens, cost, seconds."""
        cost = "unknown" if self.cost_usd is None else f"${self.cost_usd:.4f}"
        return (
            f"{self.calls} model calls ({self.attempts} HTTP attempts, {self.cached} cached "
            f"replies), {self.total_tokens} tokens ({self.prompt_tokens} prompt + "
            f"{self.completion_tokens} completion), cost {cost}, {self.seconds:.2f} s"
        )


@dataclass
class Completion:
    """One reply: text ("" when none), finish reason, refusal, whether cached, cache key, usage."""

    content: str
    finish_reason: str | None
    refusal: str | None
    cached: bool
    key: str
    usage: Usage


@dataclass
class Answer(Generic[M, T]):
    """Result of ``LLMClient.ask``: the ``reply``, ``accept``'s ``value``, the rejected attempts'
    problems, usage."""

    reply: M
    value: T
    history: list[list[str]]
    usage: Usage
