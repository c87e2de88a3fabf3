"""Static balance of a written asset on the ground: support polygon, centre of
mass (COM) against it, the margin required, the steadiest opening in the bands.

An object rests iff the COM's vertical projection lies inside the support
polygon (Featherstone & Orin, Springer Handbook of Robotics 2008, sec. 2.9;
the static zero-moment-point condition, Vukobratovic & Borovac, IJHR 2004).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from scipy.spatial import ConvexHull, QhullError

from asset2sim.engines.base import SessionOptions
from asset2sim.engines.source import SimSource
from asset2sim.engines.loading import collision_pieces, transform_points
from asset2sim.schemas.overlay import Overlay

if TYPE_CHECKING:
    from asset2sim.tasks.geometry.closed_state import ClosedState

__all__ = ["BAND_SAMPLES", "MARGIN_GAIN", "SUPPORT_MARGIN_FRACTION", "TILT_RECOVERY_RAD", "Balance", "measure_balance",
           "steadiest_fractions", "support_polygon"]


#: Tilt (rad) the object must recover from: the COM lies at least
#: h * tan(TILT_RECOVERY_RAD) inside the support's edge (h: COM height; the
#: static tipping angle is atan(margin / h)). Twice the robust-rest trials' 5 deg.
TILT_RECOVERY_RAD = math.radians(10.0)


#: Margin (fraction of the support polygon's square-root area) the COM must
#: keep inside its edge whatever its height (docs/design/metrics.md).
SUPPORT_MARGIN_FRACTION = 0.10


@dataclass
class Balance:
    """Static balance at one state (the written URDF's frame, z up): ``com`` (3,) m;
    ``support`` (K, 2) m, counter-clockwise; ``margin`` m, signed distance of the
    COM's projection to the polygon's edge (positive inside); ``required`` m."""

    com: np.ndarray
    support: np.ndarray
    margin: float
    required: float

    @property
    def stable(self) -> bool:
        return self.margin >= self.required


def _hull2d(points: np.ndarray) -> np.ndarray:
    """Convex hull (K, 2) counter-clockwise of points (N, 2) rounded to 1 nm, from the lowest x (then y); the two
    extreme points of collinear ones (Qhull: Barber, Dobkin & Huhdanpaa, ACM TOMS 1996)."""
    pts = np.unique(np.round(np.asarray(points, float), 9), axis=0)  # sorted by x, then y
    if len(pts) < 3:
        return pts
    try:
        vertices = ConvexHull(pts).vertices  # counter-clockwise in 2-D
    except QhullError:
        return pts[[0, -1]]
    return pts[np.roll(vertices, -int(np.argmin(vertices)))]


def _signed_margin(poly: np.ndarray, p: np.ndarray) -> float:
    """Signed distance (m) of ``p`` (2,) to the edge of the CCW convex polygon
    ``poly`` (K, 2), positive inside; K < 3: minus the distance to its points."""
    if len(poly) < 3:
        return -float(np.min(np.linalg.norm(poly - p, axis=1))) if len(poly) else -np.inf
    edges = np.roll(poly, -1, axis=0) - poly
    inward = np.c_[-edges[:, 1], edges[:, 0]] / np.maximum(np.linalg.norm(edges, axis=1), 1e-12)[:, None]
    return float(np.min(((p - poly) * inward).sum(axis=1)))


#: Largest angle (rad) between a bottom hull face and the ground for the object
#: to settle onto it (``tasks.check.metrics.SETTLE_TILT_LIMIT``).
SETTLE_FACE_ANGLE = 0.05


def support_polygon(points: np.ndarray, tol: float, com: np.ndarray | None = None) -> np.ndarray:
    """Support polygon (K, 2) m of collision points (N, 3) on the ground: the 2-D hull of the points within ``tol`` m of the
    hull face the vertical through ``com`` (3,) exits by, when within :data:`SETTLE_FACE_ANGLE` of straight down; else of
    the largest such face; else of the points within ``tol`` of the lowest. (0, 2) without points."""
    pts = np.asarray(points, float)
    if not len(pts):
        return np.zeros((0, 2))
    try:
        hull = ConvexHull(pts)
    except (QhullError, ValueError):
        hull = None
    if hull is not None:
        eq = hull.equations  # (F, 4): outward unit normal n, offset d; n.x + d <= 0 inside
        flat = eq[:, 2] < -np.cos(SETTLE_FACE_ANGLE)
        plane = None
        if com is not None:
            c = np.asarray(com, float)
            down = eq[:, 2] < -1e-9
            inside = np.all(eq[:, :3] @ c + eq[:, 3] <= 1e-9)
            if inside and down.any():
                t = np.where(down, (eq[:, :3] @ c + eq[:, 3]) / np.where(down, eq[:, 2], -1.0), np.inf)
                exit_face = int(np.argmin(t))
                if flat[exit_face]:
                    plane = eq[exit_face]
        if plane is None and flat.any():
            tri = pts[hull.simplices[flat]]
            area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
            keys = np.round(eq[flat] / np.array([1e-3, 1e-3, 1e-3, 1e-4]))
            _, inv = np.unique(keys, axis=0, return_inverse=True)
            best = int(np.argmax(np.bincount(inv.ravel(), weights=area)))
            plane = eq[flat][inv.ravel() == best][0]
        if plane is not None:
            on = np.abs(pts @ plane[:3] + plane[3]) <= tol
            if on.sum() >= 3:
                return _hull2d(pts[on][:, :2])
    # the points within tol of the lowest
    return _hull2d(pts[pts[:, 2] <= pts[:, 2].min() + tol][:, :2])


def _link_world(source: SimSource, state: dict[str, float]) -> tuple[dict, dict[str, np.ndarray]]:
    """Link frames (position (3,), rotation (3, 3)) and world collision hull points (N, 3) per link at ``state``."""
    pieces, _ = collision_pieces(source.model())
    with source.open("pybullet", SessionOptions(initial_state=dict(state), fixed_base=True, gravity=False, ground=False)) as s:
        return _world_at(s, pieces, state)


def _world_at(session, pieces: dict, state: dict[str, float]) -> tuple[dict, dict[str, np.ndarray]]:
    """:func:`_link_world` in an open fixed-base ``session``, ``pieces``: link -> collision pieces."""
    session.set_joint_positions(dict(state))
    frames = {ln: session.link_frame(ln) for ln in session.link_names}
    pts: dict[str, np.ndarray] = {}
    for ln, pcs in pieces.items():
        if ln not in frames:
            continue
        pos, R = frames[ln]
        arr = [transform_points(pc.origin, pc.points) @ R.T + pos for pc in pcs if pc.points is not None]
        if arr:
            pts[ln] = np.vstack(arr)
    return frames, pts


def _com(overlay: Overlay, frames: dict, masses: dict[str, float] | None = None) -> np.ndarray:
    m_tot, acc = 0.0, np.zeros(3)
    for ln, lp in overlay.links.items():
        if ln not in frames:
            continue
        m = lp.mass if masses is None else masses[ln]
        pos, R = frames[ln]
        acc += m * (pos + R @ np.asarray(lp.com, float))
        m_tot += m
    return acc / max(m_tot, 1e-12)


def measure_balance(source: SimSource, overlay: Overlay, state: dict[str, float]) -> Balance:
    """Static balance of the written asset ``source`` (scale baked in) at ``state`` (rad or m) with the overlay's masses and
    COMs. Contact band: max(1 mm, 0.5 % of the height); required margin: max(2 mm, :data:`SUPPORT_MARGIN_FRACTION` x
    sqrt(support area), h tan(:data:`TILT_RECOVERY_RAD`)), h the COM height. Raises whatever loading the URDF raises."""
    return _balance(overlay, *_link_world(source, state))


def _balance(overlay: Overlay, frames: dict, pts: dict[str, np.ndarray]) -> Balance:
    """:func:`measure_balance` from one state's link frames and world collision points."""
    allp = np.vstack(list(pts.values())) if pts else np.zeros((0, 3))
    com = _com(overlay, frames)
    if not len(allp):
        return Balance(com, np.zeros((0, 2)), -np.inf, 0.0)
    # 0.5 % of the height
    poly = support_polygon(allp, max(1e-3, 0.005 * float(allp[:, 2].max() - allp[:, 2].min())), com)
    h = max(float(com[2] - allp[:, 2].min()), 0.0)
    area = 0.5 * abs(float(np.dot(poly[:, 0], np.roll(poly[:, 1], -1)) - np.dot(poly[:, 1], np.roll(poly[:, 0], -1)))) if len(poly) >= 3 else 0.0
    return Balance(com, poly, _signed_margin(poly, com[:2]), max(2e-3, SUPPORT_MARGIN_FRACTION * np.sqrt(area), h * np.tan(TILT_RECOVERY_RAD)))


#: Opening fractions tried per joint by :func:`steadiest_fractions` (ends included).
BAND_SAMPLES = 9
#: Least gain of static margin (m) for which :func:`steadiest_fractions` moves a joint.
MARGIN_GAIN = 2e-3


@dataclass(frozen=True, slots=True)
class SteadiestOpening:
    """What :func:`steadiest_fractions` found: ``fractions`` (joint -> opening fraction it moved to; empty when
    nothing gains), the :class:`Balance` ``before`` and ``after`` (the same when nothing moved)."""

    fractions: dict[str, float]
    before: Balance
    after: Balance


def steadiest_fractions(source: SimSource, overlay: Overlay, state: dict[str, float], closed: dict[str, "ClosedState"],
                        intervals: dict[str, tuple[float, float]]) -> SteadiestOpening:
    """The opening fractions within the requested bands at which a free-standing
    object stands steadiest: for each opened joint of ``intervals`` (joint ->
    allowed fraction interval (lo, hi), lo > 0), :data:`BAND_SAMPLES` fractions over it,
    the others as found so far, keeping the largest static margin when it gains
    at least :data:`MARGIN_GAIN`; fractions that lower the object's bottom by
    more than 1 mm are skipped.

    ``source``: the written URDF of ``overlay``; ``state``: joint -> rad or m;
    ``closed``: joint -> ``ClosedState`` in the URDF's units. No fraction moved
    and the same balance before and after for a mounted asset or when nothing gains.
    """
    pieces, _ = collision_pieces(source.model())
    cur = dict(state)
    with source.open("pybullet", SessionOptions(initial_state=dict(state), fixed_base=True, gravity=False, ground=False)) as s:
        frames, pts = _world_at(s, pieces, cur)
        before = best = _balance(overlay, frames, pts)
        if overlay.mounting is not None and overlay.mounting.fixed:
            return SteadiestOpening({}, before, before)
        floor = min(float(p[:, 2].min()) for p in pts.values()) if pts else 0.0
        chosen: dict[str, float] = {}
        for name, (lo, hi) in intervals.items():
            cs = closed.get(name)
            if cs is None or name not in cur or not lo > 0 or hi <= lo:
                continue
            top, at = None, None
            for f in np.linspace(lo, hi, BAND_SAMPLES):
                frames, pts = _world_at(s, pieces, {**cur, name: cs.position(float(f))})
                if pts and min(float(p[:, 2].min()) for p in pts.values()) < floor - 1e-3:
                    continue
                b = _balance(overlay, frames, pts)
                if top is None or b.margin > top.margin:
                    top, at = b, float(f)
            if top is not None and top.margin >= best.margin + MARGIN_GAIN:
                best, chosen[name] = top, at
                cur = {**cur, name: cs.position(at)}
    return SteadiestOpening(chosen, before, best)
