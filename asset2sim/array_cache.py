"""On-disk cache of computed arrays, keyed by a digest of everything they
were computed from (:func:`digest`), the computing code's source included
(:func:`source_digest`).

Entries are ``<cache>/<kind>/<digest>.npz`` (``savez``, no pickles), written
atomically; the folder is ``$ASSET2SIM_CACHE`` (``off``, ``none`` or ``0``:
no cache), else ``~/.cache/asset2sim``. Each entry carries its kind, key and
:func:`content_digest`; :func:`load` rejects (with a :class:`CacheWarning`,
deleting it) an entry that does not prove itself. :func:`guard` keeps the
cache out of given folders (a refine's input and output).
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
    "MAX_ENTRY_BYTES", "CacheWarning", "array_json", "array_text", "cache_dir", "content_digest", "digest", "finite_json",
    "guard", "kept_out", "load", "reject", "source_digest", "store", "text_array",
]

_OFF = ("off", "none", "0")

#: Largest entry :func:`load` reads and :func:`store` writes: its members'
#: uncompressed bytes as the zip directory declares them (twice that on disk).
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
    """The cache folder, or None when turned off or inside a folder a
    :func:`guard` keeps it out of (a :class:`CacheWarning` once per pair)."""
    root = os.environ.get("ASSET2SIM_CACHE")
    if root is not None and root.strip().lower() in _OFF:
        return None
    path = Path(root) if root else Path.home() / ".cache" / "asset2sim"
    return None if kept_out(path, "asset2sim cache") else path


def kept_out(path: Path | str, what: str) -> bool:
    """True when the cache folder ``path`` lies inside a folder a :func:`guard` keeps caches out of (an input or
    output folder; symlinks resolved; a path that cannot be resolved counts as inside), with a
    :class:`CacheWarning` naming ``what`` once per pair. Every on-disk cache (arrays, model replies) asks this."""
    forbidden = _FORBIDDEN.get()
    if not forbidden:
        return False
    path = Path(path)
    try:
        resolved = path.expanduser().resolve()
    except (OSError, RuntimeError):  # a symlink loop: where it lies is unknown
        resolved = None
    for folder in forbidden:
        if resolved is None or resolved == folder or folder in resolved.parents:
            if (str(path), str(folder)) not in _WARNED:
                _WARNED.add((str(path), str(folder)))
                warnings.warn(f"{what}: the cache folder {path} lies inside {folder} (an input or output "
                              "folder): the on-disk cache is off there", CacheWarning, stacklevel=3)
            return True
    return False


@contextlib.contextmanager
def guard(*roots: Path | str | None) -> Iterator[None]:
    """Within the block the cache is off while it lies inside one of ``roots``
    (None skipped; symlinks resolved), besides those already kept out."""
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
    """Digest of the source files of the named (imported) modules.

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
    name, dtype, shape and bytes (C order)."""
    parts: list[bytes | str] = []
    for name in sorted(arrays):
        a = np.asarray(arrays[name])
        parts += [name, a.dtype.str, repr(a.shape), a.tobytes()]
    return digest(*parts)


def _finite(arrays: dict[str, np.ndarray]) -> str | None:
    """The name of the first array holding NaN or an infinity, else None."""
    return next((name for name, a in arrays.items() if a.dtype.kind in "fc" and not np.isfinite(a).all()), None)


class _Rejected(Exception):
    """An entry that does not prove itself (the message says why)."""


def _check_directory(data: bytes) -> None:
    """Refuse, before inflating anything, an entry declaring more than
    :data:`MAX_ENTRY_BYTES`, object arrays, or arrays larger than their member."""
    with zipfile.ZipFile(io.BytesIO(data)) as zf:
        infos = zf.infolist()
        total = sum(i.file_size for i in infos)
        if total > MAX_ENTRY_BYTES:
            raise _Rejected(f"its members declare {total} bytes uncompressed, more than the {MAX_ENTRY_BYTES} allowed")
        for info in infos:
            with zf.open(info) as fh:
                version = np.lib.format.read_magic(fh)
                read = {(1, 0): np.lib.format.read_array_header_1_0, (2, 0): np.lib.format.read_array_header_2_0}.get(version)
                if read is None:
                    raise _Rejected(f"{info.filename}: npy format {version} is not one savez writes")
                shape, _, dtype = read(fh)
            if dtype.hasobject:
                raise _Rejected(f"{info.filename}: an object array")
            if math.prod(shape) * dtype.itemsize > info.file_size:
                raise _Rejected(f"{info.filename}: its header declares an array larger than the member")


def _read_proven(path: Path, kind: str, key: str) -> dict[str, np.ndarray]:
    """The arrays of the entry at ``path`` once it proved to be ``kind`` /
    ``key``'s; _Rejected otherwise, FileNotFoundError when it is gone."""
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
        proof = array_json(arrays.pop(_PROOF)) if _PROOF in arrays else None
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
    if (bad := _finite(arrays)) is not None:
        raise _Rejected(f"array {bad!r} holds NaN or infinite numbers")
    return arrays


def load(kind: str, key: str) -> dict[str, np.ndarray] | None:
    """The arrays stored under ``kind`` / ``key`` (name -> array), or None
    when there is none, the cache is off, or the entry does not prove itself
    (too large, unreadable, another kind or key, altered arrays, NaN or
    infinite numbers): then it is deleted and named in a :class:`CacheWarning`."""
    path = _path(kind, key)
    if path is None or not path.is_file():
        return None
    try:
        return _read_proven(path, kind, key)
    except FileNotFoundError:  # deleted since: a miss
        return None
    except _Rejected as exc:
        return reject(path, f"asset2sim cache: entry {path} rejected: {exc}; computing it again")


def reject(path: Path, message: str) -> None:
    """Delete the cache entry ``path`` that did not prove itself, with a :class:`CacheWarning` ``message`` (at the
    cache's caller); None, the miss."""
    warnings.warn(message, CacheWarning, stacklevel=3)
    with contextlib.suppress(OSError):  # else rewritten (replaced) by the caller's store, or never used again
        path.unlink()


def store(kind: str, key: str, arrays: dict[str, np.ndarray]) -> None:
    """Store ``arrays`` (name -> array) under ``kind`` / ``key`` with their
    proof, atomically; nothing when the cache is off or cannot be written, or
    when :func:`load` would reject the entry.

    Raises:
        ValueError: an array is named ``__cache__`` (the proof's name).
    """
    if _PROOF in arrays:
        raise ValueError(f"array_cache.store: {_PROOF!r} is reserved for the entry's proof")
    path = _path(kind, key)
    if path is None:
        return
    with contextlib.suppress(OSError, ValueError):  # an optimisation only
        arrays = {name: np.asarray(a) for name, a in arrays.items()}
        if _finite(arrays) is not None:
            return
        proof = {"format": _PROOF_FORMAT, "kind": kind, "key": key, "sha256": content_digest(arrays)}
        buf = io.BytesIO()
        np.savez(buf, **arrays, **{_PROOF: text_array(json.dumps(proof))})
        if buf.tell() <= MAX_ENTRY_BYTES:
            atomic.write_bytes(path, buf.getvalue())


def text_array(text: str) -> np.ndarray:
    """``text`` as a uint8 array (UTF-8), to store beside arrays."""
    return np.frombuffer(text.encode(), dtype=np.uint8)


def array_text(array: np.ndarray) -> str:
    """The text :func:`text_array` stored.

    Raises:
        UnicodeDecodeError: the bytes are not UTF-8.
    """
    return np.asarray(array, dtype=np.uint8).tobytes().decode()


def _no_constant(name: str):
    raise ValueError(f"{name} in a cached JSON member: not a number JSON allows")


def finite_json(text: str | bytes):
    """``json.loads(text)`` refusing ``NaN``, ``Infinity`` and ``-Infinity`` (which Python's ``json`` accepts):
    a cached record carrying them is a miss for its cache.

    Raises:
        ValueError: not JSON, or a non-finite constant.
    """
    return json.loads(text, parse_constant=_no_constant)


def array_json(array: np.ndarray):
    """The JSON value a :func:`text_array` holds, strictly: ``NaN``, ``Infinity`` and ``-Infinity`` (which Python's
    ``json`` accepts) are refused, so an entry whose proof holds but whose JSON carries them is a miss for the
    caller, computed again and stored over it.

    Raises:
        ValueError: not UTF-8, not JSON, or a non-finite constant (``UnicodeDecodeError`` and
            ``json.JSONDecodeError`` are ValueErrors).
    """
    return finite_json(array_text(array))
