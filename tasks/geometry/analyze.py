"""Mesh-analysis stage: the geometry of each link, at scale 1, in the link frame.

For every link with geometry :func:`analyze_link` returns a
:class:`~asset2sim.schemas.asset.LinkGeometry`: enclosed volume, surface area,
bounding box, center of mass, and two per-kg inertia tensors about that center
of mass (uniformly filled solid; uniform thin shell over the surface). The
downstream estimator turns them into mass and inertia (SPEC, "The method",
m = v * rho * s^3 * eta).

Which geometry
    A link's ``<collision>`` elements when it has any, else its ``<visual>``
    elements (``prefer="visual"`` swaps the order). Collision geometry is what
    the simulator integrates and touches; in PartNet-Mobility it is either the
    visual OBJ pieces themselves or a convex decomposition of them
    (``new_objs/``), whose union is the solid the simulator sees.

How (details and measured accuracy in ``docs/mesh_analysis.md``)
    All pieces (meshes and box/cylinder/sphere primitives, each placed by its
    ``origin`` and ``scale``) are combined into one triangle soup.

    * Surface area, surface centroid and thin-shell inertia are exact for the
      triangles: per triangle with vertices v0, v1, v2 and area A,
      integral of x x^T dA = A/12 (sum_i v_i v_i^T + s s^T), s = v0+v1+v2
      (second moment of a triangle, e.g. Eberly, "Polyhedral Mass
      Properties", 2002; the 2-D analogue of Tonon, J. Math. Stat. 1(1), 2004).
    * Watertight (every edge shared by exactly two faces with opposite
      orientation, as indexed or with vertices merged at 1e-9 of the link
      size): volume, center of mass and solid inertia are exact, by the
      divergence theorem over signed tetrahedra (Tonon 2004: integral of
      x x^T dV = V/20 (sum_i p_i p_i^T + s s^T) over a tetrahedron with one
      vertex at the reference point). Closed parts whose bounding boxes
      overlap are checked against the voxel union so overlapping convex
      pieces are not counted twice (``voxel_union``).
    * Otherwise (polygon soup: every PartNet-Mobility visual mesh):
      voxelization. The link's length scale is the geometric mean of its
      extents (each at least 1/16 of the longest, :func:`mean_size`); the
      pitch is that / ``voxels_per_axis`` (coarser if the grid would exceed
      ``max_voxels`` cells). The surface is sampled with spacing <= pitch/2
      and the cells holding samples are marked; gaps up to ``close_gaps`` x
      the length scale are closed (3x3x3 morphological closing, at least
      once); every cell not connected to the outside (6-connectivity) is
      filled. The marked surface layer straddles the true surface, so each
      filled cell counts w = 1 - sum over its faces exposed to the outside
      of the part of the cell beyond the surface along that axis, taken from
      the mean position of the cell's surface samples (``subvoxel``; for an
      axis-aligned face this is exact). A cell exposed on both sides of an
      axis (a wall thinner than a cell) keeps, along that axis, the
      separation of its two surfaces: 2 sqrt(var(x_k | x_i, x_j)) of its
      samples (the spread that the in-plane coordinates do not explain: 0
      for a single plane of any tilt). Without sub-voxel statistics the
      part is 1/2 per exposed face (``layer_correction``), right on average
      for any orientation, since a surface with unit normal n exposes
      (|n_x| + |n_y| + |n_z|) / pitch^2 cell faces per area and leaves the
      same fraction of a cell outside on average, but noisy (docs).
      Volume = sum(w) * pitch^3; center of mass and solid inertia are the
      w-weighted cell moments (each cell a uniform cube, + pitch^2/12 per
      axis).
    * A single primitive (box, cylinder, sphere) is analytic.

    When the enclosed volume is negligible (< 0.1 x area x pitch: a surface
    that encloses nothing, such as a lone quad, an open tube or a door whose
    back is missing), ``volume_method`` ends in ``+open_shell``, ``com`` is
    the surface centroid and ``inertia_solid`` equals ``inertia_shell``; the
    mass of such a link must come from area x wall thickness.
    ``inertia_shell`` is always about ``com`` (parallel-axis theorem from the
    surface centroid), so both tensors refer to the same point, as
    :class:`LinkGeometry` documents.

Inertia tensors are symmetrized; when a principal moment is ~0 or the triangle
inequality of principal moments is tight (flat or line-like geometry), an
isotropic 1e-6 x trace term is added and noted.

OBJ files are read by a vectorized parser that reads only ``v`` and ``f``
records (no materials or textures); other formats go through trimesh. Loaded
meshes are cached by path within an :func:`analyze_asset` call.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterable, Literal

import numpy as np

from asset2sim.schemas.asset import AssetDescription, GeometryRef, LinkDesc, LinkGeometry

__all__ = [
    "MeshAnalysisError",
    "MeshCache",
    "LinkSurface",
    "read_mesh",
    "link_surface",
    "surface_properties",
    "watertight_properties",
    "voxel_properties",
    "voxelize",
    "VoxelGrid",
    "SolidMoments",
    "mean_size",
    "rpy_matrix",
    "inertia_from_second_moment",
    "regularize_inertia",
    "analyze_link",
    "analyze_asset",
]

#: Default number of voxels along the link's length scale (:func:`mean_size`).
VOXELS_PER_AXIS = 96
#: Default cap on the total number of grid cells (bounds memory: about 20
#: bytes per cell at the peak, plus 7 bytes per surface sample).
MAX_VOXELS = 3_000_000
#: Default gap closing, as a fraction of the link's length scale (:func:`mean_size`).
CLOSE_GAPS = 0.02
#: Outside part of a cell per exposed face when sub-voxel positions are off (see module doc).
LAYER_CORRECTION = 0.5
#: Surface sampling spacing, in voxel pitches.
SAMPLE_SPACING = 0.5
#: Enclosed volume below OPEN_SHELL_FRACTION * area * pitch counts as "encloses nothing".
OPEN_SHELL_FRACTION = 0.1
#: Relative size of the isotropic inertia regularisation.
REGULARIZATION = 1e-6

_CHUNK_POINTS = 1 << 21  # lattice points per rasterization batch (48 MB of float64)
_CHUNK_FACES = 1 << 18  # triangles per moment batch


class MeshAnalysisError(ValueError):
    """A link has no usable geometry; the message names the link and the file(s)."""


class _PieceError(Exception):
    """One geometry element could not be used (reason in the message)."""


# --------------------------------------------------------------------------- IO


def _parse_obj_fast(data: bytes) -> tuple[np.ndarray, np.ndarray] | None:
    """Vectorized OBJ reader for the common case (``v x y z`` lines, triangle
    faces of one index format, positive indices). ``None`` when the file needs
    the general parser."""
    arr = np.frombuffer(data, np.uint8)
    n = arr.size
    if n == 0:
        return np.zeros((0, 3)), np.zeros((0, 3), np.int64)
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
                return verts.reshape(-1, 3), np.zeros((0, 3), np.int64)
            fbytes = select(is_f).copy()
            if np.any(fbytes == 35):
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
    return verts.reshape(-1, 3), faces - 1


def _parse_obj_general(data: bytes, where: str) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """Line-by-line OBJ reader: polygons (fan-triangulated), negative indices,
    vertex colours, comments. Raises _PieceError on malformed records."""
    verts: list[tuple[float, float, float]] = []
    faces: list[tuple[int, int, int]] = []
    bad = 0
    for lineno, raw in enumerate(data.splitlines(), 1):
        line = raw.split(b"#", 1)[0].strip()
        if line.startswith((b"v ", b"v\t")):
            parts = line.split()
            if len(parts) < 4:
                raise _PieceError(f"{where}: line {lineno}: vertex with fewer than 3 coordinates")
            try:
                verts.append((float(parts[1]), float(parts[2]), float(parts[3])))
            except ValueError as exc:
                raise _PieceError(f"{where}: line {lineno}: bad vertex ({exc})") from None
        elif line.startswith((b"f ", b"f\t")):
            parts = line.split()[1:]
            try:
                ids = [int(p.split(b"/", 1)[0]) for p in parts]
            except ValueError:
                raise _PieceError(f"{where}: line {lineno}: bad face record") from None
            nvert = len(verts)
            ids = [i - 1 if i > 0 else nvert + i for i in ids]
            if len(ids) < 3:
                bad += 1
                continue
            for j in range(1, len(ids) - 1):
                faces.append((ids[0], ids[j], ids[j + 1]))
    notes = [f"{where}: {bad} face records with < 3 vertices skipped"] if bad else []
    v = np.asarray(verts, np.float64).reshape(-1, 3)
    f = np.asarray(faces, np.int64).reshape(-1, 3)
    return v, f, notes


def read_mesh(path: Path | str) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """Read a triangle mesh file without materials or textures.

    Returns ``(vertices (N, 3) float64, faces (M, 3) int64, notes)`` in the
    file's units, faces indexing ``vertices`` (not yet validated: indices may
    be out of range and vertices may be NaN; :func:`link_surface` cleans them).
    OBJ is read by a vectorized parser (falls back to a line parser for
    polygons, negative indices, comments); other formats via ``trimesh.load``.

    Raises:
        MeshAnalysisError: the file is missing or cannot be parsed (message
            names the file).
    """
    path = Path(path)
    try:
        if path.suffix.lower() == ".obj":
            data = path.read_bytes()
            fast = _parse_obj_fast(data)
            if fast is not None:
                return fast[0], fast[1], []
            return _parse_obj_general(data, str(path))
        import trimesh

        loaded = trimesh.load(str(path), force="mesh", process=False, skip_materials=True)
        return np.asarray(loaded.vertices, np.float64), np.asarray(loaded.faces, np.int64), []
    except _PieceError as exc:
        raise MeshAnalysisError(str(exc)) from None
    except MeshAnalysisError:
        raise
    except Exception as exc:  # OSError, trimesh parse errors of every kind
        raise MeshAnalysisError(f"{path}: cannot read mesh ({type(exc).__name__}: {exc})") from None


class MeshCache:
    """Meshes read by :func:`read_mesh`, keyed by resolved path (one analysis
    call; several links of some assets reference the same files). Arrays are
    shared and must be treated as read-only."""

    def __init__(self) -> None:
        self._store: dict[Path, tuple[np.ndarray, np.ndarray, list[str]] | MeshAnalysisError] = {}

    def get(self, path: Path) -> tuple[np.ndarray, np.ndarray, list[str]]:
        """The mesh at ``path`` (read on first use). Raises MeshAnalysisError."""
        key = Path(path)
        hit = self._store.get(key)
        if hit is None:
            try:
                hit = read_mesh(key)
                for a in hit[:2]:
                    a.setflags(write=False)
            except MeshAnalysisError as exc:
                hit = exc
            self._store[key] = hit
        if isinstance(hit, MeshAnalysisError):
            raise hit
        return hit

    def __len__(self) -> int:
        return len(self._store)


# ----------------------------------------------------------------- geometry


def rpy_matrix(rpy: Iterable[float]) -> np.ndarray:
    """Rotation matrix (3, 3) of URDF roll-pitch-yaw (rad, fixed axes X, Y, Z):
    R = Rz(yaw) @ Ry(pitch) @ Rx(roll) (URDF specification, ``<origin>``)."""
    r, p, y = (float(v) for v in rpy)
    cr, sr, cp, sp, cy, sy = math.cos(r), math.sin(r), math.cos(p), math.sin(p), math.cos(y), math.sin(y)
    return np.array(
        [
            [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
            [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
            [-sp, cp * sr, cp * cr],
        ]
    )


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
    """The combined, cleaned triangle surface of one link in the link frame.

    ``vertices`` (N, 3) m, ``faces`` (M, 3) int64 (valid, finite, no repeated
    index), ``piece`` (M,) index into ``sources`` of each face, ``sources``
    one label per usable geometry element (file path or primitive kind),
    ``role`` "collision" or "visual", ``notes`` what was dropped and why.
    """

    vertices: np.ndarray
    faces: np.ndarray
    piece: np.ndarray
    sources: list[str]
    kinds: list[str]
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
        notes.append(
            f"{where}: dropped {int((~finite).sum())} non-finite vertices and the {int(badf.sum())} faces using them"
        )
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


def link_surface(
    link: LinkDesc,
    *,
    prefer: Literal["collision", "visual"] = "collision",
    cache: MeshCache | None = None,
) -> LinkSurface | None:
    """Combine a link's geometry into one triangle surface in the link frame.

    Uses ``link.collisions`` when non-empty, else ``link.visuals`` (swapped by
    ``prefer="visual"``). Each element is placed as URDF does:
    x_link = R(rpy) @ (scale * x_mesh) + xyz. A mirroring scale (negative
    determinant) has its face winding flipped so outward normals stay outward.
    Elements that cannot be used (unreadable file, no valid faces) are skipped
    with a note; NaN vertices and bad faces are dropped with a note.

    Returns ``None`` when the link has no geometry elements.

    Raises:
        MeshAnalysisError: no element of the link is usable (names the link
            and every file with its reason).
    """
    first, second = (link.collisions, link.visuals) if prefer == "collision" else (link.visuals, link.collisions)
    refs = first or second
    if not refs:
        return None
    role = refs[0].role
    cache = cache if cache is not None else MeshCache()
    verts, faces, piece, sources, kinds, used, notes, failures = [], [], [], [], [], [], [], []
    offset = 0
    for i, ref in enumerate(refs):
        label = str(ref.path) if ref.kind == "mesh" else f"{ref.kind} #{i}"
        where = f"link {link.name!r}, {role} {label}"
        try:
            if ref.kind == "mesh":
                if ref.path is None:
                    raise _PieceError(f"{where}: mesh {ref.filename!r} has no resolved path")
                try:
                    v, f, read_notes = cache.get(ref.path)
                except MeshAnalysisError as exc:
                    raise _PieceError(f"{where}: {exc}") from None
                notes.extend(f"{where}: {n}" for n in read_notes)
            else:
                v, f = _primitive_mesh(ref, where)
            v, f = _clean_piece(v, f, where, notes)
            scale = np.asarray(ref.scale, np.float64)
            if not np.all(np.isfinite(scale)) or np.any(scale == 0):
                raise _PieceError(f"{where}: scale {ref.scale!r} must be finite and non-zero")
            rot = rpy_matrix(ref.origin.rpy)
            vt = (v * scale) @ rot.T + np.asarray(ref.origin.xyz, np.float64)
            if np.prod(np.sign(scale)) < 0:
                f = f[:, ::-1]
        except _PieceError as exc:
            failures.append(str(exc))
            continue
        verts.append(vt)
        faces.append(f + offset)
        piece.append(np.full(len(f), len(sources), np.int32))
        sources.append(label)
        kinds.append(ref.kind)
        used.append(ref)
        offset += len(vt)
    if not verts:
        raise MeshAnalysisError(
            f"link {link.name!r}: no usable {role} geometry: " + "; ".join(failures)
        )
    notes = failures + notes
    return LinkSurface(
        vertices=np.concatenate(verts),
        faces=np.concatenate(faces),
        piece=np.concatenate(piece),
        sources=sources,
        kinds=kinds,
        refs=used,
        role=role,
        notes=notes,
    )


# ----------------------------------------------------------------- moments


def inertia_from_second_moment(second: np.ndarray) -> np.ndarray:
    """Per-kg inertia tensor (3, 3) m^2 from the per-kg central second moment
    C = E[(x - c)(x - c)^T] (3, 3) m^2: I = tr(C) * Id - C."""
    c = 0.5 * (second + second.T)
    return np.trace(c) * np.eye(3) - c


def regularize_inertia(inertia: np.ndarray, scale_m2: float, rel: float = REGULARIZATION) -> tuple[np.ndarray, bool]:
    """Make a per-kg inertia tensor (3, 3) m^2 symmetric positive definite with
    a strict triangle inequality of principal moments.

    When the smallest principal moment is below ``rel`` x the largest, or the
    triangle inequality I_a + I_b >= I_c holds with a margin below ``rel`` x the
    largest (flat or line-like geometry), an isotropic term ``rel * trace``
    is added (``rel * scale_m2`` when the trace is below ``rel * scale_m2``;
    ``scale_m2`` m^2, e.g. the squared link size). Returns
    ``(inertia, changed)``.
    """
    i = 0.5 * (inertia + inertia.T)
    ev = np.linalg.eigvalsh(i)
    top = max(float(ev[-1]), 0.0)
    margin = float(ev[0] + ev[1] - ev[2])
    if ev[0] > rel * top and margin > rel * top and top > 0:
        return i, False
    tr = float(np.trace(i))
    eps = rel * (tr if tr > rel * scale_m2 else max(float(scale_m2), 1e-300))
    return i + eps * np.eye(3), True


def _triangles(vertices: np.ndarray, faces: np.ndarray, ref: np.ndarray) -> Iterable[np.ndarray]:
    for s in range(0, len(faces), _CHUNK_FACES):
        yield vertices[faces[s : s + _CHUNK_FACES]] - ref


def surface_properties(vertices: np.ndarray, faces: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
    """Exact area moments of a triangle surface.

    Args:
        vertices: (N, 3) m. faces: (M, 3) int, valid indices.

    Returns:
        ``(area m^2, centroid (3,) m, C (3, 3) m^2)`` with C the per-unit-area
        second moment about the centroid, integral of (x-c)(x-c)^T dA / area.
        Per triangle: integral of x x^T dA = A/12 (sum_i v_i v_i^T + s s^T),
        s = v0 + v1 + v2 (Eberly 2002). Area 0 gives centroid = vertex mean
        and C = 0.
    """
    ref = 0.5 * (vertices.min(axis=0) + vertices.max(axis=0)) if len(vertices) else np.zeros(3)
    area = 0.0
    first = np.zeros(3)
    second = np.zeros((3, 3))
    for t in _triangles(vertices, faces, ref):
        a = 0.5 * np.linalg.norm(np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]), axis=1)
        s = t.sum(axis=1)
        area += float(a.sum())
        first += (a[:, None] * s).sum(axis=0) / 3.0
        second += (np.einsum("t,tij,tik->jk", a, t, t) + np.einsum("t,tj,tk->jk", a, s, s)) / 12.0
    if area <= 0:
        used = vertices[np.unique(faces)] if faces.size else vertices
        return 0.0, used.mean(axis=0) if len(used) else ref, np.zeros((3, 3))
    c = first / area
    cov = second / area - np.outer(c, c)
    return area, c + ref, 0.5 * (cov + cov.T)


def _merge_vertices(vertices: np.ndarray, faces: np.ndarray, tol: float) -> tuple[np.ndarray, int]:
    """Faces (M, 3) re-indexed onto vertices merged on a grid of size tol."""
    lo = vertices.min(axis=0)
    key = np.round((vertices - lo) / tol).astype(np.int64)
    _, inverse = np.unique(key, axis=0, return_inverse=True)
    inverse = inverse.ravel()
    return inverse[faces], int(inverse.max()) + 1


def _is_closed_oriented(fm: np.ndarray, nv: int) -> bool:
    """Every edge in exactly two faces with opposite orientation."""
    a = np.concatenate((fm[:, 0], fm[:, 1], fm[:, 2]))
    b = np.concatenate((fm[:, 1], fm[:, 2], fm[:, 0]))
    d = np.sort(a * nv + b)
    if d.size and np.any(d[1:] == d[:-1]):
        return False
    r = np.sort(b * nv + a)
    return bool(np.array_equal(d, r))


@dataclass
class SolidMoments:
    """Volume (m^3), center of mass (3,) m and per-kg central second moment
    (3, 3) m^2 of a solid, with how they were obtained."""

    volume: float
    com: np.ndarray
    second: np.ndarray
    method: str
    notes: list[str] = field(default_factory=list)
    pitch: float = 0.0
    overlap_candidates: bool = False
    """Closed components with positive volume whose bounding boxes overlap:
    their union may be smaller than the sum of their volumes."""


def watertight_properties(vertices: np.ndarray, faces: np.ndarray, merge_tol: float | None = None) -> SolidMoments | None:
    """Exact solid moments of a closed, consistently oriented triangle surface.

    Args:
        vertices: (N, 3) m. faces: (M, 3) int. merge_tol: vertex merge
            distance, m (default 1e-9 x the longest extent).

    Returns:
        ``SolidMoments`` (method ``watertight_exact``) when the surface has
        every edge in exactly two faces with opposite orientation, either as
        indexed or with coincident vertices merged (faces that collapse in
        the merge are ignored for the test); ``None`` otherwise. Per
        connected component the signed volume is integrated over tetrahedra
        (reference point, v0, v1, v2)
        (Tonon 2004: integral of x x^T dV = V/20 (sum_i p_i p_i^T + s s^T));
        a component with negative volume that is not inside another
        component's bounding box is inside-out and is flipped (noted).
        ``overlap_candidates`` is set when closed components with positive
        volume have overlapping bounding boxes (their union may be smaller
        than the sum; :func:`analyze_link` checks it).
    """
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    lo, hi = vertices.min(axis=0), vertices.max(axis=0)
    size = float(np.max(hi - lo))
    if size <= 0:
        return None
    # topology as indexed first (meshes that share vertices, including
    # closed parts that touch), else with coincident vertices merged
    # (polygon soups whose triangles each have their own vertices)
    fm, nv = faces, len(vertices)
    if not _is_closed_oriented(fm, nv):
        fm, nv = _merge_vertices(vertices, faces, merge_tol or 1e-9 * size)
        ok = (fm[:, 0] != fm[:, 1]) & (fm[:, 1] != fm[:, 2]) & (fm[:, 0] != fm[:, 2])
        if not _is_closed_oriented(fm[ok], nv):
            return None
    rows = np.concatenate((fm[:, 0], fm[:, 1]))
    cols = np.concatenate((fm[:, 1], fm[:, 2]))
    graph = coo_matrix((np.ones(rows.size, np.int8), (rows, cols)), shape=(nv, nv))
    ncomp, vlabel = connected_components(graph, directed=False)
    comp = vlabel[fm[:, 0]]
    ref = 0.5 * (lo + hi)
    vol = np.zeros(ncomp)
    first = np.zeros((ncomp, 3))
    second = np.zeros((ncomp, 3, 3))
    for s in range(0, len(faces), _CHUNK_FACES):
        t = vertices[faces[s : s + _CHUNK_FACES]] - ref
        c = comp[s : s + _CHUNK_FACES]
        v6 = np.einsum("ti,ti->t", t[:, 0], np.cross(t[:, 1], t[:, 2])) / 6.0
        ssum = t.sum(axis=1)
        vol += np.bincount(c, v6, ncomp)
        fw = v6[:, None] * ssum / 4.0
        sw = (np.einsum("tij,tik->tjk", t, t) + np.einsum("tj,tk->tjk", ssum, ssum)) * (v6 / 20.0)[:, None, None]
        for k in range(3):
            first[:, k] += np.bincount(c, fw[:, k], ncomp)
            for m in range(3):
                second[:, k, m] += np.bincount(c, sw[:, k, m], ncomp)
    notes: list[str] = []
    bmin = np.full((ncomp, 3), np.inf)
    bmax = np.full((ncomp, 3), -np.inf)
    fcomp = np.repeat(comp, 3)
    corners = vertices[faces].reshape(-1, 3)
    for k in range(3):
        np.minimum.at(bmin[:, k], fcomp, corners[:, k])
        np.maximum.at(bmax[:, k], fcomp, corners[:, k])
    sign = np.ones(ncomp)
    tol_vol = 1e-12 * size**3
    positive = vol > tol_vol
    for i in np.flatnonzero(vol < -tol_vol):
        # a cavity lies inside a positive component; otherwise it is inside-out
        inside = positive & np.all(bmin <= bmin[i], axis=1) & np.all(bmax[i] <= bmax, axis=1)
        if not inside.any():
            sign[i] = -1.0
    if np.any(sign < 0):
        notes.append(f"{int((sign < 0).sum())} closed component(s) were inside-out (inward normals) and were flipped")
    vol_t = float((sign * vol).sum())
    if vol_t <= 0:
        return SolidMoments(0.0, ref.copy(), np.zeros((3, 3)), "watertight_exact", notes)
    fst = (sign[:, None] * first).sum(axis=0)
    snd = (sign[:, None, None] * second).sum(axis=0)
    com = fst / vol_t
    cov = snd / vol_t - np.outer(com, com)
    pos = np.flatnonzero(sign * vol > tol_vol)
    overlap = False
    for n_i, i in enumerate(pos[:-1]):
        others = pos[n_i + 1 :]
        gap = np.minimum(bmax[i], bmax[others]) - np.maximum(bmin[i], bmin[others])
        if np.any(np.all(gap > 1e-9 * size, axis=1)):
            overlap = True
            break
    return SolidMoments(vol_t, com + ref, 0.5 * (cov + cov.T), "watertight_exact", notes, overlap_candidates=overlap)


def _surface_points(tri: np.ndarray, spacing: float) -> Iterable[np.ndarray]:
    """Points (P, 3) covering triangles (T, 3, 3) with spacing <= ``spacing``.

    Triangles whose edges are all <= spacing give their vertices. Larger ones
    are sampled in rows parallel to their longest edge: k2 = ceil(height /
    spacing) + 1 rows from the base to the apex, each row split into
    segments <= spacing. The count is ~ area / spacing^2 even for slivers.
    Yielded in batches of about ``_CHUNK_POINTS`` points, in the dtype of
    ``tri``.
    """
    edges = np.stack(
        [
            np.linalg.norm(tri[:, 2] - tri[:, 1], axis=1),
            np.linalg.norm(tri[:, 0] - tri[:, 2], axis=1),
            np.linalg.norm(tri[:, 1] - tri[:, 0], axis=1),
        ],
        axis=1,
    )  # edge i is opposite vertex i
    small = edges.max(axis=1) <= spacing
    if small.any():
        yield tri[small].reshape(-1, 3)
    if small.all():
        return
    big, eb = tri[~small], edges[~small]
    r = np.arange(len(big))
    apex = eb.argmax(axis=1)
    a_pt, b_pt, c_pt = big[r, apex], big[r, (apex + 1) % 3], big[r, (apex + 2) % 3]
    base = eb[r, apex]
    height = np.linalg.norm(np.cross(b_pt - a_pt, c_pt - a_pt), axis=1) / base
    k1 = np.ceil(base / spacing).astype(np.int64)
    k2 = np.maximum(1, np.ceil(height / spacing)).astype(np.int64)
    est = np.cumsum((k1 + 2) * (k2 + 1) // 2 + k2 + 1)
    start = 0
    while start < len(big):
        stop = int(np.searchsorted(est, (est[start - 1] if start else 0) + _CHUNK_POINTS, side="right"))
        stop = max(stop, start + 1)
        sl = slice(start, stop)
        rows = k2[sl] + 1
        row_tri = np.repeat(np.arange(stop - start), rows)
        row_j = np.arange(rows.sum()) - np.repeat(np.cumsum(rows) - rows, rows)
        v = (row_j / k2[sl][row_tri])[:, None]
        apex_r = a_pt[sl][row_tri]
        row_start = b_pt[sl][row_tri]
        row_start += v * (apex_r - row_start)
        row_dir = c_pt[sl][row_tri]
        row_dir += v * (apex_r - row_dir)
        row_dir -= row_start
        m = np.ceil(base[sl][row_tri] * (1.0 - v[:, 0]) / spacing).astype(np.int64) + 1
        step = 1.0 / np.maximum(m - 1, 1)
        offsets = np.cumsum(m) - m
        u = np.arange(int(m.sum()), dtype=tri.dtype)
        u -= np.repeat(offsets, m)
        u *= np.repeat(step, m)
        pts = np.repeat(row_dir, m, axis=0)
        pts *= u[:, None]
        pts += np.repeat(row_start, m, axis=0)
        yield pts
        start = stop


def mean_size(ext: np.ndarray) -> float:
    """The length scale of a link for voxelization (m): the geometric mean of
    its bounding-box extents (3,), each taken at least 1/16 of the longest,
    so elongated and flat links get finer voxels than a cube of the same
    longest extent."""
    size = float(np.max(ext))
    return float(np.prod(np.maximum(ext, size / 16.0))) ** (1.0 / 3.0)


def _grid_pitch(ext: np.ndarray, voxels_per_axis: int, max_voxels: int, pad: int) -> float:
    h = mean_size(ext) / voxels_per_axis
    for _ in range(60):
        cells = np.prod(np.ceil(ext / h) + 2 * pad + 2)
        if cells <= max_voxels:
            return h
        h *= 1.05
    return h  # pragma: no cover


@dataclass
class VoxelGrid:
    """A voxelized link: ``surface`` and ``filled`` boolean grids (nx, ny, nz),
    cell (i, j, k) spanning ``origin + pitch * [i, i+1) x ...`` (m);
    ``closing`` the number of 3x3x3 closing iterations applied.

    With sub-voxel statistics (``None`` otherwise), for the S cells holding
    surface samples: ``cells`` (S,) their flat indices (sorted), ``mean``
    (S, 3) the mean in-cell position of their samples (cell units, 0..1),
    ``thickness`` (S, 3) the spread of the samples along each axis that the
    other two axes do not explain, 2 sqrt(var(x_k | x_i, x_j)) (cell units:
    ~0 for one plane of any orientation, the distance between two parallel
    surfaces crossing the cell)."""

    surface: np.ndarray
    filled: np.ndarray
    origin: np.ndarray
    pitch: float
    closing: int
    cells: np.ndarray | None = None
    mean: np.ndarray | None = None
    thickness: np.ndarray | None = None


def voxelize(
    vertices: np.ndarray,
    faces: np.ndarray,
    *,
    voxels_per_axis: int = VOXELS_PER_AXIS,
    max_voxels: int = MAX_VOXELS,
    close_gaps: float = CLOSE_GAPS,
    sample_spacing: float = SAMPLE_SPACING,
    grid_shift: tuple[float, float, float] = (0.0, 0.0, 0.0),
    subvoxel: bool = True,
) -> VoxelGrid:
    """Voxelize a triangle soup and fill what it encloses.

    Args:
        vertices: (N, 3) m. faces: (M, 3) int, valid.
        voxels_per_axis: voxels along the longest extent (pitch = size / this,
            coarser when the grid would exceed ``max_voxels`` cells).
        close_gaps: gaps up to this fraction of the link's length scale
            (:func:`mean_size`) are closed (morphological closing with a
            3x3x3 cube, one iteration per 2 voxels of gap, at least one).
        sample_spacing: surface sampling distance in pitches (<= 0.5 keeps
            the marked surface free of 6-connected holes before closing).
        grid_shift: (3,) shift of the grid against the geometry, in pitches,
            each in [0, 1) (for robustness studies; results should not depend
            on it beyond the method's noise).
        subvoxel: record per-cell sample statistics (``VoxelGrid.cells``,
            ``mean``, ``thickness``).

    Returns:
        :class:`VoxelGrid`; the surface is padded by closing + 2 empty cells
        and the bounding box's extreme faces sit on cell centers.

    Raises:
        ValueError: all vertices coincide.
    """
    from scipy import ndimage as ndi

    lo, hi = vertices.min(axis=0), vertices.max(axis=0)
    ext = hi - lo
    size = float(ext.max())
    if not size > 0:
        raise ValueError("all vertices coincide: nothing to voxelize")
    # pitch first with a provisional pad, then the closing iterations it implies
    h = _grid_pitch(ext, voxels_per_axis, max_voxels, 3)
    iters = max(1, int(math.ceil(close_gaps * mean_size(ext) / (2.0 * h) - 1e-9)))
    pad = iters + 2
    h = _grid_pitch(ext, voxels_per_axis, max_voxels, pad)
    # faces at the extremes of the bounding box sit on voxel centers, so
    # axis-aligned outer faces get exactly half a voxel of inflation
    dims = np.ceil(ext / h).astype(np.int64) + 2 * pad + 2
    origin = lo - (pad + 0.5 - np.asarray(grid_shift, np.float64)) * h
    ncell = int(np.prod(dims))
    s0, s1 = int(dims[1] * dims[2]), int(dims[2])
    grid = np.zeros(ncell, bool)
    samples: list[tuple[np.ndarray, np.ndarray]] = []  # (cell (P,) int32, in-cell position (P, 3) uint8)
    # in voxel units: cell (i, j, k) is [i, i+1) x [j, j+1) x [k, k+1)
    vox = ((vertices - origin) / h).astype(np.float32)

    def batches() -> Iterable[np.ndarray]:
        for s in range(0, len(faces), _CHUNK_FACES):
            fc = faces[s : s + _CHUNK_FACES]
            tri = vox[fc]
            edge = np.max(np.abs(tri - tri[:, [1, 2, 0]]).sum(axis=2), axis=1)  # >= longest edge
            small = edge <= sample_spacing
            if small.any():  # triangles smaller than the spacing: their vertices, once each
                yield vox[np.unique(fc[small])]
            if not small.all():
                yield from _surface_points(tri[~small], sample_spacing)

    for pts in batches():
        # points are convex combinations of vertices, so inside the padded grid
        ijk = pts.astype(np.int32)
        flat = ijk[:, 0].astype(np.int64) * s0 + ijk[:, 1] * s1 + ijk[:, 2]
        grid[flat] = True
        if subvoxel:
            pts -= ijk
            pts *= 255.0
            samples.append((flat.astype(np.int32), (pts + 0.5).astype(np.uint8)))
    surf = grid.reshape(tuple(dims))
    closed = _dilate(surf, iters)
    closed = _erode(closed, iters)
    closed |= surf
    labels, _ = ndi.label(~closed)  # 6-connectivity for the outside
    filled = labels != labels[0, 0, 0]
    del labels, closed
    stats: tuple = (None, None, None)
    if subvoxel:
        # statistics only where the weights need them: cells with an exposed
        # face (mean position), cells exposed on both sides of an axis (spread)
        exposed = np.zeros(filled.shape, bool)
        thin = np.zeros(filled.shape, bool)
        for up, down in _exposures(filled):
            exposed |= up | down
            thin |= up & down
        stats = _cell_statistics(grid & exposed.reshape(-1), thin.reshape(-1), samples)
        del samples
    return VoxelGrid(surf, filled, origin, h, iters, *stats)


def _exposures(filled: np.ndarray) -> Iterable[tuple[np.ndarray, np.ndarray]]:
    """Per axis, (up, down): filled cells whose +axis / -axis neighbour is
    empty (boolean grids of the shape of ``filled``; the grid is padded, so
    border cells are empty)."""
    for ax in range(3):
        lo_sl = [slice(None)] * 3
        hi_sl = [slice(None)] * 3
        lo_sl[ax] = slice(0, -1)
        hi_sl[ax] = slice(1, None)
        lo_sl, hi_sl = tuple(lo_sl), tuple(hi_sl)
        up = np.zeros(filled.shape, bool)
        down = np.zeros(filled.shape, bool)
        up[lo_sl] = filled[lo_sl] & ~filled[hi_sl]
        down[hi_sl] = filled[hi_sl] & ~filled[lo_sl]
        yield up, down


def _cell_statistics(
    wanted: np.ndarray, thin: np.ndarray, samples: list[tuple[np.ndarray, np.ndarray]]
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per wanted surface cell (flat mask ``wanted``): flat index (S,), mean
    in-cell sample position (S, 3) and, for cells also in ``thin``, the
    unexplained spread along each axis (S, 3; 0 elsewhere), see
    :class:`VoxelGrid`. ``samples``: (cell (P,) int32, in-cell position *
    255 (P, 3) uint8)."""
    cells = np.flatnonzero(wanted)
    n = cells.size
    cell_id = np.cumsum(wanted, dtype=np.int32) - 1
    need_cov = thin & wanted
    count = np.zeros(n)
    first = np.zeros((3, n))
    second = np.zeros((6, n))
    pairs = ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))
    for flat, frac in samples:
        sel = wanted[flat]
        ids = cell_id[flat[sel]]
        pos = frac[sel].astype(np.float64) / 255.0
        count += np.bincount(ids, minlength=n)
        for k in range(3):
            first[k] += np.bincount(ids, weights=pos[:, k], minlength=n)
        sel2 = need_cov[flat[sel]]
        if sel2.any():
            ids2, pos2 = ids[sel2], pos[sel2]
            for m, (a, b) in enumerate(pairs):
                second[m] += np.bincount(ids2, weights=pos2[:, a] * pos2[:, b], minlength=n)
    del cell_id
    count = np.maximum(count, 1.0)
    mean = first / count
    thickness = np.zeros((3, n))
    rows = np.flatnonzero(need_cov[cells])
    if rows.size:
        c = count[rows]
        m = mean[:, rows]
        cov = np.empty((3, 3, rows.size))
        for q, (a, b) in enumerate(pairs):
            cov[a, b] = cov[b, a] = second[q, rows] / c - m[a] * m[b]
        det = (
            cov[0, 0] * (cov[1, 1] * cov[2, 2] - cov[1, 2] ** 2)
            - cov[0, 1] * (cov[0, 1] * cov[2, 2] - cov[1, 2] * cov[0, 2])
            + cov[0, 2] * (cov[0, 1] * cov[1, 2] - cov[1, 1] * cov[0, 2])
        )
        for k in range(3):
            i, j = [a for a in range(3) if a != k]
            minor = cov[i, i] * cov[j, j] - cov[i, j] ** 2  # det of the other two axes
            ok = (minor > 1e-6) & (c >= 4)
            resid = np.where(ok, det / np.where(ok, minor, 1.0), 0.0)  # Schur complement
            thickness[k, rows] = np.clip(2.0 * np.sqrt(np.maximum(resid, 0.0)), 0.0, 1.0)
    return cells, mean.T.astype(np.float32), thickness.T.astype(np.float32)


def voxel_properties(
    vertices: np.ndarray,
    faces: np.ndarray,
    *,
    voxels_per_axis: int = VOXELS_PER_AXIS,
    max_voxels: int = MAX_VOXELS,
    close_gaps: float = CLOSE_GAPS,
    layer_correction: float = LAYER_CORRECTION,
    sample_spacing: float = SAMPLE_SPACING,
    grid_shift: tuple[float, float, float] = (0.0, 0.0, 0.0),
    subvoxel: bool = True,
) -> SolidMoments:
    """Solid enclosed by a triangle soup (any topology), by voxelization.

    Args:
        vertices: (N, 3) m. faces: (M, 3) int, valid.
        voxels_per_axis, max_voxels, close_gaps, sample_spacing, grid_shift:
            see :func:`voxelize`.
        subvoxel: weight the cells at the surface by the mean position of
            their surface samples (default); else each filled cell counts
            w = 1 - layer_correction * exposed_faces (see module doc).
        layer_correction: outside part of a cell per exposed face when
            ``subvoxel`` is False.

    Returns:
        ``SolidMoments`` (method ``voxel_fill``, ``pitch`` m). Cell weights
        are clipped to [0, 1]. Volume is sum(w) * pitch^3; com and second moment are weighted voxel moments,
        each voxel a uniform cube (pitch^2/12 per axis). Volume 0 when
        nothing is enclosed (then com is the bounding-box center).

    Raises:
        ValueError: all vertices coincide.
    """
    lo, hi = vertices.min(axis=0), vertices.max(axis=0)
    vg = voxelize(
        vertices,
        faces,
        voxels_per_axis=voxels_per_axis,
        max_voxels=max_voxels,
        close_gaps=close_gaps,
        sample_spacing=sample_spacing,
        grid_shift=grid_shift,
        subvoxel=subvoxel,
    )
    filled, h, origin, iters, dims = vg.filled, vg.pitch, vg.origin, vg.closing, vg.filled.shape
    # weight of every cell: 0 outside; inside, 1 minus the part of the cell
    # beyond the surface on each exposed face (see module doc)
    weight = np.ones(filled.shape, np.float32)
    flat_weight = weight.reshape(-1)
    for ax, (up, down) in enumerate(_exposures(filled)):
        if vg.cells is None:
            weight -= layer_correction * up
            weight -= layer_correction * down
            continue
        both = up & down  # one cell thick along ax: the surfaces' separation is inside
        for mask, kind in ((up & ~both, "up"), (down & ~both, "down"), (both, "both")):
            idx = np.flatnonzero(mask)
            if idx.size == 0:
                continue
            at = np.minimum(np.searchsorted(vg.cells, idx), max(vg.cells.size - 1, 0))
            known = vg.cells[at] == idx if vg.cells.size else np.zeros(idx.size, bool)
            if kind == "up":  # cells added by the closing have no samples: half a cell
                outside = np.where(known, 1.0 - vg.mean[at, ax], 0.5) if vg.cells.size else 0.5
            elif kind == "down":
                outside = np.where(known, vg.mean[at, ax], 0.5) if vg.cells.size else 0.5
            else:
                outside = np.where(known, 1.0 - vg.thickness[at, ax], 1.0) if vg.cells.size else 1.0
            flat_weight[idx] -= np.asarray(outside, np.float32)
    np.clip(weight, 0.0, 1.0, out=weight)
    weight *= filled
    notes = [f"voxel pitch {h:.4g} m ({int(dims[0])}x{int(dims[1])}x{int(dims[2])} grid), gap closing {iters} voxel(s)"]
    # moments from the 2-D projections of the weight grid (one pass each)
    w_xy = weight.sum(axis=2, dtype=np.float64)
    w_xz = weight.sum(axis=1, dtype=np.float64)
    w_yz = weight.sum(axis=0, dtype=np.float64)
    wx, wy, wz = w_xy.sum(axis=1), w_xy.sum(axis=0), w_xz.sum(axis=0)
    total = float(wx.sum())
    if total <= 0:
        return SolidMoments(0.0, 0.5 * (lo + hi), np.zeros((3, 3)), "voxel_fill", notes, h)
    ref = 0.5 * (lo + hi)
    x, y, z = ((np.arange(dims[k]) + 0.5) * h + origin[k] - ref[k] for k in range(3))
    com = np.array([wx @ x, wy @ y, wz @ z]) / total
    x, y, z = x - com[0], y - com[1], z - com[2]
    cov = np.empty((3, 3))
    cov[0, 0], cov[1, 1], cov[2, 2] = wx @ (x * x), wy @ (y * y), wz @ (z * z)
    cov[0, 1] = cov[1, 0] = x @ w_xy @ y
    cov[0, 2] = cov[2, 0] = x @ w_xz @ z
    cov[1, 2] = cov[2, 1] = y @ w_yz @ z
    cov = cov / total + (h * h / 12.0) * np.eye(3)
    return SolidMoments(total * h**3, com + ref, cov, "voxel_fill", notes, h)


def _dilate(grid: np.ndarray, iters: int) -> np.ndarray:
    """Binary dilation by a 3x3x3 cube, ``iters`` times (separable: a
    1-voxel OR along each axis in turn). Cells beyond the border count as
    empty."""
    out = grid.copy()
    for _ in range(iters):
        for ax in range(3):
            src = out.copy()
            a = [slice(None)] * 3
            b = [slice(None)] * 3
            a[ax], b[ax] = slice(1, None), slice(0, -1)
            out[tuple(a)] |= src[tuple(b)]
            out[tuple(b)] |= src[tuple(a)]
    return out


def _erode(grid: np.ndarray, iters: int) -> np.ndarray:
    """Binary erosion by a 3x3x3 cube, ``iters`` times (separable AND along
    each axis). Cells beyond the border count as full, so erosion never eats
    in from the grid boundary."""
    out = grid.copy()
    for _ in range(iters):
        for ax in range(3):
            src = out.copy()
            a = [slice(None)] * 3
            b = [slice(None)] * 3
            a[ax], b[ax] = slice(1, None), slice(0, -1)
            out[tuple(a)] &= src[tuple(b)]
            out[tuple(b)] &= src[tuple(a)]
    return out


# ----------------------------------------------------------------- analytic


def _analytic_primitive(ref: GeometryRef) -> tuple[float, float, np.ndarray, np.ndarray] | None:
    """(volume, area, solid C, shell C) in the primitive's own frame, or None
    when the scale is not (1, 1, 1) (then the tessellated mesh is used).
    Standard formulas (e.g. Meriam & Kraige, Engineering Mechanics: Dynamics,
    Appendix B)."""
    if tuple(ref.scale) != (1.0, 1.0, 1.0):
        return None
    if ref.kind == "box":
        a, b, c = ref.size
        vol, area = a * b * c, 2 * (a * b + b * c + c * a)
        solid = np.diag([a * a, b * b, c * c]) / 12.0
        # shell: for each axis, the two faces normal to it (area v*w each, at
        # +-u/2) add 2vw (u/2)^2 along the axis and 2vw d^2/12 along the
        # other two axes d = v, w
        shell = np.zeros(3)
        for axis, (u, v, w) in enumerate([(a, b, c), (b, a, c), (c, a, b)]):
            plate = 2 * v * w
            others = [k for k in range(3) if k != axis]
            shell[axis] += plate * (u / 2.0) ** 2
            shell[others[0]] += plate * v * v / 12.0
            shell[others[1]] += plate * w * w / 12.0
        return vol, area, solid, np.diag(shell / area)
    if ref.kind == "cylinder":
        r, length = ref.radius, ref.length
        vol = math.pi * r * r * length
        side, caps = 2 * math.pi * r * length, 2 * math.pi * r * r
        area = side + caps
        solid = np.diag([r * r / 4, r * r / 4, length * length / 12])
        # side: E[x^2] = r^2/2, E[z^2] = L^2/12; caps (discs at z = +-L/2):
        # E[x^2] = r^2/4, E[z^2] = L^2/4
        shell_xx = (side * r * r / 2 + caps * r * r / 4) / area
        shell_z = (side * length * length / 12 + caps * length * length / 4) / area
        return vol, area, solid, np.diag([shell_xx, shell_xx, shell_z])
    if ref.kind == "sphere":
        r = ref.radius
        return 4.0 / 3.0 * math.pi * r**3, 4 * math.pi * r * r, np.eye(3) * r * r / 5, np.eye(3) * r * r / 3
    return None


# ----------------------------------------------------------------- analysis


def _tup3(a: np.ndarray) -> tuple[float, float, float]:
    return (float(a[0]), float(a[1]), float(a[2]))


def _tup33(m: np.ndarray):
    return tuple(_tup3(row) for row in m)


def _shift(cov: np.ndarray, frm: np.ndarray, to: np.ndarray) -> np.ndarray:
    """Second moment about ``to`` from the central one about ``frm`` (parallel axis)."""
    d = np.asarray(frm) - np.asarray(to)
    return cov + np.outer(d, d)


def analyze_link(
    link: LinkDesc,
    *,
    prefer: Literal["collision", "visual"] = "collision",
    voxels_per_axis: int = VOXELS_PER_AXIS,
    max_voxels: int = MAX_VOXELS,
    close_gaps: float = CLOSE_GAPS,
    layer_correction: float = LAYER_CORRECTION,
    subvoxel: bool = True,
    cache: MeshCache | None = None,
) -> LinkGeometry | None:
    """Mesh analysis of one link at scale 1 in the link frame.

    Args:
        link: the link; its collision geometry is used when it has any, else
            its visual geometry (``prefer="visual"`` swaps the order).
        voxels_per_axis, max_voxels, close_gaps, layer_correction, subvoxel:
            the voxel estimate's parameters (see :func:`voxel_properties`).
        cache: meshes already read (shared across links by
            :func:`analyze_asset`).

    Returns:
        ``LinkGeometry`` (lengths m, area m^2, volume m^3, per-kg inertias
        m^2 about ``com``), or ``None`` for a link without geometry.
        ``volume_method`` is one of ``analytic_primitive``,
        ``watertight_exact``, ``voxel_union`` (closed parts that overlap),
        ``voxel_fill`` (polygon soup), with ``+open_shell`` appended when
        the surface encloses (almost) nothing (then ``com`` is the surface
        centroid and ``inertia_solid`` equals ``inertia_shell``). ``notes``
        say which geometry was used and what was dropped or regularised.

    Raises:
        MeshAnalysisError: no usable geometry (unreadable or degenerate
            meshes), or the usable surface has zero area; names the link and
            files.
    """
    surf = link_surface(link, prefer=prefer, cache=cache)
    if surf is None:
        return None
    v, f = surf.vertices, surf.faces
    notes = list(surf.notes)
    notes.append(f"geometry: {surf.role} ({len(surf.sources)} element(s))")
    bmin, bmax = v.min(axis=0), v.max(axis=0)  # every vertex is used (link_surface)
    size = float(np.max(bmax - bmin))
    area, s_centroid, s_cov = surface_properties(v, f)
    where = f"link {link.name!r} ({surf.role}: {', '.join(surf.sources[:3])}{' ...' if len(surf.sources) > 3 else ''})"
    if not (area > 0 and size > 0 and math.isfinite(area)):
        raise MeshAnalysisError(f"{where}: degenerate geometry (surface area {area:g} m^2, size {size:g} m)")

    vox_kw = dict(
        voxels_per_axis=voxels_per_axis,
        max_voxels=max_voxels,
        close_gaps=close_gaps,
        layer_correction=layer_correction,
        subvoxel=subvoxel,
    )
    watertight = False
    solid: SolidMoments | None = None
    analytic = None
    if len(surf.refs) == 1 and surf.kinds[0] != "mesh":
        analytic = _analytic_primitive(surf.refs[0])
    if analytic is not None:
        ref = surf.refs[0]
        rot = rpy_matrix(ref.origin.rpy)
        vol, area, c_solid, c_shell = analytic
        centre = np.asarray(ref.origin.xyz, np.float64)
        solid = SolidMoments(vol, centre, rot @ c_solid @ rot.T, "analytic_primitive")
        s_centroid, s_cov = centre, rot @ c_shell @ rot.T
        watertight = True
    else:
        if any(k != "mesh" for k in surf.kinds):
            notes.append(
                "primitives tessellated (cylinder: 128 sections, volume -0.04%; sphere: 5120-face icosphere, volume -0.2%)"
            )
        solid = watertight_properties(v, f)
        if solid is not None:
            watertight = True
            if solid.overlap_candidates:
                union = voxel_properties(v, f, **vox_kw)
                # the voxel estimate's error is ~1-3% (docs/mesh_analysis.md)
                if union.volume < 0.95 * solid.volume:
                    notes.append(
                        f"closed parts overlap: sum of part volumes {solid.volume:.4g} m^3, "
                        f"voxel union {union.volume:.4g} m^3 used"
                    )
                    union.method = "voxel_union"
                    union.notes = solid.notes + union.notes
                    solid = union
        if solid is None:
            solid = voxel_properties(v, f, **vox_kw)
        notes.extend(solid.notes)
    pitch = solid.pitch or _grid_pitch(bmax - bmin, voxels_per_axis, max_voxels, 3)
    method = solid.method
    volume = max(0.0, float(solid.volume))
    if volume < OPEN_SHELL_FRACTION * area * pitch:
        method += "+open_shell"
        notes.append(
            "open shell: the surface encloses (almost) no volume; com is the surface centroid and "
            "inertia_solid equals inertia_shell (use area x wall thickness for mass)"
        )
        com = s_centroid
        c_solid = s_cov
    else:
        com = solid.com
        c_solid = solid.second
    c_shell = _shift(s_cov, s_centroid, com)
    sep = float(np.linalg.norm(s_centroid - com))
    if sep > 0.01 * size:
        notes.append(f"surface centroid {np.round(s_centroid, 6).tolist()} m differs from com by {sep:.4g} m")
    i_solid, reg_s = regularize_inertia(inertia_from_second_moment(c_solid), size * size)
    i_shell, reg_h = regularize_inertia(inertia_from_second_moment(c_shell), size * size)
    if reg_s or reg_h:
        which = " and ".join(n for n, r in (("inertia_solid", reg_s), ("inertia_shell", reg_h)) if r)
        notes.append(f"{which}: flat or line-like geometry, isotropic {REGULARIZATION:g} x trace regularisation added")
    return LinkGeometry(
        link=link.name,
        volume=volume,
        volume_method=method,
        watertight=watertight,
        area=float(area),
        bbox_min=_tup3(bmin),
        bbox_max=_tup3(bmax),
        com=_tup3(com),
        inertia_solid=_tup33(i_solid),
        inertia_shell=_tup33(i_shell),
        n_meshes=len(surf.sources),
        n_faces=int(len(f)),
        notes=notes,
    )


def analyze_asset(asset: AssetDescription, **options) -> dict[str, LinkGeometry]:
    """:func:`analyze_link` for every link of ``asset`` that has geometry,
    keyed by link name (asset order). Meshes are read once per call (shared
    :class:`MeshCache`). ``options`` are passed to :func:`analyze_link`.

    Raises:
        MeshAnalysisError: a link with geometry has no usable geometry.
    """
    options.setdefault("cache", MeshCache())
    out: dict[str, LinkGeometry] = {}
    for link in asset.links:
        geo = analyze_link(link, **options)
        if geo is not None:
            out[link.name] = geo
    return out
