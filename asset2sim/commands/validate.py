"""``asset2sim validate ASSET``: one line per error and warning about an input asset (the infos too with
``--verbose``), then a verdict whose counts are those of the lines it could print. Exit status: 0 no error, 1
refused, 2 usage errors.
"""

from __future__ import annotations

import argparse
from collections import Counter
import json
from pathlib import Path

from asset2sim.commands._status import CommandError, add_allow_outside, add_mjcf_reading, outside_paths
from asset2sim.tasks.ingest.extract import validate_any
from asset2sim.formats import ReadOptions
from asset2sim.tasks.ingest.validate_input import CODES, ValidationPolicy, has_errors

NAME = "validate"
HELP = "Check an input asset (safe XML, kinematic tree, numbers, inertials, mesh paths and contents); exit 1 on errors."

#: This command's exit statuses (``--help`` lists them with those of every command: 2 usage, 70, 130).
EXITS = {0: "no error", 1: "the asset is refused"}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("asset", type=Path, help="asset folder (mobility.urdf + meshes), a URDF file, or an MJCF (.xml) or "
                        "OpenUSD (.usd, .usda, .usdc, .usdz) file (the files it names checked first)")
    add_mjcf_reading(parser)
    parser.add_argument("--json", action="store_true", help="print the findings as a JSON list instead of text")
    parser.add_argument("--strict", action="store_true", help="treat warnings as errors")
    parser.add_argument("--quiet", "-q", action="store_true", help="print errors and warnings only (the default; --verbose adds the infos)")
    parser.add_argument("--paths-only", action="store_true", help="check mesh paths but do not read mesh contents (faster)")
    parser.add_argument("--error", metavar="CODE", action="append", default=[],
                        help="make this code an error (repeatable), e.g. --error JOINT_LIMIT_EQUAL")
    parser.add_argument("--allow", metavar="CODE", action="append", default=[], help="downgrade this code to a warning (repeatable)")
    add_allow_outside(parser)


def run(args: argparse.Namespace) -> int:
    unknown = [c for c in args.error + args.allow if c not in CODES]
    if unknown:
        raise CommandError.invalid("CODE_UNKNOWN", f"--error/--allow: unknown code(s): {', '.join(unknown)} "
                                   "(docs/guide/validation.md lists the codes)")
    overrides = dict.fromkeys(args.error, "error") | dict.fromkeys(args.allow, "warning")
    policy = ValidationPolicy(overrides=overrides, warnings_as_errors=args.strict, check_mesh_contents=not args.paths_only)
    with outside_paths(args):
        findings, notes = validate_any(args.asset, policy, ReadOptions(body=args.body, mjcf_angle=args.mjcf_angle))
    infos = args.verbose and not args.quiet  # how the input was read: behind --verbose
    refused = has_errors(findings)
    if args.json:
        print(json.dumps([f.model_dump(mode="json") for f in findings if not (args.quiet and f.severity == "info")], indent=2))
        return 1 if refused else 0
    if infos:
        for note in notes:
            print(f"{'info':<7} {'INPUT_READ':<32} {args.asset.name}  {note}")
    for f in findings:
        if f.severity == "info" and not infos:
            continue
        loc = f"{f.file}:{f.line}" if f.line else f.file
        print(f"{f.severity:<7} {f.code:<32} {loc}  {f.where}: {f.message}")
    n = Counter(f.severity for f in findings)
    n["info"] += len(notes)  # every info line counted, printed or not
    hidden = "" if infos or not n["info"] else ", shown with --verbose"
    counts = ", ".join(_count(n[what], what) for what in ("error", "warning", "info"))
    print(f"{args.asset}: {'REFUSED' if refused else 'OK'} ({counts}{hidden})")
    return 1 if refused else 0


def _count(n: int, what: str) -> str:
    """``1 error``, ``3 errors``, ``2 info`` (info has no plural)."""
    return f"{n} {what}" + ("" if n == 1 or what == "info" else "s")
