"""Screenshots of report.html as a person sees it, for a passing and a failing asset, at 1280 and 800 px.

    python benchmarks/report_screenshots.py [--out DIR] [--chromium /usr/bin/chromium]

The passing report is refine's on the dev stapler (103275, a request with a part the stapler lacks, so
the request warnings show); the failing one is `asset2sim evaluate` of the raw PartNet-Mobility trash can
(102181: no physics, robust rest fails), which shows the failing trials' plots and frames. Chromium runs
headless (no sandbox, no background networking); each page is captured 4000 px tall. Prints the PNG paths.
"""

from __future__ import annotations

import argparse
import shutil
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SHARED = ROOT.parent / "shared" / "datasets" / "partnet_mobility"
WIDTHS = (1280, 800)


def screenshot(chromium: str, html: Path, png: Path, width: int, height: int = 4000) -> None:
    """One headless Chromium screenshot of ``html`` (``width`` x ``height`` px) into ``png``."""
    subprocess.run([chromium, "--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
                    "--hide-scrollbars", f"--screenshot={png}", f"--window-size={width},{height}", html.resolve().as_uri()],
                   check=True, capture_output=True, timeout=120)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=Path("/tmp/asset2sim-report-screenshots"))
    ap.add_argument("--chromium", default=shutil.which("chromium") or shutil.which("chromium-browser") or "chromium")
    args = ap.parse_args()
    from asset2sim.tasks.evaluation.evaluate import evaluate_asset
    from asset2sim.tasks.refine import refine_asset

    args.out.mkdir(parents=True, exist_ok=True)
    passing = refine_asset(SHARED / "103275", "I want a slightly open stapler with its drawer closed.", args.out / "passing",
                           skip_if_complete=False, overwrite=True)
    evaluate_asset(SHARED / "102181", out_dir=args.out / "failing", write_report=True)
    print(f"passing: {passing.report.failure_mode}; failing: see {args.out / 'failing' / 'evaluation.json'}")
    for name in ("passing", "failing"):
        for w in WIDTHS:
            png = args.out / f"{name}_{w}.png"
            screenshot(args.chromium, args.out / name / "report.html", png, w)
            print(png)
    return 0


if __name__ == "__main__":
    sys.exit(main())
