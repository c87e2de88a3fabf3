"""Mesh assets of the convex collision pieces: the original file where a hull
is a whole single-group file inside the asset folder, else the hull written
as OBJ under :data:`~asset2sim.engines.mjcf.base.DERIVED_MESH_DIR`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from asset2sim.engines.loading import CollisionPiece
from asset2sim.file_names import file_stem
from asset2sim.engines.mjcf.base import DERIVED_MESH_DIR, relative_to, vec_text
from asset2sim.mesh_io import convex_hull_mesh


def hull_obj(points: np.ndarray) -> bytes:
    """OBJ bytes of the convex hull of ``points`` (k, 3) m (vertices + outward
    faces, :func:`asset2sim.mesh_io.convex_hull_mesh`)."""
    verts, tris = convex_hull_mesh(points)
    lines = [f"v {vec_text(v)}" for v in verts]
    lines += [f"f {i} {j} {k}" for i, j, k in tris + 1]
    return ("\n".join(lines) + "\n").encode()


@dataclass
class MeshAssets:
    """Mesh files of the convex pieces. ``derived`` relative path -> OBJ bytes
    of pieces written anew; ``files`` relative path -> source file of whole
    single-group files referenced as they are; ``names`` / ``scales`` piece
    key (link, collision, group) -> name given to MuJoCo's import / scale (3,)
    or None; ``virtual`` import name -> (relative path, scale);
    ``import_assets`` import name -> bytes."""

    derived: dict[str, bytes] = field(default_factory=dict)
    files: dict[str, Path] = field(default_factory=dict)
    names: dict[tuple, str] = field(default_factory=dict)
    scales: dict[tuple, np.ndarray | None] = field(default_factory=dict)
    virtual: dict[str, tuple[str, np.ndarray | None]] = field(default_factory=dict)
    import_assets: dict[str, bytes] = field(default_factory=dict)


def mesh_assets(pieces: dict[str, list[CollisionPiece]], mesh_root: Path) -> MeshAssets:
    """One mesh per convex piece: the original file when a hull is a whole
    single-group file inside ``mesh_root``, else the hull written as OBJ
    under :data:`DERIVED_MESH_DIR`."""
    out = MeshAssets()
    for name, plist in pieces.items():
        for p in plist:
            if p.kind != "hull":
                continue
            key = (name, p.collision, p.group)
            rel = relative_to(p.source, mesh_root) if p.whole_file else None
            if rel is not None:
                out.files[rel] = p.source
                data = p.source.read_bytes()
                scale = None if np.allclose(p.scale, 1.0) else np.asarray(p.scale, float)
            else:
                rel = f"{DERIVED_MESH_DIR}/{file_stem(name)}__c{p.collision}_g{p.group}.obj"
                data = hull_obj(p.points)
                out.derived[rel] = data
                scale = None
            vname = f"piece{len(out.virtual)}.obj"
            out.virtual[vname] = (rel, scale)
            out.names[key] = vname
            out.scales[key] = scale
            out.import_assets[vname] = data
    return out
