"""``asset2sim evaluate ASSET``: evaluate any URDF asset with the checks a refine runs (a refined output with the
closed ends and request its report.json records), write evaluation.json and report.html (beside the asset unless
``--out``), print a verdict table.

Exit status: 0 interaction-ready, 1 a tier of the verdict fails, 2 the asset cannot be evaluated, 4 the output cannot
be written.
"""

from __future__ import annotations

import argparse
import functools
from dataclasses import dataclass
from pathlib import Path

from asset2sim.commands._status import check_out, parse_engines
from asset2sim.tasks.evaluation.evaluate import evaluate_asset
from asset2sim.tasks.check.as_asked import as_asked_lines
from asset2sim.tasks.check.failure_reasons import why_it_failed
from asset2sim.tasks.check.verdict import readiness
from asset2sim.tasks.publish.contract import read_report_json
from asset2sim import output_folder
from asset2sim.commands import _output
from asset2sim.inert import markup, terminal

NAME = "evaluate"
HELP = ("Evaluate an asset (any URDF) with the checks a refine runs: physical robustness, manipulation, as asked, semantic "
        "accuracy; writes evaluation.json and report.html.")

#: This command's exit statuses (``--help`` lists them with those of every command: 2 usage, 70, 130).
EXITS = {
    0: "interaction-ready: every tier of the verdict passes",
    1: "a tier of the verdict fails",
    2: "the asset cannot be evaluated",
    4: "the output cannot be written",
}


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("asset", type=Path, help="asset folder (mobility.urdf, initial_state.json ...) or a URDF file")
    p.add_argument("--reference", type=Path, help="PartNet-Mobility folder with reference_gensim2.json/.urdf")
    p.add_argument("--prompt", help=(
        "the request the asset should satisfy (default for a refined output folder: the request its report.json "
        "records, so the output is graded as refine graded it)"))
    p.add_argument("--category", help="object category (default: from the asset's files)")
    p.add_argument("--engines", help=(
        "comma-separated engines, the manipulation tiers measured in each (default: as refine checks: the tiers in "
        "PyBullet, the rest metrics in the engines a refined folder's report.json names, else PyBullet alone)"))
    p.add_argument("--out", type=Path,
                   help="where to write evaluation.json and report.html (default: a folder beside the asset, ASSET-evaluation; "
                        "never the asset folder itself unless named here)")
    p.add_argument("--no-report", action="store_true", help="do not write report.html")
    p.add_argument("--no-probes", action="store_true", help="skip the passive probes (reported beside the verdict, never deciding it)")
    p.add_argument("--no-clips", action="store_true", help="with the report: skip the clips of each task-relevant joint's sweep (clips/)")
    p.add_argument("--task",
                   help='the manipulation task, e.g. "close the microwave door": the task tier performs it, the probes try its part '
                        'and direction (default for a refined output folder: the task its report.json records)')
    p.add_argument("--seed", type=int, default=0)


#: Terminal columns from which the verdict table shows each metric's threshold.
WIDE_TABLE = 120


def default_out(asset: Path) -> Path:
    """Where ``evaluate`` writes without ``--out``: ``<folder>-evaluation`` beside the asset's folder."""
    folder = asset if asset.is_dir() else asset.parent
    return folder.parent / f"{folder.resolve().name}-evaluation"


@dataclass(frozen=True, slots=True)
class EvaluatedRequest:
    """The request an evaluation grades (:func:`refined_request`): ``prompt``, ``task`` and ``taken_from`` (where
    a request taken from the folder came from, one line; "" when none was taken)."""

    prompt: str | None
    task: str | None
    taken_from: str = ""


def refined_request(asset: Path, prompt: str | None, task: str | None) -> EvaluatedRequest:
    """The prompt and task for evaluating ``asset``: those given, else, for a refined output folder, the
    request and task its ``report.json`` records (the evaluation then grades what refine graded)."""
    try:
        report = None if prompt is not None else read_report_json(asset if asset.is_dir() else asset.parent)
    except (OSError, ValueError):  # not a refined output: evaluated as given
        report = None
    if report is None or not report.prompt:
        return EvaluatedRequest(prompt, task)
    return EvaluatedRequest(report.prompt, task if task is not None else report.task,
                            f"'{report.prompt}' (from report.json; --prompt gives another)")


def run(args: argparse.Namespace) -> int:
    from rich.table import Table

    # a terminal: its width (the threshold column wraps); a pipe or file: lines kept whole for grep
    console = _output.console()
    say = functools.partial(console.print, markup=False, soft_wrap=True)  # lines of text, kept whole
    out = args.out = args.out or default_out(args.asset)
    engines = tuple(parse_engines(args.engines)) if args.engines else None
    check_out(out, [args.asset], adopt=True)  # never into the input, but into a refined folder (its own files then)
    req = refined_request(args.asset, args.prompt, args.task)
    with output_folder.adopting(out):
        ev = evaluate_asset(args.asset, reference=args.reference, prompt=req.prompt, engines=engines, seed=args.seed,
                            category=args.category, out_dir=out, write_report=not args.no_report, probes=not args.no_probes,
                            task=req.task, clips=not args.no_clips)
    ready = readiness(list(ev.metrics))
    table = Table(title=f"{markup(ev.asset_id)} ({markup(ev.category or 'no category')}): {markup(ready.short())}")
    wide = console.width >= WIDE_TABLE  # a narrow terminal gets the table without the thresholds' column
    for col in ("metric", "engine", "value", "unit", "verdict"):
        table.add_column(col, no_wrap=True)
    if wide:
        table.add_column("threshold")
    for m in ev.metrics:
        verdict = "-" if m.passed is None else ("[green]pass[/green]" if m.passed else "[red]FAIL[/red]")
        value = "-" if m.value is None else f"{m.value:.4g}"
        table.add_row(markup(m.name), markup(m.engine), value, markup(m.unit), verdict, *([markup(m.threshold)] if wide else []))
    console.print(table)
    if not wide:
        console.print(f"[dim]thresholds: report.html, or a terminal of {WIDE_TABLE} columns or more[/dim]")
    say(f"verdict      {ready.line()}")  # refine's words, report.html's badge
    if req.taken_from:
        say(terminal(f"request      {req.taken_from}"))
    whys = why_it_failed(ev.metrics)
    for why in whys:  # the sentences of report.html's "Why it failed"
        say(f"why it failed {terminal(why)}")
    for line in as_asked_lines(ev):  # as asked: each unmet phrase with its gap, unless a sentence above says it
        if not any(line.removeprefix("NOT AS ASKED ") in w for w in whys):
            say(terminal(line))
    for n in ev.notes:
        console.print(f"[dim]note: {markup(n)}[/dim]")
    say(f"evaluated in {ev.seconds:.2f} s; wrote {out / 'evaluation.json'}"
        + ("" if args.no_report else f" and {out / 'report.html'}"))
    return 0 if ev.passed else 1
