"""The ``asset2sim`` command line.

Subcommands are the modules of :mod:`asset2sim.commands`, each defining
``NAME``, ``HELP``, ``add_arguments(parser)`` and ``run(args) -> int``; only
the module of the command given is imported. :func:`main` turns what a
command lets out into one line and its status by the one table of
:mod:`asset2sim.commands._status` (``ERRORS``), anything that table does not read
into one line naming a log of the traceback (status 70); SIGTERM unwinds as
Ctrl-C does (status 143). Statuses: docs/guide/outputs.md ("Exit statuses").
"""

from __future__ import annotations

import argparse
import atexit
import contextlib
import ctypes
import importlib
import io
import os
import pkgutil
import sys
import tempfile
import re
import signal
import threading
import time
import traceback

# One BLAS thread unless the environment says otherwise, set before numpy is imported
# (small matrices: threads add CPU time, no wall time; docs/design/pipeline.md "Throughput").
for _var in ("OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import asset2sim.commands as commands  # noqa: E402
from asset2sim import __version__, allocator, library_dirs  # noqa: E402
from asset2sim.commands import _output, _status  # noqa: E402
from asset2sim.commands._output import inert_streams  # noqa: E402
from asset2sim.inert import did_you_mean  # noqa: E402
from asset2sim.commands._status import INTERNAL_ERROR, INTERRUPTED, INVALID_REQUEST, TERMINATED, CommandError  # noqa: E402
from asset2sim.engines.quiet import STARTUP_MESSAGES  # noqa: E402


#: Environment defaults that keep the libraries' logs off the terminal (Prefect's console handler at CRITICAL: a failed
#: flow's traceback is not printed, the command says what failed in one line; Dask's ``distributed.*`` loggers and
#: MLflow's at WARNING); inherited by the processes a command starts (Prefect's server, Dask workers, stage servers).
#: ``--verbose`` leaves the libraries' own defaults; a value the user set is kept.
QUIET_LIBRARY_LOGS = {
    "PREFECT_LOGGING_HANDLERS_CONSOLE_LEVEL": "CRITICAL",
    "DASK_LOGGING__DISTRIBUTED": "warning",
    "MLFLOW_LOGGING_LEVEL": "WARNING",
}


def command_names() -> list[str]:
    """The subcommands' module names, sorted (without importing them)."""
    return sorted(m.name for m in pkgutil.iter_modules(commands.__path__) if not m.name.startswith("_"))


#: Options of the top level, accepted before the command (they take no value).
TOP_LEVEL_FLAGS = ("--debug", "--verbose", "-v")
#: A negative number, which argparse reads as a value, not an option.
_NEGATIVE_NUMBER = re.compile(r"^-\d+$|^-\d*\.\d+$")


def exit_statuses_text(own: dict[int, str] | None = None) -> str:
    """Exit statuses with their meanings, one phrase each (``--help``): every status of
    :mod:`asset2sim.commands._status`, or a command's own (its module's ``EXITS``) with those every command shares
    (2 a usage error, 70 an internal error, 130 interrupted, 143 terminated)."""
    if own is None:
        return ", ".join(f"{code} {meaning}" for code, meaning in _status.EXIT_STATUSES.items())
    shared = {INVALID_REQUEST: "usage error", INTERNAL_ERROR: "internal error", INTERRUPTED: "interrupted",
              TERMINATED: "terminated"}
    merged = {**shared, **own}
    return ", ".join(f"{code} {merged[code]}" for code in sorted(merged))


def unknown_options(parser: argparse.ArgumentParser, argv: list[str]) -> list[str]:
    """The options of ``argv`` that ``parser`` does not know (the text before any ``=``), in order: not one of its
    option strings nor, with ``allow_abbrev``, a prefix of one; a negative number and anything after ``--`` are values."""
    known = [s for a in parser._actions for s in a.option_strings]
    out = []
    for token in argv:
        if token == "--":
            break
        if not token.startswith("-") or token == "-" or _NEGATIVE_NUMBER.match(token):
            continue
        name = token.split("=", 1)[0]
        if name in known:
            continue
        if name.startswith("--"):
            if parser.allow_abbrev and any(k.startswith(name) for k in known if k.startswith("--")):
                continue  # an abbreviation (an ambiguous one argparse names itself)
        elif name[:2] in known:  # -ovalue, -qv
            continue
        out.append(name)
    return list(dict.fromkeys(out))


class CommandParser(argparse.ArgumentParser):
    """An argument parser whose usage errors are one line each, ``asset2sim COMMAND: CODE: message`` on stderr
    (status 2): an unknown option (``OPTION_UNKNOWN``) with the closest known one ("did you mean"), named before the
    problems it causes (a required option reported missing); any other usage problem ``USAGE_INVALID``."""

    command: str | None = None  # the subcommand this parser reads (None: the top level)

    def parse_known_args(self, args=None, namespace=None):
        self._argv = list(sys.argv[1:] if args is None else args)
        parsed, extras = super().parse_known_args(args, namespace)
        if extras and self.command is not None:  # a command's leftovers are its own errors, not the top level's
            self.error(f"unrecognized arguments: {' '.join(extras)}")
        return parsed, extras

    def error(self, message: str):
        argv = getattr(self, "_argv", [])
        if self.command is None:  # the top level reads only what comes before the command
            names = command_names()
            argv = next((argv[:i] for i, a in enumerate(argv) if a in names), argv)
        unknown = unknown_options(self, argv)
        known = [s for a in self._actions for s in a.option_strings]
        where = f"asset2sim {self.command} --help" if self.command else "asset2sim --help"
        lines = [CommandError.invalid("OPTION_UNKNOWN", f"unknown option {name}{did_you_mean(name, known)} (options: {where})")
                 .line(self.command) for name in unknown]
        if not lines:
            lines = [CommandError.invalid("USAGE_INVALID", f"{message} (usage: {where})").line(self.command)]
        self.exit(INVALID_REQUEST, "\n".join(lines) + "\n")


def build_parser(only: str | None = None) -> argparse.ArgumentParser:
    """The argument parser with every discovered subcommand, or only the one
    named ``only`` (its module alone is imported)."""
    parser = CommandParser(
        prog="asset2sim",
        description="Turn articulated-object assets into interaction-ready simulation assets.",
        epilog=f"exit statuses: {exit_statuses_text()} (see docs/guide/outputs.md)",
    )
    parser.add_argument("--version", action="version", version=f"asset2sim {__version__}")
    parser.add_argument("--debug", action="store_true", help="print the traceback of an error (also accepted after the command)")
    parser.add_argument("--verbose", "-v", action="store_true",
                        help="also show the simulators' start-up messages and the libraries' INFO logs (PyBullet's build line, "
                             "SAPIEN's renderer warnings, Dask's and Prefect's logs)")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=CommandParser)
    for name in (n for n in command_names() if only in (None, n)):
        module = importlib.import_module(f"asset2sim.commands.{name}")
        p = sub.add_parser(module.NAME, help=module.HELP, description=module.HELP,
                           epilog=f"exit statuses: {exit_statuses_text(getattr(module, 'EXITS', {}))} "
                                  "(see docs/guide/outputs.md)")
        p.command = module.NAME
        module.add_arguments(p)
        p.add_argument("--debug", action="store_true", default=argparse.SUPPRESS, help="print the traceback of an error")
        p.add_argument("--verbose", action="store_true", default=argparse.SUPPRESS,
                       help="also show the simulators' start-up messages and the libraries' INFO logs")
        p.set_defaults(_run=module.run)
    return parser


def command_word(argv: list[str]) -> str | None:
    """The first word of ``argv`` after the top-level flags (the command, known or not); None when an option
    such as ``--help`` comes first or nothing does."""
    word = next((arg for arg in argv if arg not in TOP_LEVEL_FLAGS), None)
    return None if word is None or word.startswith("-") else word


def requested_command(argv: list[str]) -> str | None:
    """The known subcommand ``argv`` names before any option but the top-level flags, else None."""
    word = command_word(argv)
    return word if word in command_names() else None


def main(argv: list[str] | None = None) -> int:
    """Entry point of the console script; returns the exit code. Everything the command prints passes through
    :mod:`asset2sim.commands._output` (no control character of a name or a request reaches the terminal)."""
    with inert_streams():
        return _main(argv)


def _main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    library_dirs.configure()  # matplotlib's and MLflow's folders: never created in the home folder by a command
    allocator.keep_freed_memory()  # freed arrays reused, not faulted in again (asset2sim.allocator)
    # never renders with MuJoCo: no OpenGL back-end spares its import GLFW and a GL context (a user's value is kept)
    os.environ.setdefault("MUJOCO_GL", "disable")
    word, names = command_word(argv), command_names()
    if word is not None and word not in names:
        print(CommandError.invalid("COMMAND_UNKNOWN", f"unknown command {word!r}{did_you_mean(word, names)} "
                                   f"(commands: {', '.join(names)})").line(None), file=sys.stderr, flush=True)
        return INVALID_REQUEST
    parser = build_parser(only=word)
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # --help, --version, a usage error (printed already)
        return exc.code if isinstance(exc.code, int) else 0
    if not hasattr(args, "_run"):
        parser.print_help()
        return 2
    if args.verbose:  # inherited by the worker processes a command starts
        os.environ[STARTUP_MESSAGES] = "1"
    else:  # before any library is imported: their loggers read these when configured
        for name, value in QUIET_LIBRARY_LOGS.items():
            os.environ.setdefault(name, value)
    command = args.command
    previous = _on_sigterm()
    try:
        return int(args._run(args) or 0)
    except KeyboardInterrupt as exc:  # Ctrl-C, or SIGTERM (:class:`Terminated`): cleaned up as the stack unwound
        print(f"asset2sim {command}: {'TERMINATED' if isinstance(exc, Terminated) else 'INTERRUPTED'}", file=sys.stderr, flush=True)
        return TERMINATED if isinstance(exc, Terminated) else INTERRUPTED
    except BrokenPipeError:  # the reader of a pipe stopped (`| head`): what it wanted was written
        closed_pipe()
        return 0
    except Exception as exc:  # the one place that turns a failure into a status: _status.ERRORS, else a bug
        if args.debug:
            traceback.print_exception(type(exc), exc, exc.__traceback__, file=sys.stderr)
        err = _status.failure(exc, command, args)
        if err is None:
            return internal_error(command, exc)
        print("\n".join(err.lines(command)), file=sys.stderr, flush=True)
        return err.status
    finally:
        if previous is not None:
            signal.signal(signal.SIGTERM, previous)


class Terminated(KeyboardInterrupt):
    """SIGTERM, raised where the command is, so that it unwinds as Ctrl-C does (a refine's staging folder removed,
    servers and clusters stopped): exit status 143."""


def _raise_terminated(signum, frame):
    raise Terminated()


def _on_sigterm():
    """SIGTERM raises :class:`Terminated` in the main thread while a command runs; returns the handler it replaced
    (None off the main thread, where no handler can be set)."""
    if threading.current_thread() is not threading.main_thread():
        return None
    return signal.signal(signal.SIGTERM, _raise_terminated)


def closed_pipe() -> None:
    """Standard output pointed at the null device once a pipe's reader has closed it, so nothing the process still
    writes or flushes at exit raises again (Python's "Exception ignored ... BrokenPipeError")."""
    with contextlib.suppress(OSError, ValueError, AttributeError, io.UnsupportedOperation):
        fd = _output.raw(sys.stdout).fileno()
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, fd)
        os.close(devnull)


def internal_error(command: str | None, exc: BaseException) -> int:
    """One line naming a log of ``exc``'s traceback (a new file in ``$ASSET2SIM_LOG_DIR`` or the temporary folder);
    returns :data:`INTERNAL_ERROR`."""
    try:
        folder = os.environ.get("ASSET2SIM_LOG_DIR") or tempfile.gettempdir()
        os.makedirs(folder, exist_ok=True)
        fd, path = tempfile.mkstemp(prefix=f"asset2sim-{command or 'cli'}-{time.strftime('%Y%m%d-%H%M%S')}-", suffix=".log",
                                    dir=folder)
        with os.fdopen(fd, "w", encoding="utf-8") as fh:
            fh.write(f"asset2sim {__version__} {command or ''}: internal error\nargv: {sys.argv!r}\n\n")
            fh.write("".join(traceback.format_exception(type(exc), exc, exc.__traceback__)))
        where = f"traceback in {path}"
    except OSError as log_exc:
        where = f"no log written ({log_exc}); rerun with --debug for the traceback"
    first = (str(exc).strip().splitlines() or [""])[0]
    print(f"asset2sim {command}: INTERNAL_ERROR: {type(exc).__name__}: {first}; {where}", file=sys.stderr, flush=True)
    return INTERNAL_ERROR


#: Commands whose process ends by :func:`fast_exit`: one asset's work, no
#: cluster, server or worker threads of their own.
FAST_EXIT_COMMANDS = frozenset({"refine", "demo", "evaluate"})


def run() -> None:
    """Console-script entry (``asset2sim ...``, ``python -m asset2sim``):
    :func:`main` on ``sys.argv``, then exit with its code; the commands of
    :data:`FAST_EXIT_COMMANDS` by :func:`fast_exit`."""
    argv = sys.argv[1:]
    code = main(argv)
    if requested_command(argv) in FAST_EXIT_COMMANDS:
        fast_exit(code)
    sys.exit(code)


def fast_exit(code: int) -> None:
    """End the process with ``code`` after the ``atexit`` handlers and flushing
    Python's and C's standard streams, without tearing down the interpreter's
    modules; :func:`sys.exit` while a non-daemon thread runs or without
    ``atexit._run_exitfuncs``."""
    run_exitfuncs = getattr(atexit, "_run_exitfuncs", None)
    waiting = [t for t in threading.enumerate() if t is not threading.main_thread() and t.is_alive() and not t.daemon]
    if run_exitfuncs is None or waiting:
        sys.exit(code)
    run_exitfuncs()
    for stream in (sys.stdout, sys.stderr):
        with contextlib.suppress(OSError, ValueError):  # closed or broken pipe: nothing left to flush
            stream.flush()
    with contextlib.suppress(OSError, AttributeError):
        ctypes.CDLL(None).fflush(None)  # what C libraries printed (PyBullet, MuJoCo) but not yet wrote
    os._exit(code)


if __name__ == "__main__":  # pragma: no cover
    run()
