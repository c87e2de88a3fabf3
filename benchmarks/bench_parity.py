"""Export MJCF and run the SPEC's metrics in PyBullet, PhysX (SAPIEN) and MuJoCo
for every refined output folder under a root (default: out/bench_refine, as
written by benchmarks/bench_refine.py); print the parity table and the counts.

    python benchmarks/bench_parity.py [--root out/bench_refine] [--ids 103275,7236]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--root", type=Path, default=ROOT / "out" / "bench_refine")
    ap.add_argument("--ids", default="")
    ap.add_argument("--engines", default="pybullet,physx,mujoco")
    args = ap.parse_args(argv)

    from asset2sim.tasks.publish.export_mjcf import export_mjcf
    from asset2sim.tasks.check.parity import evaluate_engines, parity_table

    engines = args.engines.split(",")
    folders = sorted(p.parent for p in args.root.glob("*/mobility.urdf"))
    if args.ids:
        keep = set(args.ids.split(","))
        folders = [f for f in folders if f.name in keep]
    counts = {e: {"stable": 0, "osc": 0, "ran": 0, "max_pen": 0.0, "max_depth": 0.0} for e in engines}
    rows_out = []
    for f in folders:
        t0 = time.perf_counter()
        try:
            xml = export_mjcf(f)
            mjcf = f"ok ({xml.relative_to(f)})"
        except Exception as exc:  # report and go on
            mjcf = f"FAILED: {exc}"
        rows = parity_table(evaluate_engines(f, engines))
        line = [f"{f.name:>7} mjcf {mjcf[:40]:<40}"]
        for r in rows:
            c = counts[r["engine"]]
            if r["status"] == "ok":
                c["ran"] += 1
                c["stable"] += bool(r["rest_stability"])
                c["osc"] += bool(r["oscillation"])
                c["max_pen"] = max(c["max_pen"], r["penetration_mm"] or 0.0)
                c["max_depth"] = max(c["max_depth"], r["max_depth_mm"] or 0.0)
            line.append(
                f"{r['engine']}: {'S' if r['rest_stability'] else 's'}{'O' if r['oscillation'] else 'o'} "
                f"Phi {r['penetration_mm'] if r['penetration_mm'] is None else round(r['penetration_mm'], 2)} ({r['status']})"
            )
        print("  ".join(line) + f"  {time.perf_counter() - t0:.1f}s", flush=True)
        rows_out.append({"id": f.name, "mjcf": mjcf, "engines": rows})
    print()
    print("engine    loaded  rest-stability  oscillation  max Phi (mm)  max deepest point (mm)")
    for e, c in counts.items():
        print(f"{e:<9} {c['ran']:>3}/{len(folders):<3} {c['stable']:>8} {c['osc']:>13} {c['max_pen']:>14.2f} {c['max_depth']:>14.2f}")
    (args.root / "parity.json").write_text(json.dumps(rows_out, indent=1, default=str))
    return 0


if __name__ == "__main__":
    sys.exit(main())
