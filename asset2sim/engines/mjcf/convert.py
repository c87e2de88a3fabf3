"""The URDF -> MJCF conversion (:func:`urdf_to_mjcf`) as named steps over MuJoCo's own import: the
convex pieces' mesh assets, the URDF handed to MuJoCo's importer, then the rewrites of :mod:`.rewrite`."""

from __future__ import annotations

import xml.etree.ElementTree as ET
from copy import deepcopy
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from lxml import etree

from asset2sim.engines.base import SessionOptions
from asset2sim.engines.loading import BULLET_DEFAULT_INERTIA, BULLET_DEFAULT_MASS, CollisionPiece, collision_pieces, read_urdf
from asset2sim.engines.mjcf.base import (DERIVED_MESH_DIR, GROUND, KEYFRAME, MjcfError, child, compile_xml, load_mujoco,
                                         mujoco_call, num_text, place_on_ground, relative_to, safe_name, vec_text)
from asset2sim.engines.mjcf.aids import add_solver_aids, ground_aid, prism_aid, write_aids
from asset2sim.engines.mjcf.rewrite import (add_root_and_ground, cylinder_prisms, place_bodies, rename_meshes, set_contacts, set_geoms,
                                            set_inertial, set_joints, set_options)
from asset2sim.engines.mjcf.visuals import add_visuals
from asset2sim.file_names import file_stem
from asset2sim.frames import translation_matrix
from asset2sim.mesh_io import MeshCache, hull_obj
from asset2sim.schemas.config import SimConventions
from asset2sim.schemas.report import SolverAid
from asset2sim.urdf import UrdfDynamics, UrdfGeometry, UrdfInertial, UrdfJoint, UrdfLimit, UrdfLink, UrdfModel, UrdfStyle, write_urdf


@dataclass
class MeshAssets:
    """Mesh files of the convex pieces: ``derived`` path -> OBJ bytes written
    anew; ``files`` path -> source file referenced as it is; ``names`` piece key (link, collision, group) -> import
    name; ``virtual`` import name -> (path, scale (3,) or None); ``import_assets`` import name -> bytes."""

    derived: dict[str, bytes] = field(default_factory=dict)
    files: dict[str, Path] = field(default_factory=dict)
    names: dict[tuple, str] = field(default_factory=dict)
    virtual: dict[str, tuple[str, np.ndarray | None]] = field(default_factory=dict)
    import_assets: dict[str, bytes] = field(default_factory=dict)


def mesh_assets(pieces: dict[str, list[CollisionPiece]], mesh_root: Path) -> MeshAssets:
    """One mesh per convex piece: the original file when a hull is a whole
    single-group file inside ``mesh_root``, else the hull written as OBJ
    under :data:`DERIVED_MESH_DIR`."""
    out = MeshAssets()
    for name, plist in pieces.items():
        for p in plist:
            if p.kind != "hull":
                continue
            rel = relative_to(p.source, mesh_root) if p.whole_file else None
            if rel is not None:
                out.files[rel] = p.source
                data = p.source.read_bytes()
                scale = None if np.allclose(p.scale, 1.0) else p.scale
            else:
                rel = f"{DERIVED_MESH_DIR}/{file_stem(name)}__c{p.collision}_g{p.group}.obj"
                data = hull_obj(p.points, num_text)
                out.derived[rel] = data
                scale = None
            vname = f"piece{len(out.virtual)}.obj"
            out.virtual[vname] = (rel, scale)
            out.names[(name, p.collision, p.group)] = vname
            out.import_assets[vname] = data
    return out


def urdf_for_import(model: UrdfModel, pieces: dict[str, list[CollisionPiece]], meshes: MeshAssets, missing_inertial: str) -> str:
    """A URDF equivalent to ``model`` whose collisions are the convex pieces
    (mesh files named and scaled as in ``meshes``), inertias in the link axes, with
    MuJoCo's ``<mujoco><compiler/>`` extension."""
    mujoco_ext = ET.Element("mujoco")
    ET.SubElement(mujoco_ext, "compiler", {
        "angle": "radian", "strippath": "false", "discardvisual": "true", "fusestatic": "false",
        "balanceinertia": "false", "inertiafromgeom": "false", "boundmass": "0", "boundinertia": "0",
    })
    out = UrdfModel(name=safe_name(model.name), extensions=[mujoco_ext])
    for name, link in model.links.items():
        ln = UrdfLink(name=name)
        ine = link.inertial
        if ine is None and missing_inertial == "bullet":
            ln.inertial = UrdfInertial(mass=BULLET_DEFAULT_MASS, inertia=np.diag(np.asarray(BULLET_DEFAULT_INERTIA, float)))
        elif ine is not None:
            ln.inertial = UrdfInertial(mass=ine.mass, origin=translation_matrix(ine.com()), inertia=ine.inertia_in_link_axes())
        for p in pieces[name]:
            if p.kind == "hull":
                vname = meshes.names[(name, p.collision, p.group)]
                scale = meshes.virtual[vname][1]
                ln.collisions.append(UrdfGeometry(kind="mesh", origin=p.origin, filename=vname, mesh_scale=scale))
            else:
                ln.collisions.append(UrdfGeometry(kind=p.kind, origin=p.origin, size=p.size, radius=p.radius, length=p.length))
        out.links[name] = ln
    out.joints = [UrdfJoint(
        name=j.name, type=j.type, parent=j.parent, child=j.child, origin=j.origin, axis_xyz=j.axis,
        limit=UrdfLimit(lower=j.lower, upper=j.upper, effort=0.0, velocity=0.0) if j.type in ("revolute", "prismatic") else None,
        dynamics=None if j.type == "fixed" else UrdfDynamics(damping=j.damping, friction=j.friction)) for j in model.joints]
    return write_urdf(out, style=UrdfStyle(number=num_text)).decode("utf-8")


def import_skeleton(urdf_text: str, assets: dict[str, bytes], urdf_path: Path, notes: list[str]):
    """MuJoCo's own URDF import: (``MjSpec``, root element of its MJCF) (MjcfError: refused)."""
    mujoco = load_mujoco()

    def load():
        spec = mujoco.MjSpec.from_string(urdf_text, assets=assets)
        return spec, spec.to_xml()

    spec, skeleton = mujoco_call(load, f"MuJoCo could not import {urdf_path}", notes)
    return spec, etree.fromstring(skeleton.encode())


@dataclass
class MjcfBuild:
    """An MJCF text and what it needs: ``derived_meshes`` path (from ``meshdir``)
    -> OBJ bytes to write; ``mesh_files`` path -> source file referenced as it
    is; ``initial_qpos`` (nq,) of the keyframe; ``joint_names`` movable joints
    in qpos order; ``notes`` what changed; ``root_height`` m the root was lifted; ``aids`` the solver aids written
    (:mod:`asset2sim.engines.mjcf.aids`).
    """

    xml: str
    derived_meshes: dict[str, bytes]
    mesh_files: dict[str, Path]
    initial_qpos: np.ndarray
    joint_names: list[str]
    notes: list[str] = field(default_factory=list)
    root_height: float = 0.0
    aids: list[SolverAid] = field(default_factory=list)

    def assets(self) -> dict[str, bytes]:
        """Every mesh as bytes, keyed as the MJCF names them (for in-memory compiles)."""
        return {**{k: p.read_bytes() for k, p in self.mesh_files.items()}, **self.derived_meshes}


def urdf_to_mjcf(urdf_path: Path | str, options: SessionOptions | None = None, *, missing_inertial: str = "massless",
                 mesh_root: Path | None = None, meshdir: str = ".", visuals: bool = False, compile_visuals: bool = True,
                 visual_meshes: MeshCache | None = None) -> MjcfBuild:
    """Convert a URDF into MJCF under the SPEC's conventions, as a session of ``options`` opens it.

    Args:
        options: what the model is opened with (default ``SessionOptions()``): ``initial_state`` (joint -> rad
            or m) in the keyframe ``initial`` (other joints at 0); ``springs`` (joint -> :class:`Spring`)
            written as joint ``stiffness`` and ``springref``; ``fixed_base``: no free joint, the root stays at
            the world origin; ``ground`` / ``gravity``: the ground plane / gravity -9.81 m/s^2 along z;
            ``conventions``: the time step and solver settings; ``press_efforts`` and ``object_root_fixed``: what
            the solver aids are judged on (:mod:`.aids`, :func:`object_model`).
        missing_inertial: a link without ``<inertial>`` is ``"massless"`` (the
            file's truth) or gets PyBullet's 1 kg and unit inertia (``"bullet"``).
        mesh_root: folder the MJCF's ``meshdir`` points at (default: the URDF's folder).
        meshdir: the ``meshdir`` written in the MJCF (relative to the MJCF file).
        visuals: also write the visual meshes as non-colliding geoms (group 2;
            collision geoms go to group 3).
        compile_visuals: with ``visuals``, compile the text with them (False: the caller loads the file it
            writes, as :func:`asset2sim.formats.mjcf.export.export_mjcf` does).
        visual_meshes: where the visual mesh files are read (default: a :class:`~asset2sim.mesh_io.MeshCache` of its own).

    Raises:
        UrdfError: the URDF cannot be read.
        MjcfError: MuJoCo cannot import or compile the result, or reads a value differently.
        ValueError: an unknown ``missing_inertial`` policy, or an initial state naming an unknown joint.
    """
    opts = options or SessionOptions()
    fixed_base, ground, gravity = opts.fixed_base, opts.ground, opts.gravity
    mujoco = load_mujoco()
    if missing_inertial not in ("massless", "bullet"):
        raise ValueError(f"missing_inertial must be 'massless' or 'bullet', not {missing_inertial!r}")
    conv = opts.conventions or SimConventions()
    urdf_path = Path(urdf_path)
    model = read_urdf(urdf_path)
    initial_state = dict(opts.initial_state or {})
    springs = dict(opts.springs or {})
    movable = {j.name: j for j in model.movable_joints}
    unknown = sorted(set(initial_state) - set(movable))
    if unknown:
        raise ValueError(f"{urdf_path}: initial state names joints that are not movable joints of the file: {unknown}")
    mesh_root = Path(mesh_root) if mesh_root is not None else urdf_path.parent
    pieces, notes = collision_pieces(model)
    meshes = mesh_assets(pieces, mesh_root)
    final_assets = {rel: meshes.import_assets[v] for v, (rel, _) in meshes.virtual.items()}

    spec, root = import_skeleton(urdf_for_import(model, pieces, meshes, missing_inertial), meshes.import_assets, urdf_path, notes)
    set_options(root, conv, gravity, meshdir)
    file_to_mesh, used = rename_meshes(root, meshes.virtual, urdf_path)
    asset_el = child(root, "asset")
    worldbody = root.find("worldbody")
    geom_mesh = {key: file_to_mesh[v] for key, v in meshes.names.items()}
    # every body of the import (pose, inertial, joint, collision geoms) rewritten from the URDF
    bodies = {b.get("name"): b for b in worldbody.iter("body")}
    if set(bodies) != set(model.links):
        raise MjcfError(f"{urdf_path}: MuJoCo's import has bodies {sorted(bodies)}, the URDF links {sorted(model.links)}")
    place_bodies(model, spec, bodies)
    names_in_qpos: list[str] = []
    for b in worldbody.iter("body"):
        link = model.links[b.get("name")]
        set_inertial(b, link, missing_inertial, notes)
        names_in_qpos += set_joints(b, link, model, spec, springs)
        set_geoms(b, link, model, pieces[link.name], geom_mesh, visuals)
    if set(names_in_qpos) != set(movable):
        raise MjcfError(f"{urdf_path}: MuJoCo's import has joints {names_in_qpos}, the URDF {sorted(movable)}")
    set_contacts(root, model, pieces, fixed_base, notes)
    root_body = bodies[model.root]
    add_root_and_ground(root_body, worldbody, fixed_base, ground)
    prisms = cylinder_prisms(worldbody, asset_el)

    compiled, qpos, height = place_on_ground(root, root_body, final_assets, initial_state, fixed_base, urdf_path, notes)
    judged = object_model(root, root_body.get("name"), final_assets, initial_state, conv, opts, urdf_path)
    judged, judged_qpos = judged or (compiled, qpos)
    aids = [prism_aid(g) for g in prisms] + add_solver_aids(worldbody, judged, judged_qpos, opts.press_efforts, conv.timestep)
    if ground and not fixed_base:
        aids.append(ground_aid(worldbody.find(f"geom[@name='{GROUND}']")))
    write_aids(root, aids)
    notes += [f"solver aid on {a.element!r}: {a.kind} {a.written} ({a.criterion}; {a.effect})" for a in aids]
    if visuals:  # after placement: visual meshes never collide, and cost compile time
        for b in worldbody.iter("body"):
            add_visuals(b, model.links[b.get("name")], mesh_root, asset_el, meshes.files, final_assets, used, notes,
                        visual_meshes if visual_meshes is not None else MeshCache())
    etree.SubElement(etree.SubElement(root, "keyframe"), "key", name=KEYFRAME, qpos=vec_text(qpos))  # the initial state
    etree.indent(root, space="  ")
    xml = etree.tostring(root, encoding="unicode")
    if visuals and compile_visuals:  # the file as written must compile too
        compile_xml(xml, final_assets, urdf_path)
    order = [mujoco.mj_id2name(compiled, mujoco.mjtObj.mjOBJ_JOINT, j) for j in range(compiled.njnt)]
    return MjcfBuild(xml=xml, derived_meshes=meshes.derived, mesh_files=meshes.files, initial_qpos=qpos,
                     joint_names=[n for n in order if n in movable], notes=notes, root_height=height, aids=aids)


def object_model(root, root_name: str, assets: dict[str, bytes], initial_state: dict[str, float], conv: SimConventions,
                 opts: SessionOptions, urdf_path: Path):
    """(``MjModel``, keyframe qpos (nq,)) of the object as its export writes it, the model the solver aids are judged
    on (:attr:`SessionOptions.object_root_fixed`): a copy of the MJCF ``root`` with the object's declared root (the
    free joint added or removed) and gravity on (``conv.gravity``, m/s^2), at ``initial_state`` (joint -> rad or m),
    placed on the ground as the export places it; None where that is the session's own model (no declared root given,
    or the same root with gravity on). Raises MjcfError: the copy does not compile."""
    own = opts.object_root_fixed
    if own is None or (own == opts.fixed_base and opts.gravity):
        return None
    copy = deepcopy(root)
    body = next(b for b in copy.find("worldbody").iter("body") if b.get("name") == root_name)
    free = body.find("freejoint")
    if own and free is not None:
        body.remove(free)
    elif not own and free is None:
        add_root_and_ground(body, copy.find("worldbody"), fixed_base=False, ground=False)
    copy.find("option").set("gravity", f"0 0 {num_text(conv.gravity)}")
    model, qpos, _ = place_on_ground(copy, body, assets, initial_state, own, urdf_path, [])
    return model, qpos

