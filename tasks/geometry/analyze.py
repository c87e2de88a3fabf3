"""Mesh-analysis stage: the geometry of each link, at scale 1, in the link frame.

For every link with geometry :func:`analyze_link` returns a
:class:`~asset2sim.schemas.asset.LinkGeometry`: enclosed volume, surface area,
bounding box, center of mass and two per-kg inertia tensors about it (solid;
thin shell), from the link's collision geometry (else its visual geometry).
The method (analytic primitive, exact watertight moments, voxel fill of
polygon soups, open shells) and its accuracy: ``docs/design/mesh_analysis.md``.
:mod:`.surface` builds the link's triangle surface, :mod:`.moments` the exact
moments and inertia helpers, :mod:`.voxels` the voxel volume.
"""

from __future__ import annotations

import hashlib
import math
from pathlib import Path
from typing import Literal

import numpy as np

from asset2sim import array_cache
from asset2sim.frames import rpy_matrix
from asset2sim.mesh_io import MeshCache
from asset2sim.schemas.asset import AssetDescription, GeometryRef, LinkDesc, LinkGeometry
from asset2sim.tasks.geometry.moments import (REGULARIZATION, SolidMoments, inertia_from_second_moment, regularize_inertia,
                                              single_sided, surface_properties, watertight_properties)
from asset2sim.tasks.geometry.surface import MeshAnalysisError, link_surface
from asset2sim.tasks.geometry.voxels import (CLOSE_GAPS, LAYER_CORRECTION, MAX_VOXELS, VOXELS_PER_AXIS, grid_pitch,
                                             voxel_properties)

__all__ = [
    "MeshAnalysisError", "MeshCache", "link_surface", "surface_properties", "watertight_properties", "voxel_properties",
    "OPEN_SHELL_FRACTION", "VOXELS_PER_AXIS", "analyze_link", "analyze_asset",
]

#: Enclosed volume below OPEN_SHELL_FRACTION * area * pitch counts as "encloses nothing".
OPEN_SHELL_FRACTION = 0.1


def _analytic_primitive(ref: GeometryRef) -> tuple[float, float, np.ndarray, np.ndarray] | None:
    """(volume, area, solid C, shell C) in the primitive's own frame; None unless the scale is
    (1, 1, 1). Standard formulas (Meriam & Kraige, Engineering Mechanics: Dynamics, Appendix B)."""
    if tuple(ref.scale) != (1.0, 1.0, 1.0):
        return None
    if ref.kind == "box":
        a, b, c = ref.size
        vol, area = a * b * c, 2 * (a * b + b * c + c * a)
        solid = np.diag([a * a, b * b, c * c]) / 12.0
        # shell: the two faces normal to each axis add 2vw (u/2)^2 along it, 2vw d^2/12 along d = v, w
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
        # side: E[x^2] = r^2/2, E[z^2] = L^2/12; caps at z = +-L/2: E[x^2] = r^2/4, E[z^2] = L^2/4
        shell_xx = (side * r * r / 2 + caps * r * r / 4) / area
        shell_z = (side * length * length / 12 + caps * length * length / 4) / area
        return vol, area, solid, np.diag([shell_xx, shell_xx, shell_z])
    if ref.kind == "sphere":
        r = ref.radius
        return 4.0 / 3.0 * math.pi * r**3, 4 * math.pi * r * r, np.eye(3) * r * r / 5, np.eye(3) * r * r / 3
    return None


#: Modules whose source the analysis of a link depends on (part of the on-disk cache key).
ANALYSIS_CODE: tuple[str, ...] = (*(f"asset2sim.tasks.geometry.{m}" for m in ("analyze", "surface", "voxels", "moments")),
                                   "asset2sim.mesh_io", "asset2sim.frames", "asset2sim.schemas.asset")


def analyze_link(link: LinkDesc, *, prefer: Literal["collision", "visual"] = "collision",
                 cache: MeshCache | None = None) -> LinkGeometry | None:
    """Mesh analysis of one link at scale 1 in the link frame.

    Args:
        link: its collision geometry is used when it has any, else its visual geometry (``prefer="visual"`` swaps).
        cache: meshes already read (shared across links by :func:`analyze_asset`).

    A surface that is not watertight is voxelized by :func:`voxel_properties` at its defaults. Kept on disk
    (:mod:`asset2sim.array_cache`, kind ``analysis``); ``ASSET2SIM_CACHE=off`` turns it off.

    Returns:
        ``LinkGeometry`` (m, m^2, m^3, per-kg inertias m^2 about ``com``), or ``None`` without geometry;
        ``volume_method`` ``analytic_primitive``, ``watertight_exact``, ``voxel_union`` or ``voxel_fill``,
        + ``+open_shell`` when the surface encloses (almost) nothing.

    Raises:
        MeshAnalysisError: no usable geometry, or zero surface area; names the link and files.
    """
    if not link.has_geometry:
        return None
    params = (prefer, VOXELS_PER_AXIS, MAX_VOXELS, CLOSE_GAPS, LAYER_CORRECTION, True)  # True: subvoxel
    # the on-disk key: the digest of the link's name, its geometry elements as written (not where the folder lies), the
    # bytes of its mesh files, ``params`` and the source of ANALYSIS_CODE; None when one cannot be read
    parts: list[bytes | str] = [link.name, repr(params)]
    files: dict[Path, bytes] = {}  # a visual and a collision of PartNet-Mobility name the same file: read once
    try:
        parts.append(array_cache.source_digest(*ANALYSIS_CODE))
        for ref in (*link.collisions, *link.visuals):
            parts.append(ref.model_dump_json(exclude={"path"}))
            if ref.kind == "mesh" and ref.path is not None:
                path = Path(ref.path)
                if path not in files:
                    files[path] = hashlib.sha256(path.read_bytes()).digest()
                parts.append(files[path])
        key = array_cache.digest(*parts)
    except (OSError, ImportError):
        key = None
    hit = array_cache.load(DISK_KIND, key) if key is not None else None
    if hit is not None and "json" in hit:
        try:
            return LinkGeometry.model_validate(array_cache.array_json(hit["json"]))
        except ValueError:  # NaN or infinity in its JSON, UnicodeDecodeError and pydantic's ValidationError included
            pass  # an unreadable entry: computed again and rewritten
    geo = _analyze_surface(link, prefer, cache)
    if geo is not None and key is not None:
        array_cache.store(DISK_KIND, key, {"json": array_cache.text_array(geo.model_dump_json())})
    return geo


#: The on-disk cache's folder of link analyses (:mod:`asset2sim.array_cache`).
DISK_KIND = "analysis"


def _analyze_surface(link: LinkDesc, prefer, cache: MeshCache | None) -> LinkGeometry | None:
    """:func:`analyze_link` without the on-disk cache."""
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
    analytic = _analytic_primitive(surf.refs[0]) if len(surf.refs) == 1 and surf.refs[0].kind != "mesh" else None
    if analytic is not None:
        ref = surf.refs[0]
        rot = rpy_matrix(ref.origin.rpy)
        vol, area, c_solid, c_shell = analytic
        centre = np.asarray(ref.origin.xyz, np.float64)
        solid = SolidMoments(vol, centre, rot @ c_solid @ rot.T, "analytic_primitive")
        s_centroid, s_cov = centre, rot @ c_shell @ rot.T
        watertight = True
    else:
        if any(r.kind != "mesh" for r in surf.refs):
            notes.append("primitives tessellated (cylinder: 128 sections, volume -0.04%; sphere: 5120-face icosphere, volume -0.2%)")
        solid = watertight_properties(v, f)
        watertight = solid is not None
        if solid is not None and solid.overlap_candidates:
            union = voxel_properties(v, f)
            # the voxel estimate's error is ~1-3% (docs/design/mesh_analysis.md)
            if union.volume < 0.95 * solid.volume:
                notes.append(f"closed parts overlap: sum of part volumes {solid.volume:.4g} m^3, "
                             f"voxel union {union.volume:.4g} m^3 used")
                union.method = "voxel_union"
                union.notes = solid.notes + union.notes
                solid = union
        if solid is None:
            solid = voxel_properties(v, f)
        notes.extend(solid.notes)
    pitch = solid.pitch or grid_pitch(bmax - bmin, VOXELS_PER_AXIS, MAX_VOXELS, 3)
    method = solid.method
    volume = max(0.0, float(solid.volume))
    if volume < OPEN_SHELL_FRACTION * area * pitch:
        method += "+open_shell"
        notes.append("open shell: the surface encloses (almost) no volume; com is the surface centroid and "
                     "inertia_solid equals inertia_shell (use area x wall thickness for mass)")
        com = s_centroid
        c_solid = s_cov
    else:
        com = solid.com
        c_solid = solid.second
    d = np.asarray(s_centroid) - np.asarray(com)
    c_shell = s_cov + np.outer(d, d)  # the surface's second moment about com (parallel axis)
    sep = float(np.linalg.norm(d))
    if sep > 0.01 * size:
        notes.append(f"surface centroid {np.round(s_centroid, 6).tolist()} m differs from com by {sep:.4g} m")
    i_solid, reg_s = regularize_inertia(inertia_from_second_moment(c_solid), size * size)
    i_shell, reg_h = regularize_inertia(inertia_from_second_moment(c_shell), size * size)
    if reg_s or reg_h:
        which = " and ".join(n for n, r in (("inertia_solid", reg_s), ("inertia_shell", reg_h)) if r)
        notes.append(f"{which}: flat or line-like geometry, isotropic {REGULARIZATION:g} x trace regularisation added")
    if analytic is None:  # the area a shell's mass takes: a surface drawn twice, once facing each way, counts once
        area = surface_properties(v, single_sided(v, f))[0]
    return LinkGeometry(link=link.name, volume=volume, volume_method=method, watertight=watertight, area=float(area),
                        bbox_min=bmin.tolist(), bbox_max=bmax.tolist(), com=np.asarray(com).tolist(),
                        inertia_solid=i_solid.tolist(), inertia_shell=i_shell.tolist(), n_meshes=len(surf.sources),
                        n_faces=int(len(f)), notes=notes)


def analyze_asset(asset: AssetDescription, cache: MeshCache | None = None) -> dict[str, LinkGeometry]:
    """:func:`analyze_link` for every link of ``asset`` that has geometry, by link
    name in asset order; meshes read once per call (shared ``cache``, a new :class:`MeshCache` when None).

    Raises:
        MeshAnalysisError: a link with geometry has no usable geometry.
    """
    cache = MeshCache() if cache is None else cache
    return {link.name: geo for link in asset.links if (geo := analyze_link(link, cache=cache)) is not None}
