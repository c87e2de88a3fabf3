"""``asset2sim init [FOLDER] [--objects DIR]``: write a starter ``catalog.yaml`` (the pipeline's list of datasets,
estimator and run settings) where none is, for an installed asset2sim with no clone around it: the built-in demo
objects as a dataset and, with ``--objects``, a folder of your own objects as the default one
(``docs/guide/pipeline.md``).
"""

from __future__ import annotations

import argparse
from pathlib import Path


NAME = "init"
HELP = ("Write a starter catalog.yaml (the demo dataset, and a folder of your own objects with --objects) for "
        "asset2sim flow, serve and failures outside a clone of asset2sim.")

#: This command's exit statuses (``--help`` lists them with those of every command: 2 usage, 70, 130).
EXITS = {0: "catalog.yaml written", 1: "--objects is not a folder of objects", 4: "catalog.yaml exists (--force) or cannot be written"}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("folder", type=Path, nargs="?", default=Path("."), help="where to write catalog.yaml (default: here)")
    parser.add_argument("--objects", type=Path, help=(
        "a folder of your objects, one per sub-folder (a URDF with its meshes, an MJCF or a USD file): the default "
        "dataset; its manifest.csv is used, else one listing every object is written beside catalog.yaml"))
    parser.add_argument("--force", action="store_true", help="replace an existing catalog.yaml (and the manifest written)")


def run(args: argparse.Namespace) -> int:
    from asset2sim.flows.starter import write_starter_catalog

    made = write_starter_catalog(args.folder, args.objects, force=args.force)
    print(f"wrote {made.catalog} (default dataset {made.dataset})")
    if made.manifest is not None:
        print(f"wrote {made.manifest}: {made.objects} object(s), each with an empty request; add a prompt (and a task) per row")
    where = "" if args.folder.resolve() == Path.cwd().resolve() else f" --catalog {made.catalog}"
    print(f"next: asset2sim flow{where}   (then: asset2sim failures{where})")
    return 0
