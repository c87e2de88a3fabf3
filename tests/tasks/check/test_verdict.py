"""The failure mode is decided in one place (tasks.check.verdict)."""

from __future__ import annotations

from dataclasses import dataclass

from asset2sim.schemas.report import FAILURE_MODES, MetricResult
from asset2sim.tasks.check.verdict import (
    INVALID_MANIFEST_ROW,
    UNRESOLVED_PENETRATION_MM,
    asset_failure_mode,
    exception_failure_mode,
    post_check_failure_mode,
)


@dataclass
class _Check:
    stable: bool
    osc: bool
    pen: float | None

    def metric(self, name):
        if name == "oscillation":
            return MetricResult(name=name, value=0.0, unit="joints", passed=self.osc)
        return MetricResult(name=name, value=self.pen, unit="mm")


def test_post_check_modes_in_order():
    assert post_check_failure_mode(_Check(False, False, 99.0)) == "unstable"
    assert post_check_failure_mode(_Check(True, False, 99.0)) == "oscillating"
    assert post_check_failure_mode(_Check(True, True, UNRESOLVED_PENETRATION_MM + 0.1)) == "unresolved_penetration"
    assert post_check_failure_mode(_Check(True, True, UNRESOLVED_PENETRATION_MM)) == "none"
    assert post_check_failure_mode(_Check(True, True, None)) == "none"


def test_asset_mode_first_failure_in_stage_order():
    assert asset_failure_mode(input_failure="invalid_input").failure_mode == "invalid_input"
    assert asset_failure_mode(refine_status="ok", refine_mode="oscillating", measured_status="ok",
                              rest_stable=False).failure_mode == "oscillating"
    v = asset_failure_mode(refine_status="ok", refine_mode="none", measured_status="ok", rest_stable=False)
    assert v.failure_mode == "unstable" and "metrics stage" in v.errors[0]
    assert asset_failure_mode(refine_status="ok", measured_status="ok", oscillation_pass=False).failure_mode == "oscillating"
    assert asset_failure_mode(refine_status="timeout").failure_mode == "timeout"
    assert asset_failure_mode(refine_status="error").failure_mode == "crash"
    assert asset_failure_mode(refine_status="error", refine_mode="estimator_failure").failure_mode == "estimator_failure"
    assert asset_failure_mode(refine_status="ok", refine_mode="none", measured_status="timeout").failure_mode == "timeout"
    assert asset_failure_mode(refine_status="ok", refine_mode="none", chain_error_mode="timeout").failure_mode == "timeout"
    assert asset_failure_mode().failure_mode == "crash"
    bad_row = asset_failure_mode(manifest_error="MANIFEST_INVALID_ID: m.csv:3: invalid asset id '../x'",
                                 refine_status="ok", refine_mode="none")
    assert bad_row.failure_mode == INVALID_MANIFEST_ROW == "invalid_manifest_row"  # no stage ran for such a row
    assert "MANIFEST_INVALID_ID" in bad_row.errors[0]
    for kw in ({}, {"refine_status": "crash"}, {"input_failure": "invalid_input"}, {"manifest_error": "x"}):
        assert asset_failure_mode(**kw).failure_mode in FAILURE_MODES


def test_exception_modes():
    class Model(RuntimeError):
        failure_mode = "estimator_failure"

    class TaskRunTimeoutError(RuntimeError):
        pass

    assert exception_failure_mode(Model("x"), Model) == "estimator_failure"
    assert exception_failure_mode(TimeoutError()) == "timeout"
    assert exception_failure_mode(TaskRunTimeoutError()) == "timeout"
    assert exception_failure_mode(ValueError()) == "crash"
