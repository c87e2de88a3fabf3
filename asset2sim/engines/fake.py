"""The fake engine, and the URDF model the non-Bullet engines share.

Three things live here, all pure numpy (no simulator is imported):

1. :func:`read_urdf`: a small, strict reader of the URDF subset asset2sim writes
   (links with ``<inertial>``, ``<collision>`` meshes or primitives, the
   PyBullet ``<contact>`` extension; revolute / continuous / prismatic / fixed
   joints with ``<limit>`` and ``<dynamics>``), and :func:`mesh_hulls`, which
   splits a collision mesh into the point sets whose convex hulls PyBullet
   collides with (one hull per OBJ ``o``/``g`` group). The PhysX and MuJoCo
   engines build their bodies from this one reading, so the three engines see
   the same inertials, frames and hulls. (It is a fake's neighbour because the
   fake engine needs the same kinematic description; see ``docs/simulators.md``.)
2. :class:`FakeSession`: a deterministic :class:`~asset2sim.engines.base.SimSession`
   without physics. Joints and root follow closed-form trajectories set by a
   :class:`FakeBehaviour` (constant drift, sinusoidal oscillation, a
   penetration that may depend on the joint positions), so metric and pipeline
   tests run in milliseconds and can be made to pass or fail on purpose.
3. :func:`write_contract_asset`: writes a small asset that satisfies the SPEC's
   output contract (URDF + OBJ meshes, an ``<inertial>`` on every link,
   ``<dynamics>`` on every movable joint, ``initial_state.json`` and
   ``overlay.json``) for tests of engines, export and parity.

Units: SI, radians; poses are 4x4 homogeneous matrices (m) unless stated.
"""

from __future__ import annotations

import contextlib
import json
import math
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Callable, Iterator

import numpy as np

from asset2sim.engines.base import ContactPair, SessionOptions, register_engine

MOVABLE = ("revolute", "continuous", "prismatic")

#: What PyBullet 3.2.7 gives a link that has no ``<inertial>``: 1 kg, identity
#: inertia (kg*m^2) at the link origin (Bullet's ``UrdfParser``; checked in
#: ``tests/asset2sim/test_engines_fake.py``).
BULLET_DEFAULT_MASS = 1.0
BULLET_DEFAULT_INERTIA = (1.0, 1.0, 1.0)
#: PyBullet's default lateral friction of a link and of its ground plane; the
#: contact friction is their product (Bullet multiplies), 0.25.
BULLET_DEFAULT_FRICTION = 0.5
BULLET_PLANE_FRICTION = 0.5


class UrdfError(ValueError):
    """The URDF cannot be read (names the file and the element)."""


# ------------------------------------------------------------------ geometry
def rpy_matrix(rpy) -> np.ndarray:
    """Rotation (3, 3) of URDF roll-pitch-yaw (rad): fixed axes X, then Y, then Z,
    i.e. R = Rz(yaw) @ Ry(pitch) @ Rx(roll)."""
    r, p, y = (float(v) for v in rpy)
    cr, sr, cp, sp, cy, sy = math.cos(r), math.sin(r), math.cos(p), math.sin(p), math.cos(y), math.sin(y)
    return np.array(
        [
            [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
            [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
            [-sp, cp * sr, cp * cr],
        ]
    )


def pose_matrix(xyz=(0.0, 0.0, 0.0), rpy=(0.0, 0.0, 0.0)) -> np.ndarray:
    """Homogeneous transform (4, 4) of a URDF origin (xyz m, rpy rad)."""
    t = np.eye(4)
    t[:3, :3] = rpy_matrix(rpy)
    t[:3, 3] = np.asarray(xyz, float)
    return t


def matrix_quat_wxyz(r: np.ndarray) -> np.ndarray:
    """Unit quaternion (4,) w, x, y, z of a rotation matrix (3, 3), w >= 0."""
    r = np.asarray(r, float)
    tr = r[0, 0] + r[1, 1] + r[2, 2]
    if tr > 0:
        s = math.sqrt(tr + 1.0) * 2
        q = [0.25 * s, (r[2, 1] - r[1, 2]) / s, (r[0, 2] - r[2, 0]) / s, (r[1, 0] - r[0, 1]) / s]
    elif r[0, 0] > r[1, 1] and r[0, 0] > r[2, 2]:
        s = math.sqrt(1.0 + r[0, 0] - r[1, 1] - r[2, 2]) * 2
        q = [(r[2, 1] - r[1, 2]) / s, 0.25 * s, (r[0, 1] + r[1, 0]) / s, (r[0, 2] + r[2, 0]) / s]
    elif r[1, 1] > r[2, 2]:
        s = math.sqrt(1.0 + r[1, 1] - r[0, 0] - r[2, 2]) * 2
        q = [(r[0, 2] - r[2, 0]) / s, (r[0, 1] + r[1, 0]) / s, 0.25 * s, (r[1, 2] + r[2, 1]) / s]
    else:
        s = math.sqrt(1.0 + r[2, 2] - r[0, 0] - r[1, 1]) * 2
        q = [(r[1, 0] - r[0, 1]) / s, (r[0, 2] + r[2, 0]) / s, (r[1, 2] + r[2, 1]) / s, 0.25 * s]
    q = np.array(q)
    q /= np.linalg.norm(q)
    return -q if q[0] < 0 else q


# ------------------------------------------------------------------ the model
@dataclass
class UrdfInertial:
    """``<inertial>``: ``mass`` kg, ``origin`` (4, 4) COM frame in the link
    frame, ``inertia`` (3, 3) kg*m^2 about the COM in the COM frame's axes."""

    mass: float
    origin: np.ndarray
    inertia: np.ndarray

    def com(self) -> np.ndarray:
        """COM (3,) in the link frame, m."""
        return self.origin[:3, 3].copy()

    def inertia_in_link_axes(self) -> np.ndarray:
        """Inertia (3, 3) about the COM expressed in the link frame's axes."""
        r = self.origin[:3, :3]
        return r @ self.inertia @ r.T


@dataclass
class UrdfCollision:
    """``<collision>``: ``kind`` mesh / box / cylinder / sphere; ``origin`` (4, 4)
    in the link frame; mesh ``path`` (absolute) with ``filename`` as written and
    ``scale`` (3,); ``size`` (3,) m for boxes; ``radius``/``length`` m."""

    kind: str
    origin: np.ndarray
    filename: str | None = None
    path: Path | None = None
    scale: np.ndarray = field(default_factory=lambda: np.ones(3))
    size: np.ndarray | None = None
    radius: float | None = None
    length: float | None = None


@dataclass
class UrdfLink:
    """A link: inertial (None when the file has none), collisions and visuals
    in file order (visuals use :class:`UrdfCollision` for their geometry), and
    the PyBullet ``<contact>`` extension values when present."""

    name: str
    inertial: UrdfInertial | None
    collisions: list[UrdfCollision]
    lateral_friction: float | None = None
    restitution: float | None = None
    visuals: list[UrdfCollision] = field(default_factory=list)


@dataclass
class UrdfJoint:
    """A joint: ``type`` as written; ``origin`` (4, 4) child frame in the parent
    frame; unit ``axis`` (3,) in the child frame; limits (rad or m; +-inf when
    absent or continuous); ``damping`` (N*m*s/rad or N*s/m) and ``friction``
    (N*m or N) from ``<dynamics>`` (0 when absent)."""

    name: str
    type: str
    parent: str
    child: str
    origin: np.ndarray
    axis: np.ndarray
    lower: float = -math.inf
    upper: float = math.inf
    damping: float = 0.0
    friction: float = 0.0
    has_dynamics: bool = False


@dataclass
class UrdfModel:
    """A parsed URDF. ``joints`` in file order; ``root`` the link without a
    parent joint; ``path`` the file."""

    name: str
    path: Path
    links: dict[str, UrdfLink]
    joints: list[UrdfJoint]
    root: str

    @property
    def movable_joints(self) -> list[UrdfJoint]:
        """Revolute, continuous and prismatic joints in file order."""
        return [j for j in self.joints if j.type in MOVABLE]

    def parent_joint(self, link: str) -> UrdfJoint | None:
        for j in self.joints:
            if j.child == link:
                return j
        return None

    def children(self, link: str) -> list[UrdfJoint]:
        return [j for j in self.joints if j.parent == link]

    def tree_order(self) -> list[str]:
        """Links depth-first from the root (children in joint file order)."""
        out, stack = [], [self.root]
        while stack:
            name = stack.pop()
            out.append(name)
            stack.extend(j.child for j in reversed(self.children(name)))
        return out

    def total_mass(self) -> float:
        """Sum of the file's ``<inertial>`` masses, kg (links without one count 0)."""
        return float(sum(l.inertial.mass for l in self.links.values() if l.inertial is not None))

    def adjacent_pairs(self) -> set[frozenset[str]]:
        """Parent-child link pairs (every joint, fixed ones included)."""
        return {frozenset((j.parent, j.child)) for j in self.joints}

    def link_poses(self, q: dict[str, float] | None = None, root_pose: np.ndarray | None = None) -> dict[str, np.ndarray]:
        """World pose (4, 4) of every link for joint positions ``q`` (rad or m,
        missing joints at 0) and the root link pose ``root_pose`` (identity)."""
        q = q or {}
        poses = {self.root: np.eye(4) if root_pose is None else np.asarray(root_pose, float)}
        for name in self.tree_order():
            for j in self.children(name):
                t = poses[name] @ j.origin
                v = float(q.get(j.name, 0.0))
                m = np.eye(4)
                if j.type in ("revolute", "continuous"):
                    m[:3, :3] = _axis_angle(j.axis, v)
                elif j.type == "prismatic":
                    m[:3, 3] = j.axis * v
                poses[j.child] = t @ m
        return poses


def _axis_angle(axis: np.ndarray, angle: float) -> np.ndarray:
    a = np.asarray(axis, float)
    a = a / np.linalg.norm(a)
    k = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    return np.eye(3) + math.sin(angle) * k + (1 - math.cos(angle)) * (k @ k)


def _floats(text: str | None, n: int, where: str, default=None) -> np.ndarray:
    if text is None:
        if default is None:
            raise UrdfError(f"{where}: missing value")
        return np.asarray(default, float)
    try:
        vals = [float(v) for v in text.split()]
    except ValueError as exc:
        raise UrdfError(f"{where}: not numbers: {text!r}") from exc
    if len(vals) == 1 and n == 3:
        vals = vals * 3
    if len(vals) != n or not all(math.isfinite(v) for v in vals):
        raise UrdfError(f"{where}: expected {n} finite numbers, got {text!r}")
    return np.asarray(vals, float)


def _origin(elem, where: str) -> np.ndarray:
    o = elem.find("origin") if elem is not None else None
    if o is None:
        return np.eye(4)
    return pose_matrix(_floats(o.get("xyz"), 3, f"{where} origin xyz", (0, 0, 0)), _floats(o.get("rpy"), 3, f"{where} origin rpy", (0, 0, 0)))


def _parse_xml(path: Path):
    from lxml import etree

    parser = etree.XMLParser(resolve_entities=False, no_network=True, load_dtd=False, remove_comments=True, huge_tree=False)
    try:
        return etree.parse(str(path), parser).getroot()
    except (OSError, etree.XMLSyntaxError) as exc:
        raise UrdfError(f"{path}: cannot parse URDF: {exc}") from exc


def _geometry(elem, base: Path, where: str) -> UrdfCollision:
    ge = elem.find("geometry")
    if ge is None or len(ge) == 0:
        raise UrdfError(f"{where}: no <geometry>")
    g = ge[0]
    org = _origin(elem, where)
    if g.tag == "mesh":
        fname = g.get("filename")
        if not fname:
            raise UrdfError(f"{where}: mesh without filename")
        rel = fname[len("package://"):] if fname.startswith("package://") else fname
        rel = rel[len("file://"):] if rel.startswith("file://") else rel
        return UrdfCollision(
            kind="mesh",
            origin=org,
            filename=fname,
            path=(base / rel).resolve(),
            scale=_floats(g.get("scale"), 3, f"{where} scale", (1, 1, 1)),
        )
    if g.tag == "box":
        return UrdfCollision(kind="box", origin=org, size=_floats(g.get("size"), 3, f"{where} size"))
    if g.tag == "cylinder":
        return UrdfCollision(
            kind="cylinder",
            origin=org,
            radius=float(_floats(g.get("radius"), 1, f"{where} radius")[0]),
            length=float(_floats(g.get("length"), 1, f"{where} length")[0]),
        )
    if g.tag == "sphere":
        return UrdfCollision(kind="sphere", origin=org, radius=float(_floats(g.get("radius"), 1, f"{where} radius")[0]))
    raise UrdfError(f"{where}: unsupported geometry <{g.tag}>")


def read_urdf(path: Path | str) -> UrdfModel:
    """Read a URDF file into a :class:`UrdfModel`.

    Mesh file names are resolved relative to the URDF's folder (``package://``
    prefixes are stripped and resolved the same way).

    Raises:
        UrdfError: unreadable XML, a malformed number, an unknown joint type, a
            joint naming a missing link, or not exactly one root link.
    """
    path = Path(path)
    root = _parse_xml(path)
    if root.tag != "robot":
        raise UrdfError(f"{path}: root element is <{root.tag}>, not <robot>")
    base = path.parent
    links: dict[str, UrdfLink] = {}
    for le in root.findall("link"):
        name = le.get("name")
        if not name:
            raise UrdfError(f"{path}: a <link> has no name")
        where = f"{path}: link {name!r}"
        inertial = None
        ie = le.find("inertial")
        if ie is not None:
            me, te = ie.find("mass"), ie.find("inertia")
            if me is None or te is None:
                raise UrdfError(f"{where}: <inertial> needs <mass> and <inertia>")
            mass = float(_floats(me.get("value"), 1, f"{where} mass")[0])
            vals = {k: float(_floats(te.get(k, "0"), 1, f"{where} inertia {k}")[0]) for k in ("ixx", "ixy", "ixz", "iyy", "iyz", "izz")}
            inertia = np.array(
                [
                    [vals["ixx"], vals["ixy"], vals["ixz"]],
                    [vals["ixy"], vals["iyy"], vals["iyz"]],
                    [vals["ixz"], vals["iyz"], vals["izz"]],
                ]
            )
            inertial = UrdfInertial(mass=mass, origin=_origin(ie, f"{where} inertial"), inertia=inertia)
        cols = [_geometry(ce, base, f"{where} collision {k}") for k, ce in enumerate(le.findall("collision"))]
        vis = [_geometry(ve, base, f"{where} visual {k}") for k, ve in enumerate(le.findall("visual"))]
        lat = rest = None
        ct = le.find("contact")
        if ct is not None:
            lf, rs = ct.find("lateral_friction"), ct.find("restitution")
            if lf is not None:
                lat = float(_floats(lf.get("value"), 1, f"{where} lateral_friction")[0])
            if rs is not None:
                rest = float(_floats(rs.get("value"), 1, f"{where} restitution")[0])
        links[name] = UrdfLink(name, inertial, cols, lat, rest, visuals=vis)
    joints = []
    children = set()
    for je in root.findall("joint"):
        name, jtype = je.get("name"), je.get("type")
        where = f"{path}: joint {name!r}"
        if jtype not in MOVABLE + ("fixed",):
            raise UrdfError(f"{where}: joint type {jtype!r} is not supported (revolute, continuous, prismatic, fixed)")
        pe, ce = je.find("parent"), je.find("child")
        if pe is None or ce is None or pe.get("link") not in links or ce.get("link") not in links:
            raise UrdfError(f"{where}: parent/child must name links of the file")
        axis = _floats(je.find("axis").get("xyz") if je.find("axis") is not None else None, 3, f"{where} axis", (1, 0, 0))
        n = np.linalg.norm(axis)
        if jtype != "fixed" and n < 1e-12:
            raise UrdfError(f"{where}: zero axis")
        axis = axis / n if n > 0 else np.array([1.0, 0.0, 0.0])
        lo, hi = -math.inf, math.inf
        lim = je.find("limit")
        if jtype in ("revolute", "prismatic"):
            if lim is None:
                raise UrdfError(f"{where}: {jtype} joint without <limit>")
            lo = float(_floats(lim.get("lower", "0"), 1, f"{where} lower")[0])
            hi = float(_floats(lim.get("upper", "0"), 1, f"{where} upper")[0])
        damping = friction = 0.0
        dyn = je.find("dynamics")
        if dyn is not None:
            damping = float(_floats(dyn.get("damping", "0"), 1, f"{where} damping")[0])
            friction = float(_floats(dyn.get("friction", "0"), 1, f"{where} friction")[0])
        child = ce.get("link")
        if child in children:
            raise UrdfError(f"{where}: link {child!r} has two parent joints")
        children.add(child)
        joints.append(
            UrdfJoint(
                name=name,
                type=jtype,
                parent=pe.get("link"),
                child=child,
                origin=_origin(je, where),
                axis=axis,
                lower=lo,
                upper=hi,
                damping=damping,
                friction=friction,
                has_dynamics=dyn is not None,
            )
        )
    roots = [n for n in links if n not in children]
    if len(roots) != 1:
        raise UrdfError(f"{path}: expected one root link, found {roots}")
    model = UrdfModel(name=root.get("name", path.stem), path=path, links=links, joints=joints, root=roots[0])
    if len(model.tree_order()) != len(links):
        raise UrdfError(f"{path}: the joints do not form a tree over all links")
    return model


# ------------------------------------------------------------ collision hulls
_HULL_CACHE: dict[tuple, list[np.ndarray]] = {}


def obj_groups(path: Path) -> list[np.ndarray]:
    """Point sets (k, 3) of an OBJ file, one per ``o``/``g`` group that has
    faces, holding the vertices its faces use (file units, unscaled).

    This is how PyBullet's URDF importer builds collision shapes from an OBJ
    (one convex hull per tinyobj shape), verified in
    ``tests/asset2sim/test_engines_fake.py``.

    Raises:
        UrdfError: the file cannot be read or a face names a missing vertex.
    """
    try:
        text = Path(path).read_text(errors="replace")
    except OSError as exc:
        raise UrdfError(f"cannot read mesh {path}: {exc}") from exc
    verts: list[tuple[float, float, float]] = []
    groups: list[list[int]] = []
    current: list[int] = []
    for line in text.splitlines():
        if not line or line[0] not in "vfog":
            continue
        parts = line.split()
        if not parts:
            continue
        tag = parts[0]
        if tag == "v":
            try:
                verts.append((float(parts[1]), float(parts[2]), float(parts[3])))
            except (IndexError, ValueError) as exc:
                raise UrdfError(f"{path}: bad vertex line {line!r}") from exc
        elif tag == "f":
            for tok in parts[1:]:
                try:
                    i = int(tok.split("/")[0])
                except ValueError as exc:
                    raise UrdfError(f"{path}: bad face line {line!r}") from exc
                current.append(i - 1 if i > 0 else len(verts) + i)
        elif tag in ("o", "g"):
            if current:
                groups.append(current)
            current = []
    if current:
        groups.append(current)
    v = np.asarray(verts, float).reshape(-1, 3)
    out = []
    for idx in groups:
        ids = np.unique(np.asarray(idx, int))
        if ids.min() < 0 or ids.max() >= len(v):
            raise UrdfError(f"{path}: a face names a vertex that does not exist")
        out.append(v[ids])
    return out


def mesh_hulls(path: Path, scale=(1.0, 1.0, 1.0)) -> list[np.ndarray]:
    """Point sets (k, 3), m, whose convex hulls PyBullet uses for a collision
    mesh ``path`` scaled by ``scale`` (3,): one per OBJ group; other formats
    (STL, ...) as one set of all vertices (loaded with trimesh). Cached by file
    modification time. Sets with fewer than 4 points or no volume are kept:
    engines decide what to do with them.

    Raises:
        UrdfError: the mesh cannot be read.
    """
    path = Path(path)
    try:
        st = path.stat()
    except OSError as exc:
        raise UrdfError(f"collision mesh {path} does not exist") from exc
    key = (str(path), st.st_mtime_ns, st.st_size)
    groups = _HULL_CACHE.get(key)
    if groups is None:
        if path.suffix.lower() == ".obj":
            groups = obj_groups(path)
        else:
            import trimesh

            try:
                m = trimesh.load(str(path), force="mesh", process=False)
            except Exception as exc:  # trimesh raises many types
                raise UrdfError(f"cannot read mesh {path}: {exc}") from exc
            groups = [np.asarray(m.vertices, float)]
        if len(_HULL_CACHE) > 4096:
            _HULL_CACHE.clear()
        _HULL_CACHE[key] = groups
    s = np.asarray(scale, float).reshape(3)
    return [g * s for g in groups]


def hull_is_solid(points: np.ndarray, tol: float = 1e-9) -> bool:
    """True when the points (k, 3) span a volume (not all on one plane/line)."""
    p = np.asarray(points, float)
    if len(p) < 4:
        return False
    c = p - p.mean(axis=0)
    sv = np.linalg.svd(c, compute_uv=False)
    return bool(sv[-1] > tol * max(1.0, sv[0]))


#: Thickness (m) given to a collision hull whose points are coplanar: PyBullet
#: keeps such a hull and inflates it by its 1 mm collision margin on each side,
#: PhysX cannot cook it and MuJoCo refuses it, so both get a 2 mm slab instead.
FLAT_HULL_THICKNESS = 0.002


@dataclass
class CollisionPiece:
    """One convex collision shape of a link, as PyBullet builds it.

    ``kind``: ``hull`` (``points`` (k, 3) m in the collision frame, scale
    applied), ``box`` (``size`` (3,) full extents m), ``sphere`` (``radius``),
    ``cylinder`` (``radius``, ``length`` along z). ``origin`` (4, 4) collision
    frame in the link frame. ``collision`` index of the URDF ``<collision>``,
    ``group`` index of the OBJ group; ``source`` the mesh file; ``whole_file``
    True when the hull is the whole (single-group) file unchanged, so exports
    may reference the file itself; ``thickened`` True for a coplanar group made
    a slab of :data:`FLAT_HULL_THICKNESS`.
    """

    link: str
    collision: int
    group: int
    kind: str
    origin: np.ndarray
    points: np.ndarray | None = None
    size: np.ndarray | None = None
    radius: float | None = None
    length: float | None = None
    source: Path | None = None
    scale: np.ndarray | None = None
    whole_file: bool = False
    thickened: bool = False


def _thicken(points: np.ndarray, thickness: float) -> np.ndarray | None:
    p = np.asarray(points, float)
    c = p.mean(axis=0)
    _, sv, vt = np.linalg.svd(p - c, full_matrices=False)
    if len(sv) < 2 or sv[1] <= 1e-12 * max(1.0, sv[0]):
        return None  # a point or a segment: nothing to collide with
    n = vt[-1] if len(vt) == 3 else np.cross(vt[0], vt[1])
    n = n / np.linalg.norm(n)
    h = 0.5 * thickness
    return np.vstack([p + h * n, p - h * n])


def collision_pieces(model: UrdfModel, flat_thickness: float = FLAT_HULL_THICKNESS) -> tuple[dict[str, list[CollisionPiece]], list[str]]:
    """Every link's convex collision pieces (PyBullet's convention: one hull
    per OBJ group), and notes on what had to change: coplanar groups become
    slabs ``flat_thickness`` m thick, groups spanning no area are dropped.

    Raises:
        UrdfError: a mesh cannot be read.
    """
    out: dict[str, list[CollisionPiece]] = {}
    notes: list[str] = []
    for name, link in model.links.items():
        pieces: list[CollisionPiece] = []
        for k, c in enumerate(link.collisions):
            if c.kind != "mesh":
                pieces.append(
                    CollisionPiece(name, k, 0, c.kind, c.origin, size=c.size, radius=c.radius, length=c.length)
                )
                continue
            groups = mesh_hulls(c.path, c.scale)
            for g, pts in enumerate(groups):
                thick = False
                if not hull_is_solid(pts):
                    slab = _thicken(pts, flat_thickness)
                    if slab is None:
                        notes.append(f"link {name!r} collision {k} group {g} ({c.filename}) spans no area: dropped")
                        continue
                    notes.append(
                        f"link {name!r} collision {k} group {g} ({c.filename}) is flat: made a {flat_thickness * 1000:g} mm slab"
                    )
                    pts, thick = slab, True
                pieces.append(
                    CollisionPiece(
                        name,
                        k,
                        g,
                        "hull",
                        c.origin,
                        points=pts,
                        source=c.path,
                        scale=np.asarray(c.scale, float),
                        whole_file=len(groups) == 1 and not thick,
                        thickened=thick,
                    )
                )
        out[name] = pieces
    return out, notes


def read_initial_state(folder: Path) -> dict[str, float]:
    """``initial_state.json`` of an output folder: joint -> rad or m ({} when absent).

    Raises:
        ValueError: the file exists but is not the contract's shape.
    """
    p = Path(folder) / "initial_state.json"
    if not p.is_file():
        return {}
    data = json.loads(p.read_text())
    q = data.get("initial_joint_positions") if isinstance(data, dict) else None
    if not isinstance(q, dict):
        raise ValueError(f"{p}: expected {{'initial_joint_positions': {{joint: value}}}}")
    return {str(k): float(v) for k, v in q.items()}


# ----------------------------------------------------------------- the fake
@dataclass
class FakeBehaviour:
    """What a :class:`FakeSession` does, all closed-form in time t (s) since
    the joint was last set.

    - ``penetration``: Phi (m), a constant or a function of the joint positions
      (dict -> m), attributed to ``pair`` (default: the first two links that
      are not parent and child, else the first two links).
    - ``root_velocity`` (3,) m/s and ``root_yaw_rate`` rad/s: constant drift
      of the root (zero with ``fixed_base``).
    - ``joint_drift``: joint -> rad/s or m/s (``"*"`` for all joints).
    - ``joint_oscillation``: joint -> (amplitude, frequency): q += a sin(2 pi f t),
      a in rad or m (half the peak-to-peak), f in Hz (``"*"`` for all joints).
    - ``ground_penetration`` m.
    - ``springs_pull``: when True (default) a joint with a spring relaxes to its
      reference with time constant ``spring_time_constant`` s instead of drifting.
    Positions are clipped to the joint limits.
    """

    penetration: float | Callable[[dict[str, float]], float] = 0.0
    pair: tuple[str, str] | None = None
    root_velocity: tuple[float, float, float] = (0.0, 0.0, 0.0)
    root_yaw_rate: float = 0.0
    joint_drift: dict[str, float] = field(default_factory=dict)
    joint_oscillation: dict[str, tuple[float, float]] = field(default_factory=dict)
    ground_penetration: float = 0.0
    springs_pull: bool = True
    spring_time_constant: float = 0.2


_DEFAULT_BEHAVIOUR = FakeBehaviour()


@contextlib.contextmanager
def fake_behaviour(behaviour: FakeBehaviour | None = None, **changes) -> Iterator[FakeBehaviour]:
    """Within the block, sessions opened with ``open_session("fake", ...)`` use
    ``behaviour`` (or the default with ``changes`` applied)."""
    global _DEFAULT_BEHAVIOUR
    old = _DEFAULT_BEHAVIOUR
    _DEFAULT_BEHAVIOUR = replace(behaviour or FakeBehaviour(), **changes)
    try:
        yield _DEFAULT_BEHAVIOUR
    finally:
        _DEFAULT_BEHAVIOUR = old


class FakeSession:
    """A :class:`~asset2sim.engines.base.SimSession` without physics (see the
    module docstring). Deterministic: the same calls give the same numbers.

    Raises (constructor):
        UrdfError: the URDF cannot be read.
    """

    engine = "fake"

    def __init__(self, urdf_path: Path, options: SessionOptions, behaviour: FakeBehaviour | None = None):
        self.model = read_urdf(urdf_path)
        self.options = options
        self.behaviour = behaviour or _DEFAULT_BEHAVIOUR
        self.dt = options.conventions.timestep
        self.joint_names = [j.name for j in self.model.movable_joints]
        self.joint_types = {j.name: j.type for j in self.model.movable_joints}
        self.joint_limits = {j.name: (j.lower, j.upper) for j in self.model.movable_joints}
        self.steps = 0
        self._anchor = {n: (0.0, 0) for n in self.joint_names}  # value, step when set
        self.set_joint_positions(options.initial_state)
        self._root0 = np.zeros(3)

    def _t(self, name: str) -> float:
        return (self.steps - self._anchor[name][1]) * self.dt

    def _value(self, name: str) -> float:
        b = self.behaviour
        q0, _ = self._anchor[name]
        t = self._t(name)
        spring = self.options.springs.get(name)
        if spring is not None and b.springs_pull and spring.stiffness > 0:
            q = spring.reference + (q0 - spring.reference) * math.exp(-t / b.spring_time_constant)
        else:
            q = q0 + b.joint_drift.get(name, b.joint_drift.get("*", 0.0)) * t
        osc = b.joint_oscillation.get(name, b.joint_oscillation.get("*"))
        if osc is not None:
            q += osc[0] * math.sin(2 * math.pi * osc[1] * t)
        lo, hi = self.joint_limits[name]
        return float(min(max(q, lo), hi))

    def set_joint_positions(self, q: dict[str, float], zero_velocity: bool = True) -> None:
        for name, v in q.items():
            if name in self._anchor:
                self._anchor[name] = (float(v), self.steps)

    def joint_positions(self) -> dict[str, float]:
        return {n: self._value(n) for n in self.joint_names}

    def _pair(self) -> tuple[str, str]:
        if self.behaviour.pair is not None:
            return self.behaviour.pair
        names = self.model.tree_order()
        adj = self.model.adjacent_pairs()
        for i, a in enumerate(names):
            for b in names[i + 1:]:
                if frozenset((a, b)) not in adj:
                    return (a, b) if a <= b else (b, a)
        return (names[0], names[-1])

    def self_penetration(self) -> tuple[float, list[ContactPair]]:
        pen = self.behaviour.penetration
        phi = float(pen(self.joint_positions()) if callable(pen) else pen)
        phi = max(0.0, phi)
        if phi <= 0:
            return 0.0, []
        a, b = self._pair()
        return phi, [ContactPair(a, b, phi, phi, 1)]

    def ground_penetration(self) -> float:
        return float(self.behaviour.ground_penetration)

    def root_pose(self) -> tuple[np.ndarray, np.ndarray]:
        if self.options.fixed_base:
            return self._root0.copy(), np.array([0.0, 0.0, 0.0, 1.0])
        t = self.steps * self.dt
        pos = self._root0 + np.asarray(self.behaviour.root_velocity, float) * t
        half = 0.5 * self.behaviour.root_yaw_rate * t
        return pos, np.array([0.0, 0.0, math.sin(half), math.cos(half)])

    def step(self, n: int = 1) -> None:
        self.steps += int(n)

    def close(self) -> None:
        pass

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def _open(urdf_path: Path, options: SessionOptions) -> FakeSession:
    return FakeSession(urdf_path, options)


register_engine("fake", _open)


# ------------------------------------------------------ contract test asset
def _box_obj(boxes: list[tuple[tuple[float, float, float], tuple[float, float, float]]], groups: bool = True) -> str:
    """OBJ text of axis-aligned boxes given as (min corner, max corner), one
    ``o`` group each (or one group for all when ``groups`` is False)."""
    faces = [(0, 1, 3), (0, 3, 2), (4, 6, 7), (4, 7, 5), (0, 4, 5), (0, 5, 1), (2, 3, 7), (2, 7, 6), (0, 2, 6), (0, 6, 4), (1, 5, 7), (1, 7, 3)]
    lines, off = [], 1
    for k, (lo, hi) in enumerate(boxes):
        if groups or k == 0:
            lines.append(f"o piece_{k}")
        for i in range(8):
            x = hi[0] if i & 4 else lo[0]
            y = hi[1] if i & 2 else lo[1]
            z = hi[2] if i & 1 else lo[2]
            lines.append(f"v {x!r} {y!r} {z!r}")
        lines.extend(f"f {a + off} {b + off} {c + off}" for a, b, c in faces)
        off += 8
    return "\n".join(lines) + "\n"


def _box_inertia(mass: float, lo, hi) -> tuple[np.ndarray, np.ndarray]:
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    d = hi - lo
    return (lo + hi) / 2, mass / 12.0 * np.diag([d[1] ** 2 + d[2] ** 2, d[0] ** 2 + d[2] ** 2, d[0] ** 2 + d[1] ** 2])


def _combine(parts: list[tuple[float, np.ndarray, np.ndarray]]) -> tuple[float, np.ndarray, np.ndarray]:
    """Mass, COM (3,), inertia about the COM (3, 3) of point-mass-shifted parts."""
    m = sum(p[0] for p in parts)
    com = sum(p[0] * p[1] for p in parts) / m
    inertia = np.zeros((3, 3))
    for mi, ci, ii in parts:
        d = ci - com
        inertia += ii + mi * (np.dot(d, d) * np.eye(3) - np.outer(d, d))
    return m, com, inertia


@dataclass
class ContractAsset:
    """Paths and facts of an asset written by :func:`write_contract_asset`."""

    root: Path
    urdf: Path
    initial_state: dict[str, float]
    masses: dict[str, float]
    lid_mass: float
    lid_com_radius: float
    """distance (m) of the lid's COM from the hinge axis, in the lid plane"""
    post_overlap_at: float
    """post position (m) above which the post's top pokes into the closed lid"""


def write_contract_asset(
    out_dir: Path,
    *,
    lid_angle: float = 0.0,
    post_height: float = 0.0,
    lid_damping: float = 0.02,
    lid_friction: float = 0.02,
    lid_stiffness: float = 0.0,
    lid_spring_reference: float | None = None,
    post_damping: float = 1.0,
    post_friction: float = 2.0,
    base_inertial: bool = True,
    body_mass: float = 1.5,
    lid_mass: float = 0.2,
) -> ContractAsset:
    """Write a small box-with-lid asset that satisfies the SPEC output contract.

    Links: ``base`` (root, a fixed joint to ``body``; an ``<inertial>`` only
    when ``base_inertial``), ``body`` (an open box 0.30 x 0.20 x 0.12 m whose
    five walls are five ``o`` groups of one OBJ), ``lid`` (0.30 x 0.20 x 0.01 m
    plate on a revolute hinge along -x at the top back edge; ``lid_angle`` rad,
    positive opens; limits [0, 2.0]) and ``post`` (a 0.02 x 0.02 x 0.10 m
    square post standing in the box on a prismatic joint along +z, limits
    [0, 0.05] m; at ``post_height`` > ``post_overlap_at`` its top pokes into
    the closed lid, which is a sibling, so the two collide).

    Masses kg, damping N*m*s/rad (lid) / N*s/m (post), friction N*m / N,
    stiffness N*m/rad. Files: ``mobility.urdf``, ``textured_objs/*.obj``,
    ``initial_state.json``, ``overlay.json``. Returns a :class:`ContractAsset`.
    """
    from asset2sim import atomic

    out = Path(out_dir)
    L, W, H, t = 0.30, 0.20, 0.12, 0.01
    walls = [
        ((-L / 2, -W / 2, 0.0), (L / 2, W / 2, t)),
        ((-L / 2, -W / 2, t), (-L / 2 + t, W / 2, H)),
        ((L / 2 - t, -W / 2, t), (L / 2, W / 2, H)),
        ((-L / 2 + t, -W / 2, t), (L / 2 - t, -W / 2 + t, H)),
        ((-L / 2 + t, W / 2 - t, t), (L / 2 - t, W / 2, H)),
    ]
    # The lid frame sits on the hinge at the top back edge (y = +W/2, z = H);
    # the plate extends towards -y, 0.5 mm above the walls, and the hinge axis
    # is -x so that positive angles lift its front edge.
    lid_lo, lid_hi = (-L / 2, -W, 0.0005), (L / 2, 0.0, 0.0005 + t)
    post_lo, post_hi = (-0.01, -0.01, t), (0.01, 0.01, t + 0.10)
    gap = H + 0.0005 - post_hi[2]  # post top to lid underside at q=0
    atomic.write_text(out / "textured_objs" / "body.obj", _box_obj(walls))
    atomic.write_text(out / "textured_objs" / "lid.obj", _box_obj([(lid_lo, lid_hi)]))
    atomic.write_text(out / "textured_objs" / "post.obj", _box_obj([(post_lo, post_hi)]))

    vol = [np.prod(np.subtract(hi, lo)) for lo, hi in walls]
    body = _combine([(body_mass * v / sum(vol), *_box_inertia(body_mass * v / sum(vol), lo, hi)) for v, (lo, hi) in zip(vol, walls)])
    lid = (lid_mass, *_box_inertia(lid_mass, lid_lo, lid_hi))
    post_mass = 0.05
    post = (post_mass, *_box_inertia(post_mass, post_lo, post_hi))
    base = (0.01, np.zeros(3), np.diag([1e-5, 1e-5, 1e-5]))

    def inertial(m, com, inertia):
        f = lambda x: repr(float(x))  # noqa: E731 - shortest round-trip text
        return (
            f'    <inertial>\n      <origin xyz="{f(com[0])} {f(com[1])} {f(com[2])}" rpy="0 0 0"/>\n'
            f'      <mass value="{f(m)}"/>\n'
            f'      <inertia ixx="{f(inertia[0, 0])}" ixy="{f(inertia[0, 1])}" ixz="{f(inertia[0, 2])}" '
            f'iyy="{f(inertia[1, 1])}" iyz="{f(inertia[1, 2])}" izz="{f(inertia[2, 2])}"/>\n    </inertial>\n'
        )

    def mesh(name, origin="0 0 0"):
        geo = f'<geometry><mesh filename="textured_objs/{name}.obj" scale="1 1 1"/></geometry>'
        return f'    <visual><origin xyz="{origin}"/>{geo}</visual>\n    <collision><origin xyz="{origin}"/>{geo}</collision>\n'

    urdf = (
        '<?xml version="1.0" encoding="utf-8"?>\n<robot name="contract_box">\n'
        "  <!-- initial joint positions: initial_state.json -->\n"
        f'  <link name="base">\n{inertial(*base) if base_inertial else ""}  </link>\n'
        f'  <link name="body">\n{inertial(*body)}{mesh("body")}  </link>\n'
        f'  <link name="lid">\n{inertial(*lid)}{mesh("lid")}  </link>\n'
        f'  <link name="post">\n{inertial(*post)}{mesh("post")}  </link>\n'
        '  <joint name="root_fixed" type="fixed"><parent link="base"/><child link="body"/>'
        '<origin xyz="0 0 0" rpy="0 0 0"/></joint>\n'
        f'  <joint name="lid_hinge" type="revolute"><parent link="body"/><child link="lid"/>'
        f'<origin xyz="0 {W / 2!r} {H!r}" rpy="0 0 0"/><axis xyz="-1 0 0"/>'
        f'<limit lower="0.0" upper="2.0" effort="1000" velocity="1000"/>'
        f'<dynamics damping="{lid_damping!r}" friction="{lid_friction!r}"/></joint>\n'
        f'  <joint name="post_slide" type="prismatic"><parent link="body"/><child link="post"/>'
        f'<origin xyz="0 0 0" rpy="0 0 0"/><axis xyz="0 0 1"/>'
        f'<limit lower="0.0" upper="0.05" effort="1000" velocity="1000"/>'
        f'<dynamics damping="{post_damping!r}" friction="{post_friction!r}"/></joint>\n'
        "</robot>\n"
    )
    urdf_path = atomic.write_text(out / "mobility.urdf", urdf)
    state = {"lid_hinge": float(lid_angle), "post_slide": float(post_height)}
    atomic.write_json(out / "initial_state.json", {"initial_joint_positions": state})

    def link_entry(m, com, inertia):
        return {
            "mass": float(m),
            "inertia": {k: float(inertia[i, j]) for k, (i, j) in {"ixx": (0, 0), "ixy": (0, 1), "ixz": (0, 2), "iyy": (1, 1), "iyz": (1, 2), "izz": (2, 2)}.items()},
            "com": [float(c) for c in com],
            "source": "geometry",
        }

    links = {"body": link_entry(*body), "lid": link_entry(*lid), "post": link_entry(*post)}
    if base_inertial:
        links["base"] = link_entry(*base)
    overlay = {
        "schema_version": "1.0",
        "estimator": {"name": "test-fixture", "queries": 0},
        "scale": 1.0,
        "links": links,
        "joints": {
            "lid_hinge": {
                "damping": float(lid_damping),
                "friction": float(lid_friction),
                "stiffness": float(lid_stiffness),
                "spring_reference": None if lid_spring_reference is None else float(lid_spring_reference),
            },
            "post_slide": {"damping": float(post_damping), "friction": float(post_friction), "stiffness": 0.0, "spring_reference": None},
        },
        "initial_joint_positions": state,
    }
    atomic.write_json(out / "overlay.json", overlay)
    masses = {"body": float(body[0]), "lid": float(lid[0]), "post": float(post[0])}
    if base_inertial:
        masses["base"] = float(base[0])
    return ContractAsset(
        root=out,
        urdf=urdf_path,
        initial_state=state,
        masses=masses,
        lid_mass=lid_mass,
        lid_com_radius=W / 2,
        post_overlap_at=float(gap),
    )


__all__ = [
    "BULLET_DEFAULT_FRICTION",
    "BULLET_DEFAULT_INERTIA",
    "BULLET_DEFAULT_MASS",
    "BULLET_PLANE_FRICTION",
    "CollisionPiece",
    "ContractAsset",
    "FLAT_HULL_THICKNESS",
    "FakeBehaviour",
    "FakeSession",
    "UrdfCollision",
    "UrdfError",
    "UrdfInertial",
    "UrdfJoint",
    "UrdfLink",
    "UrdfModel",
    "fake_behaviour",
    "collision_pieces",
    "hull_is_solid",
    "matrix_quat_wxyz",
    "mesh_hulls",
    "obj_groups",
    "pose_matrix",
    "read_initial_state",
    "read_urdf",
    "rpy_matrix",
    "write_contract_asset",
]
