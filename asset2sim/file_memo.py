"""Results computed from files, kept in this process while the files are unchanged.

A refine run reads the same files many times: the written URDF after every
write (the engines, the checks, the exports and the evaluation each read it),
the input asset at extraction and the output again in the closed-end
measurement and the evaluation. :class:`FileMemo` keeps a result with the
identity of every file it came from (:func:`identity`: device, inode, size
and modification time in ns) and gives a copy of it back only while every one
of those files still has that identity. An atomic rewrite
(:mod:`asset2sim.atomic`: a new inode) or an edit in place (a new
modification time) makes the result stale, and it is computed again. The
same rule as ``make``'s, at nanosecond resolution.

Identities are taken before the files are read wherever the caller knows the
files in advance (:func:`asset2sim.urdf.read_urdf`), so a file changed while
it is being read is never remembered under its new identity.
"""

from __future__ import annotations

import os
import threading
from collections import OrderedDict
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
    """A bounded, thread-safe map ``key -> result`` whose entries hold only
    while the files they were computed from are unchanged.

    ``copy`` makes the copies that are stored and given out (a caller may
    change what it gets; the stored result stays as computed).
    ``max_entries``: the least recently used entry is dropped beyond it.
    """

    def __init__(self, copy: Callable[[T], T], max_entries: int = 64):
        self._copy = copy
        self._max = int(max_entries)
        self._entries: OrderedDict[Hashable, tuple[tuple, T]] = OrderedDict()
        self._lock = threading.Lock()
        self.hits = 0
        self.misses = 0

    def get(self, key: Hashable) -> T | None:
        """A copy of the result stored under ``key`` when every file it came
        from still has the identity it had; else None (a stale entry is dropped)."""
        with self._lock:
            entry = self._entries.get(key)
        if entry is not None:
            files, value = entry
            if all(i is not None and identity(p) == i for p, i in files):
                with self._lock:
                    if key in self._entries:
                        self._entries.move_to_end(key)
                    self.hits += 1
                return self._copy(value)
            with self._lock:
                self._entries.pop(key, None)
        with self._lock:
            self.misses += 1
        return None

    def put(self, key: Hashable, files: tuple[tuple[str, FileIdentity | None], ...], value: T) -> None:
        """Store a copy of ``value`` under ``key`` with the file identities it
        was computed from (:func:`identities`, taken before reading); not stored
        when a file had none (it did not exist)."""
        if any(i is None for _, i in files):
            return
        stored = self._copy(value)
        with self._lock:
            self._entries[key] = (files, stored)
            self._entries.move_to_end(key)
            while len(self._entries) > self._max:
                self._entries.popitem(last=False)

    def clear(self) -> None:
        """Forget every entry."""
        with self._lock:
            self._entries.clear()
