"""Self-penetration of a fixed-base session, recomputed only where the state changed.

The state search (:mod:`asset2sim.tasks.state.refine_state`) asks for the
SPEC's self-penetration score Phi(q) (m) thousands of times, and most
candidates change one joint. Phi is a sum over the link pairs of the
self-collision filter (links with collision geometry, parent-child pairs
excluded: ``URDF_USE_SELF_COLLISION_EXCLUDE_PARENT``) of the penetration of
each pair's closest points. A link's pose depends only on the positions of
the joints above it, so a pair whose two links have the same ancestor joint
positions as at its last query sits exactly where it sat (the engine's
forward kinematics is recomputed from the joint positions), and its points
are reused. Pairs whose engine boxes are disjoint (engines of
:data:`asset2sim.tasks.geometry.closed_state.CONSERVATIVE_AABB_ENGINES`, whose
boxes include the collision margin) have no penetrating point and are not
queried. The result is the same float, and the same pairs in the same order,
as :meth:`asset2sim.engines.pybullet_engine.PyBulletSession.self_penetration_fresh`;
the number of distance queries per candidate falls from all pairs (N^2 / 2 for
N links) to the pairs that moved and whose boxes touch.
"""

from __future__ import annotations

import numpy as np

from asset2sim.engines.base import ContactPair, penetration_sum
from asset2sim.schemas.asset import AssetDescription
from asset2sim.tasks.geometry.closed_state import CONSERVATIVE_AABB_ENGINES


class StatePenetration:
    """Phi (m) and per-pair penetration of ``session`` at a given joint state.

    Args:
        session: a fixed-base session (PyBullet in the pipeline) answering
            ``link_names``, ``link_has_collision``, ``link_distances`` and
            ``link_aabb``.
        asset: the description of the session's URDF (kinematic tree; the
            link names are the session's).
        joints: the joints whose positions the caller sets (every other
            joint must keep its position while this object is used).
    """

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
        pairs = [
            (i, k)
            for i, a in enumerate(shaped)
            for k, b in enumerate(shaped)
            if i < k and parent_of.get(b) != a and parent_of.get(a) != b
        ]
        self.pairs: list[tuple[str, str]] = [(shaped[i], shaped[k]) for i, k in pairs]
        self._ia = np.array([i for i, _ in pairs], int)
        self._ib = np.array([k for _, k in pairs], int)
        # stale[j, p]: pair p must be queried again when joint j moved
        self._stale = moves[:, self._ia] | moves[:, self._ib] if pairs else np.zeros((len(self.joints), 0), bool)
        self._points: list[list[float]] = [[] for _ in pairs]
        self._penetrating: set[int] = set()
        self._last: np.ndarray | None = None
        self._screen = getattr(session, "engine", None) in CONSERVATIVE_AABB_ENGINES

    def __call__(self, q: dict[str, float]) -> tuple[float, list[ContactPair]]:
        """Phi (m) and the penetrating pairs, deepest first, at the session's
        current state, which must be ``q`` (joint -> rad or m, every joint
        given at construction) on top of the unchanged others."""
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
                lo = np.zeros((len(self.links), 3))
                hi = np.zeros((len(self.links), 3))
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


