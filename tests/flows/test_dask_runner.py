"""The flow's Dask task runner keys each submission without hashing its arguments and runs tasks as
prefect-dask's does (a flow on the test Dask cluster)."""

from __future__ import annotations

import re

import pytest

pytestmark = pytest.mark.slow  # end to end: a Prefect flow on a Dask cluster

#: A key Dask draws for an impure submission: the function's name, then a UUID.
UUID_KEY = re.compile(r"-[0-9a-f]{8}-[0-9a-f]{4}-[0-9a-f]{4}-[0-9a-f]{4}-[0-9a-f]{12}$")


def test_submissions_are_keyed_by_uuid_and_run(dask_address):
    from prefect import flow, task

    from asset2sim.flows.dask_runner import FlowDaskTaskRunner
    from asset2sim.flows.flow_runtime import dask_task_runner

    assert isinstance(dask_task_runner(2, dask_address), FlowDaskTaskRunner)
    assert isinstance(dask_task_runner(2, None), FlowDaskTaskRunner)

    @task
    def double(x: int) -> int:
        return 2 * x

    @flow(task_runner=FlowDaskTaskRunner(address=dask_address))
    def two_alike() -> tuple[list[str], list[int]]:
        futures = [double.submit(21), double.submit(21)]  # the same task and arguments twice
        return [f.wrapped_future.key for f in futures], [f.result() for f in futures]

    keys, values = two_alike()
    assert values == [42, 42]
    assert keys[0] != keys[1]
    assert all(UUID_KEY.search(str(k)) for k in keys), keys  # hashed keys end in 32 hex digits, no dashes
