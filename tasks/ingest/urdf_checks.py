"""The URDF checks of the validator: encoding, elements, numbers, limits.

:class:`UrdfChecks` checks the URDF's encoding (:func:`encoding_problem`),
parses the validated XML tree (never the file again) into light records
(:class:`LinkRecord`, :class:`JointRecord`, :class:`GeomRecord`) while
checking every numeric attribute strictly
(:func:`asset2sim.urdf.parse_number_list`), element by element: links,
geometry, materials and textures, joints, limits (revolute within +-4 pi),
dynamics, mimic. The tree checks read the records
(:mod:`asset2sim.tasks.ingest.tree_checks`).
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from asset2sim import safexml
from asset2sim.tasks.ingest.findings import IMAGE_EXTENSIONS, JOINT_TYPES, MOVABLE_TYPES, Recorder
from asset2sim.tasks.ingest.mesh_paths import MeshReference, resolve_mesh_reference
from asset2sim.urdf import NumberError, parse_number_list

__all__ = ["GeomRecord", "JointRecord", "LinkRecord", "UrdfChecks", "encoding_problem"]




_XML_DECL_ENCODING = re.compile(rb"""^<\?xml[^>]*?encoding\s*=\s*["']([A-Za-z0-9._-]+)["']""")
_UTF8_NAMES = frozenset({"utf-8", "utf8", "us-ascii", "ascii"})


def _bom_problem(data: bytes) -> str | None:
    if data.startswith((b"\xff\xfe", b"\xfe\xff", b"\x00\x00\xfe\xff")):
        return "the URDF is UTF-16 or UTF-32 (byte-order mark)"
    return None


def encoding_problem(data: bytes) -> str | None:
    """Why URDF bytes are not UTF-8 as every URDF reader expects (None: they are).

    Accepted: UTF-8 with or without a byte-order mark; any declared encoding
    when every byte is ASCII (then all encodings agree). Refused: a UTF-16 or
    UTF-32 byte-order mark or NUL bytes (UTF-16/32 without one), bytes that
    are not valid UTF-8, and a declared encoding other than UTF-8/ASCII with
    non-ASCII bytes (names would differ between this validator and PyBullet,
    which reads the bytes as UTF-8).
    """
    bom = _bom_problem(data)
    if bom is not None:
        return bom
    if b"\x00" in data[:4096]:
        return "the URDF has NUL bytes: UTF-16 or UTF-32 without a byte-order mark"
    body = data[3:] if data.startswith(b"\xef\xbb\xbf") else data
    if body.isascii():
        return None
    try:
        body.decode("utf-8")
    except UnicodeDecodeError as exc:
        return f"the URDF is not valid UTF-8 (byte {exc.start}: {body[exc.start:exc.start + 4]!r})"
    m = _XML_DECL_ENCODING.match(body)
    if m is not None and m.group(1).decode().lower() not in _UTF8_NAMES:
        return f"the URDF declares encoding {m.group(1).decode()!r} and has non-ASCII bytes"
    return None


@dataclass
class GeomRecord:
    """One ``<visual>``/``<collision>`` as read (file units, rad)."""

    role: str
    kind: str | None
    line: int | None
    filename: str | None = None
    scale: tuple[float, float, float] = (1.0, 1.0, 1.0)
    xyz: tuple[float, float, float] = (0.0, 0.0, 0.0)
    rpy: tuple[float, float, float] = (0.0, 0.0, 0.0)
    ok: bool = True
    ref: MeshReference | None = None
    size: tuple[float, float, float] | None = None  # box extents of a primitive, m
    bounds: np.ndarray | None = None  # (2, 3) of a scanned mesh, file units


@dataclass
class LinkRecord:
    """One ``<link>`` as read: geometry and given inertial."""

    name: str | None
    line: int | None
    geoms: list[GeomRecord] = field(default_factory=list)
    inertial_line: int | None = None
    mass: float | None = None
    inertia: tuple[float, ...] | None = None
    has_inertial: bool = False


@dataclass
class JointRecord:
    """One ``<joint>`` as read: type, parent, child, origin, axis, limits, mimic leader."""

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
    xyz: tuple[float, float, float] = (0.0, 0.0, 0.0)
    rpy: tuple[float, float, float] = (0.0, 0.0, 0.0)
    limit_line: int | None = None



class UrdfChecks(Recorder):
    """URDF elements, numbers, structure and inertials (mixin of the validator)."""

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
    def parse(self, urdf: Path) -> tuple[list[LinkRecord], list[JointRecord]] | None:
        try:
            data = safexml.read_xml_file(urdf, self.policy.xml)
        except safexml.SafeXMLError as exc:
            self.add(exc.code, exc.detail, line=exc.line)
            return None
        # a byte-order mark decides before parsing; other encoding problems
        # only count for a well-formed document (garbage stays XML_MALFORMED)
        problem = _bom_problem(data)
        if problem is None:
            try:
                root = safexml.parse_xml_bytes(data, source=self.urdf_rel, limits=self.policy.xml)
            except safexml.SafeXMLError as exc:
                self.add(exc.code, exc.detail, line=exc.line)
                return None
            problem = encoding_problem(data)
        if problem is not None:
            self.add("URDF_ENCODING_UNSUPPORTED", f"{problem}; PyBullet and the other URDF readers take UTF-8: "
                     "re-encode the file as UTF-8 (e.g. iconv -f UTF-16 -t UTF-8)")
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
            if ref.path is not None and ref.path not in self.result.material_files:
                self.result.material_files.append(ref.path)
            if ref.code == "MESH_NOT_FOUND":
                self.add("TEXTURE_NOT_FOUND", f"<texture filename={fname!r}> does not exist", line=tex.sourceline, link=link)
            elif ref.code is not None:
                self.add("TEXTURE_PATH_REFUSED", f"<texture filename={fname!r}>: {ref.message} ({ref.code})", line=tex.sourceline,
                         link=link, reason=ref.code)

    def parse_link(self, el) -> LinkRecord:
        name = el.get("name")
        if not name:
            self.add("LINK_NAME_MISSING", "<link> without name", line=el.sourceline)
        ln = LinkRecord(name=name or None, line=el.sourceline)
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

    def parse_geom(self, el, role: str, link: str | None) -> GeomRecord:
        xyz, rpy, ok = self.origin(el, link=link)
        g = GeomRecord(role=role, kind=None, line=el.sourceline, xyz=xyz, rpy=rpy, ok=ok)
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
            vals: dict[str, tuple[float, ...]] = {}
            for attr, n in spec:
                v = self.nums(s, attr, n, link=link, required=True)
                if v is None:
                    g.ok = False
                elif any(x <= 0 for x in v):
                    self.add("GEOMETRY_SIZE_NONPOSITIVE", f"<{s.tag} {attr}={s.get(attr)!r}> must be > 0", line=s.sourceline, link=link)
                    g.ok = False
                else:
                    vals[attr] = v
            if g.ok:
                if s.tag == "box":
                    g.size = tuple(vals["size"])  # type: ignore[assignment]
                else:
                    r = vals["radius"][0]
                    g.size = (2 * r, 2 * r, vals["length"][0] if s.tag == "cylinder" else 2 * r)
        return g

    def parse_joint(self, el) -> JointRecord:
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
        j = JointRecord(name=name, line=el.sourceline, type=jtype, parent=parent or None, child=child or None)
        j.xyz, j.rpy, _ = self.origin(el, joint=name)
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
            j.limit_line = lim.sourceline
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
                    cap = self.policy.max_revolute_limit
                    if jtype == "revolute" and max(abs(lo_v), abs(hi_v)) > cap:
                        self.add("JOINT_LIMIT_IMPLAUSIBLE", f"revolute limits [{lo_v!r}, {hi_v!r}] rad go beyond +-{cap:.4g} rad "
                                 "(two turns): not a stop anyone means (degrees written as radians?); write the stop "
                                 "angles in radians, or type=\"continuous\" for a joint that turns freely",
                                 line=lim.sourceline, joint=name, lower=lo_v, upper=hi_v, cap=cap)
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
