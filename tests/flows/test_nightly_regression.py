"""The nightly deployment fails on a regression: the flow run the
deployment starts (``refine_dataset`` as Prefect runs it) ends in state
Failed with the regression report as its message when two assets flipped
to failing and ``results.regression.fail_flow`` is on; the same run with
``fail_flow`` off completes."""

from __future__ import annotations

import pytest
import yaml

from asset2sim.flows.catalog import ResultCatalog
from asset2sim.flows.catalog_config import load_catalog
from asset2sim.flows.run_plan import flow_parameters

pytestmark = pytest.mark.slow  # end to end: the flows (Prefect, Dask, stage processes)

try:
    from . import test_regression_flow as rf  # type: ignore[no-redef]
    from .flowproject import make_project
except ImportError:
    import test_regression_flow as rf  # type: ignore[no-redef]
    from flowproject import make_project


def test_a_regression_fails_the_nightly_flow_run(tmp_path, prefect_server, dask_address):
    from asset2sim.flows.refine_flow import refine_dataset
    from asset2sim.flows.stages import RegressionFailure

    catalog = make_project(tmp_path, rf.ASSETS, catalog_extra={
        "run": {"refine_function": rf.FAILING, "time_limit_seconds": 120, "evaluate": False},
        "tracking": {"enabled": False}})
    params = flow_parameters(catalog, "gen", None, dask_address)
    first = refine_dataset(**params, return_state=True)
    assert first.is_completed()

    rf._make_fail(catalog, {"box_lid", "laptop"})
    state = refine_dataset(**params, return_state=True)
    assert state.is_failed()
    assert "regressed beyond catalog.yaml results.regression" in state.message
    exc = state.result(raise_on_failure=False)
    assert isinstance(exc, RegressionFailure)
    assert "regressed box_lid" in str(exc) and "regressed laptop" in str(exc)
    assert exc.summary["regression"]["regressed"] == 2
    # everything was recorded before the run failed
    run2 = ResultCatalog(load_catalog(catalog).catalog_root).runs("gen")[-1][1]
    assert run2 == exc.summary["run"]
    rows = ResultCatalog(load_catalog(catalog).catalog_root).read("gen", run2)
    assert sorted(rows["asset_id"]) == sorted(rf.ASSETS)

    config = yaml.safe_load(catalog.read_text())
    config["results"] = {"regression": {"fail_flow": False}}
    catalog.write_text(yaml.safe_dump(config, sort_keys=False))
    rf._make_fail(catalog, {"trash_can"})
    state = refine_dataset(**params, return_state=True)
    assert state.is_completed()
    assert state.result()["regression"]["exceeded"]
