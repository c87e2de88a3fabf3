"""Names from an input turned into file names: the one place where that happens.

An input's names are data (``/``, ``..``, NUL, any length): every file named
after one takes its stem from :func:`file_stem` (a clean name is its own stem,
any other ``<sanitised prefix>-<10 hex of its SHA-256>``) and is joined
through :func:`join_inside`, which refuses any path outside its folder.
"""

from __future__ import annotations

import hashlib
import os
import re
from pathlib import Path, PurePosixPath
from typing import Iterable

from asset2sim.output_paths import OutputError

__all__ = ["MAX_CLEAN", "UnsafePath", "clashes", "file_stem", "is_clean", "join_inside"]

#: Longest name used as a stem unchanged (characters; far below the 255-byte file-name limit with suffixes).
MAX_CLEAN = 64
_CLEAN = re.compile(rf"[A-Za-z0-9_][A-Za-z0-9_.\-]{{0,{MAX_CLEAN - 1}}}")
_UNSAFE_CHARS = re.compile(r"[^A-Za-z0-9_\-]+")
_PREFIX = 32


class UnsafePath(OutputError):
    """A path built for the output would lie outside its folder; ``path`` is it (as given, relative). An
    :class:`~asset2sim.output_paths.OutputError` with code ``OUTPUT_PATH_ESCAPES`` (absolute, ``..``, NUL) or
    ``OUTPUT_SYMLINK_ESCAPES`` (a symlink on the way leads out), so every writer reports it as the output guard's
    refusal."""

    def __init__(self, message: str, path: str, code: str = "OUTPUT_PATH_ESCAPES"):
        super().__init__(message, code, path)
        self.path = path


def is_clean(name: str) -> bool:
    """True when ``name`` is its own stem: ASCII letters, digits, ``_``, ``-``
    and ``.``, starting with one of the first three, at most :data:`MAX_CLEAN` characters."""
    return isinstance(name, str) and _CLEAN.fullmatch(name) is not None and ".." not in name


def file_stem(name: str) -> str:
    """The file-name stem for ``name``: itself when :func:`is_clean`; else
    the name with every run of other characters than ASCII letters, digits,
    ``_`` and ``-`` made one ``_`` (32 characters kept), ``-`` and the first 10
    hex digits of the SHA-256 of its UTF-8 bytes."""
    if is_clean(name):
        return name
    raw = str(name).encode("utf-8", "surrogatepass")
    prefix = _UNSAFE_CHARS.sub("_", str(name)).strip("_")[:_PREFIX] or "name"
    return f"{prefix}-{hashlib.sha256(raw).hexdigest()[:10]}"


def clashes(names: Iterable[str]) -> dict[str, list[str]]:
    """Stems that two or more of ``names`` share: stem -> those names (input order)."""
    by_stem: dict[str, list[str]] = {}
    for n in names:
        by_stem.setdefault(file_stem(n), []).append(n)
    return {s: ns for s, ns in by_stem.items() if len(ns) > 1}


def join_inside(folder: Path | str, rel: str) -> Path:
    """``folder / rel`` (not resolved), refused unless it lies inside
    ``folder`` lexically and after resolving existing symlinks.

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
        raise UnsafePath(f"{target} resolves to {real}, outside {real_root}", rel, "OUTPUT_SYMLINK_ESCAPES")
    return target
