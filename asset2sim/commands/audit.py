"""``asset2sim audit PATH... --out OUT``: audit assets that carry physics (URDF, MJCF, USD; one asset, a folder
of many, or a package's asset tree). Per asset: ``OUT/<asset>/audit.json``, ``audit.md`` and ``patch/`` (the
input's format); for the run: ``OUT/audit_assets.parquet`` and ``OUT/audit_values.parquet``; a table per
category on the terminal.

Exit status: 0 every asset plausible with its declared physics passing the checks, 3 an asset has implausible
values or fails a check, 1 an asset could not be audited, 2 usage errors, 4 the output cannot be written.
"""

from __future__ import annotations

import argparse
import functools
import sys
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

from asset2sim.commands._status import (INVALID_INPUT, NOT_READY, CommandError, add_allow_outside, add_mjcf_reading, check_jobs,
                                        check_out, outside_paths)
from asset2sim.input_files import allowed_folders, set_allowed_outside
from asset2sim.flows import audit_catalog
from asset2sim.apps.audit.batch import audit_one, find_assets
from asset2sim.schemas.config import RefineConfig
from asset2sim.tasks.check.verdict import verdict_line
from asset2sim.commands import _output
from asset2sim.inert import markup, terminal

NAME = "audit"
HELP = ("Audit assets that already carry physics (URDF, MJCF, USD): each mass, density, inertia, center of mass, damping, "
        "friction and limit against the product's estimate, simulation checks, and a patch in the input's format.")

#: This command's exit statuses (``--help`` lists them with those of every command: 2 usage, 70, 130).
EXITS = {
    0: "every asset plausible, its declared physics passing the checks",
    1: "an asset could not be audited",
    3: "an asset has implausible values or fails a check",
    4: "the output cannot be written",
}


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("paths", type=Path, nargs="+", metavar="PATH",
                   help="an asset (URDF folder or file, MJCF .xml, USD file, or a folder holding one), or a folder of many")
    p.add_argument("--out", type=Path,
                   help="where to write each asset's audit.json, audit.md and patch/, and the audit catalog (Parquet); "
                        "default: print only")
    p.add_argument("--category", help="object category for every asset (default: from the files and names)")
    add_mjcf_reading(p)
    p.add_argument("--no-sim", action="store_true", help="judge the values only; skip the simulation checks")
    p.add_argument("--jobs", type=int, default=1, help="assets audited at once (processes; default 1)")
    p.add_argument("--flow", action="store_true",
                   help="run as the Prefect audit flow on a Dask cluster of --jobs workers (needs --out; logs the run to MLflow)")
    p.add_argument("--dask-address", help="with --flow: an existing Dask scheduler instead of a local cluster")
    p.add_argument("--json", action="store_true", help="print the catalog rows as JSON lines instead of tables")
    add_allow_outside(p)


def run(args: argparse.Namespace) -> int:
    from rich.table import Table

    check_jobs(args.jobs)
    targets = find_assets(args.paths)
    if not targets:
        raise CommandError(INVALID_INPUT, "AUDIT_NO_ASSETS", None, f"no URDF, MJCF or USD asset in {', '.join(map(str, args.paths))}")
    if args.out is not None:  # never into an input (a path given, or an input file's folder), nor around one
        check_out(args.out, [*args.paths, *(t.path for t in targets)])
    if args.flow:
        if args.body or args.mjcf_angle:
            raise CommandError.invalid("OPTION_NOT_IN_FLOW", "--body and --mjcf-angle apply to an audit run here; "
                                       "leave out --flow to use them")
        if args.out is None:
            raise CommandError.invalid("OUT_REQUIRED", "--flow writes the audit catalog: give --out")
        if args.allow_outside_paths:
            raise CommandError.invalid("OPTION_CONFLICT", "--allow-outside-paths applies to audits in this "
                                       "process and its --jobs; the --flow's Dask workers do not take it")
        from asset2sim.flows.audit_flow import run_audit_flow

        summary = run_audit_flow(args.paths, args.out, category=args.category, simulate=not args.no_sim, workers=args.jobs,
                                 dask_address=args.dask_address)
        rows = summary["rows"]
    else:
        config = RefineConfig(body=args.body, mjcf={"angle": args.mjcf_angle})
        one = functools.partial(audit_one, out_root=args.out, category=args.category, simulate=not args.no_sim, config=config)
        with outside_paths(args):
            if args.jobs <= 1 or len(targets) <= 1:
                rows = [one(t) for t in targets]
            else:  # the workers read the folders --allow-outside-paths allows here
                with ProcessPoolExecutor(max_workers=args.jobs, initializer=set_allowed_outside,
                                         initargs=allowed_folders()) as pool:
                    rows = list(pool.map(one, targets))
        if args.out is not None:
            audit_catalog.write_audit_catalog(args.out, rows)
    console = _output.console()
    if args.json:
        for r in rows:
            print(r.model_dump_json())
    else:
        table = Table("asset", "format", "category", "verdict", "implausible", "declared physics",
                      title=f"audit of {len(rows)} asset(s)")
        for r in rows:
            checks = "-" if r.declared_passed is None else verdict_line("none" if r.declared_passed else "declared_physics_fails",
                                                                        {}, r.declared_failures)
            table.add_row(*map(markup, (r.asset_id, r.format, r.category, r.failure_mode,  # "[mujoco]" is text, not markup
                                        "; ".join(r.implausible) or r.error[:160] or "-", checks)))
        console.print(table)
        import pandas as pd

        by_cat = audit_catalog.failure_modes_by_category(pd.DataFrame.from_records([r.model_dump() for r in rows]))
        console.print(terminal(by_cat.to_string()), markup=False)  # categories are the inputs' words
        if args.out is not None:
            console.print(terminal(f"written: {args.out}/<asset>/audit.md, {args.out}/{audit_catalog.ASSETS_PARQUET}, "
                                   f"{args.out}/{audit_catalog.VALUES_PARQUET}"), markup=False)
    failed = [r for r in rows if r.failure_mode == "audit_failed"]
    for r in failed:  # the whole reason, one line each (the table cuts it; a missing extra's hint ends it)
        print(CommandError(INVALID_INPUT, "AUDIT_FAILED", r.source, r.error).line(NAME), file=sys.stderr)
    return INVALID_INPUT if failed else NOT_READY if any(r.failure_mode != "none" for r in rows) else 0
