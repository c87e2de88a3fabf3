"""Input validation: everything wrong with an untrusted asset, at once, with stable codes.

:func:`validate_asset` reads an asset folder (or a URDF file) and returns a list
of :class:`Finding` (code, severity, file, line, link or joint, message,
action, values). It never raises on bad input and never writes. A
:class:`ValidationPolicy` decides each finding's severity (what is an error);
:func:`errors` picks the findings that refuse the asset. The codes and what
each checks are tabulated in ``docs/validation.md`` (generated from
:data:`CODES`).

What is checked, in order (later checks run on what the earlier ones could
read; nothing stops at the first problem):

1. Files: the URDF is a regular file inside the asset folder, below the size
   cap (``URDF_*``).
2. XML: hardened parsing by :mod:`asset2sim.safexml` (``XML_*``).
3. Numbers: every numeric attribute the URDF format defines is parsed
   strictly (decimal literal, finite as a float64: NaN, inf, ``1e400``, empty,
   hex, ``1_0``, ``1,2`` rejected) with the right count (``NUMBER_*``).
4. Kinematic structure: unique names, joint parent and child exist, no self
   loop, no link with two parents, no cycles, no orphans, exactly one root,
   known joint types, non-zero axis, limits present on revolute/prismatic,
   lower <= upper (warning when equal), non-negative effort, velocity,
   damping and friction (``LINK_*``, ``JOINT_*``, ``TREE_*``).
5. Given inertials: mass > 0 on moving links, inertia symmetric positive
   definite with the triangle inequality of principal moments. An invalid
   one is reported with its eigenvalues and ``action="replace_with_estimate"``
   (the extraction stage drops it so the estimator replaces it); it is never
   balanced or clipped (``INERTIAL_*``, ``INERTIA_*``).
6. Mesh references: resolved real path inside the asset folder, a regular
   file with a mesh extension, below the size cap; absolute paths, ``..``
   escapes, URIs (``file://``, ``http://``, ``package://``), symlinks leaving
   the folder, NUL and control characters, directories, FIFOs, devices and
   sockets are refused. Every missing mesh is listed (``MESH_*``).
7. Mesh contents (OBJ and STL by a strict reader, PLY/OFF/GLB/GLTF/DAE via
   trimesh): parse errors, no faces, face-count cap, non-finite vertices, bad
   face indices, zero area. These are errors where the mesh is used for
   collision or for mass (a link's collision geometry, or its visual geometry
   when it has no collision), warnings where it is only drawn. A mesh with
   zero volume (all vertices in one plane) is ``info``; a link whose whole
   mass geometry has zero volume is a warning with
   ``action="mass_from_area"`` (PartNet-Mobility has such links, e.g. the
   single-quad door of object 8877), because a volume-based mass would be 0.
8. PartNet-Mobility extras: ``semantics.txt`` lines, ``meta.json``.

Units: lengths in the file's units (metres nominally), angles rad, mass kg,
inertia kg*m^2, sizes of files in bytes.
"""

from __future__ import annotations

import io
import json
import math
import os
import re
import stat
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterable, Literal, Mapping

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from asset2sim import safexml
from asset2sim.frames import rpy_matrix
from asset2sim.schemas.overlay import ValidationIssue
from asset2sim.tasks.ingest import partnet_mobility
from asset2sim.urdf import NumberError, parse_number_list

Severity = Literal["error", "warning", "info"]
Action = Literal["refuse", "replace_with_estimate", "mass_from_area", "ignore"]
MeshUse = Literal["collision", "mass", "visual"]

__all__ = [
    "CODES",
    "CodeInfo",
    "Finding",
    "ValidationPolicy",
    "ValidationResult",
    "MeshReference",
    "MeshScan",
    "validate_asset",
    "run_validation",
    "errors",
    "has_errors",
    "resolve_mesh_reference",
    "scan_mesh_file",
    "check_inertia",
    "parse_number_list",
    "NumberError",
    "codes_markdown_table",
]


# ----------------------------------------------------------------------------- codes


@dataclass(frozen=True)
class CodeInfo:
    """Default severity, topic and one-line meaning of a finding code."""

    severity: Severity
    topic: str
    summary: str


def _c(sev: Severity, topic: str, summary: str) -> CodeInfo:
    return CodeInfo(sev, topic, summary)


#: Every code the validator can emit (stable identifiers; never renamed).
CODES: dict[str, CodeInfo] = {
    # files
    "ASSET_NOT_FOUND": _c("error", "files", "the asset path does not exist"),
    "URDF_NOT_FOUND": _c("error", "files", "no mobility.urdf or other *.urdf in the folder"),
    "URDF_AMBIGUOUS": _c("error", "files", "several *.urdf candidates and no mobility.urdf"),
    "URDF_NOT_REGULAR_FILE": _c("error", "files", "the URDF is a directory, FIFO, device or socket"),
    "URDF_OUTSIDE_ASSET": _c("error", "files", "the URDF is a symlink leaving the asset folder"),
    "URDF_UNREADABLE": _c("error", "files", "the URDF cannot be opened or read"),
    "ASSET_FILE_NOT_REGULAR": _c("error", "files", "semantics.txt or meta.json is not a regular file inside the folder"),
    # xml (safexml)
    "XML_TOO_LARGE": _c("error", "xml", "document above the size cap"),
    "XML_TOKEN_TOO_LARGE": _c("error", "xml", "a text, tag or attribute value above the token cap"),
    "XML_TOO_DEEP": _c("error", "xml", "element nesting above the depth cap"),
    "XML_TOO_MANY_ELEMENTS": _c("error", "xml", "more elements than the cap"),
    "XML_DTD_FORBIDDEN": _c("error", "xml", "a <!DOCTYPE> declaration"),
    "XML_ENTITY_FORBIDDEN": _c("error", "xml", "an entity declaration (billion laughs, quadratic blow-up)"),
    "XML_EXTERNAL_REFERENCE_FORBIDDEN": _c("error", "xml", "an external DTD or external entity (XXE)"),
    "XML_MALFORMED": _c("error", "xml", "not well-formed XML (incl. undefined entities, NUL characters)"),
    "XML_NOT_A_FILE": _c("error", "xml", "the XML source is not a readable regular file"),
    "URDF_ROOT_NOT_ROBOT": _c("error", "structure", "the root element is not <robot>"),
    "URDF_ROBOT_NAME_MISSING": _c("error", "structure", "<robot> has no name attribute (required by URDF; yourdfpy fails on it)"),
    "URDF_NO_LINKS": _c("error", "structure", "the robot has no <link>"),
    # numbers
    "NUMBER_NAN": _c("error", "numbers", "a NaN where a number is required"),
    "NUMBER_INF": _c("error", "numbers", "an infinity where a number is required"),
    "NUMBER_OVERFLOW": _c("error", "numbers", "a decimal literal that overflows float64 (e.g. 1e400)"),
    "NUMBER_EMPTY": _c("error", "numbers", "an empty numeric attribute"),
    "NUMBER_MALFORMED": _c("error", "numbers", "not a decimal number (hex, 1_0, 1,2, words ...)"),
    "NUMBER_COUNT": _c("error", "numbers", "wrong number of values (e.g. xyz with 2 values)"),
    # structure
    "LINK_NAME_MISSING": _c("error", "structure", "a <link> without name"),
    "LINK_NAME_DUPLICATE": _c("error", "structure", "two links with the same name"),
    "JOINT_NAME_MISSING": _c("error", "structure", "a <joint> without name"),
    "JOINT_NAME_DUPLICATE": _c("error", "structure", "two joints with the same name"),
    "JOINT_TYPE_MISSING": _c("error", "structure", "a joint without type"),
    "JOINT_TYPE_INVALID": _c("error", "structure", "a type other than revolute, continuous, prismatic, fixed, floating, planar"),
    "JOINT_PARENT_MISSING": _c("error", "structure", "a joint without <parent link=...>"),
    "JOINT_CHILD_MISSING": _c("error", "structure", "a joint without <child link=...>"),
    "JOINT_PARENT_UNKNOWN": _c("error", "structure", "the parent names no link"),
    "JOINT_CHILD_UNKNOWN": _c("error", "structure", "the child names no link"),
    "JOINT_SELF_LOOP": _c("error", "structure", "parent and child are the same link"),
    "LINK_MULTIPLE_PARENTS": _c("error", "structure", "a link is the child of several joints"),
    "LINK_ORPHAN": _c("error", "structure", "a link connected by no joint (robot with several links)"),
    "TREE_CYCLE": _c("error", "structure", "joints form a cycle"),
    "TREE_NO_ROOT": _c("error", "structure", "every link has a parent: no root"),
    "TREE_MULTIPLE_ROOTS": _c("error", "structure", "several links without parent"),
    "JOINT_MIMIC_UNKNOWN": _c("error", "structure", "<mimic joint=...> names no other joint"),
    # joint values
    "JOINT_AXIS_ZERO": _c("error", "joints", "zero axis on a movable joint"),
    "JOINT_AXIS_NOT_UNIT": _c("info", "joints", "axis not of unit length (simulators normalize it)"),
    "JOINT_LIMIT_MISSING": _c("error", "joints", "revolute or prismatic joint without <limit>"),
    "JOINT_LIMIT_INCOMPLETE": _c("warning", "joints", "<limit> without lower or upper (URDF default 0)"),
    "JOINT_LIMIT_REVERSED": _c("error", "joints", "lower > upper"),
    "JOINT_LIMIT_EQUAL": _c("warning", "joints", "lower == upper: the joint cannot move"),
    "JOINT_EFFORT_NEGATIVE": _c("error", "joints", "effort < 0"),
    "JOINT_VELOCITY_NEGATIVE": _c("error", "joints", "velocity < 0"),
    "JOINT_DYNAMICS_NEGATIVE": _c("error", "joints", "damping or friction < 0"),
    # inertials
    "INERTIAL_MASS_MISSING": _c("warning", "inertials", "<inertial> without <mass value=...>; replaced by an estimate"),
    "INERTIA_MISSING": _c("warning", "inertials", "<inertial> without <inertia>; replaced by an estimate"),
    "INERTIAL_MASS_NONPOSITIVE": _c("warning", "inertials", "mass <= 0 on a moving link, or < 0 anywhere; replaced by an estimate"),
    "INERTIAL_MASS_ZERO_STATIC": _c("info", "inertials", "mass 0 on a static link (root or fixed child)"),
    "INERTIA_NOT_POSITIVE_DEFINITE": _c("warning", "inertials", "an eigenvalue <= 0; replaced by an estimate"),
    "INERTIA_TRIANGLE_INEQUALITY": _c("warning", "inertials", "principal moments violate I1 <= I2 + I3; replaced by an estimate"),
    # geometry and mesh references
    "GEOMETRY_MISSING": _c("error", "geometry", "<visual>/<collision> whose <geometry> is not exactly one <box|cylinder|sphere|mesh>"),
    "GEOMETRY_SIZE_NONPOSITIVE": _c("error", "geometry", "box size, radius or length <= 0"),
    "MESH_SCALE_ZERO": _c("error", "geometry", "a mesh scale component of 0"),
    "MESH_SCALE_NEGATIVE": _c("warning", "geometry", "a negative mesh scale (mirrored mesh)"),
    "MESH_FILENAME_EMPTY": _c("error", "mesh_paths", "<mesh> without filename"),
    "MESH_PATH_NUL": _c("error", "mesh_paths", "a NUL byte in the mesh path"),
    "MESH_PATH_CONTROL_CHAR": _c("error", "mesh_paths", "a control character in the mesh path"),
    "MESH_URI_FORBIDDEN": _c("error", "mesh_paths", "a URI (file://, http://, package:// ...) instead of a relative path"),
    "MESH_PATH_ABSOLUTE": _c("error", "mesh_paths", "an absolute mesh path"),
    "MESH_PATH_ESCAPES": _c("error", "mesh_paths", "a relative path whose ../ leave the asset folder"),
    "MESH_SYMLINK_ESCAPES": _c("error", "mesh_paths", "a symlink on the path leads outside the asset folder"),
    "MESH_NOT_FOUND": _c("error", "mesh_paths", "the mesh file does not exist (all are listed)"),
    "MESH_IS_DIRECTORY": _c("error", "mesh_paths", "the mesh path is a directory"),
    "MESH_NOT_REGULAR_FILE": _c("error", "mesh_paths", "the mesh path is a FIFO, device or socket"),
    "MESH_EXTENSION_UNSUPPORTED": _c("error", "mesh_paths", "not a mesh extension (.obj .stl .ply .off .glb .gltf .dae)"),
    "MESH_UNREADABLE": _c("error", "mesh_paths", "the mesh cannot be opened (permissions)"),
    "MESH_TOO_LARGE": _c("error", "mesh_contents", "mesh file above the byte cap"),
    "MESH_TOO_MANY_FACES": _c("error", "mesh_contents", "mesh above the face-count cap"),
    "MESH_MALFORMED": _c("error", "mesh_contents", "the mesh cannot be parsed"),
    "MESH_NO_FACES": _c("error", "mesh_contents", "the mesh has no face"),
    "MESH_NONFINITE_VERTEX": _c("error", "mesh_contents", "NaN or infinite vertex coordinates"),
    "MESH_BAD_INDEX": _c("error", "mesh_contents", "face indices out of range (or 0 in OBJ), faces with < 3 vertices"),
    "MESH_ZERO_AREA": _c("error", "mesh_contents", "every face is degenerate: the mesh has no surface"),
    "MESH_ZERO_VOLUME": _c("info", "mesh_contents", "all vertices in one plane (a sheet); fine when other pieces give volume"),
    "LINK_ZERO_VOLUME": _c("warning", "mesh_contents", "a link's whole mass geometry is flat: mass must come from area"),
    "MESH_MATERIAL_OUTSIDE": _c("warning", "mesh_paths", "an mtllib/texture path leaving the folder (not used, not copied)"),
    "MESH_MATERIAL_MISSING": _c("info", "mesh_paths", "an mtllib/texture file that does not exist"),
    "TEXTURE_PATH_REFUSED": _c("error", "mesh_paths", "a URDF <texture filename> that is absolute, a URI, escapes the folder or is not an image file"),
    "TEXTURE_NOT_FOUND": _c("warning", "mesh_paths", "a URDF <texture filename> that does not exist"),
    # extras
    "SEMANTICS_MALFORMED_LINE": _c("error", "extras", "a semantics.txt line that is not 'link joint_kind label'"),
    "SEMANTICS_UNKNOWN_LINK": _c("info", "extras", "semantics.txt names a link the URDF does not have"),
    "SEMANTICS_UNKNOWN_KIND": _c("info", "extras", "a joint kind other than hinge, slider, free, heavy, static, junk"),
    "META_UNREADABLE": _c("warning", "extras", "meta.json is not a JSON object"),
    "INTERNAL_ERROR": _c("error", "internal", "the validator itself failed on this input (a bug; message has the exception)"),
}

#: Mesh-content codes whose default severity is downgraded where the mesh is only drawn.
MESH_USE_DEPENDENT = frozenset(
    {"MESH_MALFORMED", "MESH_NO_FACES", "MESH_NONFINITE_VERTEX", "MESH_BAD_INDEX", "MESH_ZERO_AREA", "MESH_TOO_MANY_FACES"}
)

MESH_EXTENSIONS = frozenset({".obj", ".stl", ".ply", ".off", ".glb", ".gltf", ".dae"})
IMAGE_EXTENSIONS = frozenset({".png", ".jpg", ".jpeg", ".bmp", ".tga", ".tif", ".tiff", ".gif"})
JOINT_TYPES = ("revolute", "continuous", "prismatic", "fixed", "floating", "planar")
MOVABLE_TYPES = frozenset({"revolute", "continuous", "prismatic", "floating", "planar"})
SEMANTIC_KINDS = frozenset({"hinge", "slider", "free", "heavy", "static", "junk"})


# ----------------------------------------------------------------------------- findings & policy


class Finding(BaseModel):
    """One problem (or remark) about an input asset.

    ``file`` is relative to the asset folder when inside it (``mobility.urdf``,
    ``textured_objs/x.obj``), else as written; ``line`` 1-based in the URDF;
    ``link``/``joint`` name the element (``None`` for file-level findings);
    ``action`` what the pipeline does about it; ``values`` the numbers behind
    it (e.g. ``eigenvalues`` in kg*m^2).
    """

    model_config = ConfigDict(frozen=True, extra="forbid")
    code: str
    severity: Severity
    message: str
    file: str
    line: int | None = None
    link: str | None = None
    joint: str | None = None
    action: Action | None = None
    values: dict[str, Any] = Field(default_factory=dict)

    @property
    def where(self) -> str:
        """``link 'x'`` / ``joint 'y'`` / ``global``."""
        if self.joint is not None:
            return f"joint {self.joint!r}"
        if self.link is not None:
            return f"link {self.link!r}"
        return "global"

    def describe(self) -> str:
        """One line: ``error CODE file:line joint 'j': message``."""
        loc = f"{self.file}:{self.line}" if self.line else self.file
        return f"{self.severity} {self.code} {loc} {self.where}: {self.message}"

    def to_issue(self) -> ValidationIssue:
        """As the overlay schema's :class:`ValidationIssue` (for report.json)."""
        loc = f"{self.file}:{self.line}" if self.line else self.file
        return ValidationIssue(
            code=self.code,
            severity=self.severity,
            where=self.where if self.where != "global" else loc,
            message=f"{loc}: {self.message}",
            fixed=self.action in ("replace_with_estimate", "mass_from_area"),
        )


@dataclass(frozen=True)
class ValidationPolicy:
    """Decides each finding's severity, hence what refuses an asset, and the caps.

    Attributes:
        overrides: code -> severity, applied last (e.g. ``{"JOINT_LIMIT_EQUAL":
            "error"}`` or ``{"INERTIA_NOT_POSITIVE_DEFINITE": "error"}`` to
            refuse instead of replacing).
        visual_mesh_defects: severity of mesh-content defects
            (:data:`MESH_USE_DEPENDENT`) on meshes used only for drawing.
        warnings_as_errors: every warning refuses the asset.
        xml: caps of the XML parser.
        max_mesh_bytes: per mesh file, bytes.
        max_mesh_faces: per mesh file, triangles (polygons fan-triangulated).
        max_total_faces: over all distinct mesh files of the asset.
        mesh_extensions: accepted mesh suffixes (lower case, with the dot).
        check_mesh_contents: read meshes (False: paths only, much faster).
        max_extra_bytes: cap for semantics.txt and meta.json, bytes.
    """

    overrides: Mapping[str, Severity] = field(default_factory=dict)
    visual_mesh_defects: Severity = "warning"
    warnings_as_errors: bool = False
    xml: safexml.XMLLimits = safexml.DEFAULT_LIMITS
    max_mesh_bytes: int = 64 * 1024 * 1024
    max_mesh_faces: int = 2_000_000
    max_total_faces: int = 10_000_000
    mesh_extensions: frozenset[str] = MESH_EXTENSIONS
    check_mesh_contents: bool = True
    max_extra_bytes: int = 1024 * 1024

    def severity(self, code: str, use: MeshUse | None = None) -> Severity:
        """The severity of ``code`` under this policy (``use``: how the mesh
        the finding is about is used, for mesh-content codes).

        Raises:
            KeyError: unknown code.
        """
        sev = CODES[code].severity
        if use == "visual" and code in MESH_USE_DEPENDENT:
            sev = self.visual_mesh_defects
        sev = self.overrides.get(code, sev)
        if self.warnings_as_errors and sev == "warning":
            sev = "error"
        return sev

    def is_error(self, finding: Finding) -> bool:
        """True when the finding refuses the asset."""
        return finding.severity == "error"


DEFAULT_POLICY = ValidationPolicy()


def errors(findings: Iterable[Finding]) -> list[Finding]:
    """The findings whose severity is ``error``."""
    return [f for f in findings if f.severity == "error"]


def has_errors(findings: Iterable[Finding]) -> bool:
    """True when any finding is an error."""
    return any(f.severity == "error" for f in findings)


# ----------------------------------------------------------------------------- numbers
# NumberError and parse_number_list are the URDF reader's strict number parser
# (asset2sim.urdf), re-exported here for the validator's callers.


# ----------------------------------------------------------------------------- inertia


def check_inertia(ixx: float, ixy: float, ixz: float, iyy: float, iyz: float, izz: float) -> tuple[str | None, list[float]]:
    """Check a URDF inertia tensor (kg*m^2, about the COM).

    Returns:
        ``(code, eigenvalues)``: code None when the tensor is symmetric
        positive definite and its principal moments satisfy the triangle
        inequality (each <= the sum of the other two, relative tolerance
        1e-9 of the trace); else ``INERTIA_NOT_POSITIVE_DEFINITE`` (smallest
        eigenvalue <= 1e-12 x largest, or largest <= 0) or
        ``INERTIA_TRIANGLE_INEQUALITY``. Eigenvalues ascending, kg*m^2.
        The tensor is never modified ("balanced").
    """
    m = np.array([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]], float)
    lam = np.linalg.eigvalsh(m)
    vals = [float(x) for x in lam]
    if lam[2] <= 0 or lam[0] <= 1e-12 * lam[2]:
        return "INERTIA_NOT_POSITIVE_DEFINITE", vals
    tol = 1e-9 * float(lam.sum())
    if lam[2] > lam[0] + lam[1] + tol:
        return "INERTIA_TRIANGLE_INEQUALITY", vals
    return None, vals


# ----------------------------------------------------------------------------- mesh paths


@dataclass(frozen=True)
class MeshReference:
    """Outcome of resolving one ``<mesh filename=...>``.

    ``path`` is the real (symlink-free, absolute) path when acceptable, else
    None and ``code``/``message`` say why. ``size`` bytes when known.
    """

    filename: str
    path: Path | None
    code: str | None = None
    message: str = ""
    size: int | None = None


_URI = re.compile(r"^[A-Za-z][A-Za-z0-9+.\-]*://")
_SCHEME = re.compile(r"^[A-Za-z][A-Za-z0-9+.\-]{1,}:")  # 'data:', 'mailto:' (not 'C:')
_DRIVE = re.compile(r"^[A-Za-z]:[\\/]")


def _inside(path: str, root: str) -> bool:
    return path == root or path.startswith(root.rstrip(os.sep) + os.sep)


def resolve_mesh_reference(
    folder: Path | str,
    filename: str | None,
    *,
    base: Path | str | None = None,
    extensions: Iterable[str] = MESH_EXTENSIONS,
    max_bytes: int | None = None,
) -> MeshReference:
    """Resolve a mesh path written in a URDF (or an OBJ's ``mtllib``) safely.

    Checks, in this order (the first failure is returned): filename present;
    no NUL or control character; not a URI; not absolute (``/x``, ``\\x``,
    ``C:\\x``); the lexically normalized path stays in ``folder``; the real
    path (symlinks resolved) stays in the real ``folder``; it exists; it is not
    a directory; it is a regular file (no FIFO, device, socket); its suffix is
    in ``extensions`` (when non-empty); its size is <= ``max_bytes``. Only
    ``os.stat`` is used: nothing is opened, so a FIFO cannot block.

    Args:
        folder: the asset folder.
        filename: the string as written.
        base: folder the path is relative to (default ``folder``; the OBJ's
            folder for ``mtllib``).
        extensions: accepted suffixes, lower case with the dot; empty: any.
        max_bytes: size cap in bytes (None: none).

    Returns:
        A :class:`MeshReference` (never raises for bad input).
    """
    fname = filename if filename is not None else ""
    if not fname.strip():
        return MeshReference(fname, None, "MESH_FILENAME_EMPTY", "<mesh> has no filename")
    if "\x00" in fname:
        return MeshReference(fname, None, "MESH_PATH_NUL", "the path contains a NUL byte")
    if any(ord(ch) < 32 or ord(ch) == 127 for ch in fname):
        return MeshReference(fname, None, "MESH_PATH_CONTROL_CHAR", "the path contains a control character")
    if _URI.match(fname) or (_SCHEME.match(fname) and not _DRIVE.match(fname)):
        return MeshReference(fname, None, "MESH_URI_FORBIDDEN", f"URI {fname!r}: only relative paths inside the asset folder are accepted")
    if fname.startswith(("/", "\\")) or _DRIVE.match(fname):
        return MeshReference(fname, None, "MESH_PATH_ABSOLUTE", f"absolute path {fname!r}: only relative paths inside the asset folder are accepted")
    root_abs = os.path.abspath(str(folder))
    base_abs = os.path.abspath(str(base)) if base is not None else root_abs
    lexical = os.path.normpath(os.path.join(base_abs, fname))
    if not _inside(lexical, root_abs):
        return MeshReference(fname, None, "MESH_PATH_ESCAPES", f"{fname!r} resolves to {lexical}, outside the asset folder")
    root_real = os.path.realpath(root_abs)
    real = os.path.realpath(os.path.join(base_abs, fname))
    if not _inside(real, root_real):
        return MeshReference(fname, None, "MESH_SYMLINK_ESCAPES", f"{fname!r} is a symlink (or under one) to {real}, outside the asset folder")
    try:
        st = os.stat(real)
    except FileNotFoundError:
        return MeshReference(fname, None, "MESH_NOT_FOUND", f"{fname!r} does not exist")
    except NotADirectoryError:
        return MeshReference(fname, None, "MESH_NOT_FOUND", f"{fname!r} does not exist (a parent is a file)")
    except OSError as exc:
        return MeshReference(fname, None, "MESH_UNREADABLE", f"{fname!r}: {exc.strerror or exc}")
    if stat.S_ISDIR(st.st_mode):
        return MeshReference(fname, None, "MESH_IS_DIRECTORY", f"{fname!r} is a directory")
    if not stat.S_ISREG(st.st_mode):
        kind = (
            "FIFO" if stat.S_ISFIFO(st.st_mode)
            else "character device" if stat.S_ISCHR(st.st_mode)
            else "block device" if stat.S_ISBLK(st.st_mode)
            else "socket" if stat.S_ISSOCK(st.st_mode)
            else "special file"
        )
        return MeshReference(fname, None, "MESH_NOT_REGULAR_FILE", f"{fname!r} is a {kind}, not a regular file")
    exts = frozenset(e.lower() for e in extensions)
    if exts:
        for name in (fname, real):
            suf = os.path.splitext(name)[1].lower()
            if suf not in exts:
                return MeshReference(
                    fname, None, "MESH_EXTENSION_UNSUPPORTED",
                    f"{os.path.basename(name)!r} does not end in a mesh extension ({', '.join(sorted(exts))})",
                )
    if max_bytes is not None and st.st_size > max_bytes:
        return MeshReference(fname, None, "MESH_TOO_LARGE", f"{fname!r} has {st.st_size} bytes > cap {max_bytes}", st.st_size)
    return MeshReference(fname, Path(real), None, "", st.st_size)


# ----------------------------------------------------------------------------- mesh contents


@dataclass
class MeshScan:
    """What a strict read of one mesh file found (file units, scale 1).

    ``defects`` maps mesh-content codes to messages. ``n_vertices``,
    ``n_faces`` (triangles after fan triangulation of valid faces), ``area``
    (m^2, finite faces only), ``flat`` (all used vertices within 1e-9 of the
    extent of a plane), ``moments``: (count, sum (3,), sum of outer products
    (3, 3)) of the used vertices, to decide flatness of a whole link.
    ``mtllibs`` the ``mtllib`` names of an OBJ.
    """

    n_vertices: int = 0
    n_faces: int = 0
    area: float = 0.0
    flat: bool = False
    defects: dict[str, str] = field(default_factory=dict)
    moments: tuple[int, np.ndarray, np.ndarray] | None = None
    mtllibs: list[str] = field(default_factory=list)


class _TooManyFaces(Exception):
    pass


_OBJ_V = re.compile(rb"^[ \t]*v[ \t]+([^\r\n]*)", re.M)
_OBJ_F = re.compile(rb"^[ \t]*f[ \t]+([^\r\n]*)", re.M)
_OBJ_MTLLIB = re.compile(rb"^[ \t]*mtllib[ \t]+([^\r\n]*?)[ \t]*\r?$", re.M)
_OBJ_NOT_RECORD = re.compile(rb"^[ \t]*([^A-Za-z#\s][^\r\n]{0,39})", re.M)
_THREE_TOKENS = re.compile(rb"(?:[ \t]*\S+[ \t]+\S+[ \t]+\S+[ \t]*(?:\n|\Z))*")


def _obj_fast(lines_v: list[bytes], lines_f: list[bytes]) -> tuple[np.ndarray, np.ndarray] | None:
    """Vectorized path for ``v x y z`` + triangle faces with one index format
    and positive indices; None when the file needs the general path."""
    if not lines_f:
        return None
    blob = b"\n".join(lines_f)
    if _THREE_TOKENS.fullmatch(blob) is None:
        return None  # polygons or short faces: general path
    try:
        v = np.array(b" ".join(lines_v).split(), dtype=np.float64) if lines_v else np.zeros(0)
    except ValueError:
        return None
    if v.size != 3 * len(lines_v):
        return None
    first = lines_f[0].split()
    per = first[0].count(b"/") + 1
    if b"//" in first[0]:
        blob = blob.replace(b"//", b"/0/")
        per = 3
    try:
        idx = np.array(blob.replace(b"/", b" ").split(), dtype=np.int64)
    except (ValueError, OverflowError):
        return None
    if idx.size != 3 * per * len(lines_f) or blob.count(b"/") != 3 * (per - 1) * len(lines_f):
        return None  # mixed index formats: general path
    faces = idx.reshape(len(lines_f), 3, per)[:, :, 0]
    if faces.size and faces.min() < 1:
        return None
    return v.reshape(-1, 3), faces - 1


def _scan_obj(data: bytes, max_faces: int) -> tuple[np.ndarray, np.ndarray, int, dict[str, str], list[str]]:
    """Strict OBJ reader. Returns (vertices (N,3), triangles (M,3) 0-based,
    bad-face count, defects, mtllib names). Bad faces (index 0, out of range,
    < 3 vertices, non-integer) are counted and left out of the triangles."""
    defects: dict[str, str] = {}
    approx_faces = data.count(b"\nf ") + data.count(b"\nf\t") + (1 if data[:2] in (b"f ", b"f\t") else 0)
    if approx_faces > max_faces:
        raise _TooManyFaces(f"{approx_faces} face records > cap {max_faces}")
    mtllibs = [m.decode("utf-8", "replace") for m in _OBJ_MTLLIB.findall(data) if m.strip()]
    bad_rec = _OBJ_NOT_RECORD.search(data)
    if bad_rec is not None:
        # every OBJ record starts with a keyword (v, f, vt, vn, o, g, s, usemtl, l, ...)
        lineno = data.count(b"\n", 0, bad_rec.start()) + 1
        defects["MESH_MALFORMED"] = f"line {lineno}: not an OBJ record: {bad_rec.group(1)!r}"
    lines_v = _OBJ_V.findall(data)
    lines_f = _OBJ_F.findall(data)
    simple = not any(b"#" in x for x in (b"".join(lines_v), b"".join(lines_f)))
    fast = _obj_fast(lines_v, lines_f) if simple else None
    if fast is not None:
        v, faces = fast
        badrows = np.any(faces >= len(v), axis=1)
        if badrows.any():
            defects["MESH_BAD_INDEX"] = f"{int(badrows.sum())} face(s) index vertices beyond the {len(v)} defined"
        return v, faces[~badrows], int(badrows.sum()), defects, mtllibs
    # general path: per line
    verts: list[tuple[float, float, float]] = []
    tris: list[tuple[int, int, int]] = []
    nbad = 0
    first_bad = ""
    # vertices first (OBJ allows positive forward references; relative ones
    # need the count at the face's position, so keep the order)
    order: list[tuple[int, bytes]] = []
    for raw in data.splitlines():
        line = raw.split(b"#", 1)[0].strip()
        if line[:2] in (b"v ", b"v\t"):
            order.append((0, line[2:]))
        elif line[:2] in (b"f ", b"f\t"):
            order.append((1, line[2:]))
    for kind, body in order:
        if kind == 0:
            parts = body.split()
            if len(parts) < 3:
                defects.setdefault("MESH_MALFORMED", f"vertex {len(verts) + 1} has {len(parts)} coordinate(s)")
                verts.append((math.nan, math.nan, math.nan))
                continue
            try:
                verts.append((float(parts[0]), float(parts[1]), float(parts[2])))
            except ValueError:
                defects.setdefault("MESH_MALFORMED", f"vertex {len(verts) + 1}: {body[:40]!r} is not numeric")
                verts.append((math.nan, math.nan, math.nan))
        else:
            n_now = len(verts)
            try:
                ids = [int(p.split(b"/", 1)[0]) for p in body.split()]
            except ValueError:
                nbad += 1
                first_bad = first_bad or f"face {body[:40]!r} is not integer indices"
                continue
            res = [i - 1 if i > 0 else n_now + i if i < 0 else -1 for i in ids]
            if len(res) < 3 or any(r < 0 for r in res):
                nbad += 1
                first_bad = first_bad or f"face {body[:40]!r} (index 0, negative beyond start, or < 3 vertices)"
                continue
            for j in range(1, len(res) - 1):
                tris.append((res[0], res[j], res[j + 1]))
    v = np.asarray(verts, np.float64).reshape(-1, 3)
    f = np.asarray(tris, np.int64).reshape(-1, 3)
    if len(f) > max_faces:
        raise _TooManyFaces(f"{len(f)} triangles > cap {max_faces}")
    over = np.any(f >= len(v), axis=1) if len(f) else np.zeros(0, bool)
    nbad += int(over.sum())
    if nbad:
        first_bad = first_bad or f"indices beyond the {len(v)} vertices defined"
        defects["MESH_BAD_INDEX"] = f"{nbad} bad face(s); first: {first_bad}"
    return v, f[~over], nbad, defects, mtllibs


def _scan_stl(data: bytes, max_faces: int) -> tuple[np.ndarray, np.ndarray, dict[str, str]]:
    defects: dict[str, str] = {}
    if len(data) >= 84:
        n = int.from_bytes(data[80:84], "little")
        if 84 + 50 * n == len(data):
            if n > max_faces:
                raise _TooManyFaces(f"{n} triangles > cap {max_faces}")
            dt = np.dtype([("n", "<f4", 3), ("v", "<f4", (3, 3)), ("a", "<u2")])
            tri = np.frombuffer(data, dtype=dt, count=n, offset=84)["v"].astype(np.float64)
            v = tri.reshape(-1, 3)
            return v, np.arange(len(v)).reshape(-1, 3), defects
    head = data[:512].lstrip().lower()
    if not head.startswith(b"solid"):
        defects["MESH_MALFORMED"] = "neither a binary STL (size != 84 + 50 n) nor an ASCII STL"
        return np.zeros((0, 3)), np.zeros((0, 3), np.int64), defects
    if data.count(b"facet") // 2 > max_faces:
        raise _TooManyFaces(f"about {data.count(b'facet') // 2} facets > cap {max_faces}")
    coords = re.findall(rb"vertex\s+(\S+)\s+(\S+)\s+(\S+)", data)
    try:
        v = np.array(coords, dtype=np.float64).reshape(-1, 3)
    except ValueError:
        defects["MESH_MALFORMED"] = "an ASCII STL vertex is not numeric"
        return np.zeros((0, 3)), np.zeros((0, 3), np.int64), defects
    if len(v) % 3:
        defects["MESH_MALFORMED"] = f"{len(v)} vertices is not a whole number of triangles"
        v = v[: len(v) - len(v) % 3]
    return v, np.arange(len(v)).reshape(-1, 3), defects


def _scan_trimesh(data: bytes, ext: str, max_faces: int, source: str) -> tuple[np.ndarray, np.ndarray, dict[str, str]]:
    if ext == ".dae":
        safexml.parse_xml_bytes(data, source=source)  # DAE is XML: refuse DTDs/entities first
    import trimesh

    loaded = trimesh.load(io.BytesIO(data), file_type=ext[1:], force="mesh", process=False, skip_materials=True)
    v = np.asarray(getattr(loaded, "vertices", np.zeros((0, 3))), np.float64).reshape(-1, 3)
    f = np.asarray(getattr(loaded, "faces", np.zeros((0, 3))), np.int64).reshape(-1, 3)
    if len(f) > max_faces:
        raise _TooManyFaces(f"{len(f)} triangles > cap {max_faces}")
    defects: dict[str, str] = {}
    bad = np.any((f < 0) | (f >= len(v)), axis=1) if len(f) else np.zeros(0, bool)
    if bad.any():
        defects["MESH_BAD_INDEX"] = f"{int(bad.sum())} face(s) index beyond the {len(v)} vertices"
    return v, f[~bad], defects


def _read_regular(path: Path, max_bytes: int) -> bytes:
    """Read a file that was checked to be regular, re-checking on the open
    descriptor (no blocking on a FIFO swapped in, no symlink followed)."""
    flags = os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_CLOEXEC", 0)
    fd = os.open(str(path), flags)
    try:
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode):
            raise OSError(f"{path} is not a regular file")
        if st.st_size > max_bytes:
            raise OSError(f"{path} has {st.st_size} bytes > cap {max_bytes}")
        with os.fdopen(os.dup(fd), "rb") as fh:
            data = fh.read(max_bytes + 1)
        if len(data) > max_bytes:
            raise OSError(f"{path} grew beyond {max_bytes} bytes")
        return data
    finally:
        os.close(fd)


def scan_mesh_file(path: Path | str, *, max_bytes: int = 64 << 20, max_faces: int = 2_000_000) -> MeshScan:
    """Strictly read one mesh file and report its defects.

    OBJ and STL (binary and ASCII) are read by this module (OBJ: polygons
    fan-triangulated, negative relative indices, forward references); PLY,
    OFF, GLB, GLTF and DAE by ``trimesh`` (DAE first checked by
    :func:`asset2sim.safexml.parse_xml_bytes`).

    Args:
        path: a regular file (resolve it with :func:`resolve_mesh_reference`).
        max_bytes: size cap, bytes.
        max_faces: triangle cap.

    Returns:
        A :class:`MeshScan`; ``defects`` may hold MESH_MALFORMED,
        MESH_TOO_MANY_FACES, MESH_NO_FACES, MESH_NONFINITE_VERTEX,
        MESH_BAD_INDEX, MESH_ZERO_AREA, MESH_ZERO_VOLUME. Never raises for a
        bad file; OSError when the file cannot be read.
    """
    path = Path(path)
    scan = MeshScan()
    data = _read_regular(path, max_bytes)
    ext = path.suffix.lower()
    try:
        if ext == ".obj":
            v, f, _nbad, defects, scan.mtllibs = _scan_obj(data, max_faces)
        elif ext == ".stl":
            v, f, defects = _scan_stl(data, max_faces)
        else:
            v, f, defects = _scan_trimesh(data, ext, max_faces, str(path))
    except _TooManyFaces as exc:
        scan.defects["MESH_TOO_MANY_FACES"] = str(exc)
        return scan
    except safexml.SafeXMLError as exc:
        scan.defects["MESH_MALFORMED"] = f"unsafe or malformed XML: {exc.code}: {exc.detail}"
        return scan
    except Exception as exc:  # trimesh / numpy raise many types on garbage
        scan.defects["MESH_MALFORMED"] = f"cannot parse ({type(exc).__name__}: {str(exc)[:200]})"
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
        goodf = np.isfinite(v[f]).all(axis=(1, 2))
        f = f[goodf]
        uv = uv[finite]
        if len(f) == 0:
            return scan
    tri = v[f]
    cross = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    area2 = np.linalg.norm(cross, axis=1)
    ext3 = uv.max(axis=0) - uv.min(axis=0)
    diag = float(np.linalg.norm(ext3))
    scan.area = float(area2.sum() / 2.0)
    if diag == 0.0 or scan.area <= 1e-14 * diag * diag:
        scan.defects["MESH_ZERO_AREA"] = f"all {len(f)} faces are degenerate (total area {scan.area:.3g})"
        return scan
    n = len(uv)
    s1 = uv.sum(axis=0)
    s2 = uv.T @ uv
    scan.moments = (n, s1, s2)
    if _is_flat(n, s1, s2):
        scan.flat = True
        scan.defects["MESH_ZERO_VOLUME"] = "all vertices lie in one plane (zero volume)"
    return scan


def _is_flat(n: int, s1: np.ndarray, s2: np.ndarray) -> bool:
    """Vertices whose scatter has a zero direction (relative 1e-9 of the extent)."""
    if n < 4:
        return True
    mean = s1 / n
    cov = s2 / n - np.outer(mean, mean)
    lam = np.linalg.eigvalsh(0.5 * (cov + cov.T))
    return bool(lam[2] <= 0 or math.sqrt(max(lam[0], 0.0)) <= 1e-9 * math.sqrt(lam[2]))


def _transform_moments(mom, rpy, xyz, scale):
    """Moments of A x + t for A = R(rpy) diag(scale), t = xyz."""
    n, s1, s2 = mom
    a = rpy_matrix(rpy) @ np.diag(scale)
    t = np.asarray(xyz, float)
    as1 = a @ s1
    return n, as1 + n * t, a @ s2 @ a.T + np.outer(as1, t) + np.outer(t, as1) + n * np.outer(t, t)


# ----------------------------------------------------------------------------- URDF model


@dataclass
class _Geom:
    role: str
    kind: str | None
    line: int | None
    filename: str | None = None
    scale: tuple[float, float, float] = (1.0, 1.0, 1.0)
    xyz: tuple[float, float, float] = (0.0, 0.0, 0.0)
    rpy: tuple[float, float, float] = (0.0, 0.0, 0.0)
    ok: bool = True
    ref: MeshReference | None = None


@dataclass
class _Link:
    name: str | None
    line: int | None
    geoms: list[_Geom] = field(default_factory=list)
    inertial_line: int | None = None
    mass: float | None = None
    inertia: tuple[float, ...] | None = None
    has_inertial: bool = False


@dataclass
class _Joint:
    name: str | None
    line: int | None
    type: str | None
    parent: str | None
    child: str | None
    axis: tuple[float, float, float] | None = None
    has_limit: bool = False
    lower: float | None = None
    upper: float | None = None
    mimic: str | None = None


@dataclass
class ValidationResult:
    """Everything :func:`run_validation` learned.

    ``findings`` in discovery order; ``urdf`` the URDF path (None when not
    found); ``folder`` the asset folder; ``urdf_bytes`` the exact bytes that
    were validated (parse these, not the file again); ``mesh_paths`` URDF
    filename -> real path for every acceptable reference;
    ``replace_inertials`` links whose given inertial must be replaced by an
    estimate; ``semantics`` link -> (joint_kind, label); ``category`` from
    meta.json.
    """

    findings: list[Finding]
    folder: Path | None
    urdf: Path | None = None
    urdf_bytes: bytes | None = None
    mesh_paths: dict[str, Path] = field(default_factory=dict)
    replace_inertials: set[str] = field(default_factory=set)
    semantics: dict[str, tuple[str, str]] = field(default_factory=dict)
    category: str | None = None
    extra_files: list[Path] = field(default_factory=list)

    @property
    def errors(self) -> list[Finding]:
        return errors(self.findings)

    @property
    def ok(self) -> bool:
        return not has_errors(self.findings)


class _Validator:
    def __init__(self, asset: Path, policy: ValidationPolicy):
        self.asset = asset
        self.policy = policy
        self.findings: list[Finding] = []
        self.folder: Path | None = None
        self.urdf_rel = str(asset)
        self.result = ValidationResult(findings=self.findings, folder=None)

    # -- recording
    def add(
        self,
        code: str,
        message: str,
        *,
        file: str | None = None,
        line: int | None = None,
        link: str | None = None,
        joint: str | None = None,
        use: MeshUse | None = None,
        action: Action | None = None,
        **values: Any,
    ) -> None:
        sev = self.policy.severity(code, use)
        if action is None:
            action = "refuse" if sev == "error" else None
        self.findings.append(
            Finding(
                code=code,
                severity=sev,
                message=message,
                file=file if file is not None else self.urdf_rel,
                line=line,
                link=link,
                joint=joint,
                action=action,
                values=values,
            )
        )

    def rel(self, path: Path | str) -> str:
        if self.folder is None:
            return str(path)
        try:
            return str(Path(path).relative_to(self.folder))
        except ValueError:
            return str(path)

    # -- files
    def locate(self) -> Path | None:
        asset = Path(os.path.abspath(str(self.asset)))
        try:
            st = os.stat(asset)
        except OSError:
            self.add("ASSET_NOT_FOUND", f"{asset}: no such file or folder", file=str(asset))
            return None
        if stat.S_ISDIR(st.st_mode):
            folder = asset
            try:
                cands = partnet_mobility.urdf_candidates(folder)
            except OSError as exc:
                self.add("URDF_UNREADABLE", f"cannot list {folder}: {exc}", file=str(folder))
                return None
            if not cands:
                self.add("URDF_NOT_FOUND", f"{folder}: no mobility.urdf or other *.urdf file", file=str(folder))
                return None
            if len(cands) > 1:
                self.add("URDF_AMBIGUOUS", f"several URDF files ({', '.join(p.name for p in cands)}); pass one", file=str(folder))
                return None
            urdf = cands[0]
        else:
            urdf = asset
            folder = asset.parent
        self.folder = folder
        self.result.folder = folder
        self.urdf_rel = self.rel(urdf)
        real = os.path.realpath(urdf)
        if not _inside(real, os.path.realpath(folder)):
            self.add("URDF_OUTSIDE_ASSET", f"{urdf.name} is a symlink to {real}, outside the asset folder")
            return None
        try:
            st = os.stat(real)
        except OSError as exc:
            self.add("URDF_UNREADABLE", f"cannot stat {urdf}: {exc.strerror or exc}")
            return None
        if not stat.S_ISREG(st.st_mode):
            self.add("URDF_NOT_REGULAR_FILE", f"{urdf.name} is not a regular file (directory, FIFO, device or socket)")
            return None
        self.result.urdf = urdf
        return urdf

    # -- numbers
    def nums(self, el, attr: str, count, *, default=None, link=None, joint=None, required=False):
        """Parse ``el.get(attr)``; record a finding and return None when bad."""
        text = el.get(attr)
        if text is None:
            if required:
                self.add("NUMBER_EMPTY", f"<{el.tag}> has no {attr}=", line=el.sourceline, link=link, joint=joint)
                return None
            return default
        try:
            return parse_number_list(text, count)
        except NumberError as exc:
            self.add(exc.code, f"<{el.tag} {attr}={text[:60]!r}>: {exc}", line=el.sourceline, link=link, joint=joint, attribute=attr)
            return None

    def origin(self, parent, *, link=None, joint=None):
        o = parent.find("origin")
        if o is None:
            return (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), True
        xyz = self.nums(o, "xyz", 3, default=(0.0, 0.0, 0.0), link=link, joint=joint)
        rpy = self.nums(o, "rpy", 3, default=(0.0, 0.0, 0.0), link=link, joint=joint)
        return xyz or (0.0, 0.0, 0.0), rpy or (0.0, 0.0, 0.0), xyz is not None and rpy is not None

    # -- URDF
    def parse(self, urdf: Path) -> tuple[list[_Link], list[_Joint]] | None:
        try:
            data = safexml.read_xml_file(urdf, self.policy.xml)
            root = safexml.parse_xml_bytes(data, source=self.urdf_rel, limits=self.policy.xml)
        except safexml.SafeXMLError as exc:
            self.add(exc.code, exc.detail, line=exc.line)
            return None
        self.result.urdf_bytes = data
        if root.tag != "robot":
            self.add("URDF_ROOT_NOT_ROBOT", f"root element is <{root.tag}>, expected <robot>", line=root.sourceline)
            return None
        if not root.get("name"):
            self.add("URDF_ROBOT_NAME_MISSING", "<robot> has no name", line=root.sourceline)
        links = [self.parse_link(el) for el in root.findall("link")]
        joints = [self.parse_joint(el) for el in root.findall("joint")]
        for el in root.findall("material"):
            self.material(el, None)
        return links, joints

    def material(self, el, link: str | None) -> None:
        """A <material>: finite rgba, and a <texture filename> that is a safe
        relative path to an image inside the folder."""
        c = el.find("color")
        if c is not None:
            self.nums(c, "rgba", 4, link=link)
        for tex in el.findall("texture"):
            fname = tex.get("filename")
            if fname is None:
                continue
            assert self.folder is not None
            ref = resolve_mesh_reference(self.folder, fname, extensions=IMAGE_EXTENSIONS, max_bytes=self.policy.max_mesh_bytes)
            if ref.code == "MESH_NOT_FOUND":
                self.add("TEXTURE_NOT_FOUND", f"<texture filename={fname!r}> does not exist", line=tex.sourceline, link=link)
            elif ref.code is not None:
                self.add("TEXTURE_PATH_REFUSED", f"<texture filename={fname!r}>: {ref.message} ({ref.code})", line=tex.sourceline,
                         link=link, reason=ref.code)

    def parse_link(self, el) -> _Link:
        name = el.get("name")
        if not name:
            self.add("LINK_NAME_MISSING", "<link> without name", line=el.sourceline)
        ln = _Link(name=name or None, line=el.sourceline)
        for role in ("visual", "collision"):
            for g in el.findall(role):
                ln.geoms.append(self.parse_geom(g, role, name))
        for vis in el.findall("visual"):
            for mat in vis.findall("material"):
                self.material(mat, name)
        inert = el.find("inertial")
        if inert is not None:
            ln.has_inertial = True
            ln.inertial_line = inert.sourceline
            self.origin(inert, link=name)
            m = inert.find("mass")
            if m is None or m.get("value") is None:
                self.add("INERTIAL_MASS_MISSING", "<inertial> has no <mass value=...>; an estimate replaces it",
                         line=inert.sourceline, link=name, action="replace_with_estimate")
            else:
                mv = self.nums(m, "value", 1, link=name)
                ln.mass = mv[0] if mv else None
            i = inert.find("inertia")
            if i is None:
                self.add("INERTIA_MISSING", "<inertial> has no <inertia>; an estimate replaces it",
                         line=inert.sourceline, link=name, action="replace_with_estimate")
            else:
                vals = []
                for k in ("ixx", "ixy", "ixz", "iyy", "iyz", "izz"):
                    dflt = (0.0,) if k in ("ixy", "ixz", "iyz") else None
                    v = self.nums(i, k, 1, default=dflt, link=name, required=dflt is None)
                    vals.append(v[0] if v else None)
                ln.inertia = tuple(vals) if all(v is not None for v in vals) else None
        return ln

    def parse_geom(self, el, role: str, link: str | None) -> _Geom:
        xyz, rpy, ok = self.origin(el, link=link)
        g = _Geom(role=role, kind=None, line=el.sourceline, xyz=xyz, rpy=rpy, ok=ok)
        geo = el.find("geometry")
        shapes = list(geo) if geo is not None else []
        if len(shapes) != 1 or shapes[0].tag not in ("box", "cylinder", "sphere", "mesh"):
            found = ", ".join(f"<{c.tag}>" for c in shapes) or "nothing"
            self.add("GEOMETRY_MISSING", f"<{role}> needs exactly one of box, cylinder, sphere, mesh in <geometry> (found {found})",
                     line=el.sourceline, link=link)
            g.ok = False
            return g
        s = shapes[0]
        g.kind = s.tag
        if s.tag == "mesh":
            g.filename = s.get("filename")
            if s.get("scale") is not None:
                sc = self.nums(s, "scale", (1, 3), link=link)
                if sc is None:
                    g.ok = False
                else:
                    sc3 = tuple(sc * 3) if len(sc) == 1 else sc
                    if any(v == 0 for v in sc3):
                        self.add("MESH_SCALE_ZERO", f"mesh scale {s.get('scale')!r} has a zero component (the mesh collapses)",
                                 line=s.sourceline, link=link)
                        g.ok = False
                    elif any(v < 0 for v in sc3):
                        self.add("MESH_SCALE_NEGATIVE", f"mesh scale {s.get('scale')!r} mirrors the mesh", line=s.sourceline, link=link)
                    g.scale = sc3  # type: ignore[assignment]
        else:
            spec = {"box": (("size", 3),), "cylinder": (("radius", 1), ("length", 1)), "sphere": (("radius", 1),)}[s.tag]
            for attr, n in spec:
                v = self.nums(s, attr, n, link=link, required=True)
                if v is None:
                    g.ok = False
                elif any(x <= 0 for x in v):
                    self.add("GEOMETRY_SIZE_NONPOSITIVE", f"<{s.tag} {attr}={s.get(attr)!r}> must be > 0", line=s.sourceline, link=link)
                    g.ok = False
        return g

    def parse_joint(self, el) -> _Joint:
        name = el.get("name") or None
        if name is None:
            self.add("JOINT_NAME_MISSING", "<joint> without name", line=el.sourceline)
        jtype = el.get("type")
        if jtype is None:
            self.add("JOINT_TYPE_MISSING", "<joint> without type", line=el.sourceline, joint=name)
        elif jtype not in JOINT_TYPES:
            self.add("JOINT_TYPE_INVALID", f"type {jtype!r} is not one of {', '.join(JOINT_TYPES)}", line=el.sourceline, joint=name)
        p, c = el.find("parent"), el.find("child")
        parent = p.get("link") if p is not None else None
        child = c.get("link") if c is not None else None
        if not parent:
            self.add("JOINT_PARENT_MISSING", "no <parent link=...>", line=el.sourceline, joint=name)
        if not child:
            self.add("JOINT_CHILD_MISSING", "no <child link=...>", line=el.sourceline, joint=name)
        j = _Joint(name=name, line=el.sourceline, type=jtype, parent=parent or None, child=child or None)
        self.origin(el, joint=name)
        a = el.find("axis")
        if a is not None:
            ax = self.nums(a, "xyz", 3, default=(1.0, 0.0, 0.0), joint=name)
            j.axis = ax
            if ax is not None:
                norm = math.sqrt(sum(x * x for x in ax))
                if norm < 1e-12:
                    if jtype in MOVABLE_TYPES:  # ignored by simulators on fixed joints
                        self.add("JOINT_AXIS_ZERO", f"axis {a.get('xyz')!r} has zero length", line=a.sourceline, joint=name)
                elif abs(norm - 1.0) > 1e-6:
                    self.add("JOINT_AXIS_NOT_UNIT", f"axis {a.get('xyz')!r} has length {norm:.6g}", line=a.sourceline, joint=name, norm=norm)
        lim = el.find("limit")
        if lim is not None:
            j.has_limit = True
            lo = self.nums(lim, "lower", 1, joint=name)
            hi = self.nums(lim, "upper", 1, joint=name)
            eff = self.nums(lim, "effort", 1, joint=name)
            vel = self.nums(lim, "velocity", 1, joint=name)
            j.lower = lo[0] if lo else None
            j.upper = hi[0] if hi else None
            if jtype in ("revolute", "prismatic"):
                if (lim.get("lower") is None) != (lim.get("upper") is None) or (lim.get("lower") is None and lim.get("upper") is None):
                    miss = [k for k in ("lower", "upper") if lim.get(k) is None]
                    self.add("JOINT_LIMIT_INCOMPLETE", f"<limit> without {' and '.join(miss)} (URDF default 0)", line=lim.sourceline, joint=name)
                lo_v = j.lower if j.lower is not None else (0.0 if lim.get("lower") is None else None)
                hi_v = j.upper if j.upper is not None else (0.0 if lim.get("upper") is None else None)
                if lo_v is not None and hi_v is not None:
                    if lo_v > hi_v:
                        self.add("JOINT_LIMIT_REVERSED", f"lower {lo_v!r} > upper {hi_v!r}", line=lim.sourceline, joint=name, lower=lo_v, upper=hi_v)
                    elif lo_v == hi_v:
                        self.add("JOINT_LIMIT_EQUAL", f"lower == upper == {lo_v!r}: the joint cannot move", line=lim.sourceline, joint=name, lower=lo_v, upper=hi_v)
            if eff is not None and eff[0] < 0:
                self.add("JOINT_EFFORT_NEGATIVE", f"effort {eff[0]!r} < 0", line=lim.sourceline, joint=name, effort=eff[0])
            if vel is not None and vel[0] < 0:
                self.add("JOINT_VELOCITY_NEGATIVE", f"velocity {vel[0]!r} < 0", line=lim.sourceline, joint=name, velocity=vel[0])
        elif jtype in ("revolute", "prismatic"):
            self.add("JOINT_LIMIT_MISSING", f"a {jtype} joint needs <limit lower upper>", line=el.sourceline, joint=name)
        dyn = el.find("dynamics")
        if dyn is not None:
            for k in ("damping", "friction"):
                v = self.nums(dyn, k, 1, joint=name)
                if v is not None and v[0] < 0:
                    self.add("JOINT_DYNAMICS_NEGATIVE", f"{k} {v[0]!r} < 0", line=dyn.sourceline, joint=name, **{k: v[0]})
        mim = el.find("mimic")
        if mim is not None:
            j.mimic = mim.get("joint") or ""
            self.nums(mim, "multiplier", 1, joint=name)
            self.nums(mim, "offset", 1, joint=name)
        for tag, attrs in (("calibration", ("rising", "falling", "reference_position")),
                           ("safety_controller", ("soft_lower_limit", "soft_upper_limit", "k_position", "k_velocity"))):
            sub = el.find(tag)
            if sub is not None:
                for k in attrs:
                    self.nums(sub, k, 1, joint=name)
        return j

    # -- structure
    def structure(self, links: list[_Link], joints: list[_Joint]) -> tuple[set[str], str | None]:
        """Returns (moving links, root)."""
        if not links:
            self.add("URDF_NO_LINKS", "the robot has no <link>")
            return set(), None
        seen: dict[str, _Link] = {}
        for ln in links:
            if ln.name is None:
                continue
            if ln.name in seen:
                self.add("LINK_NAME_DUPLICATE", f"link {ln.name!r} is defined again (first at line {seen[ln.name].line})", line=ln.line, link=ln.name)
            else:
                seen[ln.name] = ln
        jseen: dict[str, _Joint] = {}
        for j in joints:
            if j.name is None:
                continue
            if j.name in jseen:
                self.add("JOINT_NAME_DUPLICATE", f"joint {j.name!r} is defined again (first at line {jseen[j.name].line})", line=j.line, joint=j.name)
            else:
                jseen[j.name] = j
        names = list(seen)
        has_parent: dict[str, list[str]] = {}
        children: dict[str, list[str]] = {n: [] for n in names}
        first_parent: dict[str, str] = {}
        touched: set[str] = set()
        for j in joints:
            ok = True
            if j.parent is not None and j.parent not in seen:
                self.add("JOINT_PARENT_UNKNOWN", f"parent {j.parent!r} is not a link", line=j.line, joint=j.name)
                ok = False
            if j.child is not None and j.child not in seen:
                self.add("JOINT_CHILD_UNKNOWN", f"child {j.child!r} is not a link", line=j.line, joint=j.name)
                ok = False
            if j.parent is not None and j.parent == j.child:
                self.add("JOINT_SELF_LOOP", f"parent and child are both {j.parent!r}", line=j.line, joint=j.name, link=j.child)
                touched.add(j.parent)
                continue
            for n in (j.parent, j.child):
                if n in seen:
                    touched.add(n)
            if j.child in seen:
                has_parent.setdefault(j.child, []).append(j.name or "?")
            if ok and j.parent and j.child:
                if j.child not in first_parent:
                    first_parent[j.child] = j.parent
                    children[j.parent].append(j.child)
            if j.mimic is not None and (j.mimic not in jseen or j.mimic == j.name):
                self.add("JOINT_MIMIC_UNKNOWN", f"<mimic joint={j.mimic!r}> names no other joint", line=j.line, joint=j.name)
        for child, js in has_parent.items():
            if len(js) > 1:
                self.add("LINK_MULTIPLE_PARENTS", f"link {child!r} is the child of joints {', '.join(map(repr, js))}",
                         line=seen[child].line, link=child, joints=js)
        roots = [n for n in names if n not in has_parent]
        if len(names) > 1:
            for n in roots:
                if n not in touched:
                    self.add("LINK_ORPHAN", f"link {n!r} is connected by no joint", line=seen[n].line, link=n)
        connected_roots = [n for n in roots if n in touched or len(names) == 1]
        # reachability and cycles
        reached: set[str] = set()
        stack = list(roots)
        while stack:
            n = stack.pop()
            if n in reached:
                continue
            reached.add(n)
            stack.extend(children.get(n, []))
        reported: set[str] = set()
        for n in names:
            if n in reached or n in reported or n not in first_parent:
                continue
            path: list[str] = []
            cur = n
            pos: dict[str, int] = {}
            while cur in first_parent and cur not in pos and cur not in reported:
                pos[cur] = len(path)
                path.append(cur)
                cur = first_parent[cur]
            if cur in pos:
                cyc = path[pos[cur]:]
                self.add("TREE_CYCLE", f"joints form a cycle through links {' -> '.join(cyc + [cyc[0]])}",
                         line=seen[cyc[0]].line, link=cyc[0], links=cyc)
            reported.update(path)
        if not roots:
            self.add("TREE_NO_ROOT", "every link has a parent joint: there is no root link")
            root = None
        elif len(connected_roots) > 1:
            self.add("TREE_MULTIPLE_ROOTS", f"several links have no parent: {', '.join(map(repr, connected_roots))}", roots=connected_roots)
            root = None
        elif len(roots) > 1 and not connected_roots:
            self.add("TREE_MULTIPLE_ROOTS", f"no joint connects the links {', '.join(map(repr, roots))}", roots=roots)
            root = None
        else:
            root = connected_roots[0] if connected_roots else roots[0]
        moving = {j.child for j in joints if j.child and j.type in MOVABLE_TYPES}
        return moving, root

    # -- inertials
    def inertials(self, links: list[_Link], moving: set[str]) -> None:
        for ln in links:
            if not ln.has_inertial or ln.name is None:
                continue
            bad = False
            if ln.mass is not None:
                if ln.mass < 0 or (ln.mass == 0 and ln.name in moving):
                    what = "a moving link" if ln.name in moving else "a link"
                    self.add("INERTIAL_MASS_NONPOSITIVE", f"mass {ln.mass!r} kg on {what}; an estimate replaces it",
                             line=ln.inertial_line, link=ln.name, action="replace_with_estimate", mass=ln.mass)
                    bad = True
                elif ln.mass == 0:
                    self.add("INERTIAL_MASS_ZERO_STATIC", "mass 0 on a static link (the simulator may treat it as fixed)",
                             line=ln.inertial_line, link=ln.name, mass=0.0)
            if ln.inertia is not None and not (ln.mass == 0 and ln.name not in moving and not any(ln.inertia)):
                code, lam = check_inertia(*ln.inertia)
                if code is not None:
                    why = ("an eigenvalue <= 0" if code == "INERTIA_NOT_POSITIVE_DEFINITE"
                           else "the largest principal moment exceeds the sum of the other two")
                    self.add(code, f"inertia (ixx ixy ixz iyy iyz izz) = {ln.inertia} kg*m^2 has eigenvalues "
                             f"{', '.join(f'{x:.6g}' for x in lam)}: {why}; an estimate replaces it (never balanced)",
                             line=ln.inertial_line, link=ln.name, action="replace_with_estimate",
                             eigenvalues=lam, inertia=list(ln.inertia))
                    bad = True
            if ln.mass is None or ln.inertia is None:
                bad = True
            if bad:
                self.result.replace_inertials.add(ln.name)

    # -- meshes
    def meshes(self, links: list[_Link]) -> None:
        assert self.folder is not None
        pol = self.policy
        scans: dict[Path, MeshScan | str] = {}
        total_faces = 0
        for ln in links:
            mass_role = "collision" if any(g.role == "collision" for g in ln.geoms) else "visual"
            link_moments = None
            link_has_volume = False
            link_mass_geoms = 0
            for g in ln.geoms:
                use: MeshUse = "collision" if g.role == "collision" else ("mass" if mass_role == "visual" else "visual")
                in_mass = g.role == mass_role
                if g.kind != "mesh":
                    if g.kind is not None and in_mass:
                        link_mass_geoms += 1
                        link_has_volume = link_has_volume or g.ok
                    continue
                ref = resolve_mesh_reference(self.folder, g.filename, extensions=pol.mesh_extensions, max_bytes=pol.max_mesh_bytes)
                g.ref = ref
                fname = g.filename or ""
                if ref.code is not None:
                    self.add(ref.code, f"<{g.role}> mesh {ref.message}", line=g.line, link=ln.name, role=g.role, filename=fname)
                    continue
                assert ref.path is not None
                self.result.mesh_paths[fname] = ref.path
                if not pol.check_mesh_contents:
                    continue
                scan = scans.get(ref.path)
                if scan is None:
                    try:
                        scan = scan_mesh_file(ref.path, max_bytes=pol.max_mesh_bytes, max_faces=pol.max_mesh_faces)
                    except OSError as exc:
                        scan = f"cannot read: {exc}"
                    scans[ref.path] = scan
                    if isinstance(scan, MeshScan):
                        total_faces += scan.n_faces
                        self.materials(ref.path, scan, ln.name)
                frel = self.rel(ref.path)
                at = f"{self.urdf_rel}:{g.line}"
                if isinstance(scan, str):
                    self.add("MESH_UNREADABLE", f"{scan} (referenced at {at})", file=frel, link=ln.name, role=g.role, urdf_line=g.line)
                    continue
                for code, msg in scan.defects.items():
                    if code == "MESH_ZERO_VOLUME":
                        self.add(code, f"{msg} (<{g.role}> at {at})", file=frel, link=ln.name, role=g.role, urdf_line=g.line)
                    else:
                        self.add(code, f"{msg}; used for {use} (<{g.role}> at {at})", file=frel, link=ln.name, use=use,
                                 role=g.role, urdf_line=g.line)
                if in_mass and g.ok:
                    link_mass_geoms += 1
                    if scan.moments is not None:
                        mom = _transform_moments(scan.moments, g.rpy, g.xyz, g.scale)
                        link_moments = mom if link_moments is None else (
                            link_moments[0] + mom[0], link_moments[1] + mom[1], link_moments[2] + mom[2])
            if link_mass_geoms and not link_has_volume and link_moments is not None and _is_flat(*link_moments):
                self.add("LINK_ZERO_VOLUME", f"all {mass_role} geometry of the link lies in one plane: zero volume; "
                         "mass must come from the surface area (shell), not the volume",
                         line=ln.line, link=ln.name, action="mass_from_area", role=mass_role)
        if total_faces > pol.max_total_faces:
            self.add("MESH_TOO_MANY_FACES", f"{total_faces} triangles over all meshes > cap {pol.max_total_faces}", file=self.urdf_rel)

    def materials(self, mesh: Path, scan: MeshScan, link: str | None) -> None:
        """mtllib files of an OBJ and the texture maps they name."""
        assert self.folder is not None
        for name in scan.mtllibs:
            ref = resolve_mesh_reference(self.folder, name, base=mesh.parent, extensions=(), max_bytes=self.policy.max_extra_bytes)
            self._material_ref(ref, mesh, link)
            if ref.path is None:
                continue
            try:
                text = _read_regular(ref.path, self.policy.max_extra_bytes).decode("utf-8", "replace")
            except OSError:
                continue
            for m in re.finditer(r"^\s*(?:map_\w+|bump|disp|decal|refl)\s+(?:-\S+\s+\S+\s+)*(\S.*?)\s*$", text, re.M):
                tex = resolve_mesh_reference(self.folder, m.group(1), base=ref.path.parent, extensions=())
                self._material_ref(tex, ref.path, link)

    def _material_ref(self, ref: MeshReference, owner: Path, link: str | None) -> None:
        if ref.code is None:
            return
        if ref.code in ("MESH_NOT_FOUND",):
            self.add("MESH_MATERIAL_MISSING", f"{self.rel(owner)} refers to {ref.filename!r}, which does not exist",
                     file=self.rel(owner), link=link)
        else:
            self.add("MESH_MATERIAL_OUTSIDE", f"{self.rel(owner)} refers to {ref.filename!r}: {ref.message}; it is ignored",
                     file=self.rel(owner), link=link, reason=ref.code)

    # -- extras
    def extras(self, link_names: set[str]) -> None:
        assert self.folder is not None
        sem = self.folder / partnet_mobility.SEMANTICS_NAME
        if os.path.lexists(sem):
            text = self._read_extra(sem)
            if text is not None:
                self.result.extra_files.append(sem)
                for ln in partnet_mobility.iter_semantics(text):
                    i, link, entry = ln.lineno, ln.link, ln.entry
                    if link is None or entry is None:
                        self.add("SEMANTICS_MALFORMED_LINE", f"line {i}: expected 'link_name joint_kind semantic_label', got {ln.text[:80]!r}",
                                 file="semantics.txt", line=i)
                        continue
                    self.result.semantics[link] = entry
                    if link_names and link not in link_names:
                        self.add("SEMANTICS_UNKNOWN_LINK", f"line {i}: no link {link!r} in the URDF", file="semantics.txt", line=i, link=link)
                    if entry.joint_kind not in SEMANTIC_KINDS:
                        self.add("SEMANTICS_UNKNOWN_KIND", f"line {i}: joint kind {entry.joint_kind!r} is not one of {', '.join(sorted(SEMANTIC_KINDS))}",
                                 file="semantics.txt", line=i, link=link)
        meta = self.folder / partnet_mobility.META_NAME
        if os.path.lexists(meta):
            text = self._read_extra(meta)
            if text is not None:
                self.result.extra_files.append(meta)
                try:
                    obj = json.loads(text)
                except ValueError as exc:
                    self.add("META_UNREADABLE", f"not JSON: {exc}", file="meta.json")
                    return
                if not isinstance(obj, dict):
                    self.add("META_UNREADABLE", "not a JSON object", file="meta.json")
                    return
                self.result.category = partnet_mobility.meta_category(obj)

    def _read_extra(self, path: Path) -> str | None:
        assert self.folder is not None
        ref = resolve_mesh_reference(self.folder, path.name, extensions=(), max_bytes=self.policy.max_extra_bytes)
        if ref.path is None:
            self.add("ASSET_FILE_NOT_REGULAR", f"{path.name}: {ref.message}", file=path.name)
            return None
        try:
            return _read_regular(ref.path, self.policy.max_extra_bytes).decode("utf-8", "replace")
        except OSError as exc:
            self.add("ASSET_FILE_NOT_REGULAR", f"{path.name}: {exc}", file=path.name)
            return None

    def run(self) -> ValidationResult:
        urdf = self.locate()
        if urdf is None:
            return self.result
        parsed = self.parse(urdf)
        if parsed is None:
            return self.result
        links, joints = parsed
        moving, root = self.structure(links, joints)
        self.inertials(links, moving)
        self.meshes(links)
        self.extras({ln.name for ln in links if ln.name})
        return self.result


def run_validation(asset: Path | str, policy: ValidationPolicy | None = None) -> ValidationResult:
    """Validate an asset and keep what was read (for the extraction stage).

    Args:
        asset: an asset folder (``mobility.urdf``, or the only ``*.urdf``
            not named ``reference_*``) or a URDF file (its folder is the asset
            folder).
        policy: severities and caps; default :data:`DEFAULT_POLICY`.

    Returns:
        A :class:`ValidationResult`. Never raises for bad input: an
        unexpected failure of the validator itself becomes an
        ``INTERNAL_ERROR`` finding.
    """
    v = _Validator(Path(asset), policy or DEFAULT_POLICY)
    try:
        return v.run()
    except Exception as exc:  # a bug must not crash a batch; it refuses the asset
        v.add("INTERNAL_ERROR", f"{type(exc).__name__}: {exc}")
        return v.result


def validate_asset(asset: Path | str, policy: ValidationPolicy | None = None) -> list[Finding]:
    """Every finding about an asset (folder or URDF file), in discovery order.

    Args:
        asset: as for :func:`run_validation`.
        policy: severities and caps; default :data:`DEFAULT_POLICY`.

    Returns:
        The findings; the asset is acceptable iff none has severity
        ``error`` (:func:`has_errors`). Never raises for bad input; never
        writes anything.
    """
    return run_validation(asset, policy).findings


def codes_markdown_table() -> str:
    """The table of codes (code, default severity, topic, meaning) as Markdown."""
    rows = ["| code | default severity | topic | meaning |", "|---|---|---|---|"]
    for code, info in CODES.items():
        sev = info.severity + (" (warning if only drawn)" if code in MESH_USE_DEPENDENT else "")
        rows.append(f"| `{code}` | {sev} | {info.topic} | {info.summary} |")
    return "\n".join(rows)
