"""``asset2sim flow``: refine a dataset of ``catalog.yaml`` with the Prefect
flow (with a progress bar, then the run summary and the regression check), or
register and serve the nightly deployment (``--serve``). Exit status 5 when
the run regressed beyond ``catalog.yaml`` ``results.regression`` (``fail_flow``), else 0."""

from __future__ import annotations

import argparse
import contextlib
import os
import sys
import time

from asset2sim.commands._progress import FlowProgress
from asset2sim.commands._status import INVALID_INPUT, INVALID_REQUEST, REGRESSION, CommandError, add_catalog, listed
from asset2sim.flow_progress import listening
from asset2sim.commands import _output

NAME = "flow"
HELP = (
    "Refine a dataset declared in catalog.yaml (Prefect flow, Dask fan-out, Parquet catalog, MLflow); "
    "--serve registers and serves the nightly deployment."
)

#: This command's exit statuses (``--help`` lists them with those of every command: 2 usage, 70, 130).
EXITS = {
    0: "done",
    1: "a dataset or manifest that cannot be read",
    2: "the catalog cannot be used",
    4: "the output folders cannot be written",
    5: "the run regressed against the previous run",
}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_catalog(parser)
    parser.add_argument("--dataset", help="dataset of the catalog (default: its default_dataset)")
    parser.add_argument("--workers", type=int, help="local Dask workers (default: catalog run.workers)")
    parser.add_argument("--dask-address", "--scheduler", dest="dask_address", help=(
        "existing Dask scheduler (`dask scheduler`, dask-jobqueue, dask-kubernetes), e.g. tcp://host:8786 "
        "(default: $DASK_ADDRESS, else a local cluster); its workers need PREFECT_API_URL (docs/guide/pipeline.md)"))
    parser.add_argument("--dask-host", help=(
        "interface the local Dask cluster (scheduler, workers, dashboard) listens on "
        "(default: catalog run.dask_host, 127.0.0.1: this machine only)"))
    parser.add_argument("--no-dashboard", action="store_true",
                        help="no Dask dashboard (nor other HTTP pages) on the local cluster (default: catalog run.dashboard)")
    parser.add_argument("--out", help=(
        "output store: s3://bucket/prefix or any pyarrow/fsspec URI or path; workers refine locally and upload "
        "(default: catalog output_store, else output_root)"))
    parser.add_argument("--ids", help="comma-separated asset ids to run (default: all)")
    parser.add_argument("--limit", type=int, help="run at most this many assets")
    parser.add_argument("--force", action="store_true", help="redo assets even when a finished result exists")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar or per-asset lines")
    parser.add_argument("--serve", action="store_true", help="register the nightly deployment and serve it")
    parser.add_argument("--cron", help="with --serve: cron expression (default: catalog schedule.cron)")
    parser.add_argument("--timezone", help="with --serve: IANA time zone (default: catalog schedule.timezone)")
    parser.add_argument("--register-only", action="store_true", help="with --serve: register the deployment and exit")


def _fmt(v, pct: bool = False) -> str:
    if v is None:
        return "n/a"
    return f"{100 * v:.1f}%" if pct else (f"{v:.3g}" if isinstance(v, float) else str(v))


def run(args: argparse.Namespace) -> int:
    t0, t0_epoch = time.perf_counter(), time.time()
    from asset2sim.flows.catalog_config import load_catalog
    from asset2sim.flows.stages import prepare_prefect_environment

    cat = load_catalog(args.catalog)
    prepare_prefect_environment(cat.project_root)  # before Prefect is imported
    if args.serve:
        return _serve(args, cat)
    shown = not getattr(args, "no_progress", False)
    live = shown and _output.raw(sys.stdout).isatty()
    if live:  # the bar replaces Prefect's INFO lines in the terminal (here and in the workers)
        os.environ.setdefault("PREFECT_LOGGING_HANDLERS_CONSOLE_LEVEL", "WARNING")
    from asset2sim.flows.refine_flow import NOTHING_TO_DO, run_outcome, run_refine_flow  # imports Prefect: after its environment is set

    ids = listed(args.ids) if args.ids else None
    progress = FlowProgress(live=live)
    with contextlib.ExitStack() as stack:  # a full disk: status 4 naming the file (finished assets are kept)
        if shown:
            stack.enter_context(listening(progress))
        stack.callback(progress.close)
        summary = run_refine_flow(cat.path, args.dataset, args.workers, args.dask_address, ids=ids, limit=args.limit, force=args.force,
                                  out=getattr(args, "out", None), dask_host=getattr(args, "dask_host", None),
                                  dashboard=False if getattr(args, "no_dashboard", False) else None)
    total = time.perf_counter() - t0
    prefect_s = max(0.0, float(summary.get("flow_started_epoch") or t0_epoch) - t0_epoch)
    dask_s, servers_s, assets_s, tracking_s, media_s = (
        float(summary.get(f"{k}_seconds") or 0.0) for k in ("dask_startup", "stage_servers", "assets", "tracking", "media"))
    dask_s += float(summary.get("dask_teardown_seconds") or 0.0)
    worked = int(summary.get("done", 0)) + int(summary.get("failed", 0))
    if run_outcome(summary) == NOTHING_TO_DO:
        print(f"run {summary['run']} of dataset {summary['dataset']}: nothing to do: every asset ({summary['assets']}) finished "
              "before and was reused (recorded as skipped; `asset2sim failures` passes over this run, --force redoes them)")
    else:
        print(f"run {summary['run']} of dataset {summary['dataset']}: {summary['assets']} assets "
              f"({summary['done']} done, {summary['skipped']} skipped, {summary['failed']} failed)")
    print(f"  all checks passed: {_fmt(summary.get('pass_rate_all'), True)}; rest stability "
          f"{_fmt(summary.get('stability_pass_rate'), True)}; oscillation {_fmt(summary.get('oscillation_pass_rate'), True)}; "
          f"penetration {_fmt(summary.get('penetration_mm_mean'))} mm (mean); "
          f"queries/asset {_fmt(summary.get('queries_per_asset'))}")
    print("  failure modes: " + (", ".join(f"{k} {v}" for k, v in (summary.get("failure_modes") or {}).items() if v) or "none"))
    startup = (f"Prefect start-up {prefect_s:.1f} s" if summary.get("flow_run_id")
               else "no Prefect flow run (nothing to dispatch)")
    print(f"  wall time {total:.1f} s: {startup}, Dask start-up + tear-down {dask_s:.1f} s, "
          f"stage servers {servers_s:.1f} s, assets {assets_s:.1f} s"
          + (f" ({worked / assets_s * 60:.2f} assets/min)" if worked and assets_s > 0 else "")
          + f", summary + MLflow {tracking_s:.1f} s")
    if summary.get("media_made") is not None:  # catalog.yaml run.extras: deferred
        print(f"  media    {summary['media_made']} made after the verdicts in {media_s:.1f} s"
              + (f", {summary['media_failed']} left deferred (`asset2sim report OUT` makes them)" if summary.get("media_failed") else ""))
    print(f"  outputs  {summary.get('output_store') or summary['output_dir']}")
    print(f"  catalog  {summary['catalog_root']}")
    if summary.get("mlflow_run_id"):
        from asset2sim.flows.tracking import resolve_tracking_uri

        print(f"  MLflow   run {summary['mlflow_run_id']} in {resolve_tracking_uri(cat.project_root, cat.config.tracking.uri)}")
    elif summary.get("tracking_error"):
        print(f"  MLflow   not logged: {summary['tracking_error']}")
    regression = summary.get("regression") or {}
    for line in regression.get("lines", []):
        print(line)
    if regression.get("exceeded") and cat.config.results.regression.fail_flow:
        print(f"exit status {REGRESSION}: the run regressed beyond catalog.yaml results.regression "
              f"(comparison.json, verdict_flips.csv and pass_rate_over_runs.png in {summary['output_dir']})")
        return REGRESSION
    return 0


def _serve(args: argparse.Namespace, cat) -> int:
    from asset2sim.flows import nightly
    from asset2sim.flows import server as prefect_server

    try:
        sched = nightly.nightly_schedule(cat.path, cron=args.cron, timezone=args.timezone)
    except ValueError as exc:
        raise CommandError(INVALID_REQUEST, "SCHEDULE_INVALID", cat.path, str(exc)) from exc
    server = None
    if not os.environ.get("PREFECT_API_URL"):
        # schedules need a server's scheduler; start one before Prefect reads its settings
        print("starting a local Prefect server (PREFECT_API_URL is not set) ...")
        try:
            server, url = prefect_server.start_local_server(cat.project_root)
        except RuntimeError as exc:
            raise CommandError(INVALID_INPUT, "PREFECT_SERVER_FAILED", None, str(exc)) from exc
        os.environ["PREFECT_API_URL"] = url
        print(f"Prefect server at {url} (UI: {url[:-4]}); log in {cat.project_root / '.prefect' / 'server.log'}")
    try:
        deployment = nightly.build_nightly_deployment(cat.path, dataset=args.dataset, workers=args.workers, dask_address=args.dask_address,
                                                      cron=sched.cron, timezone=sched.timezone)
        from prefect import serve
        from prefect.settings import PREFECT_API_URL, temporary_settings

        with temporary_settings({PREFECT_API_URL: os.environ["PREFECT_API_URL"]}):
            dep_id = nightly.register_nightly(deployment)
            print(f"registered deployment {nightly.deployment_full_name(deployment)} ({dep_id}): "
                  f"cron '{sched.cron}' in {sched.timezone}, parameters {deployment.parameters}")
            if args.register_only:
                return 0
            print("serving; scheduled runs execute here (Ctrl-C to stop)")
            with contextlib.suppress(KeyboardInterrupt):
                serve(deployment, print_starting_message=False)  # the server's scheduler starts a run at each cron time
    finally:
        if server is not None:
            prefect_server.stop_server(server)
    return 0
