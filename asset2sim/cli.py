"""The ``asset2sim`` command line.

Subcommands are the modules of :mod:`asset2sim.commands`, each defining
``NAME``, ``HELP``, ``add_arguments(parser)`` and ``run(args) -> int``; only
the module of the command given is imported. :func:`main` turns a
:class:`asset2sim.commands._status.CommandError` into one line and its status,
any other exception into one line naming a log of the traceback (status 70).
Statuses: docs/guide/outputs.md ("Exit statuses").
"""

from __future__ import annotations

import argparse
import atexit
import contextlib
import ctypes
import importlib
import os
import pkgutil
import sys
import tempfile
import threading
import time
import traceback

# One BLAS thread unless the environment says otherwise, set before numpy is imported
# (small matrices: threads add CPU time, no wall time; docs/design/pipeline.md "Throughput").
for _var in ("OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import asset2sim.commands as commands  # noqa: E402
from asset2sim import __version__, allocator  # noqa: E402
from asset2sim.commands._status import INTERNAL_ERROR, INTERRUPTED, CommandError  # noqa: E402
from asset2sim.engines.quiet import STARTUP_MESSAGES  # noqa: E402


def command_names() -> list[str]:
    """The subcommands' module names, sorted (without importing them)."""
    return sorted(m.name for m in pkgutil.iter_modules(commands.__path__) if not m.name.startswith("_"))


def build_parser(only: str | None = None) -> argparse.ArgumentParser:
    """The argument parser with every discovered subcommand, or only the one
    named ``only`` (its module alone is imported)."""
    parser = argparse.ArgumentParser(
        prog="asset2sim",
        description="Turn articulated-object assets into interaction-ready simulation assets.",
        epilog="exit statuses: 0 done, 1 invalid input, 2 invalid request/overlay or usage, 3 written but not "
        "interaction-ready, 4 output location problem, 70 internal error (see docs/guide/outputs.md)",
    )
    parser.add_argument("--version", action="version", version=f"asset2sim {__version__}")
    parser.add_argument("--debug", action="store_true", help="print the traceback of an error (also accepted after the command)")
    parser.add_argument("--verbose", "-v", action="store_true",
                        help="also show the simulators' start-up messages (PyBullet's build line, SAPIEN's renderer warnings)")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in command_names():
        if only is not None and name != only:
            continue
        module = importlib.import_module(f"asset2sim.commands.{name}")
        p = sub.add_parser(module.NAME, help=module.HELP, description=module.HELP)
        module.add_arguments(p)
        p.add_argument("--debug", action="store_true", default=argparse.SUPPRESS, help="print the traceback of an error")
        p.add_argument("--verbose", action="store_true", default=argparse.SUPPRESS,
                       help="also show the simulators' start-up messages")
        p.set_defaults(_run=module.run)
    return parser


def requested_command(argv: list[str]) -> str | None:
    """The known subcommand ``argv`` names before any option but ``--debug``, else None."""
    for arg in argv:
        if arg == "--debug":
            continue
        if arg.startswith("-"):
            return None
        return arg if arg in command_names() else None
    return None


def write_error_log(command: str | None, exc: BaseException) -> str:
    """Write ``exc``'s traceback to a new log file (``$ASSET2SIM_LOG_DIR`` or
    the temporary folder); returns its path."""
    folder = os.environ.get("ASSET2SIM_LOG_DIR") or tempfile.gettempdir()
    os.makedirs(folder, exist_ok=True)
    fd, path = tempfile.mkstemp(prefix=f"asset2sim-{command or 'cli'}-{time.strftime('%Y%m%d-%H%M%S')}-", suffix=".log", dir=folder)
    with os.fdopen(fd, "w", encoding="utf-8") as fh:
        fh.write(f"asset2sim {__version__} {command or ''}: internal error\nargv: {sys.argv!r}\n\n")
        fh.write("".join(traceback.format_exception(type(exc), exc, exc.__traceback__)))
    return path


def main(argv: list[str] | None = None) -> int:
    """Entry point of the console script; returns the exit code."""
    argv = sys.argv[1:] if argv is None else list(argv)
    allocator.keep_freed_memory()  # freed arrays reused, not faulted in again (asset2sim.allocator)
    # never renders with MuJoCo: no OpenGL back-end spares its import GLFW and a GL context (a user's value is kept)
    os.environ.setdefault("MUJOCO_GL", "disable")
    parser = build_parser(only=requested_command(argv))
    args = parser.parse_args(argv)
    if not hasattr(args, "_run"):
        parser.print_help()
        return 2
    debug = bool(getattr(args, "debug", False))
    if getattr(args, "verbose", False):  # inherited by the worker processes a command starts
        os.environ[STARTUP_MESSAGES] = "1"
    command = getattr(args, "command", None)
    try:
        return int(args._run(args) or 0)
    except CommandError as exc:
        if debug:
            traceback.print_exception(type(exc), exc, exc.__traceback__, file=sys.stderr)
        print(exc.line(command), file=sys.stderr, flush=True)
        return exc.status
    except KeyboardInterrupt:
        print(f"asset2sim {command}: INTERRUPTED", file=sys.stderr, flush=True)
        return INTERRUPTED
    except Exception as exc:  # the one place that turns a bug into a status
        if debug:
            traceback.print_exception(type(exc), exc, exc.__traceback__, file=sys.stderr)
        try:
            where = f"traceback in {write_error_log(command, exc)}"
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
