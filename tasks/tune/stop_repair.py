"""Collision repair where the joint sweep stops inside the range against a hull that bulges (a convex
hull filling a concave part's opening): the deepest pair (moving link, other link) over :data:`SAMPLES`
positions from the stall, deeper than :data:`MIN_DEPTH`, gets its pieces improved by
:func:`asset2sim.tasks.state.collision.improve_collisions` (refine stage 7b; ``docs/design/metrics.md``).
"""

from __future__ import annotations

import itertools
from pathlib import Path

from asset2sim.engines.source import SimObject
from asset2sim.schemas.asset import AssetDescription
from asset2sim.schemas.report import MetricResult
from asset2sim.tasks.check.sweep_stalls import blocked_stops, stall_states
from asset2sim.tasks.geometry import limits
from asset2sim.tasks.state import collision
from asset2sim.tasks.state.collision import CollisionPiece

#: Positions sampled from the stall to the end the drive aimed at.
SAMPLES = 8
#: Penetration (m) under which the stall is not a contact (PyBullet's 1 mm hull margin on each side).
MIN_DEPTH = 0.0021


def decompose_for_blocked(obj: SimObject, asset: AssetDescription, metric: MetricResult, replaced: set[str],
                          scale: float, out_dir: Path, folder: str, *,
                          max_decompositions: int = 32) -> tuple[dict[str, list[CollisionPiece]], list[str]]:
    """(collision overrides link -> pieces, notes) repairing the joints the
    ``joint_sweep`` ``metric`` found stopped short (module docstring). ``obj``:
    the written URDF at its initial state (joint -> rad or m; searched root fixed, gravity-free, no springs), with the
    joints a retry of the sweep moved where it did (:func:`~asset2sim.tasks.check.sweep_stalls.stall_states`);
    ``replaced``: links left alone; pieces under ``out_dir`` / ``folder``.

    Raises:
        DecompositionUnavailable: CoACD is not installed.
        EngineUnavailable: PyBullet is not installed.
    """
    stops, moved = blocked_stops(metric), stall_states(metric)
    if not stops:
        return {}, []
    source, state = obj.source, dict(obj.state)
    model = source.model()
    subtrees = limits.subtrees(model)
    adjacent = {frozenset((j.parent, j.child)) for j in model.joints}
    overrides: dict[str, list[CollisionPiece]] = {}
    notes: list[str] = []
    with source.open("pybullet", obj.options(springs={}, fixed_base=True, gravity=False, ground=False)) as session:
        with_collision = [ln for ln in session.link_names if session.link_has_collision(ln)]
        for name, (stall, goal) in stops.items():
            if name not in session.joint_types:
                continue
            sub = [ln for ln in subtrees.get(name, [session.joint_child[name]]) if ln in with_collision]
            others = [ln for ln in with_collision if ln not in sub]
            # the deepest pair over SAMPLES positions from the stall to the goal
            depth, q, pair = 0.0, stall, None
            for k in range(SAMPLES + 1):
                at = stall + (goal - stall) * k / SAMPLES
                session.set_joint_positions({**state, **moved[name], name: at})
                for a, b in itertools.product(sub, others):
                    d = session.link_distances(a, b, 0.0) if frozenset((a, b)) not in adjacent else None
                    if d and -min(d) > depth:
                        depth, q, pair = -min(d), at, (a, b)
            if pair is None or depth < MIN_DEPTH or set(pair) & (replaced | set(overrides)):
                continue
            session.set_joint_positions({**state, **moved[name], name: q})
            new, dnotes = collision.improve_collisions(session, asset, [pair], scale, out_dir,
                                                       max_decompositions=max_decompositions, folder=folder)
            if new:
                overrides.update(new)
                notes += [f"{n} (sweep of {name} stopped by {pair[1]}: {depth * 1000:.3g} mm at {q:.4g})" for n in dnotes]
        session.set_joint_positions(state)
    return overrides, notes
