"""Parent-child penetration at the initial state, with the pair collided: the
SPEC's Phi skips a link and its parent, so a part starting inside its
parent's hull is invisible to it. :func:`parent_child_penetration` asks the
engine's closest-point query (``SimSession.link_distances``) for every
joint's parent and child and reports the deepest penetration, margins removed.
"""

from __future__ import annotations


from asset2sim import urdf
from asset2sim.engines.base import SessionOptions
from asset2sim.engines.registry import open_session
from asset2sim.schemas.config import SimConventions
from asset2sim.schemas.metrics import unit
from asset2sim.schemas.report import MetricResult
from asset2sim.tasks.assemble.convex_pieces import CONTAINMENT_TOLERANCE

__all__ = ["CONTACT_MARGIN", "parent_child_penetration"]

#: Distance (m) an engine's closest-point query reports for two touching convex pieces
#: (PyBullet: 1 mm hull margin each; ``docs/design/simulators.md``, "Contact margins").
CONTACT_MARGIN: dict[str, float] = {"pybullet": 0.002, "mujoco": 0.0}


def parent_child_penetration(urdf_path: urdf.UrdfSource, initial_state: dict[str, float], engine: str = "pybullet",
                             conventions: SimConventions | None = None,
                             tolerance: float = CONTAINMENT_TOLERANCE) -> MetricResult:
    """Deepest penetration (mm) of a child link's collision shapes into its
    parent's at ``initial_state`` (joint -> rad or m), :data:`CONTACT_MARGIN`
    removed; passes at most ``tolerance`` m. ``details["pairs"]``: "parent/child"
    -> mm. Engines not in :data:`CONTACT_MARGIN` are replaced by PyBullet.

    Raises:
        EngineUnavailable: the engine is not installed; whatever loading the URDF raises.
    """
    engine = engine if engine in CONTACT_MARGIN else "pybullet"
    margin = CONTACT_MARGIN[engine]
    model = urdf.model_of(urdf_path, mode="lenient")
    session = open_session(engine, urdf_path, SessionOptions(initial_state=dict(initial_state), gravity=False, ground=False,
                                                             conventions=conventions or SimConventions()))
    pairs: dict[str, float] = {}
    try:
        for j in model.joints:
            if not (model.links[j.parent].collisions and model.links[j.child].collisions):
                continue
            d = session.link_distances(j.parent, j.child, 0.0)
            depth = max(0.0, -min(d, default=0.0) - margin)
            if depth > 0.0:
                pairs[f"{j.parent}/{j.child}"] = round(depth * 1000.0, 4)
    finally:
        session.close()
    worst = max(pairs.values(), default=0.0)
    return MetricResult(name="parent_child_penetration", value=worst, unit=unit("parent_child_penetration"),
                        passed=worst <= tolerance * 1000.0,
                        threshold=f"<= {tolerance * 1000:g} mm (parent-child pairs collided; the SPEC's Phi skips them)",
                        details={"pairs": pairs, "margin_removed_mm": margin * 1000.0}, engine=engine)
