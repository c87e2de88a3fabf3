"""The end of a flow run: its partition compacted, the run compared with the
previous run of the dataset (two assets made to fail: a regression, exit
status 5 of ``asset2sim flow``, MLflow tags and artifacts), per-asset progress
lines, and the code version in the skip key (``results.code_change``)."""

from __future__ import annotations

import argparse
import csv
import json
from pathlib import Path

import pytest
import yaml

from asset2sim.flows.catalog import ResultCatalog
from asset2sim.flows.catalog_config import load_catalog
from asset2sim.tasks.publish import contract

pytestmark = pytest.mark.slow  # end to end: the flows (Prefect, Dask, stage processes)

try:
    from . import regressfakes  # type: ignore[no-redef]
    from .flowproject import make_project, write_manifest
except ImportError:
    import regressfakes  # type: ignore[no-redef]
    from flowproject import make_project, write_manifest

ASSETS = {"box_lid": "box_lid", "laptop": "laptop", "trash_can": "trash_can", "cabinet_2drawer": "cabinet_2drawer"}
FAILING = f"{regressfakes.__name__}:refine_failing"


def _args(catalog: Path, dask_address: str, **kw) -> argparse.Namespace:
    d = dict(catalog=catalog, dataset=None, workers=None, dask_address=dask_address, ids=None, limit=None,
             force=False, serve=False, cron=None, timezone=None, register_only=False, no_progress=False)  # fmt: skip
    d.update(kw)
    return argparse.Namespace(**d)


def _rows(catalog: Path, run: str) -> dict[str, dict]:
    df = ResultCatalog(load_catalog(catalog).catalog_root).read("gen", run)
    return {r["asset_id"]: r for r in df.to_dict("records")}


def _latest_run(catalog: Path) -> str:
    return ResultCatalog(load_catalog(catalog).catalog_root).runs("gen")[-1][1]


def _make_fail(catalog: Path, ids: set[str]) -> None:
    manifest = load_catalog(catalog).manifest_path("gen")
    with open(manifest, newline="") as fh:
        entries = list(csv.DictReader(fh))
    for e in entries:
        if e["id"] in ids:
            e["prompt"] = f"{e['prompt']} {regressfakes.FAIL_MARK}"
    write_manifest(manifest, entries)


def test_two_assets_made_to_fail_stop_make_flow_and_a_code_change_reruns(tmp_path, prefect_server, dask_address,
                                                                        capsys, monkeypatch):
    from mlflow.tracking import MlflowClient

    from asset2sim.commands import flow as flow_cmd
    from asset2sim.flows.refine_flow import run_refine_flow

    catalog = make_project(tmp_path, ASSETS, catalog_extra={"run": {"refine_function": FAILING, "time_limit_seconds": 120, "evaluate": False}})
    cat = load_catalog(catalog)

    # 1: every asset passes; nothing to compare with
    assert flow_cmd.run(_args(catalog, dask_address)) == 0
    out = capsys.readouterr().out
    run1 = _latest_run(catalog)
    assert f"run {run1} of dataset gen: 4 assets" in out  # the progress lines (not a terminal here)
    assert "[4/4] " in out and "done 4, skipped 0, failed 0" in out
    assert "no earlier run of dataset gen to compare with" in out
    part = cat.catalog_root / "dataset=gen" / f"run={run1}"
    assert sorted(p.name for p in part.iterdir()) == ["_run.json", "rows@compacted.parquet"]

    # 2: two assets made to fail (their requests changed); the other two are skipped
    _make_fail(catalog, {"box_lid", "laptop"})
    status = flow_cmd.run(_args(catalog, dask_address))
    out = capsys.readouterr().out
    assert status == 5, out
    run2 = _latest_run(catalog)
    rows = _rows(catalog, run2)
    assert {a: r["status"] for a, r in rows.items()} == {"box_lid": "failed", "laptop": "failed",
                                                         "trash_can": "skipped", "cabinet_2drawer": "skipped"}
    assert f"regression check against run {run1}: REGRESSION" in out
    assert "pass rate (all checks) 100.0% -> 50.0%" in out
    assert "regressed box_lid" in out and "regressed laptop" in out and "exit status 5" in out
    out_dir = cat.output_root / "gen" / run2
    comparison = json.loads((out_dir / "comparison.json").read_text())
    assert comparison["status"] == "regressed" and comparison["regressed"] == 2 and comparison["previous_run"] == run1
    assert (out_dir / "pass_rate_over_runs.png").is_file() and (out_dir / "verdict_flips.csv").is_file()
    info = json.loads((cat.catalog_root / "dataset=gen" / f"run={run2}" / "_run.json").read_text())
    assert info["regression"]["status"] == "regressed" and info["regression"]["regressed"] == 2
    client = MlflowClient(tracking_uri=cat.config.tracking.uri)
    mlrun = client.get_run(info["mlflow_run_id"])
    assert mlrun.data.tags["regression.status"] == "regressed"
    assert mlrun.data.tags["regression.previous_run"] == run1 and mlrun.data.tags["regression.regressed_assets"] == "2"
    assert mlrun.data.metrics["pass_rate_drift"] == pytest.approx(-0.5)
    names = {a.path for a in client.list_artifacts(info["mlflow_run_id"])}
    assert {"comparison.json", "verdict_flips.csv", "pass_rate_over_runs.png"} <= names
    # the Prefect UI shows the same run: a markdown artifact on the flow run naming the MLflow run
    from prefect.client.orchestration import get_client
    from prefect.client.schemas.filters import ArtifactFilter, ArtifactFilterKey

    with get_client(sync_client=True) as client_p:
        arts = client_p.read_artifacts(artifact_filter=ArtifactFilter(key=ArtifactFilterKey(any_=["asset2sim-run-summary"])))
    mine = [a for a in arts if str(a.flow_run_id) == info["flow_run_id"]]
    assert mine and info["mlflow_run_id"] in mine[0].data and "REGRESSION" in mine[0].data

    # with fail_flow off the same regression is reported, not an error
    config = yaml.safe_load(catalog.read_text())
    config["results"] = {"regression": {"fail_flow": False}}
    catalog.write_text(yaml.safe_dump(config, sort_keys=False))
    # 3: a code change (another hash of the package source): finished assets are redone (policy rerun)
    monkeypatch.setattr(contract, "code_hash", lambda: "f" * 16)
    assert flow_cmd.run(_args(catalog, dask_address, no_progress=True)) == 0
    out = capsys.readouterr().out
    assert "[1/4]" not in out and "no regression" in out  # the two failures failed before too
    rows = _rows(catalog, _latest_run(catalog))
    assert rows["trash_can"]["status"] == "done" and rows["cabinet_2drawer"]["status"] == "done"
    assert rows["trash_can"]["code_hash"] == "f" * 16

    # 4: another code change under `code_change: keep`: finished results are reused
    config["results"]["code_change"] = "keep"
    catalog.write_text(yaml.safe_dump(config, sort_keys=False))
    monkeypatch.setattr(contract, "code_hash", lambda: "e" * 16)
    summary = run_refine_flow(catalog, dask_address=dask_address)
    rows = _rows(catalog, summary["run"])
    assert rows["trash_can"]["status"] == "skipped" and rows["trash_can"]["code_hash"] == "f" * 16
    assert summary["regression"]["status"] == "ok"
