"""Writer: the output folder of the SPEC's contract.

``mobility.urdf`` with the scale baked in (mesh ``scale`` attributes, joint and
geometry origins, primitive sizes, prismatic limits, inertials), an
``<inertial>`` on every link (mass > 0, valid inertia tensor, COM origin),
``<dynamics damping friction>`` on every movable joint, a comment pointing to
``initial_state.json`` / ``overlay.json``; ``semantics.txt`` with the input's
part labels (PartNet-Mobility's format, link names unchanged) when it had
any, so the output names its parts without the input beside it; meshes (with their MTL files and
textures) copied inside the folder under the same relative paths. Floats are
written at full precision (Python's shortest round-trip repr). Every file is
written atomically; the input folder is never written.
"""

from __future__ import annotations

import hashlib
import json
import os
import threading
from collections import OrderedDict
from dataclasses import dataclass, field
from pathlib import Path, PurePosixPath

import numpy as np

from asset2sim import atomic, frames, mesh_io, urdf
from asset2sim.schemas.asset import AssetDescription
from asset2sim.schemas.overlay import Overlay, RootMount
from asset2sim.tasks.ingest import partnet_mobility
from asset2sim.tasks.assemble import collision_geometry
from asset2sim.output_folder import (
    EVALUATION_NAME,
    MARKER_NAME,
    OVERLAY_NAME,
    RECORD_NAME,
    REPORT_HTML_NAME,
    REPORT_NAME,
    STATE_NAME,
    URDF_NAME,
    OutputError,
    check_location,
)

SEMANTICS_NAME = partnet_mobility.SEMANTICS_NAME


@dataclass
class OutputPaths:
    """Files of one output folder."""

    root: Path
    urdf: Path
    initial_state: Path
    overlay: Path
    semantics: Path | None = None
    """``semantics.txt``, None when the input had no part labels."""
    collision_notes: list[str] = field(default_factory=list)
    """What the writer's convex collision pieces changed
    (:func:`asset2sim.tasks.assemble.collision_geometry.link_pieces`' notes)."""


def check_output_folder(asset: AssetDescription, out_dir: Path) -> Path:
    """Resolve ``out_dir`` (symlinks followed) and refuse the input folder,
    anything inside it, a folder containing it and a path that is not a
    folder (:func:`asset2sim.output_folder.check_location`).

    Raises:
        OutputError: with ``code`` OUTPUT_IS_INPUT, OUTPUT_INSIDE_INPUT,
            OUTPUT_CONTAINS_INPUT or OUTPUT_NOT_A_FOLDER and the ``path``.
    """
    return check_location(asset.source_dir, out_dir)


def _inside(path: Path, root: Path, *, resolved: bool = False) -> bool:
    """True when ``path`` lies inside ``root`` after resolving symlinks
    (``resolved``: both are resolved already)."""
    try:
        (path if resolved else path.resolve()).relative_to(root if resolved else root.resolve())
        return True
    except ValueError:
        return False


def mesh_dependencies(mesh_path: Path, asset_root: Path) -> list[Path]:
    """Files an OBJ mesh needs besides itself (MTL libraries and their texture
    maps), as absolute paths inside ``asset_root``; missing or outside files are
    skipped (visual only). Parsing: :func:`asset2sim.mesh_io.obj_material_files`."""
    return mesh_io.obj_material_files(mesh_path, keep=lambda p: _inside(p, asset_root))


#: output paths a copied input file may not take (the contract's own files)
RESERVED_NAMES = frozenset({URDF_NAME, STATE_NAME, OVERLAY_NAME, REPORT_NAME, REPORT_HTML_NAME, EVALUATION_NAME, MARKER_NAME, RECORD_NAME})


def _reference_dirs(filename: str) -> list[str]:
    """Folders (relative POSIX paths) that must exist in the output for the
    path ``filename`` as written to open there: every folder the path walks
    through, also those it leaves again with ``..`` (``dir/../m.obj`` needs
    ``dir``)."""
    out: list[str] = []
    cur: list[str] = []
    for part in PurePosixPath(filename).parts[:-1]:
        if part in ("", "."):
            continue
        if part == "..":
            if cur:
                cur.pop()
            continue
        cur.append(part)
        out.append("/".join(cur))
    return out


#: Results of :func:`mesh_copies` kept per process (a refine writes its
#: output several times; a long-lived stage server serves many assets):
#: key -> (files it read, their stamps and their folders', copies). Bounded.
_COPIES_CACHE: OrderedDict[tuple, tuple[list[Path], tuple, dict[str, Path]]] = OrderedDict()
_COPIES_CACHE_SIZE = 32
_COPIES_LOCK = threading.Lock()


def _copies_key(asset: AssetDescription) -> tuple:
    meshes = tuple(
        (str(g.path), g.filename)
        for ln in asset.links for g in ln.visuals + ln.collisions if g.kind == "mesh" and g.path is not None
    )  # fmt: skip
    return str(asset.source_dir), str(asset.urdf_path), meshes


def _stamps(files: list[Path]) -> tuple:
    """(path, size, modification time ns, inode) of each file and of each
    folder holding one (a file added, removed or renamed there changes the
    folder's time); None for a path that cannot be read."""
    out = []
    for p in sorted({str(f) for f in files} | {str(Path(f).parent) for f in files}):
        try:
            st = os.stat(p)
            out.append((p, st.st_size, st.st_mtime_ns, st.st_ino))
        except OSError:
            out.append((p, None, None, None))
    return tuple(out)


def mesh_copies(asset: AssetDescription) -> dict[str, Path]:
    """What :func:`copy_meshes` copies: output path (relative, POSIX, exactly
    where the output URDF, the copied OBJ and MTL files will look for it) ->
    the real input file. A mesh reached through a symlink inside the asset
    folder is copied as a regular file at the referenced path; MTL files and
    textures are placed relative to their mesh as the mesh looks for them
    (an MTL that lies beside a symlinked mesh's real file and not beside the
    link is placed beside the copy: :func:`beside_link_target`).

    Finding the MTL libraries and textures reads every OBJ file (16-80 ms per
    PartNet-Mobility asset, asked for 5-11 times per refine), so the answer
    is kept per process, keyed by the asset's mesh references and checked
    against the size, modification time and inode of every file it read and
    of the folders holding them (an edited, added or replaced file computes
    it again).

    Raises:
        OutputError: ``OUTPUT_OUTSIDE_INPUT`` (a file outside the asset
            folder), ``OUTPUT_NAME_CONFLICT`` (two different input files for
            one output path, or an input file named like a contract file).
    """
    key = _copies_key(asset)
    with _COPIES_LOCK:
        hit = _COPIES_CACHE.get(key)
    if hit is not None and _stamps(hit[0]) == hit[1]:
        return dict(hit[2])
    read = [g.path for ln in asset.links for g in ln.visuals + ln.collisions if g.kind == "mesh" and g.path is not None]
    # the paths as written too: a library added beside a symlinked mesh changes where its material comes from
    read += [asset.urdf_path.parent / g.filename for ln in asset.links for g in ln.visuals + ln.collisions
             if g.kind == "mesh" and g.path is not None and g.filename]
    copies = _mesh_copies(asset)
    files = [*read, *copies.values()]
    entry = (files, _stamps(files), dict(copies))
    with _COPIES_LOCK:
        _COPIES_CACHE[key] = entry
        _COPIES_CACHE.move_to_end(key)
        while len(_COPIES_CACHE) > _COPIES_CACHE_SIZE:
            _COPIES_CACHE.popitem(last=False)
    return copies


def _mesh_copies(asset: AssetDescription) -> dict[str, Path]:
    root = asset.source_dir.resolve()
    base = asset.urdf_path.parent
    copies: dict[str, Path] = {}

    def add(rel: str, src: Path) -> None:  # src resolved
        if not _inside(src, root, resolved=True):
            raise OutputError(f"mesh {src} lies outside the asset folder {root}", "OUTPUT_OUTSIDE_INPUT", src)
        rel = PurePosixPath(os.path.normpath(rel).replace(os.sep, "/")).as_posix()
        if rel.startswith("../") or rel in ("..", ".") or rel.startswith("/"):
            raise OutputError(f"{src} would be copied to {rel!r}, outside the output folder", "OUTPUT_OUTSIDE_INPUT", src)
        if rel in RESERVED_NAMES:
            raise OutputError(f"input file {src} would be copied onto the output's own {rel}", "OUTPUT_NAME_CONFLICT", src)
        if copies.get(rel, src) != src:
            raise OutputError(f"input files {copies[rel]} and {src} would both be copied to {rel}", "OUTPUT_NAME_CONFLICT", src)
        copies[rel] = src

    for ln in asset.links:
        for g in ln.visuals + ln.collisions:
            if g.kind != "mesh" or g.path is None:
                continue
            src = g.path.resolve()
            rel = os.path.normpath(g.filename) if g.filename else os.path.relpath(src, root)
            add(rel, src)
            lexical = base / rel
            lookup = os.path.realpath(lexical.parent)
            deps = [(dep, lookup) for dep in mesh_dependencies(lexical, root)]
            if str(src.parent) != lookup:  # a symlink into another folder
                deps += [(dep, str(src.parent)) for dep in beside_link_target(lexical, src, root)]
            for dep, folder in deps:
                dep = dep.resolve()
                dep_rel = os.path.normpath(os.path.join(os.path.dirname(rel), os.path.relpath(dep, folder)))
                add(dep_rel if not dep_rel.startswith("..") else os.path.relpath(dep, root), dep)
    return copies


def beside_link_target(lexical: Path, real: Path, asset_root: Path) -> list[Path]:
    """The material files of an OBJ reached through a symlink into another
    folder (``lexical``: the path as the URDF writes it; ``real``: the file
    it leads to) that lie beside the real file and not beside the link: each
    ``mtllib`` the OBJ names that does not exist relative to the link's
    folder but does relative to the real file's, with the texture maps it
    names (relative to it), as resolved paths inside ``asset_root``.

    The mesh's author put them beside the real OBJ; a loader opening the
    link looks beside the link and draws the mesh without them. The output
    copies the OBJ as a regular file at the link's path, so
    :func:`mesh_copies` places these files relative to that copy as they lie
    relative to the real file, and the copy finds its material (the
    validator reports the input's case as ``MESH_MATERIAL_BESIDE_TARGET``).
    Missing files, files outside ``asset_root`` and libraries that do exist
    beside the link (those are the input's own choice) are left out."""
    return mesh_io.obj_material_files(real, keep=lambda p: _inside(p, asset_root),
                                      skip_library=lambda name: os.path.lexists(lexical.parent / name))


def collision_folder(asset: AssetDescription) -> str:
    """Output folder name for generated collision pieces (convex
    decomposition) that no copied input file uses: ``collision``, or
    ``collision_1``, ``collision_2`` ... when the asset's own meshes live in
    a folder of that name."""
    taken = set(mesh_copies(asset))
    for ln in asset.links:
        for g in ln.visuals + ln.collisions:
            if g.kind == "mesh" and g.filename:
                taken.update(_reference_dirs(g.filename))
    for i in range(10_000):
        name = "collision" if i == 0 else f"collision_{i}"
        if not any(t == name or t.startswith(name + "/") for t in taken):
            return name
    raise OutputError(f"{asset.source_dir}: no free folder name for collision pieces", "OUTPUT_NAME_CONFLICT", asset.source_dir)


_URI = ("file:", "http:", "https:", "ftp:", "package:", "data:")


def reference_leaves_folder(ref: str, file_rel: str) -> bool:
    """True when the path ``ref``, written in the output file ``file_rel``
    (relative POSIX path inside the output folder), would be opened outside
    the output folder: absolute, a URI (``file://``, ``package://`` ...), a
    drive or NUL, or a relative path whose ``..`` leave the folder."""
    r = ref.strip().strip('"')
    if not r or "\x00" in r or r.startswith(("/", "\\")) or r.lower().startswith(_URI) or "://" in r:
        return True
    if len(r) > 1 and r[1] == ":":  # C:\x
        return True
    joined = os.path.normpath(os.path.join(os.path.dirname(file_rel), r.replace("\\", "/")))
    return joined == ".." or joined.startswith("../") or os.path.isabs(joined)


def _drop_outside_references(data: bytes, file_rel: str, names_of) -> tuple[bytes, list[str]]:
    """``data`` with every line that names a file outside the output folder
    (:func:`reference_leaves_folder`) replaced by a comment; ``names_of(line)``
    gives the file names a line names (``mesh_io.mtl_texture_maps`` for an
    MTL, ``mesh_io.mtl_libraries`` for an OBJ). Returns (bytes, dropped
    statement keywords)."""
    out: list[bytes] = []
    dropped: list[str] = []
    for line in data.splitlines(keepends=True):
        names = names_of(line)
        if names and any(reference_leaves_folder(n, file_rel) for n in names):
            key = line.split(maxsplit=1)[0].decode("utf-8", "replace")
            dropped.append(key)
            end = b"\r\n" if line.endswith(b"\r\n") else (b"\n" if line.endswith(b"\n") else b"")
            out.append(f"# asset2sim: a {key} statement naming a file outside the asset folder was dropped".encode() + end)
        else:
            out.append(line)
    return b"".join(out), dropped


def material_references(asset: AssetDescription, copies: dict[str, Path] | None = None) -> dict[str, str]:
    """The copied files that name other files: output path -> ``"obj"`` (its
    ``mtllib`` statements) or ``"mtl"`` (its texture statements), for the
    OBJ meshes of the URDF and the MTL libraries they name (as the copies of
    :func:`mesh_copies` place them)."""
    copies = mesh_copies(asset) if copies is None else copies
    kinds: dict[str, str] = {}
    for ln in asset.links:
        for g in ln.visuals + ln.collisions:
            if g.kind != "mesh" or g.path is None or not g.filename:
                continue
            rel = PurePosixPath(os.path.normpath(g.filename).replace(os.sep, "/")).as_posix()
            if rel not in copies or PurePosixPath(rel).suffix.lower() != ".obj":
                continue
            kinds[rel] = "obj"
            try:
                names = mesh_io.mtl_libraries(atomic.read_regular(copies[rel]))
            except OSError:
                continue
            for name in names:
                if reference_leaves_folder(name, rel):
                    continue
                mtl_rel = PurePosixPath(os.path.normpath(os.path.join(os.path.dirname(rel), name))).as_posix()
                if mtl_rel in copies:
                    kinds.setdefault(mtl_rel, "mtl")
    return kinds


def copied_bytes(src: Path, rel: str, kind: str | None) -> bytes:
    """What the output holds at ``rel`` for the input file ``src``: its bytes,
    for an OBJ (``kind="obj"``) or MTL (``"mtl"``) with every ``mtllib`` /
    texture statement that names a file outside the asset folder (absolute,
    URI, ``..`` leaving it) replaced by a comment, so the output never makes a
    simulator (PyBullet, SAPIEN, MuJoCo) open a file outside it; the
    validator reports such statements (``MESH_MATERIAL_OUTSIDE``)."""
    data = atomic.read_regular(src)
    edited = _edited_copy(data, rel, kind)
    return data if edited is None else edited


def _edited_copy(data: bytes, rel: str, kind: str | None) -> bytes | None:
    """:func:`copied_bytes` of ``data`` when a statement was dropped, else None."""
    if kind not in ("obj", "mtl"):
        return None
    if kind == "obj" and b"mtllib" not in data:  # fast path for large meshes
        return None
    new, dropped = _drop_outside_references(data, rel, mesh_io.mtl_libraries if kind == "obj" else mesh_io.mtl_texture_maps)
    return new if dropped else None


def copy_meshes(asset: AssetDescription, out_dir: Path) -> list[Path]:
    """Copy every mesh the URDF references (and its MTL/textures) into
    ``out_dir`` at the paths of :func:`mesh_copies` (regular files, never
    links), creating the folders a referenced path walks through.

    OBJ and MTL copies lose the statements that name files outside the asset
    folder (:func:`copied_bytes`); every other file is copied byte for byte.

    Returns the destination paths. Files already present with the same
    content (and not symlinks) are not rewritten; they are announced to the
    atomic writer's observers as kept (:func:`asset2sim.atomic.announce`).

    Raises:
        OutputError: see :func:`mesh_copies`.
        OSError: a file cannot be read or written.
    """
    copies = mesh_copies(asset)
    kinds = material_references(asset, copies)
    out_dir = Path(out_dir)
    out: list[Path] = []
    todo: list[tuple[Path, Path]] = []
    edited: list[tuple[Path, bytes]] = []
    kept: list[Path] = []
    for rel, src in sorted(copies.items()):
        dst = out_dir / rel
        data = _edited_copy(atomic.read_regular(src), rel, kinds[rel]) if rel in kinds else None  # None: a plain copy
        size = len(data) if data is not None else src.stat().st_size
        same = (
            dst.is_file() and not dst.is_symlink() and dst.stat().st_size == size
            and atomic.sha256_file(dst) == (atomic.sha256_file(src) if data is None else hashlib.sha256(data).hexdigest())
        )
        if same:
            kept.append(dst)
        elif data is None:
            todo.append((src, dst))
        else:
            edited.append((dst, data))
        out.append(dst)
    # every destination announced at once: an output folder's owner records them
    # in one write of its record instead of one per edited file
    atomic.announce([*kept, *(d for _, d in todo), *(d for d, _ in edited)])
    atomic.copy_files(todo)
    for dst, data in edited:
        atomic.write_bytes(dst, data)
    for ln in asset.links:
        for g in ln.visuals + ln.collisions:
            if g.kind == "mesh" and g.filename:
                for d in _reference_dirs(g.filename):
                    (out_dir / d).mkdir(parents=True, exist_ok=True)
    return out


def build_urdf(
    asset: AssetDescription,
    overlay: Overlay,
    collision_overrides: dict | None = None,
    root_rotation: np.ndarray | None = None,
    collision_out: tuple[Path, dict[str, float]] | None = None,
    collision_notes: list[str] | None = None,
) -> bytes:
    """The revised URDF (bytes, UTF-8) for ``overlay`` applied to ``asset``.

    The input URDF is read by :func:`asset2sim.urdf.read_urdf` (it was
    validated at extraction), changed on the model and written by
    :func:`asset2sim.urdf.write_urdf`: scale baked in
    (:func:`asset2sim.urdf.scale_model`), the overlay's inertial on every link
    that has one (a link with geometry must), ``<dynamics>`` and a complete
    ``<limit>`` (effort and velocity 1000 when absent) on every movable
    joint, an explicit ``<axis>`` on every joint, and a comment pointing to
    ``initial_state.json`` and ``overlay.json``. As the yourdfpy writer used
    before, the output leaves out the input's ``<contact>``, ``<mimic>``,
    ``<calibration>``, ``<safety_controller>`` and vendor extensions.

    ``collision_overrides``: link -> list of
    :class:`asset2sim.tasks.state.collision.CollisionPiece` replacing the link's
    mesh collisions (convex decomposition), paths relative to the output.
    ``root_rotation``: (3, 3) rotation baked into the root link's geometry and
    the joints that hang from it (a requested resting pose, ``tasks.pose``).
    ``collision_out``: (output folder, initial state): the mesh collisions
    become the convex pieces of
    :func:`asset2sim.tasks.assemble.collision_geometry.convex_collisions`,
    written into the folder (every engine loads them; a free-standing
    object's footprint levelled,
    :func:`asset2sim.tasks.assemble.collision_geometry.level_footprint`);
    their notes (what the pieces changed) are appended to
    ``collision_notes`` when given.

    Raises:
        OutputError: the overlay lacks an entry for a link with geometry or a
            movable joint (validate the overlay first).
        UrdfError: the input URDF cannot be read.
    """
    s = float(overlay.scale)
    model = urdf.read_urdf(asset.urdf_path, mode="lenient")
    model.extensions = []
    model.name = model.name or ""
    overrides = collision_overrides or {}
    for link in model.links.values():
        link.contact = {}
        pieces = overrides.get(link.name)
        if pieces:
            kept = [c for c in link.collisions if c.kind != "mesh"]
            for piece in pieces:
                kept.append(
                    urdf.UrdfGeometry(
                        kind="mesh",
                        origin=frames.pose_matrix(piece.source.origin.xyz, piece.source.origin.rpy),
                        filename=piece.filename,
                        mesh_scale=np.asarray(piece.source.scale, float),
                    )
                )
            link.collisions = kept
    urdf.scale_model(model, s, joints=False, inertials=False)
    for link in model.links.values():
        lp = overlay.links.get(link.name)
        if lp is None:
            if link.visuals or link.collisions:
                raise OutputError(f"overlay has no mass/inertia for link {link.name!r} (validate the overlay first)")
            link.inertial = None
            continue
        link.inertial = urdf.UrdfInertial(mass=float(lp.mass), origin=frames.translation_matrix(lp.com), inertia=lp.inertia.matrix())
    if root_rotation is not None and not np.allclose(root_rotation, np.eye(3)):
        T = np.eye(4)
        T[:3, :3] = np.asarray(root_rotation, float)
        for joint in model.children(asset.root_link):
            joint.origin = T @ joint.origin
        root = model.links.get(asset.root_link)
        if root is not None:
            for elem in root.visuals + root.collisions:
                elem.origin = T @ elem.origin
            if root.inertial is not None:
                root.inertial.origin = T @ root.inertial.origin
    urdf.scale_model(model, s, geometry=False, inertials=False)
    for joint in model.joints:
        joint.mimic = joint.calibration = joint.safety_controller = None
        if joint.axis_xyz is None:
            joint.axis_xyz = np.array([1.0, 0.0, 0.0])
        if joint.type in urdf.MOVABLE:
            dyn = overlay.joints.get(joint.name)
            if dyn is None:
                raise OutputError(f"overlay has no dynamics for joint {joint.name!r} (validate the overlay first)")
            joint.dynamics = urdf.UrdfDynamics(damping=float(dyn.damping), friction=float(dyn.friction))
            if joint.limit is None:
                joint.limit = urdf.UrdfLimit()
            if joint.limit.effort is None:
                joint.limit.effort = 1000.0
            if joint.limit.velocity is None:
                joint.limit.velocity = 1000.0
            if dyn.lower is not None:  # clipped to what the geometry allows (tasks.geometry.limits)
                joint.limit.lower = float(dyn.lower)
            if dyn.upper is not None:
                joint.limit.upper = float(dyn.upper)
    urdf.conform_limits(model, effort=1000.0, velocity=1000.0)  # no <limit> on fixed joints (urdf_parser_py)
    if collision_out is not None:
        free = overlay.mounting is None or not overlay.mounting.fixed  # a mounted root does not stand on its footprint
        notes = collision_geometry.convex_collisions(model, collision_out[0], collision_folder(asset), collision_out[1], level=free)
        if collision_notes is not None:
            collision_notes.extend(notes)
    springs = {n: (d.stiffness, d.spring_reference) for n, d in overlay.joints.items() if d.stiffness > 0}
    comment = (
        f" Written by asset2sim. Uniform scale {s!r} is baked in (mesh scale, origins, prismatic limits, inertials); "
        f"load at scale 1.0. Initial joint positions (rad / m): see {STATE_NAME} (URDF has no field for them). "
        f"Joint stiffness, spring references and the reasoning notes: see {OVERLAY_NAME}"
        + (f"; springs on {', '.join(sorted(springs))}" if springs else "")
        + ". "
        + root_sentence(overlay.mounting)
    )
    return urdf.write_urdf(model, comment=comment)


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
    ``initial_state.json``, ``overlay.json`` and (when the input labelled
    parts) ``semantics.txt``. Atomic per file.

    Args:
        initial_state: joint -> position in output units (rad or m).
        copy: copy the meshes and write ``semantics.txt`` (skip when only
            dynamics or the state changed).
        collision_overrides, root_rotation: see :func:`build_urdf`.

    Raises:
        OutputError: output folder inside the input, or an incomplete overlay.
    """
    out = check_output_folder(asset, out_dir)
    out.mkdir(parents=True, exist_ok=True)
    labels = part_labels(asset)
    sem = out / SEMANTICS_NAME
    if copy:  # what comes from the input, once: later writes change only the dynamics and the state
        copy_meshes(asset, out)
        if labels:
            atomic.write_bytes(sem, partnet_mobility.format_semantics(labels).encode())
    notes: list[str] = []
    urdf = atomic.write_bytes(out / URDF_NAME, build_urdf(asset, overlay, collision_overrides, root_rotation, (out, initial_state), notes))
    state = atomic.write_json(out / STATE_NAME, {
        "initial_joint_positions": {k: float(v) for k, v in initial_state.items()},
        ROOT_KEY: root_record(overlay.mounting),
    })
    ovl = atomic.write_json(out / OVERLAY_NAME, overlay.model_dump(mode="json"))
    return OutputPaths(root=out, urdf=urdf, initial_state=state, overlay=ovl, semantics=sem if labels else None,
                       collision_notes=notes)


def part_labels(asset: AssetDescription) -> dict[str, partnet_mobility.Semantics]:
    """link -> (joint kind, part label) of the asset's links that
    ``semantics.txt`` labelled, in link order ({} for an unlabelled URDF).
    The evaluation and the task tier find parts (``lid``, ``drawer``) by
    these labels; links whose name or label the format cannot express
    (whitespace in the name) are left out."""
    out: dict[str, partnet_mobility.Semantics] = {}
    for ln in asset.links:
        if ln.semantic_label and ln.semantic_joint and ln.name.split() == [ln.name] and ln.semantic_joint.split() == [ln.semantic_joint]:
            out[ln.name] = partnet_mobility.Semantics(ln.semantic_joint, ln.semantic_label)
    return out


#: Key of the root declaration in ``initial_state.json``.
ROOT_KEY = "root"


def root_record(mount: RootMount | None) -> dict:
    """The ``"root"`` entry of ``initial_state.json`` for a mounting (None:
    free-standing): ``{"fixed": bool, "mounting": kind, "pose": ...,
    "source": ...}``. A fixed root's ``pose`` is the root link frame in the
    world, ``{"xyz": [0, 0, 0] m, "quat_xyzw": [0, 0, 0, 1]}`` (the file's
    frame: the mount holds it there, no ground plane); a free root's pose is
    null: the SPEC places it with its lowest collision point on the ground
    at z = 0 and lets it settle."""
    mount = mount or RootMount()
    pose = {"xyz": [0.0, 0.0, 0.0], "quat_xyzw": [0.0, 0.0, 0.0, 1.0]} if mount.fixed else None
    return {"fixed": bool(mount.fixed), "mounting": mount.kind, "pose": pose, "source": mount.source}


def root_sentence(mount: RootMount | None) -> str:
    """The URDF comment's sentence on how the root is held."""
    mount = mount or RootMount()
    if mount.fixed:
        return (f"Mounted ({mount.kind}): load with a FIXED root link at the file's origin "
                f"(PyBullet useFixedBase, SAPIEN fix_root_link, MJCF without a free joint); see {STATE_NAME} \"{ROOT_KEY}\". ")
    return f"Free-standing: root free, resting on the ground; see {STATE_NAME} \"{ROOT_KEY}\". "


def read_root(folder: Path | str) -> RootMount:
    """The root declaration of an output folder's ``initial_state.json``
    (:func:`root_record`); free-standing when the file or its ``"root"`` entry
    is absent (outputs of other tools, earlier versions).

    Raises:
        OutputError: ``"root"`` is present but not the shape
            :func:`root_record` writes (names the file).
    """
    p = Path(folder) / STATE_NAME
    if not p.is_file():
        return RootMount()
    try:
        data = json.loads(p.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        raise OutputError(f"{p}: not readable JSON: {exc}") from exc
    rec = data.get(ROOT_KEY) if isinstance(data, dict) else None
    if rec is None:
        return RootMount()
    if not isinstance(rec, dict) or not isinstance(rec.get("fixed"), bool):
        raise OutputError(f"{p}: \"{ROOT_KEY}\" must be an object with a boolean \"fixed\"")
    fixed = rec["fixed"]
    kind = rec.get("mounting") or ("wall-mounted" if fixed else "free-standing")
    try:
        return RootMount(kind=kind, fixed=fixed, source=str(rec.get("source") or f"declared in {STATE_NAME}"))
    except ValueError as exc:
        raise OutputError(f"{p}: \"{ROOT_KEY}\": {exc}") from exc
