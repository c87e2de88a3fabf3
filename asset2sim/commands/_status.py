"""Exit statuses of the ``asset2sim`` command line (their meaning:
docs/guide/outputs.md, "Exit statuses"), the expected-failure exception the
commands raise (:mod:`asset2sim.cli` prints it as one line and exits with its
status) and the helpers that turn failures into it.
"""

from __future__ import annotations

import contextlib
import errno
import os
from pathlib import Path
from typing import Iterable

from asset2sim.engines.registry import known_engines
from asset2sim.input_files import allow_outside
from asset2sim.output_folder import OutputError

INVALID_INPUT = 1
INVALID_REQUEST = 2
NOT_READY = 3
OUTPUT_LOCATION = 4
REGRESSION = 5
INTERNAL_ERROR = 70
INTERRUPTED = 130

#: Every exit status with its meaning, as ``asset2sim --help`` lists them (docs/guide/outputs.md has the codes).
EXIT_STATUSES = {
    0: "done",
    INVALID_INPUT: "invalid input",
    INVALID_REQUEST: "invalid request, overlay or usage",
    NOT_READY: "written but not interaction-ready or not as asked",
    OUTPUT_LOCATION: "output location problem",
    REGRESSION: "a flow run regressed against the previous run",
    INTERNAL_ERROR: "internal error",
    INTERRUPTED: "interrupted",
}


class CommandError(Exception):
    """An expected failure of a command: ``status``, ``code`` (upper case, such
    as ``OUTPUT_INSIDE_INPUT``; several joined by ``,``), ``path`` and a message;
    ``problems``, when given, the ``(code, path, message)`` of each problem, printed one line each."""

    def __init__(self, status: int, code: str, path: Path | str | None, message: str,
                 problems: Iterable[tuple[str, Path | str | None, str]] = ()):
        super().__init__(message)
        self.status = int(status)
        self.code = code
        self.path = None if path is None else str(path)
        self.message = message
        self.problems = [CommandError(status, c, p, m) for c, p, m in problems]

    def lines(self, command: str | None) -> list[str]:
        """One :meth:`line` per problem (the error's own line when it lists none)."""
        return [p.line(command) for p in self.problems] or [self.line(command)]

    def line(self, command: str | None) -> str:
        """``asset2sim COMMAND: CODE: PATH: message`` on one line (a message
        that starts or ends with the path does not repeat it)."""
        msg = " | ".join(part.strip() for part in self.message.splitlines() if part.strip())
        if self.path:
            for prefix in (f"{self.path}: ", f"{os.path.abspath(self.path)}: "):
                if msg.startswith(prefix):
                    msg = msg[len(prefix):]
                    break
            for suffix in (f": {self.path}", f": {os.path.abspath(self.path)}"):
                msg = msg.removesuffix(suffix)
        where = f"{self.path}: " if self.path else ""
        prog = f"asset2sim {command}" if command else "asset2sim"
        return f"{prog}: {self.code}: {where}{msg}"


def join_codes(codes: Iterable[str]) -> str:
    """Distinct codes in first-seen order, joined by ``,`` (``""`` when none)."""
    return ",".join(dict.fromkeys(c for c in codes if c))


def parse_engines(text: str | None, option: str = "--engines") -> list[str]:
    """The engine names of a comma-separated option value (order kept,
    duplicates dropped, uninstalled ones kept; CommandError status 2
    ``ENGINE_UNKNOWN``: an unknown name)."""
    names = list(dict.fromkeys(e.strip() for e in (text or "").split(",") if e.strip()))
    known = known_engines()
    unknown = [n for n in names if n not in known]
    if unknown:
        raise CommandError(INVALID_REQUEST, "ENGINE_UNKNOWN", None,
                           f"{option}: unknown engine(s) {', '.join(unknown)}; known: {', '.join(known)}")
    return names


def _inside(path: str | os.PathLike | None, folder: Path | str) -> bool:
    """True when ``path`` is ``folder`` or lies in it, as written or with symlinks resolved."""
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
    """An OSError of a command: under ``out`` or a full / read-only disk ->
    status 4 ``OUTPUT_WRITE_FAILED [ERRNO]``; else ``input_status`` ``input_code [ERRNO]``."""
    name = errno_name(exc)
    paths = [exc.filename, exc.filename2]
    full = exc.errno in (errno.ENOSPC, errno.EROFS, getattr(errno, "EDQUOT", -1))
    if out is not None and (full or any(_inside(p, out) for p in paths)):
        return CommandError(OUTPUT_LOCATION, f"OUTPUT_WRITE_FAILED [{name}]", exc.filename or out, exc.strerror or str(exc))
    return CommandError(input_status, f"{input_code} [{name}]", exc.filename or inp, exc.strerror or str(exc))


def output_folder_failure(out: Path | str) -> CommandError | None:
    """``OUTPUT_NOT_A_FOLDER`` (status 4) when ``out`` exists and is not a folder, else None."""
    if os.path.lexists(out) and not os.path.isdir(out):
        return CommandError(OUTPUT_LOCATION, "OUTPUT_NOT_A_FOLDER", out, "exists and is not a folder")
    return None


#: What the command line adds to an output-location message (the library names no options).
_HINTS = {"OUTPUT_NOT_EMPTY": "pass --overwrite to do so"}


def output_failure(exc: OutputError, out: Path | str) -> CommandError:
    """Status 4 with the output error's code (``[ERRNO]`` added when an OSError caused it) and path."""
    code = exc.code
    if isinstance(exc.__cause__, OSError):
        code = f"{code} [{errno_name(exc.__cause__)}]"
    msg = str(exc) + (f"; {_HINTS[exc.code]}" if exc.code in _HINTS else "")
    return CommandError(OUTPUT_LOCATION, code, exc.path or out, msg)


def catalog_failure(exc: Exception, catalog: Path | str) -> CommandError:
    """Status 2 for a ``catalog.yaml`` that cannot be used: ``CATALOG_NOT_FOUND`` (run where it is, or pass
    ``--catalog``) or ``CATALOG_INVALID`` with the reason."""
    if isinstance(exc.__cause__, FileNotFoundError):
        return CommandError(INVALID_REQUEST, "CATALOG_NOT_FOUND", catalog, "no such file; run the command in the "
                            "project's folder (where catalog.yaml is) or pass --catalog PATH")
    return CommandError(INVALID_REQUEST, "CATALOG_INVALID", catalog, str(exc).removeprefix(f"{Path(catalog).expanduser().resolve()}: "))


def add_allow_outside(parser) -> None:
    """``--allow-outside-paths DIR`` (repeatable) on a command that reads MJCF or USD inputs."""
    parser.add_argument("--allow-outside-paths", action="append", default=[], type=Path, metavar="DIR",
                        help="let MJCF and USD inputs name files in DIR too, outside their own folder (repeatable; every other "
                             "rule holds: regular files under the size cap)")


@contextlib.contextmanager
def outside_paths(args):
    """The block run with ``--allow-outside-paths`` in force (CommandError status 2 ``INPUT_NOT_FOUND``: not a folder)."""
    folders = getattr(args, "allow_outside_paths", None) or []
    bad = [f for f in folders if not os.path.isdir(f)]
    if bad:
        raise CommandError(INVALID_REQUEST, "INPUT_NOT_FOUND", bad[0], f"--allow-outside-paths {bad[0]}: not a folder")
    with allow_outside(*folders):
        yield
