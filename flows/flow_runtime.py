"""Where a flow run executes: the Dask task runner (:func:`dask_task_runner`, a local cluster or a given
scheduler), Dask's settings for it (:data:`DASK_SETTINGS`) and the Prefect API a run talks to
(:func:`prefect_api_for_run`, a temporary server when none is configured). Imports Prefect.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import tempfile
from pathlib import Path
from typing import Any

from prefect.settings import PREFECT_API_URL

from asset2sim.flows import server


def dask_task_runner(workers: int | None, address: str | None, *, host: str = "127.0.0.1",
                      dashboard: bool = True):
    """A DaskTaskRunner (:class:`~asset2sim.flows.dask_runner.FlowDaskTaskRunner`, submissions keyed without
    hashing): the scheduler at ``address``, else a local cluster of ``workers`` single-threaded processes listening
    on ``host`` (dashboard on a free port when ``dashboard``)."""
    from asset2sim.flows.dask_runner import FlowDaskTaskRunner as DaskTaskRunner

    if address:
        return DaskTaskRunner(address=address)
    n = int(workers or os.cpu_count() or 1)
    api = _prefect_api_url()
    env = {"PREFECT_API_URL": api} if api else {}
    http_address = (host.strip("[]"), 0)  # a free port on ``host`` (docs/design/pipeline.md)
    return DaskTaskRunner(
        cluster_kwargs={
            "n_workers": n,
            "threads_per_worker": 1,
            "processes": True,
            "host": host,
            "dashboard_address": http_address if dashboard else None,
            "scheduler_kwargs": {} if dashboard else {"dashboard_address": http_address},
            "env": env,
        }
    )


#: Dask's own bookkeeping kept light on the flow's cluster: no profiler sampling every worker's stacks 100 times a
#: second, the event-loop tick, the system monitor and the nanny's memory monitor at 1-2 s instead of 20-500 ms (CPU a
#: refine needs; ``docs/design/pipeline.md``, "What the orchestration costs"). A cluster the flow is given gets them
#: from its machines' environment (:func:`dask_settings_env`, the guide's recipe for N machines).
DASK_SETTINGS: dict[str, Any] = {
    "distributed.worker.profile.enabled": False,
    "distributed.admin.tick.interval": "1s",
    "distributed.admin.system-monitor.interval": "2s",
    "distributed.worker.memory.monitor-interval": "1s",
}


def dask_settings_env() -> dict[str, str]:
    """:data:`DASK_SETTINGS` as the environment variables Dask reads (``DASK_DISTRIBUTED__WORKER__PROFILE__ENABLED``
    ...)."""
    return {"DASK_" + key.replace(".", "__").replace("-", "_").upper(): str(value).lower() if isinstance(value, bool) else str(value)
            for key, value in DASK_SETTINGS.items()}


@contextlib.contextmanager
def local_cluster_config(address: str | None, dashboard: bool, scratch_in: Path | str):
    """Dask configuration for a local cluster: :data:`DASK_SETTINGS`; without ``dashboard``, no HTTP routes on
    scheduler and workers; Dask's temporary folder (its workers' scratch space and lock files, else left in the
    user's TMPDIR) a new hidden folder in ``scratch_in`` (the run's own), removed when the block ends."""
    if address:
        yield
        return
    import dask

    Path(scratch_in).mkdir(parents=True, exist_ok=True)
    scratch = tempfile.mkdtemp(prefix=".dask-", dir=scratch_in)
    settings = {**DASK_SETTINGS, "temporary-directory": scratch}
    if not dashboard:
        settings.update({"distributed.scheduler.http.routes": [], "distributed.worker.http.routes": []})
    try:
        with dask.config.set(settings):
            yield
    finally:
        shutil.rmtree(scratch, ignore_errors=True)


def _prefect_api_url() -> str | None:
    """The Prefect API this process talks to (its temporary server when none is configured), or None."""
    try:
        url = PREFECT_API_URL.value()
        if not url:
            from prefect.server.api.server import SubprocessASGIServer

            server = SubprocessASGIServer()
            if not server.running:
                server.start()
            url = server.api_url
    except Exception:  # no server to share: workers fall back to their own
        return None
    return str(url) if url else None


@contextlib.contextmanager
def prefect_api_for_run(project_root: Path | str):
    """Yield the Prefect API URL of one flow run: the configured ``PREFECT_API_URL``, else a temporary server stopped
    when the block ends (main thread only). RuntimeError: it did not start (log: ``<project>/.prefect/server.log``)."""
    from prefect.settings import temporary_settings

    url = PREFECT_API_URL.value()
    if url:
        yield str(url)
        return
    timeout = float(os.environ.get("PREFECT_SERVER_EPHEMERAL_STARTUP_TIMEOUT_SECONDS", server.STARTUP_TIMEOUT))
    proc, url = server.start_local_server(project_root, timeout=timeout, ephemeral=True)
    try:
        with temporary_settings({PREFECT_API_URL: url}):
            try:
                yield url
            finally:  # Prefect's background log and event workers flushed before the server stops
                with contextlib.suppress(Exception):  # best effort: the catalog, not Prefect's log, is the record
                    from prefect.events.worker import EventsWorker
                    from prefect.logging.handlers import APILogWorker

                    APILogWorker.drain_all(timeout=5)
                    EventsWorker.drain_all(timeout=5)
    finally:
        server.stop_server(proc)
