"""Closed ends measured on a written URDF: the one measurement refine and the evaluation share
(:mod:`asset2sim.tasks.evaluation.closed_ends`), so a request is graded against the closed ends of the
output's own collision pieces, from which refine placed it.

:func:`closed_session` measures; :func:`measure_closed_ends` gives its result and the object's extents
there; :func:`replace_positions` moves joint positions from one set of
closed ends to another.
"""

from __future__ import annotations

from collections.abc import Collection
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Iterator

import numpy as np

from asset2sim.engines.base import SessionOptions
from asset2sim.engines.source import SimSource, UrdfFile
from asset2sim.schemas.asset import AssetDescription
from asset2sim.tasks.geometry.closed_state import ClosedState, closed_positions, link_hull_points, object_extents
from asset2sim.tasks.ingest.extract import describe_model, extract_asset
from asset2sim.urdf import UrdfError, UrdfModel


@dataclass
class UrdfClosed:
    """A URDF's closed ends and what they were measured with."""

    session: object  # PyBullet, fixed base, no gravity, no ground; left at the closed state
    asset: AssetDescription
    hull: dict[str, np.ndarray] | None  # convex-hull points per link (link frame, m); None when they failed
    closed: dict[str, ClosedState]  # joint -> closed end (rad or m)


@contextmanager
def closed_session(source: SimSource, *, model: UrdfModel | None = None, pushed: Collection[str] = ()) -> Iterator[UrdfClosed]:
    """Closed ends of every movable joint of ``source`` (:func:`closed_positions` with its defaults, the joints
    ``pushed`` closed where a press's return spring rests them) in a
    fresh fixed-base, gravity-free PyBullet session without ground, open inside the ``with`` block. A file
    (:class:`~asset2sim.engines.source.UrdfFile` of a path) is described with its folder's part labels
    (:func:`~asset2sim.tasks.ingest.extract.extract_asset`), any other source from its model
    (:func:`~asset2sim.tasks.ingest.extract.describe_model`; ``model``: ``source.model()`` when the caller has it).

    Raises:
        asset2sim.tasks.ingest.extract.AssetError: ``source`` cannot be read; and whatever the engine raises.
    """
    if isinstance(source, UrdfFile) and not isinstance(source.source, UrdfModel):
        desc = extract_asset(source.path)
    else:
        desc = describe_model(model if model is not None else source.model())
    s = source.open("pybullet", SessionOptions(fixed_base=True, gravity=False, ground=False))
    try:
        try:
            hull = link_hull_points(desc)
        except Exception:
            hull = None
        cs = closed_positions(s, desc, hull_points=hull, pushed=pushed)
        yield UrdfClosed(session=s, asset=desc, hull=hull, closed=cs)
    finally:
        s.close()


@dataclass
class ClosedMeasurement:
    """What :func:`measure_closed_ends` measured on a URDF."""

    closed: dict[str, ClosedState]  # joint -> closed end (rad or m), every movable joint
    extents: np.ndarray  # (3,) m, the object's box with every joint at its closed end (geometry_extents)


def measure_closed_ends(source: SimSource, pushed: Collection[str] = ()) -> ClosedMeasurement:
    """The closed ends of ``source`` (:func:`closed_session`, the joints ``pushed`` as there) and the object's extents
    there (the measurement is kinematic: joint dynamics do not change it).

    Raises:
        as :func:`closed_session`.
    """
    try:
        model = source.model()
    except (UrdfError, OSError):
        model = None
    with closed_session(source, model=model, pushed=pushed) as m:
        return ClosedMeasurement(closed=m.closed, extents=geometry_extents(
            m.session, m.asset, {n: c.q_closed for n, c in m.closed.items()}, m.hull))


def measure_closed(source: SimSource, pushed: Collection[str] = ()) -> dict[str, ClosedState]:
    """joint -> closed end of ``source`` (:func:`measure_closed_ends`, the joints ``pushed`` as there), the joints with
    an opening range > 0.

    Raises:
        as :func:`closed_session`.
    """
    return {n: c for n, c in measure_closed_ends(source, pushed).closed.items() if c.open_range > 0}


def aabb_extents(session) -> np.ndarray:
    """Extents (3,) m of the union of the engine's (loose) AABBs of the links with collision geometry;
    zeros when there is none."""
    lo, hi = np.full(3, np.inf), np.full(3, -np.inf)
    for name in session.link_names:
        if not session.link_has_collision(name):
            continue
        a, b = session.link_aabb(name)
        lo, hi = np.minimum(lo, a), np.maximum(hi, b)
    if not np.all(np.isfinite(lo)):
        return np.zeros(3)
    return np.maximum(hi - lo, 0.0)


def geometry_extents(session, desc: AssetDescription | None, state: dict[str, float],
                     hull: dict[str, np.ndarray] | None) -> np.ndarray:
    """Extents (3,) m of the box bounding the links' collision hull vertices at ``state`` (rad/m)
    (:func:`~asset2sim.tasks.geometry.closed_state.object_extents`); without hull points or when that
    fails, :func:`aabb_extents` at ``state`` (Bullet's AABBs are loose for rotated inertia frames)."""
    try:
        if hull is not None:
            return np.asarray(object_extents(session, state, desc, hull), float)
    except Exception:
        pass
    session.set_joint_positions(state)
    return aabb_extents(session)


def replace_positions(state: dict[str, float], old: dict[str, ClosedState], new: dict[str, ClosedState],
                      keep_opening: set[str] = frozenset()) -> dict[str, float]:
    """``state`` (rad / m) with every joint in both ``old`` and ``new`` moved from closed end ``old`` to
    ``new``, keeping its opening fraction, or for ``keep_opening`` joints its opening d (q - q_closed);
    clipped to the new limits."""
    out = dict(state)
    for n, q in state.items():
        a, b = old.get(n), new.get(n)
        if a is None or b is None:
            continue
        if n in keep_opening:
            out[n] = float(np.clip(b.q_closed + b.direction * a.direction * (q - a.q_closed), b.lower, b.upper))
        else:
            out[n] = b.position(a.fraction(q))
    return out
