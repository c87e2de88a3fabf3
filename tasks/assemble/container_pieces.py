"""Collision pieces of containers: a part modelled as one OBJ group whose hull holds an open cavity (a bucket's,
a drawer box's, a toilet bowl's inside; :mod:`asset2sim.tasks.geometry.cavities`) is decomposed by CoACD
(:mod:`asset2sim.tasks.geometry.decomposition`) so that its inside stays open, with the option
``open_containers``; :mod:`asset2sim.tasks.assemble.collision_geometry` calls it for every group.
``docs/design/simulators.md`` (Containers) explains the rules. Lengths in m, in the link frame.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import QhullError

from asset2sim import mesh_io, urdf
from asset2sim.engines.loading import mesh_hulls
from asset2sim.tasks.assemble.containment_cuts import surface_samples
from asset2sim.tasks.assemble.convex_pieces import CONTAINMENT_TOLERANCE, Piece, depth_inside, posed, thinnest_axis
from asset2sim.tasks.assemble.joint_sweep import swept_child_points
from asset2sim.tasks.geometry import cavities, decomposition

__all__ = ["CAVITY_COACD", "CAVITY_NOTE", "CAVITY_WALL", "MOUTH_BELOW", "OPENED_SHARE", "REFIT_SAMPLES",
           "holding_children", "link_surfaces", "may_hold_cavity", "open_pieces"]

#: Share of an open cavity's core a decomposition must leave free to replace the part's hull.
OPENED_SHARE = 0.75
#: CoACD settings for a part holding an open cavity: a coarser concavity threshold and a shallower search than
#: :data:`decomposition.COACD_SETTINGS` (walls and a bottom are what the cavity needs; measured 1-5 s a part).
CAVITY_COACD = {**decomposition.COACD_SETTINGS, "threshold": 0.1, "mcts_iterations": 20, "mcts_max_depth": 1}
#: Surface samples along the part's largest extent that its decomposition is refitted to.
REFIT_SAMPLES = 80
#: Thinnest piece of a decomposed container's wall, m, grown toward the cavity: a model's walls are often single
#: sheets, and a piece must be thick enough for a running clearance (:data:`sliding_clearance.RUNNING_CLEARANCE`)
#: to be taken off it (at most half its width).
CAVITY_WALL = 0.006
#: A cavity whose mouth points more than this sine below the horizontal (30 degrees) opens downward.
MOUTH_BELOW = 0.5
#: Words of the notes on a part holding an open cavity.
CAVITY_NOTE = "holds an open cavity"


def holding_children(model: urdf.UrdfModel, hulls: dict[str, list[tuple[int, int, Piece]]]) -> set[str]:
    """The links whose group ``hulls`` (link -> (collision index, group index, hull), as
    :mod:`~asset2sim.tasks.assemble.collision_geometry` makes them) hold a child's vertices deeper than
    :data:`CONTAINMENT_TOLERANCE` somewhere over the child's joint range (:func:`swept_child_points`): a desk body
    around its drawer, whose space opens downward under its top but must be cut away for the drawer all the same."""
    trial = {name: [p for _, _, p in found] for name, found in hulls.items()}
    out = set()
    for name, found in trial.items():
        swept = swept_child_points(model, trial, name)
        if swept and found:
            pts = np.vstack(list(swept.values()))
            if any(depth_inside(pts, p) > CONTAINMENT_TOLERANCE for p in found):
                out.add(name)
    return out


def may_hold_cavity(piece: Piece) -> bool:
    """A hull wide enough every way (principal extents) to hold a ball of :data:`cavities.MIN_CAVITY_RADIUS`."""
    p = piece.points
    if len(p) < 4:
        return False
    _, _, vt = np.linalg.svd(p - p.mean(axis=0), full_matrices=False)
    return bool(np.ptp(p @ vt.T, axis=0).min() >= 2.0 * cavities.MIN_CAVITY_RADIUS)


def link_surfaces(link: urdf.UrdfLink, mesh_path) -> tuple[tuple[np.ndarray, np.ndarray],
                                                               dict[tuple[int, int], tuple[np.ndarray, np.ndarray]]] | None:
    """The triangles of every mesh collision group of ``link`` in the link frame (m): (all of them as one mesh
    (vertices (V, 3), faces (F, 3)), (collision, group) -> that group's mesh), or None when a file cannot be read
    the way its hulls were (then no group is decomposed)."""
    by_group: dict[tuple[int, int], tuple[np.ndarray, np.ndarray]] = {}
    for k, c in enumerate(link.collisions):
        if c.kind != "mesh":
            continue
        try:
            meshes = mesh_io.group_meshes(mesh_path(c))
            if len(meshes) != len(mesh_hulls(mesh_path(c), c.scale)):
                return None
        except (mesh_io.MeshReadError, urdf.UrdfError):
            return None
        for g, (v, f) in enumerate(meshes):
            if len(f):
                by_group[(k, g)] = (posed(v * c.scale, c.origin), f)
    if not by_group:
        return None
    offsets = np.cumsum([0] + [len(v) for v, _ in by_group.values()])
    allv = np.vstack([v for v, _ in by_group.values()])
    allf = np.vstack([f + o for (_, f), o in zip(by_group.values(), offsets)])
    return (allv, allf), by_group


def open_pieces(link: str, c: urdf.UrdfGeometry, g: int, hull: Piece, mesh: tuple[np.ndarray, np.ndarray],
                 link_mesh: tuple[np.ndarray, np.ndarray], notes: list[str],
                 slides_along: set[str] | None, up: np.ndarray | None) -> tuple[list[Piece], np.ndarray] | None:
    """The convex pieces (CoACD, :mod:`~asset2sim.tasks.geometry.decomposition`) of ``mesh`` (vertices (V, 3) m,
    faces (F, 3)), group ``g`` of collision ``c``, replacing its hull ``hull`` when the hull holds an open cavity
    that the link's surfaces ``link_mesh`` leave open (:func:`cavities.open_cavity`), the link slides along no
    other link (``slides_along``: a part sliding across the seams between pieces catches on them in PyBullet, as
    drawers stacked in a cabinet would), the cavity does not only open downward (the mouth of each of its regions,
    :class:`cavities.CavityRegion`, more than :data:`MOUTH_BELOW` below the horizontal against ``up`` (3,), the
    world's up in the link frame at the joints' reference state: a lid's underside, which nothing put in would
    stay in; a toilet body's bowl opens upward beside the space under its rim, which opens downward) and the pieces
    leave at least :data:`OPENED_SHARE` of the cavity free, with the cavity's core points (K, 3) m; None (the hull
    stays, a note says why when there is a cavity) otherwise."""
    try:
        hv, hf = mesh_io.convex_hull_mesh(hull.points)
        cav = cavities.open_cavity(link_mesh[0], link_mesh[1], hv, hf)
    except (QhullError, ValueError):
        return None
    if cav is None:
        return None
    what = (f"link {link!r}: group {g} of {c.filename} {CAVITY_NOTE} (a ball of {cav.radius * 1000:.0f} mm radius, "
            f"{100 * cav.volume / max(cav.hull_volume, 1e-12):.0f} % of its hull)")
    as_hull = f"{what}; kept as one convex hull, solid inside:"
    if up is not None and cav.regions and all(float(r.mouth @ up) < -MOUTH_BELOW for r in cav.regions):
        # how far below the horizontal the mouths face (degrees)
        below = sorted({round(float(np.degrees(np.arcsin(min(1.0, max(0.0, -float(r.mouth @ up))))))) for r in cav.regions})
        notes.append(f"{what}; kept as one convex hull: its opening faces down at the joints' reference state "
                     f"({', '.join(f'{a} deg' for a in below)} below the horizontal), so nothing put in would stay in it")
        return None
    if slides_along:
        notes.append(f"{as_hull} it slides along {', '.join(map(repr, sorted(slides_along)))} "
                     "and a part sliding across the seams between convex pieces catches on them")
        return None
    try:
        parts = decomposition.decompose(mesh[0], mesh[1], CAVITY_COACD, refit=False)
    except (decomposition.DecompositionUnavailable, ValueError) as exc:
        notes.append(f"{as_hull} {exc}")
        return None
    # refitted to points on the part's own surface: CoACD's pieces lie on its remesh, offset from the surface,
    # and a few corners per wall are too few to refit to
    size = float(np.ptp(mesh[0], axis=0).max())
    surface = np.vstack([mesh[0], surface_samples(mesh[0][mesh[1]], size / REFIT_SAMPLES)])
    pieces = []
    inward = cav.core.mean(axis=0)
    for pv, _ in decomposition.refit_pieces(surface, parts):
        axis = thinnest_axis(pv)
        if axis is None:  # spans no area
            continue
        solid, centre, n, width = axis
        if width < CAVITY_WALL:  # grown to CAVITY_WALL along its thinnest direction toward the cavity (the outer face stays)
            n = -n if float(n @ (inward - centre)) < 0 else n
            solid = np.vstack([solid, solid + n * (CAVITY_WALL - width)])
        try:
            pieces.append(Piece.of(solid, (str(c.filename),)))
        except (QhullError, ValueError):
            continue
    free = cavities.open_fraction(cav.core, [p.equations for p in pieces])
    if not pieces or free < OPENED_SHARE:
        notes.append(f"{as_hull} its convex decomposition leaves "
                     f"{100 * free:.0f} % of the cavity free")
        return None
    notes.append(f"{what}: {len(pieces)} convex pieces (CoACD) instead of its hull, so that things can be put in it")
    return pieces, cav.core

