"""Where the floating gripper grasps a part (:func:`contact_point_rule`) and
which side of a joint it moves (:func:`grasp_side`).
"""

from __future__ import annotations

import functools
import re
from pathlib import Path

import numpy as np

from asset2sim.mesh_io import MeshReadError, read_mesh
from asset2sim.tasks.ingest.mesh_checks import box_corners
from asset2sim.tasks.interpret.part_labels import canonical_label
from asset2sim.urdf import UrdfGeometry, UrdfModel

#: Canonical part labels a gripper grasps when a link carries a geometry element so named.
HANDLE_LABELS: frozenset[str] = frozenset({"handle", "knob", "lever", "button"})

#: Share of the largest distance from the axis within which collision vertices count as the far edge.
FAR_EDGE_SHARE = 0.9

#: A side of a joint whose lowest point is this much (m) below the other's carries the object (:func:`grasp_side`).
SUPPORT_TOL = 0.003

_ELEMENT_SUFFIX = re.compile(r"[-_]?\d+$")


def element_label(name: str | None) -> str | None:
    """Canonical part label of a geometry element's name (``handle-18`` -> ``handle``), or None."""
    if not name:
        return None
    return canonical_label(_ELEMENT_SUFFIX.sub("", name.strip()))


@functools.lru_cache(maxsize=256)
def _mesh_vertices(path: str) -> np.ndarray:
    """Finite vertices (n, 3) of a mesh file, file units (read-only; (0, 3) when unreadable)."""
    try:
        v = read_mesh(Path(path)).vertices
    except MeshReadError:
        return np.zeros((0, 3))
    v = np.asarray(v, float)
    v = v[np.all(np.isfinite(v), axis=1)]
    v.setflags(write=False)
    return v


def geometry_points(g: UrdfGeometry) -> np.ndarray:
    """Points (k, 3) m of a geometry element in its link's frame: mesh vertices,
    box corners, a sphere's or cylinder's centre; k = 0 when unreadable."""
    if g.kind == "mesh" and g.path is not None:
        v = _mesh_vertices(str(g.path)) * g.scale
    elif g.kind == "box" and g.size is not None:
        h = 0.5 * np.asarray(g.size, float)
        v = box_corners(-h, h)
    elif g.kind in ("sphere", "cylinder") and g.radius is not None:
        v = np.zeros((1, 3))
    else:
        return np.zeros((0, 3))
    return v @ g.origin[:3, :3].T + g.origin[:3, 3]


def _walk(link: str, nexts) -> list[str]:
    """``link`` and every link ``nexts(name)`` reaches from it, in the order a depth-first walk meets them (each once)."""
    out, stack = [], [link]
    while stack:
        name = stack.pop()
        if name not in out:
            out.append(name)
            stack.extend(nexts(name))
    return out


def subtree(model: UrdfModel, link: str) -> list[str]:
    """``link`` and every link below it in ``model``, depth first (each once)."""
    return _walk(link, lambda n: [j.child for j in model.children(n)])


def rigid_group(model: UrdfModel, link: str) -> list[str]:
    """``link`` and every link joined to it by fixed joints (up and down the tree), in the order a depth-first walk
    meets them (the set of :func:`asset2sim.tasks.geometry.limits.rigid_group`, ordered: the first handle found wins)."""
    def fixed(name: str) -> list[str]:
        pj = model.parent_joint(name)
        up = [pj.parent] if pj is not None and pj.type == "fixed" else []
        return [j.child for j in model.children(name) if j.type == "fixed"] + up
    return _walk(link, fixed)


def link_points(model: UrdfModel, link: str) -> np.ndarray:
    """Collision points (k, 3) m of ``link`` in its frame (visual ones without collisions)."""
    ln = model.links.get(link)
    if ln is None:
        return np.zeros((0, 3))
    return _points(ln.collisions or ln.visuals)


def _points(geometries) -> np.ndarray:
    """:func:`geometry_points` (k, 3) m of every element of ``geometries``, stacked."""
    pts = [p for p in map(geometry_points, geometries) if len(p)]
    return np.concatenate(pts) if pts else np.zeros((0, 3))


def handle_points(model: UrdfModel, link: str) -> np.ndarray:
    """Points (k, 3) m, in ``link``'s frame, of its collision (else visual)
    elements named as a handle (:data:`HANDLE_LABELS`); k = 0 when none.

    Raises:
        KeyError: ``link`` is not in the model.
    """
    if link not in model.links:
        raise KeyError(f"link {link!r} is not in the URDF {model.path or model.name!r}")
    ln = model.links[link]
    return _points([g for g in ln.collisions if element_label(g.name) in HANDLE_LABELS] or
                   [g for g in ln.visuals if element_label(g.name) in HANDLE_LABELS])


def _grasp_points(session, model: UrdfModel | None, link: str) -> np.ndarray:
    """Points (k, 3) of ``link`` in its frame: the URDF's collision geometry with ``model`` (:func:`link_points`), else
    the engine's collision vertices, else its AABB corners."""
    if model is not None:
        return link_points(model, link)
    v = np.asarray(session.link_collision_vertices(link), float).reshape(-1, 3)
    if len(v):
        return v
    o, R = session.link_frame(link)
    return (box_corners(*session.link_aabb(link)) - np.asarray(o, float)) @ np.asarray(R, float)


def joint_frame_axis(session, joint: str, link: str) -> tuple[np.ndarray, np.ndarray]:
    """Origin o (3,) m of ``link``'s frame (the joint's frame when ``link`` is
    its child) and the joint's unit axis a (3,) in world coordinates."""
    o, R = session.link_frame(link)
    a = np.asarray(R, float) @ np.asarray(session.joint_axis(joint), float)
    return np.asarray(o, float), a / max(float(np.linalg.norm(a)), 1e-12)


def off_axis(points: np.ndarray, o: np.ndarray, a: np.ndarray) -> np.ndarray:
    """Distances (k,) m of ``points`` (k, 3) m from the axis along unit ``a`` (3,) through ``o`` (3,) m."""
    rel = points - o
    return np.linalg.norm(rel - np.outer(rel @ a, a), axis=1)


def side_links(session, joint: str, model: UrdfModel | None, side: str) -> list[str]:
    """Links of the session rigid with one ``side`` of ``joint`` (``child`` /
    ``parent``; the joint is movable, so no fixed joint joins the two sides); without a model the child link alone.

    Raises:
        ValueError: ``side`` is not child / parent, or ``parent`` without a model.
    """
    if side not in ("child", "parent"):
        raise ValueError(f"side must be 'child' or 'parent', got {side!r}")
    child = session.joint_child[joint]
    if model is None or child not in model.links:
        if side == "parent":
            raise ValueError(f"joint {joint!r}: the parent side needs the URDF model")
        return [child]
    start = child if side == "child" else model.joint(joint).parent
    return [ln for ln in rigid_group(model, start) if ln in session.link_names]


def contact_point_rule(session, joint: str, model: UrdfModel | None = None, *, opening_direction: float = 1.0,
                       side: str = "child") -> tuple[str, np.ndarray, str]:
    """Where a gripper grasps the part that ``joint`` moves, over the links of
    the grasped ``side`` (:func:`side_links`; ``docs/design/metrics.md``):

    1. a handle (:func:`handle_points`, needs ``model``): its bounding box's centre;
    2. revolute: the mean of the collision points at least :data:`FAR_EDGE_SHARE`
       of the largest distance from the axis (the far edge), on the link holding the farthest point;
    3. prismatic: the bounding box's centre moved to the link's extreme in
       ``opening_direction`` (+-1; a drawer's front).

    Points from the URDF's collision geometry with ``model``, else from the
    engine. Returns ``(link, point (3,) m in that link's frame, rule)``.

    Raises:
        KeyError: ``joint`` is not a movable joint of the session.
        ValueError: the side has no geometry to grasp; bad ``side``.
    """
    if joint not in session.joint_child:
        raise KeyError(f"joint {joint!r} is not a movable joint of the session")
    links = side_links(session, joint, model, side)
    if model is not None:
        for ln in links:
            if ln in model.links:
                h = handle_points(model, ln)
                if len(h):
                    return ln, 0.5 * (h.min(axis=0) + h.max(axis=0)), "handle"
    o, a = joint_frame_axis(session, joint, session.joint_child[joint])
    sgn = 1.0 if opening_direction >= 0 else -1.0
    prismatic = session.joint_types[joint] == "prismatic"
    best: tuple[float, str, np.ndarray] | None = None  # (reach, link, local points)
    for ln in links:
        v = _grasp_points(session, model, ln)
        if not len(v):
            continue
        lo, R = session.link_frame(ln)
        w = v @ np.asarray(R, float).T + np.asarray(lo, float)
        reach = float(np.max((w - o) @ a * sgn if prismatic else off_axis(w, o, a)))
        if best is None or reach > best[0]:
            best = (reach, ln, v)
    if best is None:
        raise ValueError(f"joint {joint!r}: links {links} have no collision geometry to grasp")
    _, link, v = best
    p, R = session.link_frame(link)
    a_l = np.asarray(R, float).T @ a  # the axis in the grasped link's frame
    o_l = np.asarray(R, float).T @ (o - np.asarray(p, float))
    if prismatic:
        c = 0.5 * (v.min(axis=0) + v.max(axis=0))
        c = c + a_l * sgn * (float((v @ a_l * sgn).max()) - sgn * float(c @ a_l))
        return link, c, "front"
    r = off_axis(v, o_l, a_l)
    far = v[r >= FAR_EDGE_SHARE * float(r.max())]
    return link, far.mean(axis=0), "far edge"


#: A grasp point closer to the axis than this share of the part's outer radius is a twist of the part by its rim.
TWIST_SHARE = 0.25


def grasp_lever(session, joint: str, link: str, point: np.ndarray, model: UrdfModel | None = None) -> float:
    """Distance (m, >= 1e-3) from revolute ``joint``'s axis at which a hand applies its force on ``link``:
    the grasp ``point``'s ((3,) m in ``link``'s frame), or, where that lies within :data:`TWIST_SHARE` of the
    part's outer radius (a knob or dial grasped on its axis), the outer radius: the fingers twist it by its
    rim. Points from the URDF's collision geometry with ``model``, else from the engine."""
    o, a = joint_frame_axis(session, joint, session.joint_child[joint])
    p, R = session.link_frame(link)

    def radius(v: np.ndarray) -> np.ndarray:
        return off_axis(v @ np.asarray(R, float).T + np.asarray(p, float), o, a)

    d = float(radius(np.asarray(point, float).reshape(1, 3))[0])
    pts = _grasp_points(session, model, link)
    rim = float(radius(pts).max()) if len(pts) else 0.0
    return max(rim if d < TWIST_SHARE * rim else d, 1e-3)


def lowest_point(session, links: list[str], model: UrdfModel | None) -> float:
    """Lowest world z (m) of ``links``' collision points (URDF geometry with ``model``, else AABBs); +inf without."""
    z = float("inf")
    for ln in links:
        v = link_points(model, ln) if model is not None else np.zeros((0, 3))
        if len(v):
            o, R = session.link_frame(ln)
            z = min(z, float(np.min(v @ np.asarray(R, float)[2] + float(o[2]))))
        elif session.link_has_collision(ln):
            z = min(z, float(session.link_aabb(ln)[0][2]))
    return z


def grasp_side(session, joint: str, model: UrdfModel | None, *, root_fixed: bool = False) -> str:
    """Which side of ``joint`` the gripper moves: ``parent`` when the child's
    side carries the object (its lowest point more than :data:`SUPPORT_TOL` m
    below the rest's), else ``child`` (always with a fixed root or no model)."""
    if root_fixed or model is None:
        return "child"
    child = side_links(session, joint, model, "child")
    sub = set(subtree(model, session.joint_child[joint]))  # the child's whole subtree rests with it
    z_child = lowest_point(session, [ln for ln in session.link_names if ln in sub] or child, model)
    z_rest = lowest_point(session, [ln for ln in session.link_names if ln not in sub], model)
    if not np.isfinite(z_child) or not np.isfinite(z_rest):
        return "child"
    return "parent" if z_child + SUPPORT_TOL < z_rest else "child"
