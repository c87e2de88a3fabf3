"""Safe resolution of the paths an asset names (``stat`` only: a FIFO cannot block); what they name is read by
:func:`asset2sim.atomic.read_regular` (re-exported), which never blocks on a file swapped for a FIFO.
"""

from __future__ import annotations

import os
import re
import stat
from dataclasses import dataclass
from pathlib import Path
from typing import Iterable

from asset2sim.atomic import read_regular
from asset2sim.input_files import file_kind as _kind, inside
from asset2sim.tasks.ingest.findings import MESH_EXTENSIONS

__all__ = ["MeshReference", "file_kind", "inside", "read_regular", "resolve_mesh_reference"]


@dataclass(frozen=True)
class MeshReference:
    """Outcome of resolving one ``<mesh filename=...>``: ``path`` the real path when acceptable, else
    None and ``code``/``message`` say why; ``size`` bytes when known."""

    filename: str
    path: Path | None
    code: str | None = None
    message: str = ""
    size: int | None = None


_URI = re.compile(r"^[A-Za-z][A-Za-z0-9+.\-]*://")
_SCHEME = re.compile(r"^[A-Za-z][A-Za-z0-9+.\-]{1,}:")  # 'data:', 'mailto:' (not 'C:')
_DRIVE = re.compile(r"^[A-Za-z]:[\\/]")


def file_kind(filename: str, base: Path | str) -> str | None:
    """``"FIFO"``, ``"character device"``, ... when ``filename`` (absolute, or relative to ``base``) names
    a special file, symlinks followed; None for a regular file, a directory, a missing path, a URI or
    a string with NUL (``os.stat`` only)."""
    if not filename or "\x00" in filename or _URI.match(filename):
        return None
    try:
        st = os.stat(os.path.join(str(base), filename))
    except (OSError, ValueError):
        return None
    if stat.S_ISREG(st.st_mode) or stat.S_ISDIR(st.st_mode):
        return None
    return _kind(st.st_mode)


def resolve_mesh_reference(folder: Path | str, filename: str | None, *, base: Path | str | None = None,
                           extensions: Iterable[str] = MESH_EXTENSIONS, max_bytes: int | None = None) -> MeshReference:
    """Resolve a mesh path written in a URDF (or an OBJ's ``mtllib``) safely, ``os.stat`` only.

    Checks, in order (the first failure is returned): present; no NUL or control character; not a
    URI; not absolute; inside ``folder`` lexically and with symlinks resolved; exists; a regular file;
    opens as written (``dir/../x`` needs ``dir``); suffix in ``extensions``; size <= ``max_bytes``.

    Args:
        folder: the asset folder. filename: the string as written.
        base: folder the path is relative to (default ``folder``; the OBJ's folder for ``mtllib``).
        extensions: accepted suffixes, lower case with the dot; empty: any.
        max_bytes: size cap in bytes (None: none).

    Returns a :class:`MeshReference` (never raises for bad input).
    """
    fname = filename if filename is not None else ""

    def refused(code: str, message: str, size: int | None = None) -> MeshReference:
        return MeshReference(fname, None, code, message, size)

    if not fname.strip():
        return refused("MESH_FILENAME_EMPTY", "<mesh> has no filename")
    if "\x00" in fname:
        return refused("MESH_PATH_NUL", "the path contains a NUL byte")
    if any(ord(ch) < 32 or ord(ch) == 127 for ch in fname):
        return refused("MESH_PATH_CONTROL_CHAR", "the path contains a control character")
    if _URI.match(fname) or (_SCHEME.match(fname) and not _DRIVE.match(fname)):
        return refused("MESH_URI_FORBIDDEN", f"URI {fname!r}: only relative paths inside the asset folder are accepted")
    if fname.startswith(("/", "\\")) or _DRIVE.match(fname):
        return refused("MESH_PATH_ABSOLUTE", f"absolute path {fname!r}: only relative paths inside the asset folder are accepted")
    root_abs = os.path.abspath(str(folder))
    base_abs = os.path.abspath(str(base)) if base is not None else root_abs
    written = os.path.join(base_abs, fname)
    lexical = os.path.normpath(written)
    if not inside(lexical, root_abs):
        return refused("MESH_PATH_ESCAPES", f"{fname!r} resolves to {lexical}, outside the asset folder")
    real = os.path.realpath(written)
    if not inside(real, os.path.realpath(root_abs)):
        return refused("MESH_SYMLINK_ESCAPES", f"{fname!r} is a symlink (or under one) to {real}, outside the asset folder")
    try:
        st = os.stat(real)
    except FileNotFoundError:
        return refused("MESH_NOT_FOUND", f"{fname!r} does not exist")
    except NotADirectoryError:
        return refused("MESH_NOT_FOUND", f"{fname!r} does not exist (a parent is a file)")
    except OSError as exc:
        return refused("MESH_UNREADABLE", f"{fname!r}: {exc.strerror or exc}")
    if stat.S_ISDIR(st.st_mode):
        return refused("MESH_IS_DIRECTORY", f"{fname!r} is a directory")
    if not stat.S_ISREG(st.st_mode):
        return refused("MESH_NOT_REGULAR_FILE", f"{fname!r} is a {_kind(st.st_mode)}, not a regular file")
    try:  # the path as written, as the operating system (PyBullet, a user's simulator) opens it
        os.stat(written)
    except OSError:
        return refused("MESH_NOT_FOUND",
                       f"{fname!r} cannot be opened as written: a folder it walks through ('dir/../') does not exist "
                       "(only the normalized path does)")
    exts = frozenset(e.lower() for e in extensions)
    if exts:
        for name in (fname, real):
            if os.path.splitext(name)[1].lower() not in exts:
                return refused("MESH_EXTENSION_UNSUPPORTED",
                               f"{os.path.basename(name)!r} does not end in a mesh extension ({', '.join(sorted(exts))})")
    if max_bytes is not None and st.st_size > max_bytes:
        return refused("MESH_TOO_LARGE", f"{fname!r} has {st.st_size} bytes > cap {max_bytes}", st.st_size)
    return MeshReference(fname, Path(real), None, "", st.st_size)

