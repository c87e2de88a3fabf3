"""Names from an input turned into file names: the one place where that happens.

A link name of a URDF (or any other name an input declares) is data: it may
hold ``/``, ``..``, control characters, a NUL, non-ASCII text or thousands of
characters. Every file asset2sim names after an input's name (collision
pieces of a link, derived meshes of an export) takes its stem from
:func:`file_stem`, and every such path is joined through :func:`join_inside`,
which refuses any result outside its folder.

The mapping:

- a *clean* name (ASCII letters, digits, ``_``, ``-`` and ``.``; starting with
  a letter, digit or ``_``; at most :data:`MAX_CLEAN` characters) is its own
  stem, so PartNet-Mobility's ``link_0`` gives ``link_0``;
- any other name gives ``<sanitised prefix>-<first 10 hex of its SHA-256>``:
  the prefix keeps the name recognisable, the digest keeps two different
  names apart (``a/b`` and ``a_b`` no longer share files).

Two names of one asset whose stems coincide (only a crafted asset can do
that) are refused at validation (``LINK_FILE_NAMES_CLASH``,
:mod:`asset2sim.tasks.ingest.tree_checks`), which also reports every link
whose files are named differently from it (``LINK_NAME_NOT_A_FILE_NAME``).
"""

from __future__ import annotations

import hashlib
import os
import re
from pathlib import Path, PurePosixPath
from typing import Iterable

__all__ = ["MAX_CLEAN", "UnsafePath", "clashes", "file_stem", "is_clean", "join_inside"]

#: Longest name used as a stem unchanged (characters). Stems are joined with
#: suffixes (``_hull12_<12 hex>.obj``); 64 keeps every file name far below the
#: 255-byte limit of ext4, APFS and NTFS.
MAX_CLEAN = 64
_CLEAN = re.compile(rf"[A-Za-z0-9_][A-Za-z0-9_.\-]{{0,{MAX_CLEAN - 1}}}")
_UNSAFE_CHARS = re.compile(r"[^A-Za-z0-9_\-]+")
_PREFIX = 32


class UnsafePath(ValueError):
    """A path built for the output would lie outside its folder; ``path`` is it."""

    def __init__(self, message: str, path: str):
        super().__init__(message)
        self.path = path


def is_clean(name: str) -> bool:
    """True when ``name`` is used as a file-name stem unchanged (see the module docstring)."""
    return isinstance(name, str) and _CLEAN.fullmatch(name) is not None and ".." not in name


def file_stem(name: str) -> str:
    """The file-name stem for ``name`` (a link or other input name).

    Args:
        name: any string an input declares.

    Returns:
        ``name`` itself when :func:`is_clean`; else the name with every run of
        characters other than ASCII letters, digits, ``_`` and ``-`` made one
        ``_`` (at most 32 characters kept), ``-`` and the first 10 hex digits
        of the SHA-256 of its UTF-8 bytes (surrogates escaped). Never empty,
        never holds a path separator or ``..``.
    """
    if is_clean(name):
        return name
    raw = str(name).encode("utf-8", "surrogatepass")
    prefix = _UNSAFE_CHARS.sub("_", str(name)).strip("_")[:_PREFIX] or "name"
    return f"{prefix}-{hashlib.sha256(raw).hexdigest()[:10]}"


def clashes(names: Iterable[str]) -> dict[str, list[str]]:
    """Stems that two or more of ``names`` share: stem -> those names (input
    order). Empty for every real asset; a crafted one can reach it."""
    by_stem: dict[str, list[str]] = {}
    for n in names:
        by_stem.setdefault(file_stem(n), []).append(n)
    return {s: ns for s, ns in by_stem.items() if len(ns) > 1}


def join_inside(folder: Path | str, rel: str) -> Path:
    """``folder / rel``, refused unless it lies inside ``folder`` (lexically:
    no absolute part, no ``..``; and after resolving the symlinks that exist).

    Args:
        folder: the folder the file belongs in (e.g. the output folder).
        rel: a relative POSIX path built by the product (``collision/x.obj``).

    Returns:
        The joined path (not resolved).

    Raises:
        UnsafePath: ``rel`` is absolute, empty, holds ``..`` or a NUL, or the
            joined path resolves outside ``folder``.
    """
    p = PurePosixPath(rel)
    if not rel or "\x00" in rel or p.is_absolute() or ".." in p.parts or "\\" in rel:
        raise UnsafePath(f"{rel!r} is not a relative path inside {folder}", rel)
    root = Path(folder)
    target = root / p
    real_root = Path(os.path.realpath(root))
    real = Path(os.path.realpath(target))
    if real != real_root and real_root not in real.parents:
        raise UnsafePath(f"{target} resolves to {real}, outside {real_root}", rel)
    return target
