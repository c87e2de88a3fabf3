"""Closed ends measured on a written URDF: the one measurement refine and the
evaluation share.

The evaluation grades every method against closed ends it measures itself on
the method's output (:mod:`asset2sim.tasks.evaluation.closed_ends`). The
output's collision pieces depend only on the meshes and the joint limits
(:mod:`asset2sim.tasks.publish.collision_geometry`), so refine measures its
own written output with the same function and places the requested state
from that: where the output's pieces overlap a part's parent at every angle
(faucet 148's handle inside its body's hull piece, 120-156 mm summed
penetration over the whole range), the closed end found on the input meshes
and the one found on the output pieces can differ, and the request would be
graded against an end it was not placed from.

:func:`closed_session` is the measurement (extract the URDF, a fresh
fixed-base, gravity-free PyBullet session without ground, the links'
convex-hull points, :func:`asset2sim.tasks.geometry.closed_state.closed_positions`
with its defaults); :func:`replace_positions` moves joint positions from one
set of closed ends to another, keeping what the request asked of each joint.
"""

from __future__ import annotations

from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Iterator

import numpy as np

from asset2sim.engines.base import SessionOptions, open_session
from asset2sim.schemas.asset import AssetDescription
from asset2sim.tasks.geometry.closed_state import ClosedState, closed_positions, link_hull_points
from asset2sim.tasks.ingest.extract import extract_asset


@dataclass
class UrdfClosed:
    """A URDF's closed ends and what they were measured with."""

    session: object
    """The PyBullet session (fixed base, no gravity, no ground), left at the closed state."""
    asset: AssetDescription
    hull: dict[str, np.ndarray] | None
    """Convex-hull points per link (link frame, m), None when they could not be computed."""
    closed: dict[str, ClosedState]
    """joint -> closed end (rad or m, the URDF's units)."""


@contextmanager
def closed_session(urdf: Path) -> Iterator[UrdfClosed]:
    """Closed ends of every movable joint of ``urdf``, measured in a fresh
    fixed-base, gravity-free PyBullet session without ground, every other
    joint at 0 clipped to its limits (:func:`closed_positions` with its
    defaults); the session stays open inside the ``with`` block.

    Raises:
        asset2sim.tasks.ingest.extract.AssetError: ``urdf`` cannot be read.
        Whatever the engine or the hull computation raises (the caller decides
        the fallback).
    """
    desc = extract_asset(urdf)
    s = open_session("pybullet", urdf, SessionOptions(fixed_base=True, gravity=False, ground=False))
    try:
        try:
            hull = link_hull_points(desc)
        except Exception:
            hull = None
        cs = closed_positions(s, desc, **({"hull_points": hull} if hull is not None else {}))
        yield UrdfClosed(session=s, asset=desc, hull=hull, closed=cs)
    finally:
        s.close()


def measure_closed(urdf: Path) -> dict[str, ClosedState]:
    """joint -> closed end of ``urdf`` (:func:`closed_session`), only the
    joints with an opening range > 0 (the others have no geometric closed end
    to place a state from).

    Raises:
        as :func:`closed_session`.
    """
    with closed_session(urdf) as m:
        return {n: c for n, c in m.closed.items() if c.open_range > 0}


def replace_positions(state: dict[str, float], old: dict[str, ClosedState], new: dict[str, ClosedState],
                      keep_opening: set[str] = frozenset()) -> dict[str, float]:
    """``state`` (rad / m) with every joint in both ``old`` and ``new`` moved
    from the closed end ``old`` to ``new``: its opening fraction is kept
    (f = old.fraction(q), q' = new.position(f)), or for the joints in
    ``keep_opening`` (a number of degrees / metres asked from the closed end)
    its opening d (q - q_closed) in the opening direction; clipped to the new
    limits.
    """
    out = dict(state)
    for n, q in state.items():
        a, b = old.get(n), new.get(n)
        if a is None or b is None:
            continue
        if n in keep_opening:
            q2 = b.q_closed + b.direction * a.direction * (q - a.q_closed)
            out[n] = float(np.clip(q2, b.lower, b.upper))
        else:
            out[n] = b.position(a.fraction(q))
    return out
