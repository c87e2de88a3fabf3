"""``asset2sim failures``: failure-mode breakdowns and other questions of the
Parquet result catalog (``make failures``)."""

from __future__ import annotations

import argparse
from pathlib import Path

from asset2sim import queries
from asset2sim.catalog import CatalogError, ResultCatalog, load_catalog

NAME = "failures"
HELP = "Print the failure-mode breakdown of the latest run (or --run) from the Parquet catalog, and other catalog queries."


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--catalog", type=Path, default=Path("catalog.yaml"), help="catalog file (default catalog.yaml)")
    parser.add_argument("--dataset", default=None, help="dataset (default: the dataset of the latest run)")
    parser.add_argument("--run", default="latest", help="run id, or 'latest' (default), or 'all'")
    parser.add_argument("--by", default="category", help="group by these columns, comma-separated (default category)")
    parser.add_argument("--over-time", action="store_true", help="pass rates per run, oldest first")
    parser.add_argument("--slowest", type=int, default=0, metavar="N", help="also list the N slowest assets")
    parser.add_argument("--changes", nargs=2, metavar=("RUN_A", "RUN_B"), help="assets whose verdict changed between two runs")


def run(args: argparse.Namespace) -> int:
    import pandas as pd


    try:
        cat = load_catalog(args.catalog)
    except CatalogError as exc:
        print(f"error: {exc}")
        return 2
    store = ResultCatalog(cat.catalog_root)
    df = store.read(args.dataset)
    if df.empty:
        print(f"the catalog {cat.catalog_root} has no rows" + (f" for dataset {args.dataset!r}" if args.dataset else "")
              + "; run `make flow` first")
        return 1
    pd.set_option("display.width", 200)
    pd.set_option("display.max_columns", 30)
    pd.set_option("display.max_colwidth", 80)

    if args.changes:
        try:
            ch = queries.verdict_changes(df, *args.changes)
        except KeyError as exc:
            print(f"error: {exc.args[0]}")
            return 2
        print(f"verdict changes {args.changes[0]} -> {args.changes[1]}: {len(ch)} asset(s)")
        if len(ch):
            print(ch[["asset_id", "category", "change"]].to_string(index=False))
        return 0

    if args.over_time:
        print(queries.pass_rates_over_time(df, args.dataset).to_string(index=False))
        return 0

    if args.run == "latest":
        dataset = args.dataset
        if dataset is None:  # the dataset of the most recent run of any dataset
            last = df.sort_values("started_at").iloc[-1]
            dataset = str(last["dataset"])
        df = df[df["dataset"] == dataset]
        run_id = queries.latest_run(df)
        df = df[df["run"] == run_id]
        scope = f"run {run_id} of dataset {dataset}"
    elif args.run == "all":
        scope = "all runs" + (f" of dataset {args.dataset}" if args.dataset else "")
        run_id = None
    else:
        run_id = args.run
        df = df[df["run"] == run_id]
        if df.empty:
            print(f"error: no run {run_id!r} in the catalog")
            return 2
        scope = f"run {run_id}"
    by = [b.strip() for b in args.by.split(",") if b.strip()]
    try:
        table = queries.failure_modes(df, by=by if len(by) > 1 else by[0])
    except KeyError as exc:
        print(f"error: {exc.args[0]}")
        return 2
    table = table.loc[:, (table != 0).any(axis=0)]
    s = queries.run_summary(df)
    print(f"failure modes of {scope}: {s['assets']} assets, {s['done']} done, {s['skipped']} skipped, {s['failed']} failed; "
          f"all checks passed {100 * (s['pass_rate_all'] or 0):.1f}%")
    print(table.to_string())
    failed = queries.failed_assets(df)
    if len(failed):
        print("\nassets that did not pass all checks:")
        print(failed.to_string(index=False))
    if args.slowest:
        print(f"\n{args.slowest} slowest assets:")
        print(queries.slowest_assets(df, args.slowest).to_string(index=False))
    return 0
