"""URDF -> MJCF conversion under the SPEC's conventions, used by the MuJoCo
engine (:mod:`asset2sim.engines.mujoco_engine`) and by ``asset2sim export
--format mjcf`` (:mod:`asset2sim.tasks.publish.export_mjcf`).

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

The steps of :func:`urdf_to_mjcf`, in order: :func:`_mesh_assets` (one mesh
per convex piece), :func:`_urdf_for_import` + :func:`_import_skeleton`
(MuJoCo's import), :func:`_set_options`, :func:`_rename_meshes`,
:func:`_place_bodies`, per body :func:`_set_inertial`, :func:`_set_joints`,
:func:`_set_geoms`, then :func:`_contact_element`, :func:`_add_root_and_ground`
and :func:`_place_on_ground`. mujoco is imported only inside the functions
that need it.
"""

from __future__ import annotations

import contextlib
import math
import re
import warnings
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from lxml import etree
from scipy.spatial import ConvexHull

from asset2sim.engines.base import Spring
from asset2sim.engines.loading import BULLET_DEFAULT_FRICTION, BULLET_DEFAULT_INERTIA, BULLET_DEFAULT_MASS, BULLET_PLANE_FRICTION, CollisionPiece, collision_pieces, read_urdf
from asset2sim.urdf import UrdfModel
from asset2sim.frames import matrix_quat_wxyz
from asset2sim.frames import translation_matrix
from asset2sim.schemas.config import SimConventions
from asset2sim.urdf import UrdfDynamics, UrdfGeometry, UrdfInertial, UrdfJoint, UrdfLimit, UrdfLink, UrdfStyle, write_urdf

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


#: Numbers of the URDF handed to MuJoCo's importer: :func:`_f` (shortest round trip, 0 as ``0``).
_IMPORT_STYLE = UrdfStyle(number=_f)


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
    (mesh files named as in ``mesh_names``), inertias in the link axes, with
    MuJoCo's compiler extension; built as a :class:`~asset2sim.urdf.UrdfModel`
    and written by :func:`asset2sim.urdf.write_urdf`."""
    mujoco_ext = ET.Element("mujoco")
    ET.SubElement(mujoco_ext, "compiler", {
        "angle": "radian", "strippath": "false", "discardvisual": "true", "fusestatic": "false",
        "balanceinertia": "false", "inertiafromgeom": "false", "boundmass": "0", "boundinertia": "0",
    })
    out = UrdfModel(name=_safe(model.name), extensions=[mujoco_ext])
    for name, link in model.links.items():
        ln = UrdfLink(name=name)
        ine = link.inertial
        if ine is None and missing_inertial == "bullet":
            ln.inertial = UrdfInertial(mass=BULLET_DEFAULT_MASS, inertia=np.diag(np.asarray(BULLET_DEFAULT_INERTIA, float)))
        elif ine is not None:
            ln.inertial = UrdfInertial(mass=ine.mass, origin=translation_matrix(ine.com()), inertia=ine.inertia_in_link_axes())
        for p in pieces[name]:
            if p.kind == "hull":
                key = (name, p.collision, p.group)
                ln.collisions.append(UrdfGeometry(kind="mesh", origin=p.origin, filename=mesh_names[key], mesh_scale=mesh_scales[key]))
            else:
                ln.collisions.append(UrdfGeometry(kind=p.kind, origin=p.origin, size=p.size, radius=p.radius, length=p.length))
        out.links[name] = ln
    for j in model.joints:
        out.joints.append(
            UrdfJoint(
                name=j.name, type=j.type, parent=j.parent, child=j.child, origin=j.origin, axis_xyz=j.axis,
                limit=UrdfLimit(lower=j.lower, upper=j.upper, effort=0.0, velocity=0.0) if j.type in ("revolute", "prismatic") else None,
                dynamics=None if j.type == "fixed" else UrdfDynamics(damping=j.damping, friction=j.friction),
            )
        )
    return write_urdf(out, style=_IMPORT_STYLE).decode("utf-8")


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
    meshes = _mesh_assets(pieces, mesh_root)
    final_assets = {rel: meshes.import_assets[v] for v, (rel, _) in meshes.virtual.items()}

    urdf_text = _urdf_for_import(model, pieces, meshes.names, meshes.scales, missing_inertial)
    spec, root = _import_skeleton(urdf_text, meshes.import_assets, urdf_path, notes)
    _set_options(root, conv, gravity, meshdir)
    file_to_mesh, used = _rename_meshes(root, meshes.virtual, urdf_path)
    asset_el = root.find("asset")
    if asset_el is None:
        asset_el = etree.SubElement(root, "asset")
    worldbody = root.find("worldbody")
    bodies = {b.get("name"): b for b in worldbody.iter("body")}
    if set(bodies) != set(model.links):
        raise MjcfError(f"{urdf_path}: MuJoCo's import has bodies {sorted(bodies)}, the URDF links {sorted(model.links)}")
    _place_bodies(model, spec, bodies, urdf_path)
    names_in_qpos: list[str] = []
    for b in worldbody.iter("body"):
        link = model.links[b.get("name")]
        _set_inertial(b, link, missing_inertial, notes)
        names_in_qpos += _set_joints(b, link, model, spec, springs, urdf_path)
        geom_mesh = {key: file_to_mesh[v] for key, v in meshes.names.items() if key[0] == link.name}
        _set_geoms(b, link, model, pieces[link.name], geom_mesh, visuals, urdf_path)
    if set(names_in_qpos) != set(movable):
        raise MjcfError(f"{urdf_path}: MuJoCo's import has joints {names_in_qpos}, the URDF {sorted(movable)}")
    _set_contacts(root, model, pieces, fixed_base, notes)
    root_body = bodies[model.root]
    _add_root_and_ground(root_body, worldbody, fixed_base, ground)

    compiled, qpos, height = _place_on_ground(root, root_body, final_assets, initial_state, fixed_base, urdf_path, notes)
    if visuals:  # after placement: visual meshes never collide, and cost compile time
        for b in worldbody.iter("body"):
            _add_visuals(b, model.links[b.get("name")], mesh_root, asset_el, meshes.files, final_assets, used, notes)
    key = etree.SubElement(etree.SubElement(root, "keyframe"), "key", name=KEYFRAME)
    key.set("qpos", _fv(qpos))
    etree.indent(root, space="  ")
    xml = etree.tostring(root, encoding="unicode")
    # Only the root's pose and the keyframe changed since ``compiled``.
    order = [mujoco.mj_id2name(compiled, mujoco.mjtObj.mjOBJ_JOINT, j) for j in range(compiled.njnt)]
    joint_names = [n for n in order if n in movable]
    return MjcfBuild(
        xml=xml,
        derived_meshes=meshes.derived,
        mesh_files=meshes.files,
        initial_qpos=qpos,
        joint_names=joint_names,
        notes=notes,
        root_height=height,
    )


@dataclass
class _MeshAssets:
    """Mesh files of the convex pieces. ``derived`` relative path -> OBJ bytes
    of pieces written anew; ``files`` relative path -> source file of whole
    single-group files referenced as they are; ``names`` / ``scales`` piece
    key (link, collision, group) -> name given to MuJoCo's import / scale (3,)
    or None; ``virtual`` import name -> (relative path, scale);
    ``import_assets`` import name -> bytes."""

    derived: dict[str, bytes] = field(default_factory=dict)
    files: dict[str, Path] = field(default_factory=dict)
    names: dict[tuple, str] = field(default_factory=dict)
    scales: dict[tuple, np.ndarray | None] = field(default_factory=dict)
    virtual: dict[str, tuple[str, np.ndarray | None]] = field(default_factory=dict)
    import_assets: dict[str, bytes] = field(default_factory=dict)


def _mesh_assets(pieces: dict[str, list[CollisionPiece]], mesh_root: Path) -> _MeshAssets:
    """One mesh per convex piece: the original file when a hull is a whole
    single-group file inside ``mesh_root``, else the hull written as OBJ
    under :data:`DERIVED_MESH_DIR`."""
    out = _MeshAssets()
    for name, plist in pieces.items():
        for p in plist:
            if p.kind != "hull":
                continue
            key = (name, p.collision, p.group)
            rel = _relative(p.source, mesh_root) if p.whole_file else None
            if rel is not None:
                out.files[rel] = p.source
                data = p.source.read_bytes()
                scale = None if np.allclose(p.scale, 1.0) else np.asarray(p.scale, float)
            else:
                rel = f"{DERIVED_MESH_DIR}/{_safe(name)}__c{p.collision}_g{p.group}.obj"
                data = _hull_obj(p.points)
                out.derived[rel] = data
                scale = None
            vname = f"piece{len(out.virtual)}.obj"
            out.virtual[vname] = (rel, scale)
            out.names[key] = vname
            out.scales[key] = scale
            out.import_assets[vname] = data
    return out


def _import_skeleton(urdf_text: str, assets: dict[str, bytes], urdf_path: Path, notes: list[str]):
    """MuJoCo's own URDF import: (``MjSpec``, root element of its MJCF).

    Raises:
        MjcfError: MuJoCo refuses the file.
    """
    mujoco = _mujoco()
    try:
        with mujoco_messages() as caught:
            spec = mujoco.MjSpec.from_string(urdf_text, assets=assets)
            skeleton = spec.to_xml()
    except Exception as exc:  # mujoco raises ValueError with its message
        raise MjcfError(f"MuJoCo could not import {urdf_path}: {exc}") from exc
    notes.extend(_mujoco_warnings(caught))
    return spec, etree.fromstring(skeleton.encode())


def _set_options(root, conv: SimConventions, gravity: bool, meshdir: str) -> None:
    """``<compiler>``, ``<option>`` and ``<default>`` as the first three
    children of ``root`` (timestep, gravity, no-slip, elliptic cones, contact
    friction as PyBullet combines it)."""
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


def _rename_meshes(root, virtual: dict[str, tuple[str, np.ndarray | None]], urdf_path: Path) -> tuple[dict[str, str], set[str]]:
    """Give the import's ``<mesh>`` assets their final file, scale and a
    unique name; returns (import name -> mesh asset name, names used).

    Raises:
        MjcfError: the import produced a mesh that is not one of the pieces.
    """
    file_to_mesh: dict[str, str] = {}
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
    return file_to_mesh, used


def _place_bodies(model: UrdfModel, spec, bodies: dict, urdf_path: Path) -> None:
    """Body poses at full precision from the joint origins (after checking
    MuJoCo placed each body where the URDF does, to 2e-5 relative).

    Raises:
        MjcfError: a body placed elsewhere.
    """
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


def _set_inertial(b, link, missing_inertial: str, notes: list[str]) -> None:
    """The body's ``<inertial>``: the file's (``fullinertia`` in the body
    frame), PyBullet's default for a missing one under ``"bullet"``, else none."""
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


def _set_joints(b, link, model: UrdfModel, spec, springs: dict[str, Spring], urdf_path: Path) -> list[str]:
    """Rewrite the body's joint at full precision (axis, range, damping,
    ``frictionloss``, spring) after checking MuJoCo read the URDF's values;
    returns the joint names written.

    Raises:
        MjcfError: an unexpected joint, or another axis / damping / friction.
    """
    pj = model.parent_joint(link.name)
    names = []
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
        names.append(pj.name)
    return names


def _set_geoms(b, link, model: UrdfModel, plist: list[CollisionPiece], geom_mesh: dict[tuple, str], visuals: bool, urdf_path: Path) -> None:
    """Name and place the body's collision geoms (one per piece), with their
    mesh asset (``geom_mesh``: piece key -> mesh asset name) and friction.

    Raises:
        MjcfError: MuJoCo made another number of geoms than pieces.
    """
    geoms = b.findall("geom")
    if len(geoms) != len(plist):
        raise MjcfError(f"{urdf_path}: MuJoCo made {len(geoms)} geoms for link {link.name!r}, expected {len(plist)}")
    fr = _link_friction(model, link.name)
    for g, p in zip(geoms, plist):
        g.set("name", f"{_safe(link.name)}__c{p.collision}_g{p.group}")
        g.set("pos", _fv(p.origin[:3, 3]))
        g.set("quat", _quat_text(p.origin[:3, :3]))
        if p.kind == "hull":
            g.set("mesh", geom_mesh[(link.name, p.collision, p.group)])
        if not math.isclose(fr, BULLET_DEFAULT_FRICTION * BULLET_PLANE_FRICTION):
            g.set("friction", f"{_f(fr)} 0.005 0.0001")
        if visuals:
            g.set("group", "3")


def _set_contacts(root, model: UrdfModel, pieces: dict[str, list[CollisionPiece]], fixed_base: bool, notes: list[str]) -> None:
    """Replace ``<contact>`` by the ``<pair>``s and ``<exclude>``s that make
    MuJoCo collide exactly PyBullet's pairs (:func:`contact_policy`)."""
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


def _add_root_and_ground(root_body, worldbody, fixed_base: bool, ground: bool) -> None:
    """A free joint on the root body (unless ``fixed_base``) and the ground
    plane geom :data:`GROUND` (friction: MuJoCo takes the larger, the link's)."""
    if not fixed_base:
        fj = etree.Element("freejoint", name=FREE_JOINT)
        idx = 1 if root_body.find("inertial") is not None and list(root_body).index(root_body.find("inertial")) == 0 else 0
        root_body.insert(idx, fj)
    if ground:
        plane = etree.Element("geom", name=GROUND, type="plane", size="0 0 1")
        plane.set("friction", "0 0.005 0.0001")  # MuJoCo takes the larger friction: the link's
        plane.set("rgba", "0.8 0.8 0.8 1")
        worldbody.insert(0, plane)


def _place_on_ground(root, root_body, assets: dict[str, bytes], initial_state: dict[str, float], fixed_base: bool,
                     urdf_path: Path, notes: list[str]):
    """Compile ``root`` and lift the root so the lowest collision point
    touches z = 0 at the initial state (:func:`lowest_point`); returns
    (compiled ``MjModel``, keyframe qpos (nq,), height m).

    Raises:
        MjcfError: the MJCF does not compile.
    """
    mujoco = _mujoco()
    xml = etree.tostring(root, encoding="unicode")
    try:
        with mujoco_messages() as caught:
            compiled = mujoco.MjModel.from_xml_string(xml, assets=assets)
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
    return compiled, qpos, height


def _mujoco_warnings(caught: list[str]) -> list[str]:
    """MuJoCo's compiler warnings as notes (texture-coordinate complaints about
    OBJ files are dropped: collision meshes carry no texture)."""
    return [f"MuJoCo: {text}" for text in caught if "texture coordinate" not in text]


def _mtl_colour(obj: Path) -> str:
    """``rgba`` text of the first material an OBJ uses (MTL ``Kd`` and ``d``),
    grey when there is none."""
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
