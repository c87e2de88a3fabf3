"""PartNet-Mobility (Xiang et al., "SAPIEN", CVPR 2020): every convention of the dataset's folders,
in one adapter; the rest of the pipeline never opens a dataset side file itself.

An object folder holds ``mobility.urdf`` (:func:`find_urdf`), ``semantics.txt`` (one
``link_name joint_kind semantic_label`` line per link, :func:`read_semantics`), ``meta.json``
(``model_cat``: the category, :func:`read_category`) and possibly GenSim2's reference (Hua et al.,
"GenSim2", CoRL 2024: ``reference_gensim2.json`` / ``.urdf``, :func:`read_reference`). A dataset root
holds one folder per object id and ``manifest.csv`` (:mod:`asset2sim.tasks.ingest.manifest`,
re-exported here).
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
    ROW_ERROR_CODES, ManifestError, ManifestRow, ManifestRowError, is_valid_id, read_manifest, read_manifest_rows)
from asset2sim.urdf import MOVABLE, read_urdf

__all__ = [
    "META_NAME", "MANIFEST_NAME", "REFERENCE_JSON", "REFERENCE_URDF", "ROW_ERROR_CODES", "SEMANTICS_NAME", "URDF_NAMES",
    "GenSim2Reference", "ManifestError", "ManifestRow", "ManifestRowError", "Semantics", "SemanticsLine", "find_urdf",
    "format_semantics", "has_reference", "iter_semantics", "meta_category", "read_category", "is_valid_id", "read_manifest",
    "read_manifest_rows", "read_reference", "read_semantics", "urdf_candidates",
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


def size_normalized(urdf_path: Path | str) -> bool:
    """Whether the URDF follows PartNet-Mobility's convention of models normalized to about unit size (its file
    name is ``mobility.urdf``): their scale says nothing about units (SAPIEN / PartNet-Mobility dataset notes)."""
    return Path(urdf_path).name in URDF_NAMES


def _is_regular(path: Path) -> bool:
    try:
        return stat.S_ISREG(os.stat(path).st_mode)
    except OSError:
        return False


def urdf_candidates(folder: Path) -> list[Path]:
    """The URDF files that may be the object of ``folder``: ``[mobility.urdf]`` when that name exists
    (as anything), else every ``*.urdf`` not named ``reference_*``, sorted. Nothing is opened.

    Raises:
        OSError: the folder cannot be listed.
    """
    folder = Path(folder)
    for name in URDF_NAMES:
        if os.path.lexists(folder / name):
            return [folder / name]
    return sorted(p for p in folder.glob("*.urdf") if not p.name.startswith(REFERENCE_PREFIX))


def find_urdf(asset: Path | str) -> Path:
    """The URDF of an asset: the path itself if it is a file, else the one :func:`urdf_candidates` finds;
    only regular files qualify.

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


class Semantics(NamedTuple):
    """One link's entry of ``semantics.txt`` (a tuple ``(joint_kind, label)``)."""

    joint_kind: str  # hinge, slider, free, heavy, static or junk (as written)
    label: str  # part label, e.g. ``lid``, ``drawer``, ``door`` (may contain spaces)


@dataclass(frozen=True)
class SemanticsLine:
    """One non-blank line of ``semantics.txt`` (``lineno`` 1-based); ``link`` and ``entry`` None when
    it has fewer than three fields."""

    lineno: int
    text: str
    link: str | None
    entry: Semantics | None


def iter_semantics(text: str) -> Iterator[SemanticsLine]:
    """The non-blank lines of ``semantics.txt`` text, parsed as ``link_name joint_kind semantic_label...``
    (the label the rest of the line, whitespace runs joined by one space)."""
    for i, line in enumerate(text.splitlines(), 1):
        parts = line.split()
        if not parts:
            continue
        if len(parts) < 3:
            yield SemanticsLine(i, line, None, None)
        else:
            yield SemanticsLine(i, line, parts[0], Semantics(parts[1], " ".join(parts[2:])))


def read_semantics(folder: Path) -> dict[str, Semantics]:
    """``semantics.txt`` of ``folder`` as link -> :class:`Semantics` ({} when absent; the last line of a link wins).

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
    """``semantics.txt`` text for link -> :class:`Semantics`, one line per link in the given order
    (the inverse of :func:`iter_semantics`).

    Raises:
        ValueError: a link name or joint kind empty or with whitespace, or a label empty or spanning
            lines; the message names the link.
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


def meta_category(meta: Any) -> str | None:
    """``model_cat`` of a parsed ``meta.json``; None when not an object or the field is missing or empty."""
    cat = meta.get("model_cat") if isinstance(meta, dict) else None
    return str(cat) if cat else None


def read_category(folder: Path) -> str | None:
    """``model_cat`` of ``folder/meta.json``; None when absent, unreadable, not JSON or not a regular file."""
    path = Path(folder) / META_NAME
    if not _is_regular(path):
        return None
    try:
        meta = json.loads(path.read_text(encoding="utf-8"))
    except (ValueError, OSError):
        return None
    return meta_category(meta)


@dataclass(frozen=True)
class GenSim2Reference:
    """GenSim2's reference of one object folder: load ``scale``, the task joint's
    ``joint_position_range`` (rad or m), ``reference_gensim2.urdf`` and its movable ``task_joints``
    in file order; None / empty where missing."""

    scale: float | None = None
    joint_position_range: tuple[float, float] | None = None
    urdf: Path | None = None
    task_joints: list[str] = field(default_factory=list)


def has_reference(folder: Path | str) -> bool:
    """Whether ``folder`` holds ``reference_gensim2.json``."""
    return (Path(folder) / REFERENCE_JSON).is_file()


def read_reference(folder: Path | str) -> GenSim2Reference:
    """GenSim2's reference of a PartNet-Mobility folder (all fields empty when it has none).

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
