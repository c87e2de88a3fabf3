"""The metric registry's table: every metric's name, unit, group and the
catalog columns it fills (each from a :class:`~asset2sim.schemas.report.MetricResult`
field: ``value``, ``passed`` or ``details.<key>``), shared by the post-check,
the evaluation, parity and the catalog. Definitions: ``docs/design/metrics.md``.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from typing import Any, Iterable, Literal

from asset2sim.schemas.report import MetricResult

MetricGroup = Literal["physical", "semantic", "behaviour", "check"]


@dataclass(frozen=True)
class MetricInfo:
    """One metric: ``unit`` of its value; ``group`` physical (per engine),
    semantic, behaviour or check (refine's own, not SPEC); ``columns``
    catalog column -> result field."""

    name: str
    unit: str
    group: MetricGroup
    description: str
    columns: dict[str, str] = field(default_factory=dict)


#: name -> :class:`MetricInfo`, in evaluation order.
METRIC_INFO: dict[str, MetricInfo] = {
    m.name: m
    for m in (
        MetricInfo("penetration", "mm", "physical", "Phi at the initial state (self-contacts), mm, with link pairs",
                   {"penetration_mm": "value"}),
        MetricInfo("ground_penetration", "mm", "physical", "deepest penetration into the ground during the rest test, mm"),
        MetricInfo("rest_stability", "m", "physical", "rest test (1 s settle, 2 s test): D_pos <= 1e-3 m and D_ori <= 1e-2 rad",
                   {"rest_stable": "passed", "d_pos_m": "details.D_pos_m", "d_ori_rad": "details.D_ori_rad"}),
        MetricInfo("oscillation", "joints", "physical", "joint oscillation during the 2 s rest test",
                   {"oscillation_pass": "passed"}),
        MetricInfo("divergence", "flag", "physical", "NaN or explosion during the rest test"),
        MetricInfo("scale_deviation", "%", "semantic", "|s - s_ref| / s_ref vs GenSim2's scale, %",
                   {"scale_deviation_pct": "value"}),
        MetricInfo("initial_joint_deviation", "rad", "semantic", "|q - q_ref| of the task-relevant joint"),
        MetricInfo("total_mass", "kg", "semantic", "total mass and its plausibility for the category and size"),
        MetricInfo("prompt_alignment", "fraction", "semantic", "0.5 size + 0.5 joint state vs the request",
                   {"prompt_alignment": "value", "request_warnings": "json:details.warnings"}),
        MetricInfo("request_met", "unmet phrases", "semantic",
                   "as asked: every part and state the request names applied, every number asked within its tolerance",
                   {"request_met": "passed", "request_unmet": "json:details.unmet"}),
        MetricInfo("probes", "failed probes", "behaviour",
                   "scripted pusher closes/opens each task-relevant joint (learnability's stand-in; reported, not a verdict tier)"),
        MetricInfo("joint_sweep", "joints", "behaviour",
                   "root fixed: each movable joint driven (force-limited) from its closed end to >= 95 % open and back"),
        MetricInfo("operability", "parts", "behaviour",
                   "root fixed: every handled part pushed open and closed by a hand, its effort inside the part's real operating range",
                   {"operable": "passed", "operating_efforts": "json:details.efforts"}),
        MetricInfo("robust_rest", "trials", "physical",
                   "dropped 2 cm, tilted 5 deg about each horizontal axis, nudged: back to rest, joints held"),
        MetricInfo("task_execution", "failed attempts", "behaviour",
                   "a 70 N, 0.25 m/s gripper performs the task on the free object: target reached and held 1 s, no sliding or tipping"),
        MetricInfo("operating_force", "N", "behaviour",
                   "the task's peak operating force (and hinge torque) inside the real operating range of the category and part"),
        MetricInfo("state_hold", "rad|m", "check",
                   "undisturbed: every joint at rest within max(0.02 rad, 2 mm) of its initial state after the rest test"),
        MetricInfo("settle_tilt", "rad", "check", "root rotation while settling (the object fell over)"),
        MetricInfo("parent_child_penetration", "mm", "check",
                   "deepest penetration of a child into its parent's collision shapes at the initial state, the pair collided"),
    )
}  # fmt: skip

#: The SPEC's physical-robustness metrics measured in every engine (parity).
SPEC_METRICS: tuple[str, ...] = ("penetration", "rest_stability", "oscillation")

#: Metrics whose verdict depends only on the rest test and the initial state:
#: the post-check's measurement of them is the measurement.
REST_TEST_METRICS: tuple[str, ...] = SPEC_METRICS


def unit(name: str) -> str:
    """Unit of metric ``name``'s value (KeyError: not registered)."""
    return METRIC_INFO[name].unit


def _field(m: MetricResult, source: str) -> Any:
    if source == "value":
        v = m.value
    elif source == "passed":
        return m.passed
    elif source.startswith("details."):
        v = (m.details or {}).get(source[len("details."):])
    elif source.startswith("json:details."):  # a list or mapping, as a JSON text column
        v = (m.details or {}).get(source[len("json:details."):])
        return None if v is None else json.dumps(v)
    else:
        raise ValueError(f"unknown metric field {source!r}")
    try:
        f = float(v)
    except (TypeError, ValueError):
        return None
    return f if math.isfinite(f) else None


def column_values(metrics: Iterable[MetricResult], engine: str | None = "pybullet",
                  names: Iterable[str] | None = None) -> dict[str, Any]:
    """Catalog column values of ``metrics`` (first result per name, of
    ``engine`` or ``none`` when given, only ``names`` when given): every column
    of a present metric, None for a missing or non-finite number."""
    wanted = None if names is None else set(names)
    seen: set[str] = set()
    out: dict[str, Any] = {}
    for m in metrics:
        info = METRIC_INFO.get(m.name)
        if (info is None or m.name in seen or (wanted is not None and m.name not in wanted)
                or (engine is not None and m.engine not in (engine, "none"))):
            continue
        seen.add(m.name)
        for col, source in info.columns.items():
            out[col] = _field(m, source)
    return out
