"""URDFs whose meshes the simulators cannot load (GLB / glTF and PLY, as generated assets ship them: procedural
generators, image-to-articulation systems), staged like MJCF and USD inputs (:mod:`.staged`): every mesh read
(through :func:`asset2sim.mesh_io.read_mesh`, trimesh for these formats; a glTF scene's nodes placed and joined,
its coordinates taken as the URDF's, as trimesh and yourdfpy read them) and written as OBJ, the URDF otherwise
unchanged. Textures are not carried (visuals keep their URDF colours)."""

from __future__ import annotations

from pathlib import Path

from asset2sim import mesh_io
from asset2sim.formats.staging import ReadAsset, StagingError, mesh_name
from asset2sim.urdf import UrdfError, read_urdf

__all__ = ["CONVERTED_SUFFIXES", "read_urdf_converting", "urdf_needing_conversion"]

#: Mesh formats a URDF may name that the simulators' URDF loaders do not read (PyBullet: .obj, .stl, .dae).
CONVERTED_SUFFIXES = (".glb", ".gltf", ".ply")


def _urdf_of(asset: Path) -> Path | None:
    if asset.is_file():
        return asset if asset.suffix.lower() == ".urdf" else None
    if (asset / "mobility.urdf").is_file():
        return asset / "mobility.urdf"
    found = sorted(asset.glob("*.urdf"))
    return found[0] if len(found) == 1 else None


def urdf_needing_conversion(asset: Path | str) -> Path | None:
    """The URDF of ``asset`` (a ``.urdf`` file, a folder with ``mobility.urdf`` or one ``*.urdf``) when it names a mesh
    of :data:`CONVERTED_SUFFIXES`; else None (also when the URDF cannot be read: validation reports on it)."""
    urdf = _urdf_of(Path(asset))
    if urdf is None:
        return None
    try:
        model = read_urdf(urdf, mode="lenient")
    except (UrdfError, OSError):
        return None
    names = [g.filename or "" for ln in model.links.values() for g in (*ln.visuals, *ln.collisions) if g.kind == "mesh"]
    return urdf if any(n.lower().endswith(CONVERTED_SUFFIXES) for n in names) else None


def read_urdf_converting(urdf: Path | str) -> ReadAsset:
    """The URDF at ``urdf`` with every mesh read into ``meshes`` (``meshes/<stem>.obj``; format ``"urdf"``).

    Raises:
        StagingError: the URDF or a mesh cannot be read, or a mesh lies outside the URDF's folder (names the
            link and file).
    """
    urdf = Path(urdf)
    try:
        model = read_urdf(urdf, mode="lenient")
    except (UrdfError, OSError) as exc:
        raise StagingError(f"{urdf}: {exc}") from exc
    root = urdf.parent.resolve()
    meshes, names, used, converted = {}, {}, set(), set()
    for link in model.links.values():
        for g in (*link.visuals, *link.collisions):
            if g.kind != "mesh":
                continue
            if g.path is None or not g.path.resolve().is_relative_to(root):
                raise StagingError(f"{urdf}: link {link.name!r}: mesh {g.filename!r} is not a file inside {root}")
            key = g.path.resolve()
            if key not in names:
                try:
                    mesh = mesh_io.read_mesh(key)
                except mesh_io.MeshReadError as exc:
                    raise StagingError(f"{urdf}: link {link.name!r}: {exc}") from exc
                names[key] = mesh_name(key.stem, used)
                meshes[names[key]] = (mesh.vertices, mesh.faces)
                if key.suffix.lower() in CONVERTED_SUFFIXES:
                    converted.add(key.suffix.lower())
            g.filename, g.path = names[key], None
            if g.material is not None:
                g.material.texture = None
    notes = (f"meshes in {', '.join(sorted(converted))} read with trimesh and written as OBJ (textures not carried)",)
    return ReadAsset(source=urdf, format="urdf", model=model, meshes=meshes, notes=notes, files=(urdf, *sorted(names)))
