"""Write the generated objects of categories the dev set lacks (``tests/unseen_assets.py``: a wall switch, a cart, a
sliding window, pliers, a double-door cabinet, a wardrobe with two doors over two drawers, a safe, a toaster, a
bottle, a desk with a drawer, an oven, a pot, a washing machine, glasses, a swivel USB stick, a kettle, a bucket, a
pump dispenser, a desk lamp, a desk fan, a printer, a keyboard, an office chair, a desk globe, scissors), each link's
meshes merged into one OBJ as PartNet-Mobility's files are, beside a ``manifest.csv`` in the dev set's columns
(request: "A <noun>." with the category's first request word), so that the benchmarks that read
a manifest run on them:

    python benchmarks/generated_objects.py --out DIR
    python benchmarks/bench_refine.py --manifest DIR/manifest.csv --out DIR/refined
    python benchmarks/bench_parity.py --root DIR/refined --engines pybullet,physx,mujoco --no-authored
    python benchmarks/bench_press.py --root DIR/refined --engines pybullet,mujoco
"""

from __future__ import annotations

import argparse
import csv
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", type=Path, required=True)
    args = ap.parse_args(argv)
    sys.path.insert(0, str(ROOT))
    sys.path.insert(0, str(ROOT / "benchmarks"))
    from bench_generalization import _noun
    from tests import unseen_assets

    args.out.mkdir(parents=True, exist_ok=True)
    rows = []
    for name, build, category in unseen_assets.UNSEEN_BUILDERS:
        folder = args.out / name
        if not (folder / "mobility.urdf").is_file():
            unseen_assets.one_mesh_per_link(build(folder))
        rows.append({"id": name, "category": category, "prompt": f"A {_noun(category)}.", "task": "", "gensim2_task": "",
                     "reference_scale": "", "reference_joint_range": ""})
        print(f"{name:>15}  {category:<17} {rows[-1]['prompt']}", flush=True)
    with (args.out / "manifest.csv").open("w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    print(f"{len(rows)} objects and {args.out / 'manifest.csv'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
