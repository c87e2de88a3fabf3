"""The flow's stage functions in this process (no Prefect, no Dask): each
asset is read once and its rest test runs once, and the metrics stage reads
refine's evaluation instead of evaluating again."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from asset2sim import demo_assets
from asset2sim.flows import stages
from asset2sim.flows.stages import AssetJob, metrics_stage, prepare_asset, refine_stage
from asset2sim.schemas.config import RefineConfig
from asset2sim.tasks.check import metrics as check_metrics
from asset2sim.tasks.evaluation import evaluate
from asset2sim.tasks.ingest import extract
from asset2sim.flows.job_records import Prepared
from tests.helpers import rest_tests_of_refine

pytestmark = pytest.mark.slow  # end to end: the flows (Prefect, Dask, stage processes)


def _job(root, tmp_path, extras: bool, asset_id: str = "box_lid") -> AssetJob:
    entry = next(e for e in demo_assets.DEMO_OBJECTS if e.asset_id == asset_id)
    run = tmp_path / ("extras" if extras else "plain")
    return AssetJob(
        dataset="demo", run_id="r1", asset_id=asset_id, prompt=entry.prompt, asset_dir=str(root / asset_id),
        out_dir=str(run / asset_id), work_dir=str(run / ".work" / asset_id), metrics_dir=str(run / "_metrics" / asset_id),
        config=RefineConfig().model_dump(mode="json"), extras=extras, isolation="none",
    )  # fmt: skip


@pytest.fixture
def counters(monkeypatch, demo_root):
    """Calls of: reading an input asset (the evaluator's reading of a written
    output URDF is not one), the rest test, the evaluation in the metrics stage."""
    counts = {"extract": 0, "rest_test": 0, "evaluate": 0}
    real = (extract.extract_asset_checked, check_metrics.run_rest_test, evaluate.evaluate_asset)

    def wrap(key, fn):
        def counted(*a, **k):
            if key != "extract" or Path(a[0]).resolve().parent == demo_root.resolve():
                counts[key] += 1
            return fn(*a, **k)

        return counted

    monkeypatch.setattr(extract, "extract_asset_checked", wrap("extract", real[0]))
    monkeypatch.setattr(stages, "extract_asset_checked", wrap("extract", real[0]))
    monkeypatch.setattr(check_metrics, "run_rest_test", wrap("rest_test", real[1]))
    monkeypatch.setattr(stages, "evaluate_asset", wrap("evaluate", real[2]))
    return counts


def test_each_asset_is_read_once_and_rest_tested_once(demo_root, tmp_path, counters):
    job = _job(demo_root, tmp_path, extras=True, asset_id="laptop")
    prepared = prepare_asset(job)
    assert prepared.ok and prepared.asset is not None and counters["extract"] == 1
    refined = refine_stage(job, prepared)
    assert refined.status == "ok", refined.error
    report = refined.value.report
    assert counters["extract"] == 1  # refine used the prepared reading
    # the post-check's rest tests (tests.helpers.rest_tests_of_refine), none in the extras: the extras'
    # evaluation presents the record
    assert counters["rest_test"] == rest_tests_of_refine(report)
    measured = metrics_stage(job, prepared, refined)
    assert measured.status == "ok", measured.error
    assert measured.value.reused_evaluation and counters["evaluate"] == 0
    assert counters["rest_test"] == rest_tests_of_refine(report)
    refined_ev = (refined.value.out_dir + "/evaluation.json")
    assert json.loads(open(refined_ev).read()) == json.loads(open(job.metrics_dir + "/evaluation.json").read())


def test_metrics_stage_columns_equal_with_and_without_refines_evaluation(demo_root, tmp_path, counters):
    """Extras off: the metrics stage evaluates the output with the checks refine ran; its catalog columns equal those
    read from refine's evaluation."""
    on, off = _job(demo_root, tmp_path, extras=True), _job(demo_root, tmp_path, extras=False)
    cols = {}
    for job in (on, off):
        prepared = prepare_asset(job)
        refined = refine_stage(job, prepared)
        cols[job.extras] = metrics_stage(job, prepared, refined).value
    assert cols[True].reused_evaluation and not cols[False].reused_evaluation
    assert counters["evaluate"] == 1
    assert cols[True].columns == cols[False].columns


def test_prepared_carries_the_extracted_asset_as_json(demo_root, tmp_path):
    """What crosses the isolation boundary (JSON) comes back equal."""
    prepared = prepare_asset(_job(demo_root, tmp_path, extras=False, asset_id="cabinet_2drawer"))
    back = Prepared.model_validate_json(prepared.model_dump_json())
    assert back == prepared and back.asset == prepared.asset and back.findings == prepared.findings
