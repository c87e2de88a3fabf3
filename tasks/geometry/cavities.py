"""Open cavities of a part: space inside the part's convex hull that is
reachable from outside its surface, such as the inside of a bucket, a drawer
box, a refrigerator's compartment or a toilet bowl. A simulator collides an
OBJ group with its convex hull, so one hull per such part is solid where the
container should be empty and nothing can be put into it.

The part is voxelized (:func:`asset2sim.tasks.geometry.voxels.voxelize`:
surface sampling, gap closing, flood fill from outside); the cavity is the
empty space connected to the outside that lies inside the hull, and its size
is the radius of the largest ball it holds (Euclidean distance transform).
Its core (the cells deep inside it) may lie in several connected regions, each
with its own mouth, such as a toilet body's bowl, open upward, and the space
under its rim, open downward.
Lengths in the mesh's units (m for a link's geometry at its output scale).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from asset2sim.tasks.geometry.voxels import voxelize

__all__ = ["CAVITY_VOXELS", "CORE_DEPTH", "MAX_CORE_POINTS", "MIN_CAVITY_RADIUS", "MIN_CAVITY_SHARE", "MIN_CAVITY_VOLUME_SHARE", "Cavity",
           "CavityRegion",
           "open_cavity", "open_fraction"]

#: Voxels along the part's length scale (:func:`asset2sim.tasks.geometry.voxels.mean_size`).
CAVITY_VOXELS = 40
#: Smallest cavity that counts, m: the radius of the largest ball it holds (a 3 cm object fits in it).
MIN_CAVITY_RADIUS = 0.015
#: Smallest cavity that counts, as that radius over the part's largest extent (a dent in a large part is no container).
MIN_CAVITY_SHARE = 0.06
#: Smallest cavity that counts, as its volume over the part's hull's (a container is mostly its inside; a pocket
#: in a larger part, such as a toilet's tank recess or a suitcase shell's shallow inside, is no container).
MIN_CAVITY_VOLUME_SHARE = 0.4
#: The cavity's core, whose points collision pieces must leave free: cells at least this share of the largest ball's
#: radius from the cavity's boundary (the walls a decomposition thickens stay outside it).
CORE_DEPTH = 0.5
#: Most core points kept (every k-th cell in grid order beyond it).
MAX_CORE_POINTS = 4000


@dataclass(frozen=True)
class CavityRegion:
    """One connected region of an open cavity's core (the cavity's empty space falls apart into such regions, as a
    toilet body's bowl and the space under its rim): ``radius`` m of the largest ball inside it, ``volume`` m^3 of
    its cells, and ``mouth`` (3,), the unit direction from the region's centre to its opening (the cells of the
    hull's boundary next to the region that the part leaves open; zero when none is found), in the part's frame."""

    radius: float
    volume: float
    mouth: np.ndarray


@dataclass(frozen=True)
class Cavity:
    """An open cavity of a part: ``radius`` m of the largest ball inside it, ``volume`` m^3, ``hull_volume`` m^3 of the
    part's convex hull (both counted in voxels), ``core`` (K, 3) m points of its core (cell centers, :data:`CORE_DEPTH`),
    and ``regions``, the connected regions the core lies in (:class:`CavityRegion`); in the part's frame."""

    radius: float
    volume: float
    hull_volume: float
    core: np.ndarray
    regions: tuple[CavityRegion, ...]


def open_cavity(vertices: np.ndarray, faces: np.ndarray, hull_vertices: np.ndarray,
                hull_faces: np.ndarray) -> Cavity | None:
    """The open cavity inside a part's convex hull (``hull_vertices`` (U, 3) m, ``hull_faces`` (G, 3) int, a closed
    triangle mesh) that the surfaces ``vertices`` (V, 3) m, ``faces`` (F, 3) int (the part's and any around it that
    may close it, such as the other parts of its link) leave open to the outside, or None when it holds no ball of
    radius :data:`MIN_CAVITY_RADIUS` m and :data:`MIN_CAVITY_SHARE` of the hull's largest extent, or fills less
    than :data:`MIN_CAVITY_VOLUME_SHARE` of the hull.

    The surfaces alone and with the hull are voxelized on the same grid (:data:`CAVITY_VOXELS`; the hull's vertices must
    lie in the surfaces' bounding box): the cavity is the space the hull encloses that the surfaces alone leave open.

    Raises:
        ValueError: all vertices coincide, or the hull reaches out of the surfaces' bounding box.
    """
    from scipy import ndimage as ndi

    v = np.asarray(vertices, float)
    f = np.asarray(faces, np.int64)
    hv = np.asarray(hull_vertices, float)
    size = float(np.ptp(hv, axis=0).max()) if len(hv) else 0.0
    need = max(MIN_CAVITY_RADIUS, MIN_CAVITY_SHARE * size)
    part = voxelize(v, f, voxels_per_axis=CAVITY_VOXELS, subvoxel=False)
    both = voxelize(np.vstack([v, hv]), np.vstack([f, np.asarray(hull_faces, np.int64) + len(v)]),
                    voxels_per_axis=CAVITY_VOXELS, subvoxel=False)
    if part.filled.shape != both.filled.shape or not np.array_equal(part.origin, both.origin):
        raise ValueError("the hull reaches out of the surfaces' bounding box")
    cavity = both.filled & ~both.surface & ~part.filled
    if not cavity.any():
        return None
    h = part.pitch
    depth = ndi.distance_transform_edt(cavity)  # cells to the nearest non-cavity cell
    deepest = float(depth.max())
    radius = deepest * h
    volume, hull_volume = float(cavity.sum()) * h**3, float(both.filled.sum()) * h**3
    if radius < need or volume < MIN_CAVITY_VOLUME_SHARE * hull_volume:
        return None
    core_cells = depth >= max(1.0, CORE_DEPTH * deepest)
    core = np.argwhere(core_cells)
    if len(core) > MAX_CORE_POINTS:
        core = core[:: -(-len(core) // MAX_CORE_POINTS)]
    # the connected regions the core lies in, each with its mouth: the hull's boundary cells next to the region
    # that the part leaves open
    labels, _ = ndi.label(cavity)
    opening = both.surface & ~part.filled
    regions = []
    for label in np.unique(labels[core_cells]):
        cells = labels == label
        mouth = np.argwhere(opening & ndi.binary_dilation(cells))
        way = mouth.mean(axis=0) - np.argwhere(cells).mean(axis=0) if len(mouth) else np.zeros(3)
        norm = float(np.linalg.norm(way))
        regions.append(CavityRegion(radius=float(depth[cells].max()) * h, volume=float(cells.sum()) * h**3,
                                    mouth=way / norm if norm > 0 else np.zeros(3)))
    return Cavity(radius=radius, volume=volume, hull_volume=hull_volume, core=part.origin + (core + 0.5) * h,
                  regions=tuple(regions))


def open_fraction(core: np.ndarray, pieces_equations: list[np.ndarray]) -> float:
    """The share of ``core`` (K, 3) m points inside none of the convex pieces (each (H, 4) outward planes), in [0, 1]."""
    pts = np.asarray(core, float)
    if len(pts) == 0:
        return 1.0
    held = np.zeros(len(pts), bool)
    for eq in pieces_equations:
        held |= np.max(pts @ eq[:, :3].T + eq[:, 3], axis=1) <= 0.0
    return float(1.0 - held.mean())
