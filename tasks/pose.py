"""Resting pose requested by words ("lying flat", "resting sideways").

The URDF has no field for a resting orientation, so it is baked into the
asset: the joints that hang from the root link (and the root's own geometry)
are rotated by a fixed rotation R, which turns the whole object. R puts the
object's smallest closed-state extent along z (the largest face down); of the
two 90-degree rotations that do so, the one that brings the task-relevant
moving parts up (their bounding-box center above the body's) is taken, so a
suitcase lying flat has its lid on top.
"""

from __future__ import annotations

import numpy as np

from asset2sim.schemas.asset import AssetDescription


def _rot(axis: int, angle: float) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    if axis == 0:
        return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])
    if axis == 1:
        return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def resting_rotation(
    session,
    asset: AssetDescription,
    state: dict[str, float],
    hull_points: dict[str, np.ndarray],
    moving_links: list[str],
) -> tuple[np.ndarray, str]:
    """Rotation (3, 3) of the root that lays the object on its largest face,
    moving parts up, and a note. Identity when the smallest extent is already
    vertical (and the moving parts are up).

    Args:
        session: fixed-base PyBullet session of the input asset.
        state: joint positions of the closed state (input units).
        hull_points: :func:`asset2sim.tasks.closed_state.link_hull_points`.
        moving_links: links moved by the task-relevant joints.
    """
    from asset2sim.tasks.closed_state import _aabb

    names = [ln.name for ln in asset.links]
    session.set_joint_positions(state)
    box = _aabb(session, names, hull_points)
    if box is None:
        return np.eye(3), "no geometry: pose unchanged"
    lo, hi = box
    ext = hi - lo
    center = 0.5 * (lo + hi)
    up_hint = np.zeros(3)
    mov = _aabb(session, moving_links, hull_points) if moving_links else None
    if mov is not None:
        up_hint = 0.5 * (mov[0] + mov[1]) - center
    k = int(np.argmin(ext))
    if k == 2:
        if up_hint[2] >= 0:
            return np.eye(3), "smallest extent already vertical: pose unchanged"
        R = _rot(0, np.pi)
        return R, "turned upside down so the moving parts face up"
    # rotate about the horizontal axis perpendicular to axis k so that axis k maps to +z or -z
    other = 1 - k  # the remaining horizontal axis (k in {0, 1})
    best = None
    for angle in (np.pi / 2, -np.pi / 2):
        R = _rot(other, angle)
        z = R @ up_hint
        score = z[2]
        if best is None or score > best[0]:
            best = (score, R, angle)
    _, R, angle = best
    axis_name = "xyz"[other]
    return R, f"laid on its largest face: rotated {np.degrees(angle):+.0f} deg about the root {axis_name} axis (smallest extent {ext[k]:.3g} along {'xyz'[k]} -> z, moving parts up)"
