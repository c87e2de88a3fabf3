"""PyBullet clients kept between the sessions of one candidate: refine dev rows (extras off) with the clients kept
(:data:`asset2sim.engines.pybullet_clients.MAX_IDLE` as shipped) and with none kept (0), in the order
off, on, on, off per row, and print per mode the refine wall seconds, the PyBullet sessions that owned their client
and the clients connected (every ``pybullet.connect``: sessions, shape worlds and viewers).

    .venv/bin/python benchmarks/bench_sessions.py [--ids 100221,7236] [--manifest PATH]

Both modes give the same outputs to the byte (``benchmarks/bench_determinism.py --against`` shows it across
commits); this script measures only the time. The on-disk cache is used as configured (``ASSET2SIM_CACHE``): the
first refine of a row may fill it, which the off/on/on/off order spreads over both modes.
"""

from __future__ import annotations

import argparse
import csv
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DEV = ROOT.parent / "shared" / "datasets" / "partnet_mobility"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--manifest", type=Path, default=DEV / "manifest.csv")
    ap.add_argument("--ids", default="", help="comma-separated subset of ids")
    args = ap.parse_args(argv)

    import pybullet

    from asset2sim.engines import pybullet_clients as pc
    from asset2sim.tasks.refine import refine_asset

    rows = list(csv.DictReader(args.manifest.open()))
    if args.ids:
        wanted = set(args.ids.split(","))
        rows = [r for r in rows if r["id"] in wanted]
    shipped = pc.MAX_IDLE
    counts = {"connects": 0, "owned": 0}
    connect, take = pybullet.connect, pc.take

    def counted_connect(*a, **k):
        counts["connects"] += 1
        return connect(*a, **k)

    def counted_take(*a, **k):
        counts["owned"] += 1
        return take(*a, **k)

    pybullet.connect, pc.take = counted_connect, counted_take
    totals = {mode: {"s": [], "connects": 0, "owned": 0} for mode in ("off", "on")}
    load = os.getloadavg()[0]
    with tempfile.TemporaryDirectory(prefix="a2s-bench-sessions-") as work:
        for row in rows:
            line = []
            for k, mode in enumerate(("off", "on", "on", "off")):
                pc.MAX_IDLE = shipped if mode == "on" else 0
                for _, cid in list(pc.IDLE):  # nothing kept from the other mode
                    pybullet.disconnect(cid)
                pc.IDLE.clear()
                before = dict(counts)
                t0 = time.perf_counter()
                refine_asset(Path(args.manifest.parent / row["id"]), row["prompt"], Path(work) / f"{row['id']}_{k}",
                             task=row["task"] or None, extras=False, overwrite=True)
                dt = time.perf_counter() - t0
                totals[mode]["s"].append(dt)
                for key in ("connects", "owned"):
                    totals[mode][key] += counts[key] - before[key]
                line.append(f"{mode} {dt:.2f}")
            print(f"  {row['id']:>7}  " + ", ".join(line), flush=True)
    pc.MAX_IDLE = shipped
    n = len(rows)
    print(f"{n} rows, 2 refines each per mode, load average before {load:.1f} on {os.cpu_count()} cores")
    for mode, t in totals.items():
        print(f"  clients {'kept' if mode == 'on' else 'not kept'}: refine wall {sum(t['s']):.1f} s "
              f"(median {statistics.median(t['s']):.2f} s), sessions owning a client {t['owned']}, "
              f"clients connected {t['connects']}")
    off, on = sum(totals["off"]["s"]), sum(totals["on"]["s"])
    print(f"  saved {off - on:.1f} s of {off:.1f} s ({(off - on) / off:.1%})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
