"""MuJoCo engine under the SPEC's conventions, and the URDF -> MJCF conversion
that both this engine and ``asset2sim export --format mjcf`` use.

The conversion (:func:`urdf_to_mjcf`) starts from MuJoCo's own URDF import
(``MjSpec.from_string`` on a URDF carrying a ``<mujoco><compiler .../>``
extension, then ``to_xml``) and fixes what that import drops or changes; each
fix is listed in ``docs/simulators.md``:

- numbers: MuJoCo writes 6 significant digits; every pose, axis, range,
  inertial and dynamics value is rewritten at full precision from the URDF
  (after checking MuJoCo read the same value);
- inertials: written as ``fullinertia`` in the body frame, with
  ``inertiafromgeom="false"``, ``balanceinertia="false"`` and no mass/inertia
  bounds, so the compiled masses, COMs and tensors are the file's;
- collision shapes: one convex hull per OBJ group, as PyBullet builds them
  (MuJoCo would make one hull of the whole file); coplanar groups become
  2 mm slabs (MuJoCo refuses flat hulls);
- fixed joints: ``fusestatic="false"`` keeps every URDF link a body;
- self-collision: MuJoCo's filter works on groups of bodies welded by fixed
  joints (and on nothing welded to the world); explicit ``<pair>`` and
  ``<exclude>`` elements make the colliding pairs exactly PyBullet's
  (:func:`contact_policy`);
- friction: MuJoCo's soft friction would let held joints creep; the no-slip
  pass (with elliptic cones, so resting bodies do not walk) makes it hold;
- a free joint on the root, a ground plane, joint springs (``stiffness`` /
  ``springref``) from the overlay, contact friction as PyBullet combines it,
  the SPEC's timestep and gravity, and a keyframe ``initial`` with the
  initial state placed on the ground.

The engine (:class:`MuJoCoSession`) compiles that MJCF in memory. mujoco is
imported only inside the functions that need it.
"""

from __future__ import annotations

import contextlib
import math
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from asset2sim.engines.base import ContactPair, SessionOptions, Spring, register_engine
from asset2sim.engines.fake import (
    BULLET_DEFAULT_FRICTION,
    BULLET_DEFAULT_INERTIA,
    BULLET_DEFAULT_MASS,
    BULLET_PLANE_FRICTION,
    CollisionPiece,
    UrdfModel,
    collision_pieces,
    matrix_quat_wxyz,
    read_urdf,
)
from asset2sim.schemas.config import SimConventions

#: Folder (relative to the MJCF file's meshdir, the asset folder) of the convex
#: pieces the exporter writes.
DERIVED_MESH_DIR = "mjcf/meshes"
#: Name of the keyframe that holds the initial state.
KEYFRAME = "initial"
#: Name of the root's free joint.
FREE_JOINT = "root_free"
#: Name of the ground plane geom.
GROUND = "ground"
#: MuJoCo's friction (contact friction and joint ``frictionloss``) is a soft
#: constraint that lets a loaded joint creep; the no-slip post-processing
#: removes that, so friction holds as Coulomb friction does in Bullet and
#: PhysX (a lid held by 0.5 N*m against 0.16 N*m of gravity creeps 0.2 rad in
#: 3 s without it, 0 with it).
NOSLIP_ITERATIONS = 10
#: Friction cones: elliptic with impratio 10 (MuJoCo's advice for resting and
#: manipulated objects). With the default pyramidal cones, the no-slip pass
#: made the refined laptop 9748 walk 1 mm and the faucet 148 rock 2.3 mm
#: during the rest test (both still in PyBullet and PhysX); elliptic cones
#: keep them still (3e-9 m, 2e-6 m).
IMPRATIO = 10.0


class MjcfError(RuntimeError):
    """MuJoCo cannot import the URDF or compile the MJCF (names the file)."""


def _mujoco():
    import mujoco

    return mujoco


@contextlib.contextmanager
def mujoco_messages():
    """Collect MuJoCo's warnings (list of str) instead of letting MuJoCo print
    them and append them to ``MUJOCO_LOG.TXT`` in the working directory (its
    default handler) or raise Python warnings (the MjSpec compiler)."""
    mujoco = _mujoco()
    collected: list[str] = []
    previous = mujoco.get_mju_user_warning()
    mujoco.set_mju_user_warning(lambda msg: collected.append(str(msg)))
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            yield collected
        collected.extend(str(w.message) for w in caught)
    finally:
        mujoco.set_mju_user_warning(previous)


def _f(x: float) -> str:
    """Shortest round-trip text of a float."""
    x = float(x)
    if x == 0.0:
        return "0"
    return repr(x)


def _fv(v) -> str:
    return " ".join(_f(x) for x in np.asarray(v, float).ravel())


@dataclass
class MjcfBuild:
    """An MJCF document and what it needs.

    ``xml`` the MJCF text; ``derived_meshes`` relative path (from ``meshdir``)
    -> OBJ bytes of convex pieces the exporter must write; ``mesh_files``
    relative path -> absolute source file of meshes referenced as they are;
    ``initial_qpos`` (nq,) of the keyframe; ``joint_names`` movable joints in
    qpos order; ``notes`` what the conversion changed for this asset;
    ``root_height`` m the root was lifted to touch the ground.
    """

    xml: str
    derived_meshes: dict[str, bytes]
    mesh_files: dict[str, Path]
    initial_qpos: np.ndarray
    joint_names: list[str]
    notes: list[str] = field(default_factory=list)
    root_height: float = 0.0

    def assets(self) -> dict[str, bytes]:
        """Every mesh as bytes, keyed as the MJCF names them (for in-memory compiles)."""
        out = {k: p.read_bytes() for k, p in self.mesh_files.items()}
        out.update(self.derived_meshes)
        return out


def _hull_obj(points: np.ndarray) -> bytes:
    """OBJ bytes of the convex hull of ``points`` (k, 3) m (vertices + outward faces)."""
    from scipy.spatial import ConvexHull

    pts = np.asarray(points, float)
    hull = ConvexHull(pts)
    used = np.unique(hull.simplices)
    remap = np.zeros(len(pts), int)
    remap[used] = np.arange(1, len(used) + 1)
    tri = hull.simplices.copy()
    a, b, c = pts[tri[:, 0]], pts[tri[:, 1]], pts[tri[:, 2]]
    flip = np.einsum("ij,ij->i", np.cross(b - a, c - a), hull.equations[:, :3]) < 0
    tri[flip, 1], tri[flip, 2] = hull.simplices[flip, 2], hull.simplices[flip, 1]
    lines = [f"v {_fv(pts[v])}" for v in used]
    lines += [f"f {i} {j} {k}" for i, j, k in remap[tri]]
    return ("\n".join(lines) + "\n").encode()


def _safe(name: str) -> str:
    return "".join(ch if ch.isalnum() or ch in "-_." else "_" for ch in name)


def _relative(path: Path, root: Path) -> str | None:
    try:
        return path.resolve().relative_to(root.resolve()).as_posix()
    except ValueError:
        return None


def _link_friction(model: UrdfModel, link: str) -> float:
    """PyBullet's contact friction of a link against the ground plane: the
    product of the link's lateral friction (0.5 unless ``<contact>`` says) and
    the plane's (0.5)."""
    lat = model.links[link].lateral_friction
    return (BULLET_DEFAULT_FRICTION if lat is None else lat) * BULLET_PLANE_FRICTION


def _urdf_for_import(
    model: UrdfModel,
    pieces: dict[str, list[CollisionPiece]],
    mesh_names: dict[tuple, str],
    mesh_scales: dict[tuple, np.ndarray | None],
    missing_inertial: str,
) -> str:
    """A URDF equivalent to ``model`` whose collisions are the convex pieces
    (mesh files named as in ``mesh_names``), with MuJoCo's compiler extension."""
    out = [f'<robot name="{_safe(model.name)}">']
    out.append(
        '  <mujoco><compiler angle="radian" strippath="false" discardvisual="true" fusestatic="false" '
        'balanceinertia="false" inertiafromgeom="false" boundmass="0" boundinertia="0"/></mujoco>'
    )
    for name, link in model.links.items():
        out.append(f'  <link name="{name}">')
        ine = link.inertial
        if ine is None and missing_inertial == "bullet":
            out.append(
                f'    <inertial><origin xyz="0 0 0"/><mass value="{_f(BULLET_DEFAULT_MASS)}"/>'
                f'<inertia ixx="{_f(BULLET_DEFAULT_INERTIA[0])}" iyy="{_f(BULLET_DEFAULT_INERTIA[1])}" '
                f'izz="{_f(BULLET_DEFAULT_INERTIA[2])}" ixy="0" ixz="0" iyz="0"/></inertial>'
            )
        elif ine is not None:
            i = ine.inertia_in_link_axes()
            out.append(
                f'    <inertial><origin xyz="{_fv(ine.com())}"/><mass value="{_f(ine.mass)}"/>'
                f'<inertia ixx="{_f(i[0, 0])}" ixy="{_f(i[0, 1])}" ixz="{_f(i[0, 2])}" iyy="{_f(i[1, 1])}" '
                f'iyz="{_f(i[1, 2])}" izz="{_f(i[2, 2])}"/></inertial>'
            )
        for p in pieces[name]:
            xyz = p.origin[:3, 3]
            rpy = _rpy(p.origin[:3, :3])
            if p.kind == "hull":
                key = (name, p.collision, p.group)
                sc = mesh_scales[key]
                scale = "" if sc is None else f' scale="{_fv(sc)}"'
                geo = f'<mesh filename="{mesh_names[key]}"{scale}/>'
            elif p.kind == "box":
                geo = f'<box size="{_fv(p.size)}"/>'
            elif p.kind == "sphere":
                geo = f'<sphere radius="{_f(p.radius)}"/>'
            else:
                geo = f'<cylinder radius="{_f(p.radius)}" length="{_f(p.length)}"/>'
            out.append(f'    <collision><origin xyz="{_fv(xyz)}" rpy="{_fv(rpy)}"/><geometry>{geo}</geometry></collision>')
        out.append("  </link>")
    for j in model.joints:
        xyz, rpy = j.origin[:3, 3], _rpy(j.origin[:3, :3])
        s = (
            f'  <joint name="{j.name}" type="{j.type}"><parent link="{j.parent}"/><child link="{j.child}"/>'
            f'<origin xyz="{_fv(xyz)}" rpy="{_fv(rpy)}"/><axis xyz="{_fv(j.axis)}"/>'
        )
        if j.type in ("revolute", "prismatic"):
            s += f'<limit lower="{_f(j.lower)}" upper="{_f(j.upper)}" effort="0" velocity="0"/>'
        if j.type != "fixed":
            s += f'<dynamics damping="{_f(j.damping)}" friction="{_f(j.friction)}"/>'
        out.append(s + "</joint>")
    out.append("</robot>")
    return "\n".join(out)


def _rpy(r: np.ndarray) -> np.ndarray:
    """URDF rpy (rad) of a rotation matrix (inverse of ``rpy_matrix``)."""
    r = np.asarray(r, float)
    pitch = math.asin(max(-1.0, min(1.0, -r[2, 0])))
    if abs(r[2, 0]) < 1 - 1e-12:
        roll = math.atan2(r[2, 1], r[2, 2])
        yaw = math.atan2(r[1, 0], r[0, 0])
    else:  # gimbal lock: put everything in yaw
        roll = 0.0
        yaw = math.atan2(-r[0, 1], r[1, 1])
    return np.array([roll, pitch, yaw])


def _quat_text(r: np.ndarray) -> str:
    return _fv(matrix_quat_wxyz(r))


def _close(a, b, tol: float) -> bool:
    return bool(np.allclose(np.asarray(a, float), np.asarray(b, float), atol=tol, rtol=tol))


def urdf_to_mjcf(
    urdf_path: Path | str,
    *,
    initial_state: dict[str, float] | None = None,
    springs: dict[str, Spring] | None = None,
    missing_inertial: str = "massless",
    fixed_base: bool = False,
    ground: bool = True,
    gravity: bool = True,
    conventions: SimConventions | None = None,
    mesh_root: Path | None = None,
    meshdir: str = ".",
    visuals: bool = False,
) -> MjcfBuild:
    """Convert a URDF into MJCF under the SPEC's conventions.

    Args:
        initial_state: joint -> rad or m, stored in the keyframe ``initial``
            (other joints at 0).
        springs: joint -> :class:`Spring` (stiffness N*m/rad or N/m, reference
            rad or m), written as joint ``stiffness`` and ``springref``.
        missing_inertial: what a link without ``<inertial>`` weighs:
            ``"massless"`` (the file's truth; MuJoCo accepts it only for links
            welded to a massive one) or ``"bullet"`` (PyBullet's 1 kg and unit
            inertia, for parity with the reference engine).
        fixed_base: no free joint; the root stays at the world origin.
        ground / gravity: add the ground plane / gravity -9.81 m/s^2 along z.
        mesh_root: folder the MJCF's ``meshdir`` points at; meshes of the URDF
            inside it are referenced relative to it (default: the URDF's folder).
        meshdir: the ``meshdir`` written in the MJCF (relative to the MJCF file).
        visuals: also write the URDF's visual meshes as non-colliding geoms
            (group 2, colour from the MTL ``Kd``; collision geoms go to group 3).

    Returns:
        :class:`MjcfBuild`.

    Raises:
        UrdfError: the URDF cannot be read.
        MjcfError: MuJoCo cannot import or compile the result, or read a value
            differently from the URDF.
        ValueError: ``missing_inertial`` is not one of the two policies, or an
            initial state names an unknown joint.
    """
    mujoco = _mujoco()
    from lxml import etree

    if missing_inertial not in ("massless", "bullet"):
        raise ValueError(f"missing_inertial must be 'massless' or 'bullet', not {missing_inertial!r}")
    conv = conventions or SimConventions()
    urdf_path = Path(urdf_path)
    model = read_urdf(urdf_path)
    initial_state = dict(initial_state or {})
    springs = dict(springs or {})
    movable = {j.name: j for j in model.movable_joints}
    unknown = sorted(set(initial_state) - set(movable))
    if unknown:
        raise ValueError(f"{urdf_path}: initial state names joints that are not movable joints of the file: {unknown}")
    mesh_root = Path(mesh_root) if mesh_root is not None else urdf_path.parent
    pieces, notes = collision_pieces(model)

    # ---- mesh files: the original file when a hull is a whole single-group file
    derived: dict[str, bytes] = {}
    files: dict[str, Path] = {}
    mesh_names: dict[tuple, str] = {}  # piece -> unique name given to MuJoCo's import
    mesh_scales: dict[tuple, np.ndarray | None] = {}
    virtual: dict[str, tuple[str, np.ndarray | None]] = {}  # import name -> (file, scale)
    import_assets: dict[str, bytes] = {}
    for name, plist in pieces.items():
        for p in plist:
            if p.kind != "hull":
                continue
            key = (name, p.collision, p.group)
            rel = _relative(p.source, mesh_root) if p.whole_file else None
            if rel is not None:
                files[rel] = p.source
                data = p.source.read_bytes()
                scale = None if np.allclose(p.scale, 1.0) else np.asarray(p.scale, float)
            else:
                rel = f"{DERIVED_MESH_DIR}/{_safe(name)}__c{p.collision}_g{p.group}.obj"
                data = _hull_obj(p.points)
                derived[rel] = data
                scale = None
            vname = f"piece{len(virtual)}.obj"
            virtual[vname] = (rel, scale)
            mesh_names[key] = vname
            mesh_scales[key] = scale
            import_assets[vname] = data
    final_assets = {rel: import_assets[v] for v, (rel, _) in virtual.items()}

    # ---- MuJoCo's URDF import
    urdf_text = _urdf_for_import(model, pieces, mesh_names, mesh_scales, missing_inertial)
    try:
        with mujoco_messages() as caught:
            spec = mujoco.MjSpec.from_string(urdf_text, assets=import_assets)
            skeleton = spec.to_xml()
    except Exception as exc:  # mujoco raises ValueError with its message
        raise MjcfError(f"MuJoCo could not import {urdf_path}: {exc}") from exc
    notes.extend(_mujoco_warnings(caught))
    root = etree.fromstring(skeleton.encode())

    # ---- fix what the import dropped or rounded
    comp = root.find("compiler")
    if comp is None:
        comp = etree.SubElement(root, "compiler")
    for k in list(comp.attrib):
        del comp.attrib[k]
    comp.set("angle", "radian")
    comp.set("meshdir", meshdir)
    comp.set("autolimits", "true")
    comp.set("inertiafromgeom", "false")
    comp.set("balanceinertia", "false")
    comp.set("boundmass", "0")
    comp.set("boundinertia", "0")
    comp.set("fusestatic", "false")
    comp.set("discardvisual", "false")
    root.remove(comp)
    root.insert(0, comp)
    opt = etree.Element("option")
    opt.set("timestep", _f(conv.timestep))
    opt.set("gravity", f"0 0 {_f(conv.gravity if gravity else 0.0)}")
    opt.set("integrator", "implicitfast")
    opt.set("noslip_iterations", str(NOSLIP_ITERATIONS))
    opt.set("cone", "elliptic")  # with pyramidal cones the no-slip pass makes resting bodies walk
    opt.set("impratio", _f(IMPRATIO))
    for old in root.findall("option"):
        root.remove(old)
    root.insert(1, opt)
    default = etree.Element("default")
    dg = etree.SubElement(default, "geom")
    dg.set("condim", "3")
    dg.set("friction", f"{_f(BULLET_DEFAULT_FRICTION * BULLET_PLANE_FRICTION)} 0.005 0.0001")
    dj = etree.SubElement(default, "joint")
    dj.set("armature", "0")
    for old in root.findall("default"):
        root.remove(old)
    root.insert(2, default)

    file_to_mesh: dict[str, str] = {}  # import name -> mesh asset name
    used: set[str] = set()
    for mesh in root.iter("mesh"):
        f = mesh.get("file")
        if f not in virtual:
            raise MjcfError(f"{urdf_path}: MuJoCo's import produced an unknown mesh {f!r}")
        rel, scale = virtual[f]
        for k in ("content_type", "scale", "name"):
            mesh.attrib.pop(k, None)
        base = _safe(Path(rel).stem)
        nm, i = base, 1
        while nm in used:
            i += 1
            nm = f"{base}_{i}"
        used.add(nm)
        mesh.set("name", nm)
        mesh.set("file", rel)
        if scale is not None:
            mesh.set("scale", _fv(scale))
        mesh.set("inertia", "shell")  # mesh volumes are never used (inertiafromgeom="false")
        file_to_mesh[f] = nm

    asset_el = root.find("asset")
    if asset_el is None:
        asset_el = etree.SubElement(root, "asset")
    worldbody = root.find("worldbody")
    bodies = {b.get("name"): b for b in worldbody.iter("body")}
    if set(bodies) != set(model.links):
        raise MjcfError(f"{urdf_path}: MuJoCo's import has bodies {sorted(bodies)}, the URDF links {sorted(model.links)}")
    tol = 2e-5
    for jnt in model.joints:
        b = bodies[jnt.child]
        sb = spec.body(jnt.child)
        if sb is None or not _close(sb.pos, jnt.origin[:3, 3], tol * max(1.0, float(np.abs(jnt.origin[:3, 3]).max()))):
            raise MjcfError(f"{urdf_path}: MuJoCo placed body {jnt.child!r} elsewhere than the URDF ({jnt.origin[:3, 3]})")
        b.set("pos", _fv(jnt.origin[:3, 3]))
        b.set("quat", _quat_text(jnt.origin[:3, :3]))
        for k in ("euler", "axisangle", "xyaxes", "zaxis"):
            b.attrib.pop(k, None)
    names_in_qpos: list[str] = []
    for b in worldbody.iter("body"):
        link = model.links[b.get("name")]
        # inertial
        for old in b.findall("inertial"):
            b.remove(old)
        ine = link.inertial
        el = None
        if ine is not None:
            i = ine.inertia_in_link_axes()
            el = etree.Element("inertial", pos=_fv(ine.com()), mass=_f(ine.mass))
            el.set("fullinertia", _fv([i[0, 0], i[1, 1], i[2, 2], i[0, 1], i[0, 2], i[1, 2]]))
        elif missing_inertial == "bullet":
            el = etree.Element("inertial", pos="0 0 0", mass=_f(BULLET_DEFAULT_MASS), diaginertia=_fv(BULLET_DEFAULT_INERTIA))
            notes.append(f"link {link.name!r} has no <inertial>: given PyBullet's {BULLET_DEFAULT_MASS} kg, unit inertia")
        elif link.collisions:
            notes.append(f"link {link.name!r} has geometry but no <inertial>: massless in MuJoCo")
        if el is not None:
            b.insert(0, el)
        # joints
        pj = model.parent_joint(link.name)
        for je in b.findall("joint"):
            if pj is None or je.get("name") != pj.name:
                raise MjcfError(f"{urdf_path}: unexpected joint {je.get('name')!r} in body {link.name!r}")
            sj = spec.joint(pj.name)
            axis = np.asarray(sj.axis, float)
            if not _close(axis / np.linalg.norm(axis), pj.axis, 1e-5):
                raise MjcfError(f"{urdf_path}: MuJoCo read axis {axis} for joint {pj.name!r}, the URDF {pj.axis}")
            if not (math.isclose(float(np.atleast_1d(sj.damping)[0]), pj.damping, rel_tol=1e-5, abs_tol=1e-12)
                    and math.isclose(float(sj.frictionloss), pj.friction, rel_tol=1e-5, abs_tol=1e-12)):
                raise MjcfError(f"{urdf_path}: MuJoCo read other damping/friction for joint {pj.name!r}")
            for k in list(je.attrib):
                if k not in ("name", "type"):
                    del je.attrib[k]
            je.set("axis", _fv(pj.axis))
            if pj.type in ("revolute", "prismatic"):
                je.set("range", f"{_f(pj.lower)} {_f(pj.upper)}")
                je.set("limited", "true")
            else:
                je.set("limited", "false")
            je.set("damping", _f(pj.damping))
            je.set("frictionloss", _f(pj.friction))
            sp = springs.get(pj.name)
            if sp is not None and sp.stiffness > 0:
                je.set("stiffness", _f(sp.stiffness))
                je.set("springref", _f(sp.reference))
            names_in_qpos.append(pj.name)
        # geoms
        geoms = b.findall("geom")
        plist = pieces[link.name]
        if len(geoms) != len(plist):
            raise MjcfError(f"{urdf_path}: MuJoCo made {len(geoms)} geoms for link {link.name!r}, expected {len(plist)}")
        fr = _link_friction(model, link.name)
        for g, p in zip(geoms, plist):
            g.set("name", f"{_safe(link.name)}__c{p.collision}_g{p.group}")
            g.set("pos", _fv(p.origin[:3, 3]))
            g.set("quat", _quat_text(p.origin[:3, :3]))
            if p.kind == "hull":
                g.set("mesh", file_to_mesh[mesh_names[(link.name, p.collision, p.group)]])
            if not math.isclose(fr, BULLET_DEFAULT_FRICTION * BULLET_PLANE_FRICTION):
                g.set("friction", f"{_f(fr)} 0.005 0.0001")
            if visuals:
                g.set("group", "3")
    if set(names_in_qpos) != set(movable):
        raise MjcfError(f"{urdf_path}: MuJoCo's import has joints {names_in_qpos}, the URDF {sorted(movable)}")

    # ---- self-collision: exactly PyBullet's pairs
    contact = etree.Element("contact")
    pairs, excludes = contact_policy(model, pieces, free=not fixed_base)
    for a, b in pairs:
        for pa in pieces[a]:
            for pb in pieces[b]:
                pe = etree.SubElement(contact, "pair")
                pe.set("geom1", f"{_safe(a)}__c{pa.collision}_g{pa.group}")
                pe.set("geom2", f"{_safe(b)}__c{pb.collision}_g{pb.group}")
                pe.set("condim", "3")
                f = max(_link_friction(model, a), _link_friction(model, b))
                pe.set("friction", f"{_f(f)} {_f(f)} 0.005 0.0001 0.0001")
    for a, b in excludes:
        etree.SubElement(contact, "exclude", body1=a, body2=b)
    if pairs:
        notes.append(
            "MuJoCo filters contacts between bodies welded by fixed joints and their parents; "
            f"explicit <pair>s restore PyBullet's pairs {[f'{a}/{b}' for a, b in pairs]}"
        )
    if excludes:
        notes.append(f"<exclude>s remove parent/child pairs MuJoCo would collide: {[f'{a}/{b}' for a, b in excludes]}")
    for old in root.findall("contact"):
        root.remove(old)
    if len(contact):
        root.append(contact)

    # ---- root: free joint, ground
    root_body = bodies[model.root]
    if not fixed_base:
        fj = etree.Element("freejoint", name=FREE_JOINT)
        idx = 1 if root_body.find("inertial") is not None and list(root_body).index(root_body.find("inertial")) == 0 else 0
        root_body.insert(idx, fj)
    if ground:
        plane = etree.Element("geom", name=GROUND, type="plane", size="0 0 1")
        plane.set("friction", "0 0.005 0.0001")  # MuJoCo takes the larger friction: the link's
        plane.set("rgba", "0.8 0.8 0.8 1")
        worldbody.insert(0, plane)

    # ---- placement: lowest collision point on the ground, at the initial state
    xml = etree.tostring(root, encoding="unicode")
    try:
        with mujoco_messages() as caught:
            compiled = mujoco.MjModel.from_xml_string(xml, assets=final_assets)
    except Exception as exc:
        raise MjcfError(f"{urdf_path}: the converted MJCF does not compile: {exc}") from exc
    notes.extend(_mujoco_warnings(caught))
    qpos = compiled.qpos0.copy()
    for name, value in initial_state.items():
        jid = mujoco.mj_name2id(compiled, mujoco.mjtObj.mjOBJ_JOINT, name)
        qpos[compiled.jnt_qposadr[jid]] = float(value)
    height = 0.0
    if not fixed_base:
        data = mujoco.MjData(compiled)
        data.qpos[:] = qpos
        mujoco.mj_kinematics(compiled, data)
        low = lowest_point(compiled, data)
        height = -low if math.isfinite(low) else 0.0
        qpos[2] += height
        root_body.set("pos", _fv([0.0, 0.0, height]))
        root_body.set("quat", "1 0 0 0")
    if visuals:  # after placement: visual meshes never collide, and cost compile time
        for b in worldbody.iter("body"):
            _add_visuals(b, model.links[b.get("name")], mesh_root, asset_el, files, final_assets, used, notes)
    key = etree.SubElement(etree.SubElement(root, "keyframe"), "key", name=KEYFRAME)
    key.set("qpos", _fv(qpos))
    etree.indent(root, space="  ")
    xml = etree.tostring(root, encoding="unicode")
    # Only the root's pose and the keyframe changed since ``compiled``.
    order = [mujoco.mj_id2name(compiled, mujoco.mjtObj.mjOBJ_JOINT, j) for j in range(compiled.njnt)]
    joint_names = [n for n in order if n in movable]
    return MjcfBuild(
        xml=xml,
        derived_meshes=derived,
        mesh_files=files,
        initial_qpos=qpos,
        joint_names=joint_names,
        notes=notes,
        root_height=height,
    )


def _mujoco_warnings(caught: list[str]) -> list[str]:
    """MuJoCo's compiler warnings as notes (texture-coordinate complaints about
    OBJ files are dropped: collision meshes carry no texture)."""
    return [f"MuJoCo: {text}" for text in caught if "texture coordinate" not in text]


def _mtl_colour(obj: Path) -> str:
    """``rgba`` text of the first material an OBJ uses (MTL ``Kd`` and ``d``),
    grey when there is none."""
    import re

    try:
        text = obj.read_text(errors="replace")
    except OSError:
        return "0.7 0.7 0.7 1"
    libs = re.findall(r"^\s*mtllib\s+(.+?)\s*$", text, re.M)
    use = re.search(r"^\s*usemtl\s+(.+?)\s*$", text, re.M)
    for lib in libs:
        try:
            mtl = (obj.parent / lib).read_text(errors="replace")
        except OSError:
            continue
        blocks = re.split(r"^\s*newmtl\s+", mtl, flags=re.M)[1:]
        for block in blocks:
            name, _, body = block.partition("\n")
            if use is not None and name.strip() != use.group(1).strip():
                continue
            kd = re.search(r"^\s*Kd\s+(\S+)\s+(\S+)\s+(\S+)", body, re.M)
            dd = re.search(r"^\s*d\s+(\S+)", body, re.M)
            try:
                rgb = [min(1.0, max(0.0, float(v))) for v in kd.groups()] if kd else [0.7, 0.7, 0.7]
                alpha = min(1.0, max(0.0, float(dd.group(1)))) if dd else 1.0
            except ValueError:
                continue
            return _fv(rgb + [alpha])
    return "0.7 0.7 0.7 1"


def _add_visuals(body, link, mesh_root: Path, asset_el, files: dict, assets: dict, used: set, notes: list) -> None:
    """Append ``link``'s visuals to ``body`` as non-colliding geoms (group 2)."""
    from lxml import etree

    for k, v in enumerate(link.visuals):
        g = etree.SubElement(body, "geom", name=f"{_safe(link.name)}__v{k}")
        g.set("pos", _fv(v.origin[:3, 3]))
        g.set("quat", _quat_text(v.origin[:3, :3]))
        g.set("contype", "0")
        g.set("conaffinity", "0")
        g.set("group", "2")
        if v.kind == "mesh":
            rel = _relative(v.path, mesh_root) if v.path is not None and v.path.is_file() else None
            if rel is None:
                body.remove(g)
                notes.append(f"link {link.name!r} visual {k} ({v.filename}) is missing or outside the asset folder: not exported")
                continue
            name = f"{_safe(link.name)}__v{k}"
            while name in used:
                name += "_"
            used.add(name)
            me = etree.SubElement(asset_el, "mesh", name=name, file=rel, inertia="shell")
            if not np.allclose(v.scale, 1.0):
                me.set("scale", _fv(v.scale))
            files[rel] = v.path
            assets[rel] = v.path.read_bytes()
            g.set("type", "mesh")
            g.set("mesh", name)
            g.set("rgba", _mtl_colour(v.path))
        elif v.kind == "box":
            g.set("type", "box")
            g.set("size", _fv(np.asarray(v.size) / 2))
        elif v.kind == "sphere":
            g.set("type", "sphere")
            g.set("size", _f(v.radius))
        else:
            g.set("type", "cylinder")
            g.set("size", f"{_f(v.radius)} {_f(v.length / 2)}")


def contact_policy(model: UrdfModel, pieces: dict[str, list[CollisionPiece]], free: bool) -> tuple[list[tuple[str, str]], list[tuple[str, str]]]:
    """Make MuJoCo collide exactly the link pairs PyBullet collides (every
    pair of links with shapes except a link and its parent).

    MuJoCo's own filter (``filterBodyPair`` in its collision driver) drops a
    pair when both bodies are welded together (fixed joints, or both welded to
    the world when the root is not free) or, unless one of them is welded to
    the world, when one's weld group is the parent of the other's. Returns
    (pairs PyBullet collides that MuJoCo drops: restored with ``<pair>``,
    pairs MuJoCo collides that PyBullet does not: removed with ``<exclude>``).
    """
    world = ""
    weld: dict[str, str] = {}
    for name in model.tree_order():
        pj = model.parent_joint(name)
        if pj is None:
            weld[name] = name if free else world
        else:
            weld[name] = weld[pj.parent] if pj.type == "fixed" else name

    def weld_parent(w: str) -> str:
        if w == world:
            return world
        pj = model.parent_joint(w)
        return world if pj is None else weld[pj.parent]

    def mujoco_filters(a: str, b: str) -> bool:
        wa, wb = weld[a], weld[b]
        if wa == wb:
            return True
        return wa != world and wb != world and (wa == weld_parent(wb) or wb == weld_parent(wa))

    adjacent = model.adjacent_pairs()
    names = [n for n in model.tree_order() if pieces.get(n)]
    restore, exclude = [], []
    for i, a in enumerate(names):
        for b in names[i + 1:]:
            bullet = frozenset((a, b)) not in adjacent
            filtered = mujoco_filters(a, b)
            if bullet and filtered:
                restore.append((a, b))
            elif not bullet and not filtered:
                exclude.append((a, b))
    return restore, exclude


def lowest_point(m, d) -> float:
    """Lowest z (m) of any colliding geom of the object (the ground excluded)
    for the kinematics in ``d``: mesh vertices, box corners, sphere and
    cylinder extremes. ``+inf`` when there is none."""
    mujoco = _mujoco()
    low = math.inf
    for g in range(m.ngeom):
        gt = m.geom_type[g]
        if gt == mujoco.mjtGeom.mjGEOM_PLANE or (m.geom_contype[g] == 0 and m.geom_conaffinity[g] == 0):
            continue
        pos, mat = d.geom_xpos[g], d.geom_xmat[g].reshape(3, 3)
        size = m.geom_size[g]
        if gt == mujoco.mjtGeom.mjGEOM_MESH:
            mid = m.geom_dataid[g]
            a, n = m.mesh_vertadr[mid], m.mesh_vertnum[mid]
            z = pos[2] + m.mesh_vert[a:a + n] @ mat[2]
            low = min(low, float(z.min()))
        elif gt == mujoco.mjtGeom.mjGEOM_BOX:
            corners = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)]) * size
            low = min(low, float((pos[2] + corners @ mat[2]).min()))
        elif gt == mujoco.mjtGeom.mjGEOM_SPHERE:
            low = min(low, float(pos[2] - size[0]))
        elif gt == mujoco.mjtGeom.mjGEOM_CYLINDER:
            axis = mat[:, 2]
            radial = size[0] * math.sqrt(max(0.0, 1 - axis[2] ** 2))
            low = min(low, float(pos[2] - abs(axis[2]) * size[1] - radial))
        else:  # capsule, ellipsoid: bounding sphere (not produced from URDF)
            low = min(low, float(pos[2] - m.geom_rbound[g]))
    return low


# ------------------------------------------------------------------ session
class MuJoCoSession:
    """A :class:`~asset2sim.engines.base.SimSession` in MuJoCo, compiled from
    :func:`urdf_to_mjcf` in memory (links without ``<inertial>`` get
    PyBullet's default, as in the reference engine).

    ``notes``: what the conversion changed for this asset.

    Raises (constructor):
        UrdfError, MjcfError: the URDF cannot be read or compiled.
    """

    engine = "mujoco"

    def __init__(self, urdf_path: Path, options: SessionOptions, missing_inertial: str = "bullet"):
        mujoco = _mujoco()
        self._mj = mujoco
        self.options = options
        self.build = urdf_to_mjcf(
            urdf_path,
            initial_state=options.initial_state,
            springs=options.springs,
            missing_inertial=missing_inertial,
            fixed_base=options.fixed_base,
            ground=options.ground,
            gravity=options.gravity,
            conventions=options.conventions,
        )
        self.notes = list(self.build.notes)
        try:
            with mujoco_messages():
                self.m = mujoco.MjModel.from_xml_string(self.build.xml, assets=self.build.assets())
        except Exception as exc:
            raise MjcfError(f"MuJoCo could not compile {urdf_path}: {exc}") from exc
        self.d = mujoco.MjData(self.m)
        self.urdf = read_urdf(urdf_path)
        self.joint_names = list(self.build.joint_names)
        self.joint_types = {j.name: j.type for j in self.urdf.movable_joints}
        self.joint_limits = {j.name: (j.lower, j.upper) for j in self.urdf.movable_joints}
        self._qadr = {}
        self._dadr = {}
        for n in self.joint_names:
            jid = mujoco.mj_name2id(self.m, mujoco.mjtObj.mjOBJ_JOINT, n)
            self._qadr[n] = int(self.m.jnt_qposadr[jid])
            self._dadr[n] = int(self.m.jnt_dofadr[jid])
        self._ground = mujoco.mj_name2id(self.m, mujoco.mjtObj.mjOBJ_GEOM, GROUND) if options.ground else -1
        self._root = mujoco.mj_name2id(self.m, mujoco.mjtObj.mjOBJ_BODY, self.urdf.root)
        self._free = not options.fixed_base
        kid = mujoco.mj_name2id(self.m, mujoco.mjtObj.mjOBJ_KEY, KEYFRAME)
        mujoco.mj_resetDataKeyframe(self.m, self.d, kid)
        mujoco.mj_forward(self.m, self.d)

    # ------------------------------------------------------------------ state
    def set_joint_positions(self, q: dict[str, float], zero_velocity: bool = True) -> None:
        for name, v in q.items():
            a = self._qadr.get(name)
            if a is None:
                continue
            self.d.qpos[a] = float(v)
            if zero_velocity:
                self.d.qvel[self._dadr[name]] = 0.0
        self._mj.mj_forward(self.m, self.d)

    def joint_positions(self) -> dict[str, float]:
        return {n: float(self.d.qpos[a]) for n, a in self._qadr.items()}

    def joint_velocities(self) -> dict[str, float]:
        return {n: float(self.d.qvel[a]) for n, a in self._dadr.items()}

    def root_pose(self) -> tuple[np.ndarray, np.ndarray]:
        if self._free:
            pos = np.array(self.d.qpos[0:3], float)
            w, x, y, z = self.d.qpos[3:7]
        else:
            pos = np.array(self.d.xpos[self._root], float)
            w, x, y, z = self.d.xquat[self._root]
        q = np.array([x, y, z, w], float)
        n = np.linalg.norm(q)
        return pos, (q / n if n > 0 else q)

    # ---------------------------------------------------------------- contact
    def _contacts(self):
        mj = self._mj
        mj.mj_forward(self.m, self.d)
        for i in range(self.d.ncon):
            yield self.d.contact[i]

    def self_penetration(self) -> tuple[float, list[ContactPair]]:
        pairs: dict[tuple[str, str], ContactPair] = {}
        total = 0.0
        for c in self._contacts():
            if c.geom1 == self._ground or c.geom2 == self._ground or c.dist >= 0.0:
                continue
            a = self._mj.mj_id2name(self.m, self._mj.mjtObj.mjOBJ_BODY, int(self.m.geom_bodyid[c.geom1]))
            b = self._mj.mj_id2name(self.m, self._mj.mjtObj.mjOBJ_BODY, int(self.m.geom_bodyid[c.geom2]))
            key = (a, b) if a <= b else (b, a)
            cp = pairs.get(key)
            if cp is None:
                cp = pairs[key] = ContactPair(key[0], key[1], 0.0, 0.0, 0)
            depth = -float(c.dist)
            cp.depth += depth
            cp.max_depth = max(cp.max_depth, depth)
            cp.points += 1
            total += depth
        return total, sorted(pairs.values(), key=lambda c: -c.depth)

    def ground_penetration(self) -> float:
        """Deepest point (m) of the collision geoms below z = 0, from the
        geometry itself (exact for hulls on a plane; no contact query)."""
        if self._ground < 0:
            return 0.0
        self._mj.mj_kinematics(self.m, self.d)
        low = lowest_point(self.m, self.d)
        return max(0.0, -low) if math.isfinite(low) else 0.0

    # --------------------------------------------------------------- dynamics
    def step(self, n: int = 1) -> None:
        mj = self._mj
        for _ in range(int(n)):
            mj.mj_step(self.m, self.d)

    def close(self) -> None:
        self.d = None
        self.m = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def _open(urdf_path: Path, options: SessionOptions) -> MuJoCoSession:
    return MuJoCoSession(urdf_path, options)


# Registering needs the package: without it the import fails here and the
# registry reports the engine as unavailable (an optional extra).
import mujoco as _mujoco_check  # noqa: E402,F401

register_engine("mujoco", _open)
