"""``asset2sim serve``: register the nightly deployment of the refine flow and
serve it (``make serve``); same as ``asset2sim flow --serve``."""

from __future__ import annotations

import argparse
from asset2sim.commands._status import add_catalog

NAME = "serve"
HELP = "Register the nightly deployment (cron schedule from catalog.yaml) with Prefect and serve it until interrupted."

#: This command's exit statuses (``--help`` lists them with those of every command: 2 usage, 70, 130).
EXITS = {0: "stopped", 2: "the catalog cannot be used"}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_catalog(parser)
    parser.add_argument("--dataset", help="dataset to refine nightly (default: catalog schedule.dataset)")
    parser.add_argument("--workers", type=int, help="local Dask workers (default: catalog run.workers)")
    parser.add_argument("--dask-address", help="existing Dask scheduler (default: $DASK_ADDRESS at run time)")
    parser.add_argument("--cron", help="cron expression (default: $ASSET2SIM_CRON, else catalog schedule.cron)")
    parser.add_argument("--timezone", help="IANA time zone (default: $ASSET2SIM_TIMEZONE, else catalog schedule.timezone)")
    parser.add_argument("--register-only", action="store_true", help="register the deployment and exit")


def run(args: argparse.Namespace) -> int:
    from asset2sim.commands import flow

    return flow.run(argparse.Namespace(**vars(args), serve=True, ids=None, limit=None, force=False))
