"""Writer: the output folder of the SPEC's contract.

``mobility.urdf`` with the scale baked in (mesh ``scale`` attributes, joint and
geometry origins, primitive sizes, prismatic limits, inertials), an
``<inertial>`` on every link (mass > 0, valid inertia tensor, COM origin),
``<dynamics damping friction>`` on every movable joint, a comment pointing to
``initial_state.json`` / ``overlay.json``; meshes (with their MTL files and
textures) copied inside the folder under the same relative paths. Floats are
written at full precision (Python's shortest round-trip repr). Every file is
written atomically; the input folder is never written.
"""

from __future__ import annotations

import io
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from asset2sim import atomic
from asset2sim.schemas.asset import AssetDescription
from asset2sim.schemas.overlay import Overlay

URDF_NAME = "mobility.urdf"
STATE_NAME = "initial_state.json"
OVERLAY_NAME = "overlay.json"


class OutputError(ValueError):
    """The output folder cannot be used (e.g. it is inside the input)."""


@dataclass
class OutputPaths:
    """Files of one output folder."""

    root: Path
    urdf: Path
    initial_state: Path
    overlay: Path


def check_output_folder(asset: AssetDescription, out_dir: Path) -> Path:
    """Resolve ``out_dir`` and refuse the input folder or anything inside it.

    Raises:
        OutputError: ``out_dir`` is the input folder or lies inside it.
    """
    out = Path(out_dir).resolve()
    src = asset.source_dir.resolve()
    if out == src or src in out.parents:
        raise OutputError(f"output folder {out} is the input folder {src} or inside it; choose another")
    return out


_MTLLIB = re.compile(rb"^\s*mtllib\s+(.+?)\s*$", re.M)
_MAP = re.compile(rb"^\s*(?:map_\w+|bump|disp|decal|refl)\s+(?:-\S+\s+\S+\s+)*(\S.*?)\s*$", re.M)


def _inside(path: Path, root: Path) -> bool:
    try:
        path.resolve().relative_to(root.resolve())
        return True
    except ValueError:
        return False


def mesh_dependencies(mesh_path: Path, asset_root: Path) -> list[Path]:
    """Files an OBJ mesh needs besides itself (MTL libraries and their texture
    maps), as absolute paths inside ``asset_root``; missing or outside files are
    skipped (visual only)."""
    deps: list[Path] = []
    if mesh_path.suffix.lower() != ".obj":
        return deps
    try:
        data = mesh_path.read_bytes()
    except OSError:
        return deps
    for m in _MTLLIB.finditer(data):
        mtl = (mesh_path.parent / m.group(1).decode("utf-8", "replace")).resolve()
        if not (mtl.is_file() and _inside(mtl, asset_root)):
            continue
        deps.append(mtl)
        try:
            mdata = mtl.read_bytes()
        except OSError:
            continue
        for t in _MAP.finditer(mdata):
            tex = (mtl.parent / t.group(1).decode("utf-8", "replace")).resolve()
            if tex.is_file() and _inside(tex, asset_root):
                deps.append(tex)
    return deps


def copy_meshes(asset: AssetDescription, out_dir: Path) -> list[Path]:
    """Copy every mesh the URDF references (and its MTL/textures) into
    ``out_dir`` under the same path relative to the asset folder.

    Returns the copied destination paths. Files already present with the same
    content are not rewritten.
    """
    root = asset.source_dir.resolve()
    files: set[Path] = set()
    for ln in asset.links:
        for g in ln.visuals + ln.collisions:
            if g.kind == "mesh" and g.path is not None:
                files.add(g.path.resolve())
                files.update(mesh_dependencies(g.path, root))
    out = []
    todo = []
    for src in sorted(files):
        if not _inside(src, root):
            raise OutputError(f"mesh {src} lies outside the asset folder {root}")
        dst = out_dir / src.relative_to(root)
        if not (dst.is_file() and dst.stat().st_size == src.stat().st_size and atomic.sha256_file(dst) == atomic.sha256_file(src)):
            todo.append((src, dst))
        out.append(dst)
    atomic.copy_files(todo)
    return out


def _scale_origin(matrix, s: float):
    if matrix is None:
        return None
    m = np.array(matrix, float)
    m[:3, 3] *= s
    return m


def _origin_xyz(xyz) -> np.ndarray:
    m = np.eye(4)
    m[:3, 3] = np.asarray(xyz, float)
    return m


def _origin_matrix(origin) -> np.ndarray:
    import trimesh.transformations as tf

    m = tf.euler_matrix(*origin.rpy, axes="sxyz")
    m[:3, 3] = np.asarray(origin.xyz, float)
    return m


def build_urdf(
    asset: AssetDescription,
    overlay: Overlay,
    collision_overrides: dict | None = None,
    root_rotation: np.ndarray | None = None,
) -> bytes:
    """The revised URDF (bytes, UTF-8) for ``overlay`` applied to ``asset``.

    ``collision_overrides``: link -> list of
    :class:`asset2sim.tasks.state.collision.CollisionPiece` replacing the link's
    mesh collisions (convex decomposition), paths relative to the output.
    ``root_rotation``: (3, 3) rotation baked into the root link's geometry and
    the joints that hang from it (a requested resting pose, ``tasks.pose``).

    Raises:
        OutputError: the overlay lacks an entry for a link with geometry or a
            movable joint (validate the overlay first).
    """
    import yourdfpy
    from lxml import etree

    from asset2sim import safexml

    s = float(overlay.scale)
    data = asset.urdf_path.read_bytes()
    safexml.parse_xml_bytes(data, source=str(asset.urdf_path))  # the hardened parser sees it first, every time
    model = yourdfpy.URDF.load(
        io.BytesIO(data),
        build_scene_graph=False,
        load_meshes=False,
        build_collision_scene_graph=False,
        load_collision_meshes=False,
        filename_handler=lambda fname: fname,
    )
    robot = model.robot
    overrides = collision_overrides or {}
    for link in robot.links:
        pieces = overrides.get(link.name)
        if pieces:
            kept = [c for c in link.collisions if c.geometry is None or c.geometry.mesh is None]
            for piece in pieces:
                kept.append(
                    yourdfpy.Collision(
                        name=None,
                        origin=_origin_matrix(piece.source.origin),
                        geometry=yourdfpy.Geometry(mesh=yourdfpy.Mesh(filename=piece.filename, scale=np.asarray(piece.source.scale, float))),
                    )
                )
            link.collisions = kept
        for elem in list(link.visuals) + list(link.collisions):
            elem.origin = _scale_origin(elem.origin, s)
            g = elem.geometry
            if g is None:
                continue
            if g.mesh is not None:
                base = np.ones(3) if g.mesh.scale is None else np.broadcast_to(np.asarray(g.mesh.scale, float).ravel(), (3,))
                g.mesh.scale = np.asarray(base, float) * s
            if g.box is not None:
                g.box.size = np.asarray(g.box.size, float) * s
            if g.cylinder is not None:
                g.cylinder.radius = float(g.cylinder.radius) * s
                g.cylinder.length = float(g.cylinder.length) * s
            if g.sphere is not None:
                g.sphere.radius = float(g.sphere.radius) * s
        lp = overlay.links.get(link.name)
        if lp is None:
            has_geom = bool(link.visuals or link.collisions)
            if has_geom:
                raise OutputError(f"overlay has no mass/inertia for link {link.name!r} (validate the overlay first)")
            link.inertial = None
            continue
        link.inertial = yourdfpy.Inertial(
            origin=_origin_xyz(lp.com), mass=float(lp.mass), inertia=lp.inertia.matrix()
        )
    if root_rotation is not None and not np.allclose(root_rotation, np.eye(3)):
        T = np.eye(4)
        T[:3, :3] = np.asarray(root_rotation, float)
        root_name = asset.root_link
        for joint in robot.joints:
            if joint.parent == root_name:
                joint.origin = T @ (np.eye(4) if joint.origin is None else np.asarray(joint.origin, float))
        for link in robot.links:
            if link.name == root_name:
                for elem in list(link.visuals) + list(link.collisions):
                    elem.origin = T @ (np.eye(4) if elem.origin is None else np.asarray(elem.origin, float))
                if link.inertial is not None:
                    link.inertial.origin = T @ (np.eye(4) if link.inertial.origin is None else np.asarray(link.inertial.origin, float))
    for joint in robot.joints:
        joint.origin = _scale_origin(joint.origin, s)
        if joint.type == "prismatic" and joint.limit is not None:
            if joint.limit.lower is not None:
                joint.limit.lower = float(joint.limit.lower) * s
            if joint.limit.upper is not None:
                joint.limit.upper = float(joint.limit.upper) * s
        if joint.type in ("revolute", "continuous", "prismatic"):
            dyn = overlay.joints.get(joint.name)
            if dyn is None:
                raise OutputError(f"overlay has no dynamics for joint {joint.name!r} (validate the overlay first)")
            joint.dynamics = yourdfpy.Dynamics(damping=float(dyn.damping), friction=float(dyn.friction))
            if joint.limit is None:
                joint.limit = yourdfpy.Limit()
            if joint.limit.effort is None:
                joint.limit.effort = 1000.0
            if joint.limit.velocity is None:
                joint.limit.velocity = 1000.0
    tree = model.write_xml()
    root = tree.getroot()
    springs = {n: (d.stiffness, d.spring_reference) for n, d in overlay.joints.items() if d.stiffness > 0}
    comment = (
        f" Written by asset2sim. Uniform scale {s!r} is baked in (mesh scale, origins, prismatic limits, inertials); "
        f"load at scale 1.0. Initial joint positions (rad / m): see {STATE_NAME} (URDF has no field for them). "
        f"Joint stiffness, spring references and the reasoning notes: see {OVERLAY_NAME}"
        + (f"; springs on {', '.join(sorted(springs))}" if springs else "")
        + ". "
    )
    root.insert(0, etree.Comment(comment.replace("--", "- -")))
    etree.indent(root, space="  ")
    return etree.tostring(root, xml_declaration=True, encoding="utf-8", pretty_print=True)


def write_output(
    asset: AssetDescription,
    overlay: Overlay,
    out_dir: Path,
    initial_state: dict[str, float],
    *,
    copy: bool = True,
    collision_overrides: dict | None = None,
    root_rotation: np.ndarray | None = None,
) -> OutputPaths:
    """Write (or rewrite) the output folder: meshes, ``mobility.urdf``,
    ``initial_state.json`` and ``overlay.json``. Atomic per file.

    Args:
        initial_state: joint -> position in output units (rad or m).
        copy: copy the meshes (skip when only dynamics changed).
        collision_overrides, root_rotation: see :func:`build_urdf`.

    Raises:
        OutputError: output folder inside the input, or an incomplete overlay.
    """
    out = check_output_folder(asset, out_dir)
    out.mkdir(parents=True, exist_ok=True)
    if copy:
        copy_meshes(asset, out)
    urdf = atomic.write_bytes(out / URDF_NAME, build_urdf(asset, overlay, collision_overrides, root_rotation))
    state = atomic.write_json(out / STATE_NAME, {"initial_joint_positions": {k: float(v) for k, v in initial_state.items()}})
    ovl = atomic.write_json(out / OVERLAY_NAME, overlay.model_dump(mode="json"))
    return OutputPaths(root=out, urdf=urdf, initial_state=state, overlay=ovl)
