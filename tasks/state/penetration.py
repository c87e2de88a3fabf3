"""Self-penetration of a fixed-base session, re-queried only for link pairs that
moved and whose engine boxes touch; equal to the engine's fresh query
(:meth:`asset2sim.engines.pybullet_engine.PyBulletSession.self_penetration_fresh`).
"""

from __future__ import annotations

import numpy as np

from asset2sim.engines.base import ContactPair, penetration_sum
from asset2sim.schemas.asset import AssetDescription


class StatePenetration:
    """Phi (m) and per-pair penetration of the fixed-base ``session`` (of ``asset``'s
    URDF) at a joint state; ``joints``: those the caller sets (the others must not move)."""

    def __init__(self, session, asset: AssetDescription, joints: list[str]):
        self.session = session
        parent_of = {j.child: j.parent for j in asset.joints}
        joint_of = {j.child: j.name for j in asset.joints}
        self.joints = list(joints)
        col = {n: k for k, n in enumerate(self.joints)}
        shaped = [n for n in session.link_names if session.link_has_collision(n)]
        self.links = shaped
        row = {n: k for k, n in enumerate(shaped)}
        # moves[j, l]: link l moves when joint j moves (j is above it)
        moves = np.zeros((len(self.joints), len(shaped)), bool)
        for n in shaped:
            link = n
            while link in parent_of:
                if joint_of[link] in col:
                    moves[col[joint_of[link]], row[n]] = True
                link = parent_of[link]
        pairs = [(i, k) for i, a in enumerate(shaped) for k, b in enumerate(shaped)
                 if i < k and parent_of.get(b) != a and parent_of.get(a) != b]
        self.pairs: list[tuple[str, str]] = [(shaped[i], shaped[k]) for i, k in pairs]
        self._ia = np.array([i for i, _ in pairs], int)
        self._ib = np.array([k for _, k in pairs], int)
        # stale[j, p]: pair p must be queried again when joint j moved
        self._stale = moves[:, self._ia] | moves[:, self._ib] if pairs else np.zeros((len(self.joints), 0), bool)
        self._points: list[list[float]] = [[] for _ in pairs]
        self._penetrating: set[int] = set()
        self._last: np.ndarray | None = None
        self._screen = session.traits.conservative_aabb

    def __call__(self, q: dict[str, float]) -> tuple[float, list[ContactPair]]:
        """Phi (m) and the penetrating pairs, deepest first, at the session's current state, which must be ``q``."""
        now = np.array([q[j] for j in self.joints], float)
        if self._last is None:
            stale = np.arange(len(self.pairs))
        else:
            moved = np.flatnonzero(now != self._last)
            stale = np.flatnonzero(self._stale[moved].any(axis=0)) if len(moved) else np.zeros(0, int)
        self._last = now
        if len(stale):
            if self._screen:
                used = np.union1d(self._ia[stale], self._ib[stale])
                lo, hi = np.zeros((2, len(self.links), 3))
                for i in used:
                    lo[i], hi[i] = self.session.link_aabb(self.links[i])
                a, b = self._ia[stale], self._ib[stale]
                touch = np.all((lo[a] <= hi[b]) & (lo[b] <= hi[a]), axis=1)
            else:
                touch = np.ones(len(stale), bool)
            for p, t in zip(stale.tolist(), touch.tolist()):
                d = self.session.link_distances(*self.pairs[p], 0.0) if t else []
                self._points[p] = d
                if any(x < 0.0 for x in d):
                    self._penetrating.add(p)
                else:
                    self._penetrating.discard(p)
        # pairs without a penetrating point add nothing: the sum runs in pair order
        return penetration_sum((*self.pairs[p], d) for p in sorted(self._penetrating) for d in self._points[p])


