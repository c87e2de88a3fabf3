"""``asset2sim demo``: build a small articulated object and refine it (no data needed)."""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

from asset2sim import demo_assets
from asset2sim.commands import refine as refine_cmd
from asset2sim.demo_objects import CATEGORY_TASKS

NAME = "demo"
HELP = "Build a demo articulated object (a box with a hinged lid) from geometry and refine it end to end."


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--out", "-o", type=Path, default=Path("out/demo"), help="output folder (default out/demo)")
    parser.add_argument("--prompt", "-p", default="A small box with its lid slightly open. Low damping hinge.")
    parser.add_argument("--task", default=CATEGORY_TASKS["Box"],
                        help=f"the manipulation task the gripper executes (default {CATEGORY_TASKS['Box']!r}, the Box category's)")
    parser.add_argument("--no-extras", action="store_true", help="skip MJCF export, renders and the HTML report")


def run(args: argparse.Namespace) -> int:
    with tempfile.TemporaryDirectory(prefix="asset2sim-demo-") as tmp:
        src = demo_assets.build_box_with_lid(Path(tmp) / "demo_box")
        print(f"built demo asset {src}")
        ns = argparse.Namespace(asset=src, prompt=args.prompt, out=args.out, category=None, task=args.task, estimator="offline", model=None,
                                base_url=None, force=True, no_extras=args.no_extras, quiet=False, engines="pybullet", overwrite=False)
        return refine_cmd.run(ns)
