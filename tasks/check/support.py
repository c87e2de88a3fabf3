"""Did the object slide or tip while it was being operated? One measure for
the probes (:mod:`asset2sim.tasks.check.probes`), the gripper task
(:mod:`asset2sim.tasks.check.task_execution`) and the learning environment
(:mod:`asset2sim.tasks.evaluation.learn_env`); definition in
``docs/design/metrics.md`` (probes: "slid").

Sliding is measured where the object stands: the **footprint point**, below
the carrying link's origin at the object's lowest height (the lowest corner
of every link's bounding box) when the watch starts, carried rigidly with
that link; its horizontal displacement is the slide (a tall fridge rocking
0.3 deg moves its root origin 1 cm without sliding; rocking lifts the point,
it does not move it sideways). Tipping is the angle between the world
vertical and the carrying link's up direction (the world vertical at the
start, carried with the link), as robust rest measures toppling: a turn
about the vertical is not tipping (a pair of scissors lying flat turns on
the table as one blade is opened against the other: 0.95 rad of turn, no
tilt and 0.7 mm of slide; counted as "tipped", its probes failed).
"""

from __future__ import annotations

import numpy as np


class SupportWatch:
    """Slide (m) and tip (rad) of the link ``link`` of ``session`` (a
    :class:`~asset2sim.engines.base.SimSession`) since construction: the
    root, or the joint's child when a gripper moves the parent side.

    Attributes:
        slide: largest horizontal footprint displacement seen by :meth:`update`, m.
        tilt: largest tilt of the up direction seen by :meth:`update`, rad.
    """

    def __init__(self, session, link: str) -> None:
        self.session, self.link = session, link
        p0, R0 = session.link_frame(link)
        self.p0, self.R0 = np.asarray(p0, float), np.asarray(R0, float)
        z_low = min(float(session.link_aabb(ln)[0][2]) for ln in session.link_names)
        self.foot0 = np.array([self.p0[0], self.p0[1], z_low])
        self.foot_local = self.R0.T @ (self.foot0 - self.p0)
        self.up_local = self.R0.T @ np.array([0.0, 0.0, 1.0])
        self.slide = self.tilt = 0.0

    def current(self) -> tuple[np.ndarray, float]:
        """(horizontal footprint displacement (2,) m, tilt of the up
        direction from the vertical, rad) now; the tilt is inf when the
        engine reports a non-finite orientation."""
        p, R = self.session.link_frame(self.link)
        R = np.asarray(R, float)
        moved = np.asarray(p, float) + R @ self.foot_local - self.foot0
        c = float((R @ self.up_local)[2])
        t = float(np.arccos(np.clip(c, -1.0, 1.0))) if np.isfinite(c) else float("inf")
        return moved[:2], t

    def update(self) -> tuple[float, float]:
        """Fold the present slide and tip into the running maxima; returns
        (:attr:`slide` m, :attr:`tilt` rad)."""
        xy, t = self.current()
        s = float(np.linalg.norm(xy))
        self.slide = max(self.slide, s) if np.isfinite(s) else float("inf")
        self.tilt = max(self.tilt, t)
        return self.slide, self.tilt


#: Height (m) above the object's lowest collision point within which a link
#: counts as resting on the ground (:func:`rolling_joints`): PyBullet's 1 mm
#: collision margin on each of the two shapes plus 1 mm.
GROUND_CONTACT_GAP = 0.003


def link_world_vertices(session, link: str) -> np.ndarray:
    """Collision vertices (k, 3) of ``link`` in the world, m: the engine's
    collision vertices carried by the link frame, or the 8 corners of its
    AABB where the engine keeps none; (0, 3) for a link without collision
    geometry."""
    if not session.link_has_collision(link):
        return np.zeros((0, 3))
    v = session.link_collision_vertices(link)
    if len(v):
        p, R = session.link_frame(link)
        return np.asarray(v, float) @ np.asarray(R, float).T + np.asarray(p, float)
    lo, hi = session.link_aabb(link)
    return np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])], dtype=float)


def rolling_joints(session, moved: dict[str, list[str]]) -> list[str]:
    """Continuous joints of ``session`` whose moving part rests on the ground
    where the session stands now (a link of the part within
    :data:`GROUND_CONTACT_GAP` of the object's lowest collision point): the
    wheels and casters the object rolls on. Their angle is not a state the
    object holds (a cart nudged or tilted rolls; a wheel turns with the
    ground under it) and a finger does not operate them (the object is
    rolled), so robust rest does not grade their drift and the probes do not
    push them (``docs/design/metrics.md``). Revolute and prismatic parts touching
    the ground (a pedal, a foot, a lid folded down) are not rolling.

    Args:
        moved: movable joint -> the links it moves
            (:func:`asset2sim.tasks.geometry.limits.subtrees`).

    Returns:
        Joint names, in ``moved``'s order.
    """
    low = {ln: float(v[:, 2].min()) if len(v) else np.inf
           for ln, v in ((ln, link_world_vertices(session, ln)) for ln in session.link_names)}
    finite = [z for z in low.values() if np.isfinite(z)]
    if not finite:
        return []
    floor = min(finite) + GROUND_CONTACT_GAP
    return [j for j, links in moved.items()
            if session.joint_types.get(j) == "continuous" and any(low.get(ln, np.inf) <= floor for ln in links)]
