"""URDF -> render scene: the render-only copy of a URDF that PyBullet's renderer loads, and the
visual points of each link that cameras are fitted to.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from asset2sim.tasks.geometry.render_meshes import (DEFAULT_COLOR, DrawableMesh, TextureLinks, colored_obj, convert_other_mesh,
                                                    split_obj)
from asset2sim.urdf import UrdfError, UrdfGeometry, UrdfMaterial, UrdfModel, read_urdf, write_urdf


def resolve_mesh_path(filename: str, urdf_dir: Path) -> Path:
    """Absolute path of a URDF mesh reference (relative, absolute, file://, package://)."""
    name = filename.strip().removeprefix("file://")
    if name.startswith("package://"):
        rest = name.removeprefix("package://")
        _pkg, _, sub = rest.partition("/")
        candidates = [urdf_dir / sub, urdf_dir / rest]
        for parent in urdf_dir.parents:
            candidates += [parent / rest, parent / sub]
        for c in candidates:
            if c.is_file():
                return c.resolve()
        return (urdf_dir / sub).resolve()
    p = Path(name)
    return (p if p.is_absolute() else urdf_dir / p).resolve()


def primitive_points(geom: UrdfGeometry) -> np.ndarray:
    """Points (N, 3) whose hull bounds a URDF box / cylinder / sphere / capsule, m
    (a missing size counts as 0)."""
    kind = geom.kind
    if kind == "box":
        sx, sy, sz = (float(v) for v in (geom.size if geom.size is not None else (0.0, 0.0, 0.0)))
        g = np.array(np.meshgrid([-0.5, 0.5], [-0.5, 0.5], [-0.5, 0.5])).reshape(3, -1).T
        return g * [sx, sy, sz]
    ang = np.linspace(0, 2 * np.pi, 24, endpoint=False)
    r = float(geom.radius or 0.0)
    if kind in ("cylinder", "capsule"):
        length = float(geom.length or 0.0)
        ring = np.stack([r * np.cos(ang), r * np.sin(ang)], axis=1)
        h = length / 2 + (r if kind == "capsule" else 0.0)
        return np.concatenate([np.c_[ring, np.full(24, -h)], np.c_[ring, np.full(24, h)]])
    if kind == "sphere":
        # azimuths, elevations
        A, E = np.meshgrid(ang, np.linspace(-np.pi / 2, np.pi / 2, 9))
        return r * np.stack([np.cos(E) * np.cos(A), np.cos(E) * np.sin(A), np.sin(E)], -1).reshape(-1, 3)
    return np.zeros((0, 3))


def visual_rgba(vis: UrdfGeometry, named: dict[str, tuple[float, ...]]) -> tuple[float, ...] | None:
    """The RGBA of a visual's ``<material>`` (inline ``<color>`` or a named
    top-level material), or None."""
    mat = vis.material
    if mat is None:
        return None
    if mat.rgba is not None:
        return tuple(map(float, mat.rgba))
    rgba = named.get(mat.name or "")
    return rgba if rgba is not None and len(rgba) == 4 else None


@dataclass
class RenderScene:
    """What :func:`prepare_scene` made: ``urdf`` the render-only URDF, ``link_points`` link -> visual
    points (N, 3) in the link frame, m, and ``notes`` (what was changed so the asset draws)."""

    urdf: Path
    link_points: dict[str, np.ndarray]
    notes: list[str] = field(default_factory=list)


class _VisualFiles:
    """The drawable work files of the visuals' meshes: each mesh file prepared once (tags ``m0000`` ...
    in order of first use), each (mesh, color) of material-less faces colored once (``k0000`` ...)."""

    def __init__(self, work: Path, textures: TextureLinks, notes: list[str]):
        self.work = work
        self.textures = textures
        self.notes = notes
        self.n_split = 0
        self._meshes: dict[Path, DrawableMesh] = {}
        self._colored: dict[tuple[Path, tuple[float, ...]], Path] = {}

    def mesh(self, mesh_file: Path) -> DrawableMesh:
        """The prepared mesh of ``mesh_file`` (an existing file)."""
        info = self._meshes.get(mesh_file)
        if info is None:
            tag = f"m{len(self._meshes):04d}"
            if mesh_file.suffix.lower() == ".obj":
                info = split_obj(mesh_file, self.work, tag, self.textures)
                self.n_split += len(info.parts) > 1
            else:
                info = convert_other_mesh(mesh_file, self.work, tag, self.notes)
            self._meshes[mesh_file] = info
        return info

    def files(self, vis: UrdfGeometry, mesh_file: Path, named: dict[str, tuple[float, ...]]) -> tuple[DrawableMesh, list[Path]]:
        """(prepared mesh, files that draw visual ``vis`` of ``mesh_file``: the per-material parts and the
        material-less faces in the visual's ``<material>`` color, else :data:`DEFAULT_COLOR`)."""
        info = self.mesh(mesh_file)
        files = list(info.parts)
        if info.bare is not None or info.bare_text is not None:
            rgba = visual_rgba(vis, named) or DEFAULT_COLOR
            key = (mesh_file, tuple(rgba))
            if key not in self._colored:
                source = info.bare if info.bare is not None else mesh_file
                self._colored[key] = colored_obj(info, source, rgba, self.work, f"k{len(self._colored):04d}")
            files.append(self._colored[key])
        return info, files


def _all_materials(model: UrdfModel) -> list[UrdfMaterial]:
    """Top-level materials, then the visuals' own, in file order."""
    return [*model.materials, *(v.material for ln in model.links.values() for v in ln.visuals if v.material is not None)]


def prepare_scene(urdf_path: Path, work: Path, texture_max: int = 1024) -> RenderScene:
    """Write the render-only URDF into ``work`` and collect visual points per link: no ``<collision>`` or
    ``<inertial>`` (the root link frame is the body frame), each visual mesh replaced by drawable
    files, textures above ``texture_max`` pixels downscaled; without any ``<visual>`` the collision
    shapes are drawn.

    Raises:
        FileNotFoundError: the URDF or one of its visual meshes is missing.
        ValueError: the URDF or a mesh does not parse, or there is no visual geometry.
    """
    if not urdf_path.is_file():
        raise FileNotFoundError(f"no such URDF: {urdf_path}")
    try:
        model = read_urdf(urdf_path, mode="lenient")
    except UrdfError as exc:
        raise ValueError(f"{urdf_path}: not a parseable URDF ({exc})") from exc
    urdf_dir = urdf_path.parent.resolve()
    # material name -> RGBA of its first definition with a color (URDF materials are global by name)
    named = {m.name: tuple(map(float, m.rgba)) for m in reversed(_all_materials(model)) if m.name and m.rgba is not None}
    notes: list[str] = []
    if not any(ln.visuals for ln in model.links.values()) and any(ln.collisions for ln in model.links.values()):
        for ln in model.links.values():  # nothing else to show: draw the collision shapes
            ln.visuals = ln.collisions
        notes.append("the URDF has no <visual>: its collision shapes are drawn")
    textures = TextureLinks(work, texture_max)
    meshes = _VisualFiles(work, textures, notes)
    link_points: dict[str, np.ndarray] = {}
    for lname, link in model.links.items():
        # no collisions or inertial; the mesh visuals replaced by their drawable files, the visual points (N, 3) in the
        # link frame (m) kept
        link.collisions = []
        link.inertial = None
        pts: list[np.ndarray] = []
        shown: list[UrdfGeometry] = []
        for vis in link.visuals:
            if vis.kind is None:
                continue
            T = vis.origin
            if vis.kind != "mesh":
                local = primitive_points(vis)
                if len(local):
                    pts.append(local @ T[:3, :3].T + T[:3, 3])
                shown.append(vis)
                continue
            mesh_file = resolve_mesh_path(vis.filename or "", urdf_dir)
            if not mesh_file.is_file():
                raise FileNotFoundError(f"{urdf_path}: link {lname!r} visual mesh not found: {mesh_file}")
            info, files = meshes.files(vis, mesh_file, named)
            if len(info.vertices):
                pts.append((info.vertices * vis.scale) @ T[:3, :3].T + T[:3, 3])
            shown.extend(replace(vis, filename=str(part)) for part in files)
        link.visuals = shown
        if pts:
            link_points[lname] = np.concatenate(pts)
    if not link_points:
        raise ValueError(f"{urdf_path}: no visual geometry to render")
    for mat in {id(m): m for m in _all_materials(model)}.values():  # each <texture filename=...> at its link in ``work``
        if mat.texture and (src := resolve_mesh_path(mat.texture, urdf_dir)).is_file():
            mat.texture = textures.link(src)[0]
    if meshes.n_split:
        notes.append(f"{meshes.n_split} multi-material OBJ file(s) split into one OBJ per material")
    if textures.downscaled:
        notes.append(f"{textures.downscaled} texture(s) over {texture_max} px downscaled")
    out = work / "render.urdf"
    out.write_bytes(write_urdf(model))
    return RenderScene(out, link_points, notes)
