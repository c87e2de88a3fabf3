"""A pair set on disk: the folder holding ``pairs.json``
(:class:`~asset2sim.schemas.realism.PairSet`) and the clips it names. One
reader for every user of it (the rating app, the model judge, the scores) and
one writer (:mod:`asset2sim.apps.realism.pairs`).
"""

from __future__ import annotations

import stat
from pathlib import Path
from typing import Sequence

from asset2sim import atomic
from asset2sim.schemas.realism import ClipPair, PairSet

#: The pair set's file, and the folder of a run or benchmark output that holds a pair set.
PAIRS_JSON = "pairs.json"
REALISM_DIR = "realism"
#: Largest ``pairs.json`` read, bytes.
MAX_PAIRS_BYTES = 64 << 20


class PairSetError(ValueError):
    """A pair set that cannot be used: ``pairs.json`` missing or invalid, or a file it names missing or outside its
    folder; ``path`` the file at fault."""

    def __init__(self, path: Path | str, message: str):
        super().__init__(f"{path}: {message}")
        self.path = str(path)


def find_pair_set(folder: Path | str) -> Path:
    """The folder holding ``pairs.json``: ``folder`` itself or ``folder/realism`` (a benchmark or run output).

    Raises:
        PairSetError: neither holds a ``pairs.json``.
    """
    folder = Path(folder)
    for cand in (folder, folder / REALISM_DIR):
        if (cand / PAIRS_JSON).is_file():
            return cand
    raise PairSetError(folder, f"no {PAIRS_JSON} here or in {REALISM_DIR}/ (make the pair set first: asset2sim pairs)")


def read_pair_set(folder: Path | str) -> PairSet:
    """``folder/pairs.json`` as a :class:`PairSet` whose pair ids are distinct.

    Raises:
        FileNotFoundError: no ``pairs.json`` in ``folder`` (the error names the file).
        PairSetError: unreadable, not UTF-8 JSON, not a valid pair set, or a repeated pair id.
    """
    path = Path(folder) / PAIRS_JSON
    if not path.is_file():
        raise FileNotFoundError(2, "no pair set (pairs.json) here", str(path))
    try:
        data = atomic.read_regular(path, MAX_PAIRS_BYTES)
    except OSError as exc:
        raise PairSetError(path, f"cannot be read ({exc.strerror or exc})") from None
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise PairSetError(path, f"not UTF-8 JSON: {exc}") from None
    try:
        ps = PairSet.model_validate_json(text)
    except ValueError as exc:
        errors = getattr(exc, "errors", None)
        if callable(errors) and errors() and errors()[0].get("type") == "json_invalid":
            raise PairSetError(path, f"not UTF-8 JSON: {errors()[0]['msg']}") from None
        lines = [f"{'.'.join(map(str, e['loc']))}: {e['msg']}" for e in errors()[:5]] if callable(errors) else [str(exc)]
        raise PairSetError(path, "not a valid pair set: " + "; ".join(lines)) from None
    seen: set[str] = set()
    for p in ps.pairs:
        if p.pair_id in seen:
            raise PairSetError(path, f"pair_id {p.pair_id!r} appears more than once")
        seen.add(p.pair_id)
    return ps


def media_path(folder: Path | str, relative: str) -> Path:
    """The file a path of ``pairs.json`` names (relative to ``folder``, ``/``-separated), resolved.

    Raises:
        PairSetError: absolute, leaving ``folder`` (``..`` or a symlink), or not an existing regular file.
    """
    root = Path(folder).resolve()
    if not relative or relative.startswith("/") or "\\" in relative or "\0" in relative:
        raise PairSetError(root / PAIRS_JSON, f"clip path {relative!r} must be relative, with '/'")
    path = (root / relative).resolve()
    if path == root or root not in path.parents:
        raise PairSetError(root / PAIRS_JSON, f"clip path {relative!r} leaves the folder {root}")
    try:
        mode = path.stat().st_mode
    except OSError:
        raise PairSetError(path, f"missing (named by {root / PAIRS_JSON})") from None
    if not stat.S_ISREG(mode):
        raise PairSetError(path, f"not a regular file (named by {root / PAIRS_JSON})")
    return path


def write_pair_set(folder: Path | str, pairs: Sequence[ClipPair], skipped: dict[str, str] | None = None) -> PairSet:
    """Write ``folder/pairs.json`` (atomically) listing ``pairs``; returns the :class:`PairSet`."""
    ps = PairSet(pairs=list(pairs), skipped=dict(skipped or {}))
    atomic.write_json(Path(folder) / PAIRS_JSON, ps.model_dump(mode="json"))
    return ps
