"""What blocks a moving part: the link in its way and the movable joints that
place that link (shared by the joint sweep and the probes).
"""

from __future__ import annotations


from asset2sim.engines.base import EngineUnsupported, SessionOptions, SimSession, Spring
from asset2sim.engines.source import SimSource
from asset2sim.schemas.config import SimConventions
from asset2sim.tasks.geometry import limits
from asset2sim.tasks.geometry.closed_state import tree_path
from asset2sim.urdf import UrdfModel


def fixed_root_options(state: dict[str, float], conventions: SimConventions | None = None,
                       springs: dict[str, Spring] | None = None) -> SessionOptions:
    """Options of a session with the root fixed, gravity off and no ground (the sweep's) at ``state``."""
    return SessionOptions(initial_state=dict(state), springs=dict(springs or {}), fixed_base=True, gravity=False,
                          ground=False, conventions=conventions or SimConventions())


#: Opening fraction under which a part whose drive stalls counts as shut in by another part.
SHUT_IN_FRACTION = limits.MIN_FREE_FRACTION
#: Distance (m) within which a link counts as touching the part where its drive stalled.
BLOCK_DISTANCE = 0.001


def blocking_link(session: SimSession, links: list[str], exclude: set[str]) -> str | None:
    """The link (not in ``links`` nor ``exclude``) nearest to, or deepest into,
    ``links`` now, when within :data:`BLOCK_DISTANCE` m; else None."""
    sub = set(links)
    best, who = BLOCK_DISTANCE, None
    for a in links:
        if not session.link_has_collision(a):
            continue
        for b in session.link_names:
            if b in sub or b in exclude or not session.link_has_collision(b):
                continue
            d = session.link_distances(a, b, BLOCK_DISTANCE)
            if d and min(d) <= best:
                best, who = min(d), b
    return who


def joints_between(model: UrdfModel, a: str, b: str) -> list[str]:
    """Movable joints on the tree path between links ``a`` and ``b``, nearest to ``b`` first."""
    from_a, from_b = tree_path(model.joints, a, b)
    return [j.name for j in from_b + from_a[::-1] if j.type in ("revolute", "prismatic", "continuous")]


class Blocker:
    """:func:`blocking_link` at a state, in the session, or in a PyBullet session
    of the same URDF where its engine answers no closest-point queries."""

    def __init__(self, session: SimSession, source: SimSource, conventions: SimConventions):
        self.session, self.source, self.conventions = session, source, conventions
        self._pybullet: SimSession | None = None

    def __call__(self, state: dict[str, float], links: list[str], exclude: set[str]) -> str | None:
        try:
            self.session.set_joint_positions(state)
            return blocking_link(self.session, links, exclude)
        except EngineUnsupported:
            pass
        if self._pybullet is None:
            self._pybullet = self.source.open("pybullet", fixed_root_options(state, self.conventions))
        self._pybullet.set_joint_positions(state)
        return blocking_link(self._pybullet, links, exclude)

    def close(self) -> None:
        if self._pybullet is not None:
            self._pybullet.close()
            self._pybullet = None
