"""Closed ends measured on a written URDF: the one measurement refine and the
evaluation share.

The evaluation grades every method against closed ends it measures itself on
the method's output (:mod:`asset2sim.tasks.evaluation.closed_ends`). The
output's collision pieces depend only on the meshes and the joint limits
(:mod:`asset2sim.tasks.assemble.collision_geometry`), so refine measures its
own written output with the same function and places the requested state
from that: where the output's pieces overlap a part's parent at every angle
(faucet 148's handle inside its body's hull piece, 120-156 mm summed
penetration over the whole range), the closed end found on the input meshes
and the one found on the output pieces can differ, and the request would be
graded against an end it was not placed from.

:func:`closed_session` is the measurement (extract the URDF, a fresh
fixed-base, gravity-free PyBullet session without ground, the links'
convex-hull points, :func:`asset2sim.tasks.geometry.closed_state.closed_positions`
with its defaults); :func:`measure_closed_ends` gives its result and the
object's extents at the closed ends, once per geometry in a process;
:func:`replace_positions` moves joint positions from one set of closed ends to
another, keeping what the request asked of each joint.
"""

from __future__ import annotations

import copy
import hashlib
import os
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Iterator

import numpy as np

from asset2sim import file_memo
from asset2sim.engines.base import SessionOptions
from asset2sim.engines.registry import open_session
from asset2sim.schemas.asset import AssetDescription
from asset2sim.tasks.geometry.closed_state import ClosedState, closed_positions, link_hull_points, object_extents
from asset2sim.tasks.ingest.extract import extract_asset
from asset2sim.urdf import UrdfError, clone_model, read_urdf, write_urdf


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


@dataclass
class ClosedMeasurement:
    """What :func:`measure_closed_ends` measured on a URDF."""

    closed: dict[str, ClosedState]
    """joint -> closed end (rad or m, the URDF's units), every movable joint."""
    extents: np.ndarray
    """(3,) m: extents of the box bounding the object with every joint at its
    closed end (:func:`geometry_extents`)."""


def measure_closed_ends(urdf: Path) -> ClosedMeasurement:
    """The closed ends of ``urdf`` (:func:`closed_session`) and the object's
    extents there, measured once per geometry in this process: the result
    depends on the links' collision and visual geometry, inertial frames and
    the joints' frames, axes, types and limits, not on joint friction and
    damping (the measurement is kinematic), so a refine run's own measurement
    of its output (:func:`measure_closed`) is reused by the evaluation of the
    same output after escalation rewrote only the dynamics
    (:data:`_MEASURED`; each caller gets its own copy).

    Raises:
        as :func:`closed_session`.
    """
    key, files = _geometry_key(urdf)
    if key is not None:
        hit = _MEASURED.get(key)
        if hit is not None:
            return hit
    with closed_session(urdf) as m:
        out = ClosedMeasurement(closed=m.closed, extents=geometry_extents(
            m.session, m.asset, {n: c.q_closed for n, c in m.closed.items()}, m.hull))
    if key is not None:
        _MEASURED.put(key, files, out)
    return out


def measure_closed(urdf: Path) -> dict[str, ClosedState]:
    """joint -> closed end of ``urdf`` (:func:`measure_closed_ends`), only the
    joints with an opening range > 0 (the others have no geometric closed end
    to place a state from).

    Raises:
        as :func:`closed_session`.
    """
    return {n: c for n, c in measure_closed_ends(urdf).closed.items() if c.open_range > 0}


#: :func:`measure_closed_ends` results by :func:`_geometry_key`, while the
#: mesh files they were measured with are unchanged
#: (:class:`asset2sim.file_memo.FileMemo`): a 6-drawer cabinet's
#: measurement takes 0.3 s, and refine and its evaluation measure the same
#: geometry.
_MEASURED: file_memo.FileMemo[ClosedMeasurement] = file_memo.FileMemo(copy.deepcopy, max_entries=16)


def _geometry_key(urdf: Path) -> tuple[str | None, tuple]:
    """(digest of the URDF's folder and of the model with every joint's
    ``<dynamics>`` left out, identities of its mesh files), or (None, ()) when
    the URDF cannot be read (the measurement then raises what it raises)."""
    try:
        model = clone_model(read_urdf(urdf))
    except (UrdfError, OSError):
        return None, ()
    meshes = sorted({str(g.path) for link in model.links.values() for g in (*link.collisions, *link.visuals)
                     if g.kind == "mesh" and g.path is not None})
    for j in model.joints:
        j.dynamics = None
    h = hashlib.sha256(os.path.abspath(Path(urdf).parent).encode() + b"\0" + write_urdf(model))
    return h.hexdigest(), file_memo.identities(meshes)


def aabb_extents(session) -> np.ndarray:
    """Extents (3,) m of the union of the engine's link AABBs over the links
    with collision geometry (loose; see :func:`geometry_extents`); zeros when
    no link has collision geometry."""
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
    """Extents (3,) m of the box bounding the links' collision hull vertices at
    ``state`` (rad/m) (:func:`asset2sim.tasks.geometry.closed_state.object_extents`).
    Bullet's own AABBs are loose for a link whose inertia tensor has
    off-diagonal terms (the shape sits rotated in the principal-axes frame and
    its box is re-bounded: 0.67 m instead of 0.39 m for a refined toilet), so
    they are only the fallback (:func:`aabb_extents` with the joints set to
    ``state``), used without hull points or when the hull box fails."""
    try:
        if hull is not None:
            return np.asarray(object_extents(session, state, desc, hull), float)
    except Exception:
        pass
    session.set_joint_positions(state)
    return aabb_extents(session)


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
