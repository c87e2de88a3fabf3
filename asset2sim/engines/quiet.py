"""Quiet simulators: C-level prints and import-time warnings kept out of the
product's output (``asset2sim --verbose`` shows the start-up messages)."""

from __future__ import annotations

import os
import sys
import threading
from contextlib import contextmanager

#: Serializes the swaps of the process-wide file descriptors between threads (re-entrant).
_LOCK = threading.RLock()
#: Environment variable: "1" shows the simulators' start-up messages (``asset2sim --verbose``).
STARTUP_MESSAGES = "ASSET2SIM_STARTUP_MESSAGES"
#: Start of the import-time warnings :func:`startup_quiet` hides (SAPIEN's renderer probe).
STARTUP_WARNINGS = ("Failed to find system libvulkan",)


@contextmanager
def startup_quiet():
    """Hide a simulator's import-time messages on fd 1 and 2 and the warnings
    of :data:`STARTUP_WARNINGS` unless :data:`STARTUP_MESSAGES` is "1"."""
    import warnings

    if os.environ.get(STARTUP_MESSAGES) == "1":
        yield
        return
    with warnings.catch_warnings(), quiet_fds():
        for text in STARTUP_WARNINGS:
            warnings.filterwarnings("ignore", message=text)
        yield


def quiet_stdout():
    """Silence C-level prints (Bullet's b3Warning ...) on fd 1 while the block
    runs; process-wide: threads take turns, nesting is fine."""
    return quiet_fds((1,))


@contextmanager
def quiet_fds(fds: tuple[int, ...] = (1, 2)):
    """Silence C-level prints on the file descriptors ``fds`` (default 1 and 2): sent to /dev/null while the block runs
    (C and Python buffers flushed on both sides)."""
    with _LOCK:
        saved = []
        for stream in (sys.stdout, sys.stderr):
            try:
                stream.flush()
            except (AttributeError, OSError, ValueError):  # no stream, closed
                pass
        for fd in fds:
            try:
                saved.append((fd, os.dup(fd)))
            except OSError:  # no such descriptor
                pass
        devnull = os.open(os.devnull, os.O_WRONLY)
        _flush_c_stdout()  # what C code buffered before the block goes out
        try:
            for fd, _ in saved:
                os.dup2(devnull, fd)
            yield
        finally:
            _flush_c_stdout()  # what it buffered inside (a pipe's stdout is block-buffered) goes to /dev/null
            for fd, dup in saved:
                os.dup2(dup, fd)
                os.close(dup)
            os.close(devnull)


def _flush_c_stdout() -> None:
    """``fflush(stdout)`` of the C library (its buffer outlives a dup2 of fd 1)."""
    try:
        import ctypes

        ctypes.CDLL(None).fflush(None)
    except (OSError, AttributeError):  # pragma: no cover - no C library symbols
        pass
