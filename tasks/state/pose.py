"""Resting pose requested by words ("lying flat", "resting sideways"), baked
into the asset as a fixed rotation R of the root: R puts the smallest
closed-state extent along z, moving parts up (a suitcase lying flat has its
lid on top); a named pose the object leans out of as it settles is put down
where it came to rest (:func:`settled_rotation`).
"""

from __future__ import annotations

import numpy as np
from asset2sim.schemas.asset import AssetDescription
from asset2sim.tasks.geometry.closed_state import links_aabb

from asset2sim.frames import axis_rotation, quat_wxyz_matrix, quat_xyzw_to_wxyz


def resting_rotation(session, asset: AssetDescription, state: dict[str, float], hull_points: dict[str, np.ndarray],
                     moving_links: list[str]) -> tuple[np.ndarray, str]:
    """(rotation (3, 3) of the root laying the object on its largest face, moving parts up; note), identity when already so.
    ``session``: fixed-base session of the input asset; ``state``: the closed state (input units); ``hull_points``:
    ``link_hull_points``; ``moving_links``: links the task-relevant joints move."""
    names = [ln.name for ln in asset.links]
    session.set_joint_positions(state)
    box = links_aabb(session, names, hull_points)
    if box is None:
        return np.eye(3), "no geometry: pose unchanged"
    ext = box[1] - box[0]
    up_hint = _up_hint(session, moving_links, hull_points, box)
    k = int(np.argmin(ext))
    if k == 2:
        if up_hint[2] >= 0:
            return np.eye(3), "smallest extent already vertical: pose unchanged"
        return axis_rotation(0, np.pi), "turned upside down so the moving parts face up"
    # rotate about the horizontal axis perpendicular to axis k so that axis k maps to +z or -z
    other = 1 - k  # the remaining horizontal axis (k in {0, 1})
    angle = max((np.pi / 2, -np.pi / 2), key=lambda a: (axis_rotation(other, a) @ up_hint)[2])  # the first on a tie
    return axis_rotation(other, angle), (f"laid on its largest face: rotated {np.degrees(angle):+.0f} deg about the root {'xyz'[other]} "
                                         f"axis (smallest extent {ext[k]:.3g} along {'xyz'[k]} -> z, moving parts up)")


def _up_hint(session, moving_links: list[str], hull_points: dict[str, np.ndarray], box) -> np.ndarray:
    """From the centre of the whole object's box (lo, hi) to the centre of the moving links' box (3,), m; zero without either."""
    mov = links_aabb(session, moving_links, hull_points) if moving_links else None
    if mov is None or box is None:
        return np.zeros(3)
    return 0.5 * (mov[0] + mov[1]) - 0.5 * (box[0] + box[1])


#: The six axis-aligned resting orientations tried by :func:`most_stable_rotation`.
CANDIDATES: tuple[tuple[str, int, float], ...] = (
    ("as modelled", 0, 0.0),
    ("rolled +90 deg about x", 0, np.pi / 2),
    ("rolled -90 deg about x", 0, -np.pi / 2),
    ("pitched +90 deg about y", 1, np.pi / 2),
    ("pitched -90 deg about y", 1, -np.pi / 2),
    ("upside down", 0, np.pi),
)

#: Static margin, as a fraction of the object's largest extent, beyond which an
#: orientation clearly tips (margin < -this) or clearly stands (> +this).
MIN_MARGIN_FRACTION = 0.02

#: Points within this fraction of the largest extent above the lowest point
#: form the support polygon (real bases are slightly uneven: feet, pads).
SUPPORT_BAND_FRACTION = 0.02


def static_margin(session, asset: AssetDescription, links: dict, state: dict[str, float], scale: float,
                  hull_points: dict[str, np.ndarray], rotation: np.ndarray) -> tuple[float, float]:
    """(margin m, largest extent m) of the object resting on a plane: the signed distance of the COM's projection to the
    support polygon's edge (points within :data:`SUPPORT_BAND_FRACTION` of the size above the lowest), positive inside.
    ``links``: name -> LinkPhysics (scaled); ``state`` input units; ``rotation`` (3, 3) of the root."""
    from scipy.spatial import ConvexHull, QhullError

    session.set_joint_positions(state)
    R = np.asarray(rotation, float)
    pts = []
    m_tot = 0.0
    mc = np.zeros(3)
    for ln in asset.links:
        pos, Rl = session.link_frame(ln.name)
        v = hull_points.get(ln.name)
        if v is not None:
            pts.append(((v @ Rl.T + pos) * scale) @ R.T)
        lp = links.get(ln.name)
        if lp is not None:
            c = pos * scale + Rl @ np.asarray(lp.com, float)
            mc += lp.mass * (R @ c)
            m_tot += lp.mass
    if not pts or m_tot <= 0:
        return 0.0, 0.0
    P = np.concatenate(pts)
    size = float(np.max(P.max(axis=0) - P.min(axis=0)))
    base = P[P[:, 2] <= P[:, 2].min() + SUPPORT_BAND_FRACTION * size][:, :2]
    com = mc / m_tot
    try:
        hull = ConvexHull(base)
    except (QhullError, ValueError):
        return -size, size  # a point or a line of support: not statically stable
    return float(np.min(-(hull.equations[:, :2] @ com[:2] + hull.equations[:, 2]))), size


def most_stable_rotation(session, asset: AssetDescription, links: dict, state: dict[str, float], scale: float,
                         hull_points: dict[str, np.ndarray], moving_links: list[str], *,
                         exclude_modelled: bool = False) -> tuple[np.ndarray | None, str]:
    """The axis-aligned resting orientation that clearly stands at ``state`` (margin > :data:`MIN_MARGIN_FRACTION` x size),
    moving parts up first, then the largest margin; ``exclude_modelled`` drops the modelled one. Returns (rotation, note),
    or (None, reason) when none qualifies or the best is the modelled one."""

    up = _up_hint(session, moving_links, hull_points, links_aabb(session, [ln.name for ln in asset.links], hull_points))
    margin0, size = static_margin(session, asset, links, state, scale, hull_points, np.eye(3))
    if size <= 0:
        return None, "no geometry"
    best = None
    for label, axis, angle in CANDIDATES:
        if exclude_modelled and label == "as modelled":
            continue
        R = axis_rotation(axis, angle)
        margin, _ = static_margin(session, asset, links, state, scale, hull_points, R)
        # clearly standing first, then moving parts up, then the widest margin
        key = (margin >= MIN_MARGIN_FRACTION * size, float((R @ up)[2]) > 1e-9, round(margin / size, 3))
        if best is None or key > best[0]:
            best = (key, R, label, margin)
    _, R, label, margin = best
    if label == "as modelled" or margin < MIN_MARGIN_FRACTION * size:
        return None, f"no clearly stabler resting face (modelled margin {margin0 * 1000:.1f} mm, best {label} {margin * 1000:.1f} mm)"
    return R, f"rests {label} (static margin {margin * 1000:.1f} mm; {margin0 * 1000:.1f} mm as modelled)"


#: The lean a settling object may add to a resting pose the request named ("upright", "lying flat", "sideways") and
#: still be in that pose, rad: an object whose modelled base is not flat (a suitcase on wheels and feet of different
#: heights) rocks a few degrees onto its supports as it settles. Twice robust rest's 5-degree tilt (SPEC): a lean a
#: person still calls upright; an object that turns further has fallen toward another face.
SETTLE_LEAN_LIMIT = np.radians(10.0)


def settled_rotation(placed_xyzw, rested_xyzw) -> tuple[np.ndarray, float] | None:
    """(rotation (3, 3) in the world frame from the root as placed to the root where it came to rest, its angle rad),
    from the root's quaternions (4,) xyzw as placed and at the end of the rest test; None when a quaternion is not
    finite or the angle exceeds :data:`SETTLE_LEAN_LIMIT`. Composed on the left of the resting pose's rotation
    (world = R root), it puts the object down where it rests."""
    q0, q1 = np.asarray(placed_xyzw, float), np.asarray(rested_xyzw, float)
    if not (np.all(np.isfinite(q0)) and np.all(np.isfinite(q1))):
        return None
    rel = quat_wxyz_matrix(quat_xyzw_to_wxyz(q1)) @ quat_wxyz_matrix(quat_xyzw_to_wxyz(q0)).T
    angle = float(np.arccos(np.clip((np.trace(rel) - 1.0) / 2.0, -1.0, 1.0)))
    return (rel, angle) if angle <= SETTLE_LEAN_LIMIT else None
