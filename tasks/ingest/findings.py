"""Finding codes, findings, the validation policy and the result of a run.

The vocabulary of :mod:`asset2sim.tasks.ingest.validate_input`: every code
with its default severity (:data:`CODES`, tabulated in ``docs/validation.md``
by :func:`codes_markdown_table`), :class:`Finding`, :class:`ValidationPolicy`
(what is an error, the caps), :class:`ValidationResult`, and
:class:`Recorder`, the base of the validator's check mixins (adds findings
with the policy's severity).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterable, Literal, Mapping

from pydantic import BaseModel, ConfigDict, Field

from asset2sim import safexml
from asset2sim.schemas.overlay import SCALE_RANGE, ValidationIssue
from asset2sim.prior_tables import MAX_PRIOR_DIM_M, load_priors

Severity = Literal["error", "warning", "info"]
Action = Literal["refuse", "replace_with_estimate", "mass_from_area", "ignore"]
MeshUse = Literal["collision", "mass", "visual"]

__all__ = [
    "Action",
    "CODES",
    "CodeInfo",
    "DEFAULT_POLICY",
    "Finding",
    "IMAGE_EXTENSIONS",
    "JOINT_TYPES",
    "MAX_COORDINATE",
    "MAX_LINKS",
    "MAX_MOVABLE_JOINTS",
    "MAX_REVOLUTE_LIMIT",
    "MAX_TEXTURE_BYTES",
    "MAX_TEXTURE_PIXELS",
    "MAX_TOTAL_TEXTURE_BYTES",
    "MAX_TOTAL_TEXTURE_PIXELS",
    "MAX_TOTAL_FACES",
    "MESH_EXTENSIONS",
    "MESH_USE_DEPENDENT",
    "MOVABLE_TYPES",
    "MeshUse",
    "Recorder",
    "SEMANTIC_KINDS",
    "SIMULATOR_MESH_EXTENSIONS",
    "Severity",
    "ValidationPolicy",
    "ValidationResult",
    "asset_size_range",
    "codes_markdown_table",
    "errors",
    "has_errors",
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
    "URDF_ENCODING_UNSUPPORTED": _c("error", "files", "the URDF is not UTF-8 (UTF-16/32, invalid UTF-8, or another declared encoding with non-ASCII bytes)"),
    "ASSET_FILE_NOT_REGULAR": _c("error", "files", "semantics.txt or meta.json is not a regular file inside the folder"),
    "ASSET_FILE_TOO_LARGE": _c("error", "files", "semantics.txt or meta.json is a regular file above the cap (max_extra_bytes, 1 MiB); not read"),
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
    "ASSET_NO_GEOMETRY": _c("error", "structure", "no link has a <visual> or <collision>: there is nothing to size, weigh or collide"),
    "URDF_TOO_MANY_LINKS": _c("error", "structure", "more links than the cap (128: PyBullet cannot load more)"),
    "URDF_TOO_MANY_MOVABLE_JOINTS": _c("warning", "structure", "more movable joints than 32: in the worst case (all links touching) refine may not finish within the flow's per-asset time limit, which then ends it"),
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
    "LINK_NAME_NOT_A_FILE_NAME": _c("warning", "structure", "a link name with path separators, '..', control or non-ASCII characters or over 64 characters: files made for it get a safe name (asset2sim.file_names)"),
    "LINK_FILE_NAMES_CLASH": _c("error", "structure", "two link names that give their files one safe name (only a crafted asset can)"),
    "JOINT_NAME_MISSING": _c("error", "structure", "a <joint> without name"),
    "JOINT_NAME_DUPLICATE": _c("error", "structure", "two joints with the same name"),
    "JOINT_TYPE_MISSING": _c("error", "structure", "a joint without type"),
    "JOINT_TYPE_INVALID": _c("error", "structure", "a type other than revolute, continuous, prismatic, fixed, floating, planar"),
    "JOINT_TYPE_UNSUPPORTED": _c("error", "structure", "a floating or planar joint: refine and its simulators model revolute, continuous, prismatic and fixed joints only"),
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
    "JOINT_MIMIC_UNSUPPORTED": _c("error", "structure", "a <mimic> joint: coupled joints are not modelled by refine (refused, not dropped)"),
    # joint values
    "JOINT_AXIS_ZERO": _c("error", "joints", "zero axis on a movable joint"),
    "JOINT_AXIS_NOT_UNIT": _c("info", "joints", "axis not of unit length (simulators normalize it)"),
    "JOINT_LIMIT_MISSING": _c("error", "joints", "revolute or prismatic joint without <limit>"),
    "JOINT_LIMIT_INCOMPLETE": _c("warning", "joints", "<limit> without lower or upper (URDF default 0)"),
    "JOINT_LIMIT_REVERSED": _c("error", "joints", "lower > upper"),
    "JOINT_LIMIT_EQUAL": _c("warning", "joints", "lower == upper: the joint cannot move"),
    "JOINT_LIMIT_IMPLAUSIBLE": _c("error", "joints", "revolute limit beyond +-4 pi (two turns), or prismatic travel beyond the object's size"),
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
    "MESH_FORMAT_UNSUPPORTED": _c("error", "mesh_paths", "a mesh format refine's simulator cannot load (PLY, OFF, GLB, GLTF; PyBullet reads OBJ, STL, DAE)"),
    "MESH_UNREADABLE": _c("error", "mesh_paths", "the mesh cannot be opened (permissions)"),
    "MESH_TOO_LARGE": _c("error", "mesh_contents", "mesh file above the byte cap"),
    "MESH_TOO_MANY_FACES": _c("error", "mesh_contents", "mesh above the face-count cap"),
    "MESH_MALFORMED": _c("error", "mesh_contents", "the mesh cannot be parsed"),
    "MESH_NO_FACES": _c("error", "mesh_contents", "the mesh has no face"),
    "MESH_NONFINITE_VERTEX": _c("error", "mesh_contents", "NaN or infinite vertex coordinates"),
    "MESH_COORDINATE_IMPLAUSIBLE": _c("error", "mesh_contents", "a vertex coordinate beyond +-2e5 file units (MAX_COORDINATE: 20 m even at the smallest overlay scale 1e-4); checked before any arithmetic"),
    "ASSET_SIZE_IMPLAUSIBLE": _c("error", "geometry", "the object's size (bounding box of all geometry at the zero pose) lies outside what any overlay scale in [1e-4, 1e4] can bring to a household size (asset_size_range)"),
    "MESH_BAD_INDEX": _c("error", "mesh_contents", "face indices out of range (or 0 in OBJ), faces with < 3 vertices"),
    "MESH_ZERO_AREA": _c("error", "mesh_contents", "every face is degenerate: the mesh has no surface"),
    "MESH_ZERO_VOLUME": _c("info", "mesh_contents", "all vertices in one plane (a sheet); fine when other pieces give volume"),
    "LINK_ZERO_VOLUME": _c("warning", "mesh_contents", "a link's whole mass geometry is flat: mass must come from area"),
    "MESH_MATERIAL_OUTSIDE": _c("warning", "mesh_paths", "an mtllib/texture path leaving the folder (not used, not copied; the statement is dropped from the output's copy of the OBJ/MTL)"),
    "MESH_MATERIAL_MISSING": _c("info", "mesh_paths", "an mtllib/texture file that does not exist"),
    "MESH_MATERIAL_BESIDE_TARGET": _c("info", "mesh_paths", "an OBJ reached through a symlink names an mtllib that lies beside the real file, not beside the link: loaders of the input miss it; the output copies it beside the mesh"),
    "MATERIAL_NOT_REGULAR_FILE": _c("error", "mesh_paths", "an mtllib/texture path (or its symlink target, anywhere) is a FIFO, device or socket"),
    "TEXTURE_TOO_LARGE": _c("error", "mesh_paths", "a texture above the file-size or pixel cap, per file (256 MiB, 8192 x 8192) or per asset (1 GiB, 4 x 8192 x 8192); read from the image header, nothing decoded"),
    "TEXTURE_UNREADABLE": _c("error", "mesh_paths", "a texture file that is not an image PIL can identify (PyBullet and the renderer would fail on it)"),
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
#: Mesh formats PyBullet's URDF importer loads (refine loads the input URDF in PyBullet).
SIMULATOR_MESH_EXTENSIONS = frozenset({".obj", ".stl", ".dae"})
#: PyBullet loads at most this many links (base included); measured: 128 load, 129 give an invalid body.
MAX_LINKS = 128
#: Movable (revolute, continuous, prismatic) joints per asset: refine's time grows about as N^2 in the worst
#: case (every link pair in contact), so a bound on N bounds one asset's time (benchmarks/bench_joint_cap.py,
#: docs/validation.md "Joint cap").
MAX_MOVABLE_JOINTS = 32
#: |revolute limit| above this (rad, two turns) cannot be meant as a stop.
MAX_REVOLUTE_LIMIT = 4.0 * math.pi
#: Total triangles per asset: refine's time and memory grow linearly (benchmarks/bench_mesh_cap.py, docs/validation.md).
MAX_TOTAL_FACES = 1_000_000
#: |vertex coordinate| of a mesh file above this (file units) cannot be meant:
#: even at the smallest overlay scale refine accepts (SCALE_RANGE[0] = 1e-4) the
#: vertex would lie more than MAX_PRIOR_DIM_M = 20 m (the largest dimension any
#: prior may give a household object) from its link's frame. 2e5. Checked
#: before any arithmetic on the vertices (1e308 would overflow).
MAX_COORDINATE = MAX_PRIOR_DIM_M / SCALE_RANGE[0]
#: Texture caps, from benchmarks/bench_texture_cap.py (PyBullet 3.2.x loading
#: object 103275 with one texture replaced; docs/validation.md "Texture caps"):
#: PyBullet's importer reads a texture file whole and holds about 2 bytes per
#: byte of file (256 MiB: +510 MiB, 0.5 s per load; 1 GiB: +2.0 GiB, 3.1 s;
#: 2 GiB: std::bad_alloc, the process dies), and decodes every texture at
#: every load, about 8.6 MiB and 29 ms per megapixel (8192 x 8192: +577 MiB,
#: 1.3 s; 16384 x 16384: +2.3 GiB, 7.7 s). Per file: 256 MiB (an 8192 x 8192
#: PNG fits), 8192 x 8192 pixels; per asset: 1 GiB and 4 x 8192 x 8192
#: pixels, about 2.3 GiB and 8 s per load at most, within the per-asset
#: memory budget (8 GiB, benchmarks/bench_mesh_cap.py) beside the face cap.
MAX_TEXTURE_BYTES = 256 * 1024 * 1024
MAX_TEXTURE_PIXELS = 8192 * 8192
MAX_TOTAL_TEXTURE_BYTES = 1024 * 1024 * 1024
MAX_TOTAL_TEXTURE_PIXELS = 4 * 8192 * 8192
IMAGE_EXTENSIONS = frozenset({".png", ".jpg", ".jpeg", ".bmp", ".tga", ".tif", ".tiff", ".gif"})
JOINT_TYPES = ("revolute", "continuous", "prismatic", "fixed", "floating", "planar")
MOVABLE_TYPES = frozenset({"revolute", "continuous", "prismatic", "floating", "planar"})
SEMANTIC_KINDS = frozenset({"hinge", "slider", "free", "heavy", "static", "junk"})


@functools.lru_cache(maxsize=1)
def asset_size_range() -> tuple[float, float]:
    """The sizes (file units) an asset may have for refine to find an overlay
    scale inside ``SCALE_RANGE`` of :mod:`asset2sim.schemas.overlay`.

    The size measure is the one the estimator scales by
    (``tasks.synthesize.estimate.choose_scale``): g = sqrt(e1 * e2), the
    geometric mean of the two largest extents of the object's bounding box.
    Refine's scale is s = G / g for a target G = sqrt(d1 * d2) of the
    category's (or a named variant's) dimensions times a size-class factor
    (``tasks.interpret.size_priors.target_size``). Over every category,
    variant and size class of the priors, G lies in [G_min, G_max]; some
    request can give s in [s_min, s_max] only when
    g in [G_min / s_max, G_max / s_min]. With the shipped priors:
    about [1.0e-6, 2.3e4] (USB stick "tiny" .. door "very large").
    The handheld gripper cap only lowers s and is category-specific: not
    part of this (request-independent) bound.

    Returns:
        (lowest, highest) g in file units.
    """
    pri = load_priors()
    factors = [sc.factor for sc in pri.size_classes.values()]
    targets: list[float] = []
    for cat in pri.categories.values():
        g = math.sqrt(cat.dims[0] * cat.dims[1])
        targets += [g * f for f in factors]
        for var in cat.variants:
            gv = math.sqrt(var.dims[0] * var.dims[1])
            own = pri.size_classes[var.size_class].factor
            targets += [gv] + [gv * f / own for f in factors]
    lo, hi = SCALE_RANGE
    return min(targets) / hi, max(targets) / lo


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
        max_total_faces: over all distinct mesh files of the asset (the
            time and memory bound of one refine, :data:`MAX_TOTAL_FACES`).
        mesh_extensions: mesh suffixes recognised (lower case, with the dot);
            others are ``MESH_EXTENSION_UNSUPPORTED``.
        simulator_mesh_extensions: the formats refine can load; a
            recognised mesh of another format is ``MESH_FORMAT_UNSUPPORTED``.
        max_links: links per URDF (:data:`MAX_LINKS`).
        max_movable_joints: revolute, continuous and prismatic joints per
            URDF (:data:`MAX_MOVABLE_JOINTS`).
        max_coordinate: |vertex coordinate| of a mesh file, file units
            (:data:`MAX_COORDINATE`).
        asset_size_range: (lowest, highest) size of the object, file units,
            as :func:`asset_size_range` measures it; None: that function's
            value (derived from the priors and the overlay's scale range).
        max_texture_bytes: per texture file (MTL maps, URDF ``<texture>``), bytes.
        max_texture_pixels: width x height per texture (image header).
        max_total_texture_bytes, max_total_texture_pixels: the same over
            every distinct texture map the asset's MTL files name.
        max_revolute_limit: |lower| and |upper| of a revolute joint, rad.
        max_prismatic_travel: |lower| and |upper| of a prismatic joint as a
            multiple of the object's size (the diagonal of the bounding box of
            all geometry at the zero configuration).
        check_mesh_contents: read meshes (False: paths only, much faster).
        max_extra_bytes: cap for semantics.txt and meta.json, bytes.
    """

    overrides: Mapping[str, Severity] = field(default_factory=dict)
    visual_mesh_defects: Severity = "warning"
    warnings_as_errors: bool = False
    xml: safexml.XMLLimits = safexml.DEFAULT_LIMITS
    max_mesh_bytes: int = 64 * 1024 * 1024
    max_mesh_faces: int = MAX_TOTAL_FACES
    max_total_faces: int = MAX_TOTAL_FACES
    mesh_extensions: frozenset[str] = MESH_EXTENSIONS
    simulator_mesh_extensions: frozenset[str] = SIMULATOR_MESH_EXTENSIONS
    max_links: int = MAX_LINKS
    max_movable_joints: int = MAX_MOVABLE_JOINTS
    max_coordinate: float = MAX_COORDINATE
    asset_size_range: tuple[float, float] | None = None
    max_texture_bytes: int = MAX_TEXTURE_BYTES
    max_texture_pixels: int = MAX_TEXTURE_PIXELS
    max_total_texture_bytes: int = MAX_TOTAL_TEXTURE_BYTES
    max_total_texture_pixels: int = MAX_TOTAL_TEXTURE_PIXELS
    max_revolute_limit: float = MAX_REVOLUTE_LIMIT
    max_prismatic_travel: float = 1.0
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



@dataclass
class ValidationResult:
    """Everything :func:`run_validation` learned.

    ``findings`` in discovery order; ``urdf`` the URDF path (None when not
    found); ``folder`` the asset folder; ``urdf_bytes`` the exact bytes that
    were validated (parse these, not the file again); ``mesh_paths`` URDF
    filename -> real path for every acceptable reference;
    ``replace_inertials`` links whose given inertial must be replaced by an
    estimate; ``semantics`` link -> (joint_kind, label); ``category`` from
    meta.json; ``extra_files`` semantics.txt and meta.json when read;
    ``material_files`` the real paths of the MTL files and texture maps the
    OBJ meshes name and of the URDF's ``<texture>`` files (those inside the
    folder that exist), for the input hash.
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
    material_files: list[Path] = field(default_factory=list)

    @property
    def errors(self) -> list[Finding]:
        return errors(self.findings)

    @property
    def ok(self) -> bool:
        return not has_errors(self.findings)


class Recorder:
    """Holds the findings of one run and adds them with the policy's severity
    (base of the check mixins of :mod:`asset2sim.tasks.ingest.validate_input`)."""

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



def codes_markdown_table() -> str:
    """The table of codes (code, default severity, topic, meaning) as Markdown."""
    rows = ["| code | default severity | topic | meaning |", "|---|---|---|---|"]
    for code, info in CODES.items():
        sev = info.severity + (" (warning if only drawn)" if code in MESH_USE_DEPENDENT else "")
        rows.append(f"| `{code}` | {sev} | {info.topic} | {info.summary} |")
    return "\n".join(rows)
