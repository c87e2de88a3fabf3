"""Joints a check may work in one simulation at once: parts that move exactly as each would alone.

With the root fixed, the joints whose parent link is welded to the root carry dynamically independent subtrees: the
joint-space mass matrix of a fixed-base tree is block-diagonal over the root's branches (Featherstone, *Rigid Body
Dynamics Algorithms*, 2008, sec. 6.2), so a force on one branch accelerates no other. Two such parts can still meet;
a batch therefore holds only parts whose swept boxes (each subtree's axis-aligned box over every pose its check
visits, widened by :data:`MARGIN`) do not overlap. A check of many parts (a keyboard's keys, a remote's buttons) then
steps its simulation once for a batch instead of once per part (``docs/design/metrics.md``, "Parts worked at once").
"""

from __future__ import annotations

import numpy as np

from asset2sim.engines.base import SimSession
from asset2sim.tasks.check.contact_points import joint_frame_axis
from asset2sim.tasks.geometry.limits import rigid_group
from asset2sim.tasks.ingest.mesh_checks import box_corners
from asset2sim.urdf import UrdfModel

#: Clearance (m) added to every side of a swept box beyond the engine's own box (which already holds its contact
#: margin): two parts of a batch stay this far apart at the closest.
MARGIN = 1e-3


def root_branches(model: UrdfModel, joints: list[str]) -> list[str]:
    """The joints of ``joints`` (in order) whose parent link is welded to the root by fixed joints only: with the root
    fixed their parent never moves, and their subtrees are separate branches of the tree."""
    if model.root is None:
        return []
    fixed = rigid_group(model, model.root)
    return [j for j in joints if model.joint(j).parent in fixed]


def links_box(session: SimSession, links: list[str]) -> tuple[np.ndarray, np.ndarray]:
    """(lo (3,), hi (3,)) m: the engine's box of ``links`` as they are now."""
    boxes = [session.link_aabb(ln) for ln in links]
    return np.min([b[0] for b in boxes], axis=0), np.max([b[1] for b in boxes], axis=0)


def swept_box(session: SimSession, joint: str, links: list[str], state: dict[str, float],
              positions: list[float]) -> tuple[np.ndarray, np.ndarray]:
    """(lo (3,), hi (3,)) m: a box holding ``links`` (the subtree ``joint`` moves) at every position of ``joint``
    between the least and the greatest of ``positions`` (rad or m), the other joints at ``state``. A slide: the box of
    the two ends' boxes (a translation stays inside it). A hinge: the box of the cylinder about the axis through every
    corner of the links' boxes at the first position (whatever the angle, a point keeps its distance from the axis and
    its place along it). Leaves the session's joints at ``state``."""
    session.set_joint_positions({**state, joint: positions[0]})
    lo, hi = links_box(session, links)
    if session.joint_types[joint] == "prismatic":
        for q in (min(positions), max(positions)):
            session.set_joint_positions({**state, joint: q})
            lo2, hi2 = links_box(session, links)
            lo, hi = np.minimum(lo, lo2), np.maximum(hi, hi2)
    else:
        o, a = joint_frame_axis(session, joint, session.joint_child[joint])
        corners = box_corners(lo, hi) - o
        along = corners @ a
        radius = float(np.max(np.linalg.norm(corners - np.outer(along, a), axis=1)))
        ends = np.array([o + along.min() * a, o + along.max() * a])
        reach = radius * np.sqrt(np.clip(1.0 - a * a, 0.0, 1.0))
        lo, hi = ends.min(axis=0) - reach, ends.max(axis=0) + reach
    session.set_joint_positions(dict(state))
    return lo, hi


def batches(boxes: dict[str, tuple[np.ndarray, np.ndarray]], margin: float = MARGIN) -> list[list[str]]:
    """Joints grouped (first fit, in the order of ``boxes``: joint -> (lo (3,), hi (3,)) m) so that no two boxes of
    a group, each widened by ``margin`` m, overlap. Every joint is in exactly one group; a group of one is worked
    alone."""
    wide = {n: (np.asarray(lo, float) - margin, np.asarray(hi, float) + margin) for n, (lo, hi) in boxes.items()}
    groups: list[list[str]] = []
    for name, (lo, hi) in wide.items():
        for group in groups:
            if all(np.any(lo > wide[o][1]) or np.any(hi < wide[o][0]) for o in group):
                group.append(name)
                break
        else:
            groups.append([name])
    return groups
