"""Mesh files made drawable by PyBullet's renderer, written into a work folder (inputs are never
written): OBJs split per material (:func:`split_obj`), material-less faces colored
(:func:`colored_obj`), large textures downscaled (:class:`TextureLinks`), other formats converted
(:func:`convert_other_mesh`). Used by :mod:`asset2sim.tasks.geometry.render_scene`.
"""

from __future__ import annotations

import hashlib
import shutil
import threading
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

import cachetools
import numpy as np

from asset2sim import mesh_io

#: RGBA of mesh faces with neither an MTL material nor a URDF ``<material>``.
DEFAULT_COLOR: tuple[float, float, float, float] = (0.8, 0.8, 0.8, 1.0)


@dataclass
class DrawableMesh:
    """What the renderer needs from one mesh file: ``vertices`` (N, 3) in the file's units, ``parts``
    files that carry their own material, ``bare`` a file of the faces without a known material (or
    ``bare_text``, its contents still to be written per color)."""

    vertices: np.ndarray
    parts: list[Path]
    bare: Path | None = None
    bare_text: str | None = None


class TextureLinks:
    """Texture files made reachable from the work folder by a relative name (PyBullet takes no absolute
    texture paths); those larger than ``max_side`` pixels downscaled (area filter), others linked."""

    def __init__(self, work: Path, max_side: int):
        self.folder = work / "textures"
        self.max_side = max_side
        self._done: dict[Path, tuple[str, bool]] = {}
        self.downscaled = 0

    def link(self, tex: Path) -> tuple[str, bool]:
        """(name relative to the work folder, whether the texture was downscaled)."""
        if tex in self._done:
            return self._done[tex]
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


def read_mtl(path: Path, textures: TextureLinks) -> tuple[dict[str, list[str]], bool]:
    """(material name -> its lines with textures linked into the work folder, whether a texture was
    downscaled); missing textures dropped, an unreadable MTL gives none."""
    changed = False
    try:
        text = path.read_text(encoding="utf-8", errors="replace")
    except OSError:
        return {}, changed
    mats: dict[str, list[str]] = {}
    for material, lines in mesh_io.read_mtl(text).items():
        current = mats.setdefault(material, [])
        for line in lines:
            key = line.split(maxsplit=1)[0]
            if not mesh_io.is_texture_statement(key):
                current.append(line)
                continue
            tokens = line.split()
            tex = (path.parent / tokens[-1]).resolve()
            if len(tokens) < 2 or not tex.is_file():
                continue
            name, resized = textures.link(tex)
            changed |= resized
            current.append(" ".join(tokens[:-1] + [name]))
    return mats, changed


def split_obj(path: Path, work: Path, tag: str, textures: TextureLinks) -> DrawableMesh:
    """The OBJ ``path`` made drawable with its materials: PyBullet draws one material per OBJ, so a file
    with several (or downscaled textures) is written again as one OBJ (+ MTL) per material into
    ``work`` (names start with ``tag``), each with all vertex data; faces without a known material go
    to :attr:`DrawableMesh.bare_text`."""
    scan, vertices = _scanned(path.read_text(encoding="utf-8", errors="replace"))
    data_lines, faces, mtllibs = scan.data_lines, scan.faces, scan.mtllibs
    materials: dict[str, list[str]] = {}
    downscaled = False
    for lib in mtllibs:
        mats, changed = read_mtl(path.parent / lib, textures)
        downscaled |= changed
        for name, lines in mats.items():
            materials.setdefault(name, lines)
    known = [m for m in faces if m is not None and m in materials]
    unknown = [m for m in faces if m is None or m not in materials]
    if len(known) == 1 and not unknown and not downscaled:
        return DrawableMesh(vertices, [path])
    if not known and not mtllibs and list(faces) in ([None], []):
        return DrawableMesh(vertices, [], bare=path if faces else None)
    header = "\n".join(data_lines)
    parts = []
    for k, mat in enumerate(known):
        stem = f"{tag}_{k}"
        (work / f"{stem}.mtl").write_text(f"newmtl {mat}\n" + "\n".join(materials[mat]) + "\n", encoding="utf-8")
        body = "\n".join([f"mtllib {stem}.mtl", header, f"usemtl {mat}", *faces[mat]]) + "\n"
        out = work / f"{stem}.obj"
        out.write_text(body, encoding="utf-8")
        parts.append(out)
    bare_text = "\n".join([header, *(f for m in unknown for f in faces[m])]) + "\n" if unknown else None
    return DrawableMesh(vertices, parts, bare_text=bare_text)


def _scan_size(hit: tuple[mesh_io.ObjText, np.ndarray, int]) -> int:
    """The characters of the OBJ text a :data:`_SCANS` entry was scanned from."""
    return hit[2]


#: OBJ texts scanned in this process (:func:`_scanned`), by SHA-1 of the text: a refine draws the same visual
#: files in several scenes (the input's, its output's copies, the clips); at most 32 M characters kept, the oldest
#: dropped first (a scan takes about 2.7 bytes per character: 9912's 16 M characters of OBJ, 42 MiB).
_SCANS: cachetools.FIFOCache = cachetools.FIFOCache(maxsize=32_000_000, getsizeof=_scan_size)
_SCANS_LOCK = threading.Lock()


def _scanned(text: str) -> tuple[mesh_io.ObjText, np.ndarray]:
    """(:func:`mesh_io.scan_obj_text` of OBJ ``text``, its vertices (N, 3), read-only), remembered by the text's
    SHA-1 (the oldest dropped beyond :data:`_SCANS`' size in characters). The scan is shared: callers must not change
    it."""
    key = hashlib.sha1(text.encode("utf-8", "surrogatepass")).digest()
    with _SCANS_LOCK:
        hit = _SCANS.get(key)
    if hit is None:
        scan = mesh_io.scan_obj_text(text)
        vertices = mesh_io.parse_vertex_lines(scan.vertex_lines)
        vertices.setflags(write=False)
        hit = (scan, vertices, len(text))
        with _SCANS_LOCK:
            if len(text) <= _SCANS.maxsize:
                _SCANS[key] = hit
    return hit[0], hit[1]


def colored_obj(info: DrawableMesh, source: Path, rgba: Sequence[float], work: Path, tag: str) -> Path:
    """An OBJ of ``info``'s material-less faces with one material of color ``rgba`` (PyBullet draws them
    black otherwise)."""
    text = info.bare_text
    if text is None:
        lines = source.read_text(encoding="utf-8", errors="replace").splitlines()
        text = "\n".join(ln for ln in lines if not ln.startswith(("mtllib", "usemtl"))) + "\n"
    r, g, b = (min(1.0, max(0.0, float(c))) for c in rgba[:3])
    (work / f"{tag}.mtl").write_text(f"newmtl color\nKd {r:.4f} {g:.4f} {b:.4f}\n", encoding="utf-8")
    out = work / f"{tag}.obj"
    out.write_text(f"mtllib {tag}.mtl\nusemtl color\n" + text, encoding="utf-8")
    return out


def convert_other_mesh(mesh_file: Path, work: Path, tag: str, notes: list[str]) -> DrawableMesh:
    """A non-OBJ visual mesh: STL as is; other formats converted to OBJ with trimesh (geometry only).

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
        return DrawableMesh(verts, [mesh_file])
    out = work / f"{tag}.obj"
    out.write_text(trimesh.exchange.obj.export_obj(mesh, include_normals=True, include_color=False,
                                                   include_texture=False), encoding="utf-8")
    notes.append(f"{mesh_file.name}: converted to OBJ (its own colors and textures are not drawn)")
    return DrawableMesh(verts, [], bare=out)
