"""The URDF writer: :func:`write_urdf` gives the bytes of a
:class:`~asset2sim.urdf.model.UrdfModel` (``read -> write -> read`` gives an equal model), laid out by a
:class:`UrdfStyle` (:data:`DEFAULT_STYLE`, yourdfpy's order; :data:`PARTNET_STYLE`, PartNet-Mobility's).
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import dataclass
from typing import Callable

import numpy as np

from asset2sim.frames import matrix_rpy
from asset2sim.urdf.model import UrdfGeometry, UrdfInertial, UrdfJoint, UrdfLink, UrdfMaterial, UrdfModel

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

    def vec(self, v) -> str | None:
        return None if v is None else " ".join(self.fmt(x) for x in np.asarray(v, float).ravel())

    def num(self, v: float | None) -> str | None:
        return None if v is None else self.fmt(v)

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
        if g.kind == "mesh":
            out.leaf(d, "mesh", (("filename", g.filename), ("scale", out.vec(g.mesh_scale))))
        elif g.kind is not None:
            out.leaf(d, g.kind, (("size", out.vec(g.size)), ("radius", out.num(g.radius)), ("length", out.num(g.length))))

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
            out.leaf(d, "limit", tuple((k, out.num(getattr(j.limit, k))) for k in keys))
        if j.dynamics is not None:
            out.leaf(d, "dynamics", (("damping", out.num(j.dynamics.damping)), ("friction", out.num(j.dynamics.friction))))
        if j.mimic is not None:
            out.leaf(d, "mimic", (("joint", j.mimic.joint), ("multiplier", out.num(j.mimic.multiplier)),
                                  ("offset", out.num(j.mimic.offset))))
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

