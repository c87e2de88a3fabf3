"""Approximate convex decomposition of a mesh by CoACD (Wei, Liu, Lu, Li,
"Approximate convex decomposition for 3D meshes with collision-aware concavity
and tree search", SIGGRAPH 2022), refitted to the mesh's own vertices and
cached by content and settings: in this process (:data:`_MEMO`) and on disk (:mod:`asset2sim.array_cache`).
CoACD is an optional dependency (``pip install asset2sim[coacd]``).

A refine asks for the same decomposition more than once: the collision repair's second pass tries again a piece
its first pass decomposed, and the shut repair and the state search of a request that opens a part repair the
same pair. The on-disk cache answers those when it is on; with it off (``ASSET2SIM_CACHE=off``) each would run
CoACD again (about 3 s of CPU for a 13-piece stapler arm, PartNet-Mobility 102990). The process cache is keyed by
the same digest as the disk entry (the mesh's bytes and every setting), and hands out copies, so no result
depends on whether it answered.
"""

from __future__ import annotations

import hashlib
import json
import threading
import cachetools
from pathlib import Path

import numpy as np

from asset2sim import array_cache
from asset2sim.mesh_io import read_mesh

#: CoACD settings: concavity threshold (fraction of the mesh size), most hulls
#: per mesh, reduced search effort (the defaults take minutes per mesh).
COACD_SETTINGS = {
    "threshold": 0.05,
    "max_convex_hull": 16,
    "preprocess_resolution": 30,
    "resolution": 1000,
    "mcts_iterations": 60,
    "mcts_max_depth": 2,
}


#: CoACD concavity thresholds the state repair tries in turn (:func:`asset2sim.tasks.state.state_search.
#: refine_state_with_decomposition`): the default, then a finer one only where the default's pieces lowered the overlap
#: but leave the parts overlapping at every state of their bands, by no more than those pieces can bulge
#: (:func:`asset2sim.tasks.state.state_search.coarse_bulge`). A concave part whose pieces bulge up to the threshold's
#: share of its size (5 %: 7 mm on a 15 cm stapler base made of one mesh) can keep a closed part off its stop; at 2.5 %
#: CoACD follows the surface twice as closely for about twice its time (2.4 -> 5.0 s and 5.0 -> 11.5 s on that stapler's
#: base and magazine).
COACD_THRESHOLDS = (COACD_SETTINGS["threshold"], COACD_SETTINGS["threshold"] / 2)


class DecompositionUnavailable(RuntimeError):
    """CoACD is not installed (``pip install asset2sim[coacd]``)."""


def decompose_mesh(path: Path, threshold: float = COACD_SETTINGS["threshold"]) -> list[tuple[np.ndarray, np.ndarray]]:
    """Convex pieces [(vertices (N, 3), faces (M, 3))] of the mesh at ``path`` (file units), from the cache or CoACD
    (:data:`COACD_SETTINGS` with its concavity ``threshold``, a fraction of the mesh's size). Raises
    DecompositionUnavailable (no coacd) or ValueError (the mesh cannot be read)."""
    settings = {**COACD_SETTINGS, "threshold": threshold}
    digest = hashlib.sha256(path.read_bytes() + json.dumps({**settings, "refit": 1}, sort_keys=True).encode()).hexdigest()

    def triangles() -> tuple[np.ndarray, np.ndarray]:
        mesh = read_mesh(path)
        return mesh.vertices, mesh.faces
    return _decompose(digest, triangles, str(path), settings)


def decompose(vertices: np.ndarray, faces: np.ndarray, settings: dict | None = None, *,
              refit: bool = True) -> list[tuple[np.ndarray, np.ndarray]]:
    """Convex pieces [(vertices (N, 3), faces (M, 3))] of the triangle mesh ``vertices`` (V, 3), ``faces`` (F, 3) int,
    in its units, from the cache (keyed by the arrays and the settings) or CoACD, refitted to the vertices
    (:func:`refit_pieces`) with ``refit`` (else as CoACD made them, on its manifold remesh of the surface);
    ``settings``: CoACD's keyword arguments (None: :data:`COACD_SETTINGS`).

    Raises:
        DecompositionUnavailable: CoACD is not installed.
        ValueError: NaN vertices.
    """
    v = np.ascontiguousarray(vertices, np.float64)
    f = np.ascontiguousarray(faces, np.int64)
    settings = dict(COACD_SETTINGS if settings is None else settings)
    digest = array_cache.digest(v.tobytes(), f.tobytes(), repr((v.shape, f.shape)),
                                json.dumps({**settings, "refit": int(refit)}, sort_keys=True))
    return _decompose(digest, lambda: (v, f), "mesh", settings, refit)


#: Decompositions made or read in this process, by the digest of their on-disk entry (content and settings): the
#: pieces as read-only arrays, handed out as copies; the least recently used dropped beyond 64 entries.
_MEMO: cachetools.LRUCache = cachetools.LRUCache(maxsize=64)
_MEMO_LOCK = threading.Lock()


def _remember(digest: str, pieces: list[tuple[np.ndarray, np.ndarray]]) -> list[tuple[np.ndarray, np.ndarray]]:
    """``pieces``, a read-only copy of them kept in :data:`_MEMO` under ``digest``."""
    kept = []
    for v, f in pieces:
        v, f = np.array(v), np.array(f)  # copies, dtypes kept
        v.flags.writeable = f.flags.writeable = False
        kept.append((v, f))
    with _MEMO_LOCK:
        _MEMO[digest] = tuple(kept)
    return pieces


def _decompose(digest: str, mesh, where: str, settings: dict, refit: bool = True) -> list[tuple[np.ndarray, np.ndarray]]:
    with _MEMO_LOCK:
        hit = _MEMO.get(digest)
    if hit is not None:  # copies of the read-only pieces kept
        return [(v.copy(), f.copy()) for v, f in hit]
    data = array_cache.load("coacd", digest)
    if data is not None:
        try:
            return _remember(digest, [(data[f"v{i}"], data[f"f{i}"]) for i in range(int(data["n"]))])
        except (KeyError, ValueError):
            pass
    try:
        import coacd
    except ImportError as exc:
        raise DecompositionUnavailable(f"convex decomposition needs coacd ({exc})") from exc
    v, f = mesh()
    good = np.all(np.isfinite(v), axis=1)
    if not good.all():
        raise ValueError(f"{where}: NaN vertices; not decomposed")
    coacd.set_log_level("error")
    pieces = [(np.asarray(pv, float), np.asarray(pf, int)) for pv, pf in coacd.run_coacd(coacd.Mesh(v, f), **settings)]
    if refit:
        pieces = refit_pieces(v, pieces)
    arrays = {"n": np.array(len(pieces))}
    arrays.update({f"{k}{i}": a for i, piece in enumerate(pieces) for k, a in zip("vf", piece)})
    array_cache.store("coacd", digest, arrays)
    return _remember(digest, pieces)


def refit_pieces(vertices: np.ndarray, pieces: list[tuple[np.ndarray, np.ndarray]]) -> list[tuple[np.ndarray, np.ndarray]]:
    """Refit convex pieces to the original surface: each vertex (N, 3) goes to the piece it lies deepest inside, each piece
    becomes the hull of its vertices (kept as CoACD made it when they span no volume)."""
    from scipy.spatial import ConvexHull, QhullError

    v = np.asarray(vertices, float)
    v = v[np.all(np.isfinite(v), axis=1)]
    eqs = []
    for pv, _ in pieces:
        try:
            eqs.append(ConvexHull(pv).equations)
        except (QhullError, ValueError):
            eqs.append(None)
    if not eqs or all(e is None for e in eqs) or len(v) == 0:
        return pieces
    dist = np.full((len(v), len(pieces)), np.inf)
    for i, e in enumerate(eqs):
        if e is not None:
            dist[:, i] = _max_plane_distance(v, e)
    owner = np.argmin(dist, axis=1)
    out = []
    for i, (pv, pf) in enumerate(pieces):
        pts = v[owner == i]
        try:
            hull = ConvexHull(pts)
            index = np.empty(len(pts), dtype=int)  # a hull vertex's point index -> its index among the vertices
            index[hull.vertices] = np.arange(len(hull.vertices))
            out.append((pts[hull.vertices], index[hull.simplices]))
        except (QhullError, ValueError):
            out.append((pv, pf))
    return out


#: Points per block of :func:`_max_plane_distance` (a block's (points, planes) distances stay in the CPU's cache).
_BLOCK = 256


def _max_plane_distance(points: np.ndarray, equations: np.ndarray) -> np.ndarray:
    """Largest signed distance (N,) of each of ``points`` (N, 3) to the planes ``equations`` (F, 4) (Qhull's
    ``n . x + d``, outward normals): <= 0 inside the hull, in blocks of :data:`_BLOCK` points (the same values as
    one (N, F) product, without its memory)."""
    n, d = np.ascontiguousarray(equations[:, :3].T), equations[:, 3]
    out = np.empty(len(points))
    for s in range(0, len(points), _BLOCK):
        block = points[s:s + _BLOCK] @ n
        block += d
        block.max(axis=1, out=out[s:s + _BLOCK])
    return out
