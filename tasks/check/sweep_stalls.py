"""What a joint sweep's metric says about where parts stalled (:mod:`~asset2sim.tasks.check.sweep`): the stops
the stop repair and the escalation read, and the score that orders two sweeps."""

from __future__ import annotations

import numpy as np

from asset2sim.schemas.report import MetricResult
from asset2sim.tasks.check.sweep import shortfall


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


def stall_states(metric: MetricResult) -> dict[str, dict[str, float]]:
    """Joint -> the other joints' positions (rad or m) its reported sweep moved from the initial state (a retry with the
    joints between moved, ``swept_with``), for every joint of :func:`blocked_stops`; empty where it was swept from
    the initial state. Where a stall is, with these over the initial state."""
    joints = metric.details.get("joints") or {}
    return {name: dict(joints[name].get("swept_with") or {}) for name in blocked_stops(metric)}


def blocked_positions(metric: MetricResult) -> dict[str, float]:
    """Joint -> the position (rad or m) where the sweep stopped short (:func:`blocked_stops`)."""
    return {name: stall for name, (stall, _goal) in blocked_stops(metric).items()}


def sweep_score(metric: MetricResult) -> tuple[float, float]:
    """Sort key of ``joint_sweep`` results, lower is better: (failing joints,
    summed shortfall of the failing joints, each way >= 0, non-finite = 1,
    rounded to 0.01)."""
    short = sum(shortfall(j["reached_open"], j["reached_closed"])
                for j in (metric.details.get("joints") or {}).values() if not j["passed"])
    return float(metric.value), round(short, 2)
