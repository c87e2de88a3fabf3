"""Exit statuses of the ``asset2sim`` command line (their meaning:
docs/guide/outputs.md, "Exit statuses"), the expected-failure exception the
commands raise, and the one table (:data:`ERRORS`) that turns any other exception
a command lets out into one line and its status (:func:`failure`, called by
:mod:`asset2sim.cli`).
"""

from __future__ import annotations

import contextlib
import errno
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Iterable

from asset2sim.engines.registry import known_engines
from asset2sim.extras import EXTRA_OF_MODULE, install_hint, missing_module
from asset2sim.input_files import allow_outside, inside
from asset2sim.output_folder import OutputError, product_folder_as_named
from asset2sim.output_paths import check_location, exception_chain

INVALID_INPUT = 1
INVALID_REQUEST = 2
NOT_READY = 3
OUTPUT_LOCATION = 4
REGRESSION = 5
INTERNAL_ERROR = 70
INTERRUPTED = 130
#: 128 + SIGTERM (15): stopped by ``kill`` (or a scheduler) and cleaned up as for Ctrl-C.
TERMINATED = 143

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
    TERMINATED: "terminated (SIGTERM)",
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

    @classmethod
    def invalid(cls, code: str, message: str) -> "CommandError":
        """Status 2 (:data:`INVALID_REQUEST`) without a path: an option, a setting or a request the command cannot
        use."""
        return cls(INVALID_REQUEST, code, None, message)

    def lines(self, command: str | None) -> list[str]:
        """One :meth:`line` per problem (the error's own line when it lists none)."""
        return [p.line(command) for p in self.problems] or [self.line(command)]

    def line(self, command: str | None) -> str:
        """``asset2sim COMMAND: CODE: PATH: message`` on one line (a message
        that starts or ends with the path does not repeat it)."""
        msg = " | ".join(part.strip() for part in self.message.splitlines() if part.strip())
        for name in dict.fromkeys((self.path, os.path.abspath(self.path))) if self.path else ():
            msg = msg.removeprefix(f"{name}: ").removesuffix(f": {name}")
        where = f"{self.path}: " if self.path and not msg.startswith(self.path) else ""
        prog = f"asset2sim {command}" if command else "asset2sim"
        return f"{prog}: {self.code}: {where}{msg}"


# ------------------------------------------------------------------ the one table of failures
@dataclass(frozen=True)
class Reading:
    """How an exception reads to the user of a command: ``status``; ``code`` (the exception's own upper-case
    ``code`` wins when it has one); ``path``: ``"exc"`` the exception's own (``path``, ``filename``), else the
    command's input; ``"input"`` the command's input; None no path; ``prefix`` before the exception's message."""

    status: int
    code: str
    path: str | None = "exc"
    prefix: str = ""


#: Exceptions that say the disk cannot take more: whatever file they name, the output is what cannot be written.
UNWRITABLE_ERRNOS = frozenset({errno.ENOSPC, errno.EDQUOT, errno.EROFS})
#: What the command line adds to an output-location message (the library names no options).
_HINTS = {"OUTPUT_NOT_EMPTY": "pass --overwrite to do so"}


def errno_name(exc: OSError) -> str:
    """``EROFS``, ``ENOSPC`` ... of an OSError (``OSERROR`` when unknown)."""
    return errno.errorcode.get(exc.errno or 0, "OSERROR")


def _inside(path: str | os.PathLike | None, folder: Path | str) -> bool:
    """True when ``path`` is ``folder`` or lies in it, as written or with symlinks resolved."""
    return path is not None and any(inside(how(os.fsdecode(path)), how(folder)) for how in (os.path.abspath, os.path.realpath))


def output_failure(exc: OutputError, outs: list[Path], *_) -> CommandError:
    """Status 4 with the output guard's code (``[ERRNO]`` added when an OSError caused it), path and sentence."""
    code = exc.code
    if isinstance(exc.__cause__, OSError):
        code = f"{code} [{errno_name(exc.__cause__)}]"
    msg = str(exc) + (f"; {_HINTS[exc.code]}" if exc.code in _HINTS else "")
    return CommandError(OUTPUT_LOCATION, code, exc.path or next(iter(outs), None), msg)


def os_failure(exc: OSError, outs: list[Path], inp, reading: Reading | None) -> CommandError:
    """An OSError: under an output folder of the command, or a full / read-only disk anywhere in its chain ->
    status 4 ``OUTPUT_WRITE_FAILED [ERRNO]``; else the command's reading of an unreadable input (default status 1
    ``INPUT_READ_FAILED [ERRNO]``)."""
    full = next((c for c in exception_chain(exc) if isinstance(c, OSError) and c.errno in UNWRITABLE_ERRNOS), None)
    if full is not None or any(_inside(p, out) for p in (exc.filename, exc.filename2) for out in outs):
        exc, inp, reading = full or exc, next(iter(outs), None), Reading(OUTPUT_LOCATION, "OUTPUT_WRITE_FAILED")
    reading = reading or Reading(INVALID_INPUT, "INPUT_READ_FAILED")
    return CommandError(reading.status, f"{reading.code} [{errno_name(exc)}]", exc.filename or inp,
                        reading.prefix + (exc.strerror or str(exc)))


def catalog_failure(exc: Exception, _outs, catalog, *_) -> CommandError:
    """Status 2 for a ``catalog.yaml`` that cannot be used: ``CATALOG_NOT_FOUND`` (run where it is, or pass
    ``--catalog``) or ``CATALOG_INVALID`` with the reason."""
    if isinstance(exc.__cause__, FileNotFoundError):
        return CommandError(INVALID_REQUEST, "CATALOG_NOT_FOUND", catalog, "no such file; run the command in the "
                            "project's folder (where catalog.yaml is) or pass --catalog PATH")
    where = Path(catalog).expanduser().resolve() if catalog else ""
    return CommandError(INVALID_REQUEST, "CATALOG_INVALID", catalog, str(exc).removeprefix(f"{where}: "))


def extra_failure(exc: ImportError, *_) -> CommandError | None:
    """Status 2 ``EXTRA_MISSING`` naming the extra of a missing optional dependency; None for any other import
    error (a bug)."""
    return CommandError.invalid("EXTRA_MISSING", install_hint(exc)) if missing_module(exc) in EXTRA_OF_MODULE else None


Converter = Callable[[BaseException, list, object, "Reading | None"], "CommandError | None"]

#: Every command's reading of the exceptions it lets out, by class name (looked up along the exception's classes,
#: ``"COMMAND Class"`` before ``"Class"``): a :class:`Reading`, or a function ``(exc, output folders, input,
#: the command's reading of OSError) -> CommandError | None``. Anything not here is a bug: status 70, the traceback
#: in a log (:func:`asset2sim.cli.internal_error`). The statuses: docs/guide/outputs.md, "Exit statuses".
ERRORS: dict[str, Reading | Converter] = {
    # every command
    "OutputError": output_failure,  # the output guard's refusals (symlinks, hard links, names, locations): 4
    "OSError": os_failure,
    "ImportError": extra_failure,
    "CatalogError": catalog_failure,
    "AssetError": Reading(INVALID_INPUT, "INPUT_UNREADABLE", "input"),
    **dict.fromkeys(("MissingCredentials", "LLMUnavailable"), Reading(INVALID_REQUEST, "MODEL_UNAVAILABLE", None)),
    **dict.fromkeys(("PairSetError", "JudgeInputError"), Reading(INVALID_INPUT, "PAIRS_INVALID")),
    "NotRated": Reading(NOT_READY, "NOT_RATED", "input"),
    "RenderError": Reading(INVALID_INPUT, "RENDER_FAILED", "input"),
    "EvaluationError": Reading(INVALID_REQUEST, "EVALUATION_INPUT_INVALID", "input"),
    # one command's own
    "audit FileNotFoundError": Reading(INVALID_INPUT, "AUDIT_INPUT_MISSING", None),
    **dict.fromkeys(("benchmark ValueError", "benchmark KeyError", "benchmark FileNotFoundError"),
                    Reading(INVALID_REQUEST, "BENCHMARK_INPUT_INVALID", "exc", "benchmark cannot run: ")),
    "evaluate ValueError": Reading(INVALID_REQUEST, "EVALUATION_INPUT_INVALID", "input"),
    "evaluate OSError": Reading(INVALID_REQUEST, "EVALUATION_INPUT_UNREADABLE"),
    **dict.fromkeys(("export ValueError", "export FileNotFoundError"),
                    Reading(INVALID_REQUEST, "EXPORT_INPUT_INVALID", "exc", "cannot export: ")),
    "export OSError": Reading(INVALID_REQUEST, "EXPORT_INPUT_UNREADABLE"),
    **dict.fromkeys(("export MjcfError", "export ExportError", "export UsdExportError"),
                    Reading(INVALID_INPUT, "EXPORT_CHECK_FAILED", "input")),
    "failures ValueError": catalog_failure,
    "init FileExistsError": Reading(OUTPUT_LOCATION, "OUTPUT_EXISTS", None),
    "init NotADirectoryError": Reading(INVALID_INPUT, "OBJECTS_NOT_A_FOLDER", None),
    "init ValueError": Reading(INVALID_INPUT, "OBJECTS_NONE_FOUND", None),
    "judge ValueError": Reading(INVALID_REQUEST, "JUDGES_INVALID", None),
    "pairs FileNotFoundError": Reading(INVALID_INPUT, "PAIRS_INPUT_INVALID", None),
    "rate FileNotFoundError": Reading(INVALID_INPUT, "PAIRS_MISSING"),
    **dict.fromkeys(("render ValueError", "render OSError"), Reading(INVALID_REQUEST, "RENDER_INPUT_INVALID")),
    "render KeyError": Reading(INVALID_REQUEST, "RENDER_INPUT_INVALID", "input"),
}

#: The arguments naming what a command reads, first found first (its output folders: ``--out``, ``--asset-out``,
#: ``--dataset``, and the folder ``init``, ``rate`` and ``judge`` write into).
_INPUT_ARGS = ("asset", "manifest", "objects", "folder", "catalog", "out")
_OUTPUT_ARGS = {"init": ("folder",), "rate": ("folder",), "judge": ("folder",), "export": ("out/format",)}


def _arg_paths(args, names: Iterable[str]) -> list[Path]:
    out = []
    for name in names:
        head, _, sub = name.partition("/")
        value = getattr(args, head, None)
        if value is not None and not isinstance(value, (list, tuple)):
            out.append(Path(value) / getattr(args, sub) if sub else Path(value))
    return out


def _message(exc: BaseException) -> str:
    if isinstance(exc, KeyError) and exc.args:
        return str(exc.args[0])
    if isinstance(exc, OSError) and exc.strerror:
        return exc.strerror
    return str(exc) or type(exc).__name__


def failure(exc: BaseException, command: str | None, args=None) -> CommandError | None:
    """The :class:`CommandError` of an exception a command let out, read by :data:`ERRORS` (``args``: its parsed
    arguments, for the paths); None when the table has no reading of it (a bug)."""
    if isinstance(exc, CommandError):
        return exc
    outs = _arg_paths(args, _OUTPUT_ARGS.get(command or "", ("out", "asset_out", "dataset")))
    inp = next(iter(_arg_paths(args, _INPUT_ARGS)), None)
    names = [c.__name__ for c in type(exc).__mro__]
    reading = next((ERRORS[k] for n in names for k in (f"{command} {n}", n) if k in ERRORS), None)
    if reading is None:
        return None
    if not isinstance(reading, Reading):
        own = ERRORS.get(f"{command} OSError")
        return reading(exc, outs, inp, own if isinstance(own, Reading) else None)
    code = getattr(exc, "code", None)
    code = code if isinstance(code, str) and code.isupper() else reading.code
    where = {"exc": getattr(exc, "path", None) or getattr(exc, "filename", None) or inp, "input": inp}.get(reading.path or "")
    return CommandError(reading.status, code, where, reading.prefix + _message(exc))


# ------------------------------------------------------------------ shared checks and options
def join_codes(codes: Iterable[str]) -> str:
    """Distinct codes in first-seen order, joined by ``,`` (``""`` when none)."""
    return ",".join(dict.fromkeys(c for c in codes if c))


def listed(text: str | None) -> list[str]:
    """The items of a comma-separated option value, stripped, empty ones dropped."""
    return [item.strip() for item in (text or "").split(",") if item.strip()]


def parse_engines(text: str | None, option: str = "--engines") -> list[str]:
    """The engine names of a comma-separated option value (order kept,
    duplicates dropped, uninstalled ones kept; CommandError status 2
    ``ENGINE_UNKNOWN``: an unknown name)."""
    names = list(dict.fromkeys(listed(text)))
    known = known_engines()
    unknown = [n for n in names if n not in known]
    if unknown:
        raise CommandError.invalid("ENGINE_UNKNOWN",
                                   f"{option}: unknown engine(s) {', '.join(unknown)}; known: {', '.join(known)}")
    return names


def check_out(out: Path | str, inputs: Iterable[Path | str] = (), *, adopt: bool = False) -> None:
    """Refuse an output folder before any work: ``OUTPUT_NOT_A_FOLDER`` when it exists and is not a folder, and,
    for each input (a folder, or a file's folder), ``OUTPUT_IS_INPUT`` / ``OUTPUT_INSIDE_INPUT`` /
    ``OUTPUT_CONTAINS_INPUT`` (also through a symlink; :func:`asset2sim.output_paths.check_location`), unless
    ``adopt`` and ``out`` lies in an output folder asset2sim wrote (its files become that folder's own).

    Raises:
        OutputError: status 4 by :data:`ERRORS`.
    """
    if os.path.lexists(out) and not os.path.isdir(out):
        raise OutputError("exists and is not a folder", "OUTPUT_NOT_A_FOLDER", out)
    if adopt and product_folder_as_named(out) is not None:
        return
    for given in (g for g in inputs if os.path.exists(g)):  # a missing input is named as such later
        check_location(given if os.path.isdir(given) else os.path.dirname(os.path.abspath(given)), out)


def check_jobs(jobs: int) -> None:
    """CommandError status 2 ``JOBS_INVALID``: ``--jobs`` below 1."""
    if jobs < 1:
        raise CommandError.invalid("JOBS_INVALID", f"--jobs must be >= 1, got {jobs}")


def add_catalog(parser) -> None:
    """``--catalog PATH`` (default ``catalog.yaml``) on a command that reads the pipeline's catalog."""
    parser.add_argument("--catalog", type=Path, default=Path("catalog.yaml"), help="catalog file (default catalog.yaml)")


def add_allow_outside(parser) -> None:
    """``--allow-outside-paths DIR`` (repeatable) on a command that reads MJCF or USD inputs."""
    parser.add_argument("--allow-outside-paths", action="append", default=[], type=Path, metavar="DIR",
                        help="let MJCF and USD inputs name files in DIR too, outside their own folder (repeatable; every other "
                             "rule holds: regular files under the size cap)")


def add_mjcf_reading(parser) -> None:
    """``--body`` and ``--mjcf-angle``: how a command reads an MJCF input (:class:`asset2sim.formats.ReadOptions`)."""
    parser.add_argument("--body", help=(
        "the body (MJCF) whose subtree is the object, in a scene with several objects with joints (default: the one "
        "subtree under the world body with hinge or slide joints; tables and walls around it are left out)"))
    parser.add_argument("--mjcf-angle", choices=("radian", "degree"), help=(
        "the unit of an MJCF file's angles, winning over its <compiler angle> and its package's convention (default: "
        "as the package compiles it: robosuite, RoboCasa, LIBERO, Meta-World and Franka Kitchen fragments in radians; "
        "docs/guide/inputs.md)"))


@contextlib.contextmanager
def outside_paths(args):
    """The block run with ``--allow-outside-paths`` in force (CommandError status 2 ``INPUT_NOT_FOUND``: not a folder)."""
    folders = args.allow_outside_paths
    bad = next((f for f in folders if not os.path.isdir(f)), None)
    if bad is not None:
        raise CommandError(INVALID_REQUEST, "INPUT_NOT_FOUND", bad, f"--allow-outside-paths {bad}: not a folder")
    with allow_outside(*folders):
        yield
