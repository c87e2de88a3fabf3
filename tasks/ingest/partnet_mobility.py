"""PartNet-Mobility (Xiang et al., "SAPIEN", CVPR 2020): every convention of the dataset's folders,
in one adapter; the rest of the pipeline never opens a dataset side file itself.

An object folder holds ``mobility.urdf`` (:func:`find_urdf`), ``semantics.txt`` (one
``link_name joint_kind semantic_label`` line per link, :func:`read_semantics`), ``meta.json``
(``model_cat``: the category, :func:`read_category`) and possibly GenSim2's reference (Hua et al.,
"GenSim2", CoRL 2024: ``reference_gensim2.json`` / ``.urdf``, :func:`read_reference`, written as an asset
folder at its scale by :func:`write_reference`). A dataset root holds one folder per object id and
``manifest.csv`` (:mod:`asset2sim.tasks.ingest.manifest`, re-exported here).
"""

from __future__ import annotations

import json
import math
import os
import stat
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterable, Iterator, NamedTuple

from asset2sim.tasks.ingest.errors import AssetError
from asset2sim.tasks.ingest.manifest import (  # manifest.csv, re-exported: this module is the dataset's one adapter
    ROW_ERROR_CODES, ManifestError, ManifestRow, ManifestRowError, is_valid_id, read_manifest, read_manifest_rows)
from asset2sim import mesh_io
from asset2sim.atomic import copy_file, sha256_file, write_bytes, write_json
from asset2sim.output_folder import STATE_NAME, URDF_NAME
from asset2sim.urdf import MOVABLE, UrdfLimit, read_urdf, scale_model, write_urdf

__all__ = [
    "META_NAME", "MANIFEST_NAME", "REFERENCE_JSON", "REFERENCE_URDF", "ROW_ERROR_CODES", "SEMANTICS_NAME", "URDF_NAMES",
    "GenSim2Reference", "ManifestError", "ManifestRow", "ManifestRowError", "Semantics", "SemanticsLine", "WrittenReference",
    "find_urdf", "format_semantics", "has_reference", "iter_semantics", "meta_category", "read_category", "is_valid_id",
    "read_manifest", "read_manifest_rows", "read_reference", "read_semantics", "reference_initial_state", "scale_urdf",
    "urdf_candidates", "urdf_joints", "write_reference",
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
        if not cands:
            raise AssetError(f"{asset}: no mobility.urdf or other *.urdf file")
        if len(cands) > 1:
            raise AssetError(f"{asset}: several URDF files ({', '.join(p.name for p in cands)}); pass one")
        asset = cands[0]
    elif not os.path.lexists(asset):
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


#: ``semantics.txt`` joint kinds of a part that is the object itself or does not move in use, never a handled part
#: (SPEC, "Part functions"): ``free`` is the object's own body (a toaster's shell, a bucket's body, a laptop's base;
#: PartNet-Mobility and GenSim2 ship some on a slider to an empty root link), ``static`` and ``heavy`` parts stay put.
BODY_KINDS = frozenset({"free", "static", "heavy"})


def held_bodies(joints: Iterable[Any], kinds: dict[str, str | None]) -> dict[str, str]:
    """joint -> why, for every movable joint (revolute, continuous, prismatic) whose child link's ``semantics.txt`` kind
    (``kinds``: link -> kind or None) is in :data:`BODY_KINDS`: the asset's own annotation says the part does not move
    as a mechanism, so the asset model holds it where it was modelled (the joint at 0, a fixed joint), as the body does.
    ``joints``: objects with ``name``, ``type`` and ``child``."""
    out = {}
    for j in joints:
        kind = kinds.get(j.child)
        if j.type in ("revolute", "continuous", "prismatic") and kind in BODY_KINDS:
            what = "the object's own body" if kind == "free" else "a part that does not move in use"
            out[j.name] = (f"joint {j.name} ({j.type}) moves link {j.child}, of kind '{kind}' in semantics.txt: {what}, held "
                           "where it was modelled as the body holds its pose (written as a fixed joint; never handled, "
                           "probed or set by a request)")
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
        if not link or link.split() != [link]:
            raise ValueError(f"semantics.txt: link name {link!r} is empty or contains whitespace")
        if not kind or kind.split() != [kind]:
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
    types = {j.name: j.type for j in read_urdf(ru, mode="lenient").joints}  # a name written twice: first place, last type
    return GenSim2Reference(scale=scale, joint_position_range=rng, urdf=ru,
                            task_joints=[n for n, t in types.items() if t in MOVABLE])


def scale_urdf(src: Path | str, dst: Path | str, scale: float, *, joint_limits: dict[str, tuple[float, float]] | None = None,
               header: str = "") -> Path:
    """Write a copy of URDF ``src`` with the uniform scale ``scale`` (> 0) baked in
    (:func:`asset2sim.urdf.scale_model`: mesh scales, primitive sizes, origins,
    prismatic limits, inertia x s^2, masses kept) to ``dst``; returns ``dst``.

    ``joint_limits``: joint -> (lower, upper), input units, replacing the file's;
    ``header``: a comment atop ``<robot>``. The meshes inside ``src``'s folder are copied beside ``dst``
    (relative paths, with the MTL libraries and textures an OBJ names inside that folder), others
    referenced by absolute path.
    Raises ValueError: bad scale, ``package://`` mesh paths, an unknown joint; UrdfError: ``src`` unreadable."""
    if not (math.isfinite(scale) and scale > 0):
        raise ValueError(f"scale must be a finite number > 0, got {scale}")
    src = Path(src).resolve()
    model = read_urdf(src, mode="lenient")
    to_copy: set[Path] = set()
    for link in model.links.values():
        for g in link.visuals + link.collisions:
            if g.kind != "mesh":
                continue
            fname = g.filename or ""
            if fname.startswith("package://"):
                raise ValueError(f"{src}: link {link.name!r}: package:// mesh paths are not supported")
            mesh_src = (src.parent / fname.removeprefix("file://")).resolve()
            if mesh_src.is_relative_to(src.parent):
                to_copy.add(mesh_src)
                g.filename = mesh_src.relative_to(src.parent).as_posix()
            else:
                g.filename = str(mesh_src)
    dst_dir = Path(dst).parent
    for mesh_src in sorted(to_copy):
        deps = mesh_io.obj_material_files(mesh_src, keep=lambda p: p.resolve().is_relative_to(src.parent))
        for f in [mesh_src] + deps:
            out = dst_dir / f.relative_to(src.parent)
            if not (out.is_file() and sha256_file(out) == sha256_file(f)):
                copy_file(f, out)
    names = {j.name: j for j in model.joints}
    missing = set(joint_limits or {}) - set(names)
    if missing:
        raise ValueError(f"{src}: joints {sorted(missing)} not found")
    for name, (lo, hi) in (joint_limits or {}).items():
        joint = names[name]
        if joint.limit is None:
            joint.limit = UrdfLimit()
        joint.limit.lower, joint.limit.upper = float(lo), float(hi)
    scale_model(model, float(scale))
    write_bytes(Path(dst), write_urdf(model, comment=f" {header} " if header else None))
    return Path(dst)


def urdf_joints(urdf: Path | str) -> dict[str, dict[str, Any]]:
    """Joint name -> {type, lower, upper} (rad or m; None when absent) of a URDF (lenient reading).
    Raises UrdfError: unreadable XML or a malformed number."""
    return {j.name: {"type": j.type, "lower": getattr(j.limit, "lower", None), "upper": getattr(j.limit, "upper", None)}
            for j in read_urdf(urdf, mode="lenient").joints}


def reference_initial_state(joints: dict[str, dict[str, Any]], task_joints: list[str],
                            rng: tuple[float, float] | None, scale: float) -> dict[str, float]:
    """The reference's initial state (joint -> rad or m, output units) over ``joints``
    (:func:`urdf_joints`): the ``task_joints`` at the lower end of ``rng`` (prismatic times ``scale``),
    the other movable joints at 0, each clipped to its limits."""
    out = {}
    for name, j in joints.items():
        if j["type"] in MOVABLE:
            q = rng[0] * (scale if j["type"] == "prismatic" else 1.0) if rng is not None and name in task_joints else 0.0
            if j["lower"] is not None:
                q = max(q, j["lower"])
            if j["upper"] is not None:
                q = min(q, j["upper"])
            out[name] = float(q)
    return out


@dataclass(frozen=True)
class WrittenReference:
    """GenSim2's reference of one object folder written as an asset folder (:func:`write_reference`):
    ``urdf`` the written ``mobility.urdf``, ``source`` the ``reference_gensim2.urdf`` it scales,
    ``scale`` (1.0 where the JSON states none, said in ``notes``), ``joint_position_range`` (rad or
    m; None without one), the movable ``task_joints`` and the ``initial_state`` (joint -> rad or m)
    written to ``initial_state.json``."""

    urdf: Path
    source: Path
    scale: float
    joint_position_range: tuple[float, float] | None
    task_joints: list[str]
    initial_state: dict[str, float]
    notes: list[str] = field(default_factory=list)


def write_reference(folder: Path | str, out_dir: Path | str, label: str | None = None) -> WrittenReference:
    """Write GenSim2's reference of the object ``folder`` to ``out_dir`` as an asset folder (the
    learnability benchmark's ``human`` method, the ManiSkill environments' ``reference=True``):
    ``reference_gensim2.urdf`` at ``reference_gensim2.json``'s scale (:func:`scale_urdf`; 1.0,
    SAPIEN's default, where it states none), each task joint's limits ``joint_position_range``
    within the file's own (an empty intersection keeps the range) and ``initial_state.json``
    (:func:`reference_initial_state`). ``label``: the URDF's header comment before " at scale s"
    (default "GenSim2 reference of <folder name>").

    Raises:
        AssetError: the folder has no ``reference_gensim2.urdf``.
        ValueError: ``reference_gensim2.json`` is not JSON or a value not a number.
        asset2sim.urdf.UrdfError: the reference URDF cannot be read.
        OSError: a file cannot be read or written.
    """
    folder, out_dir = Path(folder), Path(out_dir)
    ref = read_reference(folder)
    if ref.urdf is None:
        raise AssetError(f"no {REFERENCE_URDF} in {folder}")
    scale = 1.0 if ref.scale is None else ref.scale
    notes = [f"{REFERENCE_JSON} has no scale: 1.0 (SAPIEN's default)"] if ref.scale is None else []
    rng = ref.joint_position_range
    limits = None
    if rng is not None:
        file_joints = urdf_joints(ref.urdf)
        limits = {}
        for j in ref.task_joints:
            lo = max(rng[0], file_joints[j]["lower"]) if file_joints[j]["lower"] is not None else rng[0]
            hi = min(rng[1], file_joints[j]["upper"]) if file_joints[j]["upper"] is not None else rng[1]
            limits[j] = (lo, hi) if lo <= hi else rng
    urdf = scale_urdf(ref.urdf, out_dir / URDF_NAME, scale, joint_limits=limits,
                      header=f"{label or f'GenSim2 reference of {folder.name}'} at scale {scale}")
    state = reference_initial_state(urdf_joints(urdf), ref.task_joints, rng, scale)
    write_json(out_dir / STATE_NAME, {"initial_joint_positions": state})
    return WrittenReference(urdf, ref.urdf, scale, rng, list(ref.task_joints), state, notes)
