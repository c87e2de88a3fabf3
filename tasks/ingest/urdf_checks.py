"""The URDF checks of the validator (:class:`UrdfChecks`): the encoding, every problem the URDF reader
(:func:`asset2sim.urdf.parse_urdf_bytes`, mode ``"collect"``) meets as a finding, ``<texture>``
files and the bounds of the joints' and inertials' numbers.
"""

from __future__ import annotations

import math
import re
from pathlib import Path

from asset2sim import safexml
from asset2sim.tasks.ingest.findings import IMAGE_EXTENSIONS, Recorder
from asset2sim.tasks.ingest.mesh_checks import texture_problem
from asset2sim.tasks.ingest.mesh_paths import resolve_mesh_reference
from asset2sim.urdf import Problem, UrdfMaterial, UrdfModel, parse_urdf_bytes

__all__ = ["UrdfChecks", "encoding_problem", "link_name", "joint_name"]


_XML_DECL_ENCODING = re.compile(rb"""^<\?xml[^>]*?encoding\s*=\s*["']([A-Za-z0-9._-]+)["']""")
_UTF8_NAMES = frozenset({"utf-8", "utf8", "us-ascii", "ascii"})


def _bom_problem(data: bytes) -> str | None:
    if data.startswith((b"\xff\xfe", b"\xfe\xff", b"\x00\x00\xfe\xff")):
        return "the URDF is UTF-16 or UTF-32 (byte-order mark)"
    return None


def encoding_problem(data: bytes) -> str | None:
    """Why URDF bytes are not UTF-8 as every URDF reader expects (None: they are): a UTF-16/32 byte-order
    mark or NUL bytes, invalid UTF-8, or another declared encoding with non-ASCII bytes."""
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


def link_name(name: str) -> str | None:
    """A link or joint name as findings carry it: None for a missing or empty name."""
    return name or None


joint_name = link_name


class UrdfChecks(Recorder):
    """Reading the URDF, and the checks of its elements (mixin of the validator)."""

    def read(self, urdf: Path) -> UrdfModel | None:
        """Read ``urdf`` once, check its encoding, parse it (every problem a finding), check textures and
        revolute limits; sets ``result.urdf_bytes``. Returns the model, or None when nothing more can
        be checked."""
        try:
            data = safexml.read_xml_file(urdf, self.policy.xml)
        except safexml.SafeXMLError as exc:
            self.add(exc.code, exc.detail, line=exc.line)
            return None
        # a byte-order mark decides before parsing; other encoding problems
        # only count for a well-formed document (garbage stays XML_MALFORMED)
        problem = _bom_problem(data)
        problems: list[Problem] = []
        model = None
        if problem is None:
            model = parse_urdf_bytes(data, source=self.urdf_rel, mode="collect", on_problem=problems.append,
                                     limits=self.policy.xml)
            if model is None and problems and problems[-1].code != "URDF_ROOT_NOT_ROBOT":  # safexml refused the XML
                self._record(problems)
                return None
            problem = encoding_problem(data)
        if problem is not None:
            self.add("URDF_ENCODING_UNSUPPORTED", f"{problem}; PyBullet and the other URDF readers take UTF-8: "
                     "re-encode the file as UTF-8 (e.g. iconv -f UTF-16 -t UTF-8)")
            return None
        self.result.urdf_bytes = data
        self._record(problems)
        if model is None:  # root is not <robot>
            return None
        for ln in model.link_elements:
            for g in ln.visuals:
                if g.material is not None:
                    self.texture(g.material, link_name(ln.name))
        self.joint_numbers(model)
        for mat in model.materials:
            self.texture(mat, None)
        return model

    def _record(self, problems: list[Problem]) -> None:
        for p in problems:
            self.add(p.code, p.message, line=p.line, link=p.link, joint=p.joint, **p.values)

    def texture(self, mat: UrdfMaterial, link: str | None) -> None:
        """A ``<texture filename>`` must be a safe relative path to an image inside the folder."""
        fname = mat.texture
        if fname is None:
            return
        assert self.folder is not None
        ref = resolve_mesh_reference(self.folder, fname, extensions=IMAGE_EXTENSIONS, max_bytes=self.policy.max_mesh_bytes)
        if ref.path is not None and ref.path not in self.result.material_files:
            self.result.material_files.append(ref.path)
        problem = texture_problem(ref.path, self.policy.max_texture_bytes, self.policy.max_texture_pixels) if ref.code is None and ref.path else None
        if problem is not None:
            self.add(problem[0], f"<texture filename={fname!r}>: {problem[1]}", line=mat.texture_line, link=link)
        if ref.code == "MESH_NOT_FOUND":
            self.add("TEXTURE_NOT_FOUND", f"<texture filename={fname!r}> does not exist", line=mat.texture_line, link=link)
        elif ref.code is not None:
            self.add("TEXTURE_PATH_REFUSED", f"<texture filename={fname!r}>: {ref.message} ({ref.code})",
                     line=mat.texture_line, link=link, reason=ref.code)

    def joint_numbers(self, model: UrdfModel) -> None:
        """The numbers of every joint and inertial bounded, so that nothing the validator passes overflows or vanishes
        in refine's arithmetic: a movable joint's axis of length in ``policy.axis_length`` (``JOINT_AXIS_IMPLAUSIBLE``),
        revolute and continuous limits within ``policy.max_revolute_limit`` rad (``JOINT_LIMIT_IMPLAUSIBLE``; a missing
        one is 0, an unreadable one skips the joint; prismatic travel: :meth:`joint_travel`), every inertial's center of
        mass within ``policy.max_coordinate`` of its link (``INERTIAL_ORIGIN_IMPLAUSIBLE``). Origins of geometry and
        joints are bounded by the object's size (``ASSET_SIZE_IMPLAUSIBLE``)."""
        cap, (short, long) = self.policy.max_revolute_limit, self.policy.axis_length
        for j in model.joints:
            axis = j.axis_xyz
            if j.type in ("revolute", "continuous", "prismatic") and axis is not None:
                norm = math.hypot(*map(float, axis))
                if norm > long or 1e-12 <= norm < short:  # below 1e-12: JOINT_AXIS_ZERO, the reader's
                    self.add("JOINT_AXIS_IMPLAUSIBLE", f"axis xyz=({', '.join(f'{v:.6g}' for v in axis)}) has length "
                             f"{norm:.6g}, outside [{short:g}, {long:g}]: an axis is a direction, written as a unit vector "
                             "(e.g. 0 0 1)", line=j.line, joint=joint_name(j.name), norm=norm)
            lim = j.limit
            if j.type not in ("revolute", "continuous") or lim is None or lim.unreadable & {"lower", "upper"}:
                continue
            lo_v = 0.0 if lim.lower is None else lim.lower
            hi_v = 0.0 if lim.upper is None else lim.upper
            if max(abs(lo_v), abs(hi_v)) <= cap:
                continue
            fix = ('write the stop angles in radians, or type="continuous" for a joint that turns freely' if j.type == "revolute"
                   else "leave them out for a joint that turns freely (asset2sim reads them as its operating range)")
            self.add("JOINT_LIMIT_IMPLAUSIBLE", f"{j.type} limits [{lo_v!r}, {hi_v!r}] rad go beyond +-{cap:.4g} rad "
                     f"(two turns): not a range anyone means (degrees written as radians?); {fix}",
                     line=lim.line, joint=joint_name(j.name), lower=lo_v, upper=hi_v, cap=cap)
        for ln in model.link_elements:
            com = None if ln.inertial is None else ln.inertial.origin[:3, 3]
            if com is not None and max(map(abs, com)) > self.policy.max_coordinate:
                self.add("INERTIAL_ORIGIN_IMPLAUSIBLE", f"the center of mass <origin xyz=({', '.join(f'{v:.6g}' for v in com)})> "
                         f"lies beyond +-{self.policy.max_coordinate:g} file units of its link: outside any object asset2sim "
                         "can scale to a household size", line=ln.inertial.line, link=link_name(ln.name))
