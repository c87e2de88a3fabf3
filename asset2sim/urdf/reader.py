"""The URDF reader: :func:`read_urdf` (a file, remembered while unchanged) and
:func:`parse_urdf_bytes` give a :class:`~asset2sim.urdf.model.UrdfModel` (XML by
:mod:`asset2sim.safexml`) in mode ``"strict"``, ``"lenient"`` or ``"collect"`` (see
:mod:`asset2sim.urdf`); :func:`model_of` and :func:`path_of` take a model or a file.
"""

from __future__ import annotations

import math
import os
from pathlib import Path
from typing import Callable, Iterable, Literal

import numpy as np

from asset2sim import file_memo, safexml
from asset2sim.frames import pose_matrix
from asset2sim.urdf.model import (
    GEOMETRY_KINDS, JOINT_TYPES, Problem, UrdfDynamics, UrdfError, UrdfGeometry, UrdfInertial, UrdfJoint, UrdfLimit,
    UrdfLink, UrdfMaterial, UrdfMimic, UrdfModel, UrdfSource, clone_model,
)
from asset2sim.urdf.number_lists import NumberError, parse_number_list, parse_number_list_lenient

#: Joint types whose child moves relative to the parent (validation's notion).
_MOVING_TYPES = frozenset({"revolute", "continuous", "prismatic", "floating", "planar"})

Mode = Literal["strict", "lenient", "collect"]


#: Longest robot, link or joint name the reader hands on (characters): PyBullet's URDF importer ends the process (exit
#: 1, or a segmentation fault) on a joint name of about 2,000 characters. The validator reports longer names as
#: ``NAME_TOO_LONG`` (``asset2sim.tasks.ingest.findings.MAX_NAME_CHARS``, the same number).
MAX_NAME_CHARS = 256


class _Reader:
    """One pass over a parsed ``<robot>`` element (see the module docstring for the modes)."""

    #: Problems mode "strict" lets pass as remarks; every other problem refuses the file.
    STRICT_REMARKS = frozenset({
        "URDF_ROBOT_NAME_MISSING", "MESH_SCALE_ZERO", "MESH_SCALE_NEGATIVE", "GEOMETRY_SIZE_NONPOSITIVE", "JOINT_AXIS_NOT_UNIT",
        "JOINT_LIMIT_INCOMPLETE", "JOINT_LIMIT_REVERSED", "JOINT_LIMIT_EQUAL", "JOINT_DYNAMICS_NEGATIVE", "JOINT_EFFORT_NEGATIVE",
        "JOINT_VELOCITY_NEGATIVE",
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
        elif self.mode == "strict" and code not in self.STRICT_REMARKS:
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
            return (parse_number_list_lenient if self.mode == "lenient" else parse_number_list)(text, count)
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
        origin, g_ok = self._parse_origin(el, link=link)
        g = UrdfGeometry(kind=None, origin=origin, name=el.get("name"), line=_line(el))
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
        at = {"line": _line(s), "link": link}  # where the shape's problems are
        g.kind = s.tag
        if s.tag == "mesh":
            g.filename = s.get("filename")
            if not (g.filename or "").strip() and self.mode != "collect":
                self.problem("MESH_FILENAME_EMPTY", "<mesh> has no filename", **at)
            if g.filename and self.base is not None:
                g.path = resolve_mesh_path(g.filename, self.base)
            if s.get("scale") is not None:
                sc = self.nums(s, "scale", (1, 3), link=link)
                if sc is None:
                    g_ok = False
                else:
                    g.mesh_scale = np.asarray(sc, float)
                    if any(v == 0 for v in sc):
                        self.problem("MESH_SCALE_ZERO", f"mesh scale {s.get('scale')!r} has a zero component (the mesh collapses)",
                                     **at)
                        g_ok = False
                    elif any(v < 0 for v in sc):
                        self.problem("MESH_SCALE_NEGATIVE", f"mesh scale {s.get('scale')!r} mirrors the mesh", **at)
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
                    self.problem("GEOMETRY_SIZE_NONPOSITIVE", f"<{s.tag} {attr}={s.get(attr)!r}> must be > 0", **at)
                    g_ok = False
        g.complete = g_ok
        return g

    def _parse_inertial(self, el, link: str | None) -> UrdfInertial:
        origin, _ = self._parse_origin(el, link=link)
        ine = UrdfInertial(mass=None, origin=origin, line=_line(el))
        at = {"line": _line(el), "link": link, "action": "replace_with_estimate"}  # a missing mass or inertia
        m = el.find("mass")
        if m is None or m.get("value") is None:
            self.problem("INERTIAL_MASS_MISSING", "<inertial> has no <mass value=...>; an estimate replaces it", **at)
        else:
            ine.mass = self.num(m, "value", link=link)
        i = el.find("inertia")
        if i is None:
            self.problem("INERTIA_MISSING", "<inertial> has no <inertia>; an estimate replaces it", **at)
        else:
            diagonal = ("ixx", "iyy", "izz")
            vals = [self.num(i, k, default=None if k in diagonal else (0.0,), link=link, required=k in diagonal)
                    for k in ("ixx", "ixy", "ixz", "iyy", "iyz", "izz")]
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
        at = {"line": _line(el), "joint": name}  # where the joint's problems are
        if name is None:
            self.problem("JOINT_NAME_MISSING", "<joint> without name", **at)
        jtype = el.get("type")
        if jtype is None:
            self.problem("JOINT_TYPE_MISSING", "<joint> without type", **at)
        elif jtype not in JOINT_TYPES:
            self.problem("JOINT_TYPE_INVALID", f"type {jtype!r} is not one of {', '.join(JOINT_TYPES)}", **at)
        elif jtype not in self.joint_types:
            self.problem("JOINT_TYPE_UNSUPPORTED", f"joint type {jtype!r} is not supported ({', '.join(self.joint_types)})", **at)
        parent, child = ((e.get("link") if e is not None else None) for e in (el.find("parent"), el.find("child")))
        if not parent:
            self.problem("JOINT_PARENT_MISSING", "no <parent link=...>", **at)
        if not child:
            self.problem("JOINT_CHILD_MISSING", "no <child link=...>", **at)
        origin, _ = self._parse_origin(el, joint=name)
        j = UrdfJoint(name=name or "", type=jtype or "", parent=parent or "", child=child or "", origin=origin, line=_line(el))
        a = el.find("axis")
        if a is not None:
            ax = self.nums(a, "xyz", 3, default=(1.0, 0.0, 0.0), joint=name)
            if ax is not None:
                j.axis_xyz = np.asarray(ax, float)
                norm = math.hypot(*ax)  # no overflow for huge components (the validator bounds the length)
                if norm < 1e-12:
                    if jtype in _MOVING_TYPES:  # ignored by simulators on fixed joints
                        self.problem("JOINT_AXIS_ZERO", f"axis {a.get('xyz')!r} has zero length", line=_line(a), joint=name)
                elif abs(norm - 1.0) > 1e-6:
                    self.problem("JOINT_AXIS_NOT_UNIT", f"axis {a.get('xyz')!r} has length {norm:.6g}", line=_line(a), joint=name, norm=norm)
        lim = el.find("limit")
        if lim is not None:
            j.limit = self._parse_limit(lim, jtype, name)
        elif jtype in ("revolute", "prismatic"):
            self.problem("JOINT_LIMIT_MISSING", f"a {jtype} joint needs <limit lower upper>", **at)
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
        keys = ("lower", "upper", "effort", "velocity")
        at = {"line": _line(lim), "joint": name}  # where the limit's problems are
        out = UrdfLimit(line=_line(lim), **{k: self.num(lim, k, joint=name) for k in keys})
        out.unreadable = frozenset(k for k in keys if lim.get(k) is not None and getattr(out, k) is None)
        if jtype in ("revolute", "prismatic"):
            miss = [k for k in ("lower", "upper") if lim.get(k) is None]
            if miss:
                self.problem("JOINT_LIMIT_INCOMPLETE", f"<limit> without {' and '.join(miss)} (URDF default 0)", **at)
            lo_v, hi_v = (0.0 if k in miss else getattr(out, k) for k in ("lower", "upper"))  # URDF default 0; None: unreadable
            if lo_v is not None and hi_v is not None:
                if lo_v > hi_v:
                    self.problem("JOINT_LIMIT_REVERSED", f"lower {lo_v!r} > upper {hi_v!r}", **at, lower=lo_v, upper=hi_v)
                elif lo_v == hi_v:
                    self.problem("JOINT_LIMIT_EQUAL", f"lower == upper == {lo_v!r}: the joint cannot move", **at,
                                 lower=lo_v, upper=hi_v)
        for k, code in (("effort", "JOINT_EFFORT_NEGATIVE"), ("velocity", "JOINT_VELOCITY_NEGATIVE")):
            v = getattr(out, k)
            if v is not None and v < 0:
                self.problem(code, f"{k} {v!r} < 0", **at, **{k: v})
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
        children = {j.child for j in joints}
        roots = [n for n in model.links if n not in children]
        model.root = roots[0] if len(roots) == 1 else None
        if self.mode == "strict":
            self._check_tree(model, roots)
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

    def _check_tree(self, model: UrdfModel, roots: list[str]) -> None:
        """Mode strict: parent and child name links, no link has two parents,
        one root (of ``roots``, the links without a parent), and every link hangs from it."""
        children: set[str] = set()
        for j in model.joints:
            if j.parent not in model.links or j.child not in model.links:
                self.problem("JOINT_CHILD_UNKNOWN" if j.parent in model.links else "JOINT_PARENT_UNKNOWN",
                             "parent/child must name links of the file", line=j.line, joint=j.name)
            if j.child in children:
                self.problem("LINK_MULTIPLE_PARENTS", f"link {j.child!r} has two parent joints", line=j.line, joint=j.name)
            children.add(j.child)
        if len(roots) != 1:
            self.problem("TREE_ROOTS", f"expected one root link, found {roots}")
        if len(model.tree_order()) != len(model.links):
            self.problem("TREE_NOT_CONNECTED", "the joints do not form a tree over all links")


class _Stop(Exception):
    """Collect mode: nothing more can be read."""


def _line(el) -> int | None:
    return getattr(el, "sourceline", None)


def resolve_mesh_path(filename: str, base: Path) -> Path:
    """Absolute path of a mesh reference relative to ``base`` (``package://``
    and ``file://`` stripped; unchecked)."""
    return (Path(base) / filename.removeprefix("package://").removeprefix("file://")).resolve()


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
              on_problem: Callable[[Problem], None] | None = None) -> UrdfModel:
    """Read a URDF file into a :class:`UrdfModel` (mesh paths resolved against
    its folder; the default XML caps). Arguments as for :func:`parse_urdf_bytes`. An unchanged file
    read before with the same arguments (no ``on_problem``) is not parsed
    again: the caller gets its own copy (:data:`_READ_MEMO`).

    Raises:
        UrdfError: the file cannot be read (missing, not a regular file, too
            large: ``XML_*`` codes) or parsed, or (modes strict / lenient) its
            content is not acceptable; names the file, line and link or joint.
    """
    path = Path(path)
    key = None if on_problem is not None else (os.path.abspath(path), mode, tuple(joint_types))
    if key is not None:
        model = _READ_MEMO.get(key)
        if model is not None:
            model.path = path
            return model
    files = file_memo.identities([path])  # before reading: a file changed while read is not remembered
    try:
        data = safexml.read_xml_file(path)
    except safexml.SafeXMLError as exc:
        raise UrdfError(f"cannot read URDF: {exc.detail}", code=exc.code, source=str(path)) from None
    model = parse_urdf_bytes(data, source=str(path), base=path.parent, mode=mode, joint_types=joint_types,
                             on_problem=on_problem)
    if model is None:
        raise UrdfError("not a URDF (see the reported problems)", code="URDF_UNREADABLE", source=str(path))
    model.path = path
    if not model.name:
        model.name = path.stem
    if key is not None:
        _READ_MEMO.put(key, files, model)
    return model


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


#: Models read by :func:`read_urdf`, by (absolute path, mode, joint types).
_READ_MEMO: file_memo.FileMemo[UrdfModel] = file_memo.FileMemo(clone_model, max_entries=32)

