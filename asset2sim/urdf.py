"""The URDF model: one set of dataclasses, one reader, one writer.

Every module reads and writes URDF through here: :func:`read_urdf` /
:func:`parse_urdf_bytes` give a :class:`UrdfModel` (XML by
:mod:`asset2sim.safexml`), :func:`write_urdf` gives its bytes (``read -> write
-> read`` gives an equal model), :func:`scale_model` bakes in a uniform scale.

Reading modes: ``"strict"`` (default: finite decimal numbers, one tree over
all links, the elements each joint and geometry needs; the first problem
raises :class:`UrdfError` naming file, line and link or joint), ``"lenient"``
(raw third-party files: ``float`` numbers, structure unchecked) and
``"collect"`` (input validation: every problem goes to ``on_problem`` as a
:class:`Problem`, in the validator's order, and reading goes on).

Units: lengths in the file's units, angles rad, mass kg, inertia kg*m^2 about
the COM in the ``<inertial><origin>`` frame, damping N*m*s/rad or N*s/m,
friction N*m or N. Poses are (4, 4) matrices, ``rpy`` as in :mod:`asset2sim.frames`.
"""

from __future__ import annotations

import copy
import math
import os
import re
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Callable, Iterable, Literal

import numpy as np

from asset2sim import file_memo, safexml
from asset2sim.frames import axis_angle_matrix, matrix_rpy, pose_matrix

__all__ = [
    "GEOMETRY_KINDS", "JOINT_TYPES", "MOVABLE", "NumberError", "PARTNET_STYLE", "Problem", "SIMULATED_JOINT_TYPES",
    "UrdfDynamics", "UrdfError", "UrdfGeometry", "UrdfInertial", "UrdfJoint", "UrdfLimit", "UrdfLink", "UrdfMaterial",
    "UrdfMimic", "UrdfModel", "UrdfSource", "UrdfStyle", "model_of", "path_of", "parse_number_list", "parse_urdf_bytes", "read_urdf", "scale_model",
    "write_urdf"
]

#: Joint types of the URDF specification.
JOINT_TYPES = ("revolute", "continuous", "prismatic", "fixed", "floating", "planar")
#: Joints with one degree of freedom, in the order the engines list them.
MOVABLE = ("revolute", "continuous", "prismatic")
#: Joint types the simulators of :mod:`asset2sim.engines` build.
SIMULATED_JOINT_TYPES = MOVABLE + ("fixed",)
#: ``<geometry>`` children of the URDF specification.
GEOMETRY_KINDS = ("box", "cylinder", "sphere", "mesh")
#: Joint types whose child moves relative to the parent (validation's notion).
_MOVING_TYPES = frozenset({"revolute", "continuous", "prismatic", "floating", "planar"})

Mode = Literal["strict", "lenient", "collect"]


#: Longest robot, link or joint name the reader hands on (characters): PyBullet's URDF importer ends the process (exit
#: 1, or a segmentation fault) on a joint name of about 2,000 characters. The validator reports longer names as
#: ``NAME_TOO_LONG`` (``asset2sim.tasks.ingest.findings.MAX_NAME_CHARS``, the same number).
MAX_NAME_CHARS = 256


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


class NumberError(ValueError):
    """A numeric attribute is not acceptable; ``code`` is a ``NUMBER_*`` code."""

    def __init__(self, code: str, message: str):
        super().__init__(message)
        self.code = code


_DECIMAL = re.compile(r"[+-]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][+-]?[0-9]+)?\Z")
_NAN = {"nan", "+nan", "-nan", "nan(ind)", "-nan(ind)", "qnan", "snan"}
_INF = {"inf", "+inf", "-inf", "infinity", "+infinity", "-infinity", "1.#inf", "-1.#inf"}


def parse_number_list(text: str | None, count: int | tuple[int, ...]) -> tuple[float, ...]:
    """The finite floats of ``text``, a whitespace-separated list of decimal
    numbers, ``count`` of them (or one of a tuple of allowed counts).

    Raises:
        NumberError: with code NUMBER_EMPTY (empty or blank), NUMBER_NAN,
            NUMBER_INF, NUMBER_OVERFLOW (finite literal beyond float64),
            NUMBER_MALFORMED (anything but ``[+-]digits[.digits][e[+-]digits]``),
            NUMBER_COUNT (wrong number of values).
    """
    if text is None or not text.strip():
        raise NumberError("NUMBER_EMPTY", "empty value where a number is required")
    out = []
    for tok in text.split():
        low = tok.lower()
        if low in _NAN:
            raise NumberError("NUMBER_NAN", f"{tok!r} is NaN")
        if low in _INF:
            raise NumberError("NUMBER_INF", f"{tok!r} is infinite")
        if not _DECIMAL.match(tok):
            raise NumberError("NUMBER_MALFORMED", f"{tok!r} is not a decimal number")
        v = float(tok)
        if not math.isfinite(v):
            raise NumberError("NUMBER_OVERFLOW", f"{tok!r} overflows a 64-bit float")
        out.append(v)
    _check_count(out, text, count)
    return tuple(out)


def _check_count(values: list[float], text: str, count: int | tuple[int, ...]) -> None:
    allowed = (count,) if isinstance(count, int) else count
    if len(values) not in allowed:
        want = " or ".join(str(c) for c in allowed)
        raise NumberError("NUMBER_COUNT", f"{len(values)} value(s) in {text!r}, expected {want}")


def _parse_number_list_lenient(text: str | None, count: int | tuple[int, ...]) -> tuple[float, ...]:
    """``float`` of every token (NaN and infinities accepted), right count."""
    if text is None or not text.strip():
        raise NumberError("NUMBER_EMPTY", "empty value where a number is required")
    try:
        out = [float(tok) for tok in text.split()]
    except ValueError as exc:
        raise NumberError("NUMBER_MALFORMED", str(exc)) from None
    _check_count(out, text, count)
    return tuple(out)


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


@dataclass(eq=False)
class UrdfMaterial(_ArrayEq):
    """``<material>``: ``rgba`` (4,) in [0, 1], ``texture`` the first
    ``<texture filename>`` (as PyBullet reads it), and their source lines."""

    name: str | None = None
    rgba: np.ndarray | None = None
    texture: str | None = None
    line: int | None = field(default=None, compare=False)
    texture_line: int | None = field(default=None, compare=False)


@dataclass(eq=False)
class UrdfInertial(_ArrayEq):
    """``<inertial>``: ``mass`` kg, ``origin`` (4, 4) COM frame in the link
    frame, ``inertia`` (3, 3) kg*m^2 about the COM in that frame's axes."""

    mass: float | None
    origin: np.ndarray = field(default_factory=_eye)
    inertia: np.ndarray | None = None
    line: int | None = field(default=None, compare=False)

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
    line: int | None = field(default=None, compare=False)
    complete: bool = field(default=True, compare=False, repr=False)
    """False when mode-collect reading could not read all of it."""

    @property
    def scale(self) -> np.ndarray:
        """Mesh scale (3,), dimensionless (ones when not written)."""
        if self.mesh_scale is None:
            return np.ones(3)
        return np.broadcast_to(np.asarray(self.mesh_scale, float).ravel(), (3,)).copy()


@dataclass(eq=False)
class UrdfLink(_ArrayEq):
    """A link: ``inertial``, ``visuals`` and ``collisions`` in file order, and
    PyBullet's ``<contact>`` extension (child tag -> ``value``)."""

    name: str
    inertial: UrdfInertial | None = None
    collisions: list[UrdfGeometry] = field(default_factory=list)
    visuals: list[UrdfGeometry] = field(default_factory=list)
    contact: dict[str, float] = field(default_factory=dict)
    line: int | None = field(default=None, compare=False)

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
    line: int | None = field(default=None, compare=False)
    unreadable: frozenset[str] = field(default=frozenset(), compare=False, repr=False)
    """Attributes written but not readable (mode collect; their value is None)."""


@dataclass(eq=False)
class UrdfDynamics(_ArrayEq):
    """``<dynamics>``: ``damping`` N*m*s/rad or N*s/m, ``friction`` N*m or N;
    None when the attribute is absent."""

    damping: float | None = None
    friction: float | None = None
    line: int | None = field(default=None, compare=False)


@dataclass(eq=False)
class UrdfMimic(_ArrayEq):
    """``<mimic joint multiplier offset>``: q = multiplier * q_joint + offset."""

    joint: str | None
    multiplier: float | None = None
    offset: float | None = None


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
    line: int | None = field(default=None, compare=False)

    @property
    def axis(self) -> np.ndarray:
        """Unit joint axis (3,) in the child frame (+x when not written or zero)."""
        a = np.array([1.0, 0.0, 0.0]) if self.axis_xyz is None else np.asarray(self.axis_xyz, float)
        n = float(np.linalg.norm(a))
        return a / n if n > 0 else np.array([1.0, 0.0, 0.0])

    @property
    def lower(self) -> float:
        """Lower limit, rad or m (-inf without a range)."""
        if self.type in ("revolute", "prismatic") and self.limit is not None:
            return 0.0 if self.limit.lower is None else float(self.limit.lower)
        return -math.inf

    @property
    def upper(self) -> float:
        """Upper limit, rad or m (+inf without a range)."""
        if self.type in ("revolute", "prismatic") and self.limit is not None:
            return 0.0 if self.limit.upper is None else float(self.limit.upper)
        return math.inf

    @property
    def damping(self) -> float:
        """Viscous damping, N*m*s/rad or N*s/m (0 when not written)."""
        d = self.dynamics
        return 0.0 if d is None or d.damping is None else float(d.damping)

    @property
    def friction(self) -> float:
        """Coulomb friction, N*m or N (0 when not written)."""
        d = self.dynamics
        return 0.0 if d is None or d.friction is None else float(d.friction)


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


class _Reader:
    """One pass over a parsed ``<robot>`` element (see the module docstring for the modes)."""

    #: Problems that refuse the file in mode "strict" (the others are remarks).
    STRICT_FATAL = frozenset({
        "URDF_ROOT_NOT_ROBOT", "LINK_NAME_MISSING", "LINK_NAME_DUPLICATE", "JOINT_NAME_MISSING", "JOINT_TYPE_MISSING",
        "JOINT_TYPE_INVALID", "JOINT_TYPE_UNSUPPORTED", "JOINT_PARENT_MISSING", "JOINT_CHILD_MISSING", "JOINT_PARENT_UNKNOWN",
        "JOINT_CHILD_UNKNOWN", "LINK_MULTIPLE_PARENTS", "TREE_ROOTS", "TREE_NOT_CONNECTED", "JOINT_AXIS_ZERO",
        "JOINT_LIMIT_MISSING", "INERTIAL_MASS_MISSING", "INERTIA_MISSING", "GEOMETRY_MISSING", "MESH_FILENAME_EMPTY",
    })

    def __init__(self, source: str, base: Path | None, mode: Mode, joint_types: Iterable[str],
                 on_problem: Callable[[Problem], None] | None):
        if mode not in ("strict", "lenient", "collect"):
            raise ValueError(f"unknown URDF reading mode {mode!r}")
        if mode == "collect" and on_problem is None:
            raise ValueError("mode 'collect' needs on_problem")
        self.source = source
        self.base = base
        self.mode = mode
        self.joint_types = tuple(joint_types)
        self.on_problem = on_problem

    def problem(self, code: str, message: str, *, line: int | None = None, link: str | None = None,
                joint: str | None = None, **values) -> None:
        if self.mode == "collect":
            assert self.on_problem is not None
            self.on_problem(Problem(code, message, line, link, joint, values))
        elif self.mode == "strict" and code in self.STRICT_FATAL:
            raise UrdfError(message, code=code, source=self.source, line=line, link=link, joint=joint)

    def nums(self, el, attr: str, count, *, default=None, link=None, joint=None, required=False):
        """Parse ``el.get(attr)`` (``count`` values); ``default`` when absent
        (a problem when ``required``); None after a problem in mode collect."""
        text = el.get(attr)
        if text is None:
            if required and self.mode != "lenient":
                return self._bad_number("NUMBER_EMPTY", f"<{el.tag}> has no {attr}=", el, link, joint)
            return default
        try:
            if self.mode == "lenient":
                return _parse_number_list_lenient(text, count)
            return parse_number_list(text, count)
        except NumberError as exc:
            return self._bad_number(exc.code, f"<{el.tag} {attr}={text[:60]!r}>: {exc}", el, link, joint, attribute=attr)

    def _bad_number(self, code: str, message: str, el, link, joint, **values) -> None:
        """Mode collect: report the problem (the number reads as None); else raise UrdfError."""
        if self.mode != "collect":
            raise UrdfError(message, code=code, source=self.source, line=_line(el), link=link, joint=joint) from None
        self.problem(code, message, line=_line(el), link=link, joint=joint, **values)

    def num(self, el, attr: str, **kw) -> float | None:
        v = self.nums(el, attr, 1, **kw)
        return None if v is None else float(v[0])

    def _parse_origin(self, parent, *, link=None, joint=None) -> tuple[np.ndarray, bool]:
        """(4, 4) pose of ``parent``'s ``<origin>`` (identity when absent, no
        negative zeros) and whether it read cleanly."""
        o = parent.find("origin")
        if o is None:
            return np.eye(4), True
        xyz = self.nums(o, "xyz", 3, default=(0.0, 0.0, 0.0), link=link, joint=joint)
        rpy = self.nums(o, "rpy", 3, default=(0.0, 0.0, 0.0), link=link, joint=joint)
        ok = xyz is not None and rpy is not None
        return pose_matrix(xyz or (0.0, 0.0, 0.0), rpy or (0.0, 0.0, 0.0)) + 0.0, ok

    def _parse_material(self, el, link: str | None) -> UrdfMaterial:
        mat = UrdfMaterial(name=el.get("name"), line=_line(el))
        c = el.find("color")
        if c is not None:
            rgba = self.nums(c, "rgba", 4, link=link)
            mat.rgba = None if rgba is None else np.asarray(rgba, float)
        tex = el.find("texture")
        if tex is not None:
            mat.texture = tex.get("filename")
            mat.texture_line = _line(tex)
        return mat

    def _parse_geometry(self, el, role: str, link: str | None) -> UrdfGeometry:
        origin, ok = self._parse_origin(el, link=link)
        g = UrdfGeometry(kind=None, origin=origin, name=el.get("name"), line=_line(el))
        g_ok = ok
        geo = el.find("geometry")
        shapes = list(geo) if geo is not None else []
        known = len(shapes) == 1 and shapes[0].tag in GEOMETRY_KINDS
        if not known and not (self.mode == "lenient" and shapes):
            found = ", ".join(f"<{c.tag}>" for c in shapes) or "nothing"
            self.problem("GEOMETRY_MISSING", f"<{role}> needs exactly one of box, cylinder, sphere, mesh in <geometry> (found {found})",
                         line=_line(el), link=link)
            g.complete = False
            return g
        s = shapes[0]
        g.kind = s.tag
        if s.tag == "mesh":
            g.filename = s.get("filename")
            if not (g.filename or "").strip() and self.mode != "collect":
                self.problem("MESH_FILENAME_EMPTY", "<mesh> has no filename", line=_line(s), link=link)
            if g.filename and self.base is not None:
                g.path = resolve_mesh_path(g.filename, self.base)
            if s.get("scale") is not None:
                sc = self.nums(s, "scale", (1, 3), link=link)
                if sc is None:
                    g_ok = False
                else:
                    g.mesh_scale = np.asarray(sc, float)
                    sc3 = tuple(sc * 3) if len(sc) == 1 else sc
                    if any(v == 0 for v in sc3):
                        self.problem("MESH_SCALE_ZERO", f"mesh scale {s.get('scale')!r} has a zero component (the mesh collapses)",
                                     line=_line(s), link=link)
                        g_ok = False
                    elif any(v < 0 for v in sc3):
                        self.problem("MESH_SCALE_NEGATIVE", f"mesh scale {s.get('scale')!r} mirrors the mesh", line=_line(s), link=link)
        else:
            spec = {"box": (("size", 3),), "cylinder": (("radius", 1), ("length", 1)), "sphere": (("radius", 1),)}.get(s.tag)
            required = spec is not None
            if spec is None:  # lenient: an unknown shape keeps whatever sizes it has
                spec = tuple((a, 3 if a == "size" else 1) for a in ("size", "radius", "length") if s.get(a) is not None)
            for attr, n in spec:
                v = self.nums(s, attr, n, link=link, required=required)
                if v is None:
                    g_ok = False
                    continue
                if attr == "size":
                    g.size = np.asarray(v, float)
                else:
                    setattr(g, attr, float(v[0]))
                if any(x <= 0 for x in v):
                    self.problem("GEOMETRY_SIZE_NONPOSITIVE", f"<{s.tag} {attr}={s.get(attr)!r}> must be > 0", line=_line(s), link=link)
                    g_ok = False
        g.complete = g_ok
        return g

    def _parse_inertial(self, el, link: str | None) -> UrdfInertial:
        origin, _ = self._parse_origin(el, link=link)
        ine = UrdfInertial(mass=None, origin=origin, line=_line(el))
        m = el.find("mass")
        if m is None or m.get("value") is None:
            self.problem("INERTIAL_MASS_MISSING", "<inertial> has no <mass value=...>; an estimate replaces it",
                         line=_line(el), link=link, action="replace_with_estimate")
        else:
            ine.mass = self.num(m, "value", link=link)
        i = el.find("inertia")
        if i is None:
            self.problem("INERTIA_MISSING", "<inertial> has no <inertia>; an estimate replaces it",
                         line=_line(el), link=link, action="replace_with_estimate")
        else:
            vals = []
            for k in ("ixx", "ixy", "ixz", "iyy", "iyz", "izz"):
                dflt = (0.0,) if k in ("ixy", "ixz", "iyz") else None
                v = self.nums(i, k, 1, default=dflt, link=link, required=dflt is None)
                vals.append(None if v is None else float(v[0]))
            if all(v is not None for v in vals):
                ixx, ixy, ixz, iyy, iyz, izz = vals
                ine.inertia = np.array([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]], float)
        return ine

    def _parse_link(self, el) -> UrdfLink:
        name = el.get("name") or ""
        if not name:
            self.problem("LINK_NAME_MISSING", "<link> without name", line=_line(el))
        lname = name or None
        ln = UrdfLink(name=name, line=_line(el))
        visual_els = el.findall("visual")
        ln.visuals = [self._parse_geometry(g, "visual", lname) for g in visual_els]
        ln.collisions = [self._parse_geometry(g, "collision", lname) for g in el.findall("collision")]
        for g, g_el in zip(ln.visuals, visual_els):  # after the collisions: problems in the validator's order
            m = g_el.find("material")
            if m is not None:
                g.material = self._parse_material(m, lname)
        inert = el.find("inertial")
        if inert is not None:
            ln.inertial = self._parse_inertial(inert, lname)
        ct = el.find("contact")
        if ct is not None:
            for sub in ct:
                if isinstance(sub.tag, str) and sub.get("value") is not None:
                    v = self.num(sub, "value", link=lname)
                    if v is not None:
                        ln.contact[sub.tag] = v
        return ln

    def _parse_joint(self, el) -> UrdfJoint:
        name = el.get("name") or None
        if name is None:
            self.problem("JOINT_NAME_MISSING", "<joint> without name", line=_line(el))
        jtype = el.get("type")
        if jtype is None:
            self.problem("JOINT_TYPE_MISSING", "<joint> without type", line=_line(el), joint=name)
        elif jtype not in JOINT_TYPES:
            self.problem("JOINT_TYPE_INVALID", f"type {jtype!r} is not one of {', '.join(JOINT_TYPES)}", line=_line(el), joint=name)
        elif jtype not in self.joint_types:
            self.problem("JOINT_TYPE_UNSUPPORTED", f"joint type {jtype!r} is not supported ({', '.join(self.joint_types)})",
                         line=_line(el), joint=name)
        p, c = el.find("parent"), el.find("child")
        parent = p.get("link") if p is not None else None
        child = c.get("link") if c is not None else None
        if not parent:
            self.problem("JOINT_PARENT_MISSING", "no <parent link=...>", line=_line(el), joint=name)
        if not child:
            self.problem("JOINT_CHILD_MISSING", "no <child link=...>", line=_line(el), joint=name)
        origin, _ = self._parse_origin(el, joint=name)
        j = UrdfJoint(name=name or "", type=jtype or "", parent=parent or "", child=child or "", origin=origin, line=_line(el))
        a = el.find("axis")
        if a is not None:
            ax = self.nums(a, "xyz", 3, default=(1.0, 0.0, 0.0), joint=name)
            if ax is not None:
                j.axis_xyz = np.asarray(ax, float)
                norm = math.sqrt(sum(x * x for x in ax))
                if norm < 1e-12:
                    if jtype in _MOVING_TYPES:  # ignored by simulators on fixed joints
                        self.problem("JOINT_AXIS_ZERO", f"axis {a.get('xyz')!r} has zero length", line=_line(a), joint=name)
                elif abs(norm - 1.0) > 1e-6:
                    self.problem("JOINT_AXIS_NOT_UNIT", f"axis {a.get('xyz')!r} has length {norm:.6g}", line=_line(a), joint=name, norm=norm)
        lim = el.find("limit")
        if lim is not None:
            j.limit = self._parse_limit(lim, jtype, name)
        elif jtype in ("revolute", "prismatic"):
            self.problem("JOINT_LIMIT_MISSING", f"a {jtype} joint needs <limit lower upper>", line=_line(el), joint=name)
        dyn = el.find("dynamics")
        if dyn is not None:
            j.dynamics = UrdfDynamics(line=_line(dyn))
            for k in ("damping", "friction"):
                v = self.num(dyn, k, joint=name)
                setattr(j.dynamics, k, v)
                if v is not None and v < 0:
                    self.problem("JOINT_DYNAMICS_NEGATIVE", f"{k} {v!r} < 0", line=_line(dyn), joint=name, **{k: v})
        mim = el.find("mimic")
        if mim is not None:
            j.mimic = UrdfMimic(joint=mim.get("joint") or "", multiplier=self.num(mim, "multiplier", joint=name),
                                offset=self.num(mim, "offset", joint=name))
        for tag, attrs in (("calibration", ("rising", "falling", "reference_position")),
                           ("safety_controller", ("soft_lower_limit", "soft_upper_limit", "k_position", "k_velocity"))):
            sub = el.find(tag)
            if sub is not None:
                vals = {k: self.num(sub, k, joint=name) for k in attrs if sub.get(k) is not None}
                setattr(j, tag, {k: v for k, v in vals.items() if v is not None})
        return j

    def _parse_limit(self, lim, jtype: str | None, name: str | None) -> UrdfLimit:
        out = UrdfLimit(line=_line(lim))
        for k in ("lower", "upper", "effort", "velocity"):
            setattr(out, k, self.num(lim, k, joint=name))
        out.unreadable = frozenset(k for k in ("lower", "upper", "effort", "velocity")
                                   if lim.get(k) is not None and getattr(out, k) is None)
        if jtype in ("revolute", "prismatic"):
            if lim.get("lower") is None or lim.get("upper") is None:
                miss = [k for k in ("lower", "upper") if lim.get(k) is None]
                self.problem("JOINT_LIMIT_INCOMPLETE", f"<limit> without {' and '.join(miss)} (URDF default 0)", line=_line(lim), joint=name)
            lo_v = out.lower if out.lower is not None else (0.0 if lim.get("lower") is None else None)
            hi_v = out.upper if out.upper is not None else (0.0 if lim.get("upper") is None else None)
            if lo_v is not None and hi_v is not None:
                if lo_v > hi_v:
                    self.problem("JOINT_LIMIT_REVERSED", f"lower {lo_v!r} > upper {hi_v!r}", line=_line(lim), joint=name, lower=lo_v, upper=hi_v)
                elif lo_v == hi_v:
                    self.problem("JOINT_LIMIT_EQUAL", f"lower == upper == {lo_v!r}: the joint cannot move", line=_line(lim),
                                 joint=name, lower=lo_v, upper=hi_v)
        if out.effort is not None and out.effort < 0:
            self.problem("JOINT_EFFORT_NEGATIVE", f"effort {out.effort!r} < 0", line=_line(lim), joint=name, effort=out.effort)
        if out.velocity is not None and out.velocity < 0:
            self.problem("JOINT_VELOCITY_NEGATIVE", f"velocity {out.velocity!r} < 0", line=_line(lim), joint=name, velocity=out.velocity)
        return out

    def _parse_robot(self, root) -> UrdfModel:
        if root.tag != "robot":
            if self.mode == "collect":
                self.problem("URDF_ROOT_NOT_ROBOT", f"root element is <{root.tag}>, expected <robot>", line=_line(root))
                raise _Stop()
            raise UrdfError(f"root element is <{root.tag}>, not <robot>", code="URDF_ROOT_NOT_ROBOT", source=self.source,
                            line=_line(root))
        if not root.get("name"):
            self.problem("URDF_ROBOT_NAME_MISSING", "<robot> has no name", line=_line(root))
        link_list = [self._parse_link(el) for el in root.findall("link")]
        joints = [self._parse_joint(el) for el in root.findall("joint")]
        model = UrdfModel(name=root.get("name") or "", joints=joints, link_elements=link_list,
                          materials=[self._parse_material(el, None) for el in root.findall("material")])
        model.extensions = [el for el in root if isinstance(el.tag, str) and el.tag not in ("link", "joint", "material")]
        for ln in link_list:
            if not ln.name:
                continue
            if ln.name in model.links:
                if self.mode == "strict":
                    self.problem("LINK_NAME_DUPLICATE", f"link {ln.name!r} is defined again", line=ln.line, link=ln.name)
                continue
            model.links[ln.name] = ln
        if self.mode != "collect":  # (the validator reports it as a finding: NAME_TOO_LONG)
            self._check_name_lengths(model)
        if self.mode == "strict":
            self._check_tree(model)
        else:
            children = {j.child for j in joints}
            roots = [n for n in model.links if n not in children]
            model.root = roots[0] if len(roots) == 1 else None
        return model

    def _check_name_lengths(self, model: UrdfModel) -> None:
        """Modes strict and lenient: no robot, link or joint name longer than :data:`MAX_NAME_CHARS` (UrdfError
        ``NAME_TOO_LONG``), so no engine or renderer is handed one (PyBullet ends the process on them)."""
        for kind, items in (("robot", [(model.name, None)]), ("link", [(ln.name, ln.line) for ln in model.link_elements]),
                            ("joint", [(j.name, j.line) for j in model.joints])):
            for name, line in items:
                if name and len(name) > MAX_NAME_CHARS:
                    shown = f"{name[:28]}...{name[-28:]}"
                    raise UrdfError(f"{kind} name of {len(name)} characters > cap {MAX_NAME_CHARS} ({shown!r})", code="NAME_TOO_LONG",
                                    source=self.source, line=line)

    def _check_tree(self, model: UrdfModel) -> None:
        """Mode strict: parent and child name links, no link has two parents,
        one root, and every link hangs from it."""
        children: set[str] = set()
        for j in model.joints:
            if j.parent not in model.links or j.child not in model.links:
                self.problem("JOINT_CHILD_UNKNOWN" if j.parent in model.links else "JOINT_PARENT_UNKNOWN",
                             "parent/child must name links of the file", line=j.line, joint=j.name)
            if j.child in children:
                self.problem("LINK_MULTIPLE_PARENTS", f"link {j.child!r} has two parent joints", line=j.line, joint=j.name)
            children.add(j.child)
        roots = [n for n in model.links if n not in children]
        if len(roots) != 1:
            self.problem("TREE_ROOTS", f"expected one root link, found {roots}")
        model.root = roots[0]
        if len(model.tree_order()) != len(model.links):
            self.problem("TREE_NOT_CONNECTED", "the joints do not form a tree over all links")


class _Stop(Exception):
    """Collect mode: nothing more can be read."""


def _line(el) -> int | None:
    return getattr(el, "sourceline", None)


def resolve_mesh_path(filename: str, base: Path) -> Path:
    """Absolute path of a mesh reference relative to ``base`` (``package://``
    and ``file://`` stripped; unchecked)."""
    rel = filename[len("package://"):] if filename.startswith("package://") else filename
    rel = rel[len("file://"):] if rel.startswith("file://") else rel
    return (Path(base) / rel).resolve()


def parse_urdf_bytes(data: bytes, *, source: str = "<bytes>", base: Path | str | None = None, mode: Mode = "strict",
                     joint_types: Iterable[str] = JOINT_TYPES, on_problem: Callable[[Problem], None] | None = None,
                     limits: safexml.XMLLimits | None = None) -> UrdfModel | None:
    """Read URDF bytes into a :class:`UrdfModel`.

    Args:
        data: the document.
        source: what the bytes are (the file path), for messages.
        base: folder mesh filenames are relative to (None: ``path`` unset).
        mode: ``"strict"``, ``"lenient"`` or ``"collect"`` (module docstring).
        joint_types: joint types accepted in mode strict (e.g.
            :data:`SIMULATED_JOINT_TYPES` for the engines).
        on_problem: receives every :class:`Problem` in mode collect.
        limits: XML caps (:class:`asset2sim.safexml.XMLLimits`).

    Returns:
        The model; None in mode collect when the XML itself was refused or the
        root is not ``<robot>`` (the problem was reported).

    Raises:
        UrdfError: (modes strict and lenient) the XML is refused by
            :mod:`asset2sim.safexml` (``code`` ``XML_*``) or the content is
            not acceptable for the mode; the message names the file, line and
            link or joint.
    """
    reader = _Reader(source, None if base is None else Path(base), mode, joint_types, on_problem)
    try:
        root = safexml.parse_xml_bytes(data, source=source, limits=limits)
    except safexml.SafeXMLError as exc:
        if mode == "collect":
            reader.problem(exc.code, exc.detail, line=exc.line)
            return None
        raise UrdfError(f"cannot parse URDF: {exc.detail}", code=exc.code, source=source, line=exc.line) from None
    try:
        return reader._parse_robot(root)
    except _Stop:
        return None


def read_urdf(path: Path | str, *, mode: Mode = "strict", joint_types: Iterable[str] = JOINT_TYPES,
              on_problem: Callable[[Problem], None] | None = None, limits: safexml.XMLLimits | None = None) -> UrdfModel:
    """Read a URDF file into a :class:`UrdfModel` (mesh paths resolved against
    its folder). Arguments as for :func:`parse_urdf_bytes`. An unchanged file
    read before with the same arguments (no ``on_problem``) is not parsed
    again: the caller gets its own copy (:data:`_READ_MEMO`).

    Raises:
        UrdfError: the file cannot be read (missing, not a regular file, too
            large: ``XML_*`` codes) or parsed, or (modes strict / lenient) its
            content is not acceptable; names the file, line and link or joint.
    """
    path = Path(path)
    key = None if on_problem is not None else (os.path.abspath(path), mode, tuple(joint_types), limits)
    if key is not None:
        model = _READ_MEMO.get(key)
        if model is not None:
            model.path = path
            return model
    files = file_memo.identities([path])  # before reading: a file changed while read is not remembered
    try:
        data = safexml.read_xml_file(path, limits)
    except safexml.SafeXMLError as exc:
        raise UrdfError(f"cannot read URDF: {exc.detail}", code=exc.code, source=str(path)) from None
    model = parse_urdf_bytes(data, source=str(path), base=path.parent, mode=mode, joint_types=joint_types,
                             on_problem=on_problem, limits=limits)
    if model is None:
        raise UrdfError("not a URDF (see the reported problems)", code="URDF_UNREADABLE", source=str(path))
    model.path = path
    if not model.name:
        model.name = path.stem
    if key is not None:
        _READ_MEMO.put(key, files, model)
    return model


#: A URDF as a file or as a model already in memory (whose ``path`` is the file it was written to):
#: what a stage measures, so that a refine hands its candidate's model over instead of the stage
#: reading back the file the refine wrote.
UrdfSource = UrdfModel | Path | str


def model_of(source: UrdfSource, *, mode: Mode = "strict") -> UrdfModel:
    """The model of ``source``: a copy of a :class:`UrdfModel`, or :func:`read_urdf` of a file
    (``mode`` as there; a model is taken as it is).

    Raises:
        UrdfError: as :func:`read_urdf`.
    """
    return clone_model(source) if isinstance(source, UrdfModel) else read_urdf(source, mode=mode)


def path_of(source: UrdfSource) -> Path:
    """The file of ``source`` (an engine loads it): a model's ``path``, or the path given.

    Raises:
        UrdfError: a model that was never read from or written to a file (``URDF_NO_FILE``).
    """
    if isinstance(source, UrdfModel):
        if source.path is None:
            raise UrdfError("the URDF model has no file an engine could load", code="URDF_NO_FILE", source=source.name)
        return Path(source.path)
    return Path(source)


#: Models read by :func:`read_urdf`, by (absolute path, mode, joint types, XML limits).
_READ_MEMO: file_memo.FileMemo[UrdfModel] = file_memo.FileMemo(lambda m: clone_model(m), max_entries=32)

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


def _repr_number(x: float) -> str:
    return repr(float(x))


def _partnet_number(x: float) -> str:
    """Shortest round-trip text, integral values without ``.0``, no ``-0``."""
    x = float(x)
    if x == 0.0:
        return "0"
    s = repr(x)
    return s[:-2] if s.endswith(".0") else s


@dataclass(frozen=True)
class UrdfStyle:
    """How :func:`write_urdf` lays a model out (never what it says):
    ``number`` formats every float, ``indent`` one level, ``declaration`` the
    first line; ``partnet_order`` PartNet-Mobility's element and attribute
    order (each link followed by its parent joint) instead of yourdfpy's."""

    number: Callable[[float], str] = _repr_number
    indent: str = "  "
    declaration: str = "<?xml version='1.0' encoding='utf-8'?>"
    partnet_order: bool = False


DEFAULT_STYLE = UrdfStyle()
#: PartNet-Mobility's layout (tabs, ``<?xml version="1.0" ?>``, integral numbers without ``.0``).
PARTNET_STYLE = UrdfStyle(number=_partnet_number, indent="\t", declaration='<?xml version="1.0" ?>', partnet_order=True)


def _esc(text: str) -> str:
    return (text.replace("&", "&amp;").replace("<", "&lt;").replace(">", "&gt;").replace('"', "&quot;")
            .replace("\n", "&#10;").replace("\r", "&#13;").replace("\t", "&#9;"))


class _Out:
    """A tiny pretty-printing XML emitter (attributes in the given order)."""

    def __init__(self, style: UrdfStyle):
        self.style = style
        self.fmt = style.number
        self.lines: list[str] = []

    def vec(self, v) -> str:
        return " ".join(self.fmt(x) for x in np.asarray(v, float).ravel())

    @staticmethod
    def _attrs(attrs) -> str:
        return "".join(f' {k}="{_esc(str(v))}"' for k, v in attrs if v is not None)

    def leaf(self, depth: int, tag: str, attrs=()) -> None:
        self.lines.append(f"{self.style.indent * depth}<{tag}{self._attrs(attrs)}/>")

    def open(self, depth: int, tag: str, attrs=()) -> None:
        self.lines.append(f"{self.style.indent * depth}<{tag}{self._attrs(attrs)}>")

    def close(self, depth: int, tag: str) -> None:
        self.lines.append(f"{self.style.indent * depth}</{tag}>")

    def element(self, depth: int, tag: str, attrs, body: Callable[[int], None]) -> None:
        """``<tag>`` with children written by ``body`` (self-closing when none)."""
        start = len(self.lines)
        self.open(depth, tag, attrs)
        body(depth + 1)
        if len(self.lines) == start + 1:
            self.lines[start] = self.lines[start][:-1] + "/>"
        else:
            self.close(depth, tag)

    def raw(self, depth: int, el: ET.Element) -> None:
        """An element kept verbatim (an extension), children indented."""
        text = (el.text or "").strip()
        kids = [c for c in el if isinstance(c.tag, str)]
        attrs = list(el.attrib.items())
        if not kids and not text:
            self.leaf(depth, el.tag, attrs)
        elif not kids:
            self.lines.append(f"{self.style.indent * depth}<{el.tag}{self._attrs(attrs)}>{_esc(text)}</{el.tag}>")
        else:
            self.open(depth, el.tag, attrs)
            for c in kids:
                self.raw(depth + 1, c)
            self.close(depth, el.tag)


def _write_origin(out: _Out, depth: int, origin: np.ndarray) -> None:
    m = np.asarray(origin, float)
    xyz, rpy = m[:3, 3], matrix_rpy(m)
    if out.style.partnet_order:
        rot = None if not np.any(rpy) else out.vec(rpy)
        out.leaf(depth, "origin", (("rpy", rot), ("xyz", out.vec(xyz))))
    else:
        out.leaf(depth, "origin", (("xyz", out.vec(xyz)), ("rpy", out.vec(rpy))))


def _write_material(out: _Out, depth: int, mat: UrdfMaterial) -> None:
    def body(d: int) -> None:
        if mat.rgba is not None:
            out.leaf(d, "color", (("rgba", out.vec(mat.rgba)),))
        if mat.texture is not None:
            out.leaf(d, "texture", (("filename", mat.texture),))

    out.element(depth, "material", (("name", mat.name),), body)


def _write_shape(out: _Out, depth: int, g: UrdfGeometry) -> None:
    def body(d: int) -> None:
        f = out.fmt
        if g.kind == "mesh":
            scale = None if g.mesh_scale is None else out.vec(g.mesh_scale)
            out.leaf(d, "mesh", (("filename", g.filename), ("scale", scale)))
        elif g.kind is not None:
            out.leaf(d, g.kind, (
                ("size", None if g.size is None else out.vec(g.size)),
                ("radius", None if g.radius is None else f(g.radius)),
                ("length", None if g.length is None else f(g.length)),
            ))

    out.element(depth, "geometry", (), body)


def _write_geometry(out: _Out, depth: int, role: str, g: UrdfGeometry) -> None:
    def body(d: int) -> None:
        if out.style.partnet_order:
            _write_origin(out, d, g.origin)
        _write_shape(out, d, g)
        if not out.style.partnet_order:
            _write_origin(out, d, g.origin)
        if role == "visual" and g.material is not None:
            _write_material(out, d, g.material)

    out.element(depth, role, (("name", g.name),), body)


def _write_inertial(out: _Out, depth: int, ine: UrdfInertial) -> None:
    def body(d: int) -> None:
        f = out.fmt
        _write_origin(out, d, ine.origin)
        if ine.mass is not None:
            out.leaf(d, "mass", (("value", f(ine.mass)),))
        if ine.inertia is not None:
            i = ine.inertia
            out.leaf(d, "inertia", tuple((k, f(i[a, b])) for k, (a, b) in _INERTIA_KEYS))

    out.element(depth, "inertial", (), body)


_INERTIA_KEYS = (("ixx", (0, 0)), ("ixy", (0, 1)), ("ixz", (0, 2)), ("iyy", (1, 1)), ("iyz", (1, 2)), ("izz", (2, 2)))


def _write_link(out: _Out, depth: int, link: UrdfLink) -> None:
    def body(d: int) -> None:
        if link.inertial is not None:
            _write_inertial(out, d, link.inertial)
        for v in link.visuals:
            _write_geometry(out, d, "visual", v)
        for c in link.collisions:
            _write_geometry(out, d, "collision", c)
        if link.contact:
            out.element(d, "contact", (), lambda d2: [out.leaf(d2, k, (("value", out.fmt(v)),)) for k, v in link.contact.items()])

    out.element(depth, "link", (("name", link.name),), body)


def _num_or_none(out: _Out, v: float | None) -> str | None:
    return None if v is None else out.fmt(v)


def _write_joint(out: _Out, depth: int, j: UrdfJoint) -> None:
    def body(d: int) -> None:
        if out.style.partnet_order:
            _write_origin(out, d, j.origin)
            if j.axis_xyz is not None:
                out.leaf(d, "axis", (("xyz", out.vec(j.axis_xyz)),))
            out.leaf(d, "child", (("link", j.child),))
            out.leaf(d, "parent", (("link", j.parent),))
        else:
            out.leaf(d, "parent", (("link", j.parent),))
            out.leaf(d, "child", (("link", j.child),))
            _write_origin(out, d, j.origin)
            if j.axis_xyz is not None:
                out.leaf(d, "axis", (("xyz", out.vec(j.axis_xyz)),))
        if j.limit is not None:
            keys = ("lower", "upper", "effort", "velocity") if out.style.partnet_order else ("effort", "velocity", "lower", "upper")
            out.leaf(d, "limit", tuple((k, _num_or_none(out, getattr(j.limit, k))) for k in keys))
        if j.dynamics is not None:
            out.leaf(d, "dynamics", (("damping", _num_or_none(out, j.dynamics.damping)),
                                     ("friction", _num_or_none(out, j.dynamics.friction))))
        if j.mimic is not None:
            out.leaf(d, "mimic", (("joint", j.mimic.joint), ("multiplier", _num_or_none(out, j.mimic.multiplier)),
                                  ("offset", _num_or_none(out, j.mimic.offset))))
        for tag in ("calibration", "safety_controller"):
            vals = getattr(j, tag)
            if vals is not None:
                out.leaf(d, tag, tuple((k, out.fmt(v)) for k, v in vals.items()))

    out.element(depth, "joint", (("name", j.name), ("type", j.type)), body)


def write_urdf(model: UrdfModel, *, style: UrdfStyle = DEFAULT_STYLE, comment: str | None = None) -> bytes:
    """The URDF document (UTF-8 bytes) of ``model``: ``<robot>`` holding
    ``comment`` (an XML comment), the extensions, links, joints and top-level
    materials, one element per line. Origins are written as ``xyz`` and
    :func:`asset2sim.frames.matrix_rpy` of their (4, 4) matrices."""
    out = _Out(style)
    out.lines.append(style.declaration)
    out.open(0, "robot", (("name", model.name),))
    if comment is not None:
        out.lines.append(f"{style.indent}<!--{comment.replace('--', '- -')}-->")
    for el in model.extensions:
        out.raw(1, el)
    written: set[int] = set()
    for link in model.links.values():
        _write_link(out, 1, link)
        if style.partnet_order:  # each link followed by the joint that carries it
            for j in model.joints:
                if j.child == link.name and id(j) not in written:
                    _write_joint(out, 1, j)
                    written.add(id(j))
    for j in model.joints:
        if id(j) not in written:
            _write_joint(out, 1, j)
    for mat in model.materials:
        _write_material(out, 1, mat)
    out.close(0, "robot")
    return ("\n".join(out.lines) + "\n").encode("utf-8")


def _scale_translation(m: np.ndarray, s: float) -> np.ndarray:
    out = np.array(m, float)
    out[:3, 3] *= s
    return out


#: Joint types whose ``<limit>`` means something (ROS URDF specification,
#: wiki.ros.org/urdf/XML/joint: ``<limit>`` is required for revolute and
#: prismatic joints; continuous joints use its effort and velocity).
LIMITED_TYPES = ("revolute", "prismatic", "continuous")


def conform_limits(model: UrdfModel, effort: float | None = None, velocity: float | None = None) -> list[str]:
    """Make every ``<limit>`` of ``model`` (in place) fit its joint: joints of types without limits lose theirs,
    revolute and prismatic joints get one; a missing ``effort`` (N*m or N) / ``velocity`` (rad/s or m/s) gets
    the value given, and stays missing with None (the default: a limit keeps what its file declared; URDF
    readers that need both, such as ROS's urdfdom, then need them added). Returns a note per dropped limit."""
    notes: list[str] = []
    for j in model.joints:
        if j.type not in LIMITED_TYPES:
            if j.limit is not None:
                notes.append(f"joint {j.name!r} ({j.type}): <limit> dropped (a {j.type} joint has none)")
                j.limit = None
            continue
        if j.limit is None:
            if j.type == "continuous":
                continue
            j.limit = UrdfLimit()
        if j.limit.effort is None and effort is not None:
            j.limit.effort = float(effort)
        if j.limit.velocity is None and velocity is not None:
            j.limit.velocity = float(velocity)
    return notes


def scale_model(model: UrdfModel, s: float, *, geometry: bool = True, joints: bool = True,
                inertials: bool = True) -> UrdfModel:
    """Bake a uniform scale ``s`` (> 0) into ``model`` in place and return it:
    ``geometry`` origins and sizes, ``joints`` origins and prismatic limits,
    ``inertials`` COM and inertia (times ``s**2``; mass kept).

    Raises:
        ValueError: ``s`` is not a finite number > 0.
    """
    s = float(s)
    if not (math.isfinite(s) and s > 0):
        raise ValueError(f"scale must be a finite number > 0, got {s}")
    for link in model.links.values():
        for g in (link.visuals + link.collisions) if geometry else ():
            g.origin = _scale_translation(g.origin, s)
            if g.kind == "mesh":
                g.mesh_scale = g.scale * s
            if g.size is not None:
                g.size = np.asarray(g.size, float) * s
            for attr in ("radius", "length"):
                if getattr(g, attr) is not None:
                    setattr(g, attr, float(getattr(g, attr)) * s)
        if inertials and link.inertial is not None:
            link.inertial.origin = _scale_translation(link.inertial.origin, s)
            if link.inertial.inertia is not None:
                link.inertial.inertia = np.asarray(link.inertial.inertia, float) * s * s
    for j in model.joints if joints else ():
        j.origin = _scale_translation(j.origin, s)
        if j.type == "prismatic" and j.limit is not None:
            for attr in ("lower", "upper"):
                if getattr(j.limit, attr) is not None:
                    setattr(j.limit, attr, float(getattr(j.limit, attr)) * s)
    return model

