"""Results computed from files, kept in this process while the files are unchanged.

:class:`FileMemo` keeps a result with the :func:`identity` (device, inode,
size, modification time in ns) of every file it came from and gives a copy
back only while each file still has it: an atomic rewrite (new inode) or an
edit in place (new mtime) makes it stale. Callers take identities before
reading, so a file changed while read is never remembered.
"""

from __future__ import annotations

import os
import threading
import cachetools
from pathlib import Path
from typing import Callable, Generic, Hashable, Iterable, TypeVar

T = TypeVar("T")

FileIdentity = tuple[int, int, int, int]
"""(device, inode, size in bytes, modification time in ns) of a file."""


def identity(path: Path | str) -> FileIdentity | None:
    """The :data:`FileIdentity` of ``path`` (symbolic links followed), None
    when it cannot be stat'ed."""
    try:
        st = os.stat(path)
    except OSError:
        return None
    return (st.st_dev, st.st_ino, st.st_size, st.st_mtime_ns)


def identities(paths: Iterable[Path | str]) -> tuple[tuple[str, FileIdentity | None], ...]:
    """(absolute path, :func:`identity`) of each of ``paths``, in order."""
    return tuple((os.path.abspath(p), identity(p)) for p in paths)


class FileMemo(Generic[T]):
    """A bounded (least recently used dropped beyond ``max_entries``),
    thread-safe map ``key -> result`` whose entries hold while their files are
    unchanged; ``copy`` makes the copies stored and given out."""

    def __init__(self, copy: Callable[[T], T], max_entries: int = 64):
        self._copy = copy
        self._entries: cachetools.LRUCache = cachetools.LRUCache(maxsize=int(max_entries))
        self._lock = threading.Lock()
        self.hits = 0

    def get(self, key: Hashable) -> T | None:
        """A copy of the result stored under ``key`` when every file it came
        from still has the identity it had; else None (a stale entry is dropped)."""
        with self._lock:
            entry = self._entries.get(key)
        if entry is not None:
            files, value = entry
            if all(i is not None and identity(p) == i for p, i in files):
                with self._lock:
                    self.hits += 1
                return self._copy(value)
            with self._lock:
                self._entries.pop(key, None)
        return None

    def put(self, key: Hashable, files: tuple[tuple[str, FileIdentity | None], ...], value: T) -> None:
        """Store a copy of ``value`` under ``key`` with the :func:`identities` of
        its files (taken before reading); not when a file had none."""
        if any(i is None for _, i in files):
            return
        stored = self._copy(value)
        with self._lock:
            self._entries[key] = (files, stored)
