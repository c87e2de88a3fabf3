"""The geometric *closed* end of every movable joint, in a fixed-base, gravity-free session: the score
(``OWN_WEIGHT``), the ties (``TIE_TOL``, ``PHI_TIE_FRACTION``) and the pick are in
``docs/design/refine.md``, "Closed state"; the refinement and the joints without a geometric closed end
in ``docs/design/core.md``. Opening fraction f(q) = direction * (q - q_closed) / open_range.
"""

from __future__ import annotations

from collections.abc import Collection, Sequence
from dataclasses import dataclass, field

import numpy as np
from asset2sim.schemas.asset import AssetDescription

from asset2sim.engines.loading import BOX_CORNERS
from asset2sim.frames import rpy_matrix
from asset2sim.mesh_io import MeshCache
from asset2sim.urdf import UrdfModel

#: Exponent of the moving subtree's own-box ratio in the closed-state score.
OWN_WEIGHT = 0.25
#: Penetration above the ties' least, as a fraction of the object size, that excludes a tie.
PHI_TIE_FRACTION = 0.05
#: Relative tolerance within which two closed-state scores tie.
TIE_TOL = 0.03
#: Samples over a joint's range (``COARSE``), in the window around the pick (``FINE``); passes over all joints
#: (later passes hold the others closed).
COARSE, FINE, PASSES = 41, 21, 2


@dataclass
class ClosedState:
    """Closed end of one joint (rad or m, in the units of the session's asset)."""

    joint: str
    q_closed: float
    direction: float  # +1 when opening increases q, -1 when it decreases q
    open_range: float  # largest opening the range allows from q_closed (rad or m)
    lower: float
    upper: float
    compactness_ratio: float = 1.0  # max/min compactness over the range (1 = the joint changes nothing)
    notes: list[str] = field(default_factory=list)

    def fraction(self, q: float) -> float:
        """Opening fraction f(q) = direction * (q - q_closed) / open_range."""
        if self.open_range <= 0:
            return 0.0
        return float(self.direction * (q - self.q_closed) / self.open_range)

    def position(self, fraction: float) -> float:
        """Joint position at opening fraction ``fraction``, clipped to the limits."""
        return float(np.clip(self.q_closed + self.direction * fraction * self.open_range, self.lower, self.upper))


def subtree_links(asset: AssetDescription | UrdfModel, link: str) -> list[str]:
    """``link`` and every link below it in the kinematic tree of ``asset`` (depth first, children in joint order)."""
    children: dict[str, list[str]] = {}
    for j in asset.joints:
        children.setdefault(j.parent, []).append(j.child)
    out, stack = [], [link]
    while stack:
        ln = stack.pop()
        out.append(ln)
        stack.extend(children.get(ln, []))
    return out


def tree_path(joints: Sequence, link_a: str, link_b: str) -> tuple[list, list]:
    """The joints (records with ``parent`` and ``child``) on the tree path between two links: (those
    from ``link_a`` up to the nearest common ancestor, nearest first; the same from ``link_b``);
    links in separate trees give each whole chain to its root."""
    parent = {j.child: j for j in joints}

    def chain(link: str) -> list[str]:
        out = [link]
        while link in parent:
            link = parent[link].parent
            out.append(link)
        return out

    ca, cb = chain(link_a), chain(link_b)
    in_b = set(cb)
    common = next((ln for ln in ca if ln in in_b), None)
    path_a = ca[: ca.index(common)] if common is not None else ca
    path_b = cb[: cb.index(common)] if common is not None else cb
    return [parent[ln] for ln in path_a if ln in parent], [parent[ln] for ln in path_b if ln in parent]


def link_hull_points(asset: AssetDescription, cache=None) -> dict[str, np.ndarray]:
    """Convex-hull vertices (N, 3) of every link's collision geometry (else visual), link frame, scale 1:
    exact bounding boxes at any state (Bullet's AABBs of rotated hulls are loose). ``cache``: a
    :class:`asset2sim.mesh_io.MeshCache`."""
    from scipy.spatial import ConvexHull, QhullError

    cache = cache if cache is not None else MeshCache()
    out: dict[str, np.ndarray] = {}
    for ln in asset.links:
        refs = ln.collisions or ln.visuals
        pts = []
        for g in refs:
            if g.kind == "mesh" and g.path is not None:
                try:
                    v = np.asarray(cache.get(g.path).vertices, float)
                except Exception:
                    continue
                v = v[np.all(np.isfinite(v), axis=1)] * np.asarray(g.scale, float)
            elif g.kind == "box" and g.size is not None or g.kind in ("cylinder", "sphere") and g.radius is not None:
                # the box's corners, or those of the cylinder's or sphere's bounding box
                h = np.asarray(g.size, float) / 2 if g.kind == "box" else (g.radius, g.radius, (g.length or 2 * g.radius) / 2)
                v = BOX_CORNERS * h
            else:
                continue
            if len(v) == 0:
                continue
            v = v @ rpy_matrix(g.origin.rpy).T + np.asarray(g.origin.xyz, float)
            if len(v) > 8:
                try:
                    v = v[ConvexHull(v).vertices]
                except (QhullError, ValueError):
                    pass
            pts.append(v)
        if pts:
            out[ln.name] = np.concatenate(pts)
    return out


def links_aabb(session, names: list[str], points: dict[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray] | None:
    """World axis-aligned box (lo (3,), hi (3,)), m, of the links ``names`` at the current state, from
    ``points`` (link -> hull points (k, 3) in the link frame); None when no link has points. Each link's points are
    reduced as a contiguous (3, k) copy: numpy reduces a row ~10x faster than a column of a (k, 3) array."""
    lo = np.full(3, np.inf)
    hi = np.full(3, -np.inf)
    for name in names:
        v = points.get(name)
        if v is None:
            continue
        pos, R = session.link_frame(name)
        w = np.ascontiguousarray((v @ R.T + pos).T)
        lo = np.minimum(lo, w.min(axis=1))
        hi = np.maximum(hi, w.max(axis=1))
    if not np.all(np.isfinite(lo)):
        return None
    return lo, hi


def _aabb_volume(session, names: list[str], points: dict[str, np.ndarray]) -> float:
    box = links_aabb(session, names, points)
    if box is None:
        return 1e-27
    return float(np.prod(np.maximum(box[1] - box[0], 1e-9)))


class _PairScreen:
    """The (subtree link, other link) pairs of one joint whose penetration can be non-zero now: with an
    engine whose ``link_aabb`` encloses the shapes (``traits.conservative_aabb``) pairs with disjoint boxes are dropped (the others keep
    their order, so the sum is the same float)."""

    def __init__(self, session, subset: set[str]):
        self.session = session
        self.sub = [n for n in session.link_names if n in subset and session.link_has_collision(n)]
        self.rest = [n for n in session.link_names if n not in subset and session.link_has_collision(n)]
        self.screen = session.traits.conservative_aabb
        self._rest_boxes: tuple[np.ndarray, np.ndarray] | None = None

    def pairs(self) -> list[tuple[str, str]]:
        """Pairs (sub link, other link) in subtree-major order, m. The other links' boxes are read at the first call:
        only the joint whose subtree this is moves between calls."""
        if not self.screen or not self.sub or not self.rest:
            return [(a, b) for a in self.sub for b in self.rest]
        lo_s, hi_s = (np.array(x) for x in zip(*(self.session.link_aabb(n) for n in self.sub)))
        if self._rest_boxes is None:
            self._rest_boxes = tuple(np.array(x) for x in zip(*(self.session.link_aabb(n) for n in self.rest)))
        lo_r, hi_r = self._rest_boxes
        # (S, R): boxes overlap (touching counts) on every axis
        overlap = np.all((lo_s[:, None, :] <= hi_r[None, :, :]) & (lo_r[None, :, :] <= hi_s[:, None, :]), axis=2)
        return [(self.sub[i], self.rest[k]) for i, k in zip(*np.nonzero(overlap))]


def closed_positions(session, asset: AssetDescription, *, hull_points: dict[str, np.ndarray] | None = None,
                     pushed: Collection[str] = ()) -> dict[str, ClosedState]:
    """Closed end of every movable joint of ``session`` (a fixed-base session of ``asset``).

    Args:
        session: a :class:`asset2sim.engines.base.SimSession` answering ``link_frame`` and ``link_distances``.
        asset: the description of the same URDF (for the kinematic tree).
        hull_points: :func:`link_hull_points` of the asset (computed when None).
        pushed: joints of parts a press moves into their body and a spring returns (push buttons, keys, a pump's
            head: :func:`~asset2sim.tasks.interpret.part_priors.push_buttons`), closed where they rest
            (:func:`_joint_closed_state`).

    Returns joint name -> :class:`ClosedState`; the session is left at the closed state.
    """
    # the reference state: 0 clipped to each joint's limits
    state = {n: float(np.clip(0.0, *session.joint_limits[n])) if np.isfinite(session.joint_limits[n][0]) else 0.0
             for n in session.joint_names}
    result: dict[str, ClosedState] = {}
    points = link_hull_points(asset) if hull_points is None else hull_points
    names = list(session.joint_names)
    # joint -> the other joints' state its result was measured at (a later pass there is skipped)
    measured_at: dict[str, dict[str, float]] = {}
    for _ in range(PASSES):
        for name in names:
            others = {k: v for k, v in state.items() if k != name}
            if name in result and measured_at.get(name) == others:
                state[name] = result[name].q_closed
                continue
            measured_at[name] = others
            jd = asset.joint(name)
            lo, hi = session.joint_limits[name]
            if not (np.isfinite(lo) and np.isfinite(hi)):
                # no stops, so no closed end: keep the modelled pose (0)
                result[name] = ClosedState(joint=name, q_closed=0.0, direction=1.0, open_range=float(np.pi), lower=-np.inf,
                                           upper=np.inf, notes=["continuous joint: no closed end; the modelled pose 0 is used"])
                state[name] = 0.0
                continue
            result[name] = _joint_closed_state(session, asset, jd, state, points, pushed=name in pushed)
            state[name] = result[name].q_closed
    session.set_joint_positions(state)
    return result


def _joint_closed_state(session, asset: AssetDescription, jd, state: dict[str, float], points: dict[str, np.ndarray],
                        pushed: bool) -> ClosedState:
    """The closed end of the bounded joint ``jd``, the others at ``state`` (module docstring). A ``pushed`` part (a push
    button, a key) rests where its spring returns it, standing out of its body, and a press moves it in: where
    compactness changes over its range, its closed end is the end of the range where the box of its parent and its
    subtree is largest (the most compact end is where it is pressed in: a keyboard's keys all pressed down)."""
    name = jd.name
    lo, hi = session.joint_limits[name]
    sub = subtree_links(asset, jd.child)
    union_links = [jd.parent] + sub
    screen = _PairScreen(session, set(sub))
    session.set_joint_positions(state)

    def measure(q: float) -> tuple[float, float, float]:
        session.set_joint_positions({name: q})
        # the penetration (m) between the moving subtree and every other link, parent included
        phi = sum((-d for a, b in screen.pairs() for d in session.link_distances(a, b, 0.0) if d < 0), 0.0)
        return _aabb_volume(session, union_links, points), _aabb_volume(session, sub, points), phi

    qs = np.linspace(lo, hi, COARSE)
    vals = np.array([measure(q) for q in qs])
    c = vals[:, 0]
    ratio = float(c.max() / max(c.min(), 1e-12))
    notes = []
    modelled = _modelled_end(qs, vals, ratio)
    if pushed and ratio >= 1.0 + TIE_TOL:
        q_closed = float(qs[0] if c[0] >= c[-1] else qs[-1])
        notes.append("a part a press moves into its body and a spring returns: closed where it rests, standing out of "
                     "its body (the end of its range where the object's box is largest)")
    elif modelled is not None:
        q_closed = modelled
        notes.append("compactness does not change over the range (a knob, a sash sliding in its frame): "
                     "no geometric closed end; the limit nearest the modelled pose 0 is used")
    else:
        q_open = float(qs[int(np.argmax(c))])
        best = _pick(qs, vals, q_open)
        a = qs[max(best - 1, 0)]
        b = qs[min(best + 1, COARSE - 1)]
        qf = np.linspace(a, b, FINE)
        vf = np.array([measure(q) for q in qf])
        q_closed = float(qf[_pick(qf, vf, q_open)])
        if ratio < 1.0 + TIE_TOL:
            notes.append("compactness does not change over the range; closed end taken at the least-penetrating state")
    up, down = hi - q_closed, q_closed - lo
    direction, rng = (1.0, float(up)) if up >= down else (-1.0, float(down))
    return ClosedState(joint=name, q_closed=q_closed, direction=direction, open_range=max(rng, 0.0),
                       lower=float(lo), upper=float(hi),
                       compactness_ratio=ratio, notes=notes)


def _pick(qv: np.ndarray, vals: np.ndarray, q_open: float) -> int:
    """Index of the closed state among samples ``qv`` with ``vals`` (n, 3) (parent+subtree box, subtree
    box, penetration), ties within :data:`TIE_TOL` (module docstring)."""
    score = (vals[:, 0] / vals[:, 0].min()) * (vals[:, 1] / vals[:, 1].min()) ** OWN_WEIGHT
    phi = vals[:, 2]
    ties = np.flatnonzero(score <= score.min() * (1.0 + TIE_TOL))
    size = float(vals[:, 0].min()) ** (1.0 / 3.0)
    ties = ties[phi[ties] <= phi[ties].min() + PHI_TIE_FRACTION * size]
    # rest against the parent: the tie farthest from the open end
    return int(ties[np.argmax(np.abs(qv[ties] - q_open))])


def _modelled_end(qs: np.ndarray, vals: np.ndarray, ratio: float) -> float | None:
    """The limit nearest the modelled pose 0 when ``ratio`` (largest / smallest parent+subtree box) is
    below 1 + :data:`TIE_TOL` and the part does not penetrate there by ``PHI_TIE_FRACTION`` of the object's
    size beyond the least; else None. ``vals`` as for :func:`_pick`."""
    if not ratio < 1.0 + TIE_TOL:
        return None
    i = 0 if abs(qs[0]) <= abs(qs[-1]) else len(qs) - 1
    size = float(vals[:, 0].min()) ** (1.0 / 3.0)
    if vals[i, 2] > vals[:, 2].min() + PHI_TIE_FRACTION * size:
        return None
    return float(qs[i])


def object_hull_volume(session, state: dict[str, float], asset: AssetDescription, hull_points: dict[str, np.ndarray]) -> float:
    """Volume (the asset's units cubed) of the convex hull of every link (``hull_points``: :func:`link_hull_points`) at
    ``state``: the closed object's outer volume, what a container's volume ("a 500 ml bottle") is compared with; 0
    without geometry.
    Source: Qhull (Barber, Dobkin, Huhdanpaa 1996) through ``scipy.spatial.ConvexHull``."""
    from scipy.spatial import ConvexHull, QhullError  # scipy is heavy to import; only a volume request needs it

    session.set_joint_positions(state)
    world = []
    for ln in asset.links:
        v = hull_points.get(ln.name)
        if v is None or not len(v):
            continue
        pos, R = session.link_frame(ln.name)
        world.append(np.asarray(v, float) @ R.T + pos)
    if not world:
        return 0.0
    try:
        return float(ConvexHull(np.concatenate(world)).volume)
    except (QhullError, ValueError):  # flat or too few points: no volume
        return 0.0


def object_extents(session, state: dict[str, float], asset: AssetDescription, hull_points: dict[str, np.ndarray] | None = None) -> np.ndarray:
    """Extents (3,) of the root-frame box bounding every link at ``state`` (the asset's units)."""
    points = link_hull_points(asset) if hull_points is None else hull_points
    session.set_joint_positions(state)
    box = links_aabb(session, [ln.name for ln in asset.links], points)
    if box is None:
        return np.zeros(3)
    return np.maximum(box[1] - box[0], 0.0)


def closed_tuples(closed: dict) -> dict[str, tuple[float, float, float]]:
    """joint -> (q_closed, direction, open_range), rad or m, of closed-end objects with those attributes."""
    return {n: (float(c.q_closed), float(c.direction), float(c.open_range)) for n, c in closed.items()}
