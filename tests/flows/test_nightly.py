"""The nightly deployment: defined in the repository, registers with a cron
schedule in a configurable time zone, and runs the flow with the parameters
``make flow`` uses."""

from __future__ import annotations

import argparse
from pathlib import Path

import pytest

from asset2sim.flows.catalog import ResultCatalog
from asset2sim.flows.catalog_config import load_catalog

pytestmark = pytest.mark.slow  # end to end: the flows (Prefect, Dask, stage processes)

try:
    from .flowproject import make_project
except ImportError:
    from flowproject import make_project

REPO = Path(__file__).resolve().parents[2]


def _make_flow_parameters(catalog: Path, dataset: str | None, dask_address: str | None) -> dict:
    """The parameters `asset2sim flow` (make flow) passes to the flow."""
    from unittest import mock

    from asset2sim.commands import flow as flow_cmd

    captured = {}

    def fake_run(catalog, dataset=None, workers=None, dask_address=None, **kw):
        from asset2sim.flows.refine_flow import flow_parameters

        captured.update(flow_parameters(catalog, dataset, workers, dask_address))
        raise SystemExit(0)

    args = argparse.Namespace(
        catalog=catalog, dataset=dataset, workers=None, dask_address=dask_address, ids=None, limit=None,
        force=False, serve=False, cron=None, timezone=None, register_only=False,
    )  # fmt: skip
    with mock.patch("asset2sim.flows.refine_flow.run_refine_flow", fake_run), pytest.raises(SystemExit):
        flow_cmd.run(args)
    return captured


def test_schedule_comes_from_the_catalog_environment_and_arguments(monkeypatch):
    from asset2sim.flows.nightly import nightly_schedule

    s = nightly_schedule(REPO / "catalog.yaml")
    assert (s.cron, s.timezone, s.dataset, s.name) == ("0 2 * * *", "UTC", "demo", "nightly")
    monkeypatch.setenv("ASSET2SIM_TIMEZONE", "America/New_York")
    assert nightly_schedule(REPO / "catalog.yaml").timezone == "America/New_York"
    assert nightly_schedule(REPO / "catalog.yaml", timezone="Asia/Tokyo").timezone == "Asia/Tokyo"
    with pytest.raises(ValueError, match="time zone"):
        nightly_schedule(REPO / "catalog.yaml", timezone="Mars/Olympus")
    with pytest.raises(ValueError, match="cron"):
        nightly_schedule(REPO / "catalog.yaml", cron="61 2 * * *")


def test_nightly_registers_and_its_flow_runs_with_make_flow_parameters(tmp_path, prefect_server, dask_address):
    from prefect.client.orchestration import get_client
    from prefect.flows import load_flow_from_entrypoint

    from asset2sim.flows import nightly

    catalog = make_project(
        tmp_path,
        {"box_lid": "box_lid", "laptop": "laptop"},
        catalog_extra={
            "schedule": {"cron": "30 3 * * *", "timezone": "Europe/Berlin", "dataset": "gen"},
            "run": {"evaluate": False},
            "tracking": {"enabled": False},
        },
    )
    dep = nightly.build_nightly_deployment(catalog, dask_address=dask_address)
    dep_id = nightly.register_nightly(dep)
    with get_client(sync_client=True) as client:
        d = client.read_deployment_by_name(nightly.deployment_full_name(dep))
    assert str(d.id) == dep_id
    assert d.entrypoint == "asset2sim.flows.refine_flow.refine_dataset"
    [sched] = d.schedules
    assert sched.schedule.cron == "30 3 * * *" and sched.schedule.timezone == "Europe/Berlin"
    assert sched.active
    # the deployment stores exactly what `make flow DATASET=gen` passes
    assert d.parameters == _make_flow_parameters(catalog, "gen", dask_address)
    assert d.parameters["catalog"] == str(catalog.resolve())

    # the deployment's entrypoint is the flow, and it runs with those parameters
    fl = load_flow_from_entrypoint(d.entrypoint)
    summary = fl(**d.parameters)
    assert summary["dataset"] == "gen" and summary["assets"] == 2 and summary["done"] == 2
    df = ResultCatalog(load_catalog(catalog).catalog_root).read("gen", summary["run"])
    assert sorted(df["asset_id"]) == ["box_lid", "laptop"]


@pytest.mark.slow
def test_a_scheduled_flow_run_executes_through_the_runner(tmp_path, prefect_server, dask_address):
    """A flow run created from the deployment (as the scheduler does) executes
    in a separate process through Prefect's runner and completes."""
    import anyio
    from prefect.client.orchestration import get_client
    from prefect.deployments import run_deployment
    from prefect.runner import Runner

    from asset2sim.flows import nightly

    catalog = make_project(
        tmp_path,
        {"box_lid": "box_lid"},
        catalog_extra={"run": {"evaluate": False}, "tracking": {"enabled": False}},
    )
    dep = nightly.build_nightly_deployment(catalog, dask_address=dask_address, name="nightly-runner-test")
    nightly.register_nightly(dep)
    fr = run_deployment(nightly.deployment_full_name(dep), timeout=0, as_subflow=False)
    anyio.run(Runner().execute_flow_run, fr.id)
    with get_client(sync_client=True) as client:
        state = client.read_flow_run(fr.id).state
    assert state.is_completed(), state
    df = ResultCatalog(load_catalog(catalog).catalog_root).read("gen")
    assert list(df["asset_id"]) == ["box_lid"] and df["status"].iloc[0] == "done"


def test_serve_command_is_flow_serve(monkeypatch):
    """`asset2sim serve` (make serve) is `asset2sim flow --serve` with the same options."""
    from unittest import mock

    from asset2sim import cli
    from asset2sim.commands import flow as flow_cmd

    seen = {}

    def fake_serve(args, cat):
        seen.update(vars(args))
        return 0

    with mock.patch.object(flow_cmd, "_serve", fake_serve):
        rc = cli.main(["serve", "--catalog", str(REPO / "catalog.yaml"), "--timezone", "Europe/Berlin", "--register-only"])
    assert rc == 0 and seen["serve"] and seen["timezone"] == "Europe/Berlin" and seen["register_only"]


@pytest.mark.slow
def test_the_server_scheduler_creates_runs_of_the_nightly_deployment(tmp_path, monkeypatch):
    """Against a real `prefect server` (what `make serve` starts), the cron
    schedule produces scheduled flow runs. (Fails with SQLAlchemy 2.1, whose
    bulk-insert rules break Prefect 3.8's scheduler: pin sqlalchemy<2.1.)"""
    import time

    from prefect.client.orchestration import get_client
    from prefect.client.schemas.filters import DeploymentFilter, DeploymentFilterId
    from prefect.settings import PREFECT_API_URL, temporary_settings

    from asset2sim.flows import nightly, server

    catalog = make_project(tmp_path, {"box_lid": "box_lid"}, catalog_extra={"tracking": {"enabled": False}})
    monkeypatch.setenv("PREFECT_SERVER_SERVICES_SCHEDULER_LOOP_SECONDS", "5")
    monkeypatch.setenv("PREFECT_HOME", str(tmp_path / ".prefect"))
    proc, url = server.start_local_server(tmp_path)
    try:
        with temporary_settings({PREFECT_API_URL: url}):
            dep = nightly.build_nightly_deployment(catalog, cron="* * * * *", timezone="Europe/Berlin")
            dep_id = nightly.register_nightly(dep)
            deadline = time.monotonic() + 150
            runs = []
            with get_client(sync_client=True) as client:
                while time.monotonic() < deadline and not runs:
                    runs = client.read_flow_runs(
                        deployment_filter=DeploymentFilter(id=DeploymentFilterId(any_=[dep_id]))
                    )
                    if not runs:
                        time.sleep(3)
        assert runs, f"no scheduled run appeared; see {tmp_path / '.prefect' / 'server.log'}"
        assert all(r.state.is_scheduled() for r in runs)
        assert runs[0].parameters == nightly.nightly_parameters(catalog)
    finally:
        proc.terminate()
        proc.wait(timeout=30)
