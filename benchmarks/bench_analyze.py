"""Time the mesh-analysis stage (``asset2sim.tasks.analyze.analyze_asset``) on
every object of the dataset and print per-object seconds and the median.

Usage::

    python benchmarks/bench_analyze.py [DATASET_DIR] [--repeat N] [--ids ID ...]
        [--voxels-per-axis N] [--links]

DATASET_DIR defaults to ``../shared/datasets/partnet_mobility`` relative to
the project root. Extraction (URDF parsing) is done once per object and not
timed; each analysis starts from an empty mesh cache (the OBJ files are read
inside the timed region). With ``--repeat N`` the minimum of N runs is shown
next to the first run (the machine is shared, so the minimum is the best
estimate of the cost). ``--links`` also prints every link's volume, volume
method and the ratio volume / bounding-box volume.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_DATA = ROOT.parent / "shared" / "datasets" / "partnet_mobility"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("data", nargs="?", type=Path, default=DEFAULT_DATA)
    parser.add_argument("--repeat", type=int, default=1)
    parser.add_argument("--ids", nargs="*", default=None)
    parser.add_argument("--voxels-per-axis", type=int, default=None)
    parser.add_argument("--links", action="store_true")
    args = parser.parse_args(argv)

    import numpy as np

    from asset2sim.tasks.analyze import VOXELS_PER_AXIS, analyze_asset
    from asset2sim.tasks.extract import extract_asset

    if not args.data.is_dir():
        print(f"dataset folder not found: {args.data}", file=sys.stderr)
        return 2
    ids = args.ids or sorted(p.name for p in args.data.iterdir() if (p / "mobility.urdf").is_file())
    vpa = args.voxels_per_axis or VOXELS_PER_AXIS
    options = {"voxels_per_axis": vpa}
    # warm-up: imports (scipy.ndimage, trimesh for primitives) outside the timings
    analyze_asset(extract_asset(args.data / ids[0]), **options)

    firsts, bests = [], []
    print(f"voxels_per_axis={vpa}")
    print(f"{'id':>8} {'links':>5} {'files':>5} {'MB':>6} {'faces':>8} {'first s':>8} {'min s':>8}")
    for oid in ids:
        asset = extract_asset(args.data / oid)
        files = {g.path for link in asset.links for g in (link.collisions or link.visuals) if g.path is not None}
        mb = sum(p.stat().st_size for p in files if p.is_file()) / 1e6
        times = []
        for _ in range(max(1, args.repeat)):
            t0 = time.perf_counter()
            result = analyze_asset(asset, **options)
            times.append(time.perf_counter() - t0)
        firsts.append(times[0])
        bests.append(min(times))
        faces = sum(g.n_faces for g in result.values())
        print(f"{oid:>8} {len(result):5d} {len(files):5d} {mb:6.2f} {faces:8d} {times[0]:8.3f} {min(times):8.3f}")
        if args.links:
            for name, g in result.items():
                bbox = float(np.prod(g.extents))
                ratio = g.volume / bbox if bbox > 0 else float("nan")
                print(f"{'':>10}{name:<10} V={g.volume:.4g} m^3  V/bbox={ratio:.3f}  A={g.area:.4g} m^2  {g.volume_method}")
    print(f"median first-run s: {statistics.median(firsts):.3f}   max: {max(firsts):.3f}   total: {sum(firsts):.2f}")
    print(f"median min s:       {statistics.median(bests):.3f}   max: {max(bests):.3f}   total: {sum(bests):.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
