"""On-disk cache of computed arrays, keyed by a digest of everything they
were computed from.

The costly geometry of a refine (CoACD decompositions, the writer's convex
collision pieces) depends only on mesh bytes, a few numbers and the code
that computes it, so a rerun of the same asset (a nightly refinement after a
code change elsewhere, a benchmark, another request at the same scale) can
load it instead of computing it again: the converters of Isaac Lab hash their
inputs and skip unchanged work the same way. Callers build the digest
(:func:`digest`) from every input, including the source of the code that
computes the value (:func:`source_digest`), so a change to that code is a
miss, never a stale hit.

Entries are ``<cache>/<kind>/<digest>.npz`` (numpy's ``savez``, no pickles),
written atomically with the mode of the umask (:mod:`asset2sim.atomic`). The
folder is ``$ASSET2SIM_CACHE``, else ``~/.cache/asset2sim``; ``off``,
``none`` or ``0`` turns the cache off. The cache is an optimisation only: an
entry that cannot be read or written is ignored.
"""

from __future__ import annotations

import functools
import hashlib
import io
import os
import zipfile
from pathlib import Path

import numpy as np

from asset2sim import atomic

__all__ = ["array_text", "cache_dir", "digest", "load", "source_digest", "store", "text_array"]

_OFF = ("off", "none", "0")


def cache_dir() -> Path | None:
    """The cache folder (``$ASSET2SIM_CACHE``, else ``~/.cache/asset2sim``),
    or None when ``$ASSET2SIM_CACHE`` is ``off`` / ``none`` / ``0``."""
    root = os.environ.get("ASSET2SIM_CACHE")
    if root is not None and root.strip().lower() in _OFF:
        return None
    return Path(root) if root else Path.home() / ".cache" / "asset2sim"


def digest(*parts: bytes | str) -> str:
    """SHA-256 hex digest of ``parts`` (bytes, or text encoded as UTF-8), each
    prefixed by its length so that no two different sequences collide."""
    h = hashlib.sha256()
    for p in parts:
        b = p.encode() if isinstance(p, str) else bytes(p)
        h.update(len(b).to_bytes(8, "little"))
        h.update(b)
    return h.hexdigest()


@functools.lru_cache(maxsize=None)
def source_digest(*modules: str) -> str:
    """Digest of the source files of the named modules (``__file__`` of each,
    imported): a cache key part that changes whenever that code changes.

    Raises:
        ImportError: a module cannot be imported.
        OSError: a source file cannot be read.
    """
    import importlib

    parts = []
    for name in modules:
        mod = importlib.import_module(name)
        parts += [name, Path(mod.__file__).read_bytes()]
    return digest(*parts)


def _path(kind: str, key: str) -> Path | None:
    root = cache_dir()
    return None if root is None else root / kind / f"{key}.npz"


def load(kind: str, key: str) -> dict[str, np.ndarray] | None:
    """The arrays stored under ``kind`` / ``key`` (name -> array), or None
    when there is no readable entry (missing, truncated, not an npz, the
    cache off)."""
    path = _path(kind, key)
    if path is None or not path.is_file():
        return None
    try:
        with np.load(path, allow_pickle=False) as data:
            return {k: data[k] for k in data.files}
    except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile):
        return None


def store(kind: str, key: str, arrays: dict[str, np.ndarray]) -> None:
    """Store ``arrays`` (name -> array; no object arrays) under ``kind`` /
    ``key``, atomically; nothing when the cache is off or cannot be written."""
    path = _path(kind, key)
    if path is None:
        return
    try:
        buf = io.BytesIO()
        np.savez(buf, **arrays)
        atomic.write_bytes(path, buf.getvalue())
    except (OSError, ValueError):
        pass  # an optimisation only


def text_array(text: str) -> np.ndarray:
    """``text`` as a uint8 array (UTF-8), to store beside arrays (JSON
    metadata, a serialised model) without pickles."""
    return np.frombuffer(text.encode(), dtype=np.uint8)


def array_text(array: np.ndarray) -> str:
    """The text :func:`text_array` stored.

    Raises:
        UnicodeDecodeError: the bytes are not UTF-8.
    """
    return np.asarray(array, dtype=np.uint8).tobytes().decode()
