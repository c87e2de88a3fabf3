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


def decompose_links(asset: AssetDescription, links: list[str], out_dir: Path) -> dict[str, list[CollisionPiece]]:
    """Decompose the collision meshes of ``links`` and write the pieces to
    ``out_dir/collision/<link>_<k>_<i>.obj``.

    Returns link -> pieces (to pass to the writer as collision overrides);
    primitives are kept as they are. Raises as :func:`decompose_mesh`.
    """
    out: dict[str, list[CollisionPiece]] = {}
    for name in links:
        link = asset.link(name)
        pieces: list[CollisionPiece] = []
        for k, g in enumerate(link.collisions):
            if g.kind != "mesh" or g.path is None:
                continue
            for i, (v, f) in enumerate(decompose_mesh(g.path)):
                rel = f"collision/{name}_{k}_{i}.obj"
                atomic.write_text(out_dir / rel, _obj_text(v, f))
                pieces.append(CollisionPiece(filename=rel, source=g))
        if pieces:
            out[name] = pieces
    return out
