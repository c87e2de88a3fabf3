"""Fixtures of the flow tests: a temporary Prefect server and a local Dask cluster; the project folder they
run on is :mod:`flowproject` (imported first: it keeps Prefect's state out of ~/.prefect)."""

from __future__ import annotations

import pytest

try:  # package layout (tests/flows/__init__.py) or rootdir-on-sys.path layout
    from . import flowproject  # type: ignore[no-redef]  # noqa: F401
except ImportError:
    import flowproject  # type: ignore[no-redef]  # noqa: F401


@pytest.fixture(scope="session")
def prefect_server():
    """A temporary Prefect server for the session (its URL)."""
    pytest.importorskip("prefect")
    pytest.importorskip("prefect_dask")
    from prefect.settings import PREFECT_API_URL
    from prefect.testing.utilities import prefect_test_harness

    with prefect_test_harness(server_startup_timeout=180):
        yield PREFECT_API_URL.value()


@pytest.fixture(scope="session")
def dask_address(prefect_server):
    """An existing local Dask scheduler (2 single-threaded worker processes)
    whose workers report to the test Prefect server."""
    from distributed import LocalCluster

    cluster = LocalCluster(
        n_workers=2,
        threads_per_worker=1,
        processes=True,
        dashboard_address="127.0.0.1:0",
        env={"PREFECT_API_URL": prefect_server},
    )
    try:
        yield cluster.scheduler_address
    finally:
        cluster.close()
