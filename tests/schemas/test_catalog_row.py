"""The catalog row model, its derived Parquet schema, and the metric registry's columns."""

from __future__ import annotations

from datetime import datetime, timezone

import pyarrow as pa
import pytest
from pydantic import ValidationError

from asset2sim.schemas.catalog import ROW_COLUMNS, CatalogRow, arrow_schema
from asset2sim.schemas.metrics import METRIC_INFO, SPEC_METRICS, column_values
from asset2sim.schemas.report import MetricResult


def test_schema_is_derived_field_for_field():
    schema = arrow_schema()
    assert tuple(schema.names) == ROW_COLUMNS
    assert schema.field("penetration_mm").type == pa.float64()
    assert schema.field("rest_stable").type == pa.bool_()
    assert schema.field("model_queries").type == pa.int64()
    assert schema.field("status").type == pa.string()
    assert schema.field("started_at").type == pa.timestamp("us", tz="UTC")


def test_rows_validate_and_drop_non_finite_numbers():
    row = CatalogRow(asset_id="a", status="done", scale=float("nan"), started_at=datetime.now(timezone.utc))
    assert row.scale is None
    row.d_pos_m = float("inf")
    assert row.d_pos_m is None
    with pytest.raises(ValidationError):
        CatalogRow(asset_id="a", status="maybe")
    with pytest.raises(ValidationError):
        CatalogRow(asset_id="a", status="done", colour="red")
    pa.Table.from_pylist([row.model_dump()], schema=arrow_schema())  # the row fits its schema


def test_every_metric_column_is_a_catalog_column():
    cols = {col: m.name for m in METRIC_INFO.values() for col in m.columns}  # catalog column -> metric
    assert set(cols) <= set(ROW_COLUMNS)
    assert cols["d_pos_m"] == "rest_stability" and cols["scale_deviation_pct"] == "scale_deviation"
    assert all(n in METRIC_INFO for n in SPEC_METRICS)


def test_column_values_from_metric_results():
    ms = [
        MetricResult(name="penetration", value=2.5, unit="mm", engine="physx"),
        MetricResult(name="penetration", value=1.5, unit="mm"),
        MetricResult(name="rest_stability", value=1e-5, unit="m", passed=True, details={"D_pos_m": 1e-5, "D_ori_rad": float("nan")}),
        MetricResult(name="prompt_alignment", value=0.75, unit="fraction", engine="none"),
    ]
    v = column_values(ms, "pybullet")
    assert v == {"penetration_mm": 1.5, "rest_stable": True, "d_pos_m": 1e-5, "d_ori_rad": None, "prompt_alignment": 0.75,
                 "request_warnings": None}
    assert column_values(ms, None)["penetration_mm"] == 2.5  # first of any engine
    assert "oscillation_pass" not in v  # absent metric: no key
