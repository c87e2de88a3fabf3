"""The ``asset2sim`` command line.

Subcommands live in :mod:`asset2sim.commands`, one module each, named as the
command and defining ``NAME`` (str, the module's name), ``HELP`` (str),
``add_arguments(parser)`` and ``run(args) -> int`` (the exit code). They are
discovered at start-up, so a command is added by adding a module. Only the
module of the command given is imported (``asset2sim refine`` does not pay
for the imports of ``flow`` or ``benchmark``); ``asset2sim --help`` and a
command line without a known command import them all to list them. The
library itself never prints or exits; only these command modules talk to the
terminal.

One top-level handler (:func:`main`): an expected failure
(:class:`asset2sim.commands._status.CommandError`) prints one line with its
code and path and exits with its status; any other exception is an internal
error: one line naming a log file that holds the traceback, exit status 70.
``--debug`` also prints the traceback. Statuses: :mod:`asset2sim.commands._status`
and docs/guide/outputs.md ("Exit statuses").
"""

from __future__ import annotations

import argparse
import atexit
import ctypes
import importlib
import os
import pkgutil
import sys
import tempfile
import threading
import time
import traceback

# One BLAS thread unless the environment says otherwise, set before numpy is
# imported (as Dask's nanny does for its workers: distributed.nanny.pre-spawn-environ).
# The array work of a refine is on small matrices (a few thousand points
# against a hull's planes), where OpenBLAS's threads add CPU time and no wall
# time: toilet 102622 refined in 7.6 s either way, with 11.9 s of CPU with
# threads and 7.3 s without (2 cores, docs/design/pipeline.md "Throughput").
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
    """The subcommand ``argv`` names when it is a known one and comes before
    any option that could take a value (``--debug`` may precede it); else None
    (then every command's module is imported to parse or to list them)."""
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
    # asset2sim compiles and simulates MJCF but never renders with MuJoCo: without an OpenGL back-end its
    # import skips GLFW and the GL context (0.12 s per process here); a value the user set is kept
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
    """End the process with ``code`` after everything a normal exit does for
    the outside world (the ``atexit`` handlers, logging's flush among them;
    Python's and C's standard streams flushed) but without tearing down the
    interpreter's modules: with numpy, SciPy, trimesh, PyBullet, SAPIEN,
    MuJoCo and OpenUSD loaded that teardown only frees memory the system
    takes back anyway and took 0.28-0.30 s of a 3 s ``refine`` (microwave
    7236, ``benchmarks/bench_refine.py``). Falls back to :func:`sys.exit`
    when a thread other than the main one that the interpreter would wait
    for is still running, or when this Python has no ``atexit._run_exitfuncs``.
    Every output file is already complete (atomic writes, ``asset2sim.atomic``)."""
    run_exitfuncs = getattr(atexit, "_run_exitfuncs", None)
    waiting = [t for t in threading.enumerate() if t is not threading.main_thread() and t.is_alive() and not t.daemon]
    if run_exitfuncs is None or waiting:
        sys.exit(code)
    run_exitfuncs()
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):  # closed or broken pipe: nothing left to flush
            pass
    try:
        ctypes.CDLL(None).fflush(None)  # what C libraries printed (PyBullet, MuJoCo) but not yet wrote
    except (OSError, AttributeError):
        pass
    os._exit(code)


if __name__ == "__main__":  # pragma: no cover
    run()
