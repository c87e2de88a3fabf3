"""One object, one reading, one verdict: for every output, each tier its failure mode names has its measurement in
``report.json``; ``report.json``, ``evaluation.json``, the catalog row and ``report.html`` give the same verdict and the
same failing checks; ``asset2sim evaluate`` on the folder gives the verdict the refine gave. On generated objects built
to pass and to fail (through the flow's stage functions, as the catalog gets them) and on every dev row."""

from __future__ import annotations

import csv
import json
import re

import pytest

from asset2sim import demo_assets
from asset2sim.flows.job_records import build_row
from asset2sim.flows.stages import AssetJob, metrics_stage, prepare_asset, refine_stage
from asset2sim.schemas.config import RefineConfig
from asset2sim.schemas.report import RefineReport
from asset2sim.tasks.check.verdict import TIERS, readiness
from asset2sim.tasks.evaluation.evaluate import evaluate_asset
from tests.conftest import SHARED, needs_shared

pytestmark = pytest.mark.slow  # end to end: the flow's stages, refines with media


def assert_one_verdict(report: RefineReport, folder) -> None:
    """The failure mode is readiness of report.json's own metrics, and every tier it names failing has a failing
    measurement there; evaluate on the folder measures the same metrics and gives the same verdict."""
    r = readiness(report.metrics)
    assert r.failure_mode == report.failure_mode and r.tiers == report.readiness
    for tier, failed in report.readiness.items():
        if failed is False:
            assert any(m.name in TIERS[tier][0] and m.passed is False for m in report.metrics), tier
    fresh = evaluate_asset(folder)
    assert fresh.failure_mode == report.failure_mode and fresh.failures == r.failures
    got = {(m.name, m.engine): (m.value, m.passed) for m in fresh.metrics}
    assert all(got.get((m.name, m.engine)) == (m.value, m.passed) for m in report.metrics)


@pytest.mark.parametrize("asset_id, prompt, mode", [
    ("box_lid", None, "none"),  # its manifest request and task
    ("box_lid", "A box with its lid open halfway; the lid swings freely.", "request_not_met"),  # a conflict named
    ("cabinet_2drawer", "A cabinet with its drawer open 120 percent.", "failing"),  # beyond its range: some tier fails
])
def test_report_evaluation_catalog_and_page_agree(asset_id, prompt, mode, demo_root, tmp_path):
    entry = next(e for e in demo_assets.DEMO_OBJECTS if e.asset_id == asset_id)
    job = AssetJob(dataset="demo", run_id="r1", asset_id=asset_id, prompt=prompt or entry.prompt,
                   asset_dir=str(demo_root / asset_id), out_dir=str(tmp_path / asset_id), work_dir=str(tmp_path / ".work"),
                   metrics_dir=str(tmp_path / "_metrics"), config=RefineConfig().model_dump(mode="json"), isolation="none")
    prepared = prepare_asset(job)
    refined = refine_stage(job, prepared)
    measured = metrics_stage(job, prepared, refined)
    report = refined.value.report
    assert report.failure_mode == mode or (mode == "failing" and report.failure_mode != "none"), report.readiness
    mode = report.failure_mode
    row = build_row(job, prepared, refined, measured)
    ev = json.loads((tmp_path / asset_id / "evaluation.json").read_text())
    page = (tmp_path / asset_id / "report.html").read_text()
    assert row.failure_mode == ev["failure_mode"] == report.failure_mode
    failures = readiness(report.metrics).failures
    assert ev["failures"] == failures and ev["metrics"][:len(report.metrics)] == [m.model_dump(mode="json") for m in report.metrics]
    badge = re.findall(r"<span class='badge (?:pass|fail)'>([^<]*)<", page)[0]
    assert badge.startswith("interaction-ready" if mode == "none" else f"NOT READY: {mode}")
    assert all(f in badge for f in failures)
    assert_one_verdict(report, tmp_path / asset_id)


@needs_shared
@pytest.mark.parametrize("row", list(csv.DictReader(open(SHARED / "manifest.csv"))) if SHARED.is_dir() else [],
                         ids=lambda r: r["id"])
def test_every_dev_row_is_judged_once(row, refine_once):
    res = refine_once(SHARED / row["id"], row["prompt"], extras=False)
    assert_one_verdict(res.report, res.out_dir)
