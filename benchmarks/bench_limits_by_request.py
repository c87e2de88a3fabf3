"""The joint limits one object gets under different requests: each request refined once (no media) and every
limit the output clipped to the geometry printed with the collision pieces of the two links the clip names.
A joint whose clipped limit differs between requests was clipped on collision pieces that differ between them.

    python benchmarks/bench_limits_by_request.py ROW_FOLDER "request 1" "request 2" ... [--work DIR]

Prints, per request: the failure mode, the scale, each clipped joint (lower, upper, the written note) and the number
of collision pieces per link of the output.
"""

from __future__ import annotations

import argparse
import json
import re
from pathlib import Path

from asset2sim.tasks.refine import refine_asset


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("row", type=Path)
    ap.add_argument("requests", nargs="+")
    ap.add_argument("--work", type=Path, default=Path("out/bench_limits_by_request"))
    args = ap.parse_args()
    for i, text in enumerate(args.requests):
        res = refine_asset(args.row, text, args.work / f"{i:02d}", extras=False, skip_if_complete=False)
        ov = json.loads((res.out_dir / "overlay.json").read_text())
        urdf = (res.out_dir / "mobility.urdf").read_text()
        pieces = {m.group(1): len(re.findall(r"<collision>", m.group(2))) for m in re.finditer(r'<link name="([^"]+)">(.*?)</link>', urdf, re.S)}
        print(f"{text!r}: {res.report.failure_mode}, scale {res.report.scale:.4g}, pieces {pieces}")
        for name, j in ov["joints"].items():
            if j.get("limit_source"):
                print(f"    {name}: lower {j['lower']}, upper {j['upper']}: {j['limit_source']}")


if __name__ == "__main__":
    main()
