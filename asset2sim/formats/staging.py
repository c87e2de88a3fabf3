"""Assets in other formats (MJCF, OpenUSD) staged as a URDF folder.

A reader of another format (:mod:`asset2sim.formats.mjcf.reader`,
:mod:`asset2sim.formats.usd.reader`) turns the file into the project's one
asset model (:class:`asset2sim.urdf.UrdfModel`, SI units, radians) and the
values URDF has no element for (joint springs). :func:`stage` writes that
model as ``<folder>/model.urdf`` with its meshes as ``<folder>/meshes/*.obj``.
The rest of the pipeline (validation, extraction, refine, audit) reads that
folder as it reads any URDF asset. The input file is only read; the folder is
a fresh temporary one (:func:`staging_folder`) or one the caller names.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import re
import tempfile
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from asset2sim import atomic, file_memo, file_names
from asset2sim.input_files import DEFAULT_MAX_BYTES, read_head
from asset2sim.urdf import UrdfInertial, UrdfLink, UrdfMaterial, UrdfModel, write_urdf

#: The staged URDF's file name inside its folder.
STAGED_URDF = "model.urdf"
#: Folder (inside the staged folder) of the meshes written for the model.
MESH_DIR = "meshes"
#: Folder (inside the staged folder) of the input's own files as the reader policy read them (an MJCF input's
#: snapshot: :meth:`asset2sim.formats.mjcf.files.MjcfSources.snapshot`), for the stages after extraction.
SOURCE_DIR = "source"
#: File suffixes read as MJCF and as OpenUSD.
MJCF_SUFFIXES = (".xml", ".mjcf")
USD_SUFFIXES = (".usd", ".usda", ".usdc", ".usdz")
#: Triangles one MJCF model or USD stage may build, every ``<mesh>`` element or mesh prim counted (one file named by
#: 60 elements is built 60 times): MuJoCo's compiler took 1.6 GB for 2,000,000 (10 references of a 200,000-face STL,
#: about 800 bytes a face) and 4.5 GB for 6,000,000; this keeps a refine of an MJCF or USD input under 2 GB (the
#: staged URDF then meets the validator's face caps).
MAX_BUILT_FACES = 1_000_000
#: Folder (inside the output's ``mjcf/`` or ``usd/``) of the files written for the host.
HOST_DIR = "host"


class StagingError(ValueError):
    """An MJCF or USD input cannot be read into the asset model (the message names the file and the
    body, prim or joint). ``code``: the finding code when a file the input names is refused by the reader
    policy (:mod:`asset2sim.input_files`: ``MJCF_PATH_ESCAPES``, ``USD_LAYER_OUTSIDE_ASSET``,
    ``INPUT_NOT_REGULAR_FILE`` ...), else None."""

    def __init__(self, message: str, code: str | None = None):
        super().__init__(message)
        self.code = code


@dataclass(frozen=True)
class DeclaredSpring:
    """A joint spring as the input declares it: ``stiffness`` N*m/rad or N/m about ``reference`` rad or m."""

    stiffness: float
    reference: float


@dataclass(frozen=True)
class ReadAsset:
    """What a reader made of one file, before it is written.

    ``model``: links, joints (limits, damping, friction as declared), inertials as declared (a link
    whose mass the file leaves to the simulator has ``inertial`` None), geometry in the link frame with
    mesh ``filename`` ``meshes/<stem>.obj``; ``meshes``: that filename -> (vertices (n, 3) m, triangles
    (m, 3) int) to write; ``springs``: joint -> :class:`DeclaredSpring`; ``inferred``: links whose
    inertial the file did not declare (the simulator would infer it from geometry); ``notes``: what was
    converted or left out, one line each; ``files``: every input file read (for the input hash);
    ``root_fixed``: the file welds the root to the world (True), lets it stand free (False), or does not say
    (None); ``simulated``: for links of ``inferred``, the inertial the simulator infers from the geometry
    (MuJoCo's compiled one), when the reader knows it; ``densities``: link -> the density (kg/m^3) its
    geometry declares for that inference; ``written_moments``: link -> the principal moments (3,) kg*m^2 as the
    file writes them, where the simulator changed them on loading (MuJoCo's ``balanceinertia``); ``prims``
    (USD): link or joint name -> the prim path it was read from; ``frames`` (USD): link -> its link frame (4, 4)
    in the stage's world (m, Z up); ``initial_state``: joint -> the position (rad or m) the file starts it at
    (MJCF: a keyframe), empty when it says none."""

    source: Path
    format: str
    model: UrdfModel
    meshes: dict[str, tuple[np.ndarray, np.ndarray]] = field(default_factory=dict)
    springs: dict[str, DeclaredSpring] = field(default_factory=dict)
    inferred: tuple[str, ...] = ()
    notes: tuple[str, ...] = ()
    files: tuple[Path, ...] = ()
    root_fixed: bool | None = None
    simulated: dict[str, UrdfInertial] = field(default_factory=dict)
    densities: dict[str, float] = field(default_factory=dict)
    written_moments: dict[str, tuple[float, float, float]] = field(default_factory=dict)
    prims: dict[str, str] = field(default_factory=dict)
    frames: dict[str, np.ndarray] = field(default_factory=dict)
    initial_state: dict[str, float] = field(default_factory=dict)
    #: the input's files as the reader policy read them (MJCF: ``MjcfSources``, the bytes), kept so that no later
    #: stage reads the input's paths again; None for other formats
    sources: Any = None
    #: the angle unit the file was read in (MJCF: ``radian`` or ``degree``), None for other formats
    angle_unit: str | None = None


@dataclass(frozen=True)
class StagedAsset:
    """A :class:`ReadAsset` written: ``urdf_path`` the staged URDF (its folder holds ``meshes/``)."""

    read: ReadAsset
    urdf_path: Path

    @property
    def folder(self) -> Path:
        """The staged folder."""
        return self.urdf_path.parent


def input_format(path: Path | str) -> str:
    """``"urdf"``, ``"mjcf"`` or ``"usd"`` for an input path: a folder or a ``.urdf`` file is URDF; ``.xml`` /
    ``.mjcf`` files are MJCF (a ``.xml`` whose root element is ``<robot>`` is URDF); ``.usd*`` files are USD. Only the
    first 4 KiB of a regular file are read (a FIFO or device is taken as MJCF by its suffix, and refused by the reader)."""
    p = Path(path)
    suffix = p.suffix.lower()
    if p.is_dir() or suffix == ".urdf":
        return "urdf"
    if suffix in USD_SUFFIXES:
        return "usd"
    if suffix in MJCF_SUFFIXES:  # the first 4 KiB of a regular file only: a FIFO or /dev/zero is never read here
        # unreadable: MJCF by its suffix
        head = read_head(p) or b""
        return "urdf" if b"<robot" in head and b"<mujoco" not in head else "mjcf"
    return "urdf"


_ROOT_TAG = re.compile(rb"<\s*([A-Za-z_][\w:.-]*)")


def root_element(path: Path | str) -> str | None:
    """The name of an XML file's root element, read from its first 4 KiB past the declaration and comments
    (``mujoco``, ``mujocoinclude``, ``robot`` ...); None when none is found or the file cannot be read."""
    head = read_head(path)
    if head is None:
        return None
    head = re.sub(rb"<\?.*?\?>|<!--.*?-->|<!DOCTYPE[^>]*>", b"", head, flags=re.S)
    m = _ROOT_TAG.search(head)
    return m.group(1).decode("ascii", "replace") if m else None


#: Sub-folders of an output folder that hold its MJCF and USD exports (``asset2sim export``), whose meshes are the
#: output folder's own (``meshdir=".."``).
EXPORT_FOLDERS = ("mjcf", "usd")


def input_tree(path: Path | str) -> Path:
    """The folder every file an MJCF or USD input names must lie in: the input file's folder; for an export of an
    asset2sim output folder (``OUT/mjcf/*.xml``, ``OUT/usd/*.usd`` beside ``OUT/mobility.urdf``), that output folder."""
    folder = Path(os.path.abspath(str(path))).parent
    if folder.name in EXPORT_FOLDERS and os.path.isfile(folder.parent / "mobility.urdf"):
        return folder.parent
    return folder


def other_format_file(asset: Path | str) -> tuple[Path, str] | None:
    """(file, ``"mjcf"`` or ``"usd"``) of the MJCF or USD file an input names: the path itself when it is one
    (:func:`input_format`); for a folder without any ``*.urdf``, its one top-level MJCF (root ``<mujoco>``, its
    ``<mujocoinclude>`` files beside it) or USD file (a folder per object, as a dataset of MJCF objects is laid
    out); else None (a URDF input, or a folder validation
    will report on)."""
    p = Path(asset)
    if not os.path.lexists(p):
        return None
    if p.is_dir():
        if any(p.glob("*.urdf")):
            return None
        cands = sorted(f for f in p.iterdir() if f.is_file() and f.suffix.lower() in (*MJCF_SUFFIXES, *USD_SUFFIXES))
    else:
        cands = [p]
    found = [(f, fmt) for f in cands if (fmt := input_format(f)) != "urdf"]
    if p.is_dir() and len(found) > 1:  # a model's <mujocoinclude> files beside it are not objects of their own
        found = [(f, fmt) for f, fmt in found if fmt != "mjcf" or root_element(f) == "mujoco"]
    return found[0] if len(found) == 1 else None


def host_overlay(asset, source: Path, what: str, error: type[Exception]):
    """The :class:`~asset2sim.schemas.overlay.Overlay` of the output folder ``asset``
    (:class:`~asset2sim.refined_asset.RefinedAsset`) for writing its physics back into the host's ``source``; raises
    ``error`` when the object was rescaled (the host ``what``, file or stage, keeps the host's sizes)."""
    overlay = asset.required_overlay()
    if not math.isclose(overlay.scale, 1.0, rel_tol=0.0, abs_tol=1e-12):
        raise error(f"{source}: the object was rescaled (x{overlay.scale:.4g}); its host {what} keeps the host's sizes, "
                    "so none is written (refine without --size / --scale / size words to keep the size)")
    return overlay


def numbered(name: str, used: set[str]) -> str:
    """``name``, or ``name_1``, ``name_2`` ... the first not in ``used``; added to ``used``."""
    cand, k = name, 1
    while cand in used:
        cand, k = f"{name}_{k}", k + 1
    used.add(cand)
    return cand


def mesh_name(stem: str, used: set[str]) -> str:
    """``meshes/<stem>.obj`` for a name from the input (made safe by :func:`asset2sim.file_names.file_stem`,
    :func:`numbered` against the stems in ``used``)."""
    return f"{MESH_DIR}/{numbered(file_names.file_stem(stem), used)}.obj"


def collisions_as_visuals(link: UrdfLink) -> None:
    """A link with collision geometry but no visual shows its collisions (copies), as the simulators that read
    the input would draw nothing else."""
    if link.collisions and not link.visuals:
        link.visuals = [replace(g, origin=g.origin.copy()) for g in link.collisions]


def rgba_material(rgba) -> UrdfMaterial:
    """A URDF material of colour ``rgba`` (4,) in 0..1, named after it (``rgba_<8 hex digits>``): URDF readers
    (PyBullet's among them) refuse a ``<material>`` without a name."""
    rgba = np.clip(np.asarray(rgba, float), 0.0, 1.0)
    return UrdfMaterial(name="rgba_" + "".join(f"{int(round(255 * float(c))):02x}" for c in rgba), rgba=rgba)


def obj_bytes(vertices: np.ndarray, triangles: np.ndarray) -> bytes:
    """A Wavefront OBJ of ``vertices`` (n, 3) and ``triangles`` (m, 3) (0-based), through trimesh's exporter.

    Raises:
        StagingError: no vertices or no triangles.
    """
    import trimesh

    v, f = np.asarray(vertices, float).reshape(-1, 3), np.asarray(triangles, np.int64).reshape(-1, 3)
    if not len(v) or not len(f):
        raise StagingError("a mesh without vertices or triangles")
    mesh = trimesh.Trimesh(v, f, process=False)
    return mesh.export(file_type="obj", include_normals=False, include_color=False, include_texture=False,
                       digits=17).encode("utf-8")


#: The manifest of a snapshot of an input's files (:func:`write_snapshot`).
SNAPSHOT_NAME = "sources.json"


def write_snapshot(folder: Path | str, files: dict[str, bytes], **meta: Any) -> Path:
    """Write ``files`` (the input's files as the reader policy read them: absolute path -> bytes) into ``folder`` (a
    staged asset's ``source/``) as ``files/<n>`` with :data:`SNAPSHOT_NAME` (each path's file and SHA-256, and
    ``meta``), so a later stage, in this process or another, uses the bytes read and never the input's paths.
    Returns ``folder``. Raises OSError."""
    folder = Path(folder)
    entries = {}
    for n, (key, data) in enumerate(sorted(files.items())):
        atomic.write_bytes(folder / "files" / str(n), data, durable=False)
        entries[key] = {"file": str(n), "sha256": hashlib.sha256(data).hexdigest()}
    atomic.write_json(folder / SNAPSHOT_NAME, {"format": 1, "files": entries, **meta}, durable=False)
    return folder


def read_snapshot(folder: Path | str) -> tuple[dict[str, bytes], dict[str, Any]]:
    """(path -> bytes, the other fields) of a snapshot :func:`write_snapshot` wrote, each file checked against its
    SHA-256 and read as a regular file of at most :data:`~asset2sim.input_files.DEFAULT_MAX_BYTES`.

    Raises:
        OSError: no snapshot, or a file missing or not a regular file.
        ValueError: not a snapshot, or a file changed since.
    """
    folder = Path(folder)
    doc = json.loads(atomic.read_regular(folder / SNAPSHOT_NAME, 1 << 24).decode("utf-8"))
    if not isinstance(doc, dict) or doc.get("format") != 1 or not isinstance(doc.get("files"), dict):
        raise ValueError(f"{folder / SNAPSHOT_NAME}: not a snapshot of an input's files")
    files = {}
    for key, entry in doc["files"].items():
        data = atomic.read_regular(folder / "files" / str(int(entry["file"])), DEFAULT_MAX_BYTES)
        if hashlib.sha256(data).hexdigest() != entry["sha256"]:
            raise ValueError(f"{folder}: the copy of {key} changed since it was read")
        files[key] = data
    return files, {k: v for k, v in doc.items() if k not in ("format", "files")}


def stage(read: ReadAsset, folder: Path | str) -> StagedAsset:
    """Write ``read`` into ``folder``: ``model.urdf`` and ``meshes/*.obj`` (atomically, inside ``folder``).

    Raises:
        StagingError: a mesh cannot be written (names the file).
        OSError: ``folder`` cannot be written.
    """
    folder = Path(folder)
    for rel, (v, f) in sorted(read.meshes.items()):
        try:
            data = obj_bytes(v, f)
        except StagingError as exc:
            raise StagingError(f"{read.source}: {rel}: {exc}") from exc
        atomic.write_bytes(file_names.join_inside(folder, rel), data)
    if hasattr(read.sources, "snapshot"):  # the bytes read, for the stages after extraction
        read.sources.snapshot(folder / SOURCE_DIR, angle=read.angle_unit)
    urdf_path = folder / STAGED_URDF
    comment = f" staged by asset2sim from {read.format.upper()} {read.source.name} "
    atomic.write_bytes(urdf_path, write_urdf(read.model, comment=comment))
    real = os.path.realpath(urdf_path)
    _READS.put(real, file_memo.identities([real]), read)
    return StagedAsset(read=read, urdf_path=urdf_path)


#: How many staged reads are kept (each holds its meshes' arrays).
_READS_KEPT = 8
#: The reads staged last in this process, by their staged URDF (real path), while that file keeps its identity when
#: written: what :func:`read_of` answers; the least recently used dropped first (kept as they are: a read is frozen).
_READS: file_memo.FileMemo[ReadAsset] = file_memo.FileMemo(lambda read: read, max_entries=_READS_KEPT)


def read_of(urdf_path: Path | str) -> ReadAsset | None:
    """The :class:`ReadAsset` this process staged as ``urdf_path`` (one of the last :data:`_READS_KEPT`, the file
    unchanged since: same device, inode, size and modification time, :func:`asset2sim.file_memo.identity`), so the
    input need not be read again; None otherwise (then read it)."""
    return _READS.get(os.path.realpath(urdf_path))


_STAGING_ROOT: list[Path] = []


def staging_folder(source: Path | str) -> Path:
    """A new empty folder for staging ``source``, under this process's temporary folder
    (``<tmp>/asset2sim-staged-<random>/<stem>-<digest of the path>``), removed when the process exits."""
    if not _STAGING_ROOT:
        _STAGING_ROOT.append(atomic.process_folder("asset2sim-staged-"))
    src = os.path.realpath(source)
    digest = hashlib.sha256(src.encode("utf-8", "surrogatepass")).hexdigest()[:12]
    return Path(tempfile.mkdtemp(prefix=f"{file_names.file_stem(Path(src).stem)[:40]}-{digest}-", dir=_STAGING_ROOT[0]))


def copy_named(src: Path, base: Path, folder: Path, data: bytes | None = None) -> str:
    """Copy an asset file the MJCF or URDF names into ``folder``: at its path relative to ``base`` (the file's folder)
    when inside it, else under ``assets/`` by a safe name; ``data``: its bytes as already read (then ``src`` only names
    it); returns the relative POSIX path written."""
    real = Path(os.path.realpath(src)) if data is None else Path(src)
    try:
        rel = real.relative_to(Path(os.path.realpath(base))).as_posix()
    except ValueError:
        digest = hashlib.sha256(str(real).encode()).hexdigest()[:8]
        rel = f"assets/{file_names.file_stem(real.stem)}-{digest}{real.suffix.lower()}"
    target = file_names.join_inside(folder, rel)
    if data is not None:
        atomic.write_bytes(target, data)  # the bytes the reader policy read: the input is not opened again
    else:
        atomic.copy_file(real, target)  # its folders made by the atomic writer, after the output's guard
    return rel
