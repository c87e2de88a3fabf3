"""Mesh files: the one reader every stage uses.

:func:`read_mesh` gives vertices (N, 3) float64 and triangles (M, 3) int64
(0-based, file units) of any mesh file: OBJ by a vectorized parser with a
line-parser fallback, other formats through :func:`load_trimesh`.
:func:`obj_groups` / :func:`hull_point_sets` give the point sets whose convex
hulls a simulator collides with; :func:`scan_obj_text` (:mod:`asset2sim.mesh_text`,
re-exported) an OBJ as lines for tools that rewrite it. :func:`remember` keeps the bytes of a mesh file a
refine writes for its engines, which :func:`file_bytes` gives back while the
file is unchanged: the stages take them from memory. The MTL helpers of :mod:`asset2sim.mesh_materials` are
re-exported. Format: Wavefront OBJ / MTL (Advanced Visualizer manual, B1/B2).
"""

from __future__ import annotations

import hashlib
import io
import os
import threading
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import cachetools
import numpy as np

from asset2sim import atomic, file_memo

from asset2sim.mesh_text import ObjText, parse_vertex_lines, scan_obj_text  # re-exported: OBJ text as lines
from asset2sim.mesh_materials import (  # re-exported: the files an OBJ needs besides itself
    is_texture_statement,
    mtl_libraries,
    mtl_texture_maps,
    obj_material_files,
    obj_material_uses,
    read_mtl,
)

__all__ = [
    "MeshCache", "MeshData", "MeshReadError", "ObjText", "file_bytes", "forget_under", "remember", "write_file", "hull_point_sets", "is_texture_statement", "load_trimesh", "mtl_libraries",
    "group_meshes", "mtl_texture_maps", "obj_groups", "obj_material_files", "obj_material_uses", "parse_vertex_lines", "read_mesh",
    "read_mtl", "read_obj", "scan_obj_text"
]


class MeshReadError(ValueError):
    """A mesh file is missing or cannot be parsed (the message names the file)."""


def _written_size(entry: tuple[file_memo.FileIdentity, bytes | Path, int]) -> int:
    """What a :data:`_WRITTEN` entry counts against its 512 MiB: its bytes, at least 8 KiB (so at most 65,536
    files are kept)."""
    return max(entry[2], 8192)


#: absolute path -> (identity when remembered, its bytes or the file it is a plain copy of, bytes kept); the least
#: recently used dropped past 512 MiB of bytes or 65,536 files (a flow worker refines many assets).
_WRITTEN: cachetools.LRUCache = cachetools.LRUCache(maxsize=512 << 20, getsizeof=_written_size)
_WRITTEN_LOCK = threading.Lock()


def remember(path: Path | str, data: bytes | Path) -> None:
    """Keep what was just written to ``path``: its bytes, or the file it is a plain copy of."""
    ident = file_memo.identity(path)
    if ident is not None:
        entry = (ident, data, len(data) if isinstance(data, bytes) else 0)
        with _WRITTEN_LOCK:
            _WRITTEN.pop(os.path.abspath(path), None)
            if _written_size(entry) <= _WRITTEN.maxsize:
                _WRITTEN[os.path.abspath(path)] = entry


def write_file(path: Path | str, data: bytes) -> Path:
    """Write a mesh file atomically (:func:`asset2sim.atomic.write_bytes`, OSError) and :func:`remember` it."""
    remember(atomic.write_bytes(path, data), data)
    return Path(path)


def forget_under(folder: Path | str) -> None:
    """Drop what :func:`remember` kept of files in ``folder``."""
    prefix = os.path.join(os.path.abspath(folder), "")
    with _WRITTEN_LOCK:
        for key in [k for k in _WRITTEN if k.startswith(prefix)]:
            _WRITTEN.pop(key)


def file_bytes(path: Path | str) -> bytes:
    """The bytes of ``path``: what :func:`remember` kept while the file still has the identity it had
    then (:func:`asset2sim.file_memo.identity`), else read. Raises OSError."""
    with _WRITTEN_LOCK:
        hit = _WRITTEN.get(os.path.abspath(path))
    if hit is not None and file_memo.identity(path) == hit[0]:
        return hit[1] if isinstance(hit[1], bytes) else Path(hit[1]).read_bytes()
    return Path(path).read_bytes()


def _parse_obj_fast(data: bytes, groups: bool = False) -> tuple[np.ndarray, ...] | None:
    """Vectorized OBJ reader for the common case (``v x y z`` lines, triangle
    faces of one index format, positive indices). ``None`` when the file needs
    the general parser. With ``groups``: a third array (M,) int, each face's
    ``o``/``g`` group (the count of group lines before it); ``None`` also for a
    byte of :data:`_OTHER_LINE_ENDS` or one that is not ASCII (the line-by-line reader splits those)."""
    arr = np.frombuffer(data, np.uint8)
    n = arr.size
    if groups and np.any(np.isin(arr, _OTHER_LINE_ENDS) | (arr >= 128)):
        return None
    nl = np.flatnonzero(arr == 10)
    starts = np.concatenate(([0], nl + 1))
    lens = np.diff(np.concatenate((starts, [n + 1])))
    padded = np.concatenate((arr, np.zeros(2, np.uint8)))
    c0 = padded[starts]
    c1 = padded[starts + 1]
    ws = (c1 == 32) | (c1 == 9)
    is_v = (c0 == 118) & ws
    is_f = (c0 == 102) & ws
    nv, nf = int(is_v.sum()), int(is_f.sum())
    group = (np.cumsum(((c0 == 111) | (c0 == 103)) & (ws | (c1 == 10) | (c1 == 0)))[is_f],) if groups else ()

    def select(mask_lines: np.ndarray) -> np.ndarray:
        mask = np.repeat(mask_lines, lens)[:n]
        s = starts[mask_lines]
        mask[s] = False
        mask[s + 1] = False
        return arr[mask]

    with warnings.catch_warnings():
        warnings.simplefilter("error")  # partial parses raise instead of truncating
        try:
            vbytes = select(is_v)
            if np.any(vbytes == 35):  # '#': trailing comment
                return None
            verts = np.fromstring(vbytes.tobytes(), dtype=np.float64, sep=" ") if nv else np.zeros(0)
            if verts.size != 3 * nv:
                return None
            if nf == 0:
                return (verts.reshape(-1, 3), np.zeros((0, 3), np.int64)) + group
            fbytes = select(is_f).copy()
            if np.any(fbytes == 35):
                return None
            # exactly 3 corners on every face line (a quad and a 2-gon must not pair up)
            tok = fbytes > 32
            starts_tok = tok & ~np.concatenate(([False], tok[:-1]))
            if np.any(np.bincount(np.cumsum(fbytes == 10)[starts_tok], minlength=nf) != 3):
                return None
            first_end = np.flatnonzero(fbytes == 10)
            first = fbytes[: first_end[0] if first_end.size else fbytes.size].tobytes().split()
            if len(first) != 3:
                return None
            per_vertex = len([p for p in first[0].split(b"/") if p])
            fbytes[fbytes == 47] = 32  # '/' -> ' '
            idx = np.fromstring(fbytes.tobytes(), dtype=np.int64, sep=" ")
        except (ValueError, DeprecationWarning):
            return None
    if idx.size != 3 * per_vertex * nf:
        return None
    faces = idx.reshape(nf, 3, per_vertex)[:, :, 0]
    if np.any(faces < 1):
        return None  # negative (relative) or zero indices: general parser
    return (verts.reshape(-1, 3), faces - 1) + group


#: NUL and the bytes other than ``\n`` that :meth:`str.splitlines` ends a line at (ASCII ones; any byte >= 128 is checked apart).
_OTHER_LINE_ENDS = np.array([0, 11, 12, 13, 28, 29, 30], np.uint8)


@dataclass(frozen=True, slots=True)
class MeshData:
    """A mesh file's triangles in its units, not validated (indices may be out of range, vertices NaN):
    ``vertices`` (N, 3) float64, ``faces`` (M, 3) int64 (0-based vertex indices) and ``notes`` (one line per
    kind of record the reader skipped)."""

    vertices: np.ndarray
    faces: np.ndarray
    notes: list[str] = field(default_factory=list)


def _parse_obj_general(data: bytes, where: str) -> MeshData:
    """Line-by-line OBJ reader (polygons, negative indices, comments); MeshReadError
    on malformed records."""
    verts: list[tuple[float, float, float]] = []
    faces: list[tuple[int, int, int]] = []
    bad = 0
    for lineno, raw in enumerate(data.splitlines(), 1):
        line = raw.split(b"#", 1)[0].strip()
        if line.startswith((b"v ", b"v\t")):
            parts = line.split()
            if len(parts) < 4:
                raise MeshReadError(f"{where}: line {lineno}: vertex with fewer than 3 coordinates")
            try:
                verts.append(tuple(map(float, parts[1:4])))
            except ValueError as exc:
                raise MeshReadError(f"{where}: line {lineno}: bad vertex ({exc})") from None
        elif line.startswith((b"f ", b"f\t")):
            parts = line.split()[1:]
            try:
                ids = [int(p.split(b"/", 1)[0]) for p in parts]
            except ValueError:
                raise MeshReadError(f"{where}: line {lineno}: bad face record") from None
            if len(ids) < 3 or 0 in ids:  # OBJ indices start at 1: 0 names no vertex
                bad += 1
                continue
            ids = [i - 1 if i > 0 else len(verts) + i for i in ids]
            faces += [(ids[0], ids[j], ids[j + 1]) for j in range(1, len(ids) - 1)]
    notes = [f"{where}: {bad} face records with < 3 vertices or index 0 skipped"] if bad else []
    return MeshData(np.asarray(verts, np.float64).reshape(-1, 3), np.asarray(faces, np.int64).reshape(-1, 3), notes)


def read_obj(data: bytes, where: str = "<obj>") -> MeshData:
    """The triangles of OBJ bytes, polygons fan-triangulated, not validated (as :func:`read_mesh`); bytes parsed
    before without a note come from :data:`_PARSED` (copies: a refine parses the same file as the input check, the
    geometry, the collision cuts and the MJCF export read it, and a copy of it in the output folder).

    Raises:
        MeshReadError: a malformed ``v`` or ``f`` record (names ``where`` and the line).
    """
    key = (len(data), hashlib.sha1(data).digest())
    with _PARSED_LOCK:
        hit = _PARSED.get(key)
    if hit is None:
        fast = _parse_obj_fast(data)
        hit = MeshData(*fast) if fast is not None else _parse_obj_general(data, where)
        if hit.notes:  # they name ``where``
            return hit
        with _PARSED_LOCK:
            _PARSED[key] = hit
    return MeshData(hit.vertices.copy(), hit.faces.copy())


#: Meshes :func:`read_obj` parsed in this process, by (length, SHA-1) of their bytes; the least recently used
#: dropped past 256 MiB of arrays.
_PARSED: cachetools.LRUCache = cachetools.LRUCache(maxsize=256 << 20, getsizeof=lambda m: m.vertices.nbytes + m.faces.nbytes + 1)
_PARSED_LOCK = threading.Lock()


def load_trimesh(path: Path | str, *, skip_materials: bool = False):
    """``trimesh.load`` of :func:`file_bytes` ``(path)`` as one mesh, unprocessed, side files (textures,
    glTF buffers) from its folder (trimesh's exceptions and OSError propagate)."""
    import trimesh  # about 1 s to import; only non-OBJ files and primitives need it

    extra = {"skip_materials": True} if skip_materials else {}
    return trimesh.load(io.BytesIO(file_bytes(path)), file_type=Path(path).suffix.lstrip(".").lower(), force="mesh",
                        process=False, resolver=trimesh.resolvers.FilePathResolver(str(path)), **extra)


def read_mesh(path: Path | str) -> MeshData:
    """The triangles of a mesh file in its units, not validated (indices may be out of range, vertices NaN).

    Raises:
        MeshReadError: the file is missing or cannot be parsed (message names
            the file).
    """
    path = Path(path)
    try:
        if path.suffix.lower() == ".obj":
            return read_obj(file_bytes(path), str(path))
        loaded = load_trimesh(path, skip_materials=True)
        return MeshData(np.asarray(loaded.vertices, np.float64), np.asarray(loaded.faces, np.int64))
    except MeshReadError:
        raise
    except Exception as exc:  # OSError, trimesh parse errors of every kind
        raise MeshReadError(f"{path}: cannot read mesh ({type(exc).__name__}: {exc})") from None


class MeshCache:
    """Meshes read by :func:`read_mesh`, keyed by path: arrays shared and
    read-only, a failed read remembered and raised again."""

    def __init__(self) -> None:
        self._store: dict[Path, MeshData | MeshReadError] = {}

    def get(self, path: Path) -> MeshData:
        """The mesh at ``path`` (read on first use), its arrays read-only. Raises MeshReadError."""
        key = Path(path)
        hit = self._store.get(key)
        if hit is None:
            try:
                hit = read_mesh(key)
                for a in (hit.vertices, hit.faces):
                    a.setflags(write=False)
            except MeshReadError as exc:
                hit = exc
            self._store[key] = hit
        if isinstance(hit, MeshReadError):
            raise hit
        return hit

    def __len__(self) -> int:
        return len(self._store)


def _obj_group_polygons(path: Path | str) -> tuple[np.ndarray, list[list[list[int]] | np.ndarray]]:
    """The vertices (N, 3) of an OBJ file (file units) and, per ``o``/``g`` group with face indices, its
    faces as lists of 0-based vertex indices (negative OBJ indices resolved), in file order; a file of
    triangles only (:func:`_parse_obj_fast`) gives each group's faces as one array (M, 3) int64.

    Raises:
        MeshReadError: the file cannot be read, or a vertex or face line is malformed.
    """
    try:
        data = file_bytes(path)
    except OSError as exc:
        raise MeshReadError(f"cannot read mesh {path}: {exc}") from exc
    fast = _parse_obj_fast(data, groups=True)
    if fast is not None:
        v, f, group = fast
        return v, [part for part in np.split(f, np.flatnonzero(np.diff(group)) + 1) if len(part)]
    verts: list[tuple[float, float, float]] = []
    current: list[list[int]] = []
    # each o/g line starts a new one
    groups = [current]
    for line in data.decode(errors="replace").splitlines():
        if not line or line[0] not in "vfog":
            continue
        parts = line.split()
        tag = parts[0]
        if tag == "v":
            try:
                verts.append((float(parts[1]), float(parts[2]), float(parts[3])))
            except (IndexError, ValueError) as exc:
                raise MeshReadError(f"{path}: bad vertex line {line!r}") from exc
        elif tag == "f":
            try:
                ids = [int(tok.split("/")[0]) for tok in parts[1:]]
            except ValueError as exc:
                raise MeshReadError(f"{path}: bad face line {line!r}") from exc
            if ids:
                current.append([i - 1 if i > 0 else len(verts) + i for i in ids])
        elif tag in ("o", "g"):
            groups.append(current := [])
    return np.asarray(verts, float).reshape(-1, 3), [g for g in groups if g]


def obj_groups(path: Path | str) -> list[np.ndarray]:
    """Point sets (k, 3) of an OBJ file, one per ``o``/``g`` group with faces:
    the vertices its faces use (sorted by index, file units), in file order;
    PyBullet collides with one convex hull per such group.

    Raises:
        MeshReadError: the file cannot be read or a face names a missing vertex.
    """
    v, groups = _obj_group_polygons(path)
    out = []
    for polygons in groups:
        ids = np.unique(polygons if isinstance(polygons, np.ndarray) else np.fromiter((i for poly in polygons for i in poly), int))
        if ids.min() < 0 or ids.max() >= len(v):
            raise MeshReadError(f"{path}: a face names a vertex that does not exist")
        out.append(v[ids])
    return out


def group_meshes(path: Path | str) -> list[tuple[np.ndarray, np.ndarray]]:
    """Triangle meshes ``(vertices (k, 3), faces (m, 3) int)`` in file units, one per group of
    :func:`hull_point_sets` in the same order (OBJ: per ``o``/``g`` group with faces, polygons
    fan-triangulated, only the vertices its triangles use; other formats: the whole mesh).

    Raises:
        MeshReadError: the file cannot be read or a face names a missing vertex.
    """
    path = Path(path)
    if path.suffix.lower() != ".obj":
        mesh = read_mesh(path)
        return [(mesh.vertices, mesh.faces)]
    v, groups = _obj_group_polygons(path)
    out = []
    for polygons in groups:
        f = polygons if isinstance(polygons, np.ndarray) else np.asarray(
            [(p[0], p[k], p[k + 1]) for p in polygons for k in range(1, len(p) - 1)], np.int64).reshape(-1, 3)
        if len(f) and (f.min() < 0 or f.max() >= len(v)):
            raise MeshReadError(f"{path}: a face names a vertex that does not exist")
        ids, inv = np.unique(f, return_inverse=True)
        out.append((v[ids], inv.reshape(-1, 3).astype(np.int64)))
    return out


def hull_point_sets(path: Path | str) -> list[np.ndarray]:
    """Point sets (k, 3) whose convex hulls a simulator collides with:
    :func:`obj_groups` for OBJ, else all vertices in one set.

    Raises:
        MeshReadError: the mesh cannot be read.
    """
    path = Path(path)
    if path.suffix.lower() == ".obj":
        return obj_groups(path)
    try:
        m = load_trimesh(path)
    except Exception as exc:  # trimesh raises many types
        raise MeshReadError(f"cannot read mesh {path}: {exc}") from exc
    return [np.asarray(m.vertices, float)]


def convex_hull_mesh(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The convex hull of ``points`` (n, 3) (scipy's Qhull): vertices (k, 3) in
    the order of their index in ``points`` and triangles (m, 3) wound outward.

    Raises:
        scipy.spatial.QhullError: fewer than 4 points not in one plane.
        ValueError: ``points`` is not (n, 3).
    """
    from scipy.spatial import ConvexHull

    pts = np.asarray(points, float)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise ValueError(f"convex_hull_mesh: points must be (n, 3), got {pts.shape}")
    hull = ConvexHull(pts)
    tri = hull.simplices.copy()
    a, b, c = (hull.points[tri[:, i]] for i in range(3))
    flip = np.einsum("ij,ij->i", np.cross(b - a, c - a), hull.equations[:, :3]) < 0
    tri[flip] = tri[flip][:, [0, 2, 1]]
    used, inverse = np.unique(tri, return_inverse=True)
    return hull.points[used], inverse.reshape(tri.shape)


def hull_obj(points: np.ndarray, num: Callable[[float], str] = repr) -> bytes:
    """OBJ bytes of :func:`convex_hull_mesh` of ``points`` (n, 3), vertices
    written exactly (``num`` of each coordinate: ``repr``, or MJCF's
    :func:`asset2sim.engines.mjcf.base.num_text`).

    Raises:
        scipy.spatial.QhullError: fewer than 4 points not in one plane.
        ValueError: ``points`` is not (n, 3).
    """
    return obj_bytes(*convex_hull_mesh(points), num)


def obj_bytes(vertices: np.ndarray, faces: np.ndarray, num: Callable[[float], str] = repr) -> bytes:
    """OBJ bytes of a triangle mesh: ``vertices`` (k, 3), each coordinate written by ``num``, and ``faces`` (m, 3)
    0-based vertex indices."""
    lines = [f"v {num(x)} {num(y)} {num(z)}" for x, y, z in np.asarray(vertices, float).tolist()]
    lines += [f"f {i} {j} {k}" for i, j, k in np.asarray(faces, int) + 1]
    return ("\n".join(lines) + "\n").encode()
