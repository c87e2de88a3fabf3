"""The nightly refinement: a Prefect deployment of the ``refine-dataset`` flow
on a cron schedule.

The deployment runs the same flow with the same parameters as ``make flow``
(:func:`asset2sim.flows.refine_flow.flow_parameters`: catalog path, dataset,
workers, Dask address); only the dataset defaults to ``schedule.dataset`` of
``catalog.yaml``. Schedule settings come from ``catalog.yaml``'s ``schedule``
section, overridden by the environment (``ASSET2SIM_CRON``,
``ASSET2SIM_TIMEZONE``) and then by explicit arguments. The time zone is an
IANA name (``UTC``, ``Europe/Berlin``); the cron expression is evaluated in it
(daylight-saving changes included).

``make serve`` calls :func:`serve_nightly`: it registers the deployment with
the Prefect server at ``PREFECT_API_URL`` (starting a local ``prefect server``
under the project when none is configured, since schedules need a server's
scheduler; it ends with the serving process, killed or not) and serves it
until interrupted, so scheduled runs execute in that process. The deployment's entrypoint is the module path
``asset2sim.flows.refine_flow.refine_dataset``.

Prefect is imported inside the functions.
"""

from __future__ import annotations

import os
import socket
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from asset2sim.catalog import load_catalog
from asset2sim.flows import lifeline
from asset2sim.flows.stages import FLOW_NAME, default_prefect_home, flow_parameters


@dataclass(frozen=True)
class NightlySchedule:
    """Cron expression, IANA time zone, deployment name and dataset of the nightly run."""

    cron: str
    timezone: str
    name: str
    dataset: str | None


def nightly_schedule(
    catalog: str | Path = "catalog.yaml", *, cron: str | None = None, timezone: str | None = None
) -> NightlySchedule:
    """The schedule of the nightly deployment (argument > environment > catalog).

    Raises:
        CatalogError: invalid catalog.
        ValueError: invalid cron expression or unknown time zone.
    """
    from zoneinfo import ZoneInfo, ZoneInfoNotFoundError

    cat = load_catalog(catalog)
    sched = cat.config.schedule
    cron = cron or os.environ.get("ASSET2SIM_CRON") or sched.cron
    tz = timezone or os.environ.get("ASSET2SIM_TIMEZONE") or sched.timezone
    try:
        ZoneInfo(tz)
    except (ZoneInfoNotFoundError, ValueError) as exc:
        raise ValueError(f"unknown time zone {tz!r} (use an IANA name such as UTC or Europe/Berlin)") from exc
    fields = cron.split()
    if len(fields) != 5:
        raise ValueError(f"cron expression {cron!r} must have 5 fields (minute hour day month weekday)")
    try:
        from prefect.schedules import Cron
    except ImportError:  # without Prefect only the shape is checked
        Cron = None
    if Cron is not None:
        try:
            Cron(cron, timezone=tz)
        except Exception as exc:
            raise ValueError(f"invalid cron expression {cron!r}: {exc}") from exc
    return NightlySchedule(cron=cron, timezone=tz, name=sched.deployment_name, dataset=sched.dataset)


def nightly_parameters(
    catalog: str | Path = "catalog.yaml",
    dataset: str | None = None,
    workers: int | None = None,
    dask_address: str | None = None,
) -> dict[str, Any]:
    """Parameters of the nightly deployment: exactly what ``make flow`` passes
    (:func:`~asset2sim.flows.refine_flow.flow_parameters`), with the dataset
    defaulting to ``schedule.dataset`` of the catalog."""
    dataset = dataset or nightly_schedule(catalog).dataset
    return flow_parameters(catalog, dataset, workers, dask_address)


def build_nightly_deployment(
    catalog: str | Path = "catalog.yaml",
    *,
    dataset: str | None = None,
    workers: int | None = None,
    dask_address: str | None = None,
    cron: str | None = None,
    timezone: str | None = None,
    name: str | None = None,
):
    """The nightly :class:`prefect.deployments.runner.RunnerDeployment` (not yet registered).

    Raises:
        CatalogError / ValueError: invalid catalog, cron expression or time zone.
    """
    from prefect.deployments.runner import EntrypointType
    from prefect.schedules import Cron

    from asset2sim.flows import refine_flow

    sched = nightly_schedule(catalog, cron=cron, timezone=timezone)
    params = nightly_parameters(catalog, dataset, workers, dask_address)
    return refine_flow.refine_dataset.to_deployment(
        name=name or sched.name,
        schedule=Cron(sched.cron, timezone=sched.timezone),
        parameters=params,
        description=f"Nightly refinement of dataset {params['dataset']!r} ({sched.cron}, {sched.timezone}).",
        tags=["asset2sim", "nightly"],
        entrypoint_type=EntrypointType.MODULE_PATH,
    )


def register_nightly(deployment) -> str:
    """Register (create or update) ``deployment`` with the Prefect API; returns
    its id. Raises whatever the Prefect client raises when no server answers."""
    return str(deployment.apply())


def deployment_full_name(deployment) -> str:
    """``<flow name>/<deployment name>`` as Prefect addresses it."""
    return f"{FLOW_NAME}/{deployment.name}"


def _free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def start_local_server(project_root: Path | str, port: int | None = None, timeout: float = 120.0, *,
                       ephemeral: bool = False):
    """Start a Prefect server bound to 127.0.0.1, state under
    ``<project>/.prefect`` (unless ``PREFECT_HOME`` is set), log in
    ``<project>/.prefect/server.log``; wait until its API answers. The server gets SIGKILL when this process ends, killed or
    not (:mod:`asset2sim.flows.lifeline`); call from the main thread.

    ``ephemeral`` False: ``prefect server start`` (scheduler and other
    services included, what ``serve`` needs). True: the API alone, as
    Prefect's temporary server runs it (``uvicorn`` on
    ``prefect.server.api.server:create_app``, UI off), what one flow run needs.

    Returns ``(process, api_url)``; the caller stops the process.

    Raises:
        RuntimeError: the server did not answer within ``timeout`` s (its log
            is ``<project>/.prefect/server.log``).
    """
    import urllib.request

    home = default_prefect_home(project_root)
    home.mkdir(parents=True, exist_ok=True)
    env = dict(os.environ)
    env.setdefault("PREFECT_HOME", str(home))
    env.setdefault("PREFECT_SERVER_ANALYTICS_ENABLED", "false")
    env.pop("PREFECT_API_URL", None)
    if ephemeral:
        env.update({"PREFECT_UI_ENABLED": "0", "PREFECT__SERVER_EPHEMERAL": "1", "PREFECT__SERVER_FINAL": "1"})
    log_path = home / "server.log"
    for attempt in range(3):  # a free port may be taken before the server binds it
        port_n = port or _free_port()
        if ephemeral:
            import prefect

            argv = [sys.executable, "-m", "uvicorn", "--app-dir", str(Path(prefect.__file__).parent.parent),
                    "--factory", "prefect.server.api.server:create_app", "--host", "127.0.0.1",
                    "--port", str(port_n), "--log-level", "error", "--lifespan", "on"]  # fmt: skip
        else:
            argv = [sys.executable, "-m", "prefect", "server", "start", "--host", "127.0.0.1", "--port", str(port_n)]
        with open(log_path, "ab") as log:
            proc = subprocess.Popen(
                lifeline.command(argv),
                stdout=log,
                stderr=subprocess.STDOUT,
                stdin=subprocess.DEVNULL,
                env=env,
                start_new_session=True,
            )
        url = f"http://127.0.0.1:{port_n}/api"
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if proc.poll() is not None:
                break
            try:
                with urllib.request.urlopen(url + "/health", timeout=2) as resp:
                    if resp.status == 200:
                        return proc, url
            except OSError:
                time.sleep(0.25)
        else:
            stop_server(proc)
            raise RuntimeError(f"prefect server did not answer at {url} within {timeout:.0f} s; see {log_path}")
        if port is not None or proc.returncode != 3 or attempt == 2:  # 3: uvicorn could not bind the port
            raise RuntimeError(f"prefect server exited with code {proc.returncode}; see {log_path}")
    raise RuntimeError(f"prefect server did not start; see {log_path}")  # not reached


def stop_server(proc, timeout: float = 20.0) -> None:
    """Stop a server of :func:`start_local_server`: SIGTERM, then SIGKILL
    after ``timeout`` s."""
    if proc.poll() is not None:
        return
    proc.terminate()
    try:
        proc.wait(timeout=timeout)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait(timeout=timeout)


def serve_nightly(deployment) -> None:
    """Register ``deployment`` and serve it (blocks until interrupted): the
    server's scheduler creates a run at each cron time and this process runs it.

    Requires ``PREFECT_API_URL`` to point at a Prefect server (see
    :func:`start_local_server`).
    """
    from prefect import serve

    serve(deployment, print_starting_message=False)
