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

How (details and measured accuracy in ``docs/design/mesh_analysis.md``)
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

Mesh files are read by :mod:`asset2sim.mesh_io` (a vectorized OBJ parser
that reads only ``v`` and ``f`` records; other formats through trimesh) and
cached by path within an :func:`analyze_asset` call (:class:`MeshCache`).

Layout: this module holds the per-link decision (analytic primitive,
watertight, voxel) and the result; :mod:`.surface` builds the link's triangle
surface, :mod:`.moments` the exact moments and inertia helpers, :mod:`.voxels`
the voxel volume.
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
from asset2sim.tasks.geometry.moments import (
    REGULARIZATION,
    SolidMoments,
    inertia_from_second_moment,
    regularize_inertia,
    surface_properties,
    watertight_properties,
)
from asset2sim.tasks.geometry.surface import LinkSurface, MeshAnalysisError, link_surface
from asset2sim.tasks.geometry.voxels import (
    CLOSE_GAPS,
    LAYER_CORRECTION,
    MAX_VOXELS,
    VOXELS_PER_AXIS,
    VoxelGrid,
    grid_pitch,
    mean_size,
    voxel_properties,
    voxelize,
)

# The stage's public names; the pieces live in ``surface`` (link geometry ->
# one triangle surface), ``moments`` (exact surface / closed-mesh moments,
# inertia helpers) and ``voxels`` (polygon-soup volume).
__all__ = [
    "MeshAnalysisError",
    "MeshCache",
    "LinkSurface",
    "link_surface",
    "surface_properties",
    "watertight_properties",
    "voxel_properties",
    "voxelize",
    "VoxelGrid",
    "SolidMoments",
    "mean_size",
    "inertia_from_second_moment",
    "regularize_inertia",
    "OPEN_SHELL_FRACTION",
    "REGULARIZATION",
    "VOXELS_PER_AXIS",
    "MAX_VOXELS",
    "CLOSE_GAPS",
    "LAYER_CORRECTION",
    "analyze_link",
    "analyze_asset",
]

#: Enclosed volume below OPEN_SHELL_FRACTION * area * pitch counts as "encloses nothing".
OPEN_SHELL_FRACTION = 0.1


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


#: Modules whose source the analysis of a link depends on: a change to any
#: of them makes every on-disk entry a miss (:func:`analyze_link`).
ANALYSIS_CODE: tuple[str, ...] = (
    "asset2sim.tasks.geometry.analyze",
    "asset2sim.tasks.geometry.surface",
    "asset2sim.tasks.geometry.voxels",
    "asset2sim.tasks.geometry.moments",
    "asset2sim.mesh_io",
    "asset2sim.frames",
    "asset2sim.schemas.asset",
)


def _disk_key(link: LinkDesc, params: tuple) -> str | None:
    """The on-disk key of ``link``'s analysis with ``params``: its name, the
    geometry elements as written (kind, origin, scale, sizes, filename; not
    where the folder lies), the bytes of every mesh file, the parameters and
    the source of :data:`ANALYSIS_CODE`; None when a file or the code cannot
    be read (then nothing is cached)."""
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
    except (OSError, ImportError):
        return None
    return array_cache.digest(*parts)


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

    The result is kept on disk (:mod:`asset2sim.array_cache`, kind
    ``analysis``) by the link's name, its geometry elements as written, the
    bytes of its mesh files, the parameters and the source of
    :data:`ANALYSIS_CODE`: the same asset refined again (another request, a
    nightly rerun) reads it instead of voxelising again (0.2-0.5 s of a dev
    object's refine); ``ASSET2SIM_CACHE=off`` turns it off.

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
    if not link.has_geometry:
        return None
    params = (prefer, voxels_per_axis, max_voxels, close_gaps, layer_correction, subvoxel)
    key = _disk_key(link, params)
    hit = array_cache.load(DISK_KIND, key) if key is not None else None
    if hit is not None and "json" in hit:
        try:
            return LinkGeometry.model_validate_json(array_cache.array_text(hit["json"]))
        except ValueError:  # UnicodeDecodeError and pydantic's ValidationError included
            pass  # an unreadable entry: computed again and rewritten
    geo = _analyze_surface(link, prefer, voxels_per_axis, max_voxels, close_gaps, layer_correction, subvoxel, cache)
    if geo is not None and key is not None:
        array_cache.store(DISK_KIND, key, {"json": array_cache.text_array(geo.model_dump_json())})
    return geo


#: The on-disk cache's folder of link analyses (:mod:`asset2sim.array_cache`).
DISK_KIND = "analysis"


def _analyze_surface(link: LinkDesc, prefer, voxels_per_axis: int, max_voxels: int, close_gaps: float,
                     layer_correction: float, subvoxel: bool, cache: MeshCache | None) -> LinkGeometry | None:
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
                # the voxel estimate's error is ~1-3% (docs/design/mesh_analysis.md)
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
    pitch = solid.pitch or grid_pitch(bmax - bmin, voxels_per_axis, max_voxels, 3)
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
