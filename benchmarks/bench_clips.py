"""What the interaction clips cost: refine every manifest row twice in one
process, clips off then on, each side from its own empty cache, and print per
row and in total the refine time of each side, their difference, and the time
spent drawing and encoding the clips themselves (``sweep_clips``, timed
in place), as wall and CPU time (the CPU figure is the one to compare on a
shared machine). The headline is the clips' CPU time over the rest of the
same pass's refine: the "off" pass runs first in the process and pays
first-use costs (imports, in-process memos) the "on" pass does not, so the
difference of the two passes understates the clips' cost or even turns
negative.

    python benchmarks/bench_clips.py [--manifest PATH] [--ids 100221,7119] [--out DIR]

Goal: clips cost at most 25 % more refine time. Writes
DIR/summary.json.
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_MANIFEST = ROOT.parent / "shared" / "datasets" / "partnet_mobility" / "manifest.csv"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--manifest", type=Path, default=DEFAULT_MANIFEST)
    ap.add_argument("--ids", default="", help="comma-separated subset of ids")
    ap.add_argument("--out", type=Path, default=ROOT / "out" / "bench_clips")
    args = ap.parse_args(argv)
    rows = list(csv.DictReader(args.manifest.open()))
    ids = [i for i in args.ids.split(",") if i]
    rows = [r for r in rows if not ids or r["id"] in ids]
    root = args.manifest.parent

    from asset2sim.schemas.config import RefineConfig
    from asset2sim.tasks import refine
    from asset2sim.tasks.evaluation import clips as clip_module

    spent = {"wall": 0.0, "cpu": 0.0}
    real = clip_module.sweep_clips

    def timed(*a, **k):  # the clips' own cost, measured where refine calls them
        w, c = time.perf_counter(), time.process_time()
        try:
            return real(*a, **k)
        finally:
            spent["wall"] += time.perf_counter() - w
            spent["cpu"] += time.process_time() - c

    clip_module.sweep_clips = timed
    results = []
    for side, on in (("off", False), ("on", True)):
        cache = tempfile.mkdtemp(prefix=f"asset2sim-bench-clips-{side}-")
        os.environ["ASSET2SIM_CACHE"] = cache  # each side from an empty cache
        for r in rows:
            spent.update(wall=0.0, cpu=0.0)
            w, c = time.perf_counter(), time.process_time()
            res = refine.refine_asset(root / r["id"], r["prompt"], args.out / side / r["id"], RefineConfig(clips=on),
                                      skip_if_complete=False, task=r.get("task") or None, reference=root / r["id"])
            rec = {"id": r["id"], "side": side, "wall_s": time.perf_counter() - w, "cpu_s": time.process_time() - c,
                   "clip_wall_s": spent["wall"], "clip_cpu_s": spent["cpu"], "failure_mode": res.report.failure_mode,
                   "clips": len(clip_module.clip_videos(res.out_dir))}
            results.append(rec)
            print(f"{side:3s} {r['id']:>7s} {rec['wall_s']:6.1f} s wall {rec['cpu_s']:6.1f} s cpu  clips {rec['clips']} "
                  f"({rec['clip_wall_s']:.2f} s wall, {rec['clip_cpu_s']:.2f} s cpu)  {rec['failure_mode']}", flush=True)
    by = {(x["side"], x["id"]): x for x in results}
    print(f"\n{'id':>7s} {'off cpu s':>9s} {'on cpu s':>9s} {'clips cpu s':>11s} {'clips/off':>9s} {'n clips':>7s}")
    tot = {"off": 0.0, "on": 0.0, "clip": 0.0, "off_wall": 0.0, "on_wall": 0.0, "clip_wall": 0.0}
    missing = []
    for r in rows:
        off, on = by[("off", r["id"])], by[("on", r["id"])]
        tot["off"] += off["cpu_s"]
        tot["on"] += on["cpu_s"]
        tot["clip"] += on["clip_cpu_s"]
        tot["off_wall"] += off["wall_s"]
        tot["on_wall"] += on["wall_s"]
        tot["clip_wall"] += on["clip_wall_s"]
        if on["clips"] == 0:
            missing.append(r["id"])
        print(f"{r['id']:>7s} {off['cpu_s']:9.1f} {on['cpu_s']:9.1f} {on['clip_cpu_s']:11.2f} "
              f"{on['clip_cpu_s'] / off['cpu_s']:9.1%} {on['clips']:7d}")
    summary = {
        "rows": len(rows), "refine_cpu_s_off": tot["off"], "refine_cpu_s_on": tot["on"], "clips_cpu_s": tot["clip"],
        "refine_wall_s_off": tot["off_wall"], "refine_wall_s_on": tot["on_wall"], "clips_wall_s": tot["clip_wall"],
        "clips_share_of_refine_cpu": tot["clip"] / tot["off"] if tot["off"] else None,
        "on_over_off_cpu": tot["on"] / tot["off"] - 1.0 if tot["off"] else None, "rows_without_clips": missing,
        # the same pass's refine without its clips: the fair base (the "off" pass warms in-process memos and pays
        # first-use costs the "on" pass does not)
        "clips_share_same_pass": tot["clip"] / (tot["on"] - tot["clip"]) if tot["on"] > tot["clip"] else None,
    }
    print(f"\ntotal: refine {tot['off']:.1f} s cpu without clips, {tot['on']:.1f} s with ({summary['on_over_off_cpu']:+.1%}); "
          f"the clips themselves {tot['clip']:.1f} s cpu = {summary['clips_share_of_refine_cpu']:.1%} of refine without them "
          f"(wall: {tot['off_wall']:.1f} s, {tot['on_wall']:.1f} s, clips {tot['clip_wall']:.1f} s); goal <= 25 %")
    print(f"the same pass: clips {tot['clip']:.1f} s cpu on top of {tot['on'] - tot['clip']:.1f} s of the rest of refine = "
          f"{summary['clips_share_same_pass']:.1%} more refine time")
    print(f"rows without clips: {', '.join(missing) or 'none'}")
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "summary.json").write_text(json.dumps({"summary": summary, "rows": results}, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
