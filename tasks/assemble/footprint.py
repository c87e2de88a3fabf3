"""A free-standing object's footprint made planar, so it stands on every foot
(:func:`level_footprint`): a bottom whose corners differ by a fraction of a
millimetre stands on three of them and creeps in PyBullet; an appliance on
levelling feet is set level by them, a few millimetres."""

from __future__ import annotations

import numpy as np
from scipy.spatial import QhullError

from asset2sim import urdf
from asset2sim.tasks.assemble.convex_pieces import Piece, posed
from asset2sim.tasks.geometry import limits

#: Height (m) above the lowest collision point within which the body's
#: vertices are taken to stand on the ground (PyBullet's contact margin of one shape) ...
LEVEL_TOLERANCE = 1e-3
#: ... at most this fraction of the object's largest horizontal extent.
LEVEL_FRACTION = 0.005
#: The words of :func:`level_footprint`'s notes (the report picks them out).
LEVEL_NOTE = "footprint levelled"


def level_footprint(model: urdf.UrdfModel, pieces: dict[str, list[Piece]], state: dict[str, float],
                    notes: list[str], feet: float | None = None) -> None:
    """Make the footprint of a free-standing object's body planar, in place:
    at ``state`` (joint -> rad or m; z up), every collision vertex of the
    links no movable joint moves lower than the object's lowest collision
    point plus ``min(LEVEL_TOLERANCE, LEVEL_FRACTION * largest horizontal
    extent)`` is moved straight down onto that point's plane (pieces only
    grow, downward). ``feet`` (m): the height the category's adjustable levelling feet take up
    (``categories.yaml`` ``levelling_feet_m``: an appliance is set level on them when it is put in place), used as
    that height instead where it is larger; a piece within it whole (a foot) has its bottom face set down, its height
    kept. A refrigerator whose modelled bottom differs by 4.4 mm from corner to corner then stands level on every
    corner, not rocked 0.33 degrees onto three, where its doors, asked to swing freely, turned open on the tilted
    hinges. Body geometry that close to the floor (a plinth 10 mm up) is set down with it. A note names each link
    changed and the largest move."""
    poses = model.link_poses(state)
    body = limits.rigid_group(model, model.root)  # the links no movable joint moves
    world = {ln: [posed(p.points, poses[ln]) for p in pl] for ln, pl in pieces.items() if pl}
    if not world:
        return
    allpts = np.vstack([w for ws in world.values() for w in ws])
    zmin = float(allpts[:, 2].min())
    base = min(LEVEL_TOLERANCE, LEVEL_FRACTION * float(np.max(allpts[:, :2].max(axis=0) - allpts[:, :2].min(axis=0))))
    tol = max(base, feet or 0.0)
    for ln, ws in world.items():
        if ln not in body:
            continue
        R, t = poses[ln][:3, :3], poses[ln][:3, 3]
        lift, count = 0.0, 0
        for i, w in enumerate(ws):
            sel = w[:, 2] < zmin + tol
            low = w[sel, 2] - zmin
            if not np.any(low > 1e-9):
                continue
            w2 = w.copy()
            if tol > base and np.all(sel):  # a piece the feet's reach holds whole (a foot): its bottom set down, its height kept
                zp = float(w[:, 2].min())
                if zp - zmin <= 1e-9:
                    continue
                w2[w[:, 2] < zp + base, 2] = zmin
                low = np.array([zp - zmin])
            else:
                w2[sel, 2] = zmin
            try:
                pieces[ln][i] = Piece.of((w2 - t) @ R, pieces[ln][i].sources)
            except (QhullError, ValueError):
                continue
            lift, count = max(lift, float(low.max())), count + 1
        if count:
            notes.append(f"link {ln!r}: {LEVEL_NOTE}: {count} collision piece(s), vertices up to {lift * 1000:.2g} mm "
                         f"above the lowest point moved down onto it (free-standing: stands on every foot"
                         f"{', its levelling feet set' if feet and lift > LEVEL_TOLERANCE else ''})")
