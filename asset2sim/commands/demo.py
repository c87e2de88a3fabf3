"""``asset2sim demo``: build one of the built-in articulated objects from geometry and refine it (no data needed).

    asset2sim demo                                         # the box with a hinged lid, refined into out/demo
    asset2sim demo --list                                  # the built-in objects
    asset2sim demo --object laptop --asset-out assets/laptop --no-refine   # an input folder of your own
    asset2sim demo --dataset assets/demo                   # every object and a manifest.csv (benchmark, flow)

Exit status: as ``refine`` (0 interaction-ready, 3 written but a check failed), 2 an unknown object, 4 a folder
that cannot be written.
"""

from __future__ import annotations

import argparse
import difflib
import tempfile
from pathlib import Path

from asset2sim import demo_assets
from asset2sim.commands import refine as refine_cmd
from asset2sim.commands._status import CommandError
from asset2sim.demo_objects import DEMO_OBJECTS

NAME = "demo"
HELP = "Build a built-in articulated object (a box with a hinged lid, a two-drawer cabinet, a laptop ...) and refine it."

#: This command's exit statuses (``--help`` lists them with those of every command: 2 usage, 70, 130).
EXITS = {0: "written and interaction-ready", 3: "written but not interaction-ready", 4: "a folder that cannot be written"}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    ids = ", ".join(o.asset_id for o in DEMO_OBJECTS)
    parser.add_argument("--list", action="store_true", help="list the built-in objects with their default requests and exit")
    parser.add_argument("--object", default="box_lid", metavar="ID", help=f"which built-in object ({ids}; default box_lid)")
    parser.add_argument("--out", "-o", type=Path, default=Path("out/demo"), help="output folder (default out/demo)")
    parser.add_argument("--prompt", "-p", help="the request (default: the object's own, see --list)")
    parser.add_argument("--task", help="the manipulation task the gripper executes (default: the object's category's)")
    parser.add_argument("--asset-out", type=Path,
                        help="also keep the object's input folder here (mobility.urdf, meshes, semantics.txt) to refine it yourself")
    parser.add_argument("--no-refine", action="store_true", help="with --asset-out: write the input folder only")
    parser.add_argument("--dataset", type=Path,
                        help="write every built-in object and a manifest.csv into this folder (for benchmark and flow) and exit")
    parser.add_argument("--no-extras", action="store_true", help="skip MJCF export, renders and the HTML report")


def run(args: argparse.Namespace) -> int:
    if args.list:
        for o in DEMO_OBJECTS:
            print(f"{o.asset_id:<16} {o.category:<17} {o.prompt}  (task: {o.task})")
        return 0
    if args.dataset is not None:
        root = demo_assets.build_demo_dataset(args.dataset)
        print(f"wrote {len(DEMO_OBJECTS)} objects and {root / 'manifest.csv'}")
        return 0
    entry = next((o for o in DEMO_OBJECTS if o.asset_id == args.object), None)
    if entry is None:
        known = [o.asset_id for o in DEMO_OBJECTS]
        close = difflib.get_close_matches(args.object, known, n=1)
        hint = f"; did you mean {close[0]!r}?" if close else ""
        raise CommandError.invalid("DEMO_OBJECT_UNKNOWN", f"--object {args.object!r} is not a built-in object{hint} "
                                   f"(known: {', '.join(known)}; `asset2sim demo --list`)")
    if args.no_refine and args.asset_out is None:
        raise CommandError.invalid("DEMO_NOTHING_TO_DO", "--no-refine writes only the input folder: give --asset-out DIR")
    with tempfile.TemporaryDirectory(prefix="asset2sim-demo-") as tmp:
        folder = args.asset_out or Path(tmp) / entry.asset_id
        src = demo_assets.build_object(entry.asset_id, folder)
        print(f"built demo asset {src} ({entry.category})")
        if args.no_refine:
            return 0
        parser = argparse.ArgumentParser()  # refine's own options, each at its default but these
        refine_cmd.add_arguments(parser)
        ns = parser.parse_args([f"--out={args.out}", "--estimator=offline", "--engines=pybullet", "--force", "--", str(src)])
        ns.prompt = args.prompt if args.prompt is not None else entry.prompt
        ns.task = args.task if args.task is not None else entry.task
        ns.no_extras = args.no_extras
        return refine_cmd.run(ns)
