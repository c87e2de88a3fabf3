"""Visual meshes as non-colliding MJCF geoms (group 2), coloured from the MTL ``Kd`` / ``d``."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from lxml import etree

from asset2sim import mesh_io
from asset2sim.engines.mjcf.base import num_text, quat_text, relative_to, safe_name, vec_text

GREY = "0.7 0.7 0.7 1"


def mtl_colour(obj: Path) -> str:
    """``rgba`` text of the first material an OBJ uses (MTL ``Kd`` and ``d``), grey when there is none."""
    try:
        text = obj.read_text(errors="replace")
    except OSError:
        return GREY
    uses = mesh_io.obj_material_uses(text)
    for lib in mesh_io.mtl_libraries(text.encode("utf-8", "replace")):
        try:
            materials = mesh_io.read_mtl((obj.parent / lib).read_text(errors="replace"))
        except OSError:
            continue
        for name, lines in materials.items():
            if uses and name != uses[0]:
                continue
            kd = next((ln.split()[1:4] for ln in lines if ln.split()[0] == "Kd" and len(ln.split()) >= 4), None)
            dd = next((ln.split()[1] for ln in lines if ln.split()[0] == "d" and len(ln.split()) >= 2), None)
            try:
                rgb = [min(1.0, max(0.0, float(x))) for x in kd] if kd else [0.7, 0.7, 0.7]
                alpha = min(1.0, max(0.0, float(dd))) if dd else 1.0
            except ValueError:
                continue
            return vec_text(rgb + [alpha])
    return GREY


#: Fewest distinct vertices MuJoCo compiles a mesh from (MuJoCo 3's mesh compiler).
MIN_MESH_VERTICES = 4


def visual_mesh_problem(path: Path, meshes: mesh_io.MeshCache) -> str:
    """Why MuJoCo would refuse ``path`` (read through ``meshes``) as a visual mesh ("" when it takes it); the
    distinct vertices are counted over all rows only when the first 64 hold fewer than enough."""
    if path.suffix.lower() not in (".obj", ".stl", ".msh"):
        return f"is a {path.suffix} file (MuJoCo reads OBJ, STL and MSH)"
    try:
        mesh = meshes.get(path)
    except mesh_io.MeshReadError as exc:
        return f"cannot be read ({exc})"
    v = np.asarray(mesh.vertices, float)
    v = v[np.all(np.isfinite(v), axis=1)]
    if len(mesh.faces) == 0:
        return "has no faces"
    if len(np.unique(v[:64], axis=0)) < MIN_MESH_VERTICES and len(np.unique(v, axis=0)) < MIN_MESH_VERTICES:
        return f"has fewer than {MIN_MESH_VERTICES} distinct vertices"
    return ""


def add_visuals(body, link, mesh_root: Path, asset_el, files: dict, assets: dict, used: set, notes: list,
                meshes: mesh_io.MeshCache) -> None:
    """Append ``link``'s visuals to ``body`` as non-colliding geoms (group 2), their files read through ``meshes``."""
    for k, v in enumerate(link.visuals):
        g = etree.SubElement(body, "geom", name=f"{safe_name(link.name)}__v{k}", pos=vec_text(v.origin[:3, 3]),
                             quat=quat_text(v.origin[:3, :3]), contype="0", conaffinity="0", group="2")
        if v.kind == "mesh":
            rel = relative_to(v.path, mesh_root) if v.path is not None and v.path.is_file() else None
            why = "is missing or outside the asset folder" if rel is None else visual_mesh_problem(v.path, meshes)
            if why:
                body.remove(g)
                notes.append(f"link {link.name!r} visual {k} ({v.filename}) {why}: not exported"
                             + ("" if rel is None else " (MuJoCo refuses it)"))
                continue
            name = g.get("name")
            while name in used:
                name += "_"
            used.add(name)
            me = etree.SubElement(asset_el, "mesh", name=name, file=rel, inertia="shell")
            if not np.allclose(v.scale, 1.0):
                me.set("scale", vec_text(v.scale))
            files[rel] = v.path
            assets[rel] = v.path.read_bytes()
            g.set("type", "mesh")
            g.set("mesh", name)
            g.set("rgba", mtl_colour(v.path))
        elif v.kind == "box":
            g.set("type", "box")
            g.set("size", vec_text(np.asarray(v.size) / 2))
        elif v.kind == "sphere":
            g.set("type", "sphere")
            g.set("size", num_text(v.radius))
        else:
            g.set("type", "cylinder")
            g.set("size", f"{num_text(v.radius)} {num_text(v.length / 2)}")
