"""Rewrites of MuJoCo's import at full precision, after checking MuJoCo read the URDF's values, and the
``<pair>`` / ``<exclude>`` elements that make MuJoCo collide PyBullet's link pairs."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from lxml import etree

from asset2sim.engines.base import Spring
from asset2sim.engines.loading import BULLET_DEFAULT_INERTIA, BULLET_DEFAULT_MASS, CONTACT_FRICTION, CollisionPiece, link_friction
from asset2sim.engines.mjcf.base import (ARMATURE, CONE, FREE_JOINT, GROUND, MjcfError, child, close, num_text, quat_text,
                                         safe_name, vec_text)
from asset2sim.schemas.config import SimConventions
from asset2sim.urdf import UrdfModel


def contact_policy(model: UrdfModel, pieces: dict[str, list[CollisionPiece]], free: bool) -> tuple[list[tuple[str, str]], list[tuple[str, str]]]:
    """Make MuJoCo collide exactly PyBullet's link pairs (all with shapes but a
    link and its parent), given MuJoCo's ``filterBodyPair`` (drops welded
    bodies and, unless welded to the world, a weld group's parent). Returns
    (pairs to restore with ``<pair>``, pairs to remove with ``<exclude>``).
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
        return wa == wb or wa != world and wb != world and (wa == weld_parent(wb) or wb == weld_parent(wa))

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


def set_contacts(root, model: UrdfModel, pieces: dict[str, list[CollisionPiece]], fixed_base: bool, notes: list[str]) -> None:
    """Replace ``<contact>`` by the ``<pair>``s and ``<exclude>``s of :func:`contact_policy`, and an ``<exclude>`` for
    every other joint's parent and child that both have shapes (pairs MuJoCo's ``filterparent`` already drops, written
    so that a host scene with ``<flag filterparent="disable"/>`` keeps the SPEC's exclusion)."""
    contact = etree.Element("contact")
    pairs, excludes = contact_policy(model, pieces, free=not fixed_base)
    needed = set(excludes)
    # every parent-child pair with shapes on both sides excluded by name, not only those MuJoCo's parent filter would
    # collide: the filter then travels with the file into a host scene that turns filterparent off, and into MJX
    shaped = [n for n in model.tree_order() if pieces.get(n)]
    for j in model.joints:
        if j.parent in shaped and j.child in shaped and needed.isdisjoint({(j.parent, j.child), (j.child, j.parent)}):
            excludes.append((j.parent, j.child))
    for a, b in pairs:
        f = num_text(max(link_friction(model, a), link_friction(model, b)))
        for pa in pieces[a]:
            for pb in pieces[b]:
                etree.SubElement(contact, "pair", geom1=f"{safe_name(a)}__c{pa.collision}_g{pa.group}",
                                 geom2=f"{safe_name(b)}__c{pb.collision}_g{pb.group}", condim="3", friction=f"{f} {f} 0.005 0.0001 0.0001")
    for a, b in excludes:
        etree.SubElement(contact, "exclude", body1=a, body2=b)
    if pairs:
        notes.append("MuJoCo filters contacts between bodies welded by fixed joints and their parents; "
                     f"explicit <pair>s restore PyBullet's pairs {[f'{a}/{b}' for a, b in pairs]}")
    if needed:
        notes.append(f"<exclude>s remove parent/child pairs MuJoCo would collide: {[f'{a}/{b}' for a, b in sorted(needed)]}")
    for old in root.findall("contact"):
        root.remove(old)
    if len(contact):
        root.append(contact)


def set_options(root, conv: SimConventions, gravity: bool, meshdir: str) -> None:
    """``<compiler>``, ``<option>`` and ``<default>`` as the first three children of ``root``."""
    comp = child(root, "compiler")
    comp.attrib.clear()
    comp.attrib.update({"angle": "radian", "meshdir": meshdir, "autolimits": "true", "inertiafromgeom": "false",
                        "balanceinertia": "false", "boundmass": "0", "boundinertia": "0", "fusestatic": "false",
                        "discardvisual": "false"})
    default = etree.Element("default")
    etree.SubElement(default, "geom", condim="3", friction=f"{num_text(CONTACT_FRICTION)} 0.005 0.0001")
    etree.SubElement(default, "joint", armature="0")
    opt = etree.Element("option", timestep=num_text(conv.timestep), gravity=f"0 0 {num_text(conv.gravity if gravity else 0.0)}",
                        integrator="implicitfast", cone=CONE)
    for i, el in enumerate((comp, opt, default)):
        for old in root.findall(el.tag):
            root.remove(old)
        root.insert(i, el)


def rename_meshes(root, virtual: dict[str, tuple[str, np.ndarray | None]], urdf_path: Path) -> tuple[dict[str, str], set[str]]:
    """Give the import's ``<mesh>`` assets their final file, scale and a unique
    name; returns (import name -> mesh asset name, names used) (MjcfError: an
    unknown mesh)."""
    file_to_mesh: dict[str, str] = {}
    used: set[str] = set()
    for mesh in root.iter("mesh"):
        f = mesh.get("file")
        if f not in virtual:
            raise MjcfError(f"{urdf_path}: MuJoCo's import produced an unknown mesh {f!r}")
        rel, scale = virtual[f]
        for k in ("content_type", "scale", "name"):
            mesh.attrib.pop(k, None)
        base = safe_name(Path(rel).stem)
        nm, i = base, 1
        while nm in used:
            i += 1
            nm = f"{base}_{i}"
        used.add(nm)
        mesh.set("name", nm)
        mesh.set("file", rel)
        if scale is not None:
            mesh.set("scale", vec_text(scale))
        mesh.set("inertia", "shell")  # mesh volumes are never used (inertiafromgeom="false")
        file_to_mesh[f] = nm
    return file_to_mesh, used


def place_bodies(model: UrdfModel, spec, bodies: dict) -> None:
    """Body poses at full precision from the joint origins (MjcfError: MuJoCo
    placed a body elsewhere, beyond 2e-5 relative)."""
    tol = 2e-5
    for jnt in model.joints:
        b = bodies[jnt.child]
        sb = spec.body(jnt.child)
        if sb is None or not close(sb.pos, jnt.origin[:3, 3], tol * max(1.0, float(np.abs(jnt.origin[:3, 3]).max()))):
            raise MjcfError(f"{model.path}: MuJoCo placed body {jnt.child!r} elsewhere than the URDF ({jnt.origin[:3, 3]})")
        b.set("pos", vec_text(jnt.origin[:3, 3]))
        b.set("quat", quat_text(jnt.origin[:3, :3]))
        for k in ("euler", "axisangle", "xyaxes", "zaxis"):
            b.attrib.pop(k, None)


def set_inertial(b, link, missing_inertial: str, notes: list[str]) -> None:
    """The body's ``<inertial>``: the file's (``fullinertia`` in the body
    frame), PyBullet's default for a missing one under ``"bullet"``, else none."""
    for old in b.findall("inertial"):
        b.remove(old)
    ine = link.inertial
    el = None
    if ine is not None:
        i = ine.inertia_in_link_axes()
        el = etree.Element("inertial", pos=vec_text(ine.com()), mass=num_text(ine.mass))
        el.set("fullinertia", vec_text([i[0, 0], i[1, 1], i[2, 2], i[0, 1], i[0, 2], i[1, 2]]))
    elif missing_inertial == "bullet":
        el = etree.Element("inertial", pos="0 0 0", mass=num_text(BULLET_DEFAULT_MASS), diaginertia=vec_text(BULLET_DEFAULT_INERTIA))
        notes.append(f"link {link.name!r} has no <inertial>: given PyBullet's {BULLET_DEFAULT_MASS} kg, unit inertia")
    elif link.collisions:
        notes.append(f"link {link.name!r} has geometry but no <inertial>: massless in MuJoCo")
    if el is not None:
        b.insert(0, el)


def set_joints(b, link, model: UrdfModel, spec, springs: dict[str, Spring]) -> list[str]:
    """Rewrite the body's joint at full precision, its ``armature`` :data:`~asset2sim.engines.mjcf.base.ARMATURE`;
    returns the joint names written (MjcfError: an unexpected joint, or another axis / damping / friction)."""
    pj = model.parent_joint(link.name)
    names = []
    for je in b.findall("joint"):
        if pj is None or je.get("name") != pj.name:
            raise MjcfError(f"{model.path}: unexpected joint {je.get('name')!r} in body {link.name!r}")
        sj = spec.joint(pj.name)
        axis = np.asarray(sj.axis, float)
        if not close(axis / np.linalg.norm(axis), pj.axis, 1e-5):
            raise MjcfError(f"{model.path}: MuJoCo read axis {axis} for joint {pj.name!r}, the URDF {pj.axis}")
        if not (math.isclose(float(np.atleast_1d(sj.damping)[0]), pj.damping, rel_tol=1e-5, abs_tol=1e-12)
                and math.isclose(float(sj.frictionloss), pj.friction, rel_tol=1e-5, abs_tol=1e-12)):
            raise MjcfError(f"{model.path}: MuJoCo read other damping/friction for joint {pj.name!r}")
        for k in list(je.attrib):
            if k not in ("name", "type"):
                del je.attrib[k]
        je.set("axis", vec_text(pj.axis))
        if pj.type in ("revolute", "prismatic"):
            je.set("range", f"{num_text(pj.lower)} {num_text(pj.upper)}")
            je.set("limited", "true")
        else:
            je.set("limited", "false")
        je.set("damping", num_text(pj.damping))
        je.set("frictionloss", num_text(pj.friction))
        sp = springs.get(pj.name)
        if sp is not None and sp.stiffness > 0:
            je.set("stiffness", num_text(sp.stiffness))
            je.set("springref", num_text(sp.reference))
        # ARMATURE on the joint itself, so that a host scene's <default> adds no inertia the files do not hold (an aid
        # may raise it: asset2sim.engines.mjcf.aids)
        je.set("armature", num_text(ARMATURE))
        names.append(pj.name)
    return names


def set_geoms(b, link, model: UrdfModel, plist: list[CollisionPiece], geom_mesh: dict[tuple, str], visuals: bool) -> None:
    """Name and place the body's collision geoms (one per piece) with their
    mesh (``geom_mesh``: piece key -> mesh name) and friction (MjcfError:
    another number of geoms than pieces)."""
    geoms = b.findall("geom")
    if len(geoms) != len(plist):
        raise MjcfError(f"{model.path}: MuJoCo made {len(geoms)} geoms for link {link.name!r}, expected {len(plist)}")
    fr = link_friction(model, link.name)
    for g, p in zip(geoms, plist):
        g.set("name", f"{safe_name(link.name)}__c{p.collision}_g{p.group}")
        g.set("pos", vec_text(p.origin[:3, 3]))
        g.set("quat", quat_text(p.origin[:3, :3]))
        if p.kind == "hull":
            g.set("mesh", geom_mesh[(link.name, p.collision, p.group)])
        if not math.isclose(fr, CONTACT_FRICTION):
            g.set("friction", f"{num_text(fr)} 0.005 0.0001")
        if visuals:
            g.set("group", "3")


#: Sides of the prism the MJCF writes for a collision cylinder: MJX (``mujoco.mjx``'s collision table) collides a
#: cylinder with neither a box nor a mesh, a convex mesh with both; 20 is the most vertices MJX takes on one face
#: without warning of its cost.
CYLINDER_SIDES = 20


def cylinder_prisms(worldbody, asset_el) -> list[str]:
    """Every collision cylinder geom under ``worldbody`` (``size`` radius, half-length m; axis z) written as a convex
    mesh, the prism of :data:`CYLINDER_SIDES` sides whose faces touch the cylinder (it holds the cylinder; its edges
    stand 1.2 % of the radius outside), in an inline ``<mesh vertex=...>`` of ``asset_el``. Returns the geoms' names."""
    k = np.arange(CYLINDER_SIDES) * (2.0 * math.pi / CYLINDER_SIDES)
    ring = np.stack([np.cos(k), np.sin(k)], axis=1) / math.cos(math.pi / CYLINDER_SIDES)
    out = []
    for g in worldbody.iter("geom"):
        if g.get("type") != "cylinder" or g.get("contype") == "0":
            continue
        r, h = (float(v) for v in g.get("size").split()[:2])
        verts = np.vstack([np.column_stack([ring * r, np.full(CYLINDER_SIDES, z)]) for z in (-h, h)])
        name = f"{g.get('name')}__prism"
        etree.SubElement(asset_el, "mesh", name=name, vertex=" ".join(num_text(v) for v in verts.ravel()))
        g.set("type", "mesh")
        g.set("mesh", name)
        del g.attrib["size"]
        out.append(g.get("name"))
    return out


def add_root_and_ground(root_body, worldbody, fixed_base: bool, ground: bool) -> None:
    """A free joint on the root body (unless ``fixed_base``) and the ground plane :data:`GROUND`."""
    if not fixed_base:
        first_inertial = len(root_body) and root_body[0].tag == "inertial"  # the free joint after it
        root_body.insert(1 if first_inertial else 0, etree.Element("freejoint", name=FREE_JOINT))
    if ground:
        # friction 0: MuJoCo takes the larger friction, the link's
        worldbody.insert(0, etree.Element("geom", name=GROUND, type="plane", size="0 0 1", friction="0 0.005 0.0001",
                                          rgba="0.8 0.8 0.8 1"))
