"""What a joint sweep's metric says about where parts stalled (:mod:`~asset2sim.tasks.check.sweep`): the stops
the stop repair and the escalation read, and the score that orders two sweeps."""

from __future__ import annotations

import numpy as np

from asset2sim.schemas.report import MetricResult
from asset2sim.tasks.check.sweep import REACH_FRACTION


def blocked_stops(metric: MetricResult) -> dict[str, tuple[float, float]]:
    """Joint -> (position where the ``joint_sweep`` ``metric`` stalled, position
    it was driven to), rad or m: on the way out when the far end was not
    reached, else on the way back. Joints that passed, diverged or only
    penetrated are left out."""
    out = {}
    for name, j in (metric.details.get("joints") or {}).items():
        if j["passed"] or j["diverged"]:
            continue
        if j["time_open"] is None:
            f, goal = j["reached_open"], j["q_far"]
        elif j["time_close"] is None:
            f, goal = j["reached_closed"], j["q_closed"]
        else:
            continue
        if np.isfinite(f):
            out[name] = (float(j["q_closed"] + (j["q_far"] - j["q_closed"]) * f), float(goal))
    return out


def blocked_positions(metric: MetricResult) -> dict[str, float]:
    """Joint -> the position (rad or m) where the sweep stopped short (:func:`blocked_stops`)."""
    return {name: stall for name, (stall, _goal) in blocked_stops(metric).items()}


def sweep_score(metric: MetricResult) -> tuple[float, float]:
    """Sort key of ``joint_sweep`` results, lower is better: (failing joints,
    summed shortfall of the failing joints, each way >= 0, non-finite = 1,
    rounded to 0.01)."""
    short = 0.0
    for j in (metric.details.get("joints") or {}).values():
        if j["passed"]:
            continue
        out, back = j["reached_open"], j["reached_closed"]
        short += max(0.0, REACH_FRACTION - out) if np.isfinite(out) else 1.0
        short += max(0.0, back - (1.0 - REACH_FRACTION)) if np.isfinite(back) else 1.0
    return float(metric.value), round(short, 2)
