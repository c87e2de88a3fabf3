"""Voxel volume of polygon soups (surface sampling, gap closing, flood fill, sub-voxel weights) for
:mod:`asset2sim.tasks.geometry.analyze`; method and accuracy in ``docs/design/mesh_analysis.md``.
Lengths in the mesh's units (m at scale 1).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Iterable

import numpy as np

from asset2sim.tasks.geometry.moments import FACE_BATCH, SolidMoments

__all__ = ["CLOSE_GAPS", "LAYER_CORRECTION", "MAX_VOXELS", "SAMPLE_SPACING", "VOXELS_PER_AXIS", "VoxelGrid", "grid_pitch",
           "mean_size", "voxel_properties", "voxelize"]

#: Default number of voxels along the link's length scale (:func:`mean_size`).
VOXELS_PER_AXIS = 96
#: Default cap on the total number of grid cells (peak memory about 20 bytes per cell).
MAX_VOXELS = 3_000_000
#: Default gap closing, as a fraction of the link's length scale (:func:`mean_size`).
CLOSE_GAPS = 0.02
#: Outside part of a cell per exposed face when sub-voxel positions are off.
LAYER_CORRECTION = 0.5
#: Surface sampling spacing, in voxel pitches.
SAMPLE_SPACING = 0.5

_CHUNK_POINTS = 1 << 21  # lattice points per rasterization batch (48 MB of float64)


def _surface_points(tri: np.ndarray, spacing: float) -> Iterable[np.ndarray]:
    """Points (P, 3) covering triangles (T, 3, 3) with spacing <= ``spacing``, in batches of about
    ``_CHUNK_POINTS``: small triangles give their vertices, larger ones rows parallel to their longest
    edge (ceil(height / spacing) + 1 rows, each split into segments <= spacing)."""
    edges = np.stack([np.linalg.norm(tri[:, 2] - tri[:, 1], axis=1), np.linalg.norm(tri[:, 0] - tri[:, 2], axis=1),
                      np.linalg.norm(tri[:, 1] - tri[:, 0], axis=1)], axis=1)  # edge i is opposite vertex i
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
    """The length scale (m) of a link for voxelization: the geometric mean of its bounding-box
    extents (3,), each taken at least 1/16 of the longest."""
    return float(np.prod(np.maximum(ext, float(np.max(ext)) / 16.0))) ** (1.0 / 3.0)


def grid_pitch(ext: np.ndarray, voxels_per_axis: int, max_voxels: int, pad: int) -> float:
    """Voxel pitch (m) for extents ``ext`` (3,) m: :func:`mean_size` / ``voxels_per_axis``, grown by 5 %
    steps until the grid padded by ``pad`` cells each side has at most ``max_voxels`` cells."""
    h = mean_size(ext) / voxels_per_axis
    for _ in range(60):
        cells = np.prod(np.ceil(ext / h) + 2 * pad + 2)
        if cells <= max_voxels:
            return h
        h *= 1.05
    return h  # pragma: no cover


@dataclass
class VoxelGrid:
    """A voxelized link: ``surface`` and ``filled`` boolean grids (nx, ny, nz), cell (i, j, k) spanning
    ``origin + pitch * [i, i+1) x ...`` (m); ``closing`` the 3x3x3 closing iterations applied.
    Sub-voxel statistics (else ``None``) of the S surface cells: ``cells`` (S,) sorted flat indices,
    ``mean`` (S, 3) mean in-cell sample position and ``thickness`` (S, 3) 2 sqrt(var(x_k | x_i, x_j))
    of the samples (cell units)."""

    surface: np.ndarray
    filled: np.ndarray
    origin: np.ndarray
    pitch: float
    closing: int
    cells: np.ndarray | None = None
    mean: np.ndarray | None = None
    thickness: np.ndarray | None = None


def voxelize(vertices: np.ndarray, faces: np.ndarray, *, voxels_per_axis: int = VOXELS_PER_AXIS, max_voxels: int = MAX_VOXELS,
             grid_shift: tuple[float, float, float] = (0.0, 0.0, 0.0), subvoxel: bool = True) -> VoxelGrid:
    """Voxelize a triangle soup and fill what it encloses.

    Args:
        vertices: (N, 3) m. faces: (M, 3) int, valid.
        voxels_per_axis: voxels along the length scale (:func:`grid_pitch`, at most ``max_voxels`` cells).
        grid_shift: (3,) shift of the grid against the geometry, in pitches, each in [0, 1).
        subvoxel: record per-cell sample statistics (``VoxelGrid.cells``, ``mean``, ``thickness``).

    Gaps up to :data:`CLOSE_GAPS` of the length scale (:func:`mean_size`) are closed (3x3x3 closing, one
    iteration per 2 voxels of gap, at least one); the surface is sampled every :data:`SAMPLE_SPACING` pitches.

    Returns:
        :class:`VoxelGrid`, padded by closing + 2 empty cells, the bounding box's extreme faces on cell centers.

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
    h = grid_pitch(ext, voxels_per_axis, max_voxels, 3)
    iters = max(1, int(math.ceil(CLOSE_GAPS * mean_size(ext) / (2.0 * h) - 1e-9)))
    pad = iters + 2
    h = grid_pitch(ext, voxels_per_axis, max_voxels, pad)
    # the bounding box's extreme faces on voxel centers: half a voxel of inflation
    dims = np.ceil(ext / h).astype(np.int64) + 2 * pad + 2
    origin = lo - (pad + 0.5 - np.asarray(grid_shift, np.float64)) * h
    ncell = int(np.prod(dims))
    s0, s1 = int(dims[1] * dims[2]), int(dims[2])
    grid = np.zeros(ncell, bool)
    samples: list[tuple[np.ndarray, np.ndarray]] = []  # (cell (P,) int32, in-cell position (P, 3) uint8)
    # in voxel units: cell (i, j, k) is [i, i+1) x [j, j+1) x [k, k+1)
    vox = ((vertices - origin) / h).astype(np.float32)

    def batches() -> Iterable[np.ndarray]:
        for s in range(0, len(faces), FACE_BATCH):
            fc = faces[s : s + FACE_BATCH]
            tri = vox[fc]
            edge = np.max(np.abs(tri - tri[:, [1, 2, 0]]).sum(axis=2), axis=1)  # >= longest edge
            small = edge <= SAMPLE_SPACING
            if small.any():  # triangles smaller than the spacing: their vertices, once each
                yield vox[np.unique(fc[small])]
            if not small.all():
                yield from _surface_points(tri[~small], SAMPLE_SPACING)

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
    closed = _morph(_morph(surf, iters, np.logical_or), iters, np.logical_and)
    closed |= surf
    labels, _ = ndi.label(~closed)  # 6-connectivity for the outside
    filled = labels != labels[0, 0, 0]
    del labels, closed
    stats: tuple = (None, None, None)
    if subvoxel:
        # statistics where the weights need them: exposed cells (mean), cells exposed both ways (spread)
        exposed, thin = np.zeros((2, *filled.shape), bool)
        for up, down in _exposures(filled):
            exposed |= up | down
            thin |= up & down
        stats = _cell_statistics(grid & exposed.reshape(-1), thin.reshape(-1), samples)
        del samples
    return VoxelGrid(surf, filled, origin, h, iters, *stats)


def _exposures(filled: np.ndarray) -> Iterable[tuple[np.ndarray, np.ndarray]]:
    """Per axis, (up, down): the filled cells whose +axis / -axis neighbour is empty."""
    for ax in range(3):
        lo_sl = tuple(slice(0, -1) if k == ax else slice(None) for k in range(3))
        hi_sl = tuple(slice(1, None) if k == ax else slice(None) for k in range(3))
        up, down = np.zeros((2, *filled.shape), bool)
        up[lo_sl] = filled[lo_sl] & ~filled[hi_sl]
        down[hi_sl] = filled[hi_sl] & ~filled[lo_sl]
        yield up, down


def _cell_statistics(wanted: np.ndarray, thin: np.ndarray,
                     samples: list[tuple[np.ndarray, np.ndarray]]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:class:`VoxelGrid`'s ``cells``, ``mean`` and ``thickness`` (0 outside ``thin``) of the cells of the
    flat mask ``wanted``; ``samples``: (cell (P,) int32, in-cell position * 255 (P, 3) uint8)."""
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
        # (3, P): a row per axis, as bincount takes its weights
        pos = np.ascontiguousarray(frac[sel].T) / 255.0
        count += np.bincount(ids, minlength=n)
        for k in range(3):
            first[k] += np.bincount(ids, weights=pos[k], minlength=n)
        sel2 = need_cov[flat[sel]]
        if sel2.any():
            ids2, pos2 = ids[sel2], pos[:, sel2]
            for m, (a, b) in enumerate(pairs):
                second[m] += np.bincount(ids2, weights=pos2[a] * pos2[b], minlength=n)
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


def voxel_properties(vertices: np.ndarray, faces: np.ndarray, *, voxels_per_axis: int = VOXELS_PER_AXIS,
                     max_voxels: int = MAX_VOXELS, grid_shift: tuple[float, float, float] = (0.0, 0.0, 0.0),
                     subvoxel: bool = True) -> SolidMoments:
    """Solid enclosed by a triangle soup (any topology), by voxelization.

    Args: as for :func:`voxelize`; ``subvoxel``: weight the surface cells by the mean position of their
    samples, else each filled cell counts w = 1 - :data:`LAYER_CORRECTION` * exposed_faces.

    Returns ``SolidMoments`` (method ``voxel_fill``, ``pitch`` m): volume sum(w) * pitch^3 (w in [0, 1]),
    com and second moment of the weighted cells (uniform cubes); volume 0 when nothing is enclosed.
    Raises ValueError when all vertices coincide.
    """
    lo, hi = vertices.min(axis=0), vertices.max(axis=0)
    vg = voxelize(vertices, faces, voxels_per_axis=voxels_per_axis, max_voxels=max_voxels, grid_shift=grid_shift,
                  subvoxel=subvoxel)
    filled, h, origin, iters, dims = vg.filled, vg.pitch, vg.origin, vg.closing, vg.filled.shape
    # weight: 0 outside; inside, 1 minus the part of the cell beyond the surface on each exposed face
    weight = np.ones(filled.shape, np.float32)
    flat_weight = weight.reshape(-1)
    for ax, (up, down) in enumerate(_exposures(filled)):
        if vg.cells is None:
            weight -= LAYER_CORRECTION * up
            weight -= LAYER_CORRECTION * down
            continue
        both = up & down  # one cell thick along ax: the surfaces' separation is inside
        # (cells, the part outside of a cell with samples, of one without: cells added by the closing, half a cell)
        for mask, known, unknown in ((up & ~both, lambda at: 1.0 - vg.mean[at, ax], 0.5),
                                     (down & ~both, lambda at: vg.mean[at, ax], 0.5),
                                     (both, lambda at: 1.0 - vg.thickness[at, ax], 1.0)):
            idx = np.flatnonzero(mask)
            if idx.size == 0:
                continue
            at = np.minimum(np.searchsorted(vg.cells, idx), max(vg.cells.size - 1, 0))
            outside = np.where(vg.cells[at] == idx, known(at), unknown) if vg.cells.size else unknown
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


def _morph(grid: np.ndarray, iters: int, op) -> np.ndarray:
    """Binary dilation (``op`` = np.logical_or) or erosion (np.logical_and) of ``grid`` by a 3x3x3 cube,
    ``iters`` times, separably; cells beyond the border count as empty, resp. full."""
    out = grid.copy()
    for _ in range(iters):
        for ax in range(3):
            src = out.copy()
            a = [slice(None)] * 3
            b = [slice(None)] * 3
            a[ax], b[ax] = slice(1, None), slice(0, -1)
            for dst, shifted in ((tuple(a), tuple(b)), (tuple(b), tuple(a))):
                view = out[dst]
                op(view, src[shifted], out=view)
    return out
