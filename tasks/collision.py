"""Collision geometry improvement by approximate convex decomposition.

Simulators collide each mesh through its convex hull (PyBullet, PhysX and
MuJoCo all do for moving bodies). Two parts whose hulls always overlap — a
stapler's curved arm over its base — make zero penetration impossible in any
joint state, and the depenetration impulses then shake the object. When state
refinement cannot bring the penetration score below tolerance, the collision
meshes of the links in the worst pairs are replaced by a CoACD decomposition
(Wei et al., "Approximate Convex Decomposition for 3D Meshes with
Collision-Aware Concavity and Tree Search", SIGGRAPH 2022; the ``coacd``
package), written as separate OBJ files under ``collision/`` in the output
folder. Visual meshes are untouched; the report lists every change.

Decompositions are cached on disk by the sha256 of the mesh file and the
settings (``ASSET2SIM_CACHE`` or ``~/.cache/asset2sim``), so reruns are fast.
"""

from __future__ import annotations

import hashlib
import json
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from asset2sim import atomic
from asset2sim.schemas.asset import AssetDescription, GeometryRef

#: CoACD settings: concavity threshold (dimensionless, fraction of the mesh
#: size), at most this many hulls per mesh, and reduced search effort (the
#: library's defaults take minutes per mesh on 2 cores).
COACD_SETTINGS = {
    "threshold": 0.08,
    "max_convex_hull": 8,
    "preprocess_resolution": 30,
    "resolution": 1000,
    "mcts_iterations": 60,
    "mcts_max_depth": 2,
}


class DecompositionUnavailable(RuntimeError):
    """CoACD is not installed (``pip install asset2sim[coacd]``)."""


@dataclass
class CollisionPiece:
    """One convex piece replacing (part of) a collision mesh.

    ``filename`` relative to the output folder; ``origin``/``scale`` copied from
    the original ``<collision>`` element (scale at the input's units; the
    writer multiplies by the overlay scale).
    """

    filename: str
    source: GeometryRef


def cache_dir() -> Path:
    """Folder of the on-disk decomposition cache."""
    root = os.environ.get("ASSET2SIM_CACHE")
    return Path(root) if root else Path.home() / ".cache" / "asset2sim"


def _obj_text(vertices: np.ndarray, faces: np.ndarray) -> str:
    lines = [f"v {x!r} {y!r} {z!r}" for x, y, z in np.asarray(vertices, float)]
    lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in np.asarray(faces, int)]
    return "\n".join(lines) + "\n"


def decompose_mesh(path: Path) -> list[tuple[np.ndarray, np.ndarray]]:
    """Convex pieces [(vertices (N, 3), faces (M, 3))] of the mesh at ``path``
    (file units), from the cache or CoACD.

    Raises:
        DecompositionUnavailable: coacd is not installed.
        ValueError: the mesh cannot be read.
    """
    from asset2sim.tasks.analyze import read_mesh

    digest = hashlib.sha256(path.read_bytes() + json.dumps(COACD_SETTINGS, sort_keys=True).encode()).hexdigest()
    cfile = cache_dir() / "coacd" / f"{digest}.npz"
    if cfile.is_file():
        try:
            data = np.load(cfile)
            n = int(data["n"])
            return [(data[f"v{i}"], data[f"f{i}"]) for i in range(n)]
        except (OSError, ValueError, KeyError):
            pass
    try:
        import coacd
    except ImportError as exc:
        raise DecompositionUnavailable(f"convex decomposition needs coacd ({exc})") from exc
    v, f, _ = read_mesh(path)
    good = np.all(np.isfinite(v), axis=1)
    if not good.all():
        raise ValueError(f"{path}: NaN vertices; not decomposed")
    coacd.set_log_level("error")
    parts = coacd.run_coacd(coacd.Mesh(v, f), **COACD_SETTINGS)
    pieces = [(np.asarray(pv, float), np.asarray(pf, int)) for pv, pf in parts]
    try:
        import io

        buf = io.BytesIO()
        arrays = {"n": np.array(len(pieces))}
        for i, (pv, pf) in enumerate(pieces):
            arrays[f"v{i}"] = pv
            arrays[f"f{i}"] = pf
        np.savez(buf, **arrays)
        atomic.write_bytes(cfile, buf.getvalue())
    except OSError:
        pass  # the cache is an optimisation only
    return pieces


def _piece_points(g: GeometryRef, cache) -> np.ndarray | None:
    from scipy.spatial import ConvexHull, QhullError

    from asset2sim.tasks.analyze import rpy_matrix

    try:
        v = np.asarray(cache.get(g.path)[0], float)
    except Exception:
        return None
    v = v[np.all(np.isfinite(v), axis=1)] * np.asarray(g.scale, float)
    if len(v) < 4:
        return None
    try:
        v = v[ConvexHull(v).vertices]
    except (QhullError, ValueError):
        pass
    return v @ rpy_matrix(g.origin.rpy).T + np.asarray(g.origin.xyz, float)


def convexity_ratio(path: Path, cache=None) -> float:
    """Surface area of the mesh over the area of its convex hull (>= ~1 for
    concave closed surfaces, ~1 for convex ones; open surfaces can be < 1)."""
    import trimesh

    from asset2sim.tasks.analyze import MeshCache

    cache = cache or MeshCache()
    v, f, _ = cache.get(path)
    m = trimesh.Trimesh(np.asarray(v, float), np.asarray(f, int), process=False)
    try:
        hull_area = float(m.convex_hull.area)
    except Exception:
        return 1.0
    return float(m.area / hull_area) if hull_area > 0 else 1.0


def colliding_pieces(session, asset: AssetDescription, pairs: list[tuple[str, str]], scale: float, cache=None) -> set[tuple[str, int]]:
    """(link, collision index) of the mesh collisions whose scaled, posed hull
    bounding box overlaps a collision piece of the other link of a pair, at
    the session's current state (``session``: PyBullet session of the scaled
    output; ``asset``: the input description)."""
    from asset2sim.tasks.analyze import MeshCache
    from asset2sim.tasks.closed_state import _link_pose

    cache = cache or MeshCache()
    boxes: dict[str, list[tuple[int, np.ndarray, np.ndarray]]] = {}
    for link in {ln for pair in pairs for ln in pair}:
        pos, R = _link_pose(session, session.link_index(link))
        items = []
        for k, g in enumerate(asset.link(link).collisions):
            if g.kind != "mesh" or g.path is None:
                continue
            pts = _piece_points(g, cache)
            if pts is None:
                continue
            w = (pts * scale) @ R.T + pos
            items.append((k, w.min(axis=0), w.max(axis=0)))
        boxes[link] = items
    out: set[tuple[str, int]] = set()
    for a, b in pairs:
        for ka, alo, ahi in boxes.get(a, []):
            for kb, blo, bhi in boxes.get(b, []):
                if np.all(alo <= bhi) and np.all(blo <= ahi):
                    out.add((a, ka))
                    out.add((b, kb))
    return out


def decompose_links(
    asset: AssetDescription,
    links: list[str],
    out_dir: Path,
    *,
    only: set[tuple[str, int]] | None = None,
    budget_s: float = 60.0,
    min_concavity: float = 1.05,
    cache=None,
) -> tuple[dict[str, list[CollisionPiece]], list[str]]:
    """Decompose collision meshes of ``links`` and write the pieces to
    ``out_dir/collision/<link>_<k>_<i>.obj``.

    Only meshes in ``only`` (when given) whose surface is concave enough
    (:func:`convexity_ratio` >= ``min_concavity``) are decomposed, largest
    first, until ``budget_s`` seconds of decomposition are spent; every other
    collision of those links is kept as it is.

    Returns (link -> pieces for the writer's collision overrides, notes).
    Raises as :func:`decompose_mesh`.
    """
    import time

    from asset2sim.tasks.analyze import MeshCache

    cache = cache or MeshCache()
    notes: list[str] = []
    candidates = []
    for name in links:
        for k, g in enumerate(asset.link(name).collisions):
            if g.kind != "mesh" or g.path is None or (only is not None and (name, k) not in only):
                continue
            ratio = convexity_ratio(g.path, cache)
            if ratio < min_concavity:
                continue
            candidates.append((len(cache.get(g.path)[1]), name, k, g))
    candidates.sort(key=lambda c: -c[0])
    t0 = time.perf_counter()
    done: dict[tuple[str, int], list[tuple[np.ndarray, np.ndarray]]] = {}
    for _, name, k, g in candidates:
        if time.perf_counter() - t0 > budget_s:
            notes.append(f"decomposition budget {budget_s:g} s spent; {name} collision {k} kept as its hull")
            continue
        done[(name, k)] = decompose_mesh(g.path)
    out: dict[str, list[CollisionPiece]] = {}
    for name in links:
        if not any(key[0] == name for key in done):
            continue
        pieces: list[CollisionPiece] = []
        for k, g in enumerate(asset.link(name).collisions):
            if (name, k) in done:
                for i, (v, f) in enumerate(done[(name, k)]):
                    rel = f"collision/{name}_{k}_{i}.obj"
                    atomic.write_text(out_dir / rel, _obj_text(v, f))
                    pieces.append(CollisionPiece(filename=rel, source=g))
            elif g.kind == "mesh" and g.filename:
                pieces.append(CollisionPiece(filename=g.filename, source=g))
        out[name] = pieces
    return out, notes
