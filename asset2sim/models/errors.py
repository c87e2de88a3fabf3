"""Errors of the model backends; :class:`LLMError` catches them all."""

from __future__ import annotations


class LLMError(RuntimeError):
    """Base class of model-backend errors (the message says what and why)."""


class LLMUnavailable(LLMError):
    """litellm is not installed, or is a forbidden version."""


class MissingCredentials(LLMError):
    """The provider needs an API key that is not in the environment."""


class ModelCallError(LLMError):
    """A call failed (not retryable, or retries exhausted) after ``attempts`` tries; ``status``: the
    last HTTP status (None when none arrived); ``code``: what happened (``MODEL_HTTP_ERROR`` a status the
    server sent, ``MODEL_CONNECTION_FAILED`` a connection that ended before any status,
    ``MODEL_REDIRECT_REFUSED`` a redirect, never followed, ``MODEL_CALL_FAILED`` anything else; the
    subclasses below name the rest). The message is one sentence: no traceback, no second line."""

    code = "MODEL_CALL_FAILED"

    def __init__(self, message: str, attempts: int, status: int | None = None,
                 code: str | None = None):
        super().__init__(message)
        self.attempts = attempts
        self.status = status
        if code is not None:
            self.code = code


class ConnectionRefused(ModelCallError):
    """No connection could be made to the model's server (nothing listens there, the name does not
    resolve, the network refuses). Code ``MODEL_CONNECTION_REFUSED``; retried like other network
    faults."""

    code = "MODEL_CONNECTION_REFUSED"


class ReplyUnreadable(ModelCallError):
    """The server answered, but its reply is not one: a 2xx body that is not a chat completion
    (not JSON, no choices), or a body in an encoding asset2sim does not inflate (nested, or one it
    did not ask for). Code ``MODEL_REPLY_INVALID``."""

    code = "MODEL_REPLY_INVALID"


class DeadlineExceeded(ModelCallError):
    """The reply did not arrive whole within the deadline of one attempt
    (``ClientConfig.timeout_s``: connecting, sending and every read), though the server was
    sending: a server that trickles its reply. Code ``MODEL_DEADLINE_EXCEEDED``; not retried."""

    code = "MODEL_DEADLINE_EXCEEDED"


class ReplyTooLarge(ModelCallError):
    """The HTTP reply grew past ``ClientConfig.max_reply_bytes`` while it arrived (refused then,
    not read whole). Code ``MODEL_REPLY_TOO_LARGE``; not retried."""

    code = "MODEL_REPLY_TOO_LARGE"


class ReplyInvalid(LLMError):
    """One reply is unusable; ``errors`` lists the problems (sent back when re-asking)."""

    def __init__(self, errors: list[str]):
        self.errors = [str(e) for e in errors] or ["unusable reply"]
        more = len(self.errors) - 10
        super().__init__("; ".join(self.errors[:10]) + (f" (+{more} more)" if more > 0 else ""))


class ReplyError(LLMError):
    """Every reply (re-asks included) was unusable; ``history`` holds each attempt's problems."""

    def __init__(self, message: str, history: list[list[str]]):
        super().__init__(message)
        self.history = history
