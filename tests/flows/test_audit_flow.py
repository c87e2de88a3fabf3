"""The audit flow: MJCF objects with planted errors audited as Prefect tasks on a Dask cluster, the catalog
written, one failed asset recorded without stopping the others, and the run in MLflow."""

from __future__ import annotations

from pathlib import Path

import pandas as pd
import pytest

from asset2sim.flows import audit_catalog
from tests.planted_assets import storage_box, write_mjcf, write_planted_folder

pytestmark = pytest.mark.slow  # end to end: the flows (Prefect, Dask, stage processes)

pytest.importorskip("mujoco")


def test_the_audit_flow_records_every_asset_and_logs_the_run(tmp_path, prefect_server, dask_address):
    from asset2sim.flows.audit_flow import audit_flow

    inputs = tmp_path / "in"
    expected = write_planted_folder(inputs)
    write_mjcf(inputs / "correct_box", "storage_box", storage_box())
    (inputs / "broken").mkdir()
    (inputs / "broken" / "ball.xml").write_text(
        "<mujoco><worldbody><body name='a'><joint type='ball'/><geom size='.1'/></body></worldbody></mujoco>")
    out = tmp_path / "out"
    summary = audit_flow([str(inputs)], str(out), simulate=False, dask_address=dask_address,
                         tracking_uri="sqlite:///" + str(tmp_path / "mlflow.db"))
    assert summary["assets"] == len(expected) + 2
    assert summary["failure_modes"]["audit_failed"] == 1 and summary["failure_modes"]["none"] == 1
    assert summary["failure_modes"]["implausible_values"] == len(expected)
    assets = pd.read_parquet(out / audit_catalog.ASSETS_PARQUET).set_index("asset_id")
    assert "ball.xml: cannot audit" in assets.loc["broken", "error"]
    for name, (where, quantity, _) in expected.items():
        assert f"{where}: {quantity}" in list(assets.loc[name, "implausible"]), name
    assert summary["implausible_by_quantity"]["mass"] >= 2

    from mlflow.tracking import MlflowClient

    client = MlflowClient(tracking_uri="sqlite:///" + str(tmp_path / "mlflow.db"))
    run = client.get_run(summary["mlflow_run_id"])
    assert run.data.metrics["assets"] == len(expected) + 2 and run.data.metrics["audit_failed"] == 1
    assert run.info.status == "FINISHED"
    artifacts = {Path(a.path).name for a in client.list_artifacts(run.info.run_id)}
    assert {audit_catalog.ASSETS_PARQUET, audit_catalog.VALUES_PARQUET} <= artifacts
