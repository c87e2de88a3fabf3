"""The joints swept over their ranges: the positions sampled, the child's
pose at each, and the volume a child (or every other link) sweeps in a link's
frame, so that the pieces hold for every state of the object."""

from __future__ import annotations

import numpy as np

from asset2sim import urdf
from asset2sim.frames import axis_angle_matrix
from asset2sim.tasks.assemble.convex_pieces import CONTAINMENT_TOLERANCE, Piece, posed

#: Largest motion (m) of a child's vertex between two neighbouring swept positions (:func:`sweep_positions`),
#: at most :data:`MAX_SWEEP_SAMPLES` positions.
SWEEP_STEP = CONTAINMENT_TOLERANCE
MAX_SWEEP_SAMPLES = 48


def sweep_positions(joint: urdf.UrdfJoint, reach: float) -> np.ndarray:
    """Positions (n,) rad or m spread evenly over ``joint``'s whole range
    (its limits; a continuous joint over a full turn), at most :data:`SWEEP_STEP` m of
    motion apart for a point ``reach`` m from a revolute axis (a prismatic
    joint moves every point by the travel), n <= :data:`MAX_SWEEP_SAMPLES`;
    [0] for a fixed joint or an empty range."""
    if joint.type == "fixed":
        return np.zeros(1)
    if joint.type == "continuous":
        lo, hi = -np.pi, np.pi
    else:
        lo, hi = float(joint.lower), float(joint.upper)
    if not (np.isfinite(lo) and np.isfinite(hi)) or hi <= lo:
        return np.array([0.0 if not np.isfinite(lo) else lo])
    travel = (hi - lo) * (1.0 if joint.type == "prismatic" else max(reach, 1e-9))
    return np.linspace(lo, hi, int(np.clip(np.ceil(travel / SWEEP_STEP) + 1, 2, MAX_SWEEP_SAMPLES)))


def _positions_for(joint: urdf.UrdfJoint, local: np.ndarray) -> np.ndarray:
    """:func:`sweep_positions` of ``joint`` for points ``local`` (k, 3) m in its child's frame (reach: their distance
    from the axis, which turns the child frame about the axis through its origin)."""
    reach = float(np.max(np.linalg.norm(np.cross(local, joint.axis), axis=1), initial=0.0)) if joint.type in ("revolute", "continuous") else 0.0
    return sweep_positions(joint, reach)


def _joint_motion(joint: urdf.UrdfJoint, q: float) -> np.ndarray:
    """(4, 4) parent -> child transform of ``joint`` at position ``q`` (rad
    or m): its origin, then the rotation about or translation along its axis,
    as :meth:`asset2sim.urdf.UrdfModel.link_poses` composes it."""
    m = np.eye(4)
    if joint.type in ("revolute", "continuous"):
        m[:3, :3] = axis_angle_matrix(joint.axis, float(q))
    elif joint.type == "prismatic":
        m[:3, 3] = joint.axis * float(q)
    return joint.origin @ m


def reference_state(model: urdf.UrdfModel) -> dict[str, float]:
    """Joint -> 0 clipped to its limits (rad or m; 0 for a joint without
    finite limits): the pose the other joints hold while one is swept."""
    return {j.name: float(np.clip(0.0, j.lower, j.upper)) if np.isfinite(j.lower) and np.isfinite(j.upper) else 0.0
            for j in model.movable_joints}


def swept_child_points(model: urdf.UrdfModel, pieces: dict[str, list[Piece]], link: str) -> dict[str, np.ndarray]:
    """Vertices of every child link's pieces, and of the links below it
    (their :attr:`Piece.support` points; the joints below
    at :func:`reference_state`), in ``link``'s frame at every position of
    :func:`sweep_positions` of the joint between them: child -> (k, 3) m."""
    out = {}
    poses = model.link_poses(reference_state(model))
    for j in model.children(link):
        inv = np.linalg.inv(poses[j.child])
        pts, stack = [], [j.child]
        while stack:
            ln = stack.pop()
            stack.extend(c.child for c in model.children(ln))
            T = inv @ poses[ln]
            pts += [posed(p.support, T) for p in pieces.get(ln, [])]
        if not pts:
            continue
        local = np.vstack(pts)
        out[j.child] = np.vstack([posed(local, _joint_motion(j, q)) for q in _positions_for(j, local)])
    return out


#: Positions per movable joint at which other links are kept out of a link's merged pieces.
GUARD_SAMPLES = 9


def swept_other_points(model: urdf.UrdfModel, pieces: dict[str, list[Piece]], link: str) -> np.ndarray | None:
    """Support points (:attr:`Piece.support`) of every other link's pieces in
    ``link``'s frame (k, 3) m, with the joints at :func:`reference_state` and
    each in turn at :data:`GUARD_SAMPLES` positions over its range; None when no other
    link has pieces."""
    ref = reference_state(model)
    local = {o: np.vstack([p.support for p in pieces[o]]) for o in model.links if o != link and pieces.get(o)}
    if not local:
        return None
    states = [ref]
    for j in model.movable_joints:
        qs = sweep_positions(j, 1.0)
        qs = qs[np.unique(np.linspace(0, len(qs) - 1, min(GUARD_SAMPLES, len(qs))).round().astype(int))]
        states += [{**ref, j.name: float(q)} for q in qs]
    seen: dict[str, list[np.ndarray]] = {o: [] for o in local}
    out = []
    for st in states:
        poses = model.link_poses(st)
        inv = np.linalg.inv(poses[link])
        for o, pts in local.items():
            T = inv @ poses[o]
            if any(np.allclose(T, U, atol=1e-9) for U in seen[o]):
                continue
            seen[o].append(T)
            out.append(posed(pts, T))
    return np.vstack(out)
