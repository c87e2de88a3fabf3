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

A dataset root holds one folder per object id and ``manifest.csv``
(:func:`read_manifest`): columns ``id``, ``prompt`` (required), ``category``,
``task``, ``gensim2_task``, ``reference_scale``, ``reference_joint_range``
(JSON ``[lo, hi]``), ``time_limit_seconds``.
"""

from __future__ import annotations

import csv
import io
import json
import math
import os
import re
import stat
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterator, NamedTuple

from asset2sim.tasks.ingest.errors import AssetError
from asset2sim.urdf import MOVABLE, read_urdf

__all__ = [
    "META_NAME",
    "MANIFEST_NAME",
    "REFERENCE_JSON",
    "REFERENCE_URDF",
    "SEMANTICS_NAME",
    "URDF_NAMES",
    "GenSim2Reference",
    "ManifestError",
    "ManifestRow",
    "Semantics",
    "SemanticsLine",
    "find_urdf",
    "has_reference",
    "iter_semantics",
    "meta_category",
    "read_category",
    "read_manifest",
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


# ------------------------------------------------------------------ manifest.csv


class ManifestError(ValueError):
    """The manifest cannot be used (names the file and the line)."""


@dataclass
class ManifestRow:
    """One row of ``manifest.csv``.

    ``id`` the object folder's name; ``category`` "" when not given;
    ``reference_scale`` dimensionless (> 0) or None; ``reference_joint_range``
    (lo, hi) in file units (rad or m) or None; ``time_limit_seconds`` s (> 0)
    or None; ``folder`` the object folder (``<root>/<id>``).
    """

    id: str
    category: str
    prompt: str
    task: str = ""
    gensim2_task: str = ""
    reference_scale: float | None = None
    reference_joint_range: tuple[float, float] | None = None
    time_limit_seconds: float | None = None
    folder: Path = Path(".")


#: Asset ids name folders and files: letters, digits, ``_.-``, not starting with a dot.
_ID_RE = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.\-]*$")


def _positive(where: str, rec: dict, column: str) -> float | None:
    text = (rec.get(column) or "").strip()
    if not text:
        return None
    try:
        value = float(text)
    except ValueError as exc:
        raise ManifestError(f"{where}: {column} {text!r} is not a number") from exc
    if not (math.isfinite(value) and value > 0):
        raise ManifestError(f"{where}: {column} must be a positive number")
    return value


def _joint_range(where: str, rec: dict) -> tuple[float, float] | None:
    text = (rec.get("reference_joint_range") or "").strip().strip('"')
    if not text:
        return None
    try:
        vals = json.loads(text)
        return (float(vals[0]), float(vals[1]))
    except (ValueError, TypeError, IndexError, KeyError) as exc:
        raise ManifestError(f"{where}: reference_joint_range {text!r} is not [lo, hi] ({exc})") from exc


def read_manifest(path: Path | str, root: Path | str | None = None) -> list[ManifestRow]:
    """Rows of a manifest CSV (UTF-8, a byte-order mark allowed), in file
    order; object folders under ``root`` (default: the manifest's folder).

    Raises:
        FileNotFoundError / OSError: the manifest cannot be read.
        ManifestError: a missing ``id`` or ``prompt`` column; a row without id,
            an unsafe id (letters, digits, ``_.-`` only) or a duplicate one; a
            ``reference_scale`` or ``time_limit_seconds`` that is not a
            positive number; a ``reference_joint_range`` that is not
            ``[lo, hi]``. Messages name the file, line and id.
    """
    path = Path(path)
    base = path.parent if root is None else Path(root)
    text = path.read_text(encoding="utf-8-sig")
    reader = csv.DictReader(io.StringIO(text))
    missing = {"id", "prompt"} - set(reader.fieldnames or [])
    if missing:
        raise ManifestError(f"{path}: missing column(s) {sorted(missing)}")
    rows: list[ManifestRow] = []
    seen: set[str] = set()
    for line, rec in enumerate(reader, start=2):
        rid = (rec.get("id") or "").strip()
        if not rid:
            raise ManifestError(f"{path}:{line}: row without id")
        if not _ID_RE.match(rid):
            raise ManifestError(f"{path}:{line}: invalid asset id {rid!r}")
        if rid in seen:
            raise ManifestError(f"{path}:{line}: duplicate asset id {rid!r}")
        seen.add(rid)
        where = f"{path}:{line} (id {rid})"
        rows.append(
            ManifestRow(
                id=rid,
                category=(rec.get("category") or "").strip(),
                prompt=(rec.get("prompt") or "").strip(),
                task=(rec.get("task") or "").strip(),
                gensim2_task=(rec.get("gensim2_task") or "").strip(),
                reference_scale=_positive(where, rec, "reference_scale"),
                reference_joint_range=_joint_range(where, rec),
                time_limit_seconds=_positive(where, rec, "time_limit_seconds"),
                folder=base / rid,
            )
        )
    return rows
