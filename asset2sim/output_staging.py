"""The staging folder of an output rewrite: ``.<name>.asset2sim-next`` beside the output folder, locked by the run
that writes it (``flock``), so that a later run can tell a live one from a killed run's leftovers and remove only
those (:mod:`asset2sim.output_folder` writes it and swaps it in).
"""

from __future__ import annotations

import fcntl
import os
import shutil
from pathlib import Path

from asset2sim.output_paths import MARKER_NAME, RECORD_NAME

_BOOKKEEPING = frozenset({MARKER_NAME, RECORD_NAME})

#: Ending of a staging folder's name (after the output folder's name and a leading dot).
STAGING_SUFFIX = ".asset2sim-next"


def staging_folder(root: Path) -> Path:
    """``.<name>.asset2sim-next`` beside ``root``."""
    return root.parent / f".{root.name}{STAGING_SUFFIX}"


def is_staging_folder(staging: Path) -> bool:
    """A staging folder asset2sim made: a real folder, empty or holding its bookkeeping files."""
    try:
        return staging.is_dir() and not staging.is_symlink() and (
            not any(staging.iterdir()) or any((staging / n).exists() for n in _BOOKKEEPING))
    except OSError:
        return False


def try_lock(folder: Path) -> int | None:
    """A descriptor of ``folder`` holding an exclusive ``flock`` (released when closed, or when the process ends,
    killed or not); None when another process holds it or the folder cannot be locked."""
    try:
        fd = os.open(folder, os.O_RDONLY | os.O_DIRECTORY | os.O_CLOEXEC)
    except OSError:
        return None
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        os.close(fd)
        return None
    return fd


def remove_stale(staging: Path) -> bool:
    """Remove a staging folder no live run holds (a killed run's leftovers); False when a run still writes it."""
    fd = try_lock(staging)
    if fd is None:
        return False
    try:
        shutil.rmtree(staging, ignore_errors=True)
    finally:
        os.close(fd)
    return not os.path.lexists(staging)
