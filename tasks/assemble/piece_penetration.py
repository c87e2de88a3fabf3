"""How deep two convex pieces overlap: the penetration depth an engine
colliding them reports (separating axes), and the depths of every
parent-child pair of a model's pieces."""

from __future__ import annotations

import numpy as np
from scipy.spatial import QhullError

from asset2sim import mesh_io, urdf
from asset2sim.tasks.assemble.convex_pieces import Piece, depth_inside, posed

#: Axes projected at once by :func:`penetration_depth` (memory: chunk x points).
_AXIS_CHUNK = 4096


def _edge_directions(piece: Piece) -> np.ndarray:
    """Unit directions (e, 3) of the edges of the hull of ``piece``'s support
    points, one per direction up to sign (diagonals of facets included: extra
    axes never make :func:`penetration_depth` wrong); kept on the piece."""
    if piece._edges is not None:
        return piece._edges
    try:
        verts, tris = mesh_io.convex_hull_mesh(piece.support)
    except (QhullError, ValueError):
        piece._edges = np.zeros((0, 3))
        return piece._edges
    e = np.concatenate([verts[tris[:, 1]] - verts[tris[:, 0]], verts[tris[:, 2]] - verts[tris[:, 1]],
                        verts[tris[:, 0]] - verts[tris[:, 2]]])
    n = np.linalg.norm(e, axis=1)
    e = e[n > 1e-12] / n[n > 1e-12, None]
    # the first non-zero component positive
    e[e[np.arange(len(e)), np.argmax(e != 0, axis=1)] < 0] *= -1
    _, keep = np.unique(np.round(e * 50.0), axis=0, return_index=True)  # one per ~1 degree cell
    e = e[np.sort(keep)]
    if len(e) > MAX_EDGE_DIRECTIONS:  # an even subsample: fewer axes only bound the depth from above
        e = e[np.linspace(0, len(e) - 1, MAX_EDGE_DIRECTIONS).round().astype(int)]
    piece._edges = e
    return e


#: Most edge directions per piece that :func:`penetration_depth` crosses
#: (its time grows with their product).
MAX_EDGE_DIRECTIONS = 64


def _overlaps(a: np.ndarray, b: np.ndarray, axes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Overlap (n,) m of the projections of points ``a`` (k, 3) and ``b``
    (j, 3) on each of ``axes`` (n, 3) unit, and whether ``a`` lies on the
    lower side (n,) bool (separating along +axis moves ``b`` up)."""
    out, low = [], []
    for i in range(0, len(axes), _AXIS_CHUNK):
        ax = axes[i:i + _AXIS_CHUNK]
        pa, pb = a @ ax.T, b @ ax.T
        up, down = pa.max(axis=0) - pb.min(axis=0), pb.max(axis=0) - pa.min(axis=0)
        out.append(np.minimum(up, down))
        low.append(up <= down)
    return np.concatenate(out), np.concatenate(low)


#: Candidate axes of :func:`penetration_depth` measured on every vertex, the
#: ones with the smallest overlap of the pieces' support points.
EXACT_AXES = 48


def _least_overlap(a: Piece, b: Piece, axes: np.ndarray) -> tuple[float, np.ndarray]:
    """Smallest overlap (m) of ``a`` and ``b`` over ``axes`` (n, 3) and its
    axis oriented from ``a`` to ``b``: ranked on the support points (fast,
    an under-estimate per axis), the :data:`EXACT_AXES` best measured on all
    vertices (exact per axis, so the result bounds the depth from above)."""
    if len(axes) > EXACT_AXES:
        approx, _ = _overlaps(a.support, b.support, axes)
        axes = axes[np.argpartition(approx, EXACT_AXES)[:EXACT_AXES]]
    ov, low = _overlaps(a.points, b.points, axes)
    i = int(np.argmin(ov))
    return float(ov[i]), axes[i] * (1.0 if low[i] else -1.0)


def penetration_depth(a: Piece, b: Piece, lower_bound: float = 0.0) -> tuple[float, np.ndarray]:
    """Penetration depth (m, >= 0) of two convex pieces in one frame and the
    direction (3,) unit along which ``b`` moves that far to separate from
    ``a`` (zero vector when they do not overlap): the smallest overlap of
    their projections over the face normals of both and the cross products
    of their edge directions (Gottschalk, Lin and Manocha, "OBBTree",
    SIGGRAPH 1996; Ericson, "Real-Time Collision Detection", 2005, sec.
    5.2.1). Edges and ranking use the support points, so the result may read
    slightly deeper than exact, never shallower. ``lower_bound``: when the
    face normals bound the depth at or below it (m), edge axes are skipped."""
    lo = np.maximum(a.points.min(axis=0), b.points.min(axis=0))
    hi = np.minimum(a.points.max(axis=0), b.points.max(axis=0))
    if np.any(hi <= lo):
        return 0.0, np.zeros(3)
    best, axis = _least_overlap(a, b, np.vstack([a.equations[:, :3], b.equations[:, :3]]))
    if best <= 0.0:
        return 0.0, np.zeros(3)
    if best <= lower_bound:
        return best, axis
    ea, eb = _edge_directions(a), _edge_directions(b)
    if len(ea) and len(eb):
        cross = np.cross(ea[:, None, :], eb[None, :, :]).reshape(-1, 3)
        n = np.linalg.norm(cross, axis=1)
        cross = cross[n > 1e-6] / n[n > 1e-6, None]
        if len(cross):
            d, ax = _least_overlap(a, b, cross)
            if d < best:
                best, axis = d, ax
    if best <= 0.0:
        return 0.0, np.zeros(3)
    return best, axis


def _transformed(piece: Piece, T: np.ndarray) -> Piece:
    """``piece`` moved by the (4, 4) transform ``T`` (planes moved with it, no Qhull)."""
    R, t = T[:3, :3], T[:3, 3]
    n = piece.equations[:, :3] @ R.T
    eq = np.hstack([n, (piece.equations[:, 3] - n @ t)[:, None]])
    return Piece(piece.points @ R.T + t, eq, piece.volume, piece.sources, piece.support @ R.T + t, _edge_directions(piece) @ R.T)


def containment_depths(model: urdf.UrdfModel, pieces: dict[str, list[Piece]], state: dict[str, float]) -> dict[tuple[str, str], float]:
    """(parent, child) -> largest depth (m) of a child's collision vertex
    inside one of the parent's pieces, at joint positions ``state`` (rad or m)."""
    poses = model.link_poses(state)
    out = {}
    for parent in model.links:
        inv = np.linalg.inv(poses[parent])
        for j in model.children(parent):
            if pieces.get(j.child):  # the child's vertices in the parent's frame
                pts = posed(np.vstack([p.points for p in pieces[j.child]]), inv @ poses[j.child])
                out[parent, j.child] = max((depth_inside(pts, p) for p in pieces.get(parent, [])), default=0.0)
    return out


def parent_child_depths(model: urdf.UrdfModel, pieces: dict[str, list[Piece]], state: dict[str, float]) -> dict[tuple[str, str], float]:
    """(parent, child) -> penetration depth (m) of the child's pieces into the
    parent's (:func:`penetration_depth`, the deepest piece pair) at joint
    positions ``state`` (rad or m): what an engine that collides the pair
    reports (margins aside)."""
    poses = model.link_poses(state)
    out = {}
    for j in model.joints:
        P, C = pieces.get(j.parent), pieces.get(j.child)
        if not P or not C:
            continue
        T = np.linalg.inv(poses[j.parent]) @ poses[j.child]
        out[(j.parent, j.child)] = max(penetration_depth(p, _transformed(c, T))[0] for p in P for c in C)
    return out
