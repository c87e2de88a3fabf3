"""Output collision geometry that every engine takes.

Every simulator collides a moving mesh through convex shapes: PyBullet one
hull per OBJ group, PhysX one cooked hull per mesh, MuJoCo one hull per mesh
file (and it refuses flat ones), Drake one hull per file. The input's visual
part meshes make poor collision files: flat (zero-thickness) groups that
MuJoCo's URDF importer refuses, degenerate groups, faces wound inside-out, and
links made of a hundred small parts (a laptop's keys) that become a hundred
geoms and hundreds of contacts.

:func:`convex_collisions` replaces the mesh collisions of every link of a
written URDF model by a few closed convex pieces, written as OBJ files in the
link frame (scale and collision origin baked in), each:

- the convex hull of one OBJ group of the link's collision meshes (the hull
  PyBullet collided with before), so the colliding volume is unchanged where
  nothing below applies;
- never flat: a group thinner than :data:`FLAT_WIDTH` is grown
  symmetrically along its thinnest direction to :data:`MIN_THICKNESS` (the
  2 mm slab of :data:`asset2sim.engines.loading.FLAT_HULL_THICKNESS`); a
  group that spans no area (a point or a segment) is dropped;
- wound with outward normals (every face's normal points away from the
  hull's interior);
- at most :data:`MAX_PIECES_PER_LINK` per link (:data:`MAX_PIECES_HARD`
  when fewer pieces would hold another link): beyond that, the two pieces
  whose merged hull adds the least empty volume are merged, repeatedly
  (the greedy hierarchical merge of Mamou and Ghorbel, "A simple and
  efficient approach for 3D mesh approximate convex decomposition", ICIP
  2009), never into a hull that would swallow another link's geometry
  anywhere over the joints' ranges (each joint swept in turn,
  :func:`swept_other_points`) when another merge is possible.

A parent whose piece contains its child (a toilet seat inside the convex
hull of the bowl) would make the two collide as soon as an engine does not
skip parent-child pairs (a fixed object, a robot finger in between), and a
hull that fills the space the child moves through blocks the joint.
:func:`convex_collisions` measures the depth of the child's vertices inside
the parent's pieces over the whole range of the joint between them
(:func:`swept_child_points`: the volume the child sweeps); above
:data:`CONTAINMENT_TOLERANCE` the parent's mesh is cut into convex pieces
around that volume (:func:`split_surface`: the surface, densely sampled, is
halved across its longest extent where a piece's hull still holds the child,
a binary space partition as in the BSP-tree decompositions of Naylor,
"Binary space partitioning trees as an alternative representation of
polytopes", CAD 1990), kept only when the child then sits less deep. Parts
are never moved. CoACD (used by the state search,
:mod:`asset2sim.tasks.state.collision`) took 215 s on the toilet 102703's
bowl on this machine; the cut takes well under a second.

Two links that are not parent and child and touch where they slide past
each other (two drawers stacked in a cabinet, two doors meeting in the
middle) are given running clearance (:func:`running_clearance`): the moving
piece's face is moved back :data:`RUNNING_CLEARANCE` from its neighbour at
the modelled pose, so the engines' contact margins do not read the touch as
2 mm of penetration whose recovery and friction hold the part. A contact
along the motion (a stop) is kept.

The pieces depend on the geometry and the joint limits only, never on the
initial state: the state search, the limit scan, the post-check and the
evaluation's closed ends all measure the same collision geometry whatever
state the file was written at (cutting and merging at the initial state made
faucet 148's written pieces close its handle at -0.079 rad where the input's
closed at -0.228 rad).
"""

from __future__ import annotations

import hashlib
import heapq
import json
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.spatial import ConvexHull, QhullError

from asset2sim import array_cache, atomic, file_names, mesh_io, urdf
from asset2sim.frames import axis_angle_matrix
from asset2sim.engines.loading import FLAT_HULL_THICKNESS, mesh_hulls
from asset2sim.tasks.geometry import limits

#: Most convex pieces a link's collision keeps. MuJoCo makes one contact per
#: colliding geom pair (``mjMAXCONPAIR`` more only for multi-contact pairs),
#: so contacts grow with the number of pieces: laptop 9912 with 118 part
#: meshes made 423 contacts in a 5 cm drop and overflowed MuJoCo's default
#: arena. 16 is the number of hulls this project already asks CoACD for per
#: mesh (:data:`asset2sim.tasks.state.collision.COACD_SETTINGS`), enough for a
#: drawer, a box or a cabinet with shelves (5-10 slabs) to keep their hollow.
MAX_PIECES_PER_LINK = 16

#: Most convex pieces a link keeps when merging further would make a piece
#: hold another link somewhere over the joints' ranges (a parent cut around
#: the volume its child sweeps): twice :data:`MAX_PIECES_PER_LINK`, still
#: far below the 118 pieces of laptop 9912 that overflowed MuJoCo.
MAX_PIECES_HARD = 32

#: Thinnest convex piece written, m: the 2 mm slab every engine here takes
#: (PyBullet inflates a flat hull by its 1 mm margin per side; PhysX cannot
#: cook a flat hull and MuJoCo refuses it).
MIN_THICKNESS = FLAT_HULL_THICKNESS

#: Width (m) under which a piece counts as flat and is grown to
#: :data:`MIN_THICKNESS`: 0.1 mm, far above Qhull's precision (MuJoCo's
#: "coplanar vertices" refusal, PhysX's failed cooking) and far below any
#: modelled wall.
FLAT_WIDTH = 1e-4

#: Depth (m) a child may sit inside its parent's collision pieces at the
#: initial state before the parent is decomposed: the SPEC's 2 mm
#: penetration tolerance.
CONTAINMENT_TOLERANCE = 0.002

#: Relative tolerance (of a piece's size) under which a point counts as
#: inside a hull (numerical noise of Qhull's plane equations).
_INSIDE_EPS = 1e-9


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
        """The hull of ``points`` (k, 3) m (Qhull once per distinct point
        array in this process: :data:`_HULLS`; the arrays are shared, never
        modified).

        Raises:
            QhullError, ValueError: the points span no volume.
        """
        pts = np.ascontiguousarray(points, dtype=float)
        key = (pts.shape, hashlib.sha1(pts.tobytes()).digest())
        hit = _HULLS.get(key)
        if hit is None:
            hull = ConvexHull(pts)
            hit = (hull.points[hull.vertices], hull.equations, float(hull.volume))
            if len(_HULLS) >= _HULLS_MAX:
                _HULLS.pop(next(iter(_HULLS)))
            _HULLS[key] = hit
        return cls(hit[0], hit[1], hit[2], sources)


#: Hulls computed in this process: (shape, SHA-1 of the points) -> (vertices,
#: equations, volume). A refine run builds the same pieces at every write
#: (state search, post-check, escalation rounds), and the greedy merge tries
#: the same pairs again for every initial state.
_HULLS: dict[tuple, tuple[np.ndarray, np.ndarray, float]] = {}
_HULLS_MAX = 5000


@dataclass
class LinkPieces:
    """What :func:`link_pieces` made of one link: the ``pieces``, how many
    input groups there were (``n_groups``), and ``notes``."""

    pieces: list[Piece]
    n_groups: int
    notes: list[str] = field(default_factory=list)


def solid_points(points: np.ndarray, thickness: float = MIN_THICKNESS, flat: float = None) -> np.ndarray | None:
    """``points`` (k, 3) m, grown to ``thickness`` m along their thinnest
    principal direction (both sides equally) when they are flat (thinner than
    ``flat`` m, default :data:`FLAT_WIDTH`); None when they span no area
    (fewer than 3 points, or all on a line). Thin but not flat sets are kept
    as they are: the collision volume the engines used before."""
    flat = FLAT_WIDTH if flat is None else flat
    p = np.asarray(points, float)
    p = p[np.all(np.isfinite(p), axis=1)]
    if len(p) < 3:
        return None
    c = p.mean(axis=0)
    _, sv, vt = np.linalg.svd(p - c, full_matrices=False)
    scale = max(float(sv[0]), 1e-12)
    if len(sv) < 2 or sv[1] <= 1e-9 * scale:
        return None
    n = vt[2] if vt.shape[0] == 3 else np.cross(vt[0], vt[1])
    n = n / np.linalg.norm(n)
    width = float(np.ptp(p @ n))
    if width >= min(flat, thickness):
        return p
    h = 0.5 * (thickness - width)
    return np.vstack([p + h * n, p - h * n])


def _sphere_directions(n: int = 100) -> np.ndarray:
    """``n`` unit vectors (n, 3) spread evenly over the sphere (Fibonacci lattice)."""
    i = np.arange(n) + 0.5
    phi = np.arccos(1 - 2 * i / n)
    theta = np.pi * (1 + 5 ** 0.5) * i
    return np.stack([np.cos(theta) * np.sin(phi), np.sin(theta) * np.sin(phi), np.cos(phi)], axis=1)


_DIRECTIONS = _sphere_directions()


def support_points(points: np.ndarray) -> np.ndarray:
    """The extreme points (<= 100, 3) of ``points`` (k, 3) along 100 evenly
    spread directions: their hull is inside the hull of ``points`` and close
    to it (within the polytope approximation error of 100 support directions)."""
    p = np.asarray(points, float)
    if len(p) <= len(_DIRECTIONS):
        return p
    return p[np.unique(np.argmax(p @ _DIRECTIONS.T, axis=0))]


def piece_obj(piece: Piece) -> bytes:
    """OBJ bytes of ``piece``: its hull vertices and triangles wound so that
    every face normal (right-hand rule) points outward (made once per
    distinct point array in this process, :data:`_OBJS`)."""
    pts = np.ascontiguousarray(piece.points, dtype=float)
    key = (pts.shape, hashlib.sha1(pts.tobytes()).digest())
    data = _OBJS.get(key)
    if data is None:
        data = mesh_io.hull_obj(pts)
        if len(_OBJS) >= 4096:
            _OBJS.pop(next(iter(_OBJS)))
        _OBJS[key] = data
    return data


#: OBJ bytes of pieces written in this process, by (shape, SHA-1 of the points).
_OBJS: dict[tuple, bytes] = {}


def depth_inside(points: np.ndarray, piece: Piece) -> float:
    """Largest depth (m, >= 0) of any of ``points`` (k, 3) inside ``piece``
    (distance to the nearest face plane of a point inside the hull)."""
    if len(points) == 0:
        return 0.0
    lo, hi = piece.points.min(axis=0), piece.points.max(axis=0)
    points = points[np.all((points > lo) & (points < hi), axis=1)]  # only points in the box can be inside
    if len(points) == 0:
        return 0.0
    d = np.max(points @ piece.equations[:, :3].T + piece.equations[:, 3], axis=1)
    return float(max(0.0, -d.min()))


def _group_pieces(link: urdf.UrdfLink, mesh_path, notes: list[str]) -> tuple[list[Piece], int]:
    """Pieces of every mesh collision of ``link`` (one per OBJ group, in the
    link frame, :func:`solid_points` applied)."""
    out: list[Piece] = []
    n = 0
    for k, c in enumerate(link.collisions):
        if c.kind != "mesh":
            continue
        path = mesh_path(c)
        try:
            groups = mesh_hulls(path, c.scale)
        except urdf.UrdfError as exc:
            raise CollisionGeometryError(f"link {link.name!r} collision {k} ({c.filename}): {exc}") from exc
        for g, pts in enumerate(groups):
            n += 1
            solid = solid_points(pts)
            if solid is None:
                notes.append(f"link {link.name!r}: group {g} of {c.filename} spans no area; no collision")
                continue
            world = solid @ c.origin[:3, :3].T + c.origin[:3, 3]
            try:
                out.append(Piece.of(world, (str(c.filename),)))
            except (QhullError, ValueError):
                notes.append(f"link {link.name!r}: group {g} of {c.filename} has no hull; no collision")
    return out, n


def merge_pieces(pieces: list[Piece], limit: int, others: np.ndarray | None = None, neighbours: int = 8,
                 *, free_only: bool = False) -> list[Piece]:
    """At most ``limit`` pieces: the pair whose merged hull adds the least
    volume (``vol(hull(A u B)) - vol(A) - vol(B)``, m^3) is merged first,
    among each piece's ``neighbours`` nearest pieces (by centre). A merge that
    would newly contain any of ``others`` (k, 3) m (other links' vertices in
    this link's frame) costs more than any merge that does not; with
    ``free_only`` such merges are never made (merging stops before one)."""
    pieces = list(pieces)
    if len(pieces) <= limit:
        return pieces
    others = np.zeros((0, 3)) if others is None else np.asarray(others, float)
    others = others[np.argsort(others[:, 0], kind="stable")]  # by x: a box's points are one slice of it
    xs = others[:, 0]
    alive = {i: p for i, p in enumerate(pieces)}
    nxt = len(pieces)
    penalty = 1.0 + sum(p.volume for p in pieces) * 1e6

    def cost(a: Piece, b: Piece) -> tuple[float, Piece | None]:
        try:  # on support points (an inner approximation of each hull): Qhull's time grows with the points
            m = Piece.of(np.vstack([a.support, b.support]))
        except (QhullError, ValueError):
            return float("inf"), None
        c = m.volume - a.volume - b.volume
        if len(others):
            lo, hi = m.points.min(axis=0), m.points.max(axis=0)
            band = others[np.searchsorted(xs, lo[0], "left"):np.searchsorted(xs, hi[0], "right")]
            near = band[np.all((band[:, 1:] >= lo[1:]) & (band[:, 1:] <= hi[1:]), axis=1)]
            size = float(np.ptp(m.points, axis=0).max())
            if len(near):
                inside_m = np.max(near @ m.equations[:, :3].T + m.equations[:, 3], axis=1) < -_INSIDE_EPS * size
                if inside_m.any():
                    before = np.zeros(len(near), bool)
                    for p in (a, b):
                        before |= np.max(near @ p.equations[:, :3].T + p.equations[:, 3], axis=1) < -_INSIDE_EPS * size
                    if (inside_m & ~before).any():
                        c += penalty
        return c, m

    def centre(p: Piece) -> np.ndarray:
        return p.points.mean(axis=0)

    heap: list[tuple[float, int, int]] = []
    merged: dict[tuple[int, int], Piece] = {}

    def push_for(i: int) -> None:
        ids = [j for j in alive if j != i]
        if not ids:
            return
        cs = np.array([centre(alive[j]) for j in ids])
        order = np.argsort(np.linalg.norm(cs - centre(alive[i]), axis=1))[:neighbours]
        for o in order:
            j = ids[int(o)]
            key = (min(i, j), max(i, j))
            if key in merged:
                continue
            c, m = cost(alive[key[0]], alive[key[1]])
            if m is not None:
                merged[key] = m
                heapq.heappush(heap, (c, key[0], key[1]))

    for i in list(alive):
        push_for(i)
    while len(alive) > limit and heap:
        c, i, j = heapq.heappop(heap)
        if i not in alive or j not in alive:
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
    return np.unique(np.vstack(out), axis=0)


#: Where a point set may be cut, as fractions of its extent along each axis
#: of the link frame: near the ends a cut peels a wall off a hollow part, in
#: the middle it halves a long one.
CUT_FRACTIONS = (0.04, 0.1, 0.2, 0.35, 0.5, 0.65, 0.8, 0.9, 0.96)


def facets(triangles: np.ndarray, gap: float) -> list[np.ndarray]:
    """The triangles (m, 3, 3) grouped into facets: by the axis direction
    (+-x, +-y, +-z) their normal is closest to, then, within a direction,
    into layers along that axis separated by more than ``gap`` m (the inner
    face of one wall and the outer face of the opposite wall face the same
    way). Each facet is nearly flat across the axis it faces, so its hull
    hugs it; returns the facets' triangles (largest first)."""
    tri = np.asarray(triangles, float)
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    good = np.linalg.norm(n, axis=1) > 0
    tri, n = tri[good], n[good]
    if len(tri) == 0:
        return []
    dirs = np.vstack([np.eye(3), -np.eye(3)])
    bin_ = np.argmax(n @ dirs.T / np.linalg.norm(n, axis=1)[:, None], axis=1)
    out = []
    for b in range(6):
        t = tri[bin_ == b]
        if len(t) == 0:
            continue
        ax = b % 3
        c = t[:, :, ax].mean(axis=1)
        order = np.argsort(c)
        lo, hi = t[order][:, :, ax].min(axis=1), t[order][:, :, ax].max(axis=1)
        reach = np.maximum.accumulate(hi)
        cuts = np.nonzero(lo[1:] > reach[:-1] + gap)[0] + 1
        out += [t[order][a:b2] for a, b2 in zip(np.r_[0, cuts], np.r_[cuts, len(t)])]
    return sorted(out, key=len, reverse=True)


#: Points of a set that :func:`split_surface` measures a candidate cut with,
#: and child vertices it keeps out (even subsamples: time grows with both).
MEASURE_SAMPLES = 1000
PROBE_POINTS = 1500


def split_surface(points: np.ndarray, keep_out: np.ndarray, tolerance: float, budget: int, spacing: float) -> list[np.ndarray]:
    """Split surface samples ``points`` (k, 3) m into point sets whose hulls
    hold none of ``keep_out`` (j, 3) m deeper than ``tolerance`` m.

    Greedy binary space partition: the set whose hull holds a point deepest
    is cut by the plane (normal along an axis of the frame, at one of
    :data:`CUT_FRACTIONS` of the set's extent) after which the deeper of the
    two halves holds ``keep_out`` least deep (ties: the smaller summed hull
    volume; the planes through the keep-out point held deepest are tried as
    well); points within ``spacing`` of the plane go to both halves, so
    neighbouring hulls overlap and leave no gap. Stops when no hull holds a
    point deeper than ``tolerance``, when ``budget`` sets exist, or when no
    cut helps. Returns the point sets."""
    def hull_of(p: np.ndarray) -> Piece | None:
        p = p[:: max(1, len(p) // MEASURE_SAMPLES)]  # an even subsample guides the cut; the pieces keep every point
        solid = solid_points(p)
        if solid is None:
            return None
        try:
            return Piece.of(solid)
        except (QhullError, ValueError):
            return None

    def measure(p: np.ndarray) -> tuple[float, float]:
        piece = hull_of(p)
        return (0.0, 0.0) if piece is None else (depth_inside(keep_out, piece), piece.volume)

    def deepest(p: np.ndarray) -> np.ndarray | None:
        """The keep-out point held deepest by the hull of ``p`` (3,), or None."""
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
                (dl, vl), (dh, vh) = measure(lo), measure(hi)
                score = (max(dl, dh), vl + vh)
                if best is None or score < best[0]:
                    best = (score, (dl, lo), (dh, hi))
        if best is None or best[0][0] >= d:
            break
        sets = sets[1:] + [best[1], best[2]]
    return [p for _, p in sets]


def _split_pieces(link: urdf.UrdfLink, source: str, mesh_path, keep_out: np.ndarray, budget: int) -> list[Piece]:
    """Pieces of the collision mesh ``source`` of ``link`` (link frame) cut
    by :func:`split_surface` so that they hold none of ``keep_out`` (k, 3)
    deeper than :data:`CONTAINMENT_TOLERANCE`, at most ``budget`` pieces.

    Raises:
        CollisionGeometryError: the mesh cannot be read.
    """
    tris = []
    for c in link.collisions:
        if c.kind != "mesh" or str(c.filename) != source:
            continue
        try:
            v, f, _ = mesh_io.read_mesh(mesh_path(c))
        except mesh_io.MeshReadError as exc:
            raise CollisionGeometryError(f"link {link.name!r}: {exc}") from exc
        v = np.asarray(v, float) * c.scale @ c.origin[:3, :3].T + c.origin[:3, 3]
        f = np.asarray(f, int)
        f = f[np.all((f >= 0) & (f < len(v)), axis=1)]
        t = v[f]
        tris.append(t[np.all(np.isfinite(t), axis=(1, 2))])
    if not tris:
        return []
    tri = np.concatenate(tris)
    size = float(np.ptp(tri.reshape(-1, 3), axis=0).max())
    spacing = size / SPLIT_RESOLUTION
    best: list[Piece] = []
    best_depth = np.inf
    for parts in (facets(tri, 2 * spacing), [tri]):  # cut facet by facet, or the whole surface: the better
        sets = []
        for part in parts:
            samples = surface_samples(part, spacing)
            if len(samples) > MAX_SPLIT_SAMPLES:  # a fixed subsample: the same pieces on every run
                samples = samples[np.random.default_rng(0).choice(len(samples), MAX_SPLIT_SAMPLES, replace=False)]
            sets += split_surface(samples, keep_out, CONTAINMENT_TOLERANCE, budget, spacing)
        out = []
        for p in sets:
            solid = solid_points(p)
            if solid is None:
                continue
            try:
                out.append(Piece.of(solid, (source,)))
            except (QhullError, ValueError):
                continue
        out = merge_pieces(out, 1, keep_out, free_only=True)
        depth = max((depth_inside(keep_out, p) for p in out), default=0.0)
        if depth < best_depth - 1e-6 or (depth <= best_depth + 1e-6 and len(out) < len(best)):
            best, best_depth = out, depth
        if best_depth <= CONTAINMENT_TOLERANCE:
            break
    return best


#: Surface sampling of a parent mesh cut around its child: samples at most
#: 1/24 of the mesh's largest extent apart (4 mm on a 10 cm part), at most
#: :data:`MAX_SPLIT_SAMPLES` of them (time grows with the samples).
SPLIT_RESOLUTION = 24
MAX_SPLIT_SAMPLES = 8000


def _child_points(model: urdf.UrdfModel, pieces: dict[str, list[Piece]], poses: dict[str, np.ndarray], link: str) -> dict[str, np.ndarray]:
    """Vertices of every child link's pieces in ``link``'s frame at ``poses``."""
    inv = np.linalg.inv(poses[link])
    out = {}
    for j in model.children(link):
        pts = [p.points for p in pieces.get(j.child, [])]
        if not pts:
            continue
        T = inv @ poses[j.child]
        out[j.child] = np.vstack(pts) @ T[:3, :3].T + T[:3, 3]
    return out


#: Largest motion (m) of a child's collision vertex between two neighbouring
#: positions of its joint at which the child is kept out of its parent's
#: pieces (:func:`sweep_positions`): the 2 mm containment tolerance, so a
#: hull that holds no sampled position holds the positions in between no
#: deeper than about that; at most :data:`MAX_SWEEP_SAMPLES` positions (the
#: time of a cut grows with them).
SWEEP_STEP = CONTAINMENT_TOLERANCE
MAX_SWEEP_SAMPLES = 48


def sweep_positions(joint: urdf.UrdfJoint, reach: float, step: float = SWEEP_STEP) -> np.ndarray:
    """Positions (n,) rad or m spread evenly over ``joint``'s whole range
    (its limits; a continuous joint over a full turn), at most ``step`` m of
    motion apart for a point ``reach`` m from a revolute axis (a prismatic
    joint moves every point by the travel), n <= :data:`MAX_SWEEP_SAMPLES`;
    [0] for a fixed joint or an empty range."""
    if joint.type == "fixed":
        return np.zeros(1)
    if joint.type == "continuous":
        lo, hi = -np.pi, np.pi
    else:
        lo, hi = float(joint.lower), float(joint.upper)
    if not (np.isfinite(lo) and np.isfinite(hi)) or hi <= lo:
        return np.array([0.0 if not np.isfinite(lo) else lo])
    travel = (hi - lo) * (1.0 if joint.type == "prismatic" else max(reach, 1e-9))
    n = int(np.clip(np.ceil(travel / max(step, 1e-9)) + 1, 2, MAX_SWEEP_SAMPLES))
    return np.linspace(lo, hi, n)


def _joint_motion(joint: urdf.UrdfJoint, q: float) -> np.ndarray:
    """(4, 4) parent -> child transform of ``joint`` at position ``q`` (rad
    or m): its origin, then the rotation about or translation along its axis,
    as :meth:`asset2sim.urdf.UrdfModel.link_poses` composes it."""
    m = np.eye(4)
    if joint.type in ("revolute", "continuous"):
        m[:3, :3] = axis_angle_matrix(joint.axis, float(q))
    elif joint.type == "prismatic":
        m[:3, 3] = joint.axis * float(q)
    return joint.origin @ m


def reference_state(model: urdf.UrdfModel) -> dict[str, float]:
    """Joint -> 0 clipped to its limits (rad or m; 0 for a joint without
    finite limits): the pose the other joints hold while one is swept."""
    ref = {}
    for j in model.movable_joints:
        lo, hi = j.lower, j.upper
        ref[j.name] = float(np.clip(0.0, lo, hi)) if np.isfinite(lo) and np.isfinite(hi) else 0.0
    return ref


def swept_child_points(model: urdf.UrdfModel, pieces: dict[str, list[Piece]], link: str,
                       support: bool = False) -> dict[str, np.ndarray]:
    """Vertices of every child link's pieces, and of the links below it
    (their :attr:`Piece.support` points with ``support``; the joints below
    at :func:`reference_state`), in ``link``'s frame at every position of
    :func:`sweep_positions` of the joint between them: the volume the child
    sweeps over its whole range (a latch carried through a box by its lid
    included). A parent-child pose depends on that one joint only, so this
    holds for every state of the object. Child -> (k, 3) m."""
    out = {}
    poses = model.link_poses(reference_state(model))
    for j in model.children(link):
        inv = np.linalg.inv(poses[j.child])
        pts, stack = [], [j.child]
        while stack:
            ln = stack.pop()
            stack.extend(c.child for c in model.children(ln))
            T = inv @ poses[ln]
            pts += [(p.support if support else p.points) @ T[:3, :3].T + T[:3, 3] for p in pieces.get(ln, [])]
        if not pts:
            continue
        local = np.vstack(pts)
        # distance of the vertices from the axis (the child frame turns about the axis through its origin)
        reach = float(np.max(np.linalg.norm(np.cross(local, j.axis), axis=1), initial=0.0)) if j.type in ("revolute", "continuous") else 0.0
        sets = []
        for q in sweep_positions(j, reach):
            T = _joint_motion(j, q)
            sets.append(local @ T[:3, :3].T + T[:3, 3])
        out[j.child] = np.vstack(sets)
    return out


def containment_depths(model: urdf.UrdfModel, pieces: dict[str, list[Piece]], state: dict[str, float]) -> dict[tuple[str, str], float]:
    """(parent, child) -> largest depth (m) of a child's collision vertex
    inside one of the parent's pieces, at joint positions ``state`` (rad or m)."""
    poses = model.link_poses(state)
    out = {}
    for parent in model.links:
        for child, pts in _child_points(model, pieces, poses, parent).items():
            out[(parent, child)] = max((depth_inside(pts, p) for p in pieces.get(parent, [])), default=0.0)
    return out


#: Largest part of a parent piece's width (along the face moved) that
#: :func:`shave_piece` may take off: the piece keeps at least half of itself.
MAX_SHAVE_FRACTION = 0.5


def clip_piece(piece: Piece, normal: np.ndarray, offset: float) -> Piece | None:
    """``piece`` cut by the half-space ``normal . x + offset <= 0`` (m): the
    hull of its vertices inside the half-space and of the points where its
    edges cross the plane; None when nothing with volume is left."""
    verts, tris = mesh_io.convex_hull_mesh(piece.points)
    s = verts @ normal + offset
    keep = [verts[s <= 0]]
    edges = np.unique(np.sort(np.concatenate([tris[:, [0, 1]], tris[:, [1, 2]], tris[:, [2, 0]]]), axis=1), axis=0)
    a, b = edges[:, 0], edges[:, 1]
    cross = (s[a] > 0) != (s[b] > 0)
    if cross.any():
        t = s[a[cross]] / (s[a[cross]] - s[b[cross]])
        keep.append(verts[a[cross]] + t[:, None] * (verts[b[cross]] - verts[a[cross]]))
    pts = np.vstack(keep)
    solid = solid_points(pts)
    if solid is None:
        return None
    try:
        return Piece.of(solid, piece.sources)
    except (QhullError, ValueError):
        return None


def shave_piece(piece: Piece, points: np.ndarray, tolerance: float = CONTAINMENT_TOLERANCE,
                max_fraction: float = MAX_SHAVE_FRACTION) -> Piece | None:
    """``piece`` with one face moved inwards just far enough that none of
    ``points`` (k, 3) m held deeper than ``tolerance`` m sits deeper than half
    of it (a margin against rounding): of the
    piece's faces, the one that needs the least move (the overlap of two
    parts' meshes, a drawer's side 3 mm into its carcass's panel: the convex
    panel cannot be cut around it, only trimmed). None when the least move
    exceeds ``max_fraction`` of the piece's width along that face's normal
    (the part does not merely overlap the face: it sits within the piece)."""
    if not len(points):
        return piece
    d = points @ piece.equations[:, :3].T + piece.equations[:, 3]  # (k, f), <= 0 inside
    inside = np.max(d, axis=1) < -tolerance
    if not inside.any():
        return piece
    need = np.max(-d[inside], axis=0) - 0.5 * tolerance  # (f,) move of each face that leaves every point within half the tolerance
    f = int(np.argmin(need))
    n = piece.equations[f, :3]
    width = float(np.ptp(piece.points @ n))
    if need[f] > max_fraction * width:
        return None
    return clip_piece(piece, n, piece.equations[f, 3] + need[f])


def probe_points(points: np.ndarray, pieces: list[Piece], n: int = PROBE_POINTS) -> np.ndarray:
    """At most ``n`` of ``points`` (k, 3) m that guide a cut of ``pieces``:
    those inside any of the pieces (the others cannot be held deeper by a
    piece cut from them), the deepest half of ``n`` first, then an even
    subsample of the rest (an even subsample of a swept child alone missed
    the few vertices that sat deepest)."""
    depth = np.zeros(len(points))
    for p in pieces:
        depth = np.maximum(depth, -np.max(points @ p.equations[:, :3].T + p.equations[:, 3], axis=1))
    inside = np.flatnonzero(depth > 0)
    if len(inside) <= n:
        return points[inside]
    order = inside[np.argsort(-depth[inside])]
    head, rest = order[: n // 2], order[n // 2:]
    return points[np.concatenate([head, rest[:: max(1, len(rest) // (n - len(head)))]])]


def _resolve_containment(model, pieces, mesh_path, notes, decompose: bool, limit: int) -> None:
    """Cut the parent pieces that contain a child deeper than
    :data:`CONTAINMENT_TOLERANCE` anywhere over the child's joint range
    (:func:`swept_child_points`; :func:`_split_pieces`, kept only when the
    children then sit less deep), so that no state of a joint starts or
    moves its child inside its parent's hull; every child of a parent at
    once (a cut around one child alone was undone by the cut around the
    next: toilet 102703's lid and seat). Pieces that still hold a child
    (overlapping meshes) are trimmed (:func:`_trim`)."""
    for parent in list(pieces):
        swept = swept_child_points(model, pieces, parent, support=True)
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
        sources = sorted({s for _, p in deep for s in p.sources})
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
    """Trim the pieces of ``parent`` that hold any of ``pts`` (the swept
    vertices of its children ``child``, names for the notes, (k, 3) m)
    deeper than :data:`CONTAINMENT_TOLERANCE` (:func:`shave_piece`), kept
    when the children then sit less deep than ``depth`` m."""
    shaved = [shave_piece(p, pts) if depth_inside(pts, p) > CONTAINMENT_TOLERANCE else p for p in pieces[parent]]
    shaved = [q if q is not None else p for p, q in zip(pieces[parent], shaved)]
    after = max((depth_inside(pts, p) for p in shaved), default=0.0)
    if after < depth - 1e-6:
        pieces[parent] = shaved
        notes.append(f"link {parent!r}: collision pieces trimmed where {child} overlap them over their ranges: "
                     f"{depth * 1000:.3g} -> {after * 1000:.3g} mm inside")
    else:
        notes.append(f"{child} sit {depth * 1000:.3g} mm inside their parent {parent!r} over their ranges; "
                     "neither cutting nor trimming its pieces helps")


#: Positions per movable joint at which other links are kept out of a link's
#: merged pieces (:func:`merge_pieces`), evenly over the joint's range.
GUARD_SAMPLES = 9


def swept_other_points(model: urdf.UrdfModel, pieces: dict[str, list[Piece]], link: str,
                       samples: int = GUARD_SAMPLES) -> np.ndarray | None:
    """Support points (:attr:`Piece.support`) of every other link's pieces in
    ``link``'s frame, with the movable joints at their reference (0 clipped
    to the limits) and each joint in turn at ``samples`` positions over its
    range: the volume the other links sweep one joint at a time (k, 3) m, or
    None when no other link has pieces. Independent of the initial state."""
    ref = reference_state(model)
    local = {o: np.vstack([p.support for p in pieces[o]]) for o in model.links if o != link and pieces.get(o)}
    if not local:
        return None
    states = [ref]
    for j in model.movable_joints:
        qs = sweep_positions(j, 1.0)
        qs = qs[np.unique(np.linspace(0, len(qs) - 1, min(samples, len(qs))).round().astype(int))]
        states += [{**ref, j.name: float(q)} for q in qs]
    seen: dict[str, list[np.ndarray]] = {o: [] for o in local}
    out = []
    for st in states:
        poses = model.link_poses(st)
        inv = np.linalg.inv(poses[link])
        for o, pts in local.items():
            T = inv @ poses[o]
            if any(np.allclose(T, U, atol=1e-9) for U in seen[o]):
                continue
            seen[o].append(T)
            out.append(pts @ T[:3, :3].T + T[:3, 3])
    return np.vstack(out)


#: Volume (m^3) under which a piece a cut or trim left is a sliver and is
#: dropped: 1 mm^3. Cuts leave duplicates and flakes a tenth of a millimetre
#: thick on a cut plane, which PyBullet collides as 2 mm deep contacts (its
#: convex margin on a hull thinner than the margin: stapler 103275's
#: magazine against 0.1 mm flakes of its base).
MIN_PIECE_VOLUME = 1e-9


def drop_slivers(pieces: list[Piece]) -> list[Piece]:
    """``pieces`` without slivers (volume < :data:`MIN_PIECE_VOLUME`) and
    without pieces whose every vertex lies inside another piece (a
    duplicate adds no volume); the largest piece is always kept."""
    if len(pieces) <= 1:
        return list(pieces)
    order = sorted(range(len(pieces)), key=lambda i: -pieces[i].volume)
    kept: list[Piece] = []
    for i in order:
        p = pieces[i]
        if kept and p.volume < MIN_PIECE_VOLUME:
            continue
        size = float(np.ptp(p.points, axis=0).max())
        if any(np.all(p.points @ q.equations[:, :3].T + q.equations[:, 3] <= 1e-9 * max(size, 1e-9)) for q in kept):
            continue
        kept.append(p)
    return [p for p in pieces if any(p is k for k in kept)]


#: Overlap (m) along the separating direction that :func:`separate_parent_child`
#: leaves between a parent's and its child's pieces: touching (0). Engines
#: with a contact margin read touching hulls as penetrating by the margin
#: (PyBullet: 1 mm per hull, so -2 mm for a touching pair).
SEPARATION_GAP = 0.0

#: Axes projected at once by :func:`penetration_depth` (memory: chunk x points).
_AXIS_CHUNK = 4096


def _edge_directions(piece: Piece) -> np.ndarray:
    """Unit directions (e, 3) of the edges of the hull of ``piece``'s
    support points (:attr:`Piece.support`: at most about 100 vertices), one
    per direction up to sign; diagonals of triangulated facets included
    (extra candidate axes never make :func:`penetration_depth` wrong).
    Computed once per piece (kept on it, turned with it by :func:`_transformed`)."""
    if piece._edges is None:
        piece._edges = _hull_edge_directions(piece.support)
    return piece._edges


def _hull_edge_directions(pts: np.ndarray) -> np.ndarray:
    """See :func:`_edge_directions`; ``pts`` (k, 3)."""
    try:
        verts, tris = mesh_io.convex_hull_mesh(pts)
    except (QhullError, ValueError):
        return np.zeros((0, 3))
    e = np.concatenate([verts[tris[:, 1]] - verts[tris[:, 0]], verts[tris[:, 2]] - verts[tris[:, 1]],
                        verts[tris[:, 0]] - verts[tris[:, 2]]])
    n = np.linalg.norm(e, axis=1)
    e = e[n > 1e-12] / n[n > 1e-12, None]
    flip = (e[:, 0] < 0) | ((e[:, 0] == 0) & (e[:, 1] < 0)) | ((e[:, 0] == 0) & (e[:, 1] == 0) & (e[:, 2] < 0))
    e[flip] *= -1
    _, keep = np.unique(np.round(e * 50.0), axis=0, return_index=True)  # one per ~1 degree cell
    e = e[np.sort(keep)]
    if len(e) > MAX_EDGE_DIRECTIONS:  # an even subsample: fewer axes only bound the depth from above
        e = e[np.linspace(0, len(e) - 1, MAX_EDGE_DIRECTIONS).round().astype(int)]
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
    their projections over the separating-axis candidates of two convex
    polyhedra, the face normals of both and the cross products of their
    edge directions (Gottschalk, Lin and Manocha, "OBBTree", SIGGRAPH 1996;
    Ericson, "Real-Time Collision Detection", 2005, sec. 5.2.1). The
    overlap along any direction bounds the depth from above, so the minimum
    over these candidates is the depth (what MuJoCo's ``mj_geomDistance``
    reports as a negative distance; PyBullet adds its margins). Edge
    directions come from the hull of the support points
    (:func:`_edge_directions`) and candidates are ranked on the support
    points (:func:`_least_overlap`), so the result may read slightly deeper
    than exact, never shallower.

    ``lower_bound``: when the face normals already bound the depth at or
    below it (m), the edge axes are not tried (the result is then an upper
    bound, <= ``lower_bound``)."""
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


def _boxes_apart(a: Piece, b: Piece, T: np.ndarray, margin: float = 1e-9) -> bool:
    """Whether ``b`` moved by the (4, 4) transform ``T`` has an axis-aligned
    bounding box more than ``margin`` m clear of ``a``'s, i.e.
    :func:`penetration_depth` would return 0 at its first test; without
    moving ``b``'s planes, support points and edges (:func:`_transformed`).
    The margin absorbs rounding, so a pose this calls apart is one the exact
    test calls apart too."""
    moved = b.points @ T[:3, :3].T + T[:3, 3]
    lo = np.maximum(a.points.min(axis=0), moved.min(axis=0))
    hi = np.minimum(a.points.max(axis=0), moved.max(axis=0))
    return bool(np.any(hi + margin < lo))


def _joint_transforms(model: urdf.UrdfModel, pieces: dict[str, list[Piece]], joint: urdf.UrdfJoint) -> tuple[list[np.ndarray], int]:
    """(4, 4) parent-frame poses of ``joint``'s child link at every position
    of :func:`sweep_positions` over its range (the reach from the axis taken
    from the child's pieces), in order, and the index of the position
    nearest the joint's :func:`reference_state`. A parent-child pose depends
    on that joint only."""
    local = np.vstack([p.points for p in pieces[joint.child]])
    reach = float(np.max(np.linalg.norm(np.cross(local, joint.axis), axis=1), initial=0.0)) if joint.type in ("revolute", "continuous") else 0.0
    qs = sweep_positions(joint, reach)
    ref = reference_state(model).get(joint.name, 0.0)
    return [_joint_motion(joint, q) for q in qs], int(np.argmin(np.abs(qs - ref)))


def _carried(depth: Callable[[int], float], n: int, ref: int, tolerance: float) -> list[int]:
    """Indices of the ``n`` positions (ordered over the range) whose depth
    (m, ``depth(i)``) the joint carries from its reference position ``ref``:
    the run of depths above ``tolerance`` m that contains ``ref`` (empty
    when the reference position is clear). A depth reached only after the
    child moved clear is a stop (the child runs into its parent), left to
    the limit scan. ``depth`` is asked only for ``ref`` and the run's
    neighbours (one position for a pair clear at the reference)."""
    if depth(ref) <= tolerance:
        return []
    lo = hi = ref
    while lo > 0 and depth(lo - 1) > tolerance:
        lo -= 1
    while hi < n - 1 and depth(hi + 1) > tolerance:
        hi += 1
    return list(range(lo, hi + 1))


def separate_parent_child(model: urdf.UrdfModel, pieces: dict[str, list[Piece]], notes: list[str],
                          tolerance: float = CONTAINMENT_TOLERANCE, state: dict[str, float] | None = None) -> None:
    """Clip, in place, the pieces of every parent and child link so that no
    child piece penetrates a parent piece deeper than ``tolerance`` m
    (:func:`penetration_depth`, the depth an engine colliding the pair
    reports) at the joint's reference position (:func:`reference_state`,
    0 clipped to the limits: the pose the meshes were modelled in) and at
    every position the overlap is carried to from there
    (:func:`sweep_positions` over the range, :func:`_carried`), so the
    pieces stay independent of the initial state. An overlap the child
    only runs into after moving clear of its parent is a stop: it is kept,
    and the limit scan (:mod:`asset2sim.tasks.geometry.limits`) clips the
    joint's range before it. With ``state`` (joint -> rad or m), only that
    state is separated (what :func:`link_pieces` does last for the initial
    state it writes: an overlap the joint was written into). The
    parent-child pairs every engine here skips
    (the SPEC's exclusion) then also work where they are collided (a fixed
    object, a robot's finger between them, a simulator without the
    exclusion). Each overlap is removed along its separating direction by
    cutting one of the two pieces (:func:`clip_piece`), up to :data:`SEPARATION_GAP`; the cut is
    the resolution of any other penetration (move apart along the
    minimum-translation direction) applied to the geometry, since a
    parent and its child cannot move apart. Per pair of pieces, every
    position's cut goes to the same piece, as one of two cuts: the side of
    the piece beyond the plane taken off, or a slot (the band the other
    piece spans along the direction taken out, :func:`_slot`, at most
    :data:`SLOT_PIECES` parts and :data:`MAX_PIECES_HARD` per link: a latch's
    shaft through a lid leaves the lid in pieces around it). Of the four
    (two pieces, two cuts) the one that removes the smallest share of its
    link's volume is made (a small piece of one link held whole in
    another's hull, a dishwasher's rail inside its rack's, is removed
    rather than the rack's hull cut around it; a microwave's thin door is
    not eaten away around its frame); a link's last piece is never removed
    (such an overlap is kept and noted). Cuts only remove volume, so an
    overlap resolved stays resolved."""
    for joint in model.joints:
        P, C = pieces.get(joint.parent), pieces.get(joint.child)
        if not P or not C:
            continue
        if state is None:
            transforms, ref = _joint_transforms(model, pieces, joint)
        else:
            transforms, ref = [_joint_motion(joint, float(state.get(joint.name, reference_state(model).get(joint.name, 0.0))))], 0
        size_p, size_c = sum(p.volume for p in P), sum(c.volume for c in C)
        before = after = 0.0
        cut_p, cut_c, kept = set(), set(), 0
        i = 0
        while i < len(P):
            k = 0
            while k < len(C) and P[i] is not None:
                if C[k] is None:
                    k += 1
                    continue
                planes_p, planes_c, slots_p, slots_c = [], [], [], []
                found: dict[int, tuple[float, np.ndarray]] = {}

                def depth_at(t: int, a: Piece = P[i], b: Piece = C[k]) -> float:
                    """The pair's depth (m) at position ``t`` (kept in ``found``)."""
                    if t not in found:
                        T = transforms[t]
                        found[t] = (0.0, np.zeros(3)) if _boxes_apart(a, b, T) else penetration_depth(a, _transformed(b, T), tolerance)
                    return found[t][0]

                for t in _carried(depth_at, len(transforms), ref, tolerance):
                    T, (d, n) = transforms[t], found[t]
                    c = _transformed(C[k], T)
                    before = max(before, d)
                    # P[i] on the low side along n: keep n.x <= min(c.n) + gap, or c above max(P.n) - gap
                    lo_c, hi_p = float((c.points @ n).min()), float((P[i].points @ n).max())
                    planes_p.append((n, -(lo_c + SEPARATION_GAP)))
                    nc = T[:3, :3].T @ n  # the same direction in the child frame
                    planes_c.append((-nc, hi_p - SEPARATION_GAP - float(n @ T[:3, 3])))
                    # or a slot: the band the other piece spans along n taken out (two pieces left)
                    slots_p.append((n, lo_c + SEPARATION_GAP, float((c.points @ n).max()) - SEPARATION_GAP, c))
                    shift = float(n @ T[:3, 3])
                    slots_c.append((nc, float((P[i].points @ n).min()) - shift + SEPARATION_GAP, hi_p - shift - SEPARATION_GAP,
                                    _transformed(P[i], np.linalg.inv(T))))
                if not planes_p:
                    k += 1
                    continue
                room_p, room_c = MAX_PIECES_HARD - len(P), MAX_PIECES_HARD - len(C)
                options = []  # (loss share, which, parts)
                for which, piece, size, others, planes, slots, room in (("p", P[i], size_p, _others(P, i), planes_p, slots_p, room_p),
                                                                         ("c", C[k], size_c, _others(C, k), planes_c, slots_c, room_c)):
                    for parts in ([_clip_all(piece, planes)], _slot(piece, slots, tolerance, min(SLOT_PIECES, 1 + max(room, 0)))):
                        if parts is None:
                            continue
                        parts = [q for q in parts if q is not None]
                        if not parts and not others:  # a link's last piece is never removed
                            continue
                        options.append(((piece.volume - sum(q.volume for q in parts)) / size, len(parts), which, parts))
                if not options:
                    kept += 1
                    # ``found`` maps position index -> (depth, direction); the
                    # positions not carried read <= tolerance, so this is the carried depth
                    after = max(after, max(d for d, _ in found.values()))
                    k += 1
                    continue
                _, _, which, parts = min(options, key=lambda o: (o[0], o[1]))
                target, idx, cut = (P, i, cut_p) if which == "p" else (C, k, cut_c)
                target[idx] = parts[0] if parts else None
                target.extend(parts[1:])
                cut.add(idx)
                k += 1
            i += 1
        gone = sum(p is None for p in P) + sum(c is None for c in C)
        P[:] = [p for p in P if p is not None]
        C[:] = [c for c in C if c is not None]
        if before > 0.0:
            what = ", ".join(x for x in (f"{len(cut_p)} of {joint.parent!r}'s pieces" if cut_p else "",
                                         f"{len(cut_c)} of {joint.child!r}'s" if cut_c else "") if x)
            notes.append(f"joint {joint.name!r}: {joint.child!r} penetrated its parent {joint.parent!r} up to {before * 1000:.3g} mm "
                         + ("from its reference position on" if state is None else "at the initial state") + f"; cut {what or 'nothing'}" + (f" ({gone} removed whole)" if gone else "")
                         + (f"; {kept} overlap(s) of a link's last piece held whole inside another kept ({after * 1000:.3g} mm)" if kept else ""))


#: Words every note of :func:`running_clearance` (and of the state stage's
#: clearance repair) carries, by which a caller picks them out of the pieces' notes.
RUNNING_CLEARANCE_NOTE = "running clearance"
#: Running clearance (m) given to a sliding contact between two links that
#: are not parent and child: PyBullet's two 1 mm hull margins (touching
#: hulls report 2 mm of penetration; see
#: :data:`asset2sim.engines.loading.FLAT_HULL_THICKNESS`) plus 0.5 mm.
RUNNING_CLEARANCE = 0.0025
#: |cos| between a contact normal and the motion of the moving piece's
#: contact face below which the contact slides (60 deg or more); above it
#: the contact is a stop, the limit's business (:mod:`asset2sim.tasks.geometry.limits`).
SLIDING_COS = 0.5
#: A squeeze never takes more than this fraction of a piece's width along the contact normal.
MAX_SQUEEZE = 0.5
#: Deepest overlap (m) :func:`running_clearance` treats as parts modelled
#: touching (PartNet-Mobility's zero-clearance fits overlap by rounding, well
#: under a millimetre); a deeper one is a penetration the state search and
#: its convex decomposition resolve (a latch's shaft 1.7 mm into a box's
#: solid hull is not shortened here).
TOUCHING_OVERLAP = 0.0005


def sat_gap(p: np.ndarray, q: np.ndarray) -> tuple[float, np.ndarray]:
    """Separating-axis test of two convex point sets (k, 3), (l, 3) m over the
    face normals of both hulls (Gottschalk, Lin and Manocha, "OBBTree",
    SIGGRAPH 1996: the face-normal axes of the SAT for convex polyhedra).
    Returns (gap g m, unit axis n from p to q): g > 0 they are apart by at
    least g; g <= 0 they overlap by at most -g along n.

    Raises:
        ValueError: a set spans no volume.
    """
    try:
        hp, hq = ConvexHull(p), ConvexHull(q)
    except (QhullError, ValueError) as exc:
        raise ValueError("a convex piece spans no volume") from exc
    axes = np.vstack([hp.equations[:, :3], hq.equations[:, :3]])
    axes = axes / np.linalg.norm(axes, axis=1, keepdims=True)
    sp, sq = p @ axes.T, q @ axes.T  # (k, A), (l, A)
    ahead = sq.min(axis=0) - sp.max(axis=0)  # q beyond p along +axis
    behind = sp.min(axis=0) - sq.max(axis=0)  # q before p
    gaps = np.maximum(ahead, behind)
    i = int(np.argmax(gaps))
    n = axes[i] if ahead[i] >= behind[i] else -axes[i]
    return float(gaps[i]), n


def squeeze(p: np.ndarray, n: np.ndarray, delta: float) -> tuple[np.ndarray, float]:
    """Move the face of ``p`` (k, 3) m towards the unit direction ``n`` back
    by ``delta`` m (at most :data:`MAX_SQUEEZE` of its width along ``n``),
    keeping the face towards -n: an affine squeeze along ``n``, so a convex
    piece stays convex. Returns (points (k, 3) m, delta used m)."""
    s = p @ n
    lo, w = float(s.min()), float(np.ptp(s))
    d = min(delta, MAX_SQUEEZE * w)
    if w <= 0 or d <= 0:
        return p, 0.0
    return p - np.outer((s - lo) * (d / w), n), d


def clear_sliding_contact(p: np.ndarray, q: np.ndarray, velocity: Callable[[np.ndarray], np.ndarray],
                          deepest: float = np.inf) -> tuple[np.ndarray, float, float] | None:
    """Running clearance of a moving convex piece ``p`` (k, 3) m against a
    piece ``q`` (l, 3) m of a link it moves past, both in one frame.

    1. :func:`sat_gap` gives the gap g and the axis n (from p to q) of least
       overlap; p and q are in contact when g < :data:`RUNNING_CLEARANCE`
       (and g > -``deepest``: a deeper overlap is left to the state search).
    2. The contact slides when n is nearly perpendicular to the motion of
       p's contact face: |n . t| < :data:`SLIDING_COS` |t|, with t =
       ``velocity(c)`` (3,) the direction the joint moves the face centre c
       (3,) m (a x (c - o) for a revolute joint with axis a through o; a for
       a prismatic one). A contact along the motion is a stop.
    3. p's face towards q is moved back along n by
       :data:`RUNNING_CLEARANCE` - g (:func:`squeeze`): the gap becomes the
       clearance.

    Returns (squeezed p (k, 3) m, squeeze used m, gap g m), or None when
    the two are not in sliding contact (or the squeeze would move nothing).

    Raises:
        ValueError: a piece spans no volume.
    """
    g, n = sat_gap(p, q)
    if g >= RUNNING_CLEARANCE - 1e-9 or g <= -deepest:  # (rounding of a piece already given clearance)
        return None
    s = p @ n
    face = p[s >= s.max() - 1e-3].mean(axis=0)
    t = np.asarray(velocity(face), float)
    norm = float(np.linalg.norm(t))
    if norm > 1e-9 and abs(float(n @ t)) / norm >= SLIDING_COS:
        return None
    out, used = squeeze(p, n, RUNNING_CLEARANCE - g)
    return (out, used, g) if used > 0 else None


def joint_velocity(joint: urdf.UrdfJoint, T: np.ndarray) -> Callable[[np.ndarray], np.ndarray]:
    """The direction (3,) in which ``joint`` moves a point (3,) m given in
    the frame ``T`` (4, 4) (the joint's child frame at its pose is the
    identity): its axis for a prismatic joint, axis x (point - origin) for a
    revolute or continuous one (the child frame's origin lies on the axis),
    both expressed in ``T``'s frame. For :func:`clear_sliding_contact`."""
    R, t = T[:3, :3], T[:3, 3]
    axis = R @ np.asarray(joint.axis, float)
    if joint.type == "prismatic":
        return lambda c: axis
    return lambda c: np.cross(axis, np.asarray(c, float) - t)


def running_clearance(model: urdf.UrdfModel, pieces: dict[str, list[Piece]], notes: list[str]) -> None:
    """Give running clearance, in place, to every sliding contact between a
    link a movable joint moves and a link it does not move (parent-child
    pairs excepted: every engine here skips them, SPEC), measured at
    :func:`reference_state` (the pose the meshes were modelled in, where
    PartNet-Mobility's parts fit with zero clearance): two drawers stacked in
    one cabinet, two doors meeting in the middle, a magazine between the
    walls of a stapler's base. Touching hulls report the engines' two
    contact margins as penetration (PyBullet: 2 mm), the penetration recovery
    presses the faces together and their friction holds the part: ManiSkill
    users report drawers jammed by their neighbours (ManiSkill issues #1205,
    #1156), and a free cabinet's drawer pushed by 1,060 N moved at 0.07 m/s
    (dev object 19179). Each moving piece in contact (gap below
    :data:`RUNNING_CLEARANCE`, overlap at most :data:`TOUCHING_OVERLAP`) along a face that slides
    is squeezed back (:func:`clear_sliding_contact`); a contact along the
    motion (a stop) and deeper overlaps are left as they are. The moving
    link's piece is squeezed, the first joint in file order taking the
    clearance (the other link is then clear); a pair of pieces is squeezed
    once (a thin piece squeezed again by the next joint that moves it would
    halve at every pass, :data:`MAX_SQUEEZE`). Notes name each change."""
    poses = model.link_poses(reference_state(model))
    done: set[tuple[str, int, str, int]] = set()
    parent_of = {j.child: j.parent for j in model.joints}
    boxes = {ln: [(p.points @ poses[ln][:3, :3].T + poses[ln][:3, 3]) for p in pl] for ln, pl in pieces.items()}
    subtrees = limits.subtrees(model)
    for joint in model.movable_joints:
        moved = subtrees[joint.name]
        for ln in moved:
            if not pieces.get(ln):
                continue
            inv = np.linalg.inv(poses[ln])
            velocity = joint_velocity(joint, inv @ poses[joint.child])
            for other in model.links:
                if other in moved or not pieces.get(other) or parent_of.get(ln) == other or parent_of.get(other) == ln:
                    continue
                To = inv @ poses[other]
                for k, Q in enumerate(pieces[other]):
                    qw = boxes[other][k]
                    for i, P in enumerate(pieces[ln]):
                        pw = boxes[ln][i]
                        if (ln, i, other, k) in done:
                            continue
                        if np.any(np.minimum(pw.max(axis=0), qw.max(axis=0)) + RUNNING_CLEARANCE
                                  < np.maximum(pw.min(axis=0), qw.min(axis=0))):
                            continue  # bounding boxes apart by more than the clearance
                        try:
                            hit = clear_sliding_contact(P.points, Q.points @ To[:3, :3].T + To[:3, 3], velocity,
                                                        deepest=TOUCHING_OVERLAP)
                        except ValueError:
                            continue
                        if hit is None:
                            continue
                        pts, used, g = hit
                        done.add((ln, i, other, k))
                        try:
                            pieces[ln][i] = Piece.of(pts, P.sources)
                        except (QhullError, ValueError):
                            continue
                        boxes[ln][i] = pieces[ln][i].points @ poses[ln][:3, :3].T + poses[ln][:3, 3]
                        notes.append(f"link {ln!r}: collision piece {i} given {used * 1000:.2g} mm {RUNNING_CLEARANCE_NOTE} against "
                                     f"{other!r} (gap {g * 1000:.2g} mm, sliding along {joint.name!r})")


#: Height above the lowest collision point of a free-standing object within
#: which the collision vertices of its body are taken to stand on the
#: ground, m (:func:`level_footprint`): PartNet-Mobility's bottoms are
#: modelled to about this (laptop 9912's four corners span 0.49 mm), and it
#: is PyBullet's contact margin of one shape.
LEVEL_TOLERANCE = 1e-3

#: ... at most this fraction of the object's largest horizontal extent (a
#: 5 cm object gets 0.25 mm).
LEVEL_FRACTION = 0.005

#: The words of :func:`level_footprint`'s notes (the report picks them out).
LEVEL_NOTE = "footprint levelled"


def level_footprint(model: urdf.UrdfModel, pieces: dict[str, list[Piece]], state: dict[str, float],
                    notes: list[str]) -> None:
    """Make the footprint of a free-standing object's body planar, in place:
    at ``state`` (joint -> rad or m; the root frame upright as written, z
    up), every collision vertex of the body (the links no movable joint
    moves) lower than the lowest collision point of the object plus
    ``min(LEVEL_TOLERANCE, LEVEL_FRACTION * largest horizontal extent)`` is
    moved straight down onto the plane of that lowest point (each piece is
    the hull of its moved vertices: it only grows, downward).

    Why: a bottom whose corners differ by a fraction of a millimetre
    (modelling noise) stands on three of them like a table with one short
    leg. PyBullet then keeps it balanced on a diagonal with one contact
    pressed 0.6 mm into the ground, creeping 0.5 mm/s for seconds before it
    drops back onto the fourth corner (laptop 9912 halfway open after a 5 deg
    tilt: robust rest failed, D_pos 2 mm); levelled, it lands on all four.
    Real objects stand on feet made coplanar (rubber feet, glides). Moving
    links (a lid or door resting on the floor, wheels) are left as they are.
    A note names each link changed and the largest move.
    """
    poses = model.link_poses(state)
    body = limits.rigid_group(model, model.root)  # the links no movable joint moves
    world = {ln: [p.points @ poses[ln][:3, :3].T + poses[ln][:3, 3] for p in pl] for ln, pl in pieces.items() if pl}
    if not world:
        return
    allpts = np.vstack([w for ws in world.values() for w in ws])
    zmin = float(allpts[:, 2].min())
    extent = float(np.max(allpts[:, :2].max(axis=0) - allpts[:, :2].min(axis=0)))
    tol = min(LEVEL_TOLERANCE, LEVEL_FRACTION * extent)
    for ln, ws in world.items():
        if ln not in body:
            continue
        R, t = poses[ln][:3, :3], poses[ln][:3, 3]
        lift = 0.0
        count = 0
        for i, w in enumerate(ws):
            sel = w[:, 2] < zmin + tol
            low = w[sel, 2] - zmin
            if not np.any(low > 1e-9):
                continue
            w2 = w.copy()
            w2[sel, 2] = zmin
            try:
                pieces[ln][i] = Piece.of((w2 - t) @ R, pieces[ln][i].sources)
            except (QhullError, ValueError):
                continue
            lift, count = max(lift, float(low.max())), count + 1
        if count:
            notes.append(f"link {ln!r}: {LEVEL_NOTE}: {count} collision piece(s), vertices up to {lift * 1000:.2g} mm "
                         f"above the lowest point moved down onto it (free-standing: stands on every foot)")


def _clip_all(piece: Piece, planes: list[tuple[np.ndarray, float]]) -> Piece | None:
    """``piece`` cut by every half-space ``n . x + offset <= 0`` of ``planes``
    (:func:`clip_piece` in turn); None when nothing with volume is left."""
    for n, off in planes:
        if piece is None:
            return None
        if float((piece.points @ n).max()) + off <= 0.0:
            continue
        piece = clip_piece(piece, n, off)
    return piece


#: Most pieces :func:`_slot` leaves of one piece.
SLOT_PIECES = 4


def _slot(piece: Piece, slots: list[tuple[np.ndarray, float, float, Piece]], tolerance: float, most: int) -> list[Piece] | None:
    """``piece`` with, for each slot (n (3,) unit, lo, hi m, other piece), the
    band ``lo < n . x < hi`` taken out of every part that still penetrates
    the other piece deeper than ``tolerance`` m (each such part becomes the
    two parts beyond the band): a shaft through a lid leaves the lid in
    pieces around it rather than one side of the lid. None when more than
    ``most`` parts would be left."""
    parts = [piece]
    for n, lo, hi, other in slots:
        out = []
        for q in parts:
            if penetration_depth(q, other, tolerance)[0] <= tolerance:
                out.append(q)
                continue
            out += [x for x in (clip_piece(q, n, -lo), clip_piece(q, -n, hi)) if x is not None]
        parts = out
        if len(parts) > most:
            return None
    return parts


def _others(pieces: list[Piece | None], i: int) -> bool:
    """Whether ``pieces`` holds a piece besides the ``i``-th (removed ones are None)."""
    return any(p is not None for j, p in enumerate(pieces) if j != i)


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


def link_pieces(model: urdf.UrdfModel, mesh_path, state: dict[str, float] | None = None, *,
                limit: int = MAX_PIECES_PER_LINK, decompose: bool = True,
                level: bool = False) -> tuple[dict[str, list[Piece]], list[str]]:
    """The convex pieces of every link's mesh collisions (link frame, m).

    The pieces hardly depend on the state of the joints: a parent is cut
    around the volume its child sweeps over the joint's whole range
    (:func:`swept_child_points`), merges are guarded against the other
    links over their ranges (:func:`swept_other_points`) and a child's
    overlap with its parent is cut from the reference position on
    (:func:`separate_parent_child`), so every state of the object (the
    initial state, a closed end measured on the written pieces, a state the
    sweep drives to) sees the same collision geometry, except where the
    initial state ``state`` puts a child into its parent (a stop it was
    written into): that overlap is cut last, for that state.

    Args:
        model: a URDF model (scale baked in; its joint limits are the ranges swept).
        mesh_path: ``UrdfGeometry -> Path`` of a collision mesh's file.
        state: joint -> rad or m, the initial state: what a child still
            penetrates of its parent there is cut (:func:`separate_parent_child`
            with ``state``; the only state-dependent step), and a note when
            a child still sits inside its parent there.
        limit: most pieces per link.
        decompose: decompose a parent piece that contains its child
            (:func:`split_surface`; else only a note).
        level: the object is free-standing: its footprint at ``state`` is
            made planar (:func:`level_footprint`; needs ``state``).

    Returns:
        (link -> pieces, notes).

    Raises:
        CollisionGeometryError: a collision mesh cannot be read.
    """
    key = _cache_key(model, mesh_path, limit, decompose)
    hit = _PIECE_CACHE.get(key)
    disk_key = None
    if hit is None:
        disk_key = _content_key(model, mesh_path, limit, decompose)
        hit = _load_pieces(disk_key, model) if disk_key is not None else None
        if hit is not None:
            _remember(key, hit)
    if hit is None:
        notes: list[str] = []
        pieces: dict[str, list[Piece]] = {}
        for name, link in model.links.items():
            pieces[name], _ = _group_pieces(link, mesh_path, notes)
        _resolve_containment(model, pieces, mesh_path, notes, decompose, limit)
        for name in model.links:
            if len(pieces[name]) <= limit:
                continue
            n = len(pieces[name])
            guard = [x for x in (swept_other_points(model, pieces, name),
                                 *swept_child_points(model, pieces, name, support=True).values()) if x is not None]
            guard = np.vstack(guard) if guard else None
            # merges that hold no other link over the ranges down to the limit; beyond
            # MAX_PIECES_HARD (pieces a parent was cut into around its child) any merge
            pieces[name] = merge_pieces(pieces[name], limit, guard, free_only=True)
            if len(pieces[name]) > max(limit, MAX_PIECES_HARD):
                pieces[name] = merge_pieces(pieces[name], max(limit, MAX_PIECES_HARD), guard)
            notes.append(f"link {name!r}: {n} convex pieces merged into {len(pieces[name])}")
            swept = swept_child_points(model, pieces, name, support=True)
            if decompose and swept:  # a merge the limit forced may hold a child again
                pts = np.vstack(list(swept.values()))
                d = max((depth_inside(pts, p) for p in pieces[name]), default=0.0)
                if d > CONTAINMENT_TOLERANCE:
                    _trim(pieces, name, ", ".join(repr(c) for c in swept), pts, d, notes)
        if decompose:
            separate_parent_child(model, pieces, notes)
        running_clearance(model, pieces, notes)
        for name in model.links:
            pieces[name] = drop_slivers(pieces[name])
        hit = ({k: list(v) for k, v in pieces.items()}, list(notes))
        _remember(key, hit)
        if disk_key is not None:
            _store_pieces(disk_key, hit)
    if state is None:  # nothing depends on a state
        return {k: list(v) for k, v in hit[0].items()}, list(hit[1])
    skey = (key, tuple(sorted((str(k), float(v)) for k, v in state.items())), bool(level))
    done = _STATE_CACHE.get(skey)
    if done is None:
        pieces, notes = {k: list(v) for k, v in hit[0].items()}, list(hit[1])
        if decompose:  # what the initial state still holds: a stop the joint was written into
            separate_parent_child(model, pieces, notes, state=state)
            for name in model.links:
                pieces[name] = drop_slivers(pieces[name])
        if level:
            level_footprint(model, pieces, state, notes)
        if state:
            for (parent, child), d in parent_child_depths(model, pieces, state).items():
                if d > CONTAINMENT_TOLERANCE:
                    notes.append(f"link {child!r} penetrates the collision pieces of its parent {parent!r} {d * 1000:.3g} mm at the initial state")
        if len(_STATE_CACHE) >= 16:
            _STATE_CACHE.pop(next(iter(_STATE_CACHE)))
        _STATE_CACHE[skey] = done = (pieces, notes)
    return {k: list(v) for k, v in done[0].items()}, list(done[1])


#: Pieces made in this process, by :func:`_cache_key` (a refine run writes the
#: same URDF several times: state search, post-check, escalation rounds).
_PIECE_CACHE: dict[str, tuple[dict[str, list[Piece]], list[str]]] = {}

#: What :func:`link_pieces` returned, by (:func:`_cache_key`, initial state):
#: the state-dependent cut of a child out of its parent is the same for the
#: same pieces and state, and a refine run writes one state several times
#: (post-check, escalation rounds, re-check); a drawer cabinet's cut costs
#: 0.1-0.3 s per write.
_STATE_CACHE: dict[tuple, tuple[dict[str, list[Piece]], list[str]]] = {}


def _remember(key: str, hit: tuple[dict[str, list[Piece]], list[str]]) -> None:
    """Keep ``hit`` in :data:`_PIECE_CACHE` (the oldest of 16 dropped)."""
    if len(_PIECE_CACHE) >= 16:
        _PIECE_CACHE.pop(next(iter(_PIECE_CACHE)))
    _PIECE_CACHE[key] = hit


#: Modules whose source the pieces depend on: a change to any of them makes
#: every on-disk entry of :func:`link_pieces` a miss.
PIECES_CODE = ("asset2sim.tasks.assemble.collision_geometry", "asset2sim.tasks.geometry.limits", "asset2sim.mesh_io",
               "asset2sim.engines.loading", "asset2sim.urdf", "asset2sim.frames")


def _content_key(model: urdf.UrdfModel, mesh_path, limit: int, decompose: bool) -> str | None:
    """:func:`_model_digest` with the collision meshes' bytes (not their
    paths: an output folder's copy of a mesh hits the entry its input made)
    and the source of :data:`PIECES_CODE`: the on-disk key. None when a mesh
    cannot be read (no disk cache: the computation raises its own error) or
    the code's source cannot."""
    try:
        code = array_cache.source_digest(*PIECES_CODE)
    except (ImportError, OSError, TypeError):  # no source beside the bytecode: no disk cache
        return None

    def content(path: Path) -> bytes | None:
        try:
            return hashlib.sha256(path.read_bytes()).digest()
        except OSError:
            return None

    return _model_digest(model, mesh_path, limit, decompose, content, code)


def _store_pieces(key: str, hit: tuple[dict[str, list[Piece]], list[str]]) -> None:
    """Write :func:`link_pieces`' state-independent result to the on-disk
    cache (:mod:`asset2sim.array_cache`, kind ``pieces``): per piece its
    vertices, planes and volume; the links, sources and notes as JSON."""
    pieces, notes = hit
    arrays: dict[str, np.ndarray] = {}
    links, n = {}, 0
    for name, plist in pieces.items():
        links[name] = [list(p.sources) for p in plist]
        for p in plist:
            arrays[f"p{n}"], arrays[f"e{n}"], arrays[f"v{n}"] = p.points, p.equations, np.array(p.volume)
            n += 1
    arrays["meta"] = array_cache.text_array(json.dumps({"links": links, "notes": notes}))
    array_cache.store("pieces", key, arrays)


def _load_pieces(key: str, model: urdf.UrdfModel) -> tuple[dict[str, list[Piece]], list[str]] | None:
    """What :func:`_store_pieces` wrote under ``key``, or None (no entry, an
    unreadable one, or one whose links are not ``model``'s)."""
    data = array_cache.load("pieces", key)
    if data is None:
        return None
    try:
        meta = json.loads(array_cache.array_text(data["meta"]))
        if set(meta["links"]) != set(model.links):
            return None
        pieces, n = {}, 0
        for name, sources in meta["links"].items():
            plist = []
            for src in sources:
                plist.append(Piece(np.asarray(data[f"p{n}"], float), np.asarray(data[f"e{n}"], float), float(data[f"v{n}"]),
                                   tuple(str(x) for x in src)))
                n += 1
            pieces[name] = plist
        return pieces, [str(x) for x in meta["notes"]]
    except (KeyError, ValueError, TypeError, UnicodeDecodeError):
        return None


def _model_digest(model: urdf.UrdfModel, mesh_path, limit: int, decompose: bool,
                  mesh_id: Callable[[Path], bytes | None], prefix: str = "") -> str | None:
    """Digest of everything :func:`link_pieces` reads: every collision
    (``mesh_id`` of its mesh file, origin, scale, primitive sizes), every
    joint's frame, axis, type and limits, the piece limit and the
    decomposition switch, after ``prefix``. None when ``mesh_id`` gives None."""
    parts: list[bytes | str] = [prefix, repr((limit, decompose))]
    for name, link in model.links.items():
        parts.append(name)
        for c in link.collisions:
            parts.append(repr((c.kind, c.size, c.radius, c.length)))
            parts.append(np.asarray(c.origin, float).tobytes() + np.asarray(c.scale, float).tobytes())
            if c.kind == "mesh":
                ident = mesh_id(Path(mesh_path(c)))
                if ident is None:
                    return None
                parts.append(ident)
    for j in model.joints:
        parts.append(repr((j.name, j.type, j.parent, j.child, j.lower, j.upper)))
        parts.append(np.asarray(j.origin, float).tobytes() + np.asarray(j.axis, float).tobytes())
    return array_cache.digest(*parts)


def _cache_key(model: urdf.UrdfModel, mesh_path, limit: int, decompose: bool) -> str:
    """:func:`_model_digest` with each mesh file's identity (resolved path,
    modification time in ns, size; the path alone when it cannot be
    read): the in-process key."""

    def identity(path: Path) -> bytes:
        try:
            st = path.stat()
            return repr((str(path.resolve()), st.st_mtime_ns, st.st_size)).encode()
        except OSError:
            return str(path).encode()

    return _model_digest(model, mesh_path, limit, decompose, identity)


def convex_collisions(model: urdf.UrdfModel, out_dir: Path, folder: str, state: dict[str, float] | None = None,
                      mesh_base: Path | None = None, *, decompose: bool = True, level: bool = False) -> list[str]:
    """Replace the mesh collisions of every link of ``model`` (in place) by
    the convex pieces of :func:`link_pieces`, written as OBJ files
    ``out_dir/folder/<link>_hull<i>_<digest>.obj`` (link frame, m; named by
    their content, so an unchanged piece is not rewritten). Primitive
    collisions (box, sphere, cylinder) stay.

    Args:
        out_dir: the output folder.
        folder: folder (relative to ``out_dir``) of the pieces.
        state: the initial state (joint -> rad or m).
        mesh_base: folder that relative collision filenames without a
            resolved ``path`` are relative to (default ``out_dir``).
        level: the object is free-standing: its body's footprint at
            ``state`` is made planar (:func:`level_footprint`).

    Returns:
        notes (what changed).

    Raises:
        CollisionGeometryError: a collision mesh cannot be read.
    """
    out_dir = Path(out_dir)
    base = Path(mesh_base) if mesh_base is not None else out_dir

    def mesh_path(g: urdf.UrdfGeometry) -> Path:
        return Path(g.path) if g.path is not None else base / str(g.filename)

    pieces, notes = link_pieces(model, mesh_path, state, decompose=decompose, level=level and state is not None)
    for name, link in model.links.items():
        if not any(c.kind == "mesh" for c in link.collisions):
            continue
        kept = [c for c in link.collisions if c.kind != "mesh"]
        safe = file_names.file_stem(name)
        for i, p in enumerate(pieces[name]):
            data = piece_obj(p)
            rel = f"{folder}/{safe}_hull{i}_{hashlib.sha256(data).hexdigest()[:12]}.obj"
            dst = file_names.join_inside(out_dir, rel)
            if not (dst.is_file() and not dst.is_symlink() and dst.read_bytes() == data):
                atomic.write_bytes(dst, data)
            else:
                atomic.announce([dst])
            kept.append(urdf.UrdfGeometry(kind="mesh", filename=rel, path=dst))
        link.collisions = kept
    return notes


def referenced_files(urdf_path: Path) -> set[str]:
    """Filenames (as written) of the collision meshes a written URDF
    references ({} when there is no file), so a clean-up of the collision
    folder keeps them.

    Raises:
        UrdfError: the URDF cannot be read.
    """
    urdf_path = Path(urdf_path)
    if not urdf_path.is_file():
        return set()
    model = urdf.read_urdf(urdf_path, mode="lenient")
    return {str(c.filename) for link in model.links.values() for c in link.collisions if c.kind == "mesh" and c.filename}
