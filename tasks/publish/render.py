"""Textured multi-view renders of an articulated object, headless on a CPU.

The object is loaded from its URDF with its OBJ/MTL/texture files, its root is
fixed at the origin in the URDF's base link frame (z up), the joints are set to
the requested state and each view is drawn by PyBullet's software renderer
(``ER_TINY_RENDERER``: pip package only, no GPU, no display, no EGL). The
camera is fitted per view to the object's *visual* vertices at that state, so
a 0.05 m stapler and a 2 m cabinet fill the image the same way.

View convention (checked on the 21 PartNet-Mobility objects, see
``docs/renders.md``): after the base joint's rotation, PartNet-Mobility objects
face **-x**: drawers slide out along -x, doors and lids open toward -x, the
lock of a chest, the user's side of a laptop, the spout of a faucet are at -x.

=============  ==========================================  ======================
view           camera (direction from the object)          image "up"
=============  ==========================================  ======================
front          -x (looks along +x), 20 deg above            +z
back           +x (looks along -x), 20 deg above            +z
left           -y, the object's own left side, 20 deg above +z
right          +y, the object's own right side, 20 deg abv. +z
perspective    front-left (-x, -y), 30 deg above            +z
top            +z (looks down)                              +x (front at bottom)
=============  ==========================================  ======================

"left"/"right" are the object's own sides (it faces -x with z up, so its left
is -y): in the front view the object's left side is on the image's right.

What is done beyond a plain ``loadURDF`` + ``getCameraImage``:

1. PyBullet draws one material per OBJ file; PartNet-Mobility OBJs often
   switch materials inside one object (``usemtl``: wood inside, metal
   outside), and PyBullet then draws them white. Such OBJs are split into one
   OBJ per material in a temporary folder (inputs are never written), and a
   render-only copy of the URDF (no collision or inertial elements, absolute
   mesh paths) is loaded with ``URDF_USE_MATERIAL_COLORS_FROM_MTL`` so ``Kd``
   colors are used. Faces without any material get the visual's URDF
   ``<material>`` color (else :data:`DEFAULT_COLOR`).
2. Textures larger than the rendered image are downscaled (area filter), as
   the renderer samples them nearest-neighbour without mipmaps.
3. The renderer has no anti-aliasing and a fixed background: views are drawn
   ``supersample`` (2) times larger, the segmentation mask composites the
   object over :data:`BACKGROUND`, and the result is box-filtered down.
4. Black materials (``Kd 0 0 0`` is common) are lifted to
   :data:`ALBEDO_FLOOR` so their shading still shows the shape.

Lighting: one directional light from the camera's upper left (fixed relative
to each camera, so every view is lit alike), intensity ``AMBIENT + DIFFUSE *
cos + SPECULAR``; optional cast shadows (``shadows=True``, slower).
"""

from __future__ import annotations

import json
import math
import shutil
import tempfile
import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Iterable, Mapping, Sequence

import numpy as np

from asset2sim import mesh_io
from asset2sim.atomic import write_bytes
from asset2sim.engines.base import open_viewer
from asset2sim.tasks.ingest import partnet_mobility
from asset2sim.urdf import UrdfError, UrdfGeometry, read_urdf, write_urdf

DEFAULT_VIEWS: tuple[str, ...] = ("front", "back", "left", "right", "perspective")
"""The five views of the SPEC's extraction stage."""

BACKGROUND: tuple[int, int, int] = (236, 238, 242)
"""RGB of the background behind the object (a light blue-grey, so white and
black objects both stand out)."""

BACKENDS: tuple[str, ...] = ("auto", "tiny")


@dataclass(frozen=True)
class ViewSpec:
    """Where a named view's camera sits, seen from the object's center.

    ``azimuth_deg``: angle in the xy plane from +x toward +y of the direction
    object -> camera; ``elevation_deg``: angle above the xy plane (90 = top).
    """

    name: str
    azimuth_deg: float
    elevation_deg: float

    def direction(self) -> np.ndarray:
        """Unit vector (3,) from the object's center toward the camera."""
        az, el = math.radians(self.azimuth_deg), math.radians(self.elevation_deg)
        return np.array([math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)])


VIEWS: dict[str, ViewSpec] = {
    v.name: v
    for v in (
        ViewSpec("front", 180.0, 20.0),
        ViewSpec("back", 0.0, 20.0),
        ViewSpec("left", -90.0, 20.0),
        ViewSpec("right", 90.0, 20.0),
        ViewSpec("perspective", -135.0, 30.0),
        ViewSpec("top", 180.0, 90.0),
    )
}
"""Named views (see the module docstring for the convention)."""

FOV_DEG = 35.0
"""Vertical field of view of every camera, degrees."""

FILL = 0.88
"""Fraction of the image's half-size that the object's farthest point reaches."""


AMBIENT, DIFFUSE, SPECULAR = 0.38, 0.68, 0.1
"""Light coefficients of the renderer (intensity = ambient + diffuse * cos + specular)."""

ALBEDO_FLOOR = 0.22
"""Every diffuse color c is drawn as f + (1 - f) c with this f, so black
materials still show shading (see :meth:`SceneRenderer._lift_dark_colors`)."""


class RenderError(RuntimeError):
    """The renderer could not load or draw the asset (message names the file)."""


# ------------------------------------------------------------------ utilities
def resolve_urdf(asset: Path | str) -> Path:
    """The URDF of ``asset``: the file itself, or ``mobility.urdf`` (else the only
    ``*.urdf`` not named ``reference_*``) in a folder
    (:func:`asset2sim.tasks.ingest.partnet_mobility.urdf_candidates`).

    Raises:
        FileNotFoundError: no such file or folder, or no URDF in the folder.
        ValueError: a folder with several URDFs and no ``mobility.urdf``.
    """
    asset = Path(asset)
    if asset.is_file():
        return asset
    if not asset.is_dir():
        raise FileNotFoundError(f"no such asset file or folder: {asset}")
    urdfs = partnet_mobility.urdf_candidates(asset)
    if len(urdfs) == 1:
        return urdfs[0]
    if not urdfs:
        raise FileNotFoundError(f"no mobility.urdf (or other .urdf) in {asset}")
    raise ValueError(f"{asset} has several URDFs and no mobility.urdf: {[u.name for u in urdfs]}")


def read_joint_state(path: Path | str) -> dict[str, float]:
    """Joint positions (rad or m) from an ``initial_state.json`` file
    ``{"initial_joint_positions": {joint: value}}``.

    Raises:
        FileNotFoundError: the file does not exist.
        ValueError: not JSON, not that shape, or a value that is not a finite number.
    """
    path = Path(path)
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except json.JSONDecodeError as exc:
        raise ValueError(f"{path}: not valid JSON ({exc})") from exc
    if not isinstance(data, dict) or not isinstance(data.get("initial_joint_positions"), dict):
        raise ValueError(f'{path}: expected {{"initial_joint_positions": {{joint: value}}}}')
    out: dict[str, float] = {}
    for name, value in data["initial_joint_positions"].items():
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise ValueError(f"{path}: joint {name!r} has position {value!r}, not a finite number")
        out[str(name)] = float(value)
    return out


# ------------------------------------------------------------ mesh handling
DEFAULT_COLOR: tuple[float, float, float, float] = (0.8, 0.8, 0.8, 1.0)
"""RGBA of mesh faces with neither an MTL material nor a URDF ``<material>``."""


@dataclass
class _ObjInfo:
    """What the renderer needs from one mesh file.

    ``vertices`` (N, 3) in the file's units; ``parts``: files to load that carry
    their own material (the original file when it has exactly one); ``bare``:
    a file with the faces that have no (known) material, colored later from the
    URDF; ``bare_text``: its contents when it still has to be written per color.
    """

    vertices: np.ndarray
    parts: list[Path]
    bare: Path | None = None
    bare_text: str | None = None


class _Textures:
    """Texture files made reachable from the work folder, by a plain relative
    name (PyBullet resolves texture names relative to the MTL's folder and does
    not accept absolute paths). Textures larger than ``max_side`` pixels are
    stored downscaled (area filter): the software renderer samples textures
    nearest-neighbour without mipmaps, so a 3000 px screen texture drawn on
    200 px aliases into stripes. Smaller ones are symlinked (or copied)."""

    def __init__(self, work: Path, max_side: int):
        self.folder = work / "textures"
        self.max_side = max_side
        self._done: dict[Path, tuple[str, bool]] = {}
        self.downscaled = 0

    def link(self, tex: Path) -> tuple[str, bool]:
        """(name relative to the work folder, whether the texture was downscaled)."""
        if tex in self._done:
            return self._done[tex]
        import hashlib

        self.folder.mkdir(exist_ok=True)
        stem = hashlib.sha1(str(tex).encode()).hexdigest()[:12]
        resized = False
        name = f"{stem}{tex.suffix.lower()}"
        try:
            from PIL import Image

            with Image.open(tex) as im:
                if max(im.size) > self.max_side:
                    im = im.convert("RGBA" if im.mode in ("RGBA", "LA", "P") else "RGB")
                    im.thumbnail((self.max_side, self.max_side), Image.Resampling.BOX)
                    name = f"{stem}.png"
                    im.save(self.folder / name)
                    resized = True
                    self.downscaled += 1
        except Exception:  # unreadable by PIL: let PyBullet try the original
            resized = False
        if not resized:
            dst = self.folder / name
            if not dst.exists():
                try:
                    dst.symlink_to(tex)
                except OSError:
                    shutil.copyfile(tex, dst)
        self._done[tex] = (f"textures/{name}", resized)
        return self._done[tex]


def _read_mtl(path: Path, textures: _Textures) -> tuple[dict[str, list[str]], bool]:
    """(material name -> its lines with textures linked into the work folder,
    whether a texture was downscaled). Missing textures are dropped."""
    mats: dict[str, list[str]] = {}
    changed = False
    current: list[str] | None = None
    try:
        text = path.read_text(encoding="utf-8", errors="replace")
    except OSError:
        return mats, changed
    for raw in text.splitlines():
        line = raw.strip()
        if not line or line.startswith("#"):
            continue
        key = line.split(maxsplit=1)[0]
        if key == "newmtl":
            current = mats.setdefault(line[len("newmtl") :].strip(), [])
            continue
        if current is None:
            continue
        if mesh_io.is_texture_statement(key):
            tokens = line.split()
            tex = (path.parent / tokens[-1]).resolve()
            if len(tokens) < 2 or not tex.is_file():
                continue
            name, resized = textures.link(tex)
            changed |= resized
            current.append(" ".join(tokens[:-1] + [name]))
        else:
            current.append(line)
    return mats, changed


def _split_obj(path: Path, work: Path, tag: str, textures: _Textures) -> _ObjInfo:
    """Read the OBJ ``path`` and make it drawable by PyBullet with its materials.

    PyBullet draws one material per OBJ file, so a file whose faces use several
    materials is written again as one OBJ (+ MTL) per material into ``work``
    (names start with ``tag``). Face indices are made absolute and every split
    file carries all vertex data (unused vertices are harmless), so the split
    files draw exactly the original faces. Faces without a known material go
    to :attr:`_ObjInfo.bare`. A file whose textures had to be downscaled (see
    :class:`_Textures`) is rewritten too.
    """
    scan = mesh_io.scan_obj_text(path.read_text(encoding="utf-8", errors="replace"))
    data_lines, faces, mtllibs = scan.data_lines, scan.faces, scan.mtllibs
    vertices = mesh_io.parse_vertex_lines(scan.vertex_lines)
    materials: dict[str, list[str]] = {}
    downscaled = False
    for lib in mtllibs:
        mats, changed = _read_mtl(path.parent / lib, textures)
        downscaled |= changed
        for name, lines in mats.items():
            materials.setdefault(name, lines)
    known = [m for m in faces if m is not None and m in materials]
    unknown = [m for m in faces if m is None or m not in materials]
    if len(known) == 1 and not unknown and not downscaled:
        return _ObjInfo(vertices, [path])
    if not known and not mtllibs and list(faces) in ([None], []):
        return _ObjInfo(vertices, [], bare=path if faces else None)
    header = "\n".join(data_lines)
    parts = []
    for k, mat in enumerate(known):
        stem = f"{tag}_{k}"
        (work / f"{stem}.mtl").write_text(f"newmtl {mat}\n" + "\n".join(materials[mat]) + "\n", encoding="utf-8")
        body = "\n".join([f"mtllib {stem}.mtl", header, f"usemtl {mat}", *faces[mat]]) + "\n"
        out = work / f"{stem}.obj"
        out.write_text(body, encoding="utf-8")
        parts.append(out)
    bare_text = None
    if unknown:
        bare_text = "\n".join([header, *(f for m in unknown for f in faces[m])]) + "\n"
    return _ObjInfo(vertices, parts, bare_text=bare_text)


def _colored_obj(info: _ObjInfo, source: Path, rgba: Sequence[float], work: Path, tag: str) -> Path:
    """An OBJ of ``info``'s material-less faces with one material of color ``rgba``.

    PyBullet (with ``URDF_USE_MATERIAL_COLORS_FROM_MTL``) draws an OBJ without
    a material black, so the URDF's ``<material>`` color (or
    :data:`DEFAULT_COLOR`) is written into an MTL instead.
    """
    if info.bare_text is None:
        text = "\n".join(
            ln for ln in source.read_text(encoding="utf-8", errors="replace").splitlines()
            if not ln.startswith(("mtllib", "usemtl"))
        ) + "\n"
    else:
        text = info.bare_text
    r, g, b = (min(1.0, max(0.0, float(c))) for c in rgba[:3])
    (work / f"{tag}.mtl").write_text(f"newmtl color\nKd {r:.4f} {g:.4f} {b:.4f}\n", encoding="utf-8")
    out = work / f"{tag}.obj"
    out.write_text(f"mtllib {tag}.mtl\nusemtl color\n" + text, encoding="utf-8")
    return out


def _resolve_mesh(filename: str, urdf_dir: Path) -> Path:
    """Absolute path of a URDF mesh reference (relative, absolute, file://, package://)."""
    name = filename.strip()
    if name.startswith("file://"):
        name = name[len("file://") :]
    if name.startswith("package://"):
        rest = name[len("package://") :]
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


def _primitive_points(geom: UrdfGeometry) -> np.ndarray:
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
        el = np.linspace(-np.pi / 2, np.pi / 2, 9)
        A, E = np.meshgrid(ang, el)
        return r * np.stack([np.cos(E) * np.cos(A), np.cos(E) * np.sin(A), np.sin(E)], -1).reshape(-1, 3)
    return np.zeros((0, 3))


def _visual_rgba(vis: UrdfGeometry, named: dict[str, tuple[float, ...]]) -> tuple[float, ...] | None:
    """The RGBA of a visual's ``<material>`` (inline ``<color>`` or a named
    top-level material), or None."""
    mat = vis.material
    if mat is None:
        return None
    if mat.rgba is not None:
        return tuple(float(v) for v in mat.rgba)
    rgba = named.get(mat.name or "")
    return rgba if rgba is not None and len(rgba) == 4 else None


@dataclass
class _Prepared:
    urdf: Path  # the render-only URDF
    link_points: dict[str, np.ndarray]  # link -> (N, 3) visual points in the link frame, m
    notes: list[str] = field(default_factory=list)


def _prepare(urdf_path: Path, work: Path, texture_max: int = 1024) -> _Prepared:
    """Write the render-only URDF into ``work`` and collect visual points per link.

    The copy has no ``<collision>`` or ``<inertial>`` (so the root link frame is
    the body frame PyBullet places at the origin), absolute mesh paths, and
    each visual mesh replaced by the files of :func:`_split_obj`; textures
    larger than ``texture_max`` pixels are downscaled.

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
    named: dict[str, tuple[float, ...]] = {}  # URDF materials are global by name
    for mat in [*model.materials, *(v.material for ln in model.links.values() for v in ln.visuals if v.material is not None)]:
        if mat.name and mat.rgba is not None and mat.name not in named:
            named[mat.name] = tuple(float(v) for v in mat.rgba)
    notes: list[str] = []
    if not any(ln.visuals for ln in model.links.values()) and any(ln.collisions for ln in model.links.values()):
        for ln in model.links.values():  # nothing else to show: draw the collision shapes
            ln.visuals = ln.collisions
        notes.append("the URDF has no <visual>: its collision shapes are drawn")
    textures = _Textures(work, texture_max)
    cache: dict[Path, _ObjInfo] = {}
    colored: dict[tuple[Path, tuple[float, ...]], Path] = {}
    link_points: dict[str, np.ndarray] = {}
    n_split = 0
    for lname, link in model.links.items():
        link.collisions = []
        link.inertial = None
        pts: list[np.ndarray] = []
        shown: list[UrdfGeometry] = []
        for vis in link.visuals:
            if vis.kind is None:
                continue
            T = vis.origin
            if vis.kind != "mesh":
                local = _primitive_points(vis)
                if len(local):
                    pts.append(local @ T[:3, :3].T + T[:3, 3])
                shown.append(vis)
                continue
            mesh_file = _resolve_mesh(vis.filename or "", urdf_dir)
            if not mesh_file.is_file():
                raise FileNotFoundError(f"{urdf_path}: link {lname!r} visual mesh not found: {mesh_file}")
            info = cache.get(mesh_file)
            if info is None:
                tag = f"m{len(cache):04d}"
                if mesh_file.suffix.lower() == ".obj":
                    info = _split_obj(mesh_file, work, tag, textures)
                    n_split += len(info.parts) > 1
                else:
                    info = _other_mesh(mesh_file, work, tag, notes)
                cache[mesh_file] = info
            files = list(info.parts)
            if info.bare is not None or info.bare_text is not None:
                rgba = _visual_rgba(vis, named) or DEFAULT_COLOR
                key = (mesh_file, tuple(rgba))
                if key not in colored:
                    source = info.bare if info.bare is not None else mesh_file
                    colored[key] = _colored_obj(info, source, rgba, work, f"k{len(colored):04d}")
                files.append(colored[key])
            if len(info.vertices):
                pts.append((info.vertices * vis.scale) @ T[:3, :3].T + T[:3, 3])
            shown.extend(replace(vis, filename=str(part)) for part in files)
        link.visuals = shown
        if pts:
            link_points[lname] = np.concatenate(pts)
    if not link_points:
        raise ValueError(f"{urdf_path}: no visual geometry to render")
    materials = [*model.materials, *(v.material for ln in model.links.values() for v in ln.visuals if v.material is not None)]
    for mat in {id(m): m for m in materials}.values():  # <material><texture filename=...> (clones share one)
        if mat.texture:
            src = _resolve_mesh(mat.texture, urdf_dir)
            if src.is_file():
                mat.texture = textures.link(src)[0]
    if n_split:
        notes.append(f"{n_split} multi-material OBJ file(s) split into one OBJ per material")
    if textures.downscaled:
        notes.append(f"{textures.downscaled} texture(s) over {texture_max} px downscaled")
    out = work / "render.urdf"
    out.write_bytes(write_urdf(model))
    return _Prepared(out, link_points, notes)


def _other_mesh(mesh_file: Path, work: Path, tag: str, notes: list[str]) -> _ObjInfo:
    """A non-OBJ visual mesh: STL is drawn by PyBullet as is (in the URDF's
    color); other formats (DAE, PLY, GLB ...) are converted to OBJ with trimesh
    (geometry only, colored from the URDF).

    Raises:
        ValueError: trimesh cannot read the file.
    """
    import trimesh

    try:
        mesh = mesh_io.load_trimesh(mesh_file)
    except Exception as exc:
        raise ValueError(f"cannot read mesh {mesh_file}: {exc}") from exc
    verts = np.asarray(mesh.vertices, float).reshape(-1, 3)
    if mesh_file.suffix.lower() == ".stl":
        return _ObjInfo(verts, [mesh_file])
    out = work / f"{tag}.obj"
    out.write_text(trimesh.exchange.obj.export_obj(mesh, include_normals=True, include_color=False,
                                                   include_texture=False), encoding="utf-8")
    notes.append(f"{mesh_file.name}: converted to OBJ (its own colors and textures are not drawn)")
    return _ObjInfo(verts, [], bare=out)


# ------------------------------------------------------------------- camera
@dataclass(frozen=True)
class Camera:
    """A pinhole camera: ``eye``/``target``/``up`` (3,) in m, vertical ``fov_deg``,
    clipping ``near``/``far`` in m."""

    eye: np.ndarray
    target: np.ndarray
    up: np.ndarray
    fov_deg: float
    near: float
    far: float


def fit_camera(
    points: np.ndarray,
    direction: np.ndarray,
    *,
    up: Sequence[float] = (0.0, 0.0, 1.0),
    aspect: float = 1.0,
    fov_deg: float = FOV_DEG,
    fill: float = FILL,
) -> Camera:
    """The camera looking at ``points`` (N, 3) m from ``direction`` (3,) (unit,
    object -> camera) that frames them: every point inside ``fill`` of the
    image's half-extent, the projected extent centered. Works at any scale.

    ``aspect`` is width / height; ``fov_deg`` the vertical field of view.

    Raises:
        ValueError: no points or a non-finite point.
    """
    P = np.asarray(points, float).reshape(-1, 3)
    if not len(P) or not np.isfinite(P).all():
        raise ValueError("fit_camera needs at least one finite point")
    b = np.asarray(direction, float)
    b = b / np.linalg.norm(b)
    upv = np.asarray(up, float)
    if abs(float(np.dot(upv / np.linalg.norm(upv), b))) > 0.999:  # looking along the up vector
        upv = np.array([1.0, 0.0, 0.0]) if abs(b[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    f = -b
    r = np.cross(f, upv)
    r /= np.linalg.norm(r)
    u = np.cross(r, f)
    lo, hi = P.min(0), P.max(0)
    extent = max(float(np.linalg.norm(hi - lo)), 1e-6)
    target = (lo + hi) / 2
    ty = math.tan(math.radians(fov_deg) / 2) * fill
    tx = ty * aspect
    d = extent
    for _ in range(4):
        rel = P - target
        x, y, z = rel @ r, rel @ u, rel @ b
        d = float(max(np.max(z + np.abs(x) / tx), np.max(z + np.abs(y) / ty), extent * 1e-3))
        depth = d - z
        X, Y = x / depth, y / depth
        cx, cy = (X.max() + X.min()) / 2, (Y.max() + Y.min()) / 2
        if abs(cx) < 1e-4 * tx and abs(cy) < 1e-4 * ty:
            break
        target = target + (r * cx + u * cy) * d
    rel = P - target
    depth = d - rel @ b
    near = max(float(depth.min()) * 0.5, extent * 1e-4)
    far = float(depth.max()) * 1.5 + extent * 0.1
    return Camera(target + b * d, target, u, fov_deg, near, far)


# ------------------------------------------------------------------ renderer
@dataclass
class RenderTimings:
    """Wall times, s: ``prepare`` (URDF/OBJ preparation), ``load`` (PyBullet
    load), ``views`` name -> list of times of each render of that view."""

    prepare: float = 0.0
    load: float = 0.0
    views: dict[str, list[float]] = field(default_factory=dict)


class SceneRenderer:
    """One asset loaded once, rendered at any joint state from any view.

    Use as a context manager (or call :meth:`close`)::

        with SceneRenderer(urdf) as r:
            r.set_joint_positions({"joint_0": 0.5})
            img = r.render("front")          # (H, W, 3) uint8

    Args:
        urdf_path: the URDF; its meshes are resolved relative to it.
        size: (width, height) of the output images, pixels.
        backend: ``"auto"`` or ``"tiny"``: PyBullet's TinyRenderer on the CPU
            (PyBullet's EGL/OpenGL path was evaluated and rejected, see
            ``docs/renders.md``).
        supersample: render this many times larger and box-filter down (1 = off).
        shadows: cast shadows (slower; see ``docs/renders.md``).

    Raises:
        FileNotFoundError: URDF or a visual mesh missing.
        ValueError: bad size / backend / supersample, URDF without visual geometry.
        RenderError: PyBullet could not load the asset.
    """

    def __init__(
        self,
        urdf_path: Path | str,
        *,
        size: tuple[int, int] = (256, 256),
        backend: str = "auto",
        supersample: int = 2,
        shadows: bool = False,
    ):
        w, h = (int(v) for v in size)
        if w < 8 or h < 8 or w > 8192 or h > 8192:
            raise ValueError(f"image size must be within 8..8192 pixels, got {size}")
        if backend not in BACKENDS:
            raise ValueError(f"unknown render backend {backend!r}; known: {BACKENDS}")
        if int(supersample) < 1 or int(supersample) > 4:
            raise ValueError(f"supersample must be 1..4, got {supersample}")
        self.size = (w, h)
        self.backend = "tiny" if backend == "auto" else backend
        self.supersample = int(supersample)
        self.shadows = bool(shadows)
        self.timings = RenderTimings()
        self.urdf_path = Path(urdf_path)
        self._viewer = None
        self._work = Path(tempfile.mkdtemp(prefix="asset2sim-render-"))
        try:
            t0 = time.perf_counter()
            self._prep = _prepare(self.urdf_path, self._work, texture_max=max(w, h) * self.supersample)
            self.notes = list(self._prep.notes)
            t1 = time.perf_counter()
            self._load()
            self.timings.prepare = t1 - t0
            self.timings.load = time.perf_counter() - t1
        except BaseException:
            self.close()
            raise

    # ---------------------------------------------------------------- setup
    def _load(self) -> None:
        try:
            self._viewer = open_viewer("pybullet", self._prep.urdf)
        except RuntimeError as exc:
            raise RenderError(f"PyBullet could not load {self.urdf_path} for rendering: {exc.__cause__ or exc}") from exc
        self._lift_dark_colors()
        self.joint_names: list[str] = list(self._viewer.joint_names)

    def _lift_dark_colors(self) -> None:
        """Raise each visual's diffuse color to at least :data:`ALBEDO_FLOOR`
        (c' = f + (1 - f) c), so black materials (Kd 0 0 0 is common in
        PartNet-Mobility) still show their shading instead of a flat silhouette."""
        f = ALBEDO_FLOOR
        if f <= 0:
            return
        for link, k, rgba in self._viewer.visual_colors():
            lifted = [f + (1 - f) * c for c in rgba[:3]] + [rgba[3]]
            self._viewer.set_visual_color(link, k, lifted)

    # ---------------------------------------------------------------- state
    def set_joint_positions(self, q: Mapping[str, float] | None) -> None:
        """Set joints (rad or m) by name; joints not named keep their position
        (initially zero). Values outside the limits are drawn as given.

        Raises:
            KeyError: a name that is not a movable joint of the URDF.
            ValueError: a non-finite value.
        """
        if not q:
            return
        for name, value in q.items():
            if name not in self.joint_names:
                raise KeyError(
                    f"{self.urdf_path}: no movable joint named {name!r}; movable joints: {self.joint_names}"
                )
            v = float(value)
            if not math.isfinite(v):
                raise ValueError(f"joint {name!r}: position {value!r} is not finite")
            self._viewer.set_joint_positions({name: v})

    def world_points(self) -> np.ndarray:
        """Visual vertices (N, 3) of all links in the base frame, m, at the current state."""
        out = []
        links = set(self._viewer.link_names)
        for lname, local in self._prep.link_points.items():
            if lname not in links:
                continue
            pos, R = self._viewer.link_frame(lname)
            out.append(local @ R.T + pos)
        return np.concatenate(out)

    # --------------------------------------------------------------- render
    def camera(self, view: str | ViewSpec) -> Camera:
        """The fitted camera of ``view`` at the current joint state.

        Raises:
            KeyError: unknown view name.
        """
        spec = _view_spec(view)
        up = (1.0, 0.0, 0.0) if spec.elevation_deg >= 89.9 else (0.0, 0.0, 1.0)
        return fit_camera(self.world_points(), spec.direction(), up=up, aspect=self.size[0] / self.size[1])

    def render(self, view: str | ViewSpec) -> np.ndarray:
        """RGB image (H, W, 3) uint8 of ``view`` at the current joint state.

        Raises:
            KeyError: unknown view name.
            RenderError: the renderer returned no image.
        """
        spec = _view_spec(view)
        t0 = time.perf_counter()
        cam = self.camera(spec)
        img = self._draw(cam)
        self.timings.views.setdefault(spec.name, []).append(time.perf_counter() - t0)
        return img

    def _draw(self, cam: Camera) -> np.ndarray:
        w, h = self.size
        s = self.supersample
        W, H = w * s, h * s
        # light from the camera's upper left, fixed relative to the camera
        b = cam.eye - cam.target
        b /= np.linalg.norm(b)
        r = np.cross(-b, cam.up)
        r /= np.linalg.norm(r)
        light = b * 1.0 + cam.up * 0.75 - r * 0.6
        light /= np.linalg.norm(light)
        dist = float(np.linalg.norm(cam.eye - cam.target))
        try:
            rgba, seg = self._viewer.draw(
                W,
                H,
                {"eye": cam.eye, "target": cam.target, "up": cam.up, "fov_deg": cam.fov_deg, "near": cam.near, "far": cam.far},
                {"direction": light, "color": (1.0, 1.0, 1.0), "distance": dist * 4, "shadow": self.shadows,
                 "ambient": AMBIENT, "diffuse": DIFFUSE, "specular": SPECULAR},
            )
        except RuntimeError as exc:
            raise RenderError(f"{self.urdf_path}: {exc}") from exc
        alpha = (seg >= 0).astype(np.float32)
        rgb = rgba[:, :, :3].astype(np.float32)
        bg = np.asarray(BACKGROUND, np.float32)
        comp = rgb * alpha[..., None] + bg * (1.0 - alpha[..., None])
        if s > 1:
            comp = comp.reshape(h, s, w, s, 3).mean(axis=(1, 3))
        return np.clip(np.rint(comp), 0, 255).astype(np.uint8)

    # -------------------------------------------------------------- cleanup
    def close(self) -> None:
        """Disconnect from PyBullet and delete the temporary files."""
        if self._viewer is not None:
            self._viewer.close()
            self._viewer = None
        if self._work is not None:
            shutil.rmtree(self._work, ignore_errors=True)
            self._work = None

    def __enter__(self) -> "SceneRenderer":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def __del__(self):  # pragma: no cover - best effort
        try:
            self.close()
        except Exception:
            pass


def _view_spec(view: str | ViewSpec) -> ViewSpec:
    if isinstance(view, ViewSpec):
        return view
    try:
        return VIEWS[view]
    except KeyError:
        raise KeyError(f"unknown view {view!r}; known views: {list(VIEWS)}") from None


# ---------------------------------------------------------------- public API
def render_views(
    urdf_path: Path | str,
    joint_positions: Mapping[str, float] | None = None,
    out_dir: Path | str | None = None,
    *,
    views: Iterable[str] = DEFAULT_VIEWS,
    size: tuple[int, int] = (256, 256),
    backend: str = "auto",
    supersample: int = 2,
    shadows: bool = False,
) -> dict[str, np.ndarray]:
    """Render ``views`` of the object at ``joint_positions``.

    Args:
        urdf_path: the URDF (meshes resolved relative to it).
        joint_positions: joint name -> position, rad (revolute/continuous) or m
            (prismatic); joints not named stay at zero. ``None``: all zero.
        out_dir: when given, each view is also written (atomically) to
            ``out_dir/<view>.png``.
        views: names from :data:`VIEWS` (default the five of the SPEC).
        size: (width, height) in pixels.
        backend: ``"auto"`` or ``"tiny"`` (see :class:`SceneRenderer`).
        supersample, shadows: see :class:`SceneRenderer`.

    Returns:
        view name -> RGB image, uint8 array of shape (height, width, 3), in the
        order of ``views``.

    Raises:
        FileNotFoundError: the URDF or one of its visual meshes is missing.
        KeyError: an unknown view or joint name.
        ValueError: a bad size, backend, joint value or a URDF without visuals.
        RenderError: PyBullet failed to load or draw the asset.
        OSError: ``out_dir`` cannot be written.
    """
    views = list(views)
    for v in views:
        _view_spec(v)
    images: dict[str, np.ndarray] = {}
    with SceneRenderer(urdf_path, size=size, backend=backend, supersample=supersample, shadows=shadows) as r:
        r.set_joint_positions(joint_positions)
        for v in views:
            images[v] = r.render(v)
    if out_dir is not None:
        for v, img in images.items():
            write_png(Path(out_dir) / f"{v}.png", img)
    return images


def write_png(path: Path | str, image: np.ndarray) -> Path:
    """Write an RGB(A) uint8 image (H, W, 3|4) as PNG, atomically. Returns the path."""
    import io

    from PIL import Image

    buf = io.BytesIO()
    Image.fromarray(np.ascontiguousarray(image)).save(buf, format="PNG", optimize=False)
    return write_bytes(path, buf.getvalue())


def render_contact_sheet(
    images: Mapping[str, np.ndarray],
    *,
    columns: int | None = None,
    title: str | None = None,
) -> np.ndarray:
    """One RGB image (H, W, 3) uint8 with every view in a grid, each labelled
    with its name above it (and an optional ``title`` line on top).

    ``columns`` defaults to all views in one row up to 3, else ceil(n / 2)
    columns (5 views -> 3 + 2). Views of different sizes are padded to the
    largest.

    Raises:
        ValueError: no images, or an image that is not (H, W, 3|4) uint8.
    """
    from PIL import Image, ImageDraw

    if not images:
        raise ValueError("render_contact_sheet needs at least one image")
    arrays = {}
    for name, img in images.items():
        a = np.asarray(img)
        if a.dtype != np.uint8 or a.ndim != 3 or a.shape[2] not in (3, 4):
            raise ValueError(f"view {name!r}: expected a (H, W, 3) uint8 image, got {a.dtype} {a.shape}")
        arrays[name] = a[:, :, :3]
    n = len(arrays)
    cols = int(columns) if columns else (n if n <= 3 else math.ceil(n / 2))
    cols = max(1, min(cols, n))
    rows = math.ceil(n / cols)
    tw = max(a.shape[1] for a in arrays.values())
    th = max(a.shape[0] for a in arrays.values())
    font = _font(max(11, tw // 16))
    label_h = _text_height(font) + 8
    title_h = label_h + 4 if title else 0
    pad = 4
    W = cols * tw + (cols + 1) * pad
    H = title_h + rows * (th + label_h) + (rows + 1) * pad
    sheet = Image.new("RGB", (W, H), (255, 255, 255))
    draw = ImageDraw.Draw(sheet)
    if title:
        draw.text((pad + 2, pad), title, fill=(20, 20, 20), font=font)
    for k, (name, a) in enumerate(arrays.items()):
        i, j = divmod(k, cols)
        x0 = pad + j * (tw + pad)
        y0 = title_h + pad + i * (th + label_h + pad)
        draw.text((x0 + 2, y0 + 3), name, fill=(30, 30, 30), font=font)
        tile = Image.new("RGB", (tw, th), BACKGROUND)
        tile.paste(Image.fromarray(a), ((tw - a.shape[1]) // 2, (th - a.shape[0]) // 2))
        sheet.paste(tile, (x0, y0 + label_h))
    return np.asarray(sheet, dtype=np.uint8)


def _font(size: int):
    from PIL import ImageFont

    try:
        return ImageFont.load_default(size=size)
    except TypeError:  # Pillow without FreeType sizes
        return ImageFont.load_default()


def _text_height(font) -> int:
    try:
        box = font.getbbox("Ag")
        return int(box[3] - box[1]) + 2
    except Exception:  # pragma: no cover
        return 12
