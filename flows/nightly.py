"""The nightly refinement: a Prefect deployment of the ``refine-dataset`` flow with the parameters of ``make
flow``, on a cron schedule evaluated in an IANA time zone; ``make serve`` (``asset2sim flow --serve``) registers
and serves it.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from asset2sim.flows.catalog_config import load_catalog
from asset2sim.flows.run_plan import flow_parameters
from asset2sim.flows.stages import FLOW_NAME


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

    sched = load_catalog(catalog).config.schedule
    cron = cron or os.environ.get("ASSET2SIM_CRON") or sched.cron
    tz = timezone or os.environ.get("ASSET2SIM_TIMEZONE") or sched.timezone
    try:
        ZoneInfo(tz)
    except (ZoneInfoNotFoundError, ValueError) as exc:
        raise ValueError(f"unknown time zone {tz!r} (use an IANA name such as UTC or Europe/Berlin)") from exc
    if len(cron.split()) != 5:
        raise ValueError(f"cron expression {cron!r} must have 5 fields (minute hour day month weekday)")
    try:
        from prefect.schedules import Cron
    except ImportError:  # without Prefect only the shape is checked
        pass
    else:
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
    return flow_parameters(catalog, dataset or nightly_schedule(catalog).dataset, workers, dask_address)


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

    # imported here, not at the top: it imports Prefect, which must not read its
    # settings before `asset2sim flow --serve` has pointed PREFECT_API_URL at a server
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
