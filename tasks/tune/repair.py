"""Which collision repairs refine's stage 7b tries, in order (``tasks/refine.py``
keeps one only when the check improves). Two triggers:

- **sweep blocked** (:func:`sweep_repairs`): limits clipped against the
  carrying chain, then running clearance (:mod:`asset2sim.tasks.state.clearance`),
  then convex decomposition (:mod:`asset2sim.tasks.tune.stop_repair`);
- **parts held together** (:func:`held_together_pairs`, :func:`clearance_repair`):
  a tier of :data:`HELD_TOGETHER_TIERS` fails while link pairs are in contact at the state.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterator

from asset2sim.engines.source import SimObject
from asset2sim.schemas.asset import AssetDescription
from asset2sim.schemas.config import RefineConfig
from asset2sim.schemas.report import MetricResult
from asset2sim.tasks.check import sweep_stalls
from asset2sim.tasks.geometry import limits
from asset2sim.tasks.geometry.decomposition import DecompositionUnavailable
from asset2sim.tasks.state import clearance
from asset2sim.tasks.tune import stop_repair
from asset2sim.tasks.state.collision import CollisionPiece
from asset2sim.urdf import UrdfModel

#: Tiers whose failure, with parts in contact at the state, asks for running clearance.
HELD_TOGETHER_TIERS: tuple[str, ...] = ("robust_rest", "task_execution", "probes")


@dataclass(frozen=True)
class CollisionRepair:
    """One candidate repair: the writer's collision overrides to try."""

    what: str
    """its name in notes and escalation reasons"""
    overrides: dict[str, list[CollisionPiece]]
    """link -> collision pieces (link frame, m): every override so far plus this repair's"""
    notes: list[str] = field(default_factory=list)
    """what changed, before -> after, for the report"""


def held_together_pairs(metrics: list[MetricResult]) -> list[tuple[str, str]]:
    """The link pairs in contact at the state (PyBullet ``penetration`` pairs)
    when a tier of :data:`HELD_TOGETHER_TIERS` failed in ``metrics``; else empty."""
    if not any(m.name in HELD_TOGETHER_TIERS and m.passed is False for m in metrics):
        return []
    pen = next((m for m in metrics if m.name == "penetration" and m.engine == "pybullet"), None)
    return [(p["link_a"], p["link_b"]) for p in ((pen.details.get("pairs") or []) if pen is not None else [])]


def clearance_repair(model: UrdfModel, urdf: Path, joints: dict[str, float], state: dict[str, float],
                     overrides: dict[str, list[CollisionPiece]], scale: float, out_dir: Path,
                     folder: str, moved: dict[str, dict[str, float]] | None = None) -> CollisionRepair | None:
    """Running clearance for the sliding contacts of ``joints`` (joint -> position,
    rad or m) of the written ``model``, other joints at ``state`` with ``moved`` over it (as
    :func:`~asset2sim.tasks.state.clearance.clearance_for_blocked`); pieces written
    under ``out_dir/folder`` at ``scale``. None when no contact needs it.

    Raises:
        OSError: a collision file cannot be read or written.
        ValueError: a repaired piece spans no volume (names its link).
    """
    rep = clearance.clearance_for_blocked(model, urdf, joints, state, limits.subtrees(model), moved)
    if not rep.pieces:
        return None
    new = clearance.write_piece_overrides(rep.pieces, scale, out_dir, folder, "clear")
    return CollisionRepair("running clearance", {**overrides, **new}, list(rep.notes))


def sweep_repairs(obj: SimObject, asset: AssetDescription, sweep_metric: MetricResult, blocked: dict[str, float],
                  overrides: dict[str, list[CollisionPiece]], scale: float, out_dir: Path, folder: str,
                  config: RefineConfig) -> Iterator[CollisionRepair]:
    """The candidate repairs of a blocked sweep of ``obj`` (at its initial state), lazily, in order (each
    computed only when the one before was not kept). ``blocked``: joint -> where the
    sweep stopped (rad or m); ``overrides``: the collision overrides so far;
    the rest as :func:`clearance_repair` and
    :func:`~asset2sim.tasks.tune.stop_repair.decompose_for_blocked`.

    Raises:
        OSError: a collision file cannot be read or written.
    """
    repair = clearance_repair(obj.source.model(), obj.source.path, blocked, dict(obj.state), overrides, scale, out_dir,
                              folder, sweep_stalls.stall_states(sweep_metric))
    if repair is not None:
        yield repair
        return
    if not config.convex_decomposition:
        return
    try:
        dec, notes = stop_repair.decompose_for_blocked(obj, asset, sweep_metric, set(overrides), scale, out_dir, folder,
                                                       max_decompositions=config.max_decompositions)
    except DecompositionUnavailable:
        return
    if dec:
        yield CollisionRepair("convex decomposition", {**overrides, **dec}, notes)
