"""Convex collision pieces: the hull of a point set (:class:`Piece`), never
flat, written as an OBJ wound outward, at most a few per link (the greedy
hierarchical merge of Mamou and Ghorbel, "A simple and efficient approach for
3D mesh approximate convex decomposition", ICIP 2009: :func:`merge_pieces`)."""

from __future__ import annotations

import hashlib
import heapq
import threading
from collections.abc import Callable
from dataclasses import dataclass, field

import cachetools
import numpy as np
from scipy.spatial import ConvexHull, QhullError

from asset2sim import mesh_io
from asset2sim.engines.loading import FLAT_HULL_THICKNESS

#: Most convex pieces a link's collision keeps (MuJoCo's contacts grow with them).
MAX_PIECES_PER_LINK = 16
#: Most pieces a link keeps when merging further would make a piece hold another link over the joints' ranges.
MAX_PIECES_HARD = 32
#: Thinnest convex piece written, m (the slab every engine here takes).
MIN_THICKNESS = FLAT_HULL_THICKNESS
#: Width (m) under which a piece counts as flat and is grown to :data:`MIN_THICKNESS`.
FLAT_WIDTH = 1e-4
#: Depth (m) a child may sit inside its parent's collision pieces before the parent is cut: the SPEC's tolerance.
CONTAINMENT_TOLERANCE = 0.002
#: Relative tolerance (of a piece's size) under which a point counts as inside a hull (Qhull's noise).
_INSIDE_EPS = 1e-9


def posed(points: np.ndarray, T: np.ndarray) -> np.ndarray:
    """``points`` (k, 3) m moved by the rigid transform ``T`` (4, 4): ``points @ R.T + t``."""
    return points @ T[:3, :3].T + T[:3, 3]


class CollisionGeometryError(RuntimeError):
    """A link's collision geometry cannot be made into convex pieces (names the link and file)."""


@dataclass
class Piece:
    """A convex piece in the link frame: ``points`` (k, 3) m (hull vertices),
    ``equations`` (f, 4) outward planes (n, d with n.x + d <= 0 inside),
    ``volume`` m^3; ``sources`` the mesh files it came from."""

    points: np.ndarray
    equations: np.ndarray
    volume: float
    sources: tuple[str, ...] = ()
    _support: np.ndarray | None = field(default=None, repr=False, compare=False)
    _edges: np.ndarray | None = field(default=None, repr=False, compare=False)

    @property
    def support(self) -> np.ndarray:
        """:func:`support_points` of the piece (computed once)."""
        if self._support is None:
            self._support = support_points(self.points)
        return self._support

    @classmethod
    def of(cls, points: np.ndarray, sources: tuple[str, ...] = ()) -> "Piece":
        """The hull of ``points`` (k, 3) m (memoised per distinct point array in :data:`_HULLS`; arrays shared).

        Raises:
            QhullError, ValueError: the points span no volume.
        """
        hit = _memo(_HULLS, points, _hull)
        return cls(hit[0], hit[1], hit[2], sources)


def _hull(pts: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """(vertices (k, 3) m, outward planes (f, 4), volume m^3) of the hull of ``pts``."""
    hull = ConvexHull(pts)
    used = np.flatnonzero(np.bincount(hull.simplices.ravel(), minlength=len(pts)))  # hull.vertices without its sort
    return pts[used], hull.equations, float(hull.volume)


def cached(cache: cachetools.Cache, key, make: Callable[[], object]):
    """What ``cache`` holds under ``key``, else ``make()`` kept there (the caches of this package share one lock)."""
    with _MEMO_LOCK:
        hit = cache.get(key)
    if hit is None:
        hit = make()
        with _MEMO_LOCK:
            cache[key] = hit
    return hit


def _memo(cache: cachetools.Cache, points: np.ndarray, make: Callable[[np.ndarray], object]):
    """``make`` of ``points`` (as contiguous floats), kept in ``cache`` by (shape, SHA-1 of the points)."""
    pts = np.ascontiguousarray(points, dtype=float)
    return cached(cache, (pts.shape, hashlib.sha1(pts.tobytes()).digest()), lambda: make(pts))


#: Hulls (:func:`_hull`) and OBJ bytes (:func:`piece_obj`) made in this process (a refine builds the same pieces
#: often), the oldest dropped first.
_HULLS: cachetools.FIFOCache = cachetools.FIFOCache(maxsize=5000)
_OBJS: cachetools.FIFOCache = cachetools.FIFOCache(maxsize=4096)
_MEMO_LOCK = threading.Lock()


def thinnest_axis(points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, float] | None:
    """The finite rows of ``points`` (k, 3) m, their centroid (3,) m, the unit direction (3,) of their
    thinnest principal axis (SVD) and their width along it, m; None when they span no area (fewer than
    3 points, or all on a line)."""
    p = np.asarray(points, float)
    p = p[np.all(np.isfinite(p), axis=1)]
    if len(p) < 3:
        return None
    c = p.mean(axis=0)
    _, sv, vt = np.linalg.svd(p - c, full_matrices=False)
    if len(sv) < 2 or sv[1] <= 1e-9 * max(float(sv[0]), 1e-12):
        return None
    n = vt[2] if vt.shape[0] == 3 else np.cross(vt[0], vt[1])
    n = n / np.linalg.norm(n)
    return p, c, n, float(np.ptp(p @ n))


def solid_points(points: np.ndarray) -> np.ndarray | None:
    """``points`` (k, 3) m, grown to :data:`MIN_THICKNESS` m along their thinnest principal direction (both
    sides equally) when they are thinner than :data:`FLAT_WIDTH` m; None when they span no area (fewer than
    3 points, or all on a line)."""
    flat = min(FLAT_WIDTH, MIN_THICKNESS)
    if _surely_solid(points, flat):
        return np.asarray(points, float)
    axis = thinnest_axis(points)
    if axis is None:
        return None
    p, _, n, width = axis
    if width >= flat:
        return p
    h = 0.5 * (MIN_THICKNESS - width)
    return np.vstack([p + h * n, p - h * n])


def _surely_solid(points: np.ndarray, width: float) -> bool:
    """Whether the finite ``points`` (k, 3) m, at least 4, are surely no thinner than ``width`` m along any
    direction, and span more than a line: the standard deviation along their thinnest principal axis (the least
    eigenvalue of their covariance, 3 x 3) is at least ``width`` (a set's extent along an axis is at least twice
    its standard deviation along it), with a 1e9 margin on the line test of :func:`thinnest_axis`. Cheaper than
    that function's SVD of the whole set; False leaves the decision to it."""
    p = np.asarray(points, float)
    if len(p) < 4 or p.ndim != 2 or p.shape[1] != 3:
        return False
    c = p - p.mean(axis=0)
    cov = c.T @ c / len(p)
    if not np.all(np.isfinite(cov)):
        return False  # a non-finite row: thinnest_axis drops it
    lam = np.linalg.eigvalsh(cov)  # ascending
    return bool(lam[0] >= width * width and lam[1] > 1e-9 * lam[2])


def solid_piece(points: np.ndarray, sources: tuple[str, ...] = ()) -> Piece | None:
    """The :class:`Piece` of :func:`solid_points` of ``points`` (k, 3) m, or
    None when they span no area or no volume."""
    solid = solid_points(points)
    if solid is None:
        return None
    try:
        return Piece.of(solid, sources)
    except (QhullError, ValueError):
        return None


def _sphere_directions(n: int = 100) -> np.ndarray:
    """``n`` unit vectors (n, 3) spread evenly over the sphere (Fibonacci lattice)."""
    i = np.arange(n) + 0.5
    phi = np.arccos(1 - 2 * i / n)
    theta = np.pi * (1 + 5 ** 0.5) * i
    return np.stack([np.cos(theta) * np.sin(phi), np.sin(theta) * np.sin(phi), np.cos(phi)], axis=1)


_DIRECTIONS = _sphere_directions()


def support_points(points: np.ndarray) -> np.ndarray:
    """The extreme points (<= 100, 3) of ``points`` (k, 3) along 100 evenly spread directions: an inner
    approximation of their hull."""
    p = np.asarray(points, float)
    if len(p) <= len(_DIRECTIONS):
        return p
    return p[np.unique(np.argmax(p @ _DIRECTIONS.T, axis=0))]


def piece_obj(piece: Piece) -> bytes:
    """OBJ bytes of ``piece``'s hull, every face normal pointing outward (memoised in :data:`_OBJS`)."""
    return _memo(_OBJS, piece.points, mesh_io.hull_obj)


def depth_inside(points: np.ndarray, piece: Piece) -> float:
    """Largest depth (m, >= 0) of any of ``points`` (k, 3) inside ``piece``
    (distance to the nearest face plane of a point inside the hull); only points in the hull's box can be inside,
    those of its x band are taken first (the same rows, cheaper).

    On a hull of many faces the deepest point is found by bounds: a point's distance to a few of the face planes
    (:data:`_BOUND_PLANES`, every k-th) bounds its depth from above; points are measured against every plane in
    the order of their bounds, :data:`_BOUND_BLOCK` at a time, until no bound left exceeds the deepest found. The
    depth is the same as when every point is measured against every plane."""
    if len(points) == 0:
        return 0.0
    lo, hi = piece.points.min(axis=0), piece.points.max(axis=0)
    points = points[(points[:, 0] > lo[0]) & (points[:, 0] < hi[0])]
    points = points[np.all((points > lo) & (points < hi), axis=1)]
    if len(points) == 0:
        return 0.0
    eq = piece.equations
    few = _bounding_planes(eq)
    if few is None or len(points) <= _BOUND_BLOCK:
        d = np.max(points @ eq[:, :3].T + eq[:, 3], axis=1)
        return float(max(0.0, -d.min()))
    bound = -np.max(points @ few[:, :3].T + few[:, 3], axis=1)  # >= the depth of each point
    order = np.argsort(-bound, kind="stable")
    order = order[bound[order] > 0.0]  # a point outside a face plane is outside the hull
    best = 0.0
    for s in range(0, len(order), _BOUND_BLOCK):
        rows = order[s:s + _BOUND_BLOCK]
        if bound[rows[0]] <= best:
            break
        best = max(best, float(-np.max(points[rows] @ eq[:, :3].T + eq[:, 3], axis=1).min()))
    return best


#: Face planes whose distances bound a point's depth in :func:`depth_inside`, and points measured at a time.
_BOUND_PLANES = 24
_BOUND_BLOCK = 64


def _bounding_planes(equations: np.ndarray) -> np.ndarray | None:
    """Every k-th of a hull's face planes ``equations`` (f, 4), about :data:`_BOUND_PLANES` of them: a point beyond
    any of them is outside the hull, its distance to them bounds its depth; None when the hull has too few faces
    for them to save work."""
    return equations[:: len(equations) // _BOUND_PLANES] if len(equations) > 2 * _BOUND_PLANES else None


def merge_pieces(pieces: list[Piece], limit: int, others: np.ndarray | None = None, *,
                 free_only: bool = False) -> list[Piece]:
    """At most ``limit`` pieces: the pair whose merged hull adds the least
    volume (``vol(hull(A u B)) - vol(A) - vol(B)``, m^3) is merged first,
    among each piece's 8 nearest pieces (by centre). A merge that
    would newly contain any of ``others`` (k, 3) m (other links' vertices in
    this link's frame) costs more than any merge that does not; with
    ``free_only`` such merges are never made (merging stops before one).

    Which merges hold one of ``others`` is measured lazily: a pair enters the queue at its volume cost, a lower
    bound of its cost, and is measured when it comes first (re-queued with the penalty when it holds a point), so a
    pair a merge retires before it comes first is never measured. The merges made are the same as when every pair
    is measured on entry (the queue's order over the measured costs is the same): a pair is measured by the same
    products of the same rows of ``others`` (those in the merged hull's box) either way, so no BLAS kernel's choice
    of how it blocks the rows can tell the two apart.

    A pair holds a point when the merged hull holds it and neither piece does: the pieces are measured only on the
    points the merged hull holds, and a point off a piece's box or beyond any of a few of its planes
    (:data:`_BOUND_PLANES`) is outside it without the rest. Each point's test is its own (three products and a sum
    per plane); tests measuring every point on every plane find the same merges, and the dev rows' outputs are
    byte-identical (``benchmarks/bench_determinism.py --against`` outputs kept before the bounds)."""
    pieces = list(pieces)
    if len(pieces) <= limit:
        return pieces
    others = np.zeros((0, 3)) if others is None else np.asarray(others, float)
    others = others[np.argsort(others[:, 0], kind="stable")]  # by x: a box's points are one slice of it
    xs = others[:, 0]
    alive = {i: p for i, p in enumerate(pieces)}
    nxt = len(pieces)
    penalty = 1.0 + sum(p.volume for p in pieces) * 1e6

    def cost(a: Piece, b: Piece) -> tuple[float, Piece | None]:  # the volume cost: a lower bound of the cost
        try:  # on support points (an inner approximation of each hull): Qhull's time grows with the points
            m = Piece.of(np.vstack([a.support, b.support]))
        except (QhullError, ValueError):
            return float("inf"), None
        return m.volume - a.volume - b.volume, m

    def outside(i: int, rows: np.ndarray, threshold: float) -> np.ndarray:  # each of others[rows] not inside alive piece i
        q = alive[i]
        pts = others[rows]
        out = np.ones(len(rows), bool)  # a point off the piece's box is outside it by far more than the threshold
        near = np.flatnonzero(np.all((pts >= q.points.min(axis=0)) & (pts <= q.points.max(axis=0)), axis=1))
        eq = q.equations
        few = _bounding_planes(eq)
        if few is not None:  # outside a few of the face planes is outside: the rest measured on them all
            near = near[np.max(pts[near] @ few[:, :3].T + few[:, 3], axis=1) < threshold]
        out[near] = np.max(pts[near] @ eq[:, :3].T + eq[:, 3], axis=1) >= threshold
        return out

    def holds_other(m: Piece, i: int, j: int) -> bool:  # whether merging alive pieces i and j into m newly holds one of others
        lo, hi = m.points.min(axis=0), m.points.max(axis=0)
        start = np.searchsorted(xs, lo[0], "left")
        band = others[start:np.searchsorted(xs, hi[0], "right")]
        rows = start + np.flatnonzero(np.all((band[:, 1:] >= lo[1:]) & (band[:, 1:] <= hi[1:]), axis=1))
        threshold = -_INSIDE_EPS * float(np.ptp(m.points, axis=0).max())
        rows = rows[np.max(others[rows] @ m.equations[:, :3].T + m.equations[:, 3], axis=1) < threshold]  # inside m
        rows = rows[outside(i, rows, threshold)]  # and outside i: each row's test is its own
        return bool(len(rows) and outside(j, rows, threshold).any())

    centres: dict[int, np.ndarray] = {}

    def centre(i: int) -> np.ndarray:  # of alive piece i, computed once
        c = centres.get(i)
        if c is None:
            c = centres[i] = alive[i].points.mean(axis=0)
        return c

    heap: list[tuple[float, int, int, bool]] = []  # (cost, i, j, measured against others)
    merged: dict[tuple[int, int], Piece] = {}

    def push_for(i: int) -> None:
        ids = [j for j in alive if j != i]
        if not ids:
            return
        cs = np.array([centre(j) for j in ids])
        order = np.argsort(np.linalg.norm(cs - centre(i), axis=1))[:8]
        for o in order:
            j = ids[int(o)]
            key = (min(i, j), max(i, j))
            if key in merged:
                continue
            c, m = cost(alive[key[0]], alive[key[1]])
            if m is not None:
                merged[key] = m
                heapq.heappush(heap, (c, key[0], key[1], False))

    for i in list(alive):
        push_for(i)
    while len(alive) > limit and heap:
        c, i, j, measured = heapq.heappop(heap)
        if i not in alive or j not in alive:
            continue
        if not measured and holds_other(merged[(i, j)], i, j):
            heapq.heappush(heap, (c + penalty, i, j, True))
            continue
        if free_only and c >= penalty:
            break
        merged.pop((i, j))
        a, b = alive.pop(i), alive.pop(j)
        alive[nxt] = Piece.of(np.vstack([a.points, b.points]), a.sources + tuple(s for s in b.sources if s not in a.sources))
        push_for(nxt)
        nxt += 1
    if len(alive) > limit and not free_only:  # no neighbour pair could merge: merge everything left into the limit by order
        rest = list(alive.values())
        while len(rest) > limit:
            a, b = rest.pop(), rest.pop()
            rest.append(Piece.of(np.vstack([a.points, b.points]), a.sources + b.sources))
        return rest
    return list(alive.values())


def clip_piece(piece: Piece, normal: np.ndarray, offset: float) -> Piece | None:
    """``piece`` cut by the half-space ``normal . x + offset <= 0`` (m): the
    hull of its vertices inside the half-space and of the points where its
    edges cross the plane; None when nothing with volume is left."""
    verts, edges = _memo(_HULL_EDGES, piece.points, _hull_edges)
    s = verts @ normal + offset
    keep = [verts[s <= 0]]
    a, b = edges[:, 0], edges[:, 1]
    cross = (s[a] > 0) != (s[b] > 0)
    if cross.any():
        t = s[a[cross]] / (s[a[cross]] - s[b[cross]])
        keep.append(verts[a[cross]] + t[:, None] * (verts[b[cross]] - verts[a[cross]]))
    return solid_piece(np.vstack(keep), piece.sources)


def _hull_edges(pts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(vertices (k, 3) m, edges (e, 2) vertex indices a < b in lexicographic order) of the hull of ``pts``."""
    verts, tris = mesh_io.convex_hull_mesh(pts)
    pairs = np.sort(np.concatenate([tris[:, [0, 1]], tris[:, [1, 2]], tris[:, [2, 0]]]), axis=1).astype(np.int64)
    n = max(1, len(verts))
    code = np.unique(pairs[:, 0] * n + pairs[:, 1])  # as np.unique(pairs, axis=0), on one integer per edge
    return verts, np.stack([code // n, code % n], axis=1)


#: Hull vertices and edges (:func:`_hull_edges`) of the pieces :func:`clip_piece` cut, in this process.
_HULL_EDGES: cachetools.FIFOCache = cachetools.FIFOCache(maxsize=5000)


#: Volume (m^3) under which a piece a cut or trim left is a sliver and is dropped: 1 mm^3.
MIN_PIECE_VOLUME = 1e-9


def drop_slivers(pieces: list[Piece]) -> list[Piece]:
    """``pieces`` without slivers (volume < :data:`MIN_PIECE_VOLUME`) and
    without pieces whose every vertex lies inside another piece (a
    duplicate adds no volume); the largest piece is always kept."""
    if len(pieces) <= 1:
        return list(pieces)
    kept: list[Piece] = []
    for p in sorted(pieces, key=lambda p: -p.volume):
        if kept and p.volume < MIN_PIECE_VOLUME:
            continue
        tol = 1e-9 * max(float(np.ptp(p.points, axis=0).max()), 1e-9)
        if any(not _surely_outside(p.support, q, tol)
               and np.all(p.points @ q.equations[:, :3].T + q.equations[:, 3] <= tol) for q in kept):
            continue
        kept.append(p)
    return [p for p in pieces if any(p is k for k in kept)]


def _surely_outside(points: np.ndarray, piece: Piece, tol: float) -> bool:
    """Whether one of ``points`` (k, 3) m lies beyond a face plane of ``piece`` by more than ``tol`` m plus a bound far
    above the floating-point error of the distances to the planes (unit normals; any summation order: 1e-12 of the
    largest coordinate and offset, the error being ~1e-16 of them): then no computation of the planes over a superset
    of ``points`` finds them all within ``tol`` (a cheap test on a few points, e.g. :attr:`Piece.support`, before the
    full one)."""
    if len(points) == 0:
        return False
    d = points @ piece.equations[:, :3].T + piece.equations[:, 3]
    margin = 1e-12 * (1.0 + float(np.abs(points).max(initial=0.0))
                      + float(np.abs(piece.equations[:, 3]).max(initial=0.0)))
    return bool(d.max() > tol + margin)
