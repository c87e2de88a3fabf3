"""``asset2sim failures``: failure-mode breakdowns and other questions of the
Parquet result catalog; each query reads only the runs and columns it needs.

Exit status: 0 printed, 1 the catalog has no rows, 2 the catalog file cannot be read or an option names no
run or column (one line, ``asset2sim failures: CODE: ...``).
"""

from __future__ import annotations

import argparse

from asset2sim.commands._status import CommandError, add_catalog, listed
from asset2sim.flows import catalog_compare, queries
from asset2sim.flows.catalog import NOTHING_TO_DO, ResultCatalog
from asset2sim.flows.catalog_config import load_catalog

NAME = "failures"
HELP = "Print the failure-mode breakdown of the latest run (or --run) from the Parquet catalog, and other catalog queries."

#: This command's exit statuses (``--help`` lists them with those of every command: 2 usage, 70, 130).
EXITS = {0: "printed", 1: "the catalog has no rows", 2: "the catalog cannot be read, or an option names no run or column"}

#: Columns the breakdown of a run reads besides the --by columns.
BREAKDOWN_COLUMNS = queries.COUNT_COLUMNS
#: Columns of the list of assets that did not pass all checks.
FAILED_COLUMNS = ("asset_id", "category", "status", "failure_mode", "error")
#: At most this many failed assets are listed.
MAX_LISTED = 50


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_catalog(parser)
    parser.add_argument("--dataset", help="dataset (default: the dataset of the latest run)")
    parser.add_argument("--run", default="latest", help="run id, or 'latest' (default), or 'all'")
    parser.add_argument("--by", default="category", help="group by these columns, comma-separated (default category)")
    parser.add_argument("--over-time", action="store_true", help="pass rates per run, oldest first")
    parser.add_argument("--slowest", type=int, default=0, metavar="N",
                        help="the N slowest assets of the run (--run; 'all': of every run)")
    parser.add_argument("--changes", nargs=2, metavar=("RUN_A", "RUN_B"), help="assets whose verdict changed between two runs")
    parser.add_argument("--compare", action="store_true", help=(
        "the run (--run, default latest) against the previous run of its dataset: "
        "verdict flips, pass-rate and metric drift (the flow's regression check)"))


def format_table(table) -> str:
    """A DataFrame of counts (index: one or more key levels) as fixed-width
    text, like ``DataFrame.to_string`` but in time linear in its size."""
    names = [str(n) if n is not None else "" for n in table.index.names]
    keys = [k if isinstance(k, tuple) else (k,) for k in table.index]
    body = [[str(v) for v in k] + [str(int(x)) for x in vals] for k, vals in zip(keys, table.to_numpy().tolist())]
    head = names + [str(c) for c in table.columns]
    widths = [max(map(len, column)) for column in zip(head, *body)]
    fmt = "  ".join(f"{{:<{w}}}" if i < len(names) else f"{{:>{w}}}" for i, w in enumerate(widths))
    return "\n".join(fmt.format(*cells).rstrip() for cells in [head, *body])


def latest_worked(store: ResultCatalog, dataset: str | None) -> tuple[tuple[str, str] | None, list[str]]:
    """((dataset, run) of the most recent run that refined anything, the later runs passed over): a rerun with
    nothing to do (``_run.json`` ``outcome`` ``nothing_to_do``: every asset reused) is passed over; a run without that
    record counts as one that worked. ((None), []) when the catalog has no run."""
    # the latest first (run ids start with the UTC start time)
    runs = sorted(store.runs(dataset), key=lambda p: (p[1], p[0]), reverse=True)
    passed: list[str] = []
    for ds, run in runs:
        if (store.run_info(ds, run) or {}).get("outcome") != NOTHING_TO_DO:
            return (ds, run), passed
        passed.append(run)
    return next(iter(runs), None), []


def run(args: argparse.Namespace) -> int:
    import pandas as pd

    cat = load_catalog(args.catalog)
    store = ResultCatalog(cat.catalog_root)
    if not store.runs(args.dataset):
        print(f"the catalog {cat.catalog_root} has no rows" + (f" for dataset {args.dataset!r}" if args.dataset else "")
              + "; run `make flow` first")
        return 1
    pd.set_option("display.width", 200, "display.max_columns", 30, "display.max_colwidth", 80)

    if args.changes:
        df = store.read(args.dataset, list(args.changes), columns=[*queries.CHANGE_COLUMNS])
        try:
            ch = queries.verdict_changes(df, *args.changes)
        except KeyError as exc:
            raise CommandError.invalid("RUN_UNKNOWN", f"--changes: {exc.args[0]}") from exc
        print(f"verdict changes {args.changes[0]} -> {args.changes[1]}: {len(ch)} asset(s)")
        if len(ch):
            print(ch[["asset_id", "category", "change"]].to_string(index=False))
        return 0

    if args.over_time:
        table = store.read_table(args.dataset, columns=[*queries.PASS_RATE_COLUMNS])
        rates = queries.pass_rates_over_time(table, args.dataset)
        if len(rates):  # each run's start to the minute, in UTC, not the raw timestamp (NaT / None: "-")
            rates["started_at"] = [t.strftime("%Y-%m-%d %H:%M UTC") if hasattr(t, "strftime") and t == t else "-"
                                   for t in rates["started_at"]]
        print(rates.to_string(index=False))
        return 0

    if args.run == "latest":
        (dataset, run_id), passed = latest_worked(store, args.dataset)
        runs: str | None = run_id
        scope = f"run {run_id} of dataset {dataset}"
        if passed:
            print(f"passed over {len(passed)} later run(s) with nothing to do (every asset reused): {', '.join(passed)}")
    elif args.run == "all":
        dataset, run_id, runs = args.dataset, None, None
        scope = "all runs" + (f" of dataset {args.dataset}" if args.dataset else "")
    else:
        run_id = runs = args.run
        found = [d for d, r in store.runs(args.dataset) if r == run_id]
        if not found:
            raise CommandError.invalid("RUN_UNKNOWN", f"--run: no run {run_id!r} in the catalog {cat.catalog_root}")
        dataset = args.dataset or found[0]
        scope = f"run {run_id}"

    if args.slowest:
        slow = queries.slowest_in_catalog(store, dataset, runs, args.slowest)
        if slow.empty:  # e.g. a rerun that reused every asset: none was worked on
            print(f"no asset was refined in {scope} (every result reused or none recorded): no timings")
            return 0
        print(f"{args.slowest} slowest assets of {scope}:")
        print(slow.to_string(index=False))
        return 0

    if getattr(args, "compare", False):
        if run_id is None or dataset is None:
            raise CommandError.invalid("USAGE_INVALID", "--compare needs one run (--run latest or a run id)")
        cmp = catalog_compare.compare_with_previous(store, dataset, run_id, cat.config.results.regression)
        print("\n".join(catalog_compare.comparison_lines(cmp)))
        return 0

    by = listed(args.by)
    try:
        # an Arrow table: the queries aggregate it in Arrow (fast on 10^6 rows)
        df = store.read_table(dataset, runs, columns=list(dict.fromkeys([*BREAKDOWN_COLUMNS, *[b for b in by if b not in ("dataset", "run")]])))
        table = queries.failure_modes(df, by=by if len(by) > 1 else by[0])
    except KeyError as exc:
        raise CommandError.invalid("COLUMN_UNKNOWN", f"--by: {exc.args[0]}") from exc
    table = table.loc[:, (table != 0).any(axis=0)]
    s = queries.status_counts(df)
    print(f"failure modes of {scope}: {s['assets']} assets, {s['done']} done, {s['skipped']} skipped, {s['failed']} failed; "
          f"all checks passed {100 * (s['pass_rate_all'] or 0):.1f}%")
    print(format_table(table))
    import pyarrow.dataset as pads

    not_passed = ~(pads.field("failure_mode") == "none") | pads.field("failure_mode").is_null()
    failed = queries.failed_assets(store.read_table(dataset, runs, columns=[*FAILED_COLUMNS], filter=not_passed,
                                                    limit=MAX_LISTED), limit=MAX_LISTED)
    n_failed = s["assets"] - s["failure_modes"].get("none", 0)
    if len(failed):
        print("\nassets that did not pass all checks:")
        print(failed.to_string(index=False))
        if n_failed > len(failed):
            print(f"... and {n_failed - len(failed)} more")
    return 0
