"""PartNet-Mobility: every convention of the dataset's folders, in one adapter.

The rest of the pipeline sees only what this module returns (typed rows and
records); it never opens a dataset side file itself. A PartNet-Mobility object
folder (Xiang et al., "SAPIEN: A SimulAted Part-based Interactive
ENvironment", CVPR 2020) holds:

``mobility.urdf``
    the articulated object (:func:`find_urdf`; a folder without it may hold
    one other ``*.urdf``, files named ``reference_*`` never count).
``semantics.txt``
    one ``link_name joint_kind semantic_label`` line per link
    (:func:`read_semantics`, :func:`iter_semantics`); joint kinds hinge,
    slider, free, heavy, static, junk.
``meta.json``
    annotation metadata; ``model_cat`` is the object category
    (:func:`read_category`).
``reference_gensim2.json`` / ``reference_gensim2.urdf``
    GenSim2's hand-curated copy (Hua et al., "GenSim2", CoRL 2024): the
    ``scale`` it loads the object at, the task joint's
    ``joint_position_range`` and a URDF whose only movable joints are the
    task's (:func:`read_reference`).

A dataset root holds one folder per object id and ``manifest.csv``, read by
:mod:`asset2sim.tasks.ingest.manifest` (re-exported here:
:func:`read_manifest_rows`; :func:`read_manifest` all or nothing).
"""

from __future__ import annotations

import json
import os
import stat
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterator, NamedTuple

from asset2sim.tasks.ingest.errors import AssetError
from asset2sim.tasks.ingest.manifest import (  # manifest.csv, re-exported: this module is the dataset's one adapter
    FILE_ERROR_CODES,
    ROW_ERROR_CODES,
    ManifestError,
    ManifestReading,
    ManifestRow,
    ManifestRowError,
    is_valid_id,
    read_manifest,
    read_manifest_rows,
)
from asset2sim.urdf import MOVABLE, read_urdf

__all__ = [
    "FILE_ERROR_CODES",
    "META_NAME",
    "MANIFEST_NAME",
    "REFERENCE_JSON",
    "REFERENCE_URDF",
    "ROW_ERROR_CODES",
    "SEMANTICS_NAME",
    "URDF_NAMES",
    "GenSim2Reference",
    "ManifestError",
    "ManifestReading",
    "ManifestRow",
    "ManifestRowError",
    "Semantics",
    "SemanticsLine",
    "find_urdf",
    "format_semantics",
    "has_reference",
    "iter_semantics",
    "meta_category",
    "read_category",
    "is_valid_id",
    "read_manifest",
    "read_manifest_rows",
    "read_reference",
    "read_semantics",
    "urdf_candidates",
]

#: URDF names looked up first in an object folder, in order.
URDF_NAMES = ("mobility.urdf",)
#: Prefix of files that are never the object's URDF (GenSim2's references).
REFERENCE_PREFIX = "reference_"
SEMANTICS_NAME = "semantics.txt"
META_NAME = "meta.json"
REFERENCE_JSON = "reference_gensim2.json"
REFERENCE_URDF = "reference_gensim2.urdf"
MANIFEST_NAME = "manifest.csv"


def _is_regular(path: Path) -> bool:
    try:
        return stat.S_ISREG(os.stat(path).st_mode)
    except OSError:
        return False


# ------------------------------------------------------------------ the URDF


def urdf_candidates(folder: Path) -> list[Path]:
    """The URDF files that may be the object of ``folder``: ``[mobility.urdf]``
    when that name exists (as anything, even a broken link), else every
    ``*.urdf`` not named ``reference_*``, sorted. Nothing is opened.

    Raises:
        OSError: the folder cannot be listed.
    """
    folder = Path(folder)
    for name in URDF_NAMES:
        if os.path.lexists(folder / name):
            return [folder / name]
    return sorted(p for p in folder.glob("*.urdf") if not p.name.startswith(REFERENCE_PREFIX))


def find_urdf(asset: Path | str) -> Path:
    """The URDF of an asset: the path itself if it is a file, else
    ``mobility.urdf`` in the folder, else the only ``*.urdf`` there (files
    named ``reference_*`` excluded). Only regular files qualify (a FIFO named
    ``mobility.urdf`` is never opened).

    Raises:
        AssetError: no (or several candidate) URDF files, or not a regular file.
    """
    asset = Path(asset)
    if asset.is_dir():
        cands = urdf_candidates(asset)
        if len(cands) == 1:
            if not _is_regular(cands[0]):
                raise AssetError(f"{cands[0]}: not a regular file")
            return cands[0]
        if not cands:
            raise AssetError(f"{asset}: no mobility.urdf or other *.urdf file")
        raise AssetError(f"{asset}: several URDF files ({', '.join(p.name for p in cands)}); pass one")
    if not os.path.lexists(asset):
        raise AssetError(f"{asset}: no such file or folder")
    if not _is_regular(asset):
        raise AssetError(f"{asset}: not a regular file")
    return asset


# ------------------------------------------------------------------ semantics.txt


class Semantics(NamedTuple):
    """One link's entry of ``semantics.txt`` (a tuple ``(joint_kind, label)``)."""

    joint_kind: str
    """hinge, slider, free, heavy, static or junk (as written)."""
    label: str
    """Part label, e.g. ``lid``, ``drawer``, ``door`` (may contain spaces)."""


@dataclass(frozen=True)
class SemanticsLine:
    """One non-blank line of ``semantics.txt``: ``lineno`` 1-based, ``text``
    as written; ``link`` and ``entry`` are None when the line is malformed
    (fewer than three fields)."""

    lineno: int
    text: str
    link: str | None
    entry: Semantics | None


def iter_semantics(text: str) -> Iterator[SemanticsLine]:
    """The non-blank lines of ``semantics.txt`` text, in order, parsed as
    ``link_name joint_kind semantic_label...`` (the label is the rest of the
    line, whitespace runs joined by one space)."""
    for i, line in enumerate(text.splitlines(), 1):
        parts = line.split()
        if not parts:
            continue
        if len(parts) < 3:
            yield SemanticsLine(i, line, None, None)
        else:
            yield SemanticsLine(i, line, parts[0], Semantics(parts[1], " ".join(parts[2:])))


def read_semantics(folder: Path) -> dict[str, Semantics]:
    """``semantics.txt`` of ``folder`` as link -> :class:`Semantics`
    ``(joint_kind, label)``; {} when absent. A link named twice keeps its
    last line.

    Raises:
        AssetError: a line that is not ``link joint_kind label``, or
            ``semantics.txt`` is not a regular file.
    """
    path = Path(folder) / SEMANTICS_NAME
    if not os.path.lexists(path):
        return {}
    if not _is_regular(path):
        raise AssetError(f"{path}: not a regular file")
    out: dict[str, Semantics] = {}
    for ln in iter_semantics(path.read_text(encoding="utf-8", errors="replace")):
        if ln.entry is None:
            raise AssetError(f"{path}:{ln.lineno}: expected 'link_name joint_kind semantic_label', got {ln.text!r}")
        out[ln.link] = ln.entry  # type: ignore[index]
    return out


def format_semantics(entries: dict[str, Semantics]) -> str:
    """``semantics.txt`` text for link -> :class:`Semantics`, one
    ``link_name joint_kind semantic_label`` line per link in the given order
    (the writer of :func:`iter_semantics`: ``iter_semantics(format_semantics(e))``
    gives ``e`` back).

    Raises:
        ValueError: a link name or joint kind that is empty or contains
            whitespace, or a label that is empty or spans lines (the format
            cannot express them); the message names the link.
    """
    lines = []
    for link, (kind, label) in entries.items():
        if not link or len(link.split()) != 1 or link.split()[0] != link:
            raise ValueError(f"semantics.txt: link name {link!r} is empty or contains whitespace")
        if not kind or len(kind.split()) != 1 or kind.split()[0] != kind:
            raise ValueError(f"semantics.txt: link {link!r}: joint kind {kind!r} is empty or contains whitespace")
        words = str(label).split()
        if not words or len(str(label).splitlines()) > 1:
            raise ValueError(f"semantics.txt: link {link!r}: label {label!r} is empty or spans lines")
        lines.append(f"{link} {kind} {' '.join(words)}\n")
    return "".join(lines)


# ------------------------------------------------------------------ meta.json


def meta_category(meta: Any) -> str | None:
    """``model_cat`` of a parsed ``meta.json`` (None when ``meta`` is not an
    object or the field is missing or empty)."""
    cat = meta.get("model_cat") if isinstance(meta, dict) else None
    return str(cat) if cat else None


def read_category(folder: Path) -> str | None:
    """``model_cat`` of ``folder/meta.json``; None when absent, unreadable,
    not JSON or not a regular file."""
    path = Path(folder) / META_NAME
    if not _is_regular(path):
        return None
    try:
        meta = json.loads(path.read_text(encoding="utf-8"))
    except (ValueError, OSError):
        return None
    return meta_category(meta)


# ------------------------------------------------------------------ GenSim2 reference


@dataclass(frozen=True)
class GenSim2Reference:
    """GenSim2's reference of one object folder.

    ``scale``: dimensionless load scale (None when ``reference_gensim2.json``
    is missing or has none); ``joint_position_range``: (lo, hi) of the task
    joint in file units (rad or m), or None; ``urdf``: path of
    ``reference_gensim2.urdf`` or None; ``task_joints``: its movable
    (revolute, continuous, prismatic) joints, in file order.
    """

    scale: float | None = None
    joint_position_range: tuple[float, float] | None = None
    urdf: Path | None = None
    task_joints: list[str] = field(default_factory=list)


def has_reference(folder: Path | str) -> bool:
    """Whether ``folder`` holds ``reference_gensim2.json``."""
    return (Path(folder) / REFERENCE_JSON).is_file()


def read_reference(folder: Path | str) -> GenSim2Reference:
    """GenSim2's reference of a PartNet-Mobility folder (all fields empty
    when the folder has none).

    Raises:
        ValueError: ``reference_gensim2.json`` is not JSON, or a range value
            is not a number.
        asset2sim.urdf.UrdfError: ``reference_gensim2.urdf`` cannot be parsed.
    """
    folder = Path(folder)
    scale = rng = None
    js = folder / REFERENCE_JSON
    if js.is_file():
        data = json.loads(js.read_text(encoding="utf-8"))
        if isinstance(data.get("scale"), (int, float)):
            scale = float(data["scale"])
        r = data.get("joint_position_range")
        if isinstance(r, list) and len(r) == 2:
            rng = (float(r[0]), float(r[1]))
    ru = folder / REFERENCE_URDF
    if not ru.is_file():
        return GenSim2Reference(scale=scale, joint_position_range=rng)
    types: dict[str, str] = {}
    for j in read_urdf(ru, mode="lenient").joints:
        types[j.name] = j.type  # a name written twice keeps its first place and last type
    task = [n for n, t in types.items() if t in MOVABLE]
    return GenSim2Reference(scale=scale, joint_position_range=rng, urdf=ru, task_joints=task)
