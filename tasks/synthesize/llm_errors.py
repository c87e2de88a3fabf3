"""Errors of the model backends (:mod:`asset2sim.tasks.synthesize.llm_client`).

One base class, :class:`LLMError`, so callers can catch every model-backend
failure at once; the subclasses say whether litellm is missing, a key is
missing, the network failed, or the replies were unusable.
"""

from __future__ import annotations


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
