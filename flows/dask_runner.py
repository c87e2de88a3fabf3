"""The flow's Dask task runner: prefect-dask's ``DaskTaskRunner`` whose submissions are keyed without hashing
their arguments. Imports prefect-dask and distributed.

Dask names a submission by a hash of its function and arguments unless told it is impure
(``Client.submit(..., pure=False)``: the function's name and a fresh UUID). prefect-dask's runner submits every
Prefect task run as pure, and the arguments Dask then hashes hold the task, its parameters and Prefect's
serialized context (every setting of the run, dumped anew for each submission); a task run also carries a fresh
task-run UUID, so two submissions never share a key and the hash buys nothing. On the dev rows x 5 that hash was
about two thirds of the driver's CPU while it submitted (``py-spy`` on ``benchmarks/bench_flow.py``: 1,045 of
1,630 samples of ``Task.submit``, in ``dask.tokenize``), taken from the refines beside it
(``docs/design/pipeline.md``, "What the orchestration costs").
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

from prefect_dask import DaskTaskRunner
from prefect_dask.task_runners import PrefectDaskFuture

__all__ = ["FlowDaskTaskRunner"]


class FlowDaskTaskRunner(DaskTaskRunner):
    """``DaskTaskRunner`` that submits each task run as impure (``pure=False``: keyed by the task's name and a UUID,
    its arguments not hashed); everything else, the cluster, the client, futures, ``map`` and ``duplicate``, is
    prefect-dask's."""

    def submit(self, task, parameters: dict[str, Any], wait_for: Iterable[Any] | None = None,
               dependencies: dict[str, set] | None = None) -> PrefectDaskFuture:
        """Submit ``task`` with ``parameters`` (after ``wait_for``) to the Dask cluster as prefect-dask does, keyed
        without hashing; returns its future.

        Raises:
            RuntimeError: the runner was not started (entered).
        """
        if not self._started:
            raise RuntimeError("The task runner must be started before submitting work.")
        parameters = self._optimize_futures(parameters)
        wait_for = self._optimize_futures(wait_for) if wait_for else None
        future = self.client.submit(task, parameters=parameters, wait_for=wait_for, dependencies=dependencies,
                                    return_type="state", pure=False)
        return PrefectDaskFuture(wrapped_future=future, task_run_id=future.task_run_id)
