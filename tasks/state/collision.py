"""Collision geometry improvement by approximate convex decomposition
(:func:`improve_collisions`): small overlapping pieces lose their collision,
concave ones are replaced by a CoACD decomposition
(:mod:`asset2sim.tasks.geometry.decomposition`).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from asset2sim import file_names, mesh_io
from asset2sim.frames import rpy_matrix
from asset2sim.engines.registry import open_shape_world
from asset2sim.mesh_io import MeshCache
from asset2sim.schemas.asset import AssetDescription, GeometryRef
from asset2sim.tasks.geometry.decomposition import COACD_SETTINGS, decompose_mesh

#: A collision piece below this fraction of its link's collision surface that
#: overlaps another link is hinge hardware and loses its collision.
PIN_AREA_FRACTION = 0.05


#: Smallest decrease of the piece-wise overlap (m) that counts as an improvement.
IMPROVEMENT_EPS = 1e-5


@dataclass
class CollisionPiece:
    """One convex piece replacing (part of) a collision mesh: ``filename`` relative to the output folder; ``source`` the
    original collision (origin, scale at the input's units)."""

    filename: str
    source: GeometryRef


def convexity_ratio(path: Path, cache: MeshCache) -> float:
    """Surface area of the mesh over the area of its convex hull (>= ~1 for
    concave closed surfaces, ~1 for convex ones; open surfaces can be < 1); ``cache`` holds the meshes read."""
    import trimesh

    mesh = cache.get(path)
    m = trimesh.Trimesh(np.asarray(mesh.vertices, float), np.asarray(mesh.faces, int), process=False)
    try:
        hull_area = float(m.convex_hull.area)
    except Exception:
        return 1.0
    return float(m.area / hull_area) if hull_area > 0 else 1.0


def overlap_depths(world, shape_a: int, shape_b: int) -> list[float]:
    """Penetration depths (m, > 0) of the closest points of two shapes of a
    :class:`asset2sim.engines.base.ShapeWorld`, net of ``world.contact_margin``."""
    m = float(world.contact_margin)
    return [-(x + m) for x in world.distances(shape_a, shape_b, 0.0) if x + m < 0]


class _PieceWorld:
    """Every collision piece of ``links`` as a static shape in a private PyBullet
    collision world, posed as in ``session``, to measure penetration piece by piece."""

    def __init__(self, session, asset: AssetDescription, links: list[str], scale: float, cache):
        from scipy.spatial.transform import Rotation

        self.world = open_shape_world("pybullet")
        self.scale = scale
        self.poses = {}  # (link, collision) -> (position (3,), quaternion xyzw)
        self.bodies: dict[tuple[str, int], list[int]] = {}
        self.refs: dict[tuple[str, int], GeometryRef] = {}
        for ln in links:
            pos, R = session.link_frame(ln)
            for k, g in enumerate(asset.link(ln).collisions):
                if g.kind != "mesh" or g.path is None:
                    continue
                self.poses[(ln, k)] = (pos + R @ (np.asarray(g.origin.xyz, float) * scale),
                                       Rotation.from_matrix(R @ rpy_matrix(g.origin.rpy)).as_quat())
                self.refs[(ln, k)] = g
                v = np.asarray(cache.get(g.path).vertices, float)
                self.bodies[(ln, k)] = [self._body(v[np.all(np.isfinite(v), axis=1)], (ln, k))]

    def _body(self, vertices: np.ndarray, key: tuple[str, int]) -> int:
        return self.world.add_convex(vertices, np.asarray(self.refs[key].scale, float) * self.scale, *self.poses[key])

    def replace(self, key: tuple[str, int], pieces: list[np.ndarray]) -> list[int]:
        """Swap the bodies of ``key`` for ``pieces`` (vertex arrays); returns the old ids."""
        old = self._park(key)
        self.bodies[key] = [self._body(v, key) for v in pieces]
        return old

    def _park(self, key: tuple[str, int]) -> list[int]:
        """Move the bodies of ``key`` 1 km away; returns their ids."""
        for b in self.bodies[key]:
            self.world.set_pose(b, [1e3, 1e3, 1e3], [0, 0, 0, 1])
        return self.bodies[key]

    def restore(self, key: tuple[str, int], old: list[int]) -> None:
        self._park(key)
        for b in old:
            self.world.set_pose(b, *self.poses[key])
        self.bodies[key] = old

    def _depths(self, ids: list[int], other: str):
        """:func:`overlap_depths` of each body of ``ids`` with each body of the link ``other``, in order."""
        for (lb, _), ids_b in self.bodies.items():
            if lb == other:
                for ia in ids:
                    for ib in ids_b:
                        yield overlap_depths(self.world, ia, ib)

    def penetration(self, a: str, b: str) -> float:
        """Sum over piece pairs of the deepest penetration, m (net of the contact margins, :func:`overlap_depths`)."""
        return sum((max(d) for (la, _), ids_a in self.bodies.items() if la == a for d in self._depths(ids_a, b) if d), 0.0)

    def overlapping(self, key: tuple[str, int], other: str) -> float:
        """Deepest penetration (m, net of the contact margins; 0 when
        apart or touching) of the piece ``key`` into the link ``other``."""
        return max([0.0, *(x for d in self._depths(self.bodies[key], other) for x in d)])

    def close(self) -> None:
        self.world.close()


def improve_collisions(session, asset: AssetDescription, pairs: list[tuple[str, str]], scale: float, out_dir: Path, *,
                       cache=None, max_decompositions: int = 32, folder: str,
                       threshold: float = COACD_SETTINGS["threshold"]) -> tuple[dict[str, list[CollisionPiece]], list[str]]:
    """Greedy, piece by piece, for link pairs whose hulls keep penetrating: a small piece (< :data:`PIN_AREA_FRACTION` of
    its link's surface) that overlaps the other link loses its collision; a concave one (:func:`convexity_ratio` >= 1.05) is
    replaced by its CoACD decomposition at concavity ``threshold`` (a fraction of the mesh's size; at most
    ``max_decompositions`` calls). Each change is kept only if it lowers the pair's piece-wise penetration
    (:func:`overlap_depths`). ``session``: PyBullet session of the scaled output at the
    refined state. Pieces go to ``out_dir/<folder>/``. Returns (collision overrides, notes)."""
    cache = cache or MeshCache()
    links = sorted({ln for pair in pairs for ln in pair})
    world = _PieceWorld(session, asset, links, scale, cache)
    try:
        rep = _Repair(world, cache, links, max_decompositions, threshold)
        for _pass in range(2):  # a second pass: a change on one side can make another one useful
            tried: set[tuple[str, int]] = set()
            for a, b in pairs:
                rep.improve_pair(a, b, tried)
    finally:
        world.close()
    # the kept decompositions written as ``out_dir/folder/<link>_<k>_<i>.obj``: link -> its pieces
    out: dict[str, list[CollisionPiece]] = {}
    for ln in sorted({k[0] for k in rep.changed}):
        pieces_out: list[CollisionPiece] = []
        for k, g in enumerate(asset.link(ln).collisions):
            # None: removed
            if (ln, k) in rep.changed:
                for i, (v, f) in enumerate(rep.changed[(ln, k)] or []):
                    rel = f"{folder}/{file_names.file_stem(ln)}_{k}_{i}.obj"
                    mesh_io.write_file(file_names.join_inside(out_dir, rel), mesh_io.obj_bytes(v, f))
                    pieces_out.append(CollisionPiece(filename=rel, source=g))
            elif g.kind == "mesh" and g.filename:
                pieces_out.append(CollisionPiece(filename=g.filename, source=g))
        out[ln] = pieces_out
    return out, rep.notes


class _Repair:
    """The greedy repair's state: ``changed`` ((link, collision index) -> convex
    pieces, None when removed), ``notes``, CoACD calls made."""

    def __init__(self, world: _PieceWorld, cache, links: list[str], max_decompositions: int, threshold: float):
        self.world, self.cache, self.max_decompositions, self.threshold = world, cache, max_decompositions, threshold
        self.area = {}  # (link, k) -> surface area of the piece (input units, mesh scale applied)
        for (ln, k), g in world.refs.items():
            mesh = cache.get(g.path)
            tri = np.asarray(mesh.vertices, float)[np.asarray(mesh.faces, int)] * np.asarray(g.scale, float)
            self.area[(ln, k)] = float(0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1).sum())
        self.link_area = {ln: sum(a for (l2, _), a in self.area.items() if l2 == ln) for ln in links}
        self.changed: dict[tuple[str, int], list[tuple[np.ndarray, np.ndarray]] | None] = {}
        self.notes: list[str] = []
        self.decompositions = 0

    def improve_pair(self, a: str, b: str, tried: set[tuple[str, int]]) -> None:
        """Each untried piece of ``a`` or ``b`` overlapping the other link, deepest first."""
        world = self.world
        before = world.penetration(a, b)
        if before <= IMPROVEMENT_EPS:
            return  # this pair no longer overlaps: spend no budget on it
        cands = [(depth, key, other) for ln, other in ((a, b), (b, a)) for key in world.refs
                 if key[0] == ln and (depth := world.overlapping(key, other)) > 0]
        for _, key, other in sorted(cands, key=lambda c: -c[0]):
            if key in self.changed or key in tried or before <= IMPROVEMENT_EPS:
                continue
            tried.add(key)
            # cleared by a change before it: no change of it lowers the pair's penetration (the other pairs' terms
            # stay as they are), so none is tried (CoACD's seconds saved)
            if world.overlapping(key, other) <= 0.0:
                continue
            ln, g, area = key[0], world.refs[key], self.area[key]
            n_link = sum(1 for k2 in world.refs if k2[0] == ln and self.changed.get(k2, 0) is not None)
            if area < PIN_AREA_FRACTION * max(self.link_area[ln], 1e-12) and n_link > 1:
                after = self._try(key, [], None, a, b, before)
                if after is not None:
                    self.notes.append(f"{ln}: collision of {g.filename} (hinge hardware, {100 * area / self.link_area[ln]:.1f} % of the link's surface) removed: it overlapped {other} ({before * 1000:.3g} -> {after * 1000:.3g} mm)")
                    before = after
                continue
            if convexity_ratio(g.path, self.cache) < 1.05:
                continue
            if self.decompositions >= self.max_decompositions:
                self.notes.append(f"decomposition budget of {self.max_decompositions} CoACD calls spent; {g.filename} of {ln} kept as its hull")
                continue
            self.decompositions += 1
            pieces = decompose_mesh(g.path, self.threshold)
            after = self._try(key, [pv for pv, _ in pieces], pieces, a, b, before)
            if after is not None:
                self.notes.append(f"{ln}: {g.filename} replaced by {len(pieces)} convex pieces (CoACD): overlap with {other} {before * 1000:.3g} -> {after * 1000:.3g} mm")
                before = after

    def _try(self, key: tuple[str, int], bodies: list[np.ndarray], change, a: str, b: str, before: float) -> float | None:
        """Penetration (m) of ``a`` and ``b`` with ``key``'s bodies swapped for ``bodies``,
        kept as ``change`` when it beats ``before``; else None, the old bodies restored."""
        old = self.world.replace(key, bodies)
        after = self.world.penetration(a, b)
        if after < before - IMPROVEMENT_EPS:
            self.changed[key] = change
            return after
        self.world.restore(key, old)
        return None
