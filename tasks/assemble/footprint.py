"""A free-standing object's footprint made planar, so it stands on every foot
(:func:`level_footprint`): a bottom whose corners differ by a fraction of a
millimetre stands on three of them, and PyBullet keeps it creeping on a
diagonal for seconds (laptop 9912 after a 5 deg tilt: robust rest failed).
Real objects stand on feet made coplanar."""

from __future__ import annotations

import numpy as np
from scipy.spatial import QhullError

from asset2sim import urdf
from asset2sim.tasks.assemble.convex_pieces import Piece
from asset2sim.tasks.geometry import limits

#: Height (m) above the lowest collision point within which the body's
#: vertices are taken to stand on the ground: PartNet-Mobility's bottoms are
#: modelled to about this (laptop 9912's corners span 0.49 mm), PyBullet's
#: contact margin of one shape.
LEVEL_TOLERANCE = 1e-3

#: ... at most this fraction of the object's largest horizontal extent (a
#: 5 cm object gets 0.25 mm).
LEVEL_FRACTION = 0.005

#: The words of :func:`level_footprint`'s notes (the report picks them out).
LEVEL_NOTE = "footprint levelled"


def level_footprint(model: urdf.UrdfModel, pieces: dict[str, list[Piece]], state: dict[str, float],
                    notes: list[str]) -> None:
    """Make the footprint of a free-standing object's body planar, in place:
    at ``state`` (joint -> rad or m; the root frame upright as written, z
    up), every collision vertex of the body (the links no movable joint
    moves) lower than the lowest collision point of the object plus
    ``min(LEVEL_TOLERANCE, LEVEL_FRACTION * largest horizontal extent)`` is
    moved straight down onto the plane of that lowest point (each piece is
    the hull of its moved vertices: it only grows, downward). Moving links
    (a lid resting on the floor, wheels) are left as they are. A note names
    each link changed and the largest move.
    """
    poses = model.link_poses(state)
    body = limits.rigid_group(model, model.root)  # the links no movable joint moves
    world = {ln: [p.points @ poses[ln][:3, :3].T + poses[ln][:3, 3] for p in pl] for ln, pl in pieces.items() if pl}
    if not world:
        return
    allpts = np.vstack([w for ws in world.values() for w in ws])
    zmin = float(allpts[:, 2].min())
    extent = float(np.max(allpts[:, :2].max(axis=0) - allpts[:, :2].min(axis=0)))
    tol = min(LEVEL_TOLERANCE, LEVEL_FRACTION * extent)
    for ln, ws in world.items():
        if ln not in body:
            continue
        R, t = poses[ln][:3, :3], poses[ln][:3, 3]
        lift = 0.0
        count = 0
        for i, w in enumerate(ws):
            sel = w[:, 2] < zmin + tol
            low = w[sel, 2] - zmin
            if not np.any(low > 1e-9):
                continue
            w2 = w.copy()
            w2[sel, 2] = zmin
            try:
                pieces[ln][i] = Piece.of((w2 - t) @ R, pieces[ln][i].sources)
            except (QhullError, ValueError):
                continue
            lift, count = max(lift, float(low.max())), count + 1
        if count:
            notes.append(f"link {ln!r}: {LEVEL_NOTE}: {count} collision piece(s), vertices up to {lift * 1000:.2g} mm "
                         f"above the lowest point moved down onto it (free-standing: stands on every foot)")
