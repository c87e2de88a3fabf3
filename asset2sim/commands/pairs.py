"""``asset2sim pairs FOLDER... [--out OUT]``: the realism pairs of refined objects: per object, asset2sim's physics
against each other method's (a benchmark output folder) and against planted defects (calibration), each pair
two clips per view of the same scripted push-and-release that differ only in physics. Writes ``OUT/pairs.json``
and ``OUT/clips/``; people rate them with ``asset2sim rate OUT``, models with ``asset2sim judge OUT``
(docs/guide/realism.md).

Exit status: 0 pairs written, 1 no input folder could be read or no pair could be made, 4 the output cannot be written.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from asset2sim.commands._status import INVALID_INPUT, CommandError, check_out, listed
from asset2sim.commands import _output
from asset2sim.inert import markup

NAME = "pairs"
HELP = ("Make realism pairs: the same scripted push-and-release of one joint simulated with asset2sim's physics and with "
        "another method's (or a planted defect), drawn as clips from two views, for people (rate) and models (judge).")

#: This command's exit statuses (``--help`` lists them with those of every command: 2 usage, 70, 130).
EXITS = {0: "pairs written", 1: "no input folder could be read or no pair could be made", 4: "the output cannot be written"}


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("folders", type=Path, nargs="+", metavar="FOLDER",
                   help="a benchmark output folder (asset2sim benchmark --out) or refine output folders")
    p.add_argument("--out", type=Path,
                   help="the pair-set folder (default: FOLDER/realism for one benchmark folder; needed otherwise)")
    p.add_argument("--against", default=",".join(("human", "direct", "defaults")),
                   help="methods of a benchmark folder to pair asset2sim with (comma-separated; default human,direct,defaults)")
    p.add_argument("--defects", default="all",
                   help="planted defects for calibration pairs: all (default), none, or comma-separated names "
                        "(mass_x100, zero_damping, stuck_friction, penetration_10mm, scale_x3, slamming_spring)")


def run(args: argparse.Namespace) -> int:
    from asset2sim.apps.realism.defects import DEFECTS
    from asset2sim.apps.realism.pairs import build_pair_set, specs_from_folders

    console = _output.console()
    out = args.out
    if out is None:
        if len(args.folders) == 1 and (args.folders[0] / "asset2sim").is_dir():
            out = args.folders[0] / "realism"
        else:
            raise CommandError.invalid("OUT_REQUIRED", "--out is needed unless FOLDER is one benchmark output folder")
    if args.defects == "all":
        defects = None
    elif args.defects == "none":
        defects = ()
    else:
        defects = tuple(listed(args.defects))
        unknown = sorted(set(defects) - set(DEFECTS))
        if unknown:
            raise CommandError.invalid("DEFECT_UNKNOWN", f"unknown defects {unknown}; known: {sorted(DEFECTS)}")
    check_out(out)
    specs, skipped = specs_from_folders(args.folders, out, against=tuple(listed(args.against)), defects=defects)
    pair_set = build_pair_set(specs, out, skipped=skipped, progress=lambda text: console.print(markup(text)))
    for key, why in pair_set.skipped.items():
        console.print(f"[yellow]skipped {markup(key)}: {markup(why)}[/yellow]")
    n_defect = sum(1 for p in pair_set.pairs if p.defect)
    console.print(f"wrote {markup(out / 'pairs.json')}: {len(pair_set.pairs)} pairs "
                  f"({n_defect} calibration pairs with planted defects)")
    if not pair_set.pairs:
        raise CommandError(INVALID_INPUT, "NO_PAIRS", out, "no pair could be made (see the skipped lines above)")
    return 0
