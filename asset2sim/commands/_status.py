"""Exit statuses of the ``asset2sim`` command line and the expected-failure
exception the commands raise (the top-level handler in :mod:`asset2sim.cli`
prints it as one line and exits with its status).

| status | meaning |
|---|---|
| 0 | done (refine: written and interaction-ready) |
| 1 | invalid input: the asset is refused or cannot be read |
| 2 | invalid request or overlay: usage error, request too long, estimator failed or its overlay is invalid |
| 3 | written but not interaction-ready (the verdict is FAILED; the report shows why) |
| 4 | output location problem: inside / containing the input, not a folder, holds others' files, cannot be written (read-only, full) |
| 70 | internal error: a bug; the traceback is written to a log file whose path is printed |
| 130 | interrupted (Ctrl-C) |

The table is repeated in README.md (section "Exit statuses").
"""

from __future__ import annotations

from pathlib import Path

OK = 0
INVALID_INPUT = 1
INVALID_REQUEST = 2
NOT_READY = 3
OUTPUT_LOCATION = 4
INTERNAL_ERROR = 70
INTERRUPTED = 130


class CommandError(Exception):
    """An expected failure of a command: ``status`` (one of the constants
    above), ``code`` (an upper-case identifier such as ``OUTPUT_INSIDE_INPUT``
    or a validation code), ``path`` (the file or folder concerned) and a
    message."""

    def __init__(self, status: int, code: str, path: Path | str | None, message: str):
        super().__init__(message)
        self.status = int(status)
        self.code = code
        self.path = None if path is None else str(path)
        self.message = message

    def line(self, command: str | None) -> str:
        """``asset2sim COMMAND: CODE: PATH: message`` on one line."""
        msg = " | ".join(part.strip() for part in self.message.splitlines() if part.strip())
        where = f"{self.path}: " if self.path else ""
        prog = f"asset2sim {command}" if command else "asset2sim"
        return f"{prog}: {self.code}: {where}{msg}"
