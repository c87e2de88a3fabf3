"""A link's geometry elements combined into one triangle soup in the link frame, for
:mod:`asset2sim.tasks.geometry.analyze`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from asset2sim.frames import rpy_matrix
from asset2sim.mesh_io import MeshCache, MeshReadError
from asset2sim.schemas.asset import GeometryRef, LinkDesc

__all__ = ["LinkSurface", "MeshAnalysisError", "link_surface"]


class MeshAnalysisError(ValueError):
    """A link has no usable geometry; the message names the link and the file(s)."""


class _PieceError(Exception):
    """One geometry element could not be used (reason in the message)."""


def _primitive_mesh(ref: GeometryRef, where: str) -> tuple[np.ndarray, np.ndarray]:
    import trimesh

    if ref.kind == "box":
        if ref.size is None or min(ref.size) <= 0 or not np.all(np.isfinite(ref.size)):
            raise _PieceError(f"{where}: box size {ref.size!r} must be three positive numbers")
        m = trimesh.creation.box(extents=ref.size)
    elif ref.kind == "cylinder":
        if not (ref.radius and ref.length and ref.radius > 0 and ref.length > 0):
            raise _PieceError(f"{where}: cylinder needs radius > 0 and length > 0 (got {ref.radius!r}, {ref.length!r})")
        m = trimesh.creation.cylinder(radius=ref.radius, height=ref.length, sections=128)
    elif ref.kind == "sphere":
        if not (ref.radius and ref.radius > 0):
            raise _PieceError(f"{where}: sphere needs radius > 0 (got {ref.radius!r})")
        m = trimesh.creation.icosphere(subdivisions=4, radius=ref.radius)
    else:  # pragma: no cover - schema restricts kinds
        raise _PieceError(f"{where}: unknown geometry kind {ref.kind!r}")
    return np.asarray(m.vertices, np.float64), np.asarray(m.faces, np.int64)


@dataclass
class LinkSurface:
    """The combined, cleaned triangle surface of one link in the link frame: ``vertices`` (N, 3) m,
    ``faces`` (M, 3) int64, ``sources`` one label per usable element (``refs``), ``role`` "collision" or
    "visual", ``notes`` what was dropped and why."""

    vertices: np.ndarray
    faces: np.ndarray
    sources: list[str]
    refs: list[GeometryRef]
    role: str
    notes: list[str] = field(default_factory=list)


def _clean_piece(v: np.ndarray, f: np.ndarray, where: str, notes: list[str]) -> tuple[np.ndarray, np.ndarray]:
    n = len(v)
    if f.size == 0:
        raise _PieceError(f"{where}: mesh has no faces")
    ok = np.all((f >= 0) & (f < n), axis=1)
    if not ok.all():
        notes.append(f"{where}: dropped {int((~ok).sum())} faces with out-of-range vertex indices")
        f = f[ok]
    finite = np.all(np.isfinite(v), axis=1)
    if not finite.all():
        badf = ~np.all(finite[f], axis=1)
        notes.append(f"{where}: dropped {int((~finite).sum())} non-finite vertices and the {int(badf.sum())} faces using them")
        f = f[~badf]
    rep = (f[:, 0] == f[:, 1]) | (f[:, 1] == f[:, 2]) | (f[:, 0] == f[:, 2])
    if rep.any():
        notes.append(f"{where}: dropped {int(rep.sum())} faces with a repeated vertex")
        f = f[~rep]
    if f.size == 0:
        raise _PieceError(f"{where}: no valid faces left")
    used = np.unique(f)
    if used.size < n:  # drop unreferenced vertices (they would widen the bounding box)
        remap = np.zeros(n, np.int64)
        remap[used] = np.arange(used.size)
        v, f = v[used], remap[f]
    return v, f


def link_surface(link: LinkDesc, *, prefer: Literal["collision", "visual"] = "collision",
                 cache: MeshCache | None = None) -> LinkSurface | None:
    """Combine a link's geometry into one triangle surface in the link frame.

    Uses ``link.collisions`` when non-empty, else ``link.visuals`` (swapped by ``prefer="visual"``),
    each placed as URDF does, x_link = R(rpy) @ (scale * x_mesh) + xyz (a mirroring scale flips the
    winding). Unusable elements are skipped, bad vertices and faces dropped, with a note.
    Returns ``None`` when the link has no geometry elements.

    Raises:
        MeshAnalysisError: no element of the link is usable (names the link and every file with its reason).
    """
    first, second = (link.collisions, link.visuals) if prefer == "collision" else (link.visuals, link.collisions)
    refs = first or second
    if not refs:
        return None
    role = refs[0].role
    cache = cache if cache is not None else MeshCache()
    verts, faces, sources, used, notes, failures = [], [], [], [], [], []
    offset = 0
    for i, ref in enumerate(refs):
        label = str(ref.path) if ref.kind == "mesh" else f"{ref.kind} #{i}"
        where = f"link {link.name!r}, {role} {label}"
        try:
            if ref.kind == "mesh":
                if ref.path is None:
                    raise _PieceError(f"{where}: mesh {ref.filename!r} has no resolved path")
                try:
                    mesh = cache.get(ref.path)
                    v, f, read_notes = mesh.vertices, mesh.faces, mesh.notes
                except MeshReadError as exc:
                    raise _PieceError(f"{where}: {exc}") from None
                notes.extend(f"{where}: {n}" for n in read_notes)
            else:
                v, f = _primitive_mesh(ref, where)
            v, f = _clean_piece(v, f, where, notes)
            scale = np.asarray(ref.scale, np.float64)
            if not np.all(np.isfinite(scale)) or np.any(scale == 0):
                raise _PieceError(f"{where}: scale {ref.scale!r} must be finite and non-zero")
            vt = (v * scale) @ rpy_matrix(ref.origin.rpy).T + np.asarray(ref.origin.xyz, np.float64)
            if np.prod(np.sign(scale)) < 0:
                f = f[:, ::-1]
        except _PieceError as exc:
            failures.append(str(exc))
            continue
        verts.append(vt)
        faces.append(f + offset)
        sources.append(label)
        used.append(ref)
        offset += len(vt)
    if not verts:
        raise MeshAnalysisError(f"link {link.name!r}: no usable {role} geometry: " + "; ".join(failures))
    notes = failures + notes
    return LinkSurface(vertices=np.concatenate(verts), faces=np.concatenate(faces), sources=sources,
                       refs=used, role=role, notes=notes)
