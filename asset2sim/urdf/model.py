"""The URDF model: the dataclasses a URDF reads into (:class:`UrdfModel` and its links, joints,
geometry, inertials, limits, materials), the joint-type tables, :class:`UrdfError` and :class:`Problem`,
and :func:`clone_model`.

Units: lengths in the file's units, angles rad, mass kg, inertia kg*m^2 about the COM in the
``<inertial><origin>`` frame, damping N*m*s/rad or N*s/m, friction N*m or N. Poses are (4, 4)
matrices, ``rpy`` as in :mod:`asset2sim.frames`.
"""

from __future__ import annotations

import copy
import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field, fields
from pathlib import Path
import numpy as np

from asset2sim.frames import axis_angle_matrix

#: Joint types of the URDF specification.
JOINT_TYPES = ("revolute", "continuous", "prismatic", "fixed", "floating", "planar")
#: Joints with one degree of freedom, in the order the engines list them.
MOVABLE = ("revolute", "continuous", "prismatic")
#: Joint types the simulators of :mod:`asset2sim.engines` build.
SIMULATED_JOINT_TYPES = MOVABLE + ("fixed",)
#: ``<geometry>`` children of the URDF specification.
GEOMETRY_KINDS = ("box", "cylinder", "sphere", "mesh")


class UrdfError(ValueError):
    """A URDF cannot be read. The message names the file, the line (when
    known) and the link or joint; ``code`` is stable (``XML_*``, ``NUMBER_*``,
    ``JOINT_*``, ``LINK_*``, ``TREE_*``, ``GEOMETRY_*``, ``INERTIAL_*``,
    ``URDF_*``)."""

    def __init__(self, message: str, *, code: str = "URDF_INVALID", source: str = "", line: int | None = None,
                 link: str | None = None, joint: str | None = None):
        self.code = code
        self.source = source
        self.line = line
        self.link = link
        self.joint = joint
        self.detail = message
        parts = [f"{source}:{line}" if line else source]
        parts.append(f"joint {joint!r}" if joint is not None else (f"link {link!r}" if link is not None else ""))
        super().__init__(": ".join([p for p in parts if p] + [message]))


@dataclass(frozen=True)
class Problem:
    """One problem met while reading (mode ``"collect"``): stable ``code``,
    ``message`` without the location, 1-based ``line`` in the URDF, the
    ``link`` or ``joint`` it is about, and the numbers behind it."""

    code: str
    message: str
    line: int | None = None
    link: str | None = None
    joint: str | None = None
    values: dict = field(default_factory=dict)


class _ArrayEq:
    """``==`` over the dataclass fields that take part in comparison, arrays
    compared with :func:`numpy.array_equal`."""

    def __eq__(self, other):
        if type(other) is not type(self):
            return NotImplemented
        for f in fields(self):  # type: ignore[arg-type]
            if not f.compare:
                continue
            a, b = getattr(self, f.name), getattr(other, f.name)
            if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
                if a is None or b is None or not np.array_equal(a, b):
                    return False
            elif a != b:
                return False
        return True

    __hash__ = None  # type: ignore[assignment]


def _eye() -> np.ndarray:
    return np.eye(4)


def _source_line():
    """The field of an element's source line (1-based; None when unknown), left out of comparisons."""
    return field(default=None, compare=False)


@dataclass(eq=False)
class UrdfMaterial(_ArrayEq):
    """``<material>``: ``rgba`` (4,) in [0, 1], ``texture`` the first
    ``<texture filename>`` (as PyBullet reads it), and their source lines."""

    name: str | None = None
    rgba: np.ndarray | None = None
    texture: str | None = None
    line: int | None = _source_line()
    texture_line: int | None = _source_line()


@dataclass(eq=False)
class UrdfInertial(_ArrayEq):
    """``<inertial>``: ``mass`` kg, ``origin`` (4, 4) COM frame in the link
    frame, ``inertia`` (3, 3) kg*m^2 about the COM in that frame's axes."""

    mass: float | None
    origin: np.ndarray = field(default_factory=_eye)
    inertia: np.ndarray | None = None
    line: int | None = _source_line()

    def com(self) -> np.ndarray:
        """Center of mass (3,) in the link frame, m."""
        return self.origin[:3, 3].copy()

    def inertia_in_link_axes(self) -> np.ndarray:
        """Inertia tensor (3, 3) about the center of mass in the link frame's axes."""
        r = self.origin[:3, :3]
        return r @ self.inertia @ r.T


@dataclass(eq=False)
class UrdfGeometry(_ArrayEq):
    """A ``<visual>`` or ``<collision>``: ``kind`` mesh / box / cylinder /
    sphere (None when unreadable), ``origin`` (4, 4) in the link frame. Mesh:
    ``filename`` as written, ``path`` resolved (not written), ``mesh_scale``
    as written (1 or 3 values). ``size`` (3,) m, ``radius`` / ``length`` m."""

    kind: str | None
    origin: np.ndarray = field(default_factory=_eye)
    name: str | None = None
    filename: str | None = None
    path: Path | None = field(default=None, compare=False)
    mesh_scale: np.ndarray | None = None
    size: np.ndarray | None = None
    radius: float | None = None
    length: float | None = None
    material: UrdfMaterial | None = None
    line: int | None = _source_line()
    complete: bool = field(default=True, compare=False, repr=False)
    """False when mode-collect reading could not read all of it."""

    @property
    def scale(self) -> np.ndarray:
        """Mesh scale (3,), dimensionless (ones when not written)."""
        return np.ones(3) if self.mesh_scale is None else np.broadcast_to(np.asarray(self.mesh_scale, float).ravel(), (3,)).copy()


@dataclass(eq=False)
class UrdfLink(_ArrayEq):
    """A link: ``inertial``, ``visuals`` and ``collisions`` in file order, and
    PyBullet's ``<contact>`` extension (child tag -> ``value``)."""

    name: str
    inertial: UrdfInertial | None = None
    collisions: list[UrdfGeometry] = field(default_factory=list)
    visuals: list[UrdfGeometry] = field(default_factory=list)
    contact: dict[str, float] = field(default_factory=dict)
    line: int | None = _source_line()

    @property
    def lateral_friction(self) -> float | None:
        """``<contact><lateral_friction value>``, or None."""
        return self.contact.get("lateral_friction")

    @property
    def restitution(self) -> float | None:
        """``<contact><restitution value>``, or None."""
        return self.contact.get("restitution")


@dataclass(eq=False)
class UrdfLimit(_ArrayEq):
    """``<limit>``: ``lower`` / ``upper`` rad or m, ``effort`` N*m or N,
    ``velocity`` rad/s or m/s; None when the attribute is absent."""

    lower: float | None = None
    upper: float | None = None
    effort: float | None = None
    velocity: float | None = None
    line: int | None = _source_line()
    unreadable: frozenset[str] = field(default=frozenset(), compare=False, repr=False)
    """Attributes written but not readable (mode collect; their value is None)."""


@dataclass(eq=False)
class UrdfDynamics(_ArrayEq):
    """``<dynamics>``: ``damping`` N*m*s/rad or N*s/m, ``friction`` N*m or N;
    None when the attribute is absent."""

    damping: float | None = None
    friction: float | None = None
    line: int | None = _source_line()


@dataclass(eq=False)
class UrdfMimic(_ArrayEq):
    """``<mimic joint multiplier offset>``: q = multiplier * q_joint + offset."""

    joint: str | None
    multiplier: float | None = None
    offset: float | None = None


def _or_zero(value: float | None) -> float:
    return 0.0 if value is None else float(value)


@dataclass(eq=False)
class UrdfJoint(_ArrayEq):
    """A joint as written: ``origin`` (4, 4) child frame in the parent frame,
    ``axis_xyz`` (3,) or None. The properties give the simulators' reading
    (unit axis, limits with the URDF defaults, damping and friction 0 when absent)."""

    name: str
    type: str
    parent: str
    child: str
    origin: np.ndarray = field(default_factory=_eye)
    axis_xyz: np.ndarray | None = None
    limit: UrdfLimit | None = None
    dynamics: UrdfDynamics | None = None
    mimic: UrdfMimic | None = None
    calibration: dict[str, float] | None = None
    safety_controller: dict[str, float] | None = None
    line: int | None = _source_line()

    @property
    def axis(self) -> np.ndarray:
        """Unit joint axis (3,) in the child frame (+x when not written or zero)."""
        a = np.array([1.0, 0.0, 0.0]) if self.axis_xyz is None else np.asarray(self.axis_xyz, float)
        n = float(np.linalg.norm(a))
        return a / n if n > 0 else np.array([1.0, 0.0, 0.0])

    @property
    def lower(self) -> float:
        """Lower limit, rad or m (-inf without a range)."""
        return self._limit("lower", -math.inf)

    @property
    def upper(self) -> float:
        """Upper limit, rad or m (+inf without a range)."""
        return self._limit("upper", math.inf)

    def _limit(self, key: str, unlimited: float) -> float:
        """``limit.<key>`` of a revolute or prismatic joint with a ``<limit>`` (0 when not written), else ``unlimited``."""
        if self.type in ("revolute", "prismatic") and self.limit is not None:
            return _or_zero(getattr(self.limit, key))
        return unlimited

    @property
    def damping(self) -> float:
        """Viscous damping, N*m*s/rad or N*s/m (0 when not written)."""
        return _or_zero(getattr(self.dynamics, "damping", None))

    @property
    def friction(self) -> float:
        """Coulomb friction, N*m or N (0 when not written)."""
        return _or_zero(getattr(self.dynamics, "friction", None))


@dataclass(eq=False)
class UrdfModel(_ArrayEq):
    """A URDF robot: ``links`` by name and ``joints`` in file order, top-level
    ``materials``, ``extensions`` (other top-level elements, kept verbatim),
    ``root`` the one link without a parent joint (else None), ``path``."""

    name: str
    links: dict[str, UrdfLink] = field(default_factory=dict)
    joints: list[UrdfJoint] = field(default_factory=list)
    materials: list[UrdfMaterial] = field(default_factory=list)
    extensions: list[ET.Element] = field(default_factory=list, compare=False)
    link_elements: list[UrdfLink] = field(default_factory=list, compare=False, repr=False)
    """Every ``<link>`` element read, unnamed and repeated ones included."""
    root: str | None = None
    path: Path | None = field(default=None, compare=False)

    @property
    def movable_joints(self) -> list[UrdfJoint]:
        """Revolute, continuous and prismatic joints in file order."""
        return [j for j in self.joints if j.type in MOVABLE]

    def joint(self, name: str) -> UrdfJoint:
        """The joint called ``name`` (KeyError when none)."""
        for j in self.joints:
            if j.name == name:
                return j
        raise KeyError(name)

    def parent_joint(self, link: str) -> UrdfJoint | None:
        """The joint whose child is ``link`` (None for the root)."""
        return next((j for j in self.joints if j.child == link), None)

    def children(self, link: str) -> list[UrdfJoint]:
        """Joints whose parent is ``link``, in file order."""
        return [j for j in self.joints if j.parent == link]

    def tree_order(self) -> list[str]:
        """Links depth-first from the root (children in joint file order)."""
        if self.root is None:
            return []
        out, stack, seen = [], [self.root], set()
        while stack:
            name = stack.pop()
            if name in seen:
                continue
            seen.add(name)
            out.append(name)
            stack.extend(j.child for j in reversed(self.children(name)))
        return out

    def total_mass(self) -> float:
        """Sum of the file's ``<inertial>`` masses, kg (links without one count 0)."""
        return float(sum(l.inertial.mass or 0.0 for l in self.links.values() if l.inertial is not None))

    def adjacent_pairs(self) -> set[frozenset[str]]:
        """Parent-child link pairs (every joint, fixed ones included)."""
        return {frozenset((j.parent, j.child)) for j in self.joints}

    def link_poses(self, q: dict[str, float] | None = None, root_pose: np.ndarray | None = None) -> dict[str, np.ndarray]:
        """World pose (4, 4) of every link for joint positions ``q`` (rad or m,
        default 0) and the root pose ``root_pose`` (default identity)."""
        q = q or {}
        poses = {self.root: np.eye(4) if root_pose is None else np.asarray(root_pose, float)}
        for name in self.tree_order():
            for j in self.children(name):
                t = poses[name] @ j.origin
                v = float(q.get(j.name, 0.0))
                m = np.eye(4)
                if j.type in ("revolute", "continuous"):
                    m[:3, :3] = axis_angle_matrix(j.axis, v)
                elif j.type == "prismatic":
                    m[:3, 3] = j.axis * v
                poses[j.child] = t @ m
        return poses


#: A URDF as a file or as a model already in memory (whose ``path`` is the file it was written to):
#: what a stage measures, so that a refine hands its candidate's model over instead of the stage
#: reading back the file the refine wrote.
UrdfSource = UrdfModel | Path | str


_MODEL_CLASSES: tuple[type, ...] = (UrdfMaterial, UrdfInertial, UrdfGeometry, UrdfLink, UrdfLimit, UrdfDynamics, UrdfMimic,
                                    UrdfJoint, UrdfModel)


def clone_model(model: UrdfModel) -> UrdfModel:
    """An independent copy of ``model``, as :func:`copy.deepcopy` makes it
    (objects reached twice copied once) but faster."""
    memo: dict[int, object] = {}

    def clone(x):
        if x is None or isinstance(x, (str, int, float, bool, Path, frozenset)):
            return x
        done = memo.get(id(x))
        if done is not None:
            return done
        if isinstance(x, np.ndarray):
            out = x.copy()
        elif type(x) in _MODEL_CLASSES:
            out = object.__new__(type(x))
            memo[id(x)] = out
            out.__dict__.update({k: clone(v) for k, v in x.__dict__.items()})
            return out
        elif isinstance(x, list):
            out = []
            memo[id(x)] = out
            out.extend(clone(v) for v in x)
            return out
        elif isinstance(x, dict):
            out = {}
            memo[id(x)] = out
            out.update((k, clone(v)) for k, v in x.items())
            return out
        elif isinstance(x, tuple):
            out = tuple(clone(v) for v in x)
        else:  # ET.Element and anything else
            out = copy.deepcopy(x)
        memo[id(x)] = out
        return out

    return clone(model)
