"""The input's meshes copied into the output folder: every mesh the URDF
references, with the MTL libraries and textures it names, placed where the
output URDF and the copied files look for them (regular files, never links);
OBJ and MTL copies lose the statements naming files outside the asset folder."""

from __future__ import annotations

import hashlib
import os
from pathlib import Path, PurePosixPath

from asset2sim import atomic, file_memo, file_names, mesh_io
from asset2sim.output_folder import (EVALUATION_NAME, MARKER_NAME, OVERLAY_NAME, RECORD_NAME, REPORT_HTML_NAME, REPORT_NAME,
                                     STATE_NAME, TIMINGS_NAME, URDF_NAME, OutputError)
from asset2sim.schemas.asset import AssetDescription


def _inside(path: Path, root: Path) -> bool:
    """True when ``path`` lies inside ``root`` after resolving symlinks."""
    return path.resolve().is_relative_to(root.resolve())


#: output paths a copied input file may not take (the contract's own files)
RESERVED_NAMES = frozenset({URDF_NAME, STATE_NAME, OVERLAY_NAME, REPORT_NAME, REPORT_HTML_NAME, EVALUATION_NAME, MARKER_NAME, RECORD_NAME,
                            TIMINGS_NAME})


def _walked_dirs(asset: AssetDescription) -> list[str]:
    """Folders (relative POSIX paths) that must exist in the output for every mesh reference of ``asset`` as written to
    open there, in order: every folder each path walks through (``dir/../m.obj`` needs ``dir``)."""
    out: list[str] = []
    for g in _meshes(asset):
        cur: list[str] = []
        for part in PurePosixPath(g.filename or "").parts[:-1]:
            if part in ("", "."):
                continue
            if part == "..":
                if cur:
                    cur.pop()
                continue
            cur.append(part)
            out.append("/".join(cur))
    return out


#: Results of :func:`mesh_copies` kept per process while the files it read, and their folders, are unchanged.
_COPIES_MEMO: file_memo.FileMemo[dict[str, Path]] = file_memo.FileMemo(dict, max_entries=32)


def _meshes(asset: AssetDescription) -> list:
    """The mesh geometries (visual and collision) of ``asset``'s links, in order."""
    return [g for ln in asset.links for g in ln.visuals + ln.collisions if g.kind == "mesh"]


def mesh_copies(asset: AssetDescription) -> dict[str, Path]:
    """What :func:`copy_meshes` copies: output path (relative, POSIX, exactly
    where the output URDF, the copied OBJ and MTL files will look for it) ->
    the real input file. A mesh reached through a symlink is copied as a
    regular file at the referenced path; MTL files and textures are placed
    relative to their mesh as it looks for them (those of a symlinked OBJ found only beside its real file
    placed beside the copy as they lie there).
    The answer is kept per process, checked against the stamps of every file
    it read and of their folders.

    Raises:
        OutputError: ``OUTPUT_OUTSIDE_INPUT`` (a file outside the asset
            folder), ``OUTPUT_NAME_CONFLICT`` (two different input files for
            one output path, or an input file named like a contract file).
    """
    key = (str(asset.source_dir), str(asset.urdf_path), tuple((str(g.path), g.filename) for g in _meshes(asset) if g.path is not None))
    hit = _COPIES_MEMO.get(key)
    if hit is not None:
        return hit
    read = [g.path for g in _meshes(asset) if g.path is not None]
    # the paths as written too: a library added beside a symlinked mesh changes where its material comes from
    read += [asset.urdf_path.parent / g.filename for g in _meshes(asset) if g.path is not None and g.filename]
    copies = _mesh_copies(asset)
    # a file added, removed or renamed in a folder holding one changes the folder's time
    files = [*read, *copies.values()]
    _COPIES_MEMO.put(key, file_memo.identities({str(f) for f in files} | {os.path.dirname(os.path.abspath(f)) for f in files}),
                     copies)
    return copies


def _mesh_copies(asset: AssetDescription) -> dict[str, Path]:
    root = asset.source_dir.resolve()
    base = asset.urdf_path.parent
    copies: dict[str, Path] = {}

    def add(rel: str, src: Path) -> None:  # src resolved
        if not src.is_relative_to(root):  # both resolved
            raise OutputError(f"mesh {src} lies outside the asset folder {root}", "OUTPUT_OUTSIDE_INPUT", src)
        rel = PurePosixPath(os.path.normpath(rel).replace(os.sep, "/")).as_posix()
        if rel.startswith("../") or rel in ("..", ".") or rel.startswith("/"):
            raise OutputError(f"{src} would be copied to {rel!r}, outside the output folder", "OUTPUT_OUTSIDE_INPUT", src)
        if rel in RESERVED_NAMES:
            raise OutputError(f"input file {src} would be copied onto the output's own {rel}", "OUTPUT_NAME_CONFLICT", src)
        if copies.get(rel, src) != src:
            raise OutputError(f"input files {copies[rel]} and {src} would both be copied to {rel}", "OUTPUT_NAME_CONFLICT", src)
        copies[rel] = src

    for g in _meshes(asset):
        if g.path is None:
            continue
        src = g.path.resolve()
        rel = os.path.normpath(g.filename) if g.filename else os.path.relpath(src, root)
        add(rel, src)
        lexical = base / rel
        lookup = os.path.realpath(lexical.parent)
        # the MTL libraries and texture maps the OBJ names, inside the asset folder (missing ones skipped: visual only)
        deps = [(dep, lookup) for dep in mesh_io.obj_material_files(lexical, keep=lambda p: _inside(p, root))]
        if str(src.parent) != lookup:  # a symlink into another folder
            # the material files that lie beside the real file and not beside the link: each mtllib found only relative to
            # the real file, with its texture maps (missing ones left out), placed beside the copy as they lie there
            deps += [(dep, str(src.parent)) for dep in mesh_io.obj_material_files(
                src, keep=lambda p: _inside(p, root), skip_library=lambda name: os.path.lexists(lexical.parent / name))]
        for dep, folder in deps:
            dep = dep.resolve()
            dep_rel = os.path.normpath(os.path.join(os.path.dirname(rel), os.path.relpath(dep, folder)))
            add(dep_rel if not dep_rel.startswith("..") else os.path.relpath(dep, root), dep)
    return copies


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


def material_references(asset: AssetDescription, copies: dict[str, Path]) -> dict[str, str]:
    """The copied files that name other files: output path -> ``"obj"`` (its
    ``mtllib`` statements) or ``"mtl"`` (its texture statements), for the
    OBJ meshes of the URDF and the MTL libraries they name (as ``copies``, what :func:`mesh_copies` gives,
    place them)."""
    kinds: dict[str, str] = {}
    for g in _meshes(asset):
        if g.path is None or not g.filename:
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


def _edited_copy(data: bytes, rel: str, kind: str) -> bytes | None:
    """``data`` of an OBJ (``kind="obj"``) or MTL (``"mtl"``) copied to ``rel`` with every ``mtllib`` / texture
    statement naming a file outside the asset folder replaced by a comment; None when nothing was dropped.
    An OBJ is edited line by line (the slowest part of a copy) only when a ``mtllib`` of the whole file names
    a file outside, or a CR could split its lines otherwise than the whole-file scan reads them."""
    if kind == "obj" and (b"mtllib" not in data or (b"\r" not in data and not any(
            reference_leaves_folder(n, rel) for n in mesh_io.mtl_libraries(data)))):
        return None
    new, dropped = _drop_outside_references(data, rel, mesh_io.mtl_libraries if kind == "obj" else mesh_io.mtl_texture_maps)
    return new if dropped else None


def copy_meshes(asset: AssetDescription, out_dir: Path) -> list[Path]:
    """Copy every mesh the URDF references (and its MTL/textures) into
    ``out_dir`` at the paths of :func:`mesh_copies` (regular files, never
    links; OBJ and MTL as :func:`_edited_copy`), creating the folders a
    referenced path walks through. Files already present with the same
    content are not rewritten (announced as kept, :func:`asset2sim.atomic.announce`).
    Returns the destination paths.

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
    for src, dst in todo:
        mesh_io.remember(dst, src)
    for dst, data in edited:
        mesh_io.write_file(dst, data)
    for d in _walked_dirs(asset):
        try:  # the one output guard's rule: a folder reached through a symlink out of out_dir is not made
            file_names.join_inside(out_dir, d).mkdir(parents=True, exist_ok=True)
        except file_names.UnsafePath as exc:
            raise OutputError(str(exc), "OUTPUT_SYMLINK_ESCAPES", out_dir / d) from exc
    return out


def taken_paths(asset: AssetDescription) -> set[str]:
    """Output paths (relative, POSIX) the copies of :func:`mesh_copies` take and the folders the asset's mesh references
    walk through: where nothing else may be written."""
    return set(mesh_copies(asset)) | set(_walked_dirs(asset))
