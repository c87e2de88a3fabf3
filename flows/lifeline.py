"""Child processes that end with the process that started them, killed or not.

A flow's driver starts long-lived helpers (the temporary Prefect server, the
isolated stage processes of the Dask workers). A driver that exits normally
stops them; one killed with SIGKILL (or SIGTERM, whose default action skips
``atexit`` and ``finally``) cannot, and they would run on as orphans. On
Linux the kernel can do it instead: ``prctl(PR_SET_PDEATHSIG, sig)`` asks for
``sig`` when the parent ends (prctl(2): strictly, when the *thread* that
created the child ends, so start helpers from a thread that lives as long as
they are wanted, e.g. the main thread or the thread that waits for them).
The setting survives ``execve``, so a launcher can set it and then become the
real program:

    python -m asset2sim.flows.lifeline <parent pid> -- <program> <args...>

(:func:`command` builds that argument list). The launcher checks that its
parent is still ``<parent pid>`` after setting the signal, closing the race
of a parent that died before: it then ends itself the same way.

Dask worker processes of a local cluster already exit when the driver dies
(``distributed`` watches a pipe from the parent); Prefect's own temporary
server does not, which is why the flow starts its server through this module
(:func:`asset2sim.flows.server.start_local_server`). A process that a
lifeline-bound child starts itself is not covered (nothing the refine stage
runs starts one).

Elsewhere than Linux, :func:`set_parent_death_signal` returns False and the
launcher just runs the program. Nothing here imports Prefect, Dask or MLflow.
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
    (Linux ``prctl(PR_SET_PDEATHSIG)``).

    Args:
        sig: the signal (default SIGKILL: ends the process even inside a long
            native call).
        expected_parent: the pid the parent should have; when the parent is
            already another process (the expected one died before the call),
            ``sig`` is sent to this process at once.

    Returns:
        True when the kernel took the setting; False elsewhere than Linux or
        when ``prctl`` is unavailable (nothing else is done then).
    """
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
    ``parent`` (default: this process) ends. Start the result with
    :class:`subprocess.Popen` from this process.

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
    set_parent_death_signal(signal.SIGKILL, expected_parent=int(args[0]))
    os.execvp(args[2], args[2:])
    return 127  # not reached: execvp replaces this process or raises


if __name__ == "__main__":
    sys.exit(_main(sys.argv[1:]))
