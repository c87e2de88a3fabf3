"""Small valid assets and a corpus of malformed ones derived from them.

Used by ``tests/tasks/test_malformed_corpus.py``, the hypothesis round-trip
test and ``benchmarks/loader_comparison.py``. Nothing here reads the dev
dataset: every file is generated.

The valid asset (:func:`build_valid`) is PartNet-Mobility-shaped:
``mobility.urdf``, meshes under ``meshes/`` (OBJ with an MTL and an image, a
binary STL), ``semantics.txt``, ``meta.json``. Its links: ``base`` (root,
closed box mesh), ``lid`` (revolute ``lid_hinge``), ``drawer`` (prismatic
``drawer_slide``, STL mesh) and ``handle`` (fixed to the drawer, box and
cylinder primitives). Every link has a valid ``<inertial>`` so MuJoCo can load
it too.

Each :class:`Case` of :data:`CASES` builds the valid asset and breaks one
thing; ``code`` is the finding the validator must report and ``refused``
whether the asset must be refused (a finding of severity error).
"""

from __future__ import annotations

import contextlib
import copy
import os
import socket
import struct
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

from asset2sim.file_names import file_stem

# ----------------------------------------------------------------------------- mesh files


def box_obj(x0=0.0, x1=1.0, y0=0.0, y1=1.0, z0=0.0, z1=1.0, mtllib: str | None = None) -> str:
    """A closed, outward-oriented axis-aligned box as OBJ text (8 v, 12 f)."""
    v = [(x, y, z) for z in (z0, z1) for y in (y0, y1) for x in (x0, x1)]
    # vertex numbering: 1 + ix + 2 iy + 4 iz
    quads = [(1, 3, 4, 2), (5, 6, 8, 7), (1, 2, 6, 5), (3, 7, 8, 4), (1, 5, 7, 3), (2, 4, 8, 6)]
    lines = [f"mtllib {mtllib}"] if mtllib else []
    lines += [f"v {x!r} {y!r} {z!r}" for x, y, z in v]
    if mtllib:
        lines.append("usemtl m0")
    for a, b, c, d in quads:
        lines.append(f"f {a} {b} {c}")
        lines.append(f"f {a} {c} {d}")
    return "\n".join(lines) + "\n"


def box_stl(x0=0.0, x1=1.0, y0=0.0, y1=1.0, z0=0.0, z1=1.0) -> bytes:
    """The same box as a binary STL."""
    v = [(x, y, z) for z in (z0, z1) for y in (y0, y1) for x in (x0, x1)]
    quads = [(1, 3, 4, 2), (5, 6, 8, 7), (1, 2, 6, 5), (3, 7, 8, 4), (1, 5, 7, 3), (2, 4, 8, 6)]
    tris = []
    for a, b, c, d in quads:
        tris += [(a, b, c), (a, c, d)]
    out = bytearray(b"asset2sim test box".ljust(80, b" "))
    out += struct.pack("<I", len(tris))
    for t in tris:
        out += struct.pack("<3f", 0.0, 0.0, 0.0)
        for i in t:
            out += struct.pack("<3f", *v[i - 1])
        out += b"\0\0"
    return bytes(out)


MTL = "newmtl m0\nKd 0.8 0.6 0.4\nmap_Kd ../images/tex.png\n"
PNG_1PX = bytes.fromhex(
    "89504e470d0a1a0a0000000d4948445200000001000000010806000000"
    "1f15c4890000000d49444154789c6360000002000154a24f5d0000000049454e44ae426082"
)

# ----------------------------------------------------------------------------- URDF model


@dataclass
class Geom:
    """One <visual>/<collision>; numbers are strings so tests can corrupt them."""

    kind: str = "mesh"  # mesh | box | cylinder | sphere
    filename: str | None = None
    scale: str | None = None
    size: str | None = None
    radius: str | None = None
    length: str | None = None
    xyz: str | None = None
    rpy: str | None = None
    name: str | None = None


@dataclass
class Inertial:
    mass: str | None = "1.0"
    ixx: str | None = "0.1"
    ixy: str | None = "0"
    ixz: str | None = "0"
    iyy: str | None = "0.1"
    iyz: str | None = "0"
    izz: str | None = "0.1"
    xyz: str | None = None
    with_mass: bool = True
    with_inertia: bool = True


@dataclass
class Link:
    name: str | None
    visuals: list[Geom] = field(default_factory=list)
    collisions: list[Geom] = field(default_factory=list)
    inertial: Inertial | None = field(default_factory=Inertial)


@dataclass
class Joint:
    name: str | None
    type: str | None
    parent: str | None
    child: str | None
    xyz: str | None = None
    rpy: str | None = None
    axis: str | None = None
    lower: str | None = None
    upper: str | None = None
    effort: str | None = None
    velocity: str | None = None
    damping: str | None = None
    friction: str | None = None
    with_limit: bool = True
    mimic: str | None = None


@dataclass
class Model:
    name: str | None = "corpus_object"
    links: list[Link] = field(default_factory=list)
    joints: list[Joint] = field(default_factory=list)

    def link(self, name: str) -> Link:
        return next(ln for ln in self.links if ln.name == name)

    def joint(self, name: str) -> Joint:
        return next(j for j in self.joints if j.name == name)


def _set(el: ET.Element, **attrs: str | None) -> ET.Element:
    for k, v in attrs.items():
        if v is not None:
            el.set(k, v)
    return el


def render_urdf(model: Model) -> str:
    """The URDF text of ``model`` (attributes escaped by ElementTree)."""
    robot = _set(ET.Element("robot"), name=model.name)
    for ln in model.links:
        le = _set(ET.SubElement(robot, "link"), name=ln.name)
        if ln.inertial is not None:
            ie = ET.SubElement(le, "inertial")
            if ln.inertial.xyz is not None:
                _set(ET.SubElement(ie, "origin"), xyz=ln.inertial.xyz)
            if ln.inertial.with_mass:
                _set(ET.SubElement(ie, "mass"), value=ln.inertial.mass)
            if ln.inertial.with_inertia:
                i = ln.inertial
                _set(ET.SubElement(ie, "inertia"), ixx=i.ixx, ixy=i.ixy, ixz=i.ixz, iyy=i.iyy, iyz=i.iyz, izz=i.izz)
        for role, geoms in (("visual", ln.visuals), ("collision", ln.collisions)):
            for g in geoms:
                ge = _set(ET.SubElement(le, role), name=g.name)
                if g.xyz is not None or g.rpy is not None:
                    _set(ET.SubElement(ge, "origin"), xyz=g.xyz, rpy=g.rpy)
                geo = ET.SubElement(ge, "geometry")
                if g.kind == "mesh":
                    _set(ET.SubElement(geo, "mesh"), filename=g.filename, scale=g.scale)
                elif g.kind == "box":
                    _set(ET.SubElement(geo, "box"), size=g.size)
                elif g.kind == "cylinder":
                    _set(ET.SubElement(geo, "cylinder"), radius=g.radius, length=g.length)
                elif g.kind == "sphere":
                    _set(ET.SubElement(geo, "sphere"), radius=g.radius)
    for j in model.joints:
        je = _set(ET.SubElement(robot, "joint"), name=j.name, type=j.type)
        if j.xyz is not None or j.rpy is not None:
            _set(ET.SubElement(je, "origin"), xyz=j.xyz, rpy=j.rpy)
        if j.parent is not None:
            _set(ET.SubElement(je, "parent"), link=j.parent)
        if j.child is not None:
            _set(ET.SubElement(je, "child"), link=j.child)
        if j.axis is not None:
            _set(ET.SubElement(je, "axis"), xyz=j.axis)
        if j.with_limit and any(v is not None for v in (j.lower, j.upper, j.effort, j.velocity)):
            _set(ET.SubElement(je, "limit"), lower=j.lower, upper=j.upper, effort=j.effort, velocity=j.velocity)
        if j.damping is not None or j.friction is not None:
            _set(ET.SubElement(je, "dynamics"), damping=j.damping, friction=j.friction)
        if j.mimic is not None:
            _set(ET.SubElement(je, "mimic"), joint=j.mimic)
    ET.indent(robot, "  ")
    return ET.tostring(robot, encoding="unicode") + "\n"


def valid_model() -> Model:
    """The small valid articulated object (see module docstring)."""
    base = Link(
        "base",
        visuals=[Geom(filename="meshes/base.obj", name="body")],
        collisions=[Geom(filename="meshes/base.obj")],
        inertial=Inertial(mass="2.0", ixx="0.2", iyy="0.2", izz="0.3", xyz="0.5 0.5 0.25"),
    )
    lid = Link(
        "lid",
        visuals=[Geom(filename="meshes/lid.obj", xyz="0 0 0", name="body")],  # a repeated visual name: PartNet quirk
        collisions=[Geom(filename="meshes/lid.obj")],
        inertial=Inertial(mass="0.3", ixx="0.02", iyy="0.02", izz="0.03"),
    )
    drawer = Link(
        "drawer",
        visuals=[Geom(filename="meshes/drawer.stl")],
        collisions=[Geom(filename="meshes/drawer.stl")],
        inertial=Inertial(mass="0.5", ixx="0.01", iyy="0.01", izz="0.015"),
    )
    handle = Link(
        "handle",
        visuals=[Geom(kind="cylinder", radius="0.01", length="0.1", rpy="1.5707963267948966 0 0")],
        collisions=[Geom(kind="box", size="0.02 0.1 0.02")],
        inertial=Inertial(mass="0.05", ixx="0.0001", iyy="0.0001", izz="0.0001"),
    )
    joints = [
        Joint("lid_hinge", "revolute", "base", "lid", xyz="0 1 0.5", axis="1 0 0",
              lower="-1.5", upper="0", effort="10", velocity="1", damping="0.1", friction="0.05"),
        Joint("drawer_slide", "prismatic", "base", "drawer", xyz="1 0.1 0.05", axis="1 0 0",
              lower="0", upper="0.3", effort="20", velocity="0.5"),
        Joint("handle_fix", "fixed", "drawer", "handle", xyz="0.2 0.4 0.1"),
    ]
    return Model(links=[base, lid, drawer, handle], joints=joints)


def write_asset(folder: Path, model: Model | None = None, urdf_text: str | None = None) -> Path:
    """Write the valid asset's files (meshes, extras) and ``model``'s URDF
    (or ``urdf_text`` verbatim) into ``folder``. Returns the folder."""
    folder = Path(folder)
    (folder / "meshes").mkdir(parents=True, exist_ok=True)
    (folder / "images").mkdir(exist_ok=True)
    (folder / "meshes" / "base.obj").write_text(box_obj(0, 1, 0, 1, 0, 0.5, mtllib="base.mtl"))
    (folder / "meshes" / "base.mtl").write_text(MTL)
    (folder / "images" / "tex.png").write_bytes(PNG_1PX)
    (folder / "meshes" / "lid.obj").write_text(box_obj(0, 1, -1, 0, 0, 0.05))
    (folder / "meshes" / "drawer.stl").write_bytes(box_stl(-0.2, 0.2, 0, 0.8, 0, 0.3))
    (folder / "semantics.txt").write_text("base static body\nlid hinge lid\ndrawer slider drawer\nhandle static handle\n")
    (folder / "meta.json").write_text('{"model_cat": "StorageFurniture", "note": "generated by tests/corpus_builder.py"}\n')
    text = urdf_text if urdf_text is not None else render_urdf(model or valid_model())
    (folder / "mobility.urdf").write_text(text)
    return folder


def build_valid(folder: Path) -> Path:
    """Write the valid asset into ``folder``."""
    return write_asset(folder)


# ----------------------------------------------------------------------------- cases


@dataclass(frozen=True)
class Case:
    """One malformed asset: ``build(folder)`` writes it; the validator must
    report ``code`` (with severity ``error`` iff ``refused``)."""

    name: str
    topic: str
    code: str
    build: Callable[[Path], Path]
    refused: bool = True
    policy: dict | None = None
    """ValidationPolicy keyword overrides (e.g. lower caps)."""
    note: str = ""


def _model_case(fn: Callable[[Model], None]) -> Callable[[Path], Path]:
    def build(folder: Path) -> Path:
        m = valid_model()
        fn(m)
        return write_asset(folder, m)

    return build


def _text_case(fn: Callable[[str], str]) -> Callable[[Path], Path]:
    def build(folder: Path) -> Path:
        return write_asset(folder, urdf_text=fn(render_urdf(valid_model())))

    return build


def _raw_urdf(data: bytes) -> Callable[[Path], Path]:
    def build(folder: Path) -> Path:
        write_asset(folder)
        (folder / "mobility.urdf").write_bytes(data)
        return folder

    return build


def _files_case(fn: Callable[[Path], None], model_fn: Callable[[Model], None] | None = None) -> Callable[[Path], Path]:
    def build(folder: Path) -> Path:
        m = valid_model()
        if model_fn is not None:
            model_fn(m)
        write_asset(folder, m)
        fn(folder)
        return folder

    return build


def _mesh(link: str, filename: str, *, role: str = "both") -> Callable[[Model], None]:
    def fn(m: Model) -> None:
        ln = m.link(link)
        if role in ("both", "visual"):
            ln.visuals[0].filename = filename
        if role in ("both", "collision"):
            ln.collisions[0].filename = filename

    return fn


def _attr(target: str, which: str, **values: str | None) -> Callable[[Model], None]:
    """Set fields of a joint (target 'joint') or a link's inertial ('inertial')."""

    def fn(m: Model) -> None:
        obj = m.joint(which) if target == "joint" else m.link(which).inertial
        for k, v in values.items():
            setattr(obj, k, v)

    return fn


def _write(rel: str, data: bytes | str) -> Callable[[Path], None]:
    def fn(folder: Path) -> None:
        p = folder / rel
        p.parent.mkdir(parents=True, exist_ok=True)
        if isinstance(data, str):
            p.write_text(data)
        else:
            p.write_bytes(data)

    return fn


ROBOT_HEAD = b'<?xml version="1.0"?>\n'
LAUGHS = (
    b'<!DOCTYPE robot [\n<!ENTITY lol "lol">\n'
    + b"".join(
        f'<!ENTITY lol{i} "{("&lol" + (str(i - 1) if i > 1 else "") + ";") * 10}">\n'.encode() for i in range(1, 10)
    )
    + b']>\n<robot name="&lol9;"><link name="base"/></robot>\n'
)
QUADRATIC = (
    b'<!DOCTYPE robot [<!ENTITY a "' + b"x" * 50_000 + b'">]>\n<robot name="q"><link name="base">'
    + b"&a;" * 50_000
    + b"</link></robot>\n"
)
XXE_FILE = b'<!DOCTYPE robot [<!ENTITY xxe SYSTEM "file:///etc/passwd">]>\n<robot name="&xxe;"><link name="base"/></robot>\n'
XXE_PARAM = b'<!DOCTYPE robot [<!ENTITY % ext SYSTEM "file:///etc/passwd"> %ext;]>\n<robot name="x"><link name="base"/></robot>\n'
XXE_DTD = b'<!DOCTYPE robot SYSTEM "http://127.0.0.1:9/evil.dtd">\n<robot name="x"><link name="base"/></robot>\n'
PLAIN_DTD = b'<!DOCTYPE robot>\n<robot name="x"><link name="base"/></robot>\n'


def _deep(n: int) -> bytes:
    return b'<robot name="deep"><link name="base">' + b"<a>" * n + b"</a>" * n + b"</link></robot>\n"


def _big_token(n_bytes: int) -> Callable[[Path], Path]:
    def build(folder: Path) -> Path:
        write_asset(folder)
        with open(folder / "mobility.urdf", "wb") as fh:
            fh.write(b'<robot name="')
            chunk = b"x" * (1 << 20)
            left = n_bytes
            while left > 0:
                fh.write(chunk[: min(left, len(chunk))])
                left -= len(chunk)
            fh.write(b'"><link name="base"/></robot>\n')
        return folder

    return build


def _two_urdfs(folder: Path) -> None:
    os.replace(folder / "mobility.urdf", folder / "a.urdf")
    (folder / "b.urdf").write_text((folder / "a.urdf").read_text())


def _urdf_fifo(folder: Path) -> None:
    os.unlink(folder / "mobility.urdf")
    os.mkfifo(folder / "mobility.urdf")


def _urdf_symlink_out(folder: Path) -> None:
    outside = folder.parent / (folder.name + "_outside")
    outside.mkdir(exist_ok=True)
    os.replace(folder / "mobility.urdf", outside / "mobility.urdf")
    os.symlink(outside / "mobility.urdf", folder / "mobility.urdf")


def _symlink_mesh_out(folder: Path) -> None:
    outside = folder.parent / (folder.name + "_outside")
    outside.mkdir(exist_ok=True)
    (outside / "secret.obj").write_text(box_obj())
    os.symlink(outside / "secret.obj", folder / "meshes" / "escape.obj")


def _symlink_dir_out(folder: Path) -> None:
    outside = folder.parent / (folder.name + "_outside")
    (outside / "m").mkdir(parents=True, exist_ok=True)
    (outside / "m" / "lid.obj").write_text(box_obj())
    os.symlink(outside / "m", folder / "linked")


def _symlink_dev(folder: Path) -> None:
    os.symlink("/dev/zero", folder / "meshes" / "zero.obj")


def _fifo_mesh(folder: Path) -> None:
    os.mkfifo(folder / "meshes" / "pipe.obj")


@contextlib.contextmanager
def _cwd(path: Path):
    old = os.getcwd()
    os.chdir(path)
    try:
        yield
    finally:
        os.chdir(old)


def _socket_mesh(folder: Path) -> None:
    s = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    try:
        with _cwd(folder / "meshes"):  # relative bind: AF_UNIX paths are limited to ~108 bytes
            s.bind("sock.obj")
    finally:
        s.close()


def _dir_mesh(folder: Path) -> None:
    (folder / "meshes" / "dir.obj").mkdir()


def _obj(text: str) -> bytes:
    return text.encode()


CUBE_V = "".join(f"v {x} {y} {z}\n" for z in (0, 1) for y in (0, 1) for x in (0, 1))
CUBE_F = "f 1 3 4\nf 1 4 2\nf 5 6 8\nf 5 8 7\nf 1 2 6\nf 1 6 5\nf 3 7 8\nf 3 8 4\nf 1 5 7\nf 1 7 3\nf 2 4 8\nf 2 8 6\n"


def _many_faces_obj(n: int) -> str:
    return "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\n" + "f 1 2 3\n" * n


def _texture(filename: str) -> Callable[[str], str]:
    """Give the base link's visual a <material> with a texture."""

    def fn(text: str) -> str:
        mat = f'<material name="skin"><color rgba="1 1 1 1" /><texture filename="{filename}" /></material></visual>'
        return text.replace("</visual>", mat, 1)

    return fn


def _add_sheet_piece(m: Model) -> None:
    m.link("lid").collisions.append(Geom(filename="meshes/sheet.obj"))


def _empty_geometry(m: Model) -> None:
    m.link("handle").visuals[0].kind = "capsule"  # not a URDF shape: <geometry> ends up empty


def _extra_fifo(folder: Path) -> None:
    os.unlink(folder / "semantics.txt")
    os.mkfifo(folder / "semantics.txt")


def _remove_folder(folder: Path) -> None:
    import shutil

    shutil.rmtree(folder)


def _flat_link(m: Model) -> None:
    ln = m.link("lid")
    ln.visuals[0].filename = "meshes/sheet.obj"
    ln.collisions[0].filename = "meshes/sheet.obj"


def _stl_nan() -> bytes:
    data = bytearray(box_stl())
    struct.pack_into("<f", data, 84 + 12, float("nan"))
    return bytes(data)


# ----------------------------------------------------------------------------- validate agrees with refine
# (classes: formats, encodings, link cap, special files
# named by MTL files, limits that cannot be meant, mimic, the face cap)

BOX_V = [(x, y, z) for z in (0.0, 0.05) for y in (-1.0, 0.0) for x in (0.0, 1.0)]
BOX_T = [(0, 2, 3), (0, 3, 1), (4, 5, 7), (4, 7, 6), (0, 1, 5), (0, 5, 4), (2, 6, 7), (2, 7, 3), (0, 4, 6), (0, 6, 2), (1, 3, 7), (1, 7, 5)]


def box_ply() -> str:
    """The lid box as ASCII PLY."""
    head = "ply\nformat ascii 1.0\nelement vertex 8\nproperty float x\nproperty float y\nproperty float z\nelement face 12\nproperty list uchar int vertex_indices\nend_header\n"
    return head + "".join(f"{x} {y} {z}\n" for x, y, z in BOX_V) + "".join(f"3 {a} {b} {c}\n" for a, b, c in BOX_T)


def box_off() -> str:
    """The lid box as OFF."""
    return "OFF\n8 12 0\n" + "".join(f"{x} {y} {z}\n" for x, y, z in BOX_V) + "".join(f"3 {a} {b} {c}\n" for a, b, c in BOX_T)


def box_glb() -> bytes:
    """The lid box as binary glTF (written by trimesh)."""
    import trimesh  # heavy; only this case needs it

    return trimesh.Trimesh(BOX_V, BOX_T, process=False).export(file_type="glb")


def _mesh_file(rel: str, data: Callable[[], bytes | str]) -> Callable[[Path], None]:
    def fn(folder: Path) -> None:
        _write(rel, data())(folder)

    return fn


def _utf16(folder: Path) -> None:
    p = folder / "mobility.urdf"
    p.write_bytes(p.read_text().encode("utf-16"))


def _latin1_declared(folder: Path) -> None:
    p = folder / "mobility.urdf"
    text = p.read_text().replace('name="lid"', 'name="lid\u00e9"')
    p.write_bytes(b'<?xml version="1.0" encoding="ISO-8859-1"?>\n' + text.encode("latin-1"))


def _chain(n: int) -> Callable[[Model], None]:
    """Hang a chain of ``n`` small fixed links under the handle."""

    def fn(m: Model) -> None:
        prev = "handle"
        for i in range(n):
            m.links.append(Link(f"chain_{i}", inertial=Inertial(mass="0.01", ixx="1e-6", iyy="1e-6", izz="1e-6")))
            m.joints.append(Joint(f"chain_joint_{i}", "fixed", prev, f"chain_{i}", xyz="0 0 0.001"))
            prev = f"chain_{i}"

    return fn


def _mimic(m: Model) -> None:
    m.links.append(Link("lid2", visuals=[Geom(filename="meshes/lid.obj")], collisions=[Geom(filename="meshes/lid.obj")],
                        inertial=Inertial(mass="0.3", ixx="0.02", iyy="0.02", izz="0.03")))
    m.joints.append(Joint("lid2_hinge", "revolute", "base", "lid2", xyz="0 0 0.5", axis="1 0 0", lower="-1.5", upper="0",
                          effort="10", velocity="1", mimic="lid_hinge"))


def _missing_dir_dotdot(m: Model) -> None:
    _mesh("lid", "nodir/../meshes/lid.obj")(m)


def _mtl_special(kind: str, which: str) -> Callable[[Path], None]:
    """Replace the MTL (``which='mtl'``) or its texture (``'texture'``) by a
    FIFO (``kind='fifo'``) or a symlink to /dev/zero (``'device'``)."""

    def fn(folder: Path) -> None:
        p = folder / ("meshes/base.mtl" if which == "mtl" else "images/tex.png")
        os.unlink(p)
        if kind == "fifo":
            os.mkfifo(p)
        else:
            os.symlink("/dev/zero", p)

    return fn


def _symlink_other_format(folder: Path) -> None:
    os.symlink("drawer.stl", folder / "meshes" / "alias.obj")


def png_header(width: int, height: int) -> bytes:
    """A PNG whose header claims ``width`` x ``height`` RGB pixels, with one
    tiny IDAT chunk (valid CRCs): what a reader learns from the header
    without decoding (the image data would not decode)."""
    import zlib

    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)

    ihdr = struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0)
    return b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IDAT", zlib.compress(b"\0\0\0\0")) + chunk(b"IEND", b"")


def _sparse_texture(size: int) -> Callable[[Path], None]:
    """Extend the texture to ``size`` bytes with zeros (a sparse file: no disk used)."""

    def fn(folder: Path) -> None:
        os.truncate(folder / "images" / "tex.png", size)

    return fn


def _sparse_extra(name: str, size: int) -> Callable[[Path], None]:
    """Extend ``name`` (``meta.json``, ``semantics.txt``) to ``size`` bytes with
    zeros (a sparse file: no disk used)."""

    def fn(folder: Path) -> None:
        os.truncate(folder / name, size)

    return fn


def _rename_link(old: str, new: str) -> Callable[[Model], None]:
    """Rename link ``old`` to ``new`` everywhere the URDF names it."""

    def fn(m: Model) -> None:
        m.link(old).name = new
        for j in m.joints:
            j.parent = new if j.parent == old else j.parent
            j.child = new if j.child == old else j.child

    return fn


def _strip_geometry(m: Model) -> None:
    """No link keeps a <visual> or <collision> (links, joints and inertials stay)."""
    for ln in m.links:
        ln.visuals, ln.collisions = [], []


def _lid_scale(factor: str) -> Callable[[Model], None]:
    def fn(m: Model) -> None:
        for g in m.link("lid").visuals + m.link("lid").collisions:
            g.scale = f"{factor} {factor} {factor}"

    return fn


def _cases() -> list[Case]:
    C = Case
    out: list[Case] = []
    add = out.append
    # --- XML attacks and XML-level errors
    add(C("xml_billion_laughs", "xml", "XML_ENTITY_FORBIDDEN", _raw_urdf(ROBOT_HEAD + LAUGHS)))
    add(C("xml_quadratic_blowup", "xml", "XML_ENTITY_FORBIDDEN", _raw_urdf(QUADRATIC)))
    add(C("xml_xxe_local_file", "xml", "XML_EXTERNAL_REFERENCE_FORBIDDEN", _raw_urdf(XXE_FILE)))
    add(C("xml_xxe_parameter_entity", "xml", "XML_EXTERNAL_REFERENCE_FORBIDDEN", _raw_urdf(XXE_PARAM)))
    add(C("xml_external_dtd", "xml", "XML_EXTERNAL_REFERENCE_FORBIDDEN", _raw_urdf(XXE_DTD)))
    add(C("xml_plain_doctype", "xml", "XML_DTD_FORBIDDEN", _raw_urdf(PLAIN_DTD)))
    add(C("xml_nesting_10000", "xml", "XML_TOO_DEEP", _raw_urdf(_deep(10_000))))
    add(C("xml_token_100MB", "xml", "XML_TOO_LARGE", _big_token(100 << 20), note="100 MB attribute; refused by the size cap before reading"))
    add(C("xml_token_2MB", "xml", "XML_TOKEN_TOO_LARGE", _big_token(2 << 20)))
    add(C("xml_too_many_elements", "xml", "XML_TOO_MANY_ELEMENTS",
          _raw_urdf(b'<robot name="m"><link name="base"/>' + b"<x/>" * 120_000 + b"</robot>")))
    add(C("xml_unclosed_tag", "xml", "XML_MALFORMED", _text_case(lambda t: t.replace("</robot>", ""))))
    add(C("xml_undefined_entity", "xml", "XML_MALFORMED", _text_case(lambda t: t.replace('name="corpus_object"', 'name="&ent;"'))))
    add(C("xml_nul_in_mesh_path", "xml", "XML_MALFORMED", _text_case(lambda t: t.replace("meshes/lid.obj", "meshes/lid&#0;.obj", 1)),
          note="XML cannot carry NUL; resolve_mesh_reference refuses it too (MESH_PATH_NUL)"))
    add(C("xml_duplicate_attribute", "xml", "XML_MALFORMED", _text_case(lambda t: t.replace('<link name="lid"', '<link name="lid" name="lid2"'))))
    add(C("xml_root_not_robot", "xml", "URDF_ROOT_NOT_ROBOT", _raw_urdf(b'<mujoco model="x"><worldbody/></mujoco>')))
    add(C("xml_binary_garbage", "xml", "XML_MALFORMED", _raw_urdf(bytes(range(256)) * 4)))
    # --- files
    add(C("files_no_urdf", "files", "URDF_NOT_FOUND", _files_case(lambda f: os.unlink(f / "mobility.urdf"))))
    add(C("files_two_urdfs", "files", "URDF_AMBIGUOUS", _files_case(_two_urdfs)))
    add(C("files_urdf_is_fifo", "files", "URDF_NOT_REGULAR_FILE", _files_case(_urdf_fifo)))
    add(C("files_urdf_symlink_outside", "files", "URDF_OUTSIDE_ASSET", _files_case(_urdf_symlink_out)))
    add(C("files_semantics_bad_line", "files", "SEMANTICS_MALFORMED_LINE", _files_case(_write("semantics.txt", "base static body\nlid\n"))))
    add(C("files_semantics_is_fifo", "files", "ASSET_FILE_NOT_REGULAR", _files_case(_extra_fifo)))
    add(C("files_meta_1gb_sparse", "files", "ASSET_FILE_TOO_LARGE", _files_case(_sparse_extra("meta.json", 1 << 30)),
          note="a regular file above the 1 MiB cap; was called ASSET_FILE_NOT_REGULAR"))
    add(C("files_asset_missing", "files", "ASSET_NOT_FOUND", _files_case(_remove_folder)))
    add(C("files_meta_not_json", "files", "META_UNREADABLE", _files_case(_write("meta.json", "{model_cat: Box")), refused=False))
    add(C("files_semantics_unknown_link", "files", "SEMANTICS_UNKNOWN_LINK",
          _files_case(_write("semantics.txt", "base static body\nghost hinge door\n")), refused=False))
    add(C("files_semantics_unknown_kind", "files", "SEMANTICS_UNKNOWN_KIND",
          _files_case(_write("semantics.txt", "lid rotating lid\n")), refused=False))
    # --- structure
    def two_roots(m: Model) -> None:
        m.links.append(Link("island"))
        m.links.append(Link("island_child"))
        m.joints.append(Joint("island_joint", "fixed", "island", "island_child"))

    add(C("structure_two_roots", "structure", "TREE_MULTIPLE_ROOTS", _model_case(two_roots)))
    add(C("structure_orphan_link", "structure", "LINK_ORPHAN", _model_case(lambda m: m.links.append(Link("orphan")))))

    def cycle(m: Model) -> None:
        m.links += [Link("c1"), Link("c2")]
        m.joints += [Joint("c12", "fixed", "c1", "c2"), Joint("c21", "fixed", "c2", "c1")]

    add(C("structure_detached_cycle", "structure", "TREE_CYCLE", _model_case(cycle)))

    def full_cycle(m: Model) -> None:
        m.joints.append(Joint("back", "fixed", "handle", "base"))

    add(C("structure_cycle_no_root", "structure", "TREE_NO_ROOT", _model_case(full_cycle)))
    add(C("structure_self_loop", "structure", "JOINT_SELF_LOOP", _model_case(lambda m: m.joints.append(Joint("loop", "fixed", "lid", "lid")))))
    add(C("structure_two_parents", "structure", "LINK_MULTIPLE_PARENTS",
          _model_case(lambda m: m.joints.append(Joint("second_parent", "fixed", "lid", "drawer")))))
    add(C("structure_duplicate_link", "structure", "LINK_NAME_DUPLICATE", _model_case(lambda m: m.links.append(Link("lid")))))
    add(C("structure_duplicate_joint", "structure", "JOINT_NAME_DUPLICATE",
          _model_case(lambda m: setattr(m.joint("drawer_slide"), "name", "lid_hinge"))))
    add(C("structure_parent_unknown", "structure", "JOINT_PARENT_UNKNOWN", _model_case(_attr("joint", "lid_hinge", parent="no_such_link"))))
    add(C("structure_child_unknown", "structure", "JOINT_CHILD_UNKNOWN", _model_case(_attr("joint", "lid_hinge", child="no_such_link"))))
    add(C("structure_parent_missing", "structure", "JOINT_PARENT_MISSING", _model_case(_attr("joint", "lid_hinge", parent=None))))
    add(C("structure_child_missing", "structure", "JOINT_CHILD_MISSING", _model_case(_attr("joint", "drawer_slide", child=None))))
    add(C("structure_link_name_missing", "structure", "LINK_NAME_MISSING", _model_case(lambda m: m.links.append(Link(None)))))
    add(C("structure_joint_name_missing", "structure", "JOINT_NAME_MISSING", _model_case(_attr("joint", "handle_fix", name=None))))
    add(C("structure_joint_type_invalid", "structure", "JOINT_TYPE_INVALID", _model_case(_attr("joint", "lid_hinge", type="hinge"))))
    add(C("structure_joint_type_missing", "structure", "JOINT_TYPE_MISSING", _model_case(_attr("joint", "lid_hinge", type=None))))
    add(C("structure_no_links", "structure", "URDF_NO_LINKS", _raw_urdf(b'<robot name="empty"></robot>')))
    add(C("structure_mimic_unknown", "structure", "JOINT_MIMIC_UNKNOWN", _model_case(_attr("joint", "lid_hinge", mimic="ghost"))))
    add(C("structure_limit_missing", "structure", "JOINT_LIMIT_MISSING", _model_case(_attr("joint", "lid_hinge", with_limit=False))))
    add(C("structure_limit_incomplete", "structure", "JOINT_LIMIT_INCOMPLETE", _model_case(_attr("joint", "lid_hinge", lower=None)), refused=False))
    add(C("structure_robot_name_missing", "structure", "URDF_ROBOT_NAME_MISSING", _model_case(lambda m: setattr(m, "name", None))))
    add(C("structure_geometry_missing", "structure", "GEOMETRY_MISSING", _model_case(_empty_geometry)))
    add(C("structure_axis_not_unit", "structure", "JOINT_AXIS_NOT_UNIT", _model_case(_attr("joint", "lid_hinge", axis="2 0 0")), refused=False))
    # --- numbers
    add(C("numbers_nan_origin", "numbers", "NUMBER_NAN", _model_case(_attr("joint", "lid_hinge", xyz="0 nan 0.5"))))
    add(C("numbers_inf_axis", "numbers", "NUMBER_INF", _model_case(_attr("joint", "lid_hinge", axis="inf 0 0"))))
    add(C("numbers_1e400_limit", "numbers", "NUMBER_OVERFLOW", _model_case(_attr("joint", "drawer_slide", upper="1e400"))))
    add(C("numbers_minus_inf_mass", "numbers", "NUMBER_INF", _model_case(_attr("inertial", "lid", mass="-inf"))))
    add(C("numbers_empty_effort", "numbers", "NUMBER_EMPTY", _model_case(_attr("joint", "lid_hinge", effort=""))))
    add(C("numbers_malformed", "numbers", "NUMBER_MALFORMED", _model_case(_attr("joint", "lid_hinge", lower="-1.5.0"))))
    add(C("numbers_hex_float", "numbers", "NUMBER_MALFORMED", _model_case(_attr("joint", "lid_hinge", upper="0x1p-2"))))
    add(C("numbers_underscore", "numbers", "NUMBER_MALFORMED", _model_case(_attr("joint", "drawer_slide", effort="1_000"))))
    add(C("numbers_comma_separated", "numbers", "NUMBER_MALFORMED", _model_case(_attr("joint", "lid_hinge", xyz="0,1,0.5"))))
    add(C("numbers_two_values", "numbers", "NUMBER_COUNT", _model_case(_attr("joint", "lid_hinge", xyz="0 1"))))
    add(C("numbers_four_values", "numbers", "NUMBER_COUNT", _model_case(_attr("joint", "lid_hinge", axis="1 0 0 0"))))
    add(C("numbers_nan_inertia", "numbers", "NUMBER_NAN", _model_case(_attr("inertial", "drawer", ixx="NaN"))))

    def nan_scale(m: Model) -> None:
        m.link("lid").visuals[0].scale = "1 nan 1"

    add(C("numbers_nan_mesh_scale", "numbers", "NUMBER_NAN", _model_case(nan_scale)))
    add(C("numbers_limit_reversed", "numbers", "JOINT_LIMIT_REVERSED", _model_case(_attr("joint", "lid_hinge", lower="1", upper="-1"))))
    add(C("numbers_limit_equal", "numbers", "JOINT_LIMIT_EQUAL", _model_case(_attr("joint", "lid_hinge", lower="0.5", upper="0.5")), refused=False))
    add(C("numbers_effort_negative", "numbers", "JOINT_EFFORT_NEGATIVE", _model_case(_attr("joint", "lid_hinge", effort="-10"))))
    add(C("numbers_velocity_negative", "numbers", "JOINT_VELOCITY_NEGATIVE", _model_case(_attr("joint", "drawer_slide", velocity="-0.5"))))
    add(C("numbers_damping_negative", "numbers", "JOINT_DYNAMICS_NEGATIVE", _model_case(_attr("joint", "lid_hinge", damping="-0.1"))))
    add(C("numbers_zero_axis", "numbers", "JOINT_AXIS_ZERO", _model_case(_attr("joint", "lid_hinge", axis="0 0 0"))))

    def zero_box(m: Model) -> None:
        m.link("handle").collisions[0].size = "0.02 0 0.02"

    add(C("numbers_box_size_zero", "numbers", "GEOMETRY_SIZE_NONPOSITIVE", _model_case(zero_box)))

    def zero_scale(m: Model) -> None:
        m.link("lid").collisions[0].scale = "1 1 0"

    add(C("numbers_mesh_scale_zero", "numbers", "MESH_SCALE_ZERO", _model_case(zero_scale)))

    def mirror_scale(m: Model) -> None:
        m.link("lid").visuals[0].scale = "-1 1 1"

    add(C("numbers_mesh_scale_negative", "numbers", "MESH_SCALE_NEGATIVE", _model_case(mirror_scale), refused=False))
    # --- inertials (reported and replaced by an estimate: warnings, not refusals)
    add(C("inertial_mass_zero_moving", "inertials", "INERTIAL_MASS_NONPOSITIVE", _model_case(_attr("inertial", "lid", mass="0")), refused=False))
    add(C("inertial_mass_negative", "inertials", "INERTIAL_MASS_NONPOSITIVE", _model_case(_attr("inertial", "drawer", mass="-0.5")), refused=False))
    add(C("inertial_negative_eigenvalue", "inertials", "INERTIA_NOT_POSITIVE_DEFINITE",
          _model_case(_attr("inertial", "lid", ixx="-0.02")), refused=False))
    add(C("inertial_all_zero", "inertials", "INERTIA_NOT_POSITIVE_DEFINITE",
          _model_case(_attr("inertial", "drawer", ixx="0", iyy="0", izz="0")), refused=False))
    add(C("inertial_indefinite_offdiagonal", "inertials", "INERTIA_NOT_POSITIVE_DEFINITE",
          _model_case(_attr("inertial", "lid", ixy="0.05")), refused=False))
    add(C("inertial_triangle_violated", "inertials", "INERTIA_TRIANGLE_INEQUALITY",
          _model_case(_attr("inertial", "lid", ixx="0.01", iyy="0.01", izz="0.03")), refused=False))
    add(C("inertial_mass_missing", "inertials", "INERTIAL_MASS_MISSING", _model_case(_attr("inertial", "lid", with_mass=False)), refused=False))
    add(C("inertial_inertia_missing", "inertials", "INERTIA_MISSING", _model_case(_attr("inertial", "drawer", with_inertia=False)), refused=False))
    add(C("inertial_static_mass_zero", "inertials", "INERTIAL_MASS_ZERO_STATIC",
          _model_case(_attr("inertial", "base", mass="0", ixx="0", iyy="0", izz="0")), refused=False))
    # --- mesh paths
    add(C("path_absolute_etc_passwd", "mesh_paths", "MESH_PATH_ABSOLUTE", _model_case(_mesh("lid", "/etc/passwd"))))

    def abs_inside(folder: Path) -> Path:
        m = valid_model()
        _mesh("lid", str(Path(folder).resolve() / "meshes" / "lid.obj"))(m)
        return write_asset(folder, m)

    add(C("path_absolute_inside_folder", "mesh_paths", "MESH_PATH_ABSOLUTE", abs_inside, note="absolute paths are refused even inside: the output must be portable"))
    add(C("path_dotdot_escape", "mesh_paths", "MESH_PATH_ESCAPES", _model_case(_mesh("lid", "../outside.obj"))))
    add(C("path_deep_dotdot_passwd", "mesh_paths", "MESH_PATH_ESCAPES", _model_case(_mesh("lid", "meshes/../../../../../../etc/passwd"))))
    add(C("path_file_uri", "mesh_paths", "MESH_URI_FORBIDDEN", _model_case(_mesh("lid", "file:///etc/passwd"))))
    add(C("path_http_uri", "mesh_paths", "MESH_URI_FORBIDDEN", _model_case(_mesh("lid", "http://127.0.0.1:9/lid.obj"))))
    add(C("path_package_uri", "mesh_paths", "MESH_URI_FORBIDDEN", _model_case(_mesh("lid", "package://corpus/meshes/lid.obj"))))
    add(C("path_windows_absolute", "mesh_paths", "MESH_PATH_ABSOLUTE", _model_case(_mesh("lid", "C:\\meshes\\lid.obj"))))
    add(C("path_symlink_file_outside", "mesh_paths", "MESH_SYMLINK_ESCAPES", _files_case(_symlink_mesh_out, _mesh("lid", "meshes/escape.obj"))))
    add(C("path_symlink_dir_outside", "mesh_paths", "MESH_SYMLINK_ESCAPES", _files_case(_symlink_dir_out, _mesh("lid", "linked/lid.obj"))))
    add(C("path_symlink_to_device", "mesh_paths", "MESH_SYMLINK_ESCAPES", _files_case(_symlink_dev, _mesh("lid", "meshes/zero.obj"))))
    add(C("path_fifo", "mesh_paths", "MESH_NOT_REGULAR_FILE", _files_case(_fifo_mesh, _mesh("lid", "meshes/pipe.obj"))))
    add(C("path_socket", "mesh_paths", "MESH_NOT_REGULAR_FILE", _files_case(_socket_mesh, _mesh("lid", "meshes/sock.obj"))))
    add(C("path_directory", "mesh_paths", "MESH_IS_DIRECTORY", _files_case(_dir_mesh, _mesh("lid", "meshes/dir.obj"))))

    def three_missing(m: Model) -> None:
        m.link("base").visuals[0].filename = "meshes/missing_a.obj"
        m.link("lid").visuals[0].filename = "meshes/missing_b.obj"
        m.link("lid").collisions[0].filename = "meshes/missing_c.obj"

    add(C("path_three_missing", "mesh_paths", "MESH_NOT_FOUND", _model_case(three_missing), note="all three are listed"))
    add(C("path_not_mesh_extension", "mesh_paths", "MESH_EXTENSION_UNSUPPORTED", _model_case(_mesh("lid", "semantics.txt"))))
    add(C("path_empty_filename", "mesh_paths", "MESH_FILENAME_EMPTY", _model_case(_mesh("lid", ""))))
    add(C("path_control_char", "mesh_paths", "MESH_PATH_CONTROL_CHAR", _model_case(_mesh("lid", "meshes/li\td.obj"))))
    add(C("path_too_large", "mesh_paths", "MESH_TOO_LARGE", build_valid, policy={"max_mesh_bytes": 256}))
    add(C("path_texture_absolute", "mesh_paths", "TEXTURE_PATH_REFUSED", _text_case(_texture("/etc/passwd"))))
    add(C("path_texture_escapes", "mesh_paths", "TEXTURE_PATH_REFUSED", _text_case(_texture("../../secret.png"))))
    add(C("path_texture_missing", "mesh_paths", "TEXTURE_NOT_FOUND", _text_case(_texture("images/none.png")), refused=False))
    add(C("path_mtllib_missing", "mesh_paths", "MESH_MATERIAL_MISSING",
          _files_case(_write("meshes/lid.obj", box_obj(0, 1, -1, 0, 0, 0.05, mtllib="nowhere.mtl"))), refused=False))
    add(C("path_mtllib_escapes", "mesh_paths", "MESH_MATERIAL_OUTSIDE",
          _files_case(_write("meshes/lid.obj", box_obj(0, 1, -1, 0, 0, 0.05, mtllib="../../../etc/passwd"))), refused=False))
    # --- mesh contents
    add(C("mesh_nan_vertex", "mesh_contents", "MESH_NONFINITE_VERTEX",
          _files_case(_write("meshes/lid.obj", CUBE_V.replace("v 1 1 1", "v nan 1 1") + CUBE_F))))
    add(C("mesh_inf_vertex", "mesh_contents", "MESH_NONFINITE_VERTEX",
          _files_case(_write("meshes/lid.obj", CUBE_V.replace("v 0 0 0", "v -inf 0 0") + CUBE_F))))
    add(C("mesh_index_out_of_range", "mesh_contents", "MESH_BAD_INDEX", _files_case(_write("meshes/lid.obj", CUBE_V + CUBE_F + "f 1 2 99\n"))))
    add(C("mesh_index_zero", "mesh_contents", "MESH_BAD_INDEX", _files_case(_write("meshes/lid.obj", CUBE_V + CUBE_F + "f 0 1 2\n"))))
    add(C("mesh_negative_index_before_start", "mesh_contents", "MESH_BAD_INDEX",
          _files_case(_write("meshes/lid.obj", CUBE_V + CUBE_F + "f -1 -2 -20\n"))))
    add(C("mesh_face_two_vertices", "mesh_contents", "MESH_BAD_INDEX", _files_case(_write("meshes/lid.obj", CUBE_V + CUBE_F + "f 1 2\n"))))
    add(C("mesh_no_faces", "mesh_contents", "MESH_NO_FACES", _files_case(_write("meshes/lid.obj", CUBE_V))))
    add(C("mesh_empty_file", "mesh_contents", "MESH_NO_FACES", _files_case(_write("meshes/lid.obj", b""))))
    add(C("mesh_collapsed_to_point", "mesh_contents", "MESH_ZERO_AREA",
          _files_case(_write("meshes/lid.obj", "v 0.5 0.5 0.5\n" * 8 + CUBE_F))))
    add(C("mesh_collinear", "mesh_contents", "MESH_ZERO_AREA",
          _files_case(_write("meshes/lid.obj", "".join(f"v {i} {i} {i}\n" for i in range(8)) + CUBE_F))))
    add(C("mesh_flat_piece", "mesh_contents", "MESH_ZERO_VOLUME",
          _files_case(_write("meshes/sheet.obj", "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3\nf 1 3 4\n"), _add_sheet_piece),
          refused=False, note="a flat piece among volumetric ones (PartNet-Mobility has many)"))
    add(C("mesh_flat_link", "mesh_contents", "LINK_ZERO_VOLUME",
          _files_case(_write("meshes/sheet.obj", "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3\nf 1 3 4\n"), _flat_link), refused=False))
    add(C("mesh_binary_garbage_obj", "mesh_contents", "MESH_MALFORMED", _files_case(_write("meshes/lid.obj", bytes(range(256)) * 16))))
    add(C("mesh_vertex_two_coords", "mesh_contents", "MESH_MALFORMED", _files_case(_write("meshes/lid.obj", CUBE_V + "v 1 2\n" + CUBE_F))))
    add(C("mesh_stl_truncated", "mesh_contents", "MESH_MALFORMED", _files_case(_write("meshes/drawer.stl", box_stl()[:500]))))
    add(C("mesh_stl_nan", "mesh_contents", "MESH_NONFINITE_VERTEX", _files_case(_write("meshes/drawer.stl", _stl_nan()))))
    add(C("mesh_too_many_faces", "mesh_contents", "MESH_TOO_MANY_FACES",
          _files_case(_write("meshes/lid.obj", CUBE_V + CUBE_F * 100)), policy={"max_mesh_faces": 1000}))
    add(C("mesh_visual_only_bad_index", "mesh_contents", "MESH_BAD_INDEX",
          _files_case(_write("meshes/lid_visual.obj", CUBE_V + CUBE_F + "f 1 2 99\n"), _mesh("lid", "meshes/lid_visual.obj", role="visual")),
          refused=False, note="a visual-only defect is a warning"))
    # --- validate agrees with refine
    for fmt, data in (("off", box_off),):  # GLB, glTF and PLY are converted to OBJ (tests/tasks/ingest/test_urdf_meshes.py)
        add(C(f"format_{fmt}_mesh", "refine_agreement", "MESH_FORMAT_UNSUPPORTED",
              _files_case(_mesh_file(f"meshes/lid.{fmt}", data), _mesh("lid", f"meshes/lid.{fmt}")),
              note="PyBullet (refine loads the input URDF) reads OBJ, STL, DAE only; refine converts GLB, glTF, PLY: OFF refused"))
    add(C("format_symlink_name_differs", "refine_agreement", "MESH_FORMAT_UNSUPPORTED",
          _files_case(_symlink_other_format, _mesh("lid", "meshes/alias.obj")),
          note="alias.obj -> drawer.stl: the simulator picks the reader by the name"))
    add(C("encoding_utf16", "refine_agreement", "URDF_ENCODING_UNSUPPORTED", _files_case(_utf16),
          note="UTF-16 with BOM: the XML parser reads it, PyBullet does not"))
    add(C("encoding_latin1_declared", "refine_agreement", "URDF_ENCODING_UNSUPPORTED", _files_case(_latin1_declared),
          note="declared ISO-8859-1 with a non-ASCII name: names would differ between readers"))
    add(C("links_400_chain", "refine_agreement", "URDF_TOO_MANY_LINKS", _model_case(_chain(400)),
          note="PyBullet loads at most 128 links per body"))
    add(C("path_dotdot_through_missing_dir", "refine_agreement", "MESH_NOT_FOUND", _model_case(_missing_dir_dotdot),
          note="'nodir/../meshes/lid.obj' normalizes inside the folder but cannot be opened as written"))
    add(C("material_mtl_fifo", "refine_agreement", "MATERIAL_NOT_REGULAR_FILE", _files_case(_mtl_special("fifo", "mtl")),
          note="was 'ignored' by validate, then hung refine (PyBullet reads the MTL)"))
    add(C("material_texture_fifo", "refine_agreement", "MATERIAL_NOT_REGULAR_FILE", _files_case(_mtl_special("fifo", "texture")),
          note="was 'ignored' by validate, then hung refine (PyBullet reads the texture)"))
    add(C("material_texture_symlink_dev_zero", "refine_agreement", "MATERIAL_NOT_REGULAR_FILE",
          _files_case(_mtl_special("device", "texture")), note="a symlink leaving the folder to an endless device"))
    add(C("limit_revolute_1e300", "refine_agreement", "JOINT_LIMIT_IMPLAUSIBLE",
          _model_case(_attr("joint", "lid_hinge", lower="-1e300", upper="1e300")),
          note="gave an initial state of 9.5e299 rad called interaction-ready"))
    add(C("limit_revolute_degrees", "refine_agreement", "JOINT_LIMIT_IMPLAUSIBLE",
          _model_case(_attr("joint", "lid_hinge", lower="-90", upper="0")), note="degrees written as radians"))
    add(C("limit_prismatic_beyond_size", "refine_agreement", "JOINT_LIMIT_IMPLAUSIBLE",
          _model_case(_attr("joint", "drawer_slide", upper="30")), note="30 m of travel on an object about 1.6 m across"))
    # --- finite but absurd numbers: refused by validate as by refine, never an overflow further on
    add(C("axis_1e308", "refine_agreement", "JOINT_AXIS_IMPLAUSIBLE", _model_case(_attr("joint", "lid_hinge", axis="1e308 1e308 0")),
          note="passed validate; refine printed numpy overflow warnings and ended exit 70 in the sweep"))
    add(C("axis_1e-9", "refine_agreement", "JOINT_AXIS_IMPLAUSIBLE", _model_case(_attr("joint", "lid_hinge", axis="1e-9 0 0")),
          note="passed validate; refine's sweep could not move the joint"))
    add(C("limit_continuous_1e308", "refine_agreement", "JOINT_LIMIT_IMPLAUSIBLE",
          _model_case(_attr("joint", "lid_hinge", type="continuous", lower="-1e308", upper="1e308")),
          note="passed validate; refine ended ESTIMATOR_FAILED with pydantic's error count"))
    add(C("inertial_com_1e308", "refine_agreement", "INERTIAL_ORIGIN_IMPLAUSIBLE", _model_case(_attr("inertial", "lid", xyz="1e308 0 0")),
          note="passed validate; refine ended ESTIMATOR_FAILED"))
    add(C("inertial_mass_1e308", "refine_agreement", "INERTIAL_IMPLAUSIBLE",
          _model_case(_attr("inertial", "lid", mass="1e308", ixx="1e308", iyy="1e308", izz="1e308")),
          note="passed validate with numpy overflow warnings; the audit and --keep-declared overflowed to infinity"))
    add(C("mimic_joint", "refine_agreement", "JOINT_MIMIC_UNSUPPORTED", _model_case(_mimic),
          note="was silently dropped from the output"))
    # --- every URDF joint type is carried through or refused here, never an internal error
    add(C("joint_type_floating_below_root", "refine_agreement", "JOINT_TYPE_UNSUPPORTED",
          _model_case(_attr("joint", "handle_fix", type="floating")),
          note="passed validate, then refine's balance stage refused its own output (INTERNAL_ERROR, exit 70, partial output); "
               "PyBullet loads it as fixed, SAPIEN and MuJoCo refuse a floating joint below the root"))
    add(C("joint_type_floating_from_root", "refine_agreement", "JOINT_TYPE_UNSUPPORTED",
          _model_case(_attr("joint", "lid_hinge", type="floating", axis=None, lower=None, upper=None, effort=None,
                            velocity=None, damping=None, friction=None)),
          note="a loose part on the root: SAPIEN makes it a separate actor, refine cannot set or check it"))
    add(C("joint_type_planar", "refine_agreement", "JOINT_TYPE_UNSUPPORTED",
          _model_case(_attr("joint", "drawer_slide", type="planar", axis="0 0 1", with_limit=False)),
          note="3 degrees of freedom (axis = plane normal): same internal error as floating before; SAPIEN builds no planar joint"))
    # --- names are data, never paths
    add(C("link_name_path_traversal", "structure", "LINK_NAME_NOT_A_FILE_NAME",
          _model_case(_rename_link("lid", "../../../../../../elsewhere/pwn")), refused=False,
          note="its CoACD pieces were written as ../../../../../../elsewhere/pwn_5_0.obj outside --out; now named "
               "'elsewhere_pwn-<sha256>' inside the output (tests/tasks/test_unsafe_names.py refines such assets)"))
    add(C("link_names_sharing_a_file_name", "refine_agreement", "LINK_FILE_NAMES_CLASH",
          _model_case(lambda m: (_rename_link("lid", "a/b")(m), _rename_link("drawer", file_stem("a/b"))(m))),
          note="a crafted link named as another's safe file name: their files would share one name, refused"))
    add(C("faces_total_cap", "refine_agreement", "MESH_TOO_MANY_FACES", build_valid, policy={"max_total_faces": 30},
          note="the per-asset face cap (1,000,000 by default; docs/design/validation.md) with a lowered cap"))
    # --- validate agrees with refine: sizes and textures refine or PyBullet cannot take
    add(C("mesh_coordinate_1e308", "refine_agreement", "MESH_COORDINATE_IMPLAUSIBLE",
          _files_case(_write("meshes/lid.obj", "v 1e308 0 0\nv -1e308 0 0\nv 0 1e308 0\nv 0 0 1e308\nf 1 2 3\nf 1 2 4\nf 1 3 4\nf 2 3 4\n")),
          note="overflowed numpy (warnings, then INTERNAL_ERROR LinAlgError); now checked by comparison before any arithmetic"))
    add(C("asset_size_mesh_scale_1e6", "refine_agreement", "ASSET_SIZE_IMPLAUSIBLE", _model_case(_lid_scale("1e6")),
          note="passed validate, then refine refused the overlay (OVL_SCALE_INVALID, exit 2)"))
    add(C("asset_size_box_1e6", "refine_agreement", "ASSET_SIZE_IMPLAUSIBLE",
          _model_case(lambda m: setattr(m.link("handle").collisions[0], "size", "1e6 2e6 1e6")),
          note="a primitive 2e6 units across: the size bound holds for primitives too"))
    add(C("asset_no_geometry", "refine_agreement", "ASSET_NO_GEOMETRY", _model_case(_strip_geometry),
          note="passed validate, then refine blamed the request: OVL_SCALE_INVALID, scale 7.9e8 (the size of no geometry)"))
    add(C("texture_2gb_sparse", "refine_agreement", "TEXTURE_TOO_LARGE", _files_case(_sparse_texture(2200 * 1024 * 1024)),
          note="passed validate, then PyBullet died with std::bad_alloc (exit 134)"))
    add(C("texture_pixels_over_cap", "refine_agreement", "TEXTURE_TOO_LARGE",
          _files_case(_write("images/tex.png", png_header(8193, 8193))),
          note="8193 x 8193 pixels from the PNG header (nothing decoded); PyBullet decodes ~8.6 MiB per megapixel at each load"))
    add(C("texture_not_an_image", "refine_agreement", "TEXTURE_UNREADABLE", _files_case(_write("images/tex.png", "not an image\n")),
          note="PIL cannot identify it: neither PyBullet nor the renderer can use it"))
    add(C("texture_total_cap", "mesh_paths", "TEXTURE_TOO_LARGE", build_valid, policy={"max_total_texture_pixels": 0},
          note="the per-asset texture caps (1 GiB, 4 x 8192 x 8192 pixels by default) with a lowered cap"))
    out.extend(_other_format_cases())
    return out


# ----------------------------------------------------------------------------- MJCF and USD inputs

_TETRA = "v 0 0 0\nv 0.1 0 0\nv 0 0.1 0\nv 0 0 0.1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n"


def _mjcf_folder(mesh: str = "part.obj", head: str = "", asset: str = "",
                 prepare: Callable[[Path], None] | None = None) -> Callable[[Path], Path]:
    """A folder holding one MJCF object (a base and a hinged lid whose geom is the mesh ``mesh``) and ``part.obj``;
    ``head`` goes after ``<mujoco>``, ``asset`` into ``<asset>``; ``prepare(folder)`` adds what the case needs
    (files outside go beside the folder, in ``outside/``)."""

    def build(folder: Path) -> Path:
        folder.mkdir(parents=True, exist_ok=True)
        outside = folder.parent / "outside"
        outside.mkdir(exist_ok=True)
        (outside / "secret.obj").write_text(_TETRA)
        (folder / "part.obj").write_text(_TETRA)
        if prepare is not None:
            prepare(folder)
        (folder / "object.xml").write_text(
            f'<mujoco model="corpus">{head}<asset><mesh name="m" file="{mesh}"/>{asset}</asset>'
            '<worldbody><body name="base" pos="0 0 0.1"><freejoint/><geom type="box" size="0.2 0.2 0.1" mass="2"/>'
            '<body name="lid" pos="0 0 0.1"><joint name="hinge" type="hinge" axis="0 1 0" range="0 1.5"/>'
            '<geom type="mesh" mesh="m" mass="0.3"/></body></body></worldbody></mujoco>\n')
        return folder

    return build


def _usd_folder(header: str, prepare: Callable[[Path], None] | None = None) -> Callable[[Path], Path]:
    """A folder holding one USD object whose layer metadata carries ``header`` (its sublayers)."""

    def build(folder: Path) -> Path:
        folder.mkdir(parents=True, exist_ok=True)
        outside = folder.parent / "outside"
        outside.mkdir(exist_ok=True)
        (outside / "extra.usda").write_text('#usda 1.0\n\nover "obj"\n{\n}\n')
        if prepare is not None:
            prepare(folder)
        (folder / "object.usda").write_text(
            f'#usda 1.0\n(\n    defaultPrim = "obj"\n    metersPerUnit = 1\n    upAxis = "Z"\n    {header}\n)\n'
            'def Xform "obj" (prepend apiSchemas = ["PhysicsArticulationRootAPI"])\n{\n'
            '    def Xform "base" (prepend apiSchemas = ["PhysicsRigidBodyAPI", "PhysicsMassAPI"])\n    {\n'
            '        float physics:mass = 2\n'
            '        def Cube "box" (prepend apiSchemas = ["PhysicsCollisionAPI"])\n        {\n            double size = 0.3\n        }\n'
            '    }\n}\n')
        return folder

    return build


def _other_format_cases() -> list[Case]:
    """MJCF and USD inputs under the reader policy: every file they name a regular file inside their folder."""
    C, topic = Case, "other_formats"
    out = [
        C("mjcf_mesh_absolute", topic, "MJCF_PATH_ESCAPES", lambda f: _mjcf_folder(str(f.parent / "outside" / "secret.obj"))(f)),
        C("mjcf_mesh_dotdot", topic, "MJCF_PATH_ESCAPES", _mjcf_folder("../outside/secret.obj")),
        C("mjcf_meshdir_outside", topic, "MJCF_PATH_ESCAPES", _mjcf_folder("secret.obj", head='<compiler meshdir="../outside"/>')),
        C("mjcf_mesh_symlink_out", topic, "MJCF_PATH_ESCAPES",
          _mjcf_folder("link.obj", prepare=lambda f: os.symlink(f.parent / "outside" / "secret.obj", f / "link.obj"))),
        C("mjcf_texture_outside", topic, "MJCF_PATH_ESCAPES",
          _mjcf_folder(asset='<texture name="t" type="2d" file="../outside/secret.png"/>')),
        C("mjcf_mesh_fifo", topic, "INPUT_NOT_REGULAR_FILE", _mjcf_folder("pipe.obj", prepare=lambda f: os.mkfifo(f / "pipe.obj"))),
        C("mjcf_include_fifo", topic, "INPUT_NOT_REGULAR_FILE",
          _mjcf_folder(head='<include file="pipe.xml"/>', prepare=lambda f: os.mkfifo(f / "pipe.xml"))),
        C("mjcf_mesh_dev_zero", topic, "MJCF_PATH_ESCAPES",
          _mjcf_folder("zero.obj", prepare=lambda f: os.symlink("/dev/zero", f / "zero.obj"))),
        C("mjcf_include_loop", topic, "MJCF_INCLUDE_INVALID",
          _mjcf_folder(head='<include file="a.xml"/>', prepare=lambda f: (
              (f / "a.xml").write_text('<mujocoinclude><include file="b.xml"/></mujocoinclude>'),
              (f / "b.xml").write_text('<mujocoinclude><include file="a.xml"/></mujocoinclude>')))),
        C("mjcf_mesh_missing", topic, "INPUT_NOT_FOUND", _mjcf_folder("nosuch.obj")),
    ]
    try:
        import pxr  # noqa: F401  - the USD cases need usd-core (the [usd] extra)
    except ImportError:
        return out
    out += [
        C("usd_sublayer_absolute_outside", topic, "USD_LAYER_OUTSIDE_ASSET",
          lambda f: _usd_folder(f"subLayers = [@{f.parent / 'outside' / 'extra.usda'}@]")(f)),
        C("usd_sublayer_dotdot", topic, "USD_LAYER_OUTSIDE_ASSET", _usd_folder("subLayers = [@../outside/extra.usda@]")),
        C("usd_sublayer_fifo", topic, "INPUT_NOT_REGULAR_FILE",
          _usd_folder("subLayers = [@./pipe.usda@]", prepare=lambda f: os.mkfifo(f / "pipe.usda"))),
    ]
    return out


CASES: list[Case] = _cases()
CASES_BY_NAME: dict[str, Case] = {c.name: c for c in CASES}


#: Assets refine must handle that validate accepts (continuous and fixed
#: joints among them): name -> builder.
ACCEPTED: dict[str, Callable[[Path], Path]] = {
    "symlink_mesh_inside": _files_case(lambda f: os.symlink("lid.obj", f / "meshes" / "alias.obj"), _mesh("lid", "meshes/alias.obj")),
    "dotdot_through_existing_dir": _model_case(_mesh("lid", "images/../meshes/lid.obj")),
    "utf8_bom": _files_case(lambda f: (f / "mobility.urdf").write_bytes(b"\xef\xbb\xbf" + (f / "mobility.urdf").read_bytes())),
    "revolute_two_turns": _model_case(_attr("joint", "lid_hinge", lower="-12.5", upper="0")),
    "joint_continuous": _model_case(_attr("joint", "lid_hinge", type="continuous", lower=None, upper=None)),
    "joint_fixed": _model_case(_attr("joint", "lid_hinge", type="fixed", axis=None, lower=None, upper=None, effort=None,
                                     velocity=None, damping=None, friction=None)),
}


def clone_model(m: Model) -> Model:
    """A deep copy of a model."""
    return copy.deepcopy(m)
