"""``asset2sim benchmark manifest.csv``: run methods on every manifest row,
evaluate each result, write the thesis table (CSV, JSON, HTML, Parquet) and an
index page, print the tables. Exit status 1 when ``--compare`` finds a
difference from an earlier run (timings excluded), 4 when the output cannot be written, else 0.
"""

from __future__ import annotations

import argparse
import json
import math
import statistics
from pathlib import Path

from asset2sim.commands._status import listed, parse_engines
from asset2sim.tasks.evaluation.benchmark_pages import _PASS_RATES as PASS_RATES
from asset2sim.apps.benchmark.benchmark import RESEARCH_NUMBERS, benchmark_tables, run_benchmark, write_benchmark_outputs
from asset2sim.commands import _output
from asset2sim.atomic import jsonable
from asset2sim.inert import markup

NAME = "benchmark"
HELP = "Run methods (defaults, human, direct, asset2sim) on a manifest, evaluate each, write the thesis table and an index page."

#: This command's exit statuses (``--help`` lists them with those of every command: 2 usage, 70, 130).
EXITS = {0: "done", 1: "--compare found a difference from the earlier run", 4: "the output cannot be written"}

#: Record fields excluded from the reproducibility comparison (wall times; the report link, absent with --no-reports).
TIMING_FIELDS = ("seconds", "method_seconds", "report")


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("manifest", type=Path, help="manifest.csv (id, category, prompt, ..., reference_scale)")
    p.add_argument("--methods", default="defaults,human,direct,asset2sim", help="comma-separated methods")
    p.add_argument("--out", type=Path, default=Path("bench"), help="output folder (default bench/)")
    p.add_argument("--ids", help="comma-separated manifest ids to run (default all)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--engines", default="pybullet", help="comma-separated evaluation engines")
    p.add_argument("--no-reports", action="store_true", help="skip the per-asset report.html files")
    p.add_argument("--compare", type=Path, help="results.json of an earlier run to check reproducibility against")


def compare_records(a: list[dict], b: list[dict], rel: float = 1e-9) -> list[str]:
    """Differences between two runs' records, timings excluded (strings)."""
    ia, ib = ({(r["method"], r["id"]): r for r in records} for records in (a, b))
    diffs = []
    for k in sorted(set(ia) | set(ib)):
        if k not in ia or k not in ib:
            diffs.append(f"{k}: only in one run")
            continue
        for f in sorted((set(ia[k]) | set(ib[k])) - set(TIMING_FIELDS)):
            x, y = ia[k].get(f), ib[k].get(f)
            floats = isinstance(x, float) and isinstance(y, float)
            if not (math.isclose(x, y, rel_tol=rel, abs_tol=1e-12) if floats else x == y):
                diffs.append(f"{k} {f}: {x!r} vs {y!r}")
    return diffs


def _print_table(console, title: str, summary: dict) -> None:
    from rich.table import Table

    t = Table("method", "pen. mm (toilet+stapler)", "pen. mm (all)", "rest pass", "osc. pass", "probes pass", "sweep pass",
              "robust rest pass", "task pass", "force plausible", "ready", "scale dev. %", "init. dev.", "prompt", "all pass",
              "median eval s", "realism", "failed", title=title)

    def pm(m, s):
        return "-" if m is None else f"{m:.3g} +- {s:.3g}"

    def pct(x):
        return "-" if x is None else f"{100 * x:.1f}%"

    for method, r in summary.items():
        t.add_row(markup(method), pm(r["pen_ts_mean"], r["pen_ts_sd"]), pm(r["pen_mean"], r["pen_sd"]),
                  *(f"{pct(r.get(rate))} ({r.get(n, 0)})" for rate, n in PASS_RATES),
                  pm(r["scale_mean"], r["scale_sd"]), pm(r["init_mean"], r["init_sd"]),
                  pct(r["prompt_mean"]), pct(r["all_pass"]), "-" if r["median_seconds"] is None else f"{r['median_seconds']:.2f}",
                  markup(r.get("realism", "not rated")), str(r["errors"]))
    console.print(t)


def run(args: argparse.Namespace) -> int:
    from rich.table import Table

    from asset2sim.apps.realism.pair_set import PairSetError
    from asset2sim.apps.realism.scores import NOT_RATED, realism_column

    console = _output.console(width=180)
    methods = listed(args.methods)
    ids = [i.strip() for i in args.ids.split(",")] if args.ids else None
    engines = tuple(parse_engines(args.engines))
    out = args.out

    def progress(method: str, rid: str, msg: str) -> None:
        console.print(f"[bold]{markup(method)}[/bold] {markup(rid)}: {markup(msg)}")

    records = jsonable(run_benchmark(args.manifest, methods, out, rows=ids, seed=args.seed, engines=engines,
                                     reports=not args.no_reports, progress=progress))  # strict JSON, as results.json holds them
    tables = benchmark_tables(records, methods)
    try:  # the Bradley-Terry scores of OUT/realism (`asset2sim pairs OUT`, then rate or judge), never invented ones
        realism = realism_column(out / "realism", methods)
    except PairSetError as exc:
        realism = {m: f"{NOT_RATED} ({exc})" for m in methods}
    for summary in tables.values():
        for method, row in summary.items():
            row["realism"] = realism[method]
    meta = {"manifest": str(args.manifest), "methods": methods, "seed": args.seed, "rows": len({r["id"] for r in records}),
            "engines": list(engines)}
    write_benchmark_outputs(records, methods, out, meta)
    if meta.get("parquet_error"):
        console.print(f"[yellow]results.parquet not written: {markup(meta['parquet_error'])}[/yellow]")
    for title, summary in tables.items():
        _print_table(console, title, summary)
    rt = Table(*RESEARCH_NUMBERS[0], title="research numbers (thesis 9-object set, Isaac Sim)")
    for r in RESEARCH_NUMBERS:
        rt.add_row(*r.values())
    console.print(rt)
    secs = [r["seconds"] for r in records if not r.get("error") and r.get("seconds") is not None]
    if secs:
        console.print(f"median evaluation time per asset: {statistics.median(secs):.2f} s over {len(secs)} evaluations (goal <= 1.5 s; "
                      f"method runs, report writing and start-up excluded)")
    console.print(f"wrote {out / 'summary.html'}, {out / 'index.html'}, results.csv/json/parquet, summary.csv/json", markup=False)
    if args.compare is not None:
        diffs = compare_records(json.loads(Path(args.compare).read_text())["records"], records)
        if diffs:
            console.print(f"[red]{len(diffs)} differences from {markup(args.compare)}:[/red]")
            for d in diffs[:50]:
                console.print(f"  {markup(d)}")
            return 1
        console.print(f"[green]same results as {markup(args.compare)} (timings excluded)[/green]")
    return 0
