"""The ``asset2sim`` command line.

Subcommands live in :mod:`asset2sim.commands`, one module each, defining
``NAME`` (str), ``HELP`` (str), ``add_arguments(parser)`` and
``run(args) -> int`` (the exit code). They are discovered at start-up, so a
command is added by adding a module. The library itself never prints or exits;
only these command modules talk to the terminal.
"""

from __future__ import annotations

import argparse
import importlib
import pkgutil
import sys

from asset2sim import __version__


def build_parser() -> argparse.ArgumentParser:
    """The argument parser with every discovered subcommand."""
    import asset2sim.commands as commands

    parser = argparse.ArgumentParser(
        prog="asset2sim",
        description="Turn articulated-object assets into interaction-ready simulation assets.",
    )
    parser.add_argument("--version", action="version", version=f"asset2sim {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for info in sorted(pkgutil.iter_modules(commands.__path__), key=lambda m: m.name):
        if info.name.startswith("_"):
            continue
        module = importlib.import_module(f"asset2sim.commands.{info.name}")
        p = sub.add_parser(module.NAME, help=module.HELP, description=module.HELP)
        module.add_arguments(p)
        p.set_defaults(_run=module.run)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Entry point of the console script; returns the exit code."""
    parser = build_parser()
    args = parser.parse_args(argv)
    if not hasattr(args, "_run"):
        parser.print_help()
        return 2
    return int(args._run(args) or 0)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
