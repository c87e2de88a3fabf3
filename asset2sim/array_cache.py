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
entry that cannot be written is not written.

An entry proves itself: beside its arrays it holds its kind, its key and the
SHA-256 of its arrays (:func:`content_digest`), and :func:`load` checks them
all before returning anything. An entry whose zip directory declares more
than :data:`MAX_ENTRY_BYTES` (checked before anything is inflated), that
cannot be read, that was stored under another kind or key (copied or moved
between file names), whose arrays do not match their digest, or that holds
NaN or infinite numbers is rejected: a :class:`CacheWarning` names it, the
file is deleted and the caller computes the value again and stores it anew.

:func:`guard` keeps the cache out of given folders (a refine's input and
output): while it holds, a cache folder inside one of them is refused with a
warning and the cache is off, so nothing is written into an input or output.
"""

from __future__ import annotations

import contextlib
import contextvars
import functools
import hashlib
import io
import json
import math
import os
import sys
import warnings
import zipfile
from pathlib import Path
from typing import Iterator

import numpy as np

from asset2sim import atomic

__all__ = [
    "MAX_ENTRY_BYTES", "CacheWarning", "array_text", "cache_dir", "content_digest", "digest", "guard", "load",
    "source_digest", "store", "text_array",
]

_OFF = ("off", "none", "0")

#: Largest entry :func:`load` reads and :func:`store` writes: the sum of its
#: members' uncompressed sizes in bytes, as the zip directory declares them
#: (checked before anything is inflated; the file on disk may hold at most
#: twice as much). The largest entries the refines of the 21 dev objects
#: wrote measure 0.72 MB (``pieces``), 35 kB (``coacd``) and 1.2 kB
#: (``analysis``) uncompressed: 64 MiB is ~90x the largest and bounds what a
#: crafted entry can make a refine allocate (a 9 MB deflated entry that
#: inflated to 2 GiB once took one to 6.35 GB).
MAX_ENTRY_BYTES = 64 << 20

#: The member that carries an entry's proof (JSON: format, kind, key, sha256).
_PROOF = "__cache__"
_PROOF_FORMAT = 1

#: The folders the cache must stay out of in this context (resolved; :func:`guard`).
_FORBIDDEN: contextvars.ContextVar[tuple[Path, ...]] = contextvars.ContextVar("asset2sim_array_cache_forbidden", default=())
#: (cache folder, forbidden folder) pairs already warned about.
_WARNED: set[tuple[str, str]] = set()


class CacheWarning(UserWarning):
    """An on-disk cache entry was rejected (it is computed again), or the
    cache folder was refused (inside an input or output folder)."""


def cache_dir() -> Path | None:
    """The cache folder (``$ASSET2SIM_CACHE``, else ``~/.cache/asset2sim``),
    or None when ``$ASSET2SIM_CACHE`` is ``off`` / ``none`` / ``0``, or when
    the folder (symlinks resolved) lies inside a folder a :func:`guard` in
    force keeps it out of (a :class:`CacheWarning` once per pair of folders)."""
    root = os.environ.get("ASSET2SIM_CACHE")
    if root is not None and root.strip().lower() in _OFF:
        return None
    path = Path(root) if root else Path.home() / ".cache" / "asset2sim"
    forbidden = _FORBIDDEN.get()
    if forbidden:
        try:
            resolved = path.expanduser().resolve()
        except (OSError, RuntimeError):  # a symlink loop: where it lies is unknown
            resolved = None
        for folder in forbidden:
            if resolved is None or resolved == folder or folder in resolved.parents:
                if (str(path), str(folder)) not in _WARNED:
                    _WARNED.add((str(path), str(folder)))
                    warnings.warn(f"asset2sim cache: the cache folder {path} lies inside {folder} (an input or output "
                                  "folder): the on-disk cache is off there", CacheWarning, stacklevel=2)
                return None
    return path


@contextlib.contextmanager
def guard(*roots: Path | str | None) -> Iterator[None]:
    """Within the block the cache stays out of ``roots`` (folders, None
    skipped; symlinks resolved), besides the folders already kept out in this
    context: :func:`cache_dir` is None while it lies inside one of them, so
    nothing is read from or written to it (a :class:`CacheWarning` says so)."""
    resolved = []
    for r in roots:
        if r is not None:
            try:
                resolved.append(Path(r).expanduser().resolve())
            except (OSError, RuntimeError):  # a symlink loop: kept out as written
                resolved.append(Path(os.path.abspath(r)))
    token = _FORBIDDEN.set(_FORBIDDEN.get() + tuple(resolved))
    try:
        yield
    finally:
        _FORBIDDEN.reset(token)


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
    """Digest of the source files of the named modules (``__file__`` of each;
    the caller has imported them, this module imports nothing): a cache key
    part that changes whenever that code changes.

    Raises:
        ImportError: a module is not imported or has no source file.
        OSError: a source file cannot be read.
    """
    parts = []
    for name in modules:
        mod = sys.modules.get(name)
        if mod is None or not getattr(mod, "__file__", None):
            raise ImportError(f"{name} is not an imported module with a source file")
        parts += [name, Path(mod.__file__).read_bytes()]
    return digest(*parts)


def _path(kind: str, key: str) -> Path | None:
    root = cache_dir()
    return None if root is None else root / kind / f"{key}.npz"


def content_digest(arrays: dict[str, np.ndarray]) -> str:
    """SHA-256 hex digest of ``arrays`` (name -> array): in name order each
    name, dtype, shape and bytes (C order), so that any change to an array,
    its type or its shape, a renamed, added or missing array changes it."""
    parts: list[bytes | str] = []
    for name in sorted(arrays):
        a = np.asarray(arrays[name])
        parts += [name, a.dtype.str, repr(a.shape), a.tobytes()]
    return digest(*parts)


def _finite(arrays: dict[str, np.ndarray]) -> str | None:
    """The name of the first array holding NaN or an infinity, else None."""
    for name, a in arrays.items():
        if a.dtype.kind in "fc" and not np.isfinite(a).all():
            return name
    return None


class _Rejected(Exception):
    """An entry that does not prove itself (the message says why)."""


def _check_directory(data: bytes) -> None:
    """Refuse an entry whose zip directory declares more than
    :data:`MAX_ENTRY_BYTES` uncompressed, or whose ``.npy`` headers declare
    more array bytes than their member holds or object arrays, before any
    array is inflated (a member is only ever inflated up to its declared
    size: zipfile stops there)."""
    with zipfile.ZipFile(io.BytesIO(data)) as zf:
        infos = zf.infolist()
        total = sum(i.file_size for i in infos)
        if total > MAX_ENTRY_BYTES:
            raise _Rejected(f"its members declare {total} bytes uncompressed, more than the {MAX_ENTRY_BYTES} allowed")
        for info in infos:
            with zf.open(info) as fh:
                version = np.lib.format.read_magic(fh)
                if version == (1, 0):
                    shape, _, dtype = np.lib.format.read_array_header_1_0(fh)
                elif version == (2, 0):
                    shape, _, dtype = np.lib.format.read_array_header_2_0(fh)
                else:
                    raise _Rejected(f"{info.filename}: npy format {version} is not one savez writes")
            if dtype.hasobject:
                raise _Rejected(f"{info.filename}: an object array")
            if math.prod(shape) * dtype.itemsize > info.file_size:
                raise _Rejected(f"{info.filename}: its header declares an array larger than the member")


def _read_proven(path: Path, kind: str, key: str) -> dict[str, np.ndarray]:
    """The arrays of the entry at ``path`` once it proved to be ``kind`` /
    ``key``'s (see :func:`load`); _Rejected otherwise, FileNotFoundError when
    it is gone."""
    try:
        size = path.stat().st_size
        if size > 2 * MAX_ENTRY_BYTES:
            raise _Rejected(f"{size} bytes on disk, more than twice the {MAX_ENTRY_BYTES} allowed")
        data = atomic.read_regular(path, size)  # a cap as large as the file: read() allocates the cap at once
    except FileNotFoundError:
        raise
    except OSError as exc:
        raise _Rejected(f"unreadable ({exc})") from exc
    try:
        _check_directory(data)
        with np.load(io.BytesIO(data), allow_pickle=False) as npz:
            arrays = {k: npz[k] for k in npz.files}
        proof = json.loads(array_text(arrays.pop(_PROOF))) if _PROOF in arrays else None
    except _Rejected:
        raise
    except (OSError, ValueError, KeyError, EOFError, MemoryError, RuntimeError, NotImplementedError,
            zipfile.BadZipFile) as exc:  # JSON and Unicode errors included; encrypted or unknown compression
        raise _Rejected(f"not a readable entry ({type(exc).__name__}: {exc})") from exc
    if not isinstance(proof, dict) or proof.get("format") != _PROOF_FORMAT:
        raise _Rejected("it carries no proof of its key and content (an older version's entry, or not this cache's)")
    if proof.get("kind") != kind or proof.get("key") != key:
        raise _Rejected(f"it was stored as {str(proof.get('kind'))[:40]}/{str(proof.get('key'))[:80]}, not as this "
                        "key (copied or moved between keys)")
    if proof.get("sha256") != content_digest(arrays):
        raise _Rejected("its arrays do not match their digest (altered)")
    bad = _finite(arrays)
    if bad is not None:
        raise _Rejected(f"array {bad!r} holds NaN or infinite numbers")
    return arrays


def load(kind: str, key: str) -> dict[str, np.ndarray] | None:
    """The arrays stored under ``kind`` / ``key`` (name -> array), or None
    when there is no entry (or the cache is off) or the entry does not prove
    itself: its zip directory declares more than :data:`MAX_ENTRY_BYTES`
    uncompressed, it cannot be read (truncated, not an npz, a pickle), its
    proof names another kind or key or is missing, its arrays do not match
    its content digest, or it holds NaN or infinite numbers. A rejected
    entry is deleted and named in a :class:`CacheWarning`; the caller
    computes the value again and :func:`store` writes it anew."""
    path = _path(kind, key)
    if path is None or not path.is_file():
        return None
    try:
        return _read_proven(path, kind, key)
    except FileNotFoundError:  # deleted since: a miss
        return None
    except _Rejected as exc:
        warnings.warn(f"asset2sim cache: entry {path} rejected: {exc}; computing it again", CacheWarning, stacklevel=2)
        try:
            path.unlink()
        except OSError:
            pass  # rewritten (replaced) by the caller's store, or never used again
        return None


def store(kind: str, key: str, arrays: dict[str, np.ndarray]) -> None:
    """Store ``arrays`` (name -> array; no object arrays) under ``kind`` /
    ``key`` with their proof (kind, key, :func:`content_digest`), atomically
    (replacing an entry there); nothing when the cache is off or cannot be
    written, or when :func:`load` would reject the entry (NaN or infinite
    numbers, more than :data:`MAX_ENTRY_BYTES`).

    Raises:
        ValueError: an array is named ``__cache__`` (the proof's name).
    """
    if _PROOF in arrays:
        raise ValueError(f"array_cache.store: {_PROOF!r} is reserved for the entry's proof")
    path = _path(kind, key)
    if path is None:
        return
    try:
        arrays = {name: np.asarray(a) for name, a in arrays.items()}
        if _finite(arrays) is not None:
            return
        proof = {"format": _PROOF_FORMAT, "kind": kind, "key": key, "sha256": content_digest(arrays)}
        buf = io.BytesIO()
        np.savez(buf, **arrays, **{_PROOF: text_array(json.dumps(proof))})
        if buf.tell() > MAX_ENTRY_BYTES:
            return
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
