"""One hostile name set through every command and the report, end to end (``asset2sim.inert``).

An asset whose link and joint names are console markup (``[/bold]``), HTML with an event handler and a script,
and mathtext (``$\\frac{1}{0}$``); a request and a task holding terminal control sequences (ESC, an OSC window
title, BEL, backspaces, a bidirectional override) and markup; output folders and a manifest id holding the same;
a second asset with a 10,000-character joint name and a 10,000-character request. Every command (``validate``,
``refine``, ``evaluate``, ``report``, ``audit``, ``export``, ``render``, ``demo``, ``benchmark``, ``pairs``, ``judge``
against a local model server replying with the same text, ``rate --scores``) runs as a process: none ends in an
internal error or a crash, and no control character reaches its output. Every HTML page written is opened in
headless Chromium: no script runs and the names read as written."""

from __future__ import annotations

import html
import json
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from asset2sim import demo_assets

pytestmark = pytest.mark.slow  # end to end: every command as a process, and the browser

ROOT = Path(__file__).resolve().parents[1]
MARKUP = "[/bold] [red]lid[/]"
HTML = 'j<img src=x onerror="window.__pwned=1"><script>window.__pwned=2</script>'
MATH = r"body $\frac{1}{0}$ a$b"
CONTROL = "\x1b]0;pwned\x07\x1b[31m\x08\x08\u202e"
LONG = "n" * 10_000
#: What must never reach a terminal: C0 controls but newline and tab, DEL, C1 controls, bidirectional overrides.
CONTROL_CHARS = re.compile("[\x00-\x08\x0b-\x1f\x7f-\x9f\u202a-\u202e\u2066-\u2069]")
#: Exit statuses of a command that ended as designed (not 70, no signal).
DESIGNED = {0, 1, 2, 3, 4}


def _rename(folder: Path, names: dict[str, str]) -> Path:
    urdf = folder / "mobility.urdf"
    text = urdf.read_text()
    for old, new in names.items():
        text = text.replace(f'"{old}"', '"' + html.escape(new, quote=True) + '"')
    urdf.write_text(text)
    lines = (folder / "semantics.txt").read_text().splitlines()
    (folder / "semantics.txt").write_text("".join(" ".join(names.get(f, f) for f in ln.split(" ")) + "\n" for ln in lines))
    return folder


def _run(*args, cwd: Path, env: dict | None = None, timeout: int = 600) -> subprocess.CompletedProcess:
    proc = subprocess.run([sys.executable, "-m", "asset2sim", *map(str, args)], cwd=cwd, capture_output=True, timeout=timeout,
                          env={**os.environ, **(env or {})})
    out, err = proc.stdout.decode("utf-8", "replace"), proc.stderr.decode("utf-8", "replace")
    assert proc.returncode in DESIGNED, (args[0], proc.returncode, out[-3000:], err[-3000:])
    bad = CONTROL_CHARS.search(out + err)
    assert bad is None, (args[0], repr((out + err)[max(0, bad.start() - 80): bad.end() + 80]))
    assert "INTERNAL_ERROR" not in err and "Traceback" not in err, (args[0], err[-3000:])
    return proc


@pytest.fixture(scope="module")
def area(tmp_path_factory):
    base = tmp_path_factory.mktemp("hostile")
    box = _rename(demo_assets.build_box_with_lid(base / "in" / "box"), {"link_0": MARKUP, "joint_0": HTML, "link_1": MATH})
    long = _rename(demo_assets.build_box_with_lid(base / "in" / "long"), {"joint_0": LONG})
    return base, box, long


def test_every_command_over_hostile_names(area):
    from tests import fake_openai_server as fake

    base, box, long = area
    prompt = f"a box with its lid open {MARKUP} {CONTROL}"
    task = f"open the lid [/] {CONTROL}"
    out = base / f"out{CONTROL}"
    _run("validate", box, cwd=base)
    _run("validate", long, cwd=base)
    refined = _run("refine", box, "-p", prompt, "--task", task, "--out", out, cwd=base)
    assert (out / "report.html").is_file(), refined.stdout[-2000:]
    _run("refine", long, "-p", "a box", "--out", base / "out_long", cwd=base)
    _run("refine", box, "-p", LONG, "--out", base / "out_long_prompt", cwd=base)
    _run("evaluate", out, "-p", prompt, "--task", task, "--out", base / f"ev{CONTROL}", cwd=base)
    _run("evaluate", long, "--out", base / "ev_long", "--no-report", cwd=base)
    _run("report", out, "--force", cwd=base)
    _run("audit", box, long, "--out", base / "audit", "--no-sim", cwd=base)
    _run("export", out, "--format", "mjcf", cwd=base)
    _run("render", box, "--out", base / "views", cwd=base)
    _run("render", long, "--out", base / "views_long", cwd=base)
    _run("demo", "--object", "box_lid", "-p", prompt, "--task", task, "--out", base / "demo", "--no-extras", cwd=base)
    # a benchmark whose manifest id and request are hostile
    data = base / "data"
    shutil.copytree(box, data / "s1[/x]")
    (data / "manifest.csv").write_text("id,category,prompt,task\n" + f'"s1[/x]",Box,"{prompt}","open the lid"\n')
    _run("benchmark", data / "manifest.csv", "--methods", "asset2sim,defaults", "--out", base / "bench", cwd=base)
    _run("pairs", base / "bench", "--defects", "mass_x100", cwd=base)
    said = f"{MARKUP} {HTML} {CONTROL} the more realistic one is A"
    with fake.FakeOpenAIServer(fake.reply(json.dumps({"more_realistic": "A", "reason": said})), lifetime_s=300) as srv:
        _run("judge", base / "bench", "--model", "openai/hostile", "--base-url", srv.url, "--timeout", "30", cwd=base,
             env={"ASSET2SIM_LLM_CACHE_DIR": "off"})
    _run("rate", base / "bench", "--scores", cwd=base)
    pages = [out / "report.html", base / f"ev{CONTROL}" / "report.html", base / "bench" / "summary.html",
             base / "bench" / "index.html", *sorted((base / "bench").glob("*/*/report.html"))]
    _browse([p for p in pages if p.is_file()])


def _chromium() -> str:
    try:
        import playwright.sync_api  # noqa: F401
    except ImportError:
        pytest.skip("playwright is not installed (pip install playwright)")
    for path in ("/usr/bin/chromium", shutil.which("chromium"), shutil.which("chromium-browser")):
        if path and os.access(path, os.X_OK):
            return path
    pytest.skip("no chromium executable (/usr/bin/chromium or chromium on PATH)")


def _browse(pages: list[Path]) -> None:
    """Open each page in headless Chromium: no script of a name runs (no ``window.__pwned``, no dialog), the page
    has no ``<script>`` or event-handler attribute, and the names read as written."""
    from playwright.sync_api import sync_playwright

    assert pages
    chromium = _chromium()
    seen_names = False
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=chromium, args=["--no-sandbox", "--disable-background-networking"])
        try:
            for path in pages:
                page = browser.new_page()
                dialogs: list[str] = []
                page.on("dialog", lambda d: (dialogs.append(d.message), d.dismiss()))
                page.goto(path.as_uri())
                page.wait_for_load_state("load")
                assert page.evaluate("window.__pwned") is None, path
                assert not dialogs, (path, dialogs)
                assert page.evaluate("document.querySelectorAll('script').length") == 0, path
                handlers = page.evaluate("[...document.querySelectorAll('*')].flatMap(e => [...e.attributes]"
                                         ".filter(a => a.name.startsWith('on')).map(a => e.tagName + ' ' + a.name))")
                assert handlers == [], (path, handlers[:5])
                text = page.inner_text("body")
                seen_names = seen_names or HTML in text
                page.close()
        finally:
            browser.close()
    assert seen_names, "the HTML name is shown as text in no report"
