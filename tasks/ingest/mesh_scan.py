"""Strict reading of one mesh file for the validator's mesh checks: :func:`scan_mesh_file`."""

from __future__ import annotations

import copy
import hashlib
import io
import math
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from asset2sim import file_memo, mesh_io, mesh_materials, safexml
from asset2sim.tasks.ingest.findings import MAX_COORDINATE
from asset2sim.tasks.ingest.mesh_paths import read_regular

__all__ = ["MeshScan", "is_flat", "scan_mesh_file"]


@dataclass
class MeshScan:
    """What a strict read of one mesh file found (file units, scale 1): ``defects`` code -> message,
    ``n_vertices``, ``n_faces`` triangles, ``area``, ``moments`` (count, sum (3,), sum of outer products (3, 3)) and
    ``bounds`` (2, 3) of the used vertices, an OBJ's ``mtllibs``."""

    n_vertices: int = 0
    n_faces: int = 0
    area: float = 0.0
    defects: dict[str, str] = field(default_factory=dict)
    moments: tuple[int, np.ndarray, np.ndarray] | None = None
    mtllibs: list[str] = field(default_factory=list)
    bounds: np.ndarray | None = None


class _TooManyFaces(Exception):
    def __init__(self, count: int, max_faces: int, what: str = "triangles"):
        super().__init__(f"{count} {what} > cap {max_faces}")
        self.count = count


class _Unparsable(Exception):
    def __init__(self, message: str, mtllibs: list[str]):
        super().__init__(message)
        self.mtllibs = mtllibs


@dataclass(frozen=True, slots=True)
class _Triangles:
    """A strict read's triangles (file units): ``vertices`` (N, 3), the valid ``faces`` (M, 3) int64, ``defects``
    code -> message and an OBJ's ``mtllibs``."""

    vertices: np.ndarray
    faces: np.ndarray
    defects: dict[str, str]
    mtllibs: list[str] = field(default_factory=list)


def _malformed(defects: dict[str, str], why: str) -> _Triangles:
    """No triangles: ``defects`` with ``MESH_MALFORMED`` saying ``why``."""
    defects["MESH_MALFORMED"] = why
    return _Triangles(np.zeros((0, 3)), np.zeros((0, 3), np.int64), defects)


def _bad_faces(f: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Which faces (M,) of ``f`` (M, 3) index a vertex outside ``v`` (N, 3)."""
    return np.any((f < 0) | (f >= len(v)), axis=1) if len(f) else np.zeros(0, bool)


#: A line (after its newline: a search for a literal first byte is several times faster than for a line start) whose
#: first byte after blanks begins no OBJ record.
_OBJ_NOT_RECORD = re.compile(rb"\n[ \t]*([^A-Za-z#\s][^\r\n]{0,39})")


def _scan_obj(data: bytes, max_faces: int) -> _Triangles:
    """An OBJ as refine reads it (:func:`asset2sim.mesh_io.read_obj`) plus strict checks (face cap before
    parsing, non-records, bad indices, skipped faces)."""
    defects: dict[str, str] = {}
    approx_faces = data.count(b"\nf ") + data.count(b"\nf\t") + (data[:2] in (b"f ", b"f\t"))
    if approx_faces > max_faces:
        raise _TooManyFaces(approx_faces, max_faces, "face records")
    mtllibs = [m for m in mesh_materials.mtl_libraries(data) if m.strip()]
    bad_rec = _OBJ_NOT_RECORD.search(b"\n" + data)
    if bad_rec is not None:
        # every OBJ record starts with a keyword (v, f, vt, vn, o, g, s, usemtl, l, ...)
        lineno = bad_rec.string.count(b"\n", 0, bad_rec.start(1))
        defects["MESH_MALFORMED"] = f"line {lineno}: not an OBJ record: {bad_rec.group(1)!r}"
    try:
        mesh = mesh_io.read_obj(data, "OBJ")
        v, f, notes = mesh.vertices, mesh.faces, mesh.notes
    except mesh_io.MeshReadError as exc:  # refine could not read it either: nothing more to check
        raise _Unparsable(defects.get("MESH_MALFORMED") or str(exc), mtllibs) from None
    if len(f) > max_faces:
        raise _TooManyFaces(len(f), max_faces)
    bad = _bad_faces(f, v)
    if bad.any() or notes:
        what = [f"{int(bad.sum())} face(s) index vertices outside the {len(v)} defined"] if bad.any() else []
        defects["MESH_BAD_INDEX"] = "; ".join(what + [n.replace("OBJ: ", "") for n in notes])
    return _Triangles(v, f[~bad], defects, mtllibs)


def _scan_stl(data: bytes, max_faces: int) -> _Triangles:
    defects: dict[str, str] = {}
    if len(data) >= 84:
        n = int.from_bytes(data[80:84], "little")
        if 84 + 50 * n == len(data):
            if n > max_faces:
                raise _TooManyFaces(n, max_faces)
            dt = np.dtype([("n", "<f4", 3), ("v", "<f4", (3, 3)), ("a", "<u2")])
            v = np.frombuffer(data, dtype=dt, count=n, offset=84)["v"].astype(np.float64).reshape(-1, 3)
            return _Triangles(v, np.arange(len(v)).reshape(-1, 3), defects)
    if not data[:512].lstrip().lower().startswith(b"solid"):
        return _malformed(defects, "neither a binary STL (size != 84 + 50 n) nor an ASCII STL")
    if data.count(b"facet") // 2 > max_faces:
        raise _TooManyFaces(data.count(b"facet") // 2, max_faces, "facets (about)")
    coords = re.findall(rb"vertex\s+(\S+)\s+(\S+)\s+(\S+)", data)
    try:
        v = np.array(coords, dtype=np.float64).reshape(-1, 3)
    except ValueError:
        return _malformed(defects, "an ASCII STL vertex is not numeric")
    if len(v) % 3:
        defects["MESH_MALFORMED"] = f"{len(v)} vertices is not a whole number of triangles"
        v = v[: len(v) - len(v) % 3]
    return _Triangles(v, np.arange(len(v)).reshape(-1, 3), defects)


def scan_mesh_file(path: Path | str, *, max_bytes: int = 64 << 20, max_faces: int = 2_000_000,
                   max_coordinate: float = MAX_COORDINATE) -> MeshScan:
    """Strictly read one mesh file and report its defects: OBJ by :func:`asset2sim.mesh_io.read_obj`
    (the reader of every later stage) with strict checks on top, STL by this module, other formats by
    ``trimesh`` (DAE first through :func:`asset2sim.safexml.parse_xml_bytes`).

    Args:
        path: a regular file (resolve it with :func:`resolve_mesh_reference`).
        max_bytes, max_faces: size cap (bytes) and triangle cap.
        max_coordinate: |coordinate| cap of the used vertices, file units (compared before any arithmetic).

    Returns:
        A :class:`MeshScan` (never raises for a bad file); OSError when the file cannot be read.
    """
    path = Path(path)
    data = read_regular(path, max_bytes, follow_links=False)
    ext = path.suffix.lower()
    if ext not in (".obj", ".stl"):  # trimesh's messages may name the file
        return _scan_data(data, ext, max_faces, max_coordinate, str(path))
    key = (hashlib.sha1(data).digest(), ext, max_faces, max_coordinate)
    scan = _SCANS.get(key)
    if scan is None:
        scan = _scan_data(data, ext, max_faces, max_coordinate, str(path))
        _SCANS.put(key, (), scan)  # no file identities: the key is the content itself
    return scan


#: Scans of OBJ and STL files in this process by (SHA-1 of the bytes, extension, caps), each caller given its own
#: copy: an output's visual meshes are copies of its input's, and both are validated.
_SCANS: file_memo.FileMemo[MeshScan] = file_memo.FileMemo(copy.deepcopy, max_entries=4096)


def _scan_data(data: bytes, ext: str, max_faces: int, max_coordinate: float, source: str) -> MeshScan:
    """:func:`scan_mesh_file` of a file's ``data`` with extension ``ext`` (``source``: its name for messages)."""
    scan = MeshScan()
    try:
        if ext == ".obj":
            read = _scan_obj(data, max_faces)
            scan.mtllibs = read.mtllibs
        elif ext == ".stl":
            read = _scan_stl(data, max_faces)
        else:  # other formats by trimesh
            if ext == ".dae":
                safexml.parse_xml_bytes(data, source=source)  # DAE is XML: refuse DTDs/entities first
            import trimesh

            loaded = trimesh.load(io.BytesIO(data), file_type=ext[1:], force="mesh", process=False, skip_materials=True)
            v = np.asarray(getattr(loaded, "vertices", np.zeros((0, 3))), np.float64).reshape(-1, 3)
            f = np.asarray(getattr(loaded, "faces", np.zeros((0, 3))), np.int64).reshape(-1, 3)
            if len(f) > max_faces:
                raise _TooManyFaces(len(f), max_faces)
            bad = _bad_faces(f, v)
            read = _Triangles(v, f[~bad], {"MESH_BAD_INDEX": f"{int(bad.sum())} face(s) index beyond the {len(v)} vertices"}
                              if bad.any() else {})
        v, f, defects = read.vertices, read.faces, read.defects
    except _TooManyFaces as exc:  # counted in the asset's total all the same
        scan.defects["MESH_TOO_MANY_FACES"] = str(exc)
        scan.n_faces = exc.count
        return scan
    except _Unparsable as exc:
        scan.defects["MESH_MALFORMED"], scan.mtllibs = str(exc), exc.mtllibs
        return scan
    except Exception as exc:  # trimesh / numpy raise many types on garbage
        scan.defects["MESH_MALFORMED"] = (f"unsafe or malformed XML: {exc.code}: {exc.detail}"
                                          if isinstance(exc, safexml.SafeXMLError)
                                          else f"cannot parse ({type(exc).__name__}: {str(exc)[:200]})")
        return scan
    scan.defects.update(defects)
    scan.n_vertices, scan.n_faces = len(v), len(f)
    if len(f) == 0:
        scan.defects.setdefault("MESH_NO_FACES", "no (valid) face")
        return scan
    used = np.unique(f)
    uv = v[used]
    finite = np.isfinite(uv).all(axis=1)
    if not finite.all():
        scan.defects["MESH_NONFINITE_VERTEX"] = f"{int((~finite).sum())} used vertex(es) with NaN or infinite coordinates"
        f, uv = f[np.isfinite(v[f]).all(axis=(1, 2))], uv[finite]
        if len(f) == 0:
            return scan
    far = np.abs(uv) > max_coordinate  # a comparison: no overflow, no warning
    if far.any():
        scan.defects["MESH_COORDINATE_IMPLAUSIBLE"] = (
            f"{int(far.any(axis=1).sum())} used vertex(es) beyond +-{max_coordinate:g} file units (largest |coordinate| "
            f"{float(np.abs(uv).max()):.3g}): no overlay scale can make this a household object; check the mesh's units")
        return scan
    tri = v[f]
    area2 = np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    diag = float(np.linalg.norm(uv.max(axis=0) - uv.min(axis=0)))
    scan.area = float(area2.sum() / 2.0)
    if diag == 0.0 or scan.area <= 1e-14 * diag * diag:
        scan.defects["MESH_ZERO_AREA"] = f"all {len(f)} faces are degenerate (total area {scan.area:.3g})"
        return scan
    scan.moments = (len(uv), uv.sum(axis=0), uv.T @ uv)
    scan.bounds = np.stack([uv.min(axis=0), uv.max(axis=0)])
    if is_flat(*scan.moments):
        scan.defects["MESH_ZERO_VOLUME"] = "all vertices lie in one plane (zero volume)"
    return scan


def is_flat(n: int, s1: np.ndarray, s2: np.ndarray) -> bool:
    """Vertices whose scatter has a zero direction (relative 1e-9 of the extent); False for non-finite moments."""
    if n < 4:
        return True
    if not (np.isfinite(s1).all() and np.isfinite(s2).all()):
        return False
    with np.errstate(over="ignore", invalid="ignore"):
        mean = s1 / n
        cov = s2 / n - np.outer(mean, mean)
    if not np.isfinite(cov).all():
        return False
    lam = np.linalg.eigvalsh(0.5 * (cov + cov.T))
    return bool(lam[2] <= 0 or math.sqrt(max(lam[0], 0.0)) <= 1e-9 * math.sqrt(lam[2]))
