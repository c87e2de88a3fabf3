"""Time the renderer: per view and per object, over a dataset folder.

Usage::

    python benchmarks/bench_render.py [DATASET_OR_ASSETS ...] [--size 256 256]
        [--views front,back,left,right,perspective] [--supersample 2]
        [--shadows] [--out DIR]

DATASET_OR_ASSETS: PartNet-Mobility object folders, URDFs, or a folder of
object folders (default ``../shared/datasets/partnet_mobility``). With
``--out``, each object's views and contact sheet are written to
``DIR/<id>/`` for looking at them. Prints one row per object (prepare = URDF
and OBJ preparation, load = PyBullet load, mean and max wall time per view,
total wall time, CPU time)
and a summary line. ``cpu s`` is the process CPU time, the figure to quote on
a shared machine (wall times grow with the load). Objects render at zero joint
positions.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_DATA = ROOT.parent / "shared" / "datasets" / "partnet_mobility"


def _assets(paths: list[Path]) -> list[Path]:
    out = []
    for p in paths:
        if p.is_file() or (p / "mobility.urdf").is_file():
            out.append(p)
        elif p.is_dir():
            out += sorted(d for d in p.iterdir() if (d / "mobility.urdf").is_file())
    return out


def main(argv: list[str] | None = None) -> int:
    from asset2sim.tasks.geometry.render import SceneRenderer, render_contact_sheet, resolve_urdf, write_png

    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("paths", nargs="*", type=Path, default=[DEFAULT_DATA])
    ap.add_argument("--size", type=int, nargs=2, default=(256, 256), metavar=("W", "H"))
    ap.add_argument("--views", default="front,back,left,right,perspective")
    ap.add_argument("--supersample", type=int, default=2)
    ap.add_argument("--shadows", action="store_true")
    ap.add_argument("--out", type=Path, default=None, help="write views and contact sheets here")
    args = ap.parse_args(argv)
    views = [v for v in args.views.split(",") if v]
    assets = _assets(args.paths)
    if not assets:
        print(f"no assets found in {[str(p) for p in args.paths]}")
        return 2
    print(
        f"renderer: PyBullet TinyRenderer (CPU), {args.size[0]}x{args.size[1]} px, supersample {args.supersample}, "
        f"shadows {'on' if args.shadows else 'off'}, views {views}"
    )
    print(f"{'object':>10} {'prepare s':>9} {'load s':>7} {'view mean s':>11} {'view max s':>10} {'total s':>8} {'cpu s':>6}  notes")
    per_view: list[float] = []
    per_object: list[float] = []
    per_cpu: list[float] = []
    failures = 0
    for asset in assets:
        name = asset.stem if asset.is_file() else asset.name
        t0, c0 = time.perf_counter(), time.process_time()
        try:
            with SceneRenderer(
                resolve_urdf(asset), size=tuple(args.size), supersample=args.supersample, shadows=args.shadows
            ) as r:
                images = {v: r.render(v) for v in views}
                tm, notes = r.timings, r.notes
        except Exception as exc:  # report and go on with the others
            failures += 1
            print(f"{name:>10}  FAILED: {type(exc).__name__}: {exc}")
            continue
        total, cpu = time.perf_counter() - t0, time.process_time() - c0
        per_cpu.append(cpu)
        times = [t for ts in tm.views.values() for t in ts]
        per_view += times
        per_object.append(total)
        print(
            f"{name:>10} {tm.prepare:9.3f} {tm.load:7.3f} {statistics.mean(times):11.3f} {max(times):10.3f} "
            f"{total:8.2f} {cpu:6.2f}  {'; '.join(notes)}"
        )
        if args.out is not None:
            for v, img in images.items():
                write_png(args.out / name / f"{v}.png", img)
            write_png(args.out / name / "contact_sheet.png", render_contact_sheet(images, title=name))
    if per_view:
        print(
            f"summary: {len(per_object)} objects, {len(per_view)} views; per view mean {statistics.mean(per_view):.3f} s "
            f"(median {statistics.median(per_view):.3f}, max {max(per_view):.3f}); per object mean "
            f"{statistics.mean(per_object):.2f} s (max {max(per_object):.2f}), CPU {statistics.mean(per_cpu):.2f} s; "
            f"failures {failures}"
        )
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
