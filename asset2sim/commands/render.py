"""``asset2sim render ASSET [--state initial_state.json] --out views/``: write
textured PNG views of an asset at a joint state.

Exit status: 0 every view written, 1 rendering failed, 2 bad input, 4 the
output folder cannot be used.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from asset2sim.commands._status import CommandError, check_out, listed
from asset2sim import output_folder
from asset2sim.tasks.geometry.render import VIEWS, SceneRenderer, read_joint_state, render_contact_sheet, resolve_urdf, write_png

NAME = "render"
HELP = "Render textured views (front, back, left, right, perspective; optionally top) of an asset at a joint state to PNGs."

#: This command's exit statuses (``--help`` lists them with those of every command: 2 usage, 70, 130).
EXITS = {0: "every view written", 1: "rendering failed", 2: "bad input", 4: "the output folder cannot be used"}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("asset", type=Path, help="asset folder (mobility.urdf + meshes) or a URDF file")
    parser.add_argument("--state", type=Path,
                        help='initial_state.json ({"initial_joint_positions": {joint: value}}, rad or m); default: all joints at zero')
    parser.add_argument("--out", "-o", type=Path, required=True, help="output folder for <view>.png")
    parser.add_argument("--views", default="front,back,left,right,perspective",
                        help="comma-separated views among front, back, left, right, perspective, top (default: the first five)")
    parser.add_argument("--size", type=int, nargs=2, default=(256, 256), metavar=("W", "H"), help="pixels (default 256 256)")
    parser.add_argument("--backend", default="auto", help="renderer: auto or tiny (PyBullet TinyRenderer, CPU)")
    parser.add_argument("--shadows", action="store_true", help="cast shadows (slower)")
    parser.add_argument("--sheet", action=argparse.BooleanOptionalAction, default=True,
                        help="also write contact_sheet.png with every view labelled (default on)")


def run(args: argparse.Namespace) -> int:
    views = listed(args.views)
    unknown = [v for v in views if v not in VIEWS]
    if unknown or not views:
        raise CommandError.invalid("VIEW_UNKNOWN", f"--views: unknown view(s) {unknown}; known views: {list(VIEWS)}")
    check_out(args.out, [args.asset], adopt=True)  # never into the input, but into a refined folder (its own views then)
    urdf = resolve_urdf(args.asset)
    state = read_joint_state(args.state) if args.state else {}
    t0 = time.perf_counter()
    with SceneRenderer(urdf, size=tuple(args.size), backend=args.backend, shadows=args.shadows) as r:
        r.set_joint_positions(state)
        images = {v: r.render(v) for v in views}
        load = r.timings.prepare + r.timings.load
    with output_folder.adopting(args.out):
        written = [write_png(args.out / f"{v}.png", img) for v, img in images.items()]
        if args.sheet:
            written.append(write_png(args.out / "contact_sheet.png", render_contact_sheet(images, title=urdf.parent.name)))
    total = time.perf_counter() - t0
    for path in written:
        print(path)
    print(f"{len(images)} views of {urdf} in {total:.2f} s (load {load:.2f} s)")
    return 0
