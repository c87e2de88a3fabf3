"""The mesh checks of the validator (:class:`MeshChecks`): mesh references and contents (each file
scanned once), the link flatness rule, the face caps, MTL libraries and texture maps; the bounding
boxes of geometry at the zero pose and the texture caps.
"""

from __future__ import annotations

import math
import os
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from PIL import Image, UnidentifiedImageError

from asset2sim import atomic, mesh_materials
from asset2sim.tasks.ingest.findings import MeshUse, Recorder, asset_size_range
from asset2sim.tasks.ingest.mesh_paths import MeshReference, file_kind, read_regular, resolve_mesh_reference
from asset2sim.tasks.ingest import urdf_meshes
from asset2sim.tasks.ingest.mesh_scan import MeshScan, is_flat, scan_mesh_file
from asset2sim.urdf import UrdfGeometry, UrdfLink, UrdfModel

__all__ = ["MeshChecks", "box_corners", "geometry_corners", "texture_problem", "zero_pose_bounds"]


def box_corners(lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """The 8 corners (8, 3) of the axis-aligned box [lo, hi]."""
    return np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])], float)


def geometry_corners(g: UrdfGeometry, bounds: np.ndarray | None = None) -> np.ndarray | None:
    """Corners (8, 3) of a geometry's bounding box in its link's frame (file units; scale and origin
    applied), or None when unknown; ``bounds``: (2, 3) corners of a mesh's vertices at scale 1."""
    if not g.complete:
        return None
    if g.kind == "mesh":
        if bounds is None:
            return None
        c = box_corners(bounds[0], bounds[1]) * g.scale
    elif g.kind == "box" and g.size is not None or g.kind in ("cylinder", "sphere") and g.radius is not None:
        r = g.radius
        h = np.array(g.size if g.kind == "box" else (2 * r, 2 * r, g.length if g.kind == "cylinder" else 2 * r), float) / 2.0
        c = box_corners(-h, h)
    else:
        return None
    return c @ g.origin[:3, :3].T + g.origin[:3, 3]


def zero_pose_bounds(model: UrdfModel, root: str | None, mesh_bounds: dict[int, np.ndarray]) -> np.ndarray | None:
    """Lower and upper corner (2, 3) of the box bounding every geometry at the zero configuration (file
    units, root link frame; ``mesh_bounds`` by ``id`` of the geometry). None when the tree is broken,
    some size is unknown or there is no geometry."""
    if root is None:
        return None
    by_parent: dict[str, list] = {}
    for j in model.joints:
        if j.parent and j.child:
            by_parent.setdefault(j.parent, []).append(j)
    geoms = {ln.name: ln.visuals + ln.collisions for ln in model.link_elements if ln.name}
    pts: list[np.ndarray] = []
    stack = [(root, np.eye(4))]
    seen: set[str] = set()
    with np.errstate(over="ignore", invalid="ignore"):
        while stack:
            name, T = stack.pop()
            if name in seen:
                return None
            seen.add(name)
            for g in geoms.get(name, []):
                c = geometry_corners(g, mesh_bounds.get(id(g)))
                if c is None:
                    if g.kind is not None:
                        return None  # a size is unknown: no claim about the object's size
                    continue
                pts.append(c @ T[:3, :3].T + T[:3, 3])
            stack.extend((j.child, T @ j.origin) for j in by_parent.get(name, []))
        if not pts:
            return None
        allp = np.vstack(pts)
        return np.stack([allp.min(axis=0), allp.max(axis=0)])


@dataclass(frozen=True, slots=True)
class TextureHeader:
    """What a texture map's header says (:func:`texture_header`): the file's ``size`` (bytes), its ``width`` and
    ``height`` (pixels; -1 when the file was too large to open)."""

    size: int
    width: int
    height: int


def texture_header(path: Path, max_bytes: int) -> TextureHeader:
    """The file size and pixel size of a texture map from the image header, nothing decoded; a file above
    ``max_bytes`` is not opened (width and height -1).

    Raises:
        OSError: it cannot be inspected or is not a regular file.
        ValueError: PIL cannot identify it as an image.
        PIL.Image.DecompressionBombError: the header claims more than twice PIL's pixel limit.
    """
    size = os.stat(path).st_size
    if size > max_bytes:
        return TextureHeader(size, -1, -1)
    with atomic.open_regular(path) as fh, warnings.catch_warnings():
        warnings.simplefilter("ignore", Image.DecompressionBombWarning)
        try:
            with Image.open(fh) as im:
                w, h = im.size
        except (UnidentifiedImageError, SyntaxError) as exc:
            raise ValueError(f"{type(exc).__name__}: {str(exc)[:160]}") from exc
    return TextureHeader(size, int(w), int(h))


def texture_problem(path: Path, max_bytes: int, max_pixels: int) -> tuple[str, str] | None:
    """Why a texture map cannot be loaded safely, (``TEXTURE_TOO_LARGE`` or ``TEXTURE_UNREADABLE``,
    message); None when it can."""
    try:
        header = texture_header(path, max_bytes)
    except Image.DecompressionBombError as exc:
        return "TEXTURE_TOO_LARGE", f"{exc}".split(",")[0] + f" (cap {max_pixels} pixels)"
    except OSError as exc:
        return "TEXTURE_UNREADABLE", f"cannot be opened as a regular file ({exc.strerror or exc})"
    except ValueError as exc:
        return "TEXTURE_UNREADABLE", f"not an image the simulator can load ({exc})"
    size, w, h = header.size, header.width, header.height
    if size > max_bytes:
        return "TEXTURE_TOO_LARGE", f"{size} bytes > cap {max_bytes} (PyBullet reads the whole file, twice over)"
    if w * h > max_pixels:
        return "TEXTURE_TOO_LARGE", f"{w} x {h} = {w * h} pixels > cap {max_pixels} (PyBullet decodes it at every load)"
    return None


class MeshChecks(Recorder):
    """Mesh references, contents and materials (mixin of the validator)."""

    def __init__(self, asset: Path, policy):
        super().__init__(asset, policy)
        # (2, 3) vertex bounds (file units, scale 1) of each scanned mesh geometry, by id of its UrdfGeometry
        self.mesh_bounds: dict[int, np.ndarray] = {}
        self._textures_seen: set[Path] = set()
        self._texture_totals = [0, 0]  # bytes, pixels of the accepted texture maps

    def asset_size(self, box: np.ndarray | None) -> None:
        """``ASSET_SIZE_IMPLAUSIBLE`` when the object's size g = sqrt(e1 * e2) (``box``: :func:`zero_pose_bounds`)
        is not finite or outside the policy's :func:`asset_size_range`; skipped when unknown (None)."""
        if box is None:
            return
        lo, hi = self.policy.asset_size_range or asset_size_range()
        with np.errstate(over="ignore", invalid="ignore"):
            ext = np.sort(box[1] - box[0])[::-1]
            g = float(math.sqrt(ext[0]) * math.sqrt(ext[1])) if np.isfinite(ext).all() else math.inf
        if not (lo <= g <= hi):
            self.add("ASSET_SIZE_IMPLAUSIBLE",
                     f"the object measures {np.array2string(ext, precision=3)} file units (bounding box of all geometry at the "
                     f"zero pose; size sqrt(e1 e2) = {g:.3g}): refine scales it to a household size with one factor in "
                     f"the overlay's range, which needs a size within [{lo:.3g}, {hi:.3g}]; check the units of the "
                     "meshes and of the mesh scale", size=g, extents=[float(x) for x in ext], size_range=[lo, hi])

    def meshes(self, links: list[UrdfLink]) -> None:
        """Resolve, scan and check every ``<mesh>`` of ``links``; record ``mesh_paths``,
        ``material_files`` and ``mesh_bounds``."""
        assert self.folder is not None
        pol = self.policy
        scans: dict[Path, MeshScan | str] = {}
        total_faces = built_faces = references = 0
        for ln in links:
            lname = ln.name or None
            geoms = [("visual", g) for g in ln.visuals] + [("collision", g) for g in ln.collisions]
            mass_role = "collision" if ln.collisions else "visual"
            link_moments, link_has_volume = None, False
            for role, g in geoms:
                use: MeshUse = "collision" if role == "collision" else ("mass" if mass_role == "visual" else "visual")
                in_mass = role == mass_role
                if g.kind != "mesh":
                    link_has_volume = link_has_volume or (g.kind is not None and in_mass and g.complete)
                    continue
                ref = resolve_mesh_reference(self.folder, g.filename, extensions=pol.mesh_extensions, max_bytes=pol.max_mesh_bytes)
                fname = g.filename or ""
                if ref.code is not None:
                    self.add(ref.code, f"<{role}> mesh {ref.message}", line=g.line, link=lname, role=role, filename=fname)
                    continue
                assert ref.path is not None
                fmt = self._format_problem(fname, ref.path)
                if fmt is not None:
                    self.add("MESH_FORMAT_UNSUPPORTED", f"<{role}> mesh {fname!r}: {fmt}", line=g.line, link=lname,
                             role=role, filename=fname)
                    continue
                self.result.mesh_paths[fname] = ref.path
                if not pol.check_mesh_contents:
                    continue
                scan = scans.get(ref.path)
                if scan is None:
                    try:
                        scan = scan_mesh_file(ref.path, max_bytes=pol.max_mesh_bytes, max_faces=pol.max_mesh_faces,
                                              max_coordinate=pol.max_coordinate)
                    except OSError as exc:
                        scan = f"cannot read: {exc}"
                    scans[ref.path] = scan
                    if isinstance(scan, MeshScan):
                        total_faces += scan.n_faces
                        # the OBJ's own folder as the operating system (and PyBullet) sees it
                        as_written = os.path.dirname(os.path.join(os.path.abspath(str(self.folder)), fname))
                        self.materials(ref.path, Path(as_written), scan, lname)
                frel = self.rel(ref.path)
                at = f"{self.urdf_rel}:{g.line}"
                if isinstance(scan, str):
                    self.add("MESH_UNREADABLE", f"{scan} (referenced at {at})", file=frel, link=lname, role=role, urdf_line=g.line)
                    continue
                built_faces += scan.n_faces  # every reference: the simulators build each
                references += 1
                if scan.bounds is not None:
                    self.mesh_bounds[id(g)] = scan.bounds
                for code, msg in scan.defects.items():
                    flat = code == "MESH_ZERO_VOLUME"
                    self.add(code, f"{msg}{'' if flat else f'; used for {use}'} (<{role}> at {at})", file=frel, link=lname,
                             use=None if flat else use, role=role, urdf_line=g.line)
                if in_mass and g.complete and scan.moments is not None:
                    # the moments of A x + t, A = R diag(scale), (R, t) the origin
                    n, s1, s2 = scan.moments
                    a, t = g.origin[:3, :3] @ np.diag(g.scale), g.origin[:3, 3]
                    with np.errstate(over="ignore", invalid="ignore"):  # huge scales or origins: non-finite, see is_flat
                        as1 = a @ s1
                        mom = n, as1 + n * t, a @ s2 @ a.T + np.outer(as1, t) + np.outer(t, as1) + n * np.outer(t, t)
                    link_moments = mom if link_moments is None else tuple(a + b for a, b in zip(link_moments, mom))
            if not link_has_volume and link_moments is not None and is_flat(*link_moments):
                self.add("LINK_ZERO_VOLUME", f"all {mass_role} geometry of the link lies in one plane: zero volume; "
                         "mass must come from the surface area (shell), not the volume",
                         line=ln.line, link=lname, action="mass_from_area", role=mass_role)
        # the per-asset texture caps, over every distinct texture map
        size, pixels = self._texture_totals
        if size > pol.max_total_texture_bytes or pixels > pol.max_total_texture_pixels:
            self.add("TEXTURE_TOO_LARGE", f"the textures of the asset total {size} bytes and {pixels} pixels > caps "
                     f"{pol.max_total_texture_bytes} bytes, {pol.max_total_texture_pixels} pixels (PyBullet loads them all; "
                     "docs/design/validation.md, Texture caps)", total_bytes=size, total_pixels=pixels)
        if total_faces > pol.max_total_faces:
            self.add("MESH_TOO_MANY_FACES", f"{total_faces} triangles over all meshes > cap {pol.max_total_faces} "
                     "(the bound that keeps one asset's refine within the flow's time and memory limits; docs/design/validation.md)",
                     file=self.urdf_rel, total_faces=total_faces, cap=pol.max_total_faces)
        elif built_faces > pol.max_built_faces:
            self.add("MESH_TOO_MANY_FACES", f"{built_faces} triangles as the simulators build them ({references} <mesh> references, "
                     f"a file named twice counted twice) > cap {pol.max_built_faces} (docs/design/validation.md)",
                     file=self.urdf_rel, built_faces=built_faces, references=references, cap=pol.max_built_faces)

    def _format_problem(self, fname: str, real: Path) -> str | None:
        """Why refine cannot load this mesh file (None: it can): the suffix as written (PyBullet's choice)
        and the real file's must be the same format of ``policy.simulator_mesh_extensions``, or both GLB, glTF
        or PLY (:data:`~asset2sim.tasks.ingest.urdf_meshes.CONVERTED_SUFFIXES`: converted to OBJ first)."""
        written, actual = os.path.splitext(fname)[1].lower(), real.suffix.lower()
        if written == actual and written in urdf_meshes.CONVERTED_SUFFIXES:  # staged as OBJ before refine loads it
            return None
        allowed = self.policy.simulator_mesh_extensions
        if written not in allowed or actual not in allowed:
            bad = written if written not in allowed else actual
            return (f"{bad} meshes cannot be loaded by refine's simulator (PyBullet reads "
                    f"{', '.join(sorted(allowed))}); convert it, e.g. trimesh.load(path).export('mesh.obj')")
        if written != actual:
            return f"the name ends in {written} but it is a symlink to a {actual} file; the simulator would misread it"
        return None

    def materials(self, mesh: Path, mesh_dir: Path, scan: MeshScan, link: str | None) -> None:
        """The ``mtllib`` files of an OBJ (relative to ``mesh_dir``, its folder as written) and their
        texture maps; a library found only beside the real file of a symlinked OBJ is used from there
        (``MESH_MATERIAL_BESIDE_TARGET``), and the texture caps on each texture map."""
        assert self.folder is not None
        pol = self.policy
        for name in scan.mtllibs:
            ref = resolve_mesh_reference(self.folder, name, base=mesh_dir, extensions=(), max_bytes=pol.max_mesh_bytes)
            lib_dir = mesh_dir
            if ref.code == "MESH_NOT_FOUND" and os.path.realpath(mesh_dir) != str(mesh.parent):
                beside = resolve_mesh_reference(self.folder, name, base=mesh.parent, extensions=(), max_bytes=pol.max_mesh_bytes)
                if beside.code is None:
                    assert beside.path is not None
                    self.add("MESH_MATERIAL_BESIDE_TARGET",
                             f"a mesh in {self.rel(mesh_dir)}/ is a symlink to {self.rel(mesh)}, whose mtllib {name!r} is not in "
                             f"{self.rel(mesh_dir)}/ but beside the real file ({self.rel(beside.path)}): a simulator loading the "
                             "input draws the mesh without its material; the output copies it (and its textures) beside "
                             "the copied mesh", file=self.rel(mesh), link=link, mtllib=name, found=self.rel(beside.path))
                    ref, lib_dir = beside, mesh.parent
            if not self._material_ref(ref, lib_dir, mesh, link):
                continue
            assert ref.path is not None
            try:
                data = read_regular(ref.path, pol.max_mesh_bytes, follow_links=False)
            except OSError:
                continue
            mtl_dir, owner = Path(os.path.dirname(os.path.join(str(lib_dir), name))), self.rel(ref.path)
            for tname in mesh_materials.mtl_texture_maps(data):
                tex = resolve_mesh_reference(self.folder, tname, base=mtl_dir, extensions=())
                # the texture caps on each texture map, each real file once
                if not self._material_ref(tex, mtl_dir, ref.path, link) or tex.path in self._textures_seen:
                    continue
                self._textures_seen.add(tex.path)
                problem = texture_problem(tex.path, pol.max_texture_bytes, pol.max_texture_pixels)
                if problem is not None:
                    self.add(problem[0], f"{owner} refers to texture {tname!r}: {problem[1]}", file=self.rel(tex.path), link=link,
                             referenced_by=owner)
                    continue
                header = texture_header(tex.path, pol.max_texture_bytes)
                self._texture_totals[0] += header.size
                self._texture_totals[1] += header.width * header.height

    def _material_ref(self, ref: MeshReference, base: Path, owner: Path, link: str | None) -> bool:
        """Record one MTL or texture reference; True when it is a usable file inside the folder."""
        orel = self.rel(owner)
        if ref.code is None:
            assert ref.path is not None
            if ref.path not in self.result.material_files:
                self.result.material_files.append(ref.path)
            return True
        kind = file_kind(ref.filename, base)
        if kind is not None:  # a FIFO blocks PyBullet's reader forever; a device streams without end
            self.add("MATERIAL_NOT_REGULAR_FILE", f"{orel} refers to {ref.filename!r}, a {kind}: reading it would block "
                     "or never end", file=orel, link=link, kind=kind)
        elif ref.code == "MESH_NOT_FOUND":
            self.add("MESH_MATERIAL_MISSING", f"{orel} refers to {ref.filename!r}, which does not exist", file=orel, link=link)
        else:
            self.add("MESH_MATERIAL_OUTSIDE", f"{orel} refers to {ref.filename!r}: {ref.message}; it is ignored "
                     "(not copied; the statement is dropped from the output's copy)",
                     file=orel, link=link, reason=ref.code)
        return False
