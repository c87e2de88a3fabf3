"""Do the reports play their clips? Open each output folder's report.html in headless Chromium (Playwright),
check that every clip clips/clips.json lists is on the page and that each video decodes and plays (its time
advances), and screenshot the "How it moves" section.

    python benchmarks/report_clips_check.py OUT_DIR... [--png DIR] [--chromium /usr/bin/chromium]

Prints one line per folder (videos listed, on the page, playing) and the screenshot paths; exits 1 when a
folder has no clip or a video does not play.
"""

from __future__ import annotations

import argparse
import json
import shutil
import sys
import time
from pathlib import Path

PLAYING = """() => Array.from(document.querySelectorAll('video')).map(v => ({
    src: v.getAttribute('src'), ready: v.readyState, t: v.currentTime, error: v.error ? v.error.code : null,
    width: v.videoWidth}))"""


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("folders", type=Path, nargs="+")
    ap.add_argument("--png", type=Path, default=Path("/tmp/asset2sim-report-clips"))
    ap.add_argument("--chromium", default=shutil.which("chromium") or "/usr/bin/chromium")
    args = ap.parse_args(argv)
    from playwright.sync_api import sync_playwright

    args.png.mkdir(parents=True, exist_ok=True)
    bad = 0
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=args.chromium, args=[
            "--no-sandbox", "--disable-background-networking", "--autoplay-policy=no-user-gesture-required"])
        for folder in args.folders:
            listed_file = folder / "clips" / "clips.json"
            listed = [f"clips/{c['video']}" for c in json.loads(listed_file.read_text())["clips"]] if listed_file.is_file() else []
            page = browser.new_page(viewport={"width": 1280, "height": 900})
            page.goto((folder / "report.html").resolve().as_uri())
            page.wait_for_timeout(300)
            first = {v["src"]: v for v in page.evaluate(PLAYING)}
            time.sleep(0.7)
            later = {v["src"]: v for v in page.evaluate(PLAYING)}
            playing = [s for s in listed if s in later and later[s]["ready"] >= 2 and later[s]["error"] is None
                       and later[s]["width"] > 0 and later[s]["t"] != first.get(s, {}).get("t")]
            heading = page.query_selector("h2:text('How it moves')")
            png = None
            if heading is not None:
                heading.scroll_into_view_if_needed()
                png = args.png / f"{folder.name}.png"
                page.screenshot(path=str(png))
            page.close()
            ok = bool(listed) and len(playing) == len(listed) and set(listed) <= set(later)
            bad += not ok
            print(f"{folder.name:>10s}: {len(listed)} clips listed, {len(set(listed) & set(later))} on the page, "
                  f"{len(playing)} playing  {'ok' if ok else 'FAIL'}  {png or ''}", flush=True)
        browser.close()
    print(f"{len(args.folders) - bad} of {len(args.folders)} reports play every clip")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
