"""Child processes that end with the process that started them, killed or not (Linux
``prctl(PR_SET_PDEATHSIG)``, which survives ``execve``): the launcher ``python -m asset2sim.flows.lifeline
<parent pid> -- <program> <args...>`` (:func:`command`) sets it and becomes the program; elsewhere than
Linux it just runs the program.
"""

from __future__ import annotations

import ctypes
import os
import signal
import sys

#: ``PR_SET_PDEATHSIG`` of ``<linux/prctl.h>``.
PR_SET_PDEATHSIG = 1


def set_parent_death_signal(sig: int = signal.SIGKILL, expected_parent: int | None = None) -> bool:
    """Have the kernel send ``sig`` to this process when its parent ends
    (Linux ``prctl(PR_SET_PDEATHSIG)``); when the parent is no longer
    ``expected_parent``, ``sig`` is sent at once. Returns False elsewhere
    than Linux or without ``prctl`` (nothing done)."""
    if not sys.platform.startswith("linux"):
        return False
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        if libc.prctl(PR_SET_PDEATHSIG, int(sig), 0, 0, 0) != 0:
            return False
    except (OSError, AttributeError):
        return False
    if expected_parent is not None and os.getppid() != int(expected_parent):
        os.kill(os.getpid(), sig)
    return True


def command(argv: list[str], parent: int | None = None) -> list[str]:
    """``argv`` run through the launcher: the program gets SIGKILL when
    ``parent`` (default: this process) ends.

    Raises:
        ValueError: empty ``argv``.
    """
    if not argv:
        raise ValueError("no program to run")
    return [sys.executable, "-m", "asset2sim.flows.lifeline", str(parent or os.getpid()), "--", *map(str, argv)]


def _main(args: list[str]) -> int:
    if len(args) < 3 or args[1] != "--":
        sys.stderr.write("usage: python -m asset2sim.flows.lifeline <parent pid> -- <program> [args...]\n")
        return 2
    set_parent_death_signal(expected_parent=int(args[0]))
    os.execvp(args[2], args[2:])
    return 127  # not reached: execvp replaces this process or raises


if __name__ == "__main__":
    sys.exit(_main(sys.argv[1:]))
