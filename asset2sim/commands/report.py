"""``asset2sim report OUT [--reference DIR] [--no-clips] [--force]``: make the media of a refined output folder
(renders in ``views/``, sweep clips in ``clips/``, ``report.html``) when its refine deferred them
(``refine --defer-media``, a flow with ``extras: deferred``), or again with ``--force``. The verdict is the one
``report.json`` records; nothing else of the folder changes.

Exit status: 0 the media are made (or were already), 4 the folder holds no complete refine output or cannot be
written.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from asset2sim.commands._status import CommandError, OUTPUT_LOCATION

NAME = "report"
HELP = "Make the renders, clips and report.html of a refined output folder whose refine deferred them (--defer-media)."

#: This command's exit statuses (``--help`` lists them with those of every command: 2 usage, 70, 130).
EXITS = {0: "the media are made (or were already)", 4: "no complete refine output, or it cannot be written"}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("out", type=Path, help="a refined output folder (the --out of refine, or an asset's folder of a flow)")
    parser.add_argument("--reference", type=Path,
                        help="PartNet-Mobility folder with GenSim2's reference, shown in the report as refine would")
    parser.add_argument("--no-clips", action="store_true", help="skip the clips of each task-relevant joint's sweep (clips/)")
    parser.add_argument("--force", action="store_true", help="make the media again even when report.json says they are done")


def run(args: argparse.Namespace) -> int:
    from asset2sim.tasks.publish.media import make_media

    if not args.out.is_dir():
        raise CommandError(OUTPUT_LOCATION, "OUTPUT_INCOMPLETE", args.out, "not a folder; give the --out folder of a refine")
    made = make_media(args.out, reference=args.reference, clips=not args.no_clips, force=args.force)
    if not made:
        print(f"{args.out}: media already made (report.html); --force makes them again")
    for name, path in sorted(made.items()):
        print(f"{name:<6} {path}")
    return 0
