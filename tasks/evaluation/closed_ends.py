"""Geometry the evaluation measures itself, so no method grades itself:
closed ends, extents (of the links' convex-hull vertices, Bullet's AABBs the
fallback), scale.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from asset2sim.engines.base import SessionOptions
from asset2sim.engines.registry import open_session
from asset2sim.schemas.asset import AssetDescription
from asset2sim.tasks.check.asset_files import JointInfo, clip_to_limits
from asset2sim.tasks.geometry.closed_state import link_hull_points
from asset2sim.engines.source import UrdfFile
from asset2sim.tasks.geometry.urdf_closed import geometry_extents, measure_closed_ends
from asset2sim.tasks.ingest.extract import extract_asset


@dataclass
class ClosedEnd:
    """Closed end of a joint: q_closed (rad/m), direction +-1, open range (rad/m), source."""

    q_closed: float
    direction: float
    open_range: float
    source: str

    def fraction(self, q: float) -> float:
        """Opening fraction of ``q`` (rad/m): 0 closed, 1 fully open (0 when it cannot open)."""
        if self.open_range <= 0:
            return 0.0
        return float(self.direction * (q - self.q_closed) / self.open_range)


def closed_fallback(j: JointInfo) -> ClosedEnd:
    """Closed end without geometry: the limit nearest 0 (continuous: 0, range pi)."""
    lo, hi = j.lower, j.upper
    if j.type == "continuous" or lo is None or hi is None or lo > hi:
        return ClosedEnd(0.0, 1.0, math.pi, "fallback: continuous joint, 0 taken as closed")
    qc = lo if abs(lo) <= abs(hi) else hi
    d = 1.0 if qc == lo else -1.0
    return ClosedEnd(float(qc), d, float(hi - lo), "fallback: the limit nearest 0")


def hull_points(desc: AssetDescription) -> dict[str, np.ndarray] | None:
    """link -> convex-hull vertices (N, 3) m, link frame (``link_hull_points``), or None when they cannot be computed."""
    try:
        return link_hull_points(desc)
    except Exception:
        return None


def infer_scale_from_geometry(urdf: Path, raw_urdf: Path) -> float | None:
    """Uniform scale of ``urdf`` relative to ``raw_urdf``: the ratio of their largest geometry extents
    (:func:`geometry_extents`, fixed base, joints at 0 clipped to the limits); None when either cannot be measured."""
    exts = []
    for path in (urdf, raw_urdf):
        try:
            s = open_session("pybullet", path, SessionOptions(fixed_base=True, gravity=False, ground=False))
        except Exception:
            return None
        try:
            try:
                desc = extract_asset(path)
                hull = hull_points(desc)
            except Exception:
                desc, hull = None, None
            q0 = {n: clip_to_limits(0.0, *s.joint_limits[n]) for n in s.joint_names}
            exts.append(geometry_extents(s, desc, q0, hull))
        finally:
            s.close()
    a, b = float(np.max(exts[0])), float(np.max(exts[1]))
    return a / b if a > 0 and b > 0 else None


def compute_closed(urdf: Path, joints: dict[str, JointInfo], names: list[str],
                   extents_out: list | None = None) -> tuple[dict[str, ClosedEnd], list[str]]:
    """Closed end of each joint in ``names`` (the URDF's units) by
    :func:`asset2sim.tasks.geometry.urdf_closed.measure_closed_ends`, else (failure, or no opening) :func:`closed_fallback`.
    ``joints``: the URDF's (``parse_urdf``); ``extents_out``: when given, the (3,) m extents with every joint closed are
    appended. Returns (joint -> :class:`ClosedEnd`, notes)."""
    notes: list[str] = []
    out: dict[str, ClosedEnd] = {}
    if not names:
        return out, notes
    try:
        m = measure_closed_ends(UrdfFile(urdf))
        if extents_out is not None:
            extents_out.append(m.extents)
        for n in names:
            c = m.closed.get(n)
            out[n] = (closed_fallback(joints[n]) if c is None or not c.open_range > 0
                      else ClosedEnd(float(c.q_closed), float(c.direction), float(c.open_range), "geometry (closed_state)"))
    except Exception as exc:
        notes.append(f"closed_positions failed ({type(exc).__name__}: {exc}); closed end = limit nearest 0")
        out = {n: closed_fallback(joints[n]) for n in names}
    return out, notes
