"""Exit statuses of the ``asset2sim`` command line and the expected-failure
exception the commands raise (the top-level handler in :mod:`asset2sim.cli`
prints it as one line and exits with its status), with the helpers every
command uses to turn its failures into that line.

| status | meaning |
|---|---|
| 0 | done (refine: written and interaction-ready) |
| 1 | invalid input: the asset is refused or cannot be read (``evaluate``/``export``: a metric or check fails; ``render``: rendering failed) |
| 2 | invalid request or overlay: usage error (unknown engine, view, code), request too long, estimator failed or its overlay is invalid; ``evaluate``/``export``/``render``: the input cannot be used |
| 3 | written but not interaction-ready: a readiness tier fails (rest, penetration, joint sweep, robust rest, probes; ``tasks/check/verdict.py``, ``docs/design/metrics.md`` 3a); the terminal verdict, ``report.json`` ``failure_mode`` and ``report.html`` name it |
| 4 | output location problem (every command): inside / containing the input, not a folder, holds others' files, a bookkeeping file that is not a regular file, cannot be written (read-only, full) |
| 5 | ``flow``: the run regressed against the previous run of its dataset beyond ``catalog.yaml`` ``results.regression`` (rows and artifacts written) |
| 70 | internal error: a bug; the traceback is written to a log file whose path is printed |
| 130 | interrupted (Ctrl-C) |

The table is repeated in docs/guide/outputs.md (section "Exit statuses").
"""

from __future__ import annotations

import errno
import os
from pathlib import Path
from typing import Iterable

from asset2sim.engines.registry import known_engines
from asset2sim.output_folder import OutputError

OK = 0
INVALID_INPUT = 1
INVALID_REQUEST = 2
NOT_READY = 3
OUTPUT_LOCATION = 4
REGRESSION = 5
INTERNAL_ERROR = 70
INTERRUPTED = 130


class CommandError(Exception):
    """An expected failure of a command: ``status`` (one of the constants
    above), ``code`` (an upper-case identifier such as ``OUTPUT_INSIDE_INPUT``
    or a validation code; several distinct codes joined by ``,``), ``path``
    (the file or folder concerned) and a message."""

    def __init__(self, status: int, code: str, path: Path | str | None, message: str):
        super().__init__(message)
        self.status = int(status)
        self.code = code
        self.path = None if path is None else str(path)
        self.message = message

    def line(self, command: str | None) -> str:
        """``asset2sim COMMAND: CODE: PATH: message`` on one line (a message
        that starts with the path does not repeat it)."""
        msg = " | ".join(part.strip() for part in self.message.splitlines() if part.strip())
        if self.path:
            for prefix in (f"{self.path}: ", f"{os.path.abspath(self.path)}: "):
                if msg.startswith(prefix):
                    msg = msg[len(prefix):]
                    break
        where = f"{self.path}: " if self.path else ""
        prog = f"asset2sim {command}" if command else "asset2sim"
        return f"{prog}: {self.code}: {where}{msg}"


def join_codes(codes: Iterable[str]) -> str:
    """Distinct codes in first-seen order, joined by ``,`` (``""`` when none)."""
    return ",".join(dict.fromkeys(c for c in codes if c))


def parse_engines(text: str | None, option: str = "--engines") -> list[str]:
    """The engine names of a comma-separated option value (order kept,
    duplicates dropped). A known engine that is not installed is kept (the
    command reports it as skipped).

    Raises:
        CommandError: status 2, ``ENGINE_UNKNOWN``, naming the known engines.
    """
    names = list(dict.fromkeys(e.strip() for e in (text or "").split(",") if e.strip()))
    known = known_engines()
    unknown = [n for n in names if n not in known]
    if unknown:
        raise CommandError(INVALID_REQUEST, "ENGINE_UNKNOWN", None,
                           f"{option}: unknown engine(s) {', '.join(unknown)}; known: {', '.join(known)}")
    return names


def _inside(path: str | os.PathLike | None, folder: Path | str) -> bool:
    """True when ``path`` is ``folder`` or lies in it, compared both as
    written (absolute) and with symlinks resolved (``/proc/self`` ...)."""
    if path is None:
        return False
    p = os.fsdecode(path)
    for a, b in ((os.path.abspath(p), os.path.abspath(folder)), (os.path.realpath(p), os.path.realpath(folder))):
        if a == b or a.startswith(b.rstrip(os.sep) + os.sep):
            return True
    return False


def errno_name(exc: OSError) -> str:
    """``EROFS``, ``ENOSPC`` ... of an OSError (``OSERROR`` when unknown)."""
    return errno.errorcode.get(exc.errno or 0, "OSERROR")


def os_failure(exc: OSError, out: Path | str | None, inp: Path | str | None, input_status: int = INVALID_INPUT,
               input_code: str = "INPUT_READ_FAILED") -> CommandError:
    """An OSError of a command: under the output folder ``out`` (read-only,
    full disk, permissions) or a disk-full / read-only error -> status 4
    ``OUTPUT_WRITE_FAILED [ERRNO]``; else the input could not be read ->
    ``input_status`` with ``input_code [ERRNO]``."""
    name = errno_name(exc)
    paths = [exc.filename, exc.filename2]
    full = exc.errno in (errno.ENOSPC, errno.EROFS, getattr(errno, "EDQUOT", -1))
    if out is not None and (full or any(_inside(p, out) for p in paths)):
        return CommandError(OUTPUT_LOCATION, f"OUTPUT_WRITE_FAILED [{name}]", exc.filename or out, exc.strerror or str(exc))
    return CommandError(input_status, f"{input_code} [{name}]", exc.filename or inp, exc.strerror or str(exc))


def output_folder_failure(out: Path | str) -> CommandError | None:
    """``OUTPUT_NOT_A_FOLDER`` (status 4) when ``out`` exists and is not a
    folder (a file, ``/dev/null``); None otherwise."""
    if os.path.lexists(out) and not os.path.isdir(out):
        return CommandError(OUTPUT_LOCATION, "OUTPUT_NOT_A_FOLDER", out, "exists and is not a folder")
    return None


#: What the command line adds to an output-location message (the library names no options).
_HINTS = {"OUTPUT_NOT_EMPTY": "pass --overwrite to do so"}


def output_failure(exc: OutputError, out: Path | str) -> CommandError:
    """Status 4 with the output error's own code (``OUTPUT_WRITE_FAILED [ERRNO]``
    when an OSError caused it) and the path concerned."""
    code = exc.code
    if isinstance(exc.__cause__, OSError):
        code = f"{code} [{errno_name(exc.__cause__)}]"
    msg = str(exc) + (f"; {_HINTS[exc.code]}" if exc.code in _HINTS else "")
    return CommandError(OUTPUT_LOCATION, code, exc.path or out, msg)
