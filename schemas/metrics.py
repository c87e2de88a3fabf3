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
from asset2sim.package_data import package_yaml

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


#: name -> :class:`MetricInfo`, in evaluation order (``metrics.yaml`` beside this module).
METRIC_INFO: dict[str, MetricInfo] = {
    name: MetricInfo(name, *entry)
    for name, entry in package_yaml(__package__, "metrics.yaml").items()
}

#: The SPEC's physical-robustness metrics measured in every engine (parity).
SPEC_METRICS: tuple[str, ...] = ("penetration", "rest_stability", "oscillation")


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
        out.update({col: _field(m, source) for col, source in info.columns.items()})
    return out
