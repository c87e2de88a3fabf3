"""Did the object slide or tip while it was being operated? One measure (the footprint point's
horizontal displacement, the carrying link's up direction against the vertical) for the probes, the
gripper task and the learning environment (``docs/design/metrics.md``, probes, step 4).
"""

from __future__ import annotations

import numpy as np

from asset2sim.tasks.ingest.mesh_checks import box_corners


class SupportWatch:
    """Slide (m) and tip (rad) of ``link`` of ``session`` since construction;
    ``slide`` and ``tilt`` are the largest seen by :meth:`update`."""

    def __init__(self, session, link: str) -> None:
        self.session, self.link = session, link
        p0, R0 = (np.asarray(x, float) for x in session.link_frame(link))
        z_low = min(float(session.link_aabb(ln)[0][2]) for ln in session.link_names)
        self.foot0 = np.array([p0[0], p0[1], z_low])
        self.foot_local = R0.T @ (self.foot0 - p0)
        self.up_local = R0.T @ np.array([0.0, 0.0, 1.0])
        self.slide = self.tilt = 0.0

    def current(self) -> tuple[np.ndarray, float]:
        """(horizontal footprint displacement (2,) m, tilt rad, inf when non-finite) now."""
        p, R = self.session.link_frame(self.link)
        R = np.asarray(R, float)
        moved = np.asarray(p, float) + R @ self.foot_local - self.foot0
        c = float((R @ self.up_local)[2])
        t = float(np.arccos(np.clip(c, -1.0, 1.0))) if np.isfinite(c) else float("inf")
        return moved[:2], t

    def update(self) -> tuple[float, float]:
        """Fold the present slide and tip into the running maxima; returns (slide, tilt)."""
        xy, t = self.current()
        s = float(np.linalg.norm(xy))
        self.slide = max(self.slide, s) if np.isfinite(s) else float("inf")
        self.tilt = max(self.tilt, t)
        return self.slide, self.tilt


#: Height (m) above the object's lowest collision point within which a link rests on the ground
#: (PyBullet's 1 mm margin on each shape plus 1 mm).
GROUND_CONTACT_GAP = 0.003


def link_world_vertices(session, link: str) -> np.ndarray:
    """Collision vertices (k, 3) of ``link`` in the world, m (its AABB corners
    where the engine keeps none; (0, 3) without collision geometry)."""
    if not session.link_has_collision(link):
        return np.zeros((0, 3))
    v = session.link_collision_vertices(link)
    if len(v):
        p, R = session.link_frame(link)
        return np.asarray(v, float) @ np.asarray(R, float).T + np.asarray(p, float)
    return box_corners(*session.link_aabb(link))


def rolling_joints(session, moved: dict[str, list[str]]) -> list[str]:
    """Continuous joints whose moving part (``moved``: joint -> its links) rests on the
    ground now (within :data:`GROUND_CONTACT_GAP`): the wheels the object rolls on."""
    low = {ln: float(v[:, 2].min()) if len(v) else np.inf
           for ln, v in ((ln, link_world_vertices(session, ln)) for ln in session.link_names)}
    finite = [z for z in low.values() if np.isfinite(z)]
    if not finite:
        return []
    floor = min(finite) + GROUND_CONTACT_GAP
    return [j for j, links in moved.items()
            if session.joint_types.get(j) == "continuous" and any(low.get(ln, np.inf) <= floor for ln in links)]
