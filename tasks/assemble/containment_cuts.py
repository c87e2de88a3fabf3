"""Parents cut around their children: where a parent's hull holds the volume
a child sweeps over its joint's range deeper than
:data:`~asset2sim.tasks.assemble.convex_pieces.CONTAINMENT_TOLERANCE`, the
parent's densely sampled mesh is split by a greedy binary space partition
(Naylor, "Binary space partitioning trees as an alternative representation
of polytopes", CAD 1990), kept only when the child then sits less deep;
pieces that still hold it are trimmed."""

from __future__ import annotations

import hashlib
import cachetools

import numpy as np

from asset2sim import mesh_io, urdf
from asset2sim.tasks.assemble.convex_pieces import (CONTAINMENT_TOLERANCE, CollisionGeometryError, Piece, cached, clip_piece,
                                                    depth_inside, merge_pieces, posed, solid_piece)
from asset2sim.tasks.assemble.joint_sweep import swept_child_points

def surface_samples(triangles: np.ndarray, spacing: float) -> np.ndarray:
    """Points (k, 3) on the triangles (m, 3, 3) no farther than ``spacing``
    apart along any edge: each triangle's barycentric grid with
    ``ceil(longest edge / spacing)`` steps (its corners included)."""
    tri = np.asarray(triangles, float)
    if len(tri) == 0:
        return np.zeros((0, 3))
    longest = np.max(np.linalg.norm(tri - np.roll(tri, 1, axis=1), axis=2), axis=1)
    steps = np.clip(np.ceil(longest / max(spacing, 1e-12)).astype(int), 1, 64)
    out = [tri.reshape(-1, 3)]
    for n in np.unique(steps[steps > 1]):
        i, j = np.meshgrid(np.arange(n + 1), np.arange(n + 1), indexing="ij")
        keep = i + j <= n
        a, b = i[keep] / n, j[keep] / n
        w = np.stack([1 - a - b, a, b], axis=1)  # (g, 3) barycentric weights
        t = tri[steps == n]
        out.append(np.einsum("gk,mkd->mgd", w, t).reshape(-1, 3))
    return _unique_rows(np.vstack(out))


def _unique_rows(points: np.ndarray) -> np.ndarray:
    """The distinct rows of ``points`` (k, 3), sorted by x, then y, then z: what ``np.unique(points, axis=0)``
    gives (a signed zero taken as positive), from a lexicographic sort of the three columns (numpy's row-unique
    sorts a structured view, several times slower)."""
    p = points + 0.0  # -0.0 -> 0.0: equal rows compare equal bit for bit
    s = p[np.lexsort((p[:, 2], p[:, 1], p[:, 0]))]
    keep = np.ones(len(s), bool)
    keep[1:] = (s[1:] != s[:-1]).any(axis=1)
    return s[keep]


#: Where a point set may be cut, as fractions of its extent along each axis of the link frame.
CUT_FRACTIONS = (0.04, 0.1, 0.2, 0.35, 0.5, 0.65, 0.8, 0.9, 0.96)


def facets(triangles: np.ndarray, gap: float) -> list[np.ndarray]:
    """The triangles (m, 3, 3) grouped into facets: by the axis direction
    (+-x, +-y, +-z) their normal is closest to, then into layers along that
    axis separated by more than ``gap`` m; returns the facets' triangles
    (largest first)."""
    tri = np.asarray(triangles, float)
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    good = np.linalg.norm(n, axis=1) > 0
    tri, n = tri[good], n[good]
    if len(tri) == 0:
        return []
    # +-x, +-y, +-z
    bin_ = np.argmax(n @ np.vstack([np.eye(3), -np.eye(3)]).T / np.linalg.norm(n, axis=1)[:, None], axis=1)
    out = []
    for b in range(6):
        t = tri[bin_ == b]
        if len(t) == 0:
            continue
        ax = b % 3
        t = t[np.argsort(t[:, :, ax].mean(axis=1))]
        lo, hi = t[:, :, ax].min(axis=1), t[:, :, ax].max(axis=1)
        reach = np.maximum.accumulate(hi)
        cuts = np.nonzero(lo[1:] > reach[:-1] + gap)[0] + 1
        out += [t[a:b2] for a, b2 in zip(np.r_[0, cuts], np.r_[cuts, len(t)])]
    return sorted(out, key=len, reverse=True)


#: Points of a set that :func:`split_surface` measures a cut with, and child vertices it keeps out (subsamples).
MEASURE_SAMPLES = 1000
PROBE_POINTS = 1500


def split_surface(points: np.ndarray, keep_out: np.ndarray, tolerance: float, budget: int, spacing: float) -> list[np.ndarray]:
    """Split surface samples ``points`` (k, 3) m into at most ``budget`` point
    sets whose hulls hold none of ``keep_out`` (j, 3) m deeper than
    ``tolerance`` m: the set holding a point deepest is cut by the axis plane
    (at :data:`CUT_FRACTIONS` of its extent, or through that point) after
    which the deeper half holds ``keep_out`` least deep (ties: less hull
    volume); points within ``spacing`` m of the plane go to both halves.
    Stops when no cut helps. Returns the point sets (read-only arrays).

    Kept per process by the content of its arguments (:data:`_SPLITS`): a parent cut facet by facet and as a
    whole often splits the same samples twice (a single facet), and a refine builds the pieces of a model
    again after changes elsewhere."""
    pts = np.ascontiguousarray(points, dtype=float)
    out = np.ascontiguousarray(keep_out, dtype=float)
    key = (pts.shape, out.shape, hashlib.sha256(pts.tobytes() + b"|" + out.tobytes()).digest(), float(tolerance), int(budget),
           float(spacing))

    def made() -> tuple[np.ndarray, ...]:
        sets = _split_surface(pts.copy(), out, tolerance, budget, spacing)  # a copy: the arrays kept never alias the caller's
        for a in sets:
            a.flags.writeable = False
        return tuple(sets)

    return list(cached(_SPLITS, key, made))


#: :func:`split_surface`'s point sets made in this process, by (shapes, SHA-256 of the points and the points kept
#: out, tolerance, budget, spacing); the least recently used dropped beyond 64.
_SPLITS: cachetools.LRUCache = cachetools.LRUCache(maxsize=64)


def _split_surface(points: np.ndarray, keep_out: np.ndarray, tolerance: float, budget: int, spacing: float) -> list[np.ndarray]:
    """:func:`split_surface`, computed."""
    def hull_of(p: np.ndarray) -> Piece | None:
        return solid_piece(p[:: max(1, len(p) // MEASURE_SAMPLES)])  # an even subsample guides the cut; the pieces keep every point

    def measure(p: np.ndarray) -> tuple[float, float]:
        piece = hull_of(p)
        return (0.0, 0.0) if piece is None else (depth_inside(keep_out, piece), piece.volume)

    def deepest(p: np.ndarray) -> np.ndarray | None:
        piece = hull_of(p)
        if piece is None or not len(keep_out):
            return None
        d = np.max(keep_out @ piece.equations[:, :3].T + piece.equations[:, 3], axis=1)
        return keep_out[int(np.argmin(d))] if d.min() < 0 else None

    sets = [(measure(points)[0], points)]
    while len(sets) < budget:
        sets.sort(key=lambda t: -t[0])
        d, p = sets[0]
        if d <= tolerance or len(p) < 8:
            break
        lo_b, ext = p.min(axis=0), np.ptp(p, axis=0)
        best = None
        at = deepest(p)
        for ax in range(3):
            if ext[ax] <= 2 * spacing:
                continue
            cuts = [lo_b[ax] + f * ext[ax] for f in CUT_FRACTIONS]
            if at is not None:  # through the point held deepest: it ends up on the faces of both halves
                cuts.append(at[ax])
            for cut in cuts:
                lo, hi = p[p[:, ax] <= cut + spacing], p[p[:, ax] >= cut - spacing]
                if len(lo) < 4 or len(hi) < 4 or len(lo) == len(p) or len(hi) == len(p):
                    continue
                # the larger half first (more often deeper than the best cut): max(dl, dh) > the best's depth,
                # this cut cannot win and the other half is not measured
                big, small = (hi, lo) if len(hi) > len(lo) else (lo, hi)
                d1, v1 = measure(big)
                if best is not None and d1 > best[0][0]:
                    continue
                d2, v2 = measure(small)
                (dl, vl), (dh, vh) = ((d2, v2), (d1, v1)) if big is hi else ((d1, v1), (d2, v2))
                score = (max(dl, dh), vl + vh)
                if best is None or score < best[0]:
                    best = (score, (dl, lo), (dh, hi))
        if best is None or best[0][0] >= d:
            break
        sets = sets[1:] + [best[1], best[2]]
    return [p for _, p in sets]


def _split_pieces(link: urdf.UrdfLink, source: str, mesh_path, keep_out: np.ndarray, budget: int) -> list[Piece]:
    """Pieces of the collision mesh ``source`` of ``link`` (link frame) cut by :func:`split_surface` around
    ``keep_out`` (k, 3) m, at most ``budget`` pieces.

    Raises:
        CollisionGeometryError: the mesh cannot be read.
    """
    tris = []
    for c in link.collisions:
        if c.kind != "mesh" or str(c.filename) != source:
            continue
        try:
            mesh = mesh_io.read_mesh(mesh_path(c))
        except mesh_io.MeshReadError as exc:
            raise CollisionGeometryError(f"link {link.name!r}: {exc}") from exc
        v = posed(np.asarray(mesh.vertices, float) * c.scale, c.origin)
        f = np.asarray(mesh.faces, int)
        f = f[np.all((f >= 0) & (f < len(v)), axis=1)]
        t = v[f]
        tris.append(t[np.all(np.isfinite(t), axis=(1, 2))])
    if not tris:
        return []
    tri = np.concatenate(tris)
    spacing = float(np.ptp(tri.reshape(-1, 3), axis=0).max()) / SPLIT_RESOLUTION
    best: list[Piece] = []
    best_depth = np.inf
    for parts in (facets(tri, 2 * spacing), [tri]):  # cut facet by facet, or the whole surface: the better
        sets = []
        for part in parts:
            samples = surface_samples(part, spacing)
            if len(samples) > MAX_SPLIT_SAMPLES:  # a fixed subsample: the same pieces on every run
                samples = samples[np.random.default_rng(0).choice(len(samples), MAX_SPLIT_SAMPLES, replace=False)]
            sets += split_surface(samples, keep_out, CONTAINMENT_TOLERANCE, budget, spacing)
        out = merge_pieces([q for q in (solid_piece(p, (source,)) for p in sets) if q is not None], 1, keep_out, free_only=True)
        depth = max((depth_inside(keep_out, p) for p in out), default=0.0)
        if depth < best_depth - 1e-6 or (depth <= best_depth + 1e-6 and len(out) < len(best)):
            best, best_depth = out, depth
        if best_depth <= CONTAINMENT_TOLERANCE:
            break
    return best


#: Surface samples of a parent mesh cut around its child: 1/24 of its largest extent apart, at most MAX_SPLIT_SAMPLES.
SPLIT_RESOLUTION = 24
MAX_SPLIT_SAMPLES = 8000


#: Largest part of a parent piece's width (along the face moved) that :func:`shave_piece` may take off.
MAX_SHAVE_FRACTION = 0.5


def shave_piece(piece: Piece, points: np.ndarray) -> Piece | None:
    """``piece`` with the face that needs the least move moved inwards just
    far enough that none of ``points`` (k, 3) m held deeper than
    :data:`CONTAINMENT_TOLERANCE` m sits deeper than half of it; None when that move exceeds
    :data:`MAX_SHAVE_FRACTION` of the piece's width along the face's normal."""
    if not len(points):
        return piece
    # a point outside the piece's box is outside its hull: never held deeper than the tolerance
    lo, hi = piece.points.min(axis=0), piece.points.max(axis=0)
    points = points[np.all((points >= lo) & (points <= hi), axis=1)]
    d = points @ piece.equations[:, :3].T + piece.equations[:, 3]  # (k, f), <= 0 inside
    inside = np.max(d, axis=1) < -CONTAINMENT_TOLERANCE
    if not inside.any():
        return piece
    # (f,) move of each face that leaves every point within half the tolerance
    need = np.max(-d[inside], axis=0) - 0.5 * CONTAINMENT_TOLERANCE
    f = int(np.argmin(need))
    n = piece.equations[f, :3]
    width = float(np.ptp(piece.points @ n))
    if need[f] > MAX_SHAVE_FRACTION * width:
        return None
    return clip_piece(piece, n, piece.equations[f, 3] + need[f])


#: Margin (fraction of a piece's size) by which :func:`probe_points` grows a piece's box before measuring points in it.
BOX_MARGIN = 1e-6


def probe_points(points: np.ndarray, pieces: list[Piece], n: int = PROBE_POINTS) -> np.ndarray:
    """At most ``n`` of ``points`` (k, 3) m inside any of ``pieces``: the deepest ``n // 2``, then an even subsample.
    Each piece is measured on the points in its box grown by :data:`BOX_MARGIN` of its size (a point farther out
    is outside it by far more than a rounding error: its depth there is not positive)."""
    depth = np.zeros(len(points))
    for p in pieces:
        lo, hi = p.points.min(axis=0), p.points.max(axis=0)
        grow = BOX_MARGIN * float(np.max(hi - lo))
        near = np.flatnonzero(np.all((points >= lo - grow) & (points <= hi + grow), axis=1))
        d = -np.max(points[near] @ p.equations[:, :3].T + p.equations[:, 3], axis=1)
        depth[near] = np.maximum(depth[near], d)
    inside = np.flatnonzero(depth > 0)
    if len(inside) <= n:
        return points[inside]
    order = inside[np.argsort(-depth[inside])]
    head, rest = order[: n // 2], order[n // 2:]
    return points[np.concatenate([head, rest[:: max(1, len(rest) // (n - len(head)))]])]


def _resolve_containment(model, pieces, mesh_path, notes, decompose: bool, limit: int,
                         whole: frozenset[tuple[str, str]]) -> None:
    """Cut, in place, the parent pieces that contain a child deeper than
    :data:`CONTAINMENT_TOLERANCE` anywhere over the child's joint range
    (:func:`_split_pieces` around all children at once, kept only when they
    then sit less deep); pieces that still hold a child are trimmed (:func:`_trim`).
    The pieces of a (link, source) in ``whole`` (a container's decomposition, whose
    cavity a new cut would fill) are never cut again, only trimmed."""
    for parent in list(pieces):
        swept = swept_child_points(model, pieces, parent)
        if not swept:
            continue
        pts = np.vstack(list(swept.values()))
        deep = [(d, p) for d, p in ((depth_inside(pts, p), p) for p in pieces[parent]) if d > CONTAINMENT_TOLERANCE]
        if not deep:
            continue
        before = max(d for d, _ in deep)
        names = ", ".join(repr(c) for c in swept)
        if not decompose:
            notes.append(f"{names} sit {before * 1000:.3g} mm inside the collision hull of their parent {parent!r} over their ranges")
            continue
        sources = sorted({s for _, p in deep for s in p.sources if (parent, s) not in whole})
        if not sources:
            _trim(pieces, parent, names, pts, before, notes)
            continue
        trial = [p for p in pieces[parent] if not set(p.sources) & set(sources)]
        budget = max(2, limit - len(trial)) if len(sources) == 1 else max(2, (limit - len(trial)) // len(sources))
        probe = probe_points(pts, [p for _, p in deep])
        for s in sources:
            # guided by the swept vertices inside the pieces cut, judged on all of them
            trial += _split_pieces(model.links[parent], s, mesh_path, probe, budget)
        after = max((depth_inside(pts, p) for p in trial), default=0.0)
        if after < before - 1e-6:
            pieces[parent] = trial
            notes.append(f"link {parent!r}: {', '.join(sources)} cut into convex pieces around {names} over their ranges: "
                         f"{before * 1000:.3g} -> {after * 1000:.3g} mm inside")
        else:
            after = before
        if after > CONTAINMENT_TOLERANCE:  # the meshes overlap: trim the pieces that still hold a child
            _trim(pieces, parent, names, pts, after, notes)


def _trim(pieces: dict[str, list[Piece]], parent: str, child: str, pts: np.ndarray, depth: float, notes: list[str]) -> None:
    """Trim the pieces of ``parent`` that hold any of ``pts`` (k, 3) m, the swept vertices of its children ``child``,
    deeper than :data:`CONTAINMENT_TOLERANCE` (:func:`shave_piece`), kept when they then sit less deep than ``depth`` m."""
    # a piece that cannot be shaved (None) stays as it is
    shaved = [shave_piece(p, pts) or p if depth_inside(pts, p) > CONTAINMENT_TOLERANCE else p for p in pieces[parent]]
    after = max((depth_inside(pts, p) for p in shaved), default=0.0)
    if after < depth - 1e-6:
        pieces[parent] = shaved
        notes.append(f"link {parent!r}: collision pieces trimmed where {child} overlap them over their ranges: "
                     f"{depth * 1000:.3g} -> {after * 1000:.3g} mm inside")
    else:
        notes.append(f"{child} sit {depth * 1000:.3g} mm inside their parent {parent!r} over their ranges; "
                     "neither cutting nor trimming its pieces helps")
