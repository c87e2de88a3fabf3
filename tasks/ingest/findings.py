"""Findings, the validation policy and its caps, the result of a run, and :class:`Recorder`, the base
of the validator's check mixins (codes: :mod:`asset2sim.tasks.ingest.finding_codes`).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterable, Literal, Mapping

from pydantic import BaseModel, ConfigDict, Field

from asset2sim import safexml
from asset2sim.urdf import MAX_NAME_CHARS
from asset2sim.schemas.overlay import SCALE_RANGE, ValidationIssue
from asset2sim.prior_tables import MAX_PRIOR_DIM_M, load_priors
from asset2sim.tasks.ingest.finding_codes import CODES, MESH_USE_DEPENDENT, Severity

Action = Literal["refuse", "replace_with_estimate", "mass_from_area", "ignore"]
MeshUse = Literal["collision", "mass", "visual"]

__all__ = [
    "Action", "CODES", "DEFAULT_POLICY", "Finding", "IMAGE_EXTENSIONS", "MAX_COORDINATE", "MAX_LINKS",
    "MAX_MOVABLE_JOINTS", "MAX_NAME_CHARS", "MAX_BUILT_FACES", "MAX_REVOLUTE_LIMIT", "AXIS_LENGTH", "MAX_INERTIAL", "MAX_TEXTURE_BYTES", "MAX_TEXTURE_PIXELS", "MAX_TOTAL_TEXTURE_BYTES",
    "MAX_TOTAL_TEXTURE_PIXELS", "MAX_TOTAL_FACES", "MESH_EXTENSIONS", "MESH_USE_DEPENDENT", "MOVABLE_TYPES", "MeshUse",
    "Recorder", "SEMANTIC_KINDS", "SIMULATOR_MESH_EXTENSIONS", "Severity", "ValidationPolicy", "ValidationResult",
    "asset_size_range", "errors", "has_errors",
]


MESH_EXTENSIONS = frozenset({".obj", ".stl", ".ply", ".off", ".glb", ".gltf", ".dae"})
#: Mesh formats PyBullet's URDF importer loads (refine loads the input URDF in PyBullet).
SIMULATOR_MESH_EXTENSIONS = frozenset({".obj", ".stl", ".dae"})
#: PyBullet loads at most this many links (base included).
MAX_LINKS = 128
#: Movable joints per asset (refine's time grows about as N^2; docs/design/validation.md "Joint cap").
MAX_MOVABLE_JOINTS = 32
#: Longest link, joint or robot name (characters; ``asset2sim.urdf.MAX_NAME_CHARS``, re-exported): PyBullet's URDF
#: importer ends the process (exit 1, nothing said; a segmentation fault in ``evaluate``) on a joint name of about
#: 2,000 characters and cannot load a 10,000-character link name; real assets' names are far shorter.
#: |revolute limit| above this (rad, two turns) cannot be meant as a stop.
MAX_REVOLUTE_LIMIT = 4.0 * math.pi
#: Lengths a joint axis may have (file units are none: an axis is a direction): simulators normalise it, but
#: ``1e308 1e308 0`` overflows the norm and ``1e-9 0 0`` loses the direction in float64 arithmetic done before
#: normalising (a sweep that cannot move the joint was measured on it); a unit vector written with any rounding
#: lies far inside.
AXIS_LENGTH = (1e-3, 1e3)
#: |mass| (kg) or |inertia entry| (kg*m^2; kg*mm^2 in a file drawn in millimetres: a 50 kg cabinet is 4e6) above
#: this is no object's (a million tonnes); an inertial of 1e308 overflowed the audit's and ``--keep-declared``'s
#: arithmetic to infinity.
MAX_INERTIAL = 1e9
#: Total triangles per asset (refine's time and memory grow linearly; docs/design/validation.md "Face cap").
MAX_TOTAL_FACES = 1_000_000
#: Triangles of a URDF as the simulators build them: every ``<visual>`` and ``<collision>`` mesh reference counts
#: (PyBullet builds each), so one file named many times counts as often; twice :data:`MAX_TOTAL_FACES`, so an
#: asset whose every mesh is both its link's visual and collision (PartNet-Mobility's layout) within the face cap
#: stays within this one (the dev set's largest: 482,452, the laptop 9912).
MAX_BUILT_FACES = 2 * MAX_TOTAL_FACES
#: |vertex coordinate| (file units) beyond which a vertex lies more than MAX_PRIOR_DIM_M (20 m) from its
#: link even at the smallest overlay scale (SCALE_RANGE[0]): 2e5.
MAX_COORDINATE = MAX_PRIOR_DIM_M / SCALE_RANGE[0]
#: Texture caps per file and per asset (PyBullet's memory and time per load; docs/design/validation.md "Texture caps").
MAX_TEXTURE_BYTES = 256 * 1024 * 1024
MAX_TEXTURE_PIXELS = 8192 * 8192
MAX_TOTAL_TEXTURE_BYTES = 1024 * 1024 * 1024
MAX_TOTAL_TEXTURE_PIXELS = 4 * 8192 * 8192
IMAGE_EXTENSIONS = frozenset({".png", ".jpg", ".jpeg", ".bmp", ".tga", ".tif", ".tiff", ".gif"})
MOVABLE_TYPES = frozenset({"revolute", "continuous", "prismatic", "floating", "planar"})
SEMANTIC_KINDS = frozenset({"hinge", "slider", "free", "heavy", "static", "junk"})


@functools.lru_cache(maxsize=1)
def asset_size_range() -> tuple[float, float]:
    """(lowest, highest) size g = sqrt(e1 * e2) (the two largest extents, file units) for which some
    category, variant and size class of the priors gives an overlay scale s = G / g inside
    ``SCALE_RANGE``: [G_min / s_max, G_max / s_min] (docs/design/validation.md "Size bounds").
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


class Finding(BaseModel):
    """One problem (or remark) about an input asset: ``file`` relative to the asset folder when inside
    it, ``line`` 1-based, ``link``/``joint`` the element (``None`` for file-level findings), ``action``
    what the pipeline does about it, ``values`` the numbers behind it (e.g. ``eigenvalues`` kg*m^2)."""

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

    @property
    def loc(self) -> str:
        """``file:line``, or ``file`` without a line."""
        return f"{self.file}:{self.line}" if self.line else self.file

    def describe(self) -> str:
        """One line: ``error CODE file:line joint 'j': message``."""
        return f"{self.severity} {self.code} {self.loc} {self.where}: {self.message}"

    def to_issue(self) -> ValidationIssue:
        """As the overlay schema's :class:`ValidationIssue` (for report.json)."""
        return ValidationIssue(code=self.code, severity=self.severity, where=self.where if self.where != "global" else self.loc,
                               message=f"{self.loc}: {self.message}",
                               fixed=self.action in ("replace_with_estimate", "mass_from_area"))


@dataclass(frozen=True)
class ValidationPolicy:
    """Decides each finding's severity, hence what refuses an asset, and the caps.

    Attributes:
        overrides: code -> severity, applied last (e.g. ``{"JOINT_LIMIT_EQUAL": "error"}``).
        visual_mesh_defects: severity of :data:`MESH_USE_DEPENDENT` defects on meshes only drawn.
        warnings_as_errors: every warning refuses the asset.
        xml: caps of the XML parser.
        max_mesh_bytes, max_mesh_faces: per mesh file, bytes and triangles.
        max_total_faces: triangles over all distinct mesh files of the asset.
        max_built_faces: triangles over every mesh reference (a file named twice counts twice).
        mesh_extensions: mesh suffixes recognised (lower case, with the dot).
        simulator_mesh_extensions: the formats refine can load.
        max_links, max_movable_joints: per URDF.
        max_coordinate: |vertex coordinate| of a mesh file, file units.
        asset_size_range: (lowest, highest) object size, file units; None: :func:`asset_size_range`.
        max_texture_bytes, max_texture_pixels: per texture file, bytes and width x height.
        max_total_texture_bytes, max_total_texture_pixels: the same over every distinct texture map.
        max_revolute_limit: |lower| and |upper| of a revolute or continuous joint, rad.
        axis_length: (shortest, longest) length of a movable joint's axis.
        max_inertial: |mass| (kg) and |inertia entries| (kg*m^2) of an ``<inertial>``.
        max_prismatic_travel: |lower| and |upper| of a prismatic joint / the object's diagonal at the zero pose.
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
    max_built_faces: int = MAX_BUILT_FACES
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
    axis_length: tuple[float, float] = AXIS_LENGTH
    max_inertial: float = MAX_INERTIAL
    max_prismatic_travel: float = 1.0
    check_mesh_contents: bool = True
    max_extra_bytes: int = 1024 * 1024

    def severity(self, code: str, use: MeshUse | None = None) -> Severity:
        """The severity of ``code`` under this policy (``use``: how the mesh is used, for mesh-content codes).

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


DEFAULT_POLICY = ValidationPolicy()


def errors(findings: Iterable[Finding]) -> list[Finding]:
    """The findings whose severity is ``error``."""
    return [f for f in findings if f.severity == "error"]


def has_errors(findings: Iterable[Finding]) -> bool:
    """True when any finding is an error."""
    return any(f.severity == "error" for f in findings)


@dataclass
class ValidationResult:
    """Everything :func:`run_validation` learned: ``findings`` in discovery order, ``urdf_bytes`` the
    exact bytes validated (parse these, not the file again), ``mesh_paths`` URDF filename -> real path
    of every acceptable reference, ``replace_inertials`` links whose given inertial an estimate must
    replace, ``semantics`` link -> (joint_kind, label), ``category`` from meta.json, ``extra_files``
    and ``material_files`` (MTL files, texture maps) for the input hash."""

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


class Recorder:
    """Holds the findings of one run and adds them with the policy's severity."""

    def __init__(self, asset: Path, policy: ValidationPolicy):
        self.asset = asset
        self.policy = policy
        self.findings: list[Finding] = []
        self.folder: Path | None = None
        self.urdf_rel = str(asset)
        self.result = ValidationResult(findings=self.findings, folder=None)

    def add(self, code: str, message: str, *, file: str | None = None, line: int | None = None, link: str | None = None,
            joint: str | None = None, use: MeshUse | None = None, action: Action | None = None, **values: Any) -> None:
        sev = self.policy.severity(code, use)
        self.findings.append(Finding(code=code, severity=sev, message=message, file=file if file is not None else self.urdf_rel,
                                     line=line, link=link, joint=joint, action=action or ("refuse" if sev == "error" else None),
                                     values=values))

    def rel(self, path: Path | str) -> str:
        if self.folder is not None and Path(path).is_relative_to(self.folder):
            return str(Path(path).relative_to(self.folder))
        return str(path)
