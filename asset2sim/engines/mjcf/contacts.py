"""Contacts: the link pairs PyBullet collides made MuJoCo's (:func:`contact_policy`,
written as ``<pair>`` / ``<exclude>``) and PyBullet's friction of a link.
"""

from __future__ import annotations

from lxml import etree

from asset2sim.engines.loading import BULLET_DEFAULT_FRICTION, BULLET_PLANE_FRICTION, CollisionPiece
from asset2sim.engines.mjcf.base import num_text, safe_name
from asset2sim.urdf import UrdfModel


def link_friction(model: UrdfModel, link: str) -> float:
    """PyBullet's contact friction of a link against the ground plane: the
    product of the link's lateral friction (0.5 unless ``<contact>`` says) and
    the plane's (0.5)."""
    lat = model.links[link].lateral_friction
    return (BULLET_DEFAULT_FRICTION if lat is None else lat) * BULLET_PLANE_FRICTION


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


def set_contacts(root, model: UrdfModel, pieces: dict[str, list[CollisionPiece]], fixed_base: bool, notes: list[str]) -> None:
    """Replace ``<contact>`` by the ``<pair>``s and ``<exclude>``s that make
    MuJoCo collide exactly PyBullet's pairs (:func:`contact_policy`)."""
    contact = etree.Element("contact")
    pairs, excludes = contact_policy(model, pieces, free=not fixed_base)
    for a, b in pairs:
        for pa in pieces[a]:
            for pb in pieces[b]:
                pe = etree.SubElement(contact, "pair")
                pe.set("geom1", f"{safe_name(a)}__c{pa.collision}_g{pa.group}")
                pe.set("geom2", f"{safe_name(b)}__c{pb.collision}_g{pb.group}")
                pe.set("condim", "3")
                f = max(link_friction(model, a), link_friction(model, b))
                pe.set("friction", f"{num_text(f)} {num_text(f)} 0.005 0.0001 0.0001")
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
