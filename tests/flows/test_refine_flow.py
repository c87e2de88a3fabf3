"""The refine-dataset flow on generated assets with local Dask clusters:
fan-out, failure recording, time limits, skip/redo, retries, catalog rows,
MLflow tracking, and the real refine pipeline end to end (slow)."""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest

from asset2sim.flows.catalog import ROW_COLUMNS, ResultCatalog
from asset2sim.flows.catalog_config import load_catalog
from asset2sim.schemas.overlay import Overlay
from asset2sim.tasks.publish.contract import read_report_json
from tests.helpers import assert_ready_or_honestly_not_robust, catalog_reader_counts

pytestmark = pytest.mark.slow  # end to end: the flows (Prefect, Dask, stage processes)

try:
    from . import flowfakes  # type: ignore[no-redef]
    from .flowproject import CALLS_PATH, make_project, write_manifest
except ImportError:
    import flowfakes  # type: ignore[no-redef]
    from flowproject import CALLS_PATH, make_project, write_manifest

GOOD = {"box_lid": "box_lid", "cabinet_2drawer": "cabinet_2drawer", "laptop": "laptop"}
BAD = {
    "broken_box": "broken",  # a mesh is missing: invalid input
    "hang_box": "box_lid",  # the refine function never returns: time limit
    "crash_box": "box_lid",  # the refine process aborts: crash
    "modelfail_box": "box_lid",  # estimator failure with the offline estimator: not retried
    "unstable_box": "trash_can",  # refined, but the post-check found it unstable
}
HANG_LIMIT = 8.0  # the hanging asset's own limit (manifest column); the others have 120 s


def _run(catalog: Path, **kw):
    from asset2sim.flows.refine_flow import run_refine_flow

    return run_refine_flow(catalog, **kw)


def _rows(catalog: Path, run: str | None = None) -> dict[str, dict]:
    cat = load_catalog(catalog)
    df = ResultCatalog(cat.catalog_root).read("gen", run)
    return {r["asset_id"]: r for r in df.to_dict("records")}


def _calls() -> list[dict]:
    return flowfakes.calls(CALLS_PATH)


@pytest.fixture(scope="module")
def first_run(tmp_path_factory, prefect_server):
    """One flow run over 3 good and 5 bad generated assets on a fresh local
    cluster of 2 workers (the default path: no scheduler address)."""
    CALLS_PATH.write_text("")
    root = tmp_path_factory.mktemp("flowproj")
    catalog = make_project(
        root,
        {**GOOD, **BAD},
        catalog_extra={"run": {"time_limit_seconds": 120}},
        time_limits={"hang_box": HANG_LIMIT},
    )
    summary = _run(catalog, workers=2)
    return catalog, summary, _calls()


def test_flow_refines_generated_assets_and_records_every_failure(first_run):
    catalog, summary, calls = first_run
    rows = _rows(catalog, summary["run"])
    assert set(rows) == set(GOOD) | set(BAD)  # one row per asset, none lost
    assert summary["assets"] == 8 and summary["done"] == 4 and summary["failed"] == 4
    for aid in GOOD:
        r = rows[aid]
        assert r["status"] == "done", r["error"]
        out = Path(r["out_dir"])
        assert out == load_catalog(catalog).output_root / "gen" / summary["run"] / aid
        for f in ("mobility.urdf", "report.json", "initial_state.json", "overlay.json"):
            assert (out / f).is_file(), f
        # the metrics stage's numbers are the ones in the row ...
        ev = json.loads((out.parent / "_metrics" / aid / "evaluation.json").read_text())
        pen = [m for m in ev["metrics"] if m["name"] == "penetration" and m["engine"] == "pybullet"][0]
        assert r["penetration_mm"] == pytest.approx(pen["value"])
        # ... and the verdict is the refine's, decided once (report.json), whatever the metrics stage measured
        assert r["failure_mode"] == json.loads((out / "report.json").read_text())["failure_mode"]
        stages = json.loads(r["stage_seconds"])
        assert {"prepare", "refine", "metrics", "refine.extract"} <= set(stages)
        assert r["scale"] == 0.5 and r["total_mass_kg"] == 1.25 and r["model_queries"] == 0 and r["tokens"] == 0
        assert r["prompt_alignment"] is not None and 0.0 <= r["prompt_alignment"] <= 1.0
        assert len(r["input_hash"]) == 64 and len(r["config_hash"]) == 16
        assert json.loads(r["initial_state"])  # joint -> value
    assert rows["broken_box"]["status"] == "failed" and rows["broken_box"]["failure_mode"] == "invalid_input"
    assert "obj" in rows["broken_box"]["error"]
    hang = rows["hang_box"]
    assert hang["failure_mode"] == "timeout" and "time limit" in hang["error"]
    assert HANG_LIMIT - 3 <= hang["wall_seconds"] <= HANG_LIMIT + 10
    crash = rows["crash_box"]
    assert crash["failure_mode"] == "crash" and "signal 6" in crash["error"]
    assert rows["modelfail_box"]["failure_mode"] == "estimator_failure"
    assert sum(c["asset_id"] == "modelfail_box" for c in calls) == 1  # offline: no retry
    assert rows["unstable_box"]["status"] == "done" and rows["unstable_box"]["failure_mode"] == "unstable"
    assert summary["failure_modes"]["invalid_input"] == 1 and summary["failure_modes"]["timeout"] == 1
    # two worker processes shared the work
    assert len({rows[a]["worker"] for a in rows if rows[a]["worker"]}) == 2


def test_catalog_partitions_run_info_and_artifacts(first_run):
    catalog, summary, _ = first_run
    cat = load_catalog(catalog)
    run_dir = cat.catalog_root / "dataset=gen" / f"run={summary['run']}"
    # the run's rows were compacted into one file when it ended
    assert [p.name for p in run_dir.glob("*.parquet")] == ["rows@compacted.parquet"]
    assert ResultCatalog(cat.catalog_root).recorded_assets("gen", summary["run"]) == set({**GOOD, **BAD})
    assert summary["compaction"]["rows"] == 8 and summary["compaction"]["files_removed"] == 8
    assert not list(run_dir.glob(".*"))  # no temporary files left behind
    info = json.loads((run_dir / "_run.json").read_text())
    assert info["status"] == "finished" and info["assets"] == 8 and info["mlflow_run_id"] == summary["mlflow_run_id"]
    df = ResultCatalog(cat.catalog_root).read("gen", summary["run"])
    assert list(df.columns) == [*ROW_COLUMNS, "dataset", "run"]
    out = Path(summary["output_dir"])
    import pandas as pd

    assert sorted(pd.read_csv(out / "summary.csv")["asset_id"]) == sorted({**GOOD, **BAD})
    assert (out / "failure_modes.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_mlflow_run_has_params_metrics_artifacts_and_nested_assets(first_run):
    from mlflow.tracking import MlflowClient

    catalog, summary, _ = first_run
    cat = load_catalog(catalog)
    client = MlflowClient(tracking_uri=cat.config.tracking.uri)
    run = client.get_run(summary["mlflow_run_id"])
    assert run.info.status == "FINISHED"
    assert run.data.params["dataset"] == "gen" and run.data.params["estimator"] == "offline"
    assert run.data.params["config_hash"] == cat.refine_config().config_hash()
    m = run.data.metrics
    assert m["assets"] == 8 and m["failures_timeout"] == 1 and m["failures_crash"] == 1
    assert m["pass_rate_all"] == pytest.approx(summary["pass_rate_all"])
    assert "queries_per_asset" in m and "penetration_mm_mean" in m
    arts = {a.path for a in client.list_artifacts(run.info.run_id)}
    assert {"summary.csv", "failure_modes.png"} <= arts
    exp = client.get_experiment_by_name("flowtest")
    children = client.search_runs([exp.experiment_id], f"tags.mlflow.parentRunId = '{run.info.run_id}'")
    assert sorted(c.data.tags["asset_id"] for c in children) == sorted({**GOOD, **BAD})
    by_id = {c.data.tags["asset_id"]: c for c in children}
    assert by_id["hang_box"].data.tags["failure_mode"] == "timeout"
    assert by_id["box_lid"].data.metrics["wall_seconds"] > 0
    # the run's true duration (the flow's planning to its end, Prefect and Dask start-up included), each asset's own
    span = (run.info.end_time - run.info.start_time) / 1000.0
    assert span >= summary["assets_seconds"] and run.data.tags["asset2sim.outcome"] == "worked"
    box = by_id["box_lid"].info
    # an asset's run spans its own work (its stages' wall time), not the time it waited for a worker
    assert abs((box.end_time - box.start_time) / 1000.0 - by_id["box_lid"].data.metrics["wall_seconds"]) <= 0.01
    info = json.loads((load_catalog(catalog).catalog_root / "dataset=gen" / f"run={summary['run']}" / "_run.json").read_text())
    assert run.info.start_time == round(info["requested_at"] * 1000)  # the flow run from when it was asked for
    assert "report.json" in {a.path for a in client.list_artifacts(box.run_id)}  # the asset's files, for a refined asset
    assert exp.tags["mlflow.experimentKind"] == "custom_model_development"  # the UI opens on the runs table


def test_rerun_skips_finished_assets_and_a_changed_request_redoes_only_that_one(first_run, dask_address):
    """Same input and configuration -> skipped (nothing recomputed, the earlier
    output reused); a changed prompt -> only that asset redone. Runs on an
    existing Dask scheduler given by address."""
    catalog, summary1, _ = first_run
    finished = [*GOOD, "unstable_box"]
    CALLS_PATH.write_text("")
    s2 = _run(catalog, ids=finished, dask_address=dask_address)
    rows2 = _rows(catalog, s2["run"])
    assert s2["run"] != summary1["run"] and s2["skipped"] == 4 and s2["done"] == 0
    # nothing to do: recorded as such, not compared (no drift figures), and never the run a later one is compared with
    assert s2["regression"]["status"] == "nothing_done" and not any(k.startswith("drift_") for k in s2)
    from mlflow.tracking import MlflowClient

    tracked = MlflowClient(tracking_uri=load_catalog(catalog).config.tracking.uri).get_run(s2["mlflow_run_id"])
    assert tracked.data.tags["asset2sim.outcome"] == "nothing_to_do" and "drift_wall_seconds" not in tracked.data.metrics
    rows1 = _rows(catalog, summary1["run"])
    for aid in finished:
        assert rows2[aid]["status"] == "skipped"
        assert rows2[aid]["source_run"] == summary1["run"]
        assert rows2[aid]["out_dir"] == rows1[aid]["out_dir"]
        assert rows2[aid]["failure_mode"] == rows1[aid]["failure_mode"]
        assert rows2[aid]["config_hash"] == rows1[aid]["config_hash"]
    assert _calls() == []  # the refine function was not called at all

    # change one request in the manifest
    cat = load_catalog(catalog)
    manifest = cat.manifest_path("gen")
    import csv

    with open(manifest, newline="") as fh:
        entries = list(csv.DictReader(fh))
    for e in entries:
        if e["id"] == "laptop":
            e["prompt"] = "I want a laptop with its screen halfway open."
    write_manifest(manifest, entries)
    CALLS_PATH.write_text("")
    s3 = _run(catalog, ids=finished, dask_address=dask_address)
    rows3 = _rows(catalog, s3["run"])
    assert s3["regression"]["previous_run"] == summary1["run"]  # the run that did nothing is passed over
    assert [c["asset_id"] for c in _calls()] == ["laptop"]
    assert rows3["laptop"]["status"] == "done" and rows3["laptop"]["source_run"] == s3["run"]
    assert rows3["laptop"]["config_hash"] != rows1["laptop"]["config_hash"]
    assert rows3["laptop"]["input_hash"] == rows1["laptop"]["input_hash"]
    assert {a: rows3[a]["status"] for a in finished if a != "laptop"} == {a: "skipped" for a in finished if a != "laptop"}
    # after the flows, their compaction and the reruns, each row lies in one visible file: read as a user would, once
    n = len(ResultCatalog(cat.catalog_root).read())
    assert n == len(rows1) + len(rows2) + len(rows3) and n >= 16
    assert catalog_reader_counts(cat.catalog_root) == {"pandas": n, "pyarrow": n, "duckdb": n}


def test_force_and_subsets_when_planning_a_run(first_run):
    """``--force`` plans without earlier results (everything is redone);
    ``--ids`` / ``--limit`` select assets; unknown ids are refused."""
    from asset2sim.flows.catalog_config import CatalogError
    from asset2sim.flows.run_plan import plan_run

    catalog, summary, _ = first_run
    cat = load_catalog(catalog)
    jobs = plan_run(cat, "gen", "20990101T000000Z-zzzzzz", ids=["box_lid", "laptop"]).jobs
    assert [j.asset_id for j in jobs] == ["box_lid", "laptop"] and all(j.finished for j in jobs)
    assert jobs[0].out_dir.endswith("gen/20990101T000000Z-zzzzzz/box_lid")
    forced = plan_run(cat, "gen", "20990101T000000Z-zzzzzz", ids=["box_lid"], force=True).jobs
    assert forced[0].finished == {}
    assert len(plan_run(cat, "gen", "20990101T000000Z-zzzzzz", limit=3).jobs) == 3
    assert {j.asset_id: j.time_limit_seconds for j in plan_run(cat, "gen", "r1").jobs}["hang_box"] == HANG_LIMIT
    with pytest.raises(CatalogError, match="unknown id"):
        plan_run(cat, "gen", "r1", ids=["nope"]).jobs


def test_model_call_failures_are_retried_and_nothing_else(tmp_path, dask_address, prefect_server):
    """With a model-backed estimator, a failing model call is retried (up to
    ``retries``); the asset that fails every time ends as estimator_failure."""
    catalog = make_project(
        tmp_path,
        {"flaky_box": "box_lid", "modelfail_box": "box_lid", "crash_box": "box_lid"},
        catalog_extra={
            "estimator": {"name": "fake-model", "model": "fake/model-1", "retries": 2, "retry_delay_seconds": 0},
            "run": {"evaluate": False, "time_limit_seconds": 60},
            "tracking": {"enabled": False},
        },
    )
    CALLS_PATH.write_text("")
    s = _run(catalog, dask_address=dask_address)
    rows = _rows(catalog, s["run"])
    n = {a: sum(c["asset_id"] == a for c in _calls()) for a in rows}
    assert rows["flaky_box"]["status"] == "done" and n["flaky_box"] == 2
    assert rows["flaky_box"]["model_queries"] == 2 and rows["flaky_box"]["estimator"] == "fake-model"
    assert rows["modelfail_box"]["failure_mode"] == "estimator_failure" and n["modelfail_box"] == 3
    assert rows["crash_box"]["failure_mode"] == "crash" and n["crash_box"] == 1  # a crash is not retried
    assert s["mlflow_run_id"] is None and s["tracking_error"] is None


@pytest.mark.slow
def test_flow_with_the_real_refine_pipeline_on_demo_assets(tmp_path, prefect_server):
    """End to end with ``asset2sim.tasks.refine.refine_asset`` and the metrics
    stage on two demo objects (closed-state detection exercised by the laptop)."""
    catalog = make_project(
        tmp_path,
        {"box_lid": "box_lid", "laptop": "laptop"},
        catalog_extra={
            "run": {
                "refine_function": "asset2sim.tasks.refine:refine_asset",
                "extras": False,
                "time_limit_seconds": 900,
            }
        },
    )
    s = _run(catalog, workers=2)
    rows = _rows(catalog, s["run"])
    # both workers' stage servers were started before the first asset: no asset paid for one
    assert s["stage_servers_seconds"] > 0
    assert not any("isolation.server_start" in json.loads(r["stage_seconds"]) for r in rows.values())
    for aid in ("box_lid", "laptop"):
        r = rows[aid]
        assert r["status"] == "done", r["error"]
        if aid == "box_lid":
            assert r["failure_mode"] == "none", r
        else:  # the laptop's slightly open screen: held at what a hand overcomes, which robust rest may say moves
            # (as tests/tasks/test_refine.py::test_demo_objects_refine_to_interaction_ready accepts)
            out = Path(r["out_dir"])
            assert_ready_or_honestly_not_robust(read_report_json(out), Overlay.model_validate_json((out / "overlay.json").read_text()))
            assert r["failure_mode"] in ("none", "not_robust_at_rest"), r
        assert r["rest_stable"] and r["oscillation_pass"]
        assert 0 < r["scale"] < 1 and r["total_mass_kg"] > 0
        report = json.loads((Path(r["out_dir"]) / "report.json").read_text())
        assert report["input_hash"] == r["input_hash"] and report["config_hash"] == r["refine_config_hash"]
    # slightly open laptop: modelled open at zero, closed at the lower limit
    q = json.loads(rows["laptop"]["initial_state"])["joint_1"]
    assert -1.83 < q < -1.2
    assert os.path.isfile(Path(s["output_dir"]) / "failure_modes.png")
