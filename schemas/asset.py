"""Structured description of an input asset (the output of the extraction
stage), in the asset's own units and frames before any scale: lengths in the
file's units, angles rad, poses as URDF ``xyz`` (3,) and ``rpy`` (3,).
"""

from __future__ import annotations

from pathlib import Path
from typing import Literal

from asset2sim.schemas import Frozen, Strict

Vec3 = tuple[float, float, float]

JointType = Literal["revolute", "continuous", "prismatic", "fixed", "floating", "planar"]
GeometryKind = Literal["mesh", "box", "cylinder", "sphere"]


class Origin(Frozen):
    """A URDF ``<origin>``: translation ``xyz`` (m) and rotation ``rpy`` (rad)."""

    xyz: Vec3 = (0.0, 0.0, 0.0)
    rpy: Vec3 = (0.0, 0.0, 0.0)


class GeometryRef(Strict):
    """One ``<visual>`` or ``<collision>`` element of a link.

    For ``kind == "mesh"``: ``filename`` is the string written in the URDF,
    ``path`` the resolved file (absolute), ``scale`` the URDF mesh scale (3,).
    For primitives: ``size`` (box, (3,) m), ``radius`` and ``length`` (m).
    """

    role: Literal["visual", "collision"]
    kind: GeometryKind
    name: str | None = None
    origin: Origin = Origin()
    filename: str | None = None
    path: Path | None = None
    scale: Vec3 = (1.0, 1.0, 1.0)
    size: Vec3 | None = None
    radius: float | None = None
    length: float | None = None


class GivenInertial(Strict):
    """An ``<inertial>`` present in the input file (kept for reporting/validation).

    ``mass`` in kg; ``inertia`` (3, 3) in kg*m^2 about the COM in the frame of
    ``origin``.
    """

    mass: float
    origin: Origin = Origin()
    inertia: tuple[Vec3, Vec3, Vec3]


class LinkDesc(Strict):
    """A link: its geometry and (PartNet-Mobility) semantics."""

    name: str
    visuals: list[GeometryRef] = []
    collisions: list[GeometryRef] = []
    semantic_label: str | None = None
    """Part label from ``semantics.txt`` (e.g. ``lid``, ``drawer``, ``door``)."""
    semantic_joint: str | None = None
    """Joint kind from ``semantics.txt``: hinge, slider, free, heavy, static, junk."""
    given_inertial: GivenInertial | None = None

    @property
    def has_geometry(self) -> bool:
        return bool(self.visuals or self.collisions)


class JointDesc(Strict):
    """A joint. ``lower``/``upper`` in rad (revolute) or m (prismatic), ``None``
    when absent (continuous, fixed). ``axis`` (3,) unit vector in the joint frame.
    ``effort`` N or N*m, ``velocity`` rad/s or m/s, ``damping``/``friction`` as
    given in the file (SI units of the joint type), ``None`` when absent.
    """

    name: str
    type: JointType
    parent: str
    child: str
    origin: Origin = Origin()
    axis: Vec3 = (1.0, 0.0, 0.0)
    lower: float | None = None
    upper: float | None = None
    effort: float | None = None
    velocity: float | None = None
    damping: float | None = None
    friction: float | None = None

    @property
    def is_movable(self) -> bool:
        return self.type in ("revolute", "continuous", "prismatic")


class AssetDescription(Strict):
    """Everything the extraction stage knows about one input asset."""

    asset_id: str
    source_dir: Path
    urdf_path: Path
    robot_name: str
    links: list[LinkDesc]
    joints: list[JointDesc]
    root_link: str
    category: str | None = None
    """Category as given by the asset (``meta.json`` ``model_cat``) or the manifest."""
    input_hash: str = ""
    """sha256 over the URDF and every file it references (hex)."""
    staged_from: Path | None = None
    """The MJCF or USD file this asset was read from (then ``urdf_path`` is the URDF staged from it,
    :mod:`asset2sim.formats.staging`); None for a URDF input."""
    staging_notes: list[str] = []
    """What staging converted or left out, one line each (empty for a URDF input)."""

    def link(self, name: str) -> LinkDesc:
        for link in self.links:
            if link.name == name:
                return link
        raise KeyError(f"no link named {name!r} in {self.urdf_path}")

    def joint(self, name: str) -> JointDesc:
        for joint in self.joints:
            if joint.name == name:
                return joint
        raise KeyError(f"no joint named {name!r} in {self.urdf_path}")

    def movable_joints(self) -> list[JointDesc]:
        return [j for j in self.joints if j.is_movable]

    def parent_joint(self, link_name: str) -> JointDesc | None:
        return next((joint for joint in self.joints if joint.child == link_name), None)


class LinkGeometry(Strict):
    """Mesh analysis of one link at scale 1, in the link frame: ``volume`` m^3
    (exact when watertight, else by ``volume_method``), ``area`` m^2, bounding
    box and ``com`` (3,) m, ``inertia_solid`` / ``inertia_shell`` (3, 3)
    kg*m^2 per kg about ``com`` (filled solid, thin shell)."""

    link: str
    volume: float
    volume_method: str
    watertight: bool
    area: float
    bbox_min: Vec3
    bbox_max: Vec3
    com: Vec3
    inertia_solid: tuple[Vec3, Vec3, Vec3]
    inertia_shell: tuple[Vec3, Vec3, Vec3]
    n_meshes: int = 0
    n_faces: int = 0
    notes: list[str] = []

    @property
    def extents(self) -> Vec3:
        return tuple(b - a for a, b in zip(self.bbox_min, self.bbox_max))  # type: ignore[return-value]
