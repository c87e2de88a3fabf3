"""The run-against-previous-run comparison (verdict flips, pass-rate and
metric drift, limits from catalog.yaml), its artifacts, and the progress
display of ``asset2sim flow``."""

from __future__ import annotations

import io
import json

import pandas as pd
import pytest

from asset2sim.flows import catalog_compare, catalog_finish
from asset2sim import flow_progress
from asset2sim.flows.catalog import ResultCatalog
from asset2sim.flows.catalog_config import RegressionSettings, ResultsSettings
from asset2sim.commands import _progress
from asset2sim.commands._progress import FlowProgress, eta_seconds
from asset2sim.flow_progress import ProgressEvent
from asset2sim.schemas.catalog import CatalogRow

RUN0, RUN1, RUN2 = "20260101T020000Z-000000", "20260102T020000Z-aaaaaa", "20260103T020000Z-bbbbbb"
ASSETS = {f"obj{i}": "Box" if i % 2 else "Laptop" for i in range(10)}


def _rows(failing: dict[str, str], penetration: float = 0.2) -> list[CatalogRow]:
    out = []
    for aid, cat in ASSETS.items():
        mode = failing.get(aid, "none")
        out.append(CatalogRow(asset_id=aid, category=cat, status="done", failure_mode=mode,
                              rest_stable=mode != "unstable", oscillation_pass=True, penetration_mm=penetration,
                              prompt_alignment=0.8, wall_seconds=2.0))  # fmt: skip
    return out


@pytest.fixture()
def store(tmp_path) -> ResultCatalog:
    s = ResultCatalog(tmp_path / "catalog")
    for r in _rows({"obj9": "oscillating"}):
        s.append_row("d", RUN1, r)
    # the next night: two assets made to fail, one fixed, penetration up by 0.5 mm
    for r in _rows({"obj0": "unstable", "obj1": "unresolved_penetration"}, penetration=0.7):
        s.append_row("d", RUN2, r)
    return s


def test_two_assets_made_to_fail_are_a_regression(store, tmp_path):
    cmp = catalog_compare.compare_with_previous(store, "d", RUN2)
    assert cmp.previous_run == RUN1 and cmp.common_assets == 10
    assert [(f.asset_id, f.direction, f.before, f.after) for f in cmp.flips] == [
        ("obj0", "regressed", "none", "unstable"),
        ("obj1", "regressed", "none", "unresolved_penetration"),
        ("obj9", "improved", "oscillating", "none"),
    ]
    assert (cmp.regressed, cmp.improved) == (2, 1)
    assert cmp.previous_pass_rate == pytest.approx(0.9) and cmp.pass_rate == pytest.approx(0.8)
    assert cmp.pass_rate_drift == pytest.approx(-0.1)
    pen = next(m for m in cmp.metrics if m.column == "penetration_mm")
    assert pen.drift == pytest.approx(0.5) and pen.worsening == pytest.approx(0.5) and not pen.exceeded
    stab = next(m for m in cmp.metrics if m.column == "rest_stable")
    assert stab.before == 1.0 and stab.after == pytest.approx(0.9) and stab.worsening == pytest.approx(0.1)
    assert cmp.exceeded and cmp.status == "regressed"
    assert "2 asset(s) no longer pass all checks (limit 0): obj0, obj1" in cmp.reasons[0]
    tags = cmp.tags()
    assert tags["regression.status"] == "regressed" and tags["regression.regressed_assets"] == "2"
    text = "\n".join(catalog_compare.comparison_lines(cmp))
    assert "REGRESSION" in text and "regressed obj0 (Laptop): none -> unstable" in text

    # limits that tolerate it, except the penetration drift
    loose = RegressionSettings(max_regressed_assets=2, max_pass_rate_drop=0.1, max_metric_drift={"penetration_mm": 0.25})
    cmp2 = catalog_compare.compare_with_previous(store, "d", RUN2, loose)
    assert cmp2.exceeded and len(cmp2.reasons) == 1 and "penetration_mm" in cmp2.reasons[0]
    looser = loose.model_copy(update={"max_metric_drift": {"penetration_mm": 1.0}})
    assert not catalog_compare.compare_with_previous(store, "d", RUN2, looser).exceeded
    typo = RegressionSettings(max_regressed_assets=5, max_pass_rate_drop=1.0, max_metric_drift={"penetraton": 1.0})
    assert "unknown metric" in catalog_compare.compare_with_previous(store, "d", RUN2, typo).reasons[0]


def test_the_first_run_and_a_subset_run(store):
    first = catalog_compare.compare_with_previous(store, "d", RUN1)
    assert first.previous_run is None and first.status == "no_previous_run" and not first.exceeded
    # a later run over two assets only compares those two
    for r in _rows({})[:2]:
        store.append_row("d", "20260104T020000Z-cccccc", r)
    sub = catalog_compare.compare_with_previous(store, "d", "20260104T020000Z-cccccc")
    assert sub.previous_run == RUN2 and sub.common_assets == 2 and sub.improved == 2 and not sub.exceeded


def test_finish_run_compacts_compares_and_writes_artifacts(store, tmp_path):
    out = tmp_path / "out"
    fin = catalog_finish.finish_run(store, "d", RUN2, out, ResultsSettings())
    assert fin.compaction.rows == 10 and fin.compaction.files_removed == 10 and not fin.errors
    assert [p.name for p in (store.root / "dataset=d" / f"run={RUN2}").glob("*.parquet")] == ["rows@compacted.parquet"]
    assert fin.comparison.regressed == 2
    data = json.loads((out / "comparison.json").read_text())
    assert data["status"] == "regressed" and data["previous_run"] == RUN1
    flips = pd.read_csv(out / "verdict_flips.csv")
    assert list(flips["asset_id"]) == ["obj0", "obj1", "obj9"]
    assert (out / "pass_rate_over_runs.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert set(fin.artifacts) == {"comparison.json", "verdict_flips.csv", "pass_rate_over_runs.png"}
    summary = catalog_compare.comparison_summary(fin.comparison)
    assert summary["exceeded"] and summary["regressed"] == 2 and summary["lines"][0].startswith("regression check")
    no_compact = catalog_finish.finish_run(store, "d", RUN1, out, ResultsSettings(compact=False))
    assert no_compact.compaction is None
    assert len(list((store.root / "dataset=d" / f"run={RUN1}").glob("obj*.parquet"))) == 10


def test_progress_lines_count_and_estimate():
    buf = io.StringIO()
    view = FlowProgress(live=False, stream=buf)
    with flow_progress.listening(view):
        flow_progress.emit(ProgressEvent("run_started", "d", RUN1, total=3))
        flow_progress.emit(ProgressEvent("asset_finished", "d", RUN1, asset_id="a", status="skipped", seconds=0.01))
        flow_progress.emit(ProgressEvent("asset_finished", "d", RUN1, asset_id="b", status="failed",
                                         failure_mode="timeout", seconds=8.0))
        flow_progress.emit(ProgressEvent("asset_finished", "d", RUN1, asset_id="c", status="done",
                                         failure_mode="none", seconds=2.0))
        flow_progress.emit(ProgressEvent("run_finished", "d", RUN1, total=3))
    flow_progress.emit(ProgressEvent("asset_finished", "d", RUN1, asset_id="late", status="done"))  # not listening
    lines = buf.getvalue().splitlines()
    assert lines[0] == f"run {RUN1} of dataset d: 3 assets; {_progress.STARTING}"  # said until the first asset finishes
    assert lines[2].startswith("[2/3] b: failed (timeout) 8.0 s | done 0, skipped 1, failed 1")
    assert lines[3].startswith("[3/3] c: done 2.0 s | done 1, skipped 1, failed 1") and "ETA 0 s" in lines[3]
    assert len(lines) == 4
    # the rate over worked assets: skipped ones do not make the estimate optimistic
    assert eta_seconds(10.0, 2, 4, worked=1) == pytest.approx(20.0)
    assert eta_seconds(10.0, 0, 4) is None


def test_a_failing_listener_never_disturbs_the_run():
    seen = []

    def broken(ev):
        raise RuntimeError("display gone")

    with flow_progress.listening(broken), flow_progress.listening(seen.append):
        flow_progress.emit(ProgressEvent("run_started", "d", RUN1, total=1))
    assert [e.kind for e in seen] == ["run_started"]


def test_the_live_bar_draws_counts(monkeypatch):
    buf = io.StringIO()
    view = FlowProgress(live=True, stream=buf)
    view(ProgressEvent("run_started", "d", RUN1, total=2))
    view(ProgressEvent("asset_finished", "d", RUN1, asset_id="a", status="done"))
    view(ProgressEvent("asset_finished", "d", RUN1, asset_id="b", status="failed"))
    view(ProgressEvent("run_finished", "d", RUN1, total=2))
    out = buf.getvalue()
    assert "2/2" in out and "done 1" in out and "failed 1" in out and "skipped 0" in out


def test_the_live_bar_quiets_terminal_log_lines_and_restores_them():
    import logging
    import sys

    handler = logging.StreamHandler(sys.stderr)
    handler.setLevel(logging.INFO)
    lg = logging.getLogger("a2s.test.progress")
    lg.addHandler(handler)
    try:
        view = FlowProgress(live=True, stream=io.StringIO())
        view(ProgressEvent("run_started", "d", RUN1, total=1))
        assert handler.level == logging.WARNING  # INFO lines would be written across the bar
        view(ProgressEvent("run_finished", "d", RUN1, total=1))
        assert handler.level == logging.INFO
    finally:
        lg.removeHandler(handler)
