"""Parent-child penetration at the initial state, with the pair collided: the
self-contact Phi skips a link and its parent, so a part starting inside its
parent's hull is invisible to it. :func:`parent_child_penetration` asks the
engine's closest-point query (``SimSession.link_distances``) for every
joint's parent and child and reports the deepest penetration, margins removed,
and how much deeper than at the modelled pose (every joint at 0 clipped to its
limits) each pair is: an axle modelled inside its body is as the asset says,
a door opened through a bar of its own body is not. The metric passes by the
rule the readiness verdict reads (:data:`~asset2sim.tasks.check.verdict.UNRESOLVED_PENETRATION_MM`
beyond the modelled pose), so refine, evaluate and audit grade a pair alike.
"""

from __future__ import annotations


from asset2sim.engines.base import SessionOptions
from asset2sim.engines.source import SimSource
from asset2sim.schemas.config import SimConventions
from asset2sim.schemas.metrics import unit
from asset2sim.schemas.report import MetricResult
from asset2sim.tasks.assemble.joint_sweep import reference_state
from asset2sim.tasks.check.verdict import UNRESOLVED_PENETRATION_MM

__all__ = ["CONTACT_MARGIN", "parent_child_penetration"]

#: Distance (m) an engine's closest-point query reports for two touching convex pieces
#: (PyBullet: 1 mm hull margin each; ``docs/design/simulators.md``, "Contact margins").
CONTACT_MARGIN: dict[str, float] = {"pybullet": 0.002, "mujoco": 0.0}


def parent_child_penetration(source: SimSource, initial_state: dict[str, float], engine: str = "pybullet",
                             conventions: SimConventions | None = None) -> MetricResult:
    """Deepest penetration (mm) of a child link's collision shapes into its
    parent's at ``initial_state`` (joint -> rad or m), :data:`CONTACT_MARGIN`
    removed. ``details["pairs"]``: "parent/child" -> mm; ``details["modelled"]``: the same with every joint
    at :func:`~asset2sim.tasks.assemble.joint_sweep.reference_state`; ``details["beyond_modelled_mm"]``: the most a
    pair is deeper than there. Passes when no pair is more than :data:`UNRESOLVED_PENETRATION_MM` deeper than as modelled (a part drawn
    inside its parent, as robosuite draws a door's latch, is as the asset says: no simulator collides the pair), the
    rule :func:`~asset2sim.tasks.check.verdict.readiness` reads. Engines not in :data:`CONTACT_MARGIN` are replaced by
    PyBullet.

    Raises:
        EngineUnavailable: the engine is not installed; whatever loading the URDF raises.
    """
    engine = engine if engine in CONTACT_MARGIN else "pybullet"
    margin = CONTACT_MARGIN[engine]
    model = source.model(mode="lenient")
    session = source.open(engine, SessionOptions(initial_state=dict(initial_state), gravity=False, ground=False,
                                                 conventions=conventions or SimConventions()))
    joints = [j for j in model.joints if model.links[j.parent].collisions and model.links[j.child].collisions]

    def depths() -> dict[str, float]:
        out = {}
        for j in joints:
            depth = max(0.0, -min(session.link_distances(j.parent, j.child, 0.0), default=0.0) - margin)
            if depth > 0.0:
                out[f"{j.parent}/{j.child}"] = round(depth * 1000.0, 4)
        return out

    try:
        pairs = depths()
        modelled = {}
        if pairs:
            session.set_joint_positions(reference_state(model))
            modelled = depths()
    finally:
        session.close()
    worst = max(pairs.values(), default=0.0)
    beyond = round(max([0.0, *(d - modelled.get(k, 0.0) for k, d in pairs.items())]), 4)
    return MetricResult(name="parent_child_penetration", value=worst, unit=unit("parent_child_penetration"),
                        passed=beyond <= UNRESOLVED_PENETRATION_MM,
                        threshold=f"a child at most {UNRESOLVED_PENETRATION_MM:g} mm deeper inside its parent than as modelled "
                                  "(the pair collided; the self-contact penetration leaves it out)",
                        details={"pairs": pairs, "beyond_modelled_mm": beyond, "modelled": modelled,
                                 "margin_removed_mm": margin * 1000.0}, engine=engine)
