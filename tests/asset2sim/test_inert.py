"""Names are inert wherever they are shown (``asset2sim.inert``): one hostile name set (console markup, HTML with
an event handler, mathtext, terminal control sequences, 10,000 characters) through each medium's helper, the
terminal of a command (its streams wrapped by ``asset2sim.cli.main``), the report's failure evidence, a figure and
``audit.md``. The end-to-end run of every command over an asset so named, with the report opened in Chromium, is
``tests/test_hostile_names.py``."""

from __future__ import annotations

import re
from pathlib import Path

from asset2sim import inert

HOSTILE = {
    "markup": "[/bold] [red]x[/] [link=file:///etc/passwd]y[/link]",
    "html": 'j<img src=x onerror="window.__pwned=1"><script>window.__pwned=2</script>&amp;',
    "mathtext": r"lid $\frac{1}{0}$ a$b",
    "control": "lid\x1b]0;pwned\x07\x1b[31m red\x08\x08\x9b2J\r\u202eevil\x00",
    "long": "n" * 10_000,
}
#: What no terminal line may hold: C0 controls but newline and tab, DEL, C1 controls, bidirectional overrides.
CONTROL = re.compile("[\x00-\x08\x0b-\x1f\x7f-\x9f\u202a-\u202e\u2066-\u2069]")


def test_terminal_shows_every_control_character_as_its_escape():
    for name in HOSTILE.values():
        shown = inert.terminal(name)
        assert not CONTROL.search(shown)
    assert inert.terminal(HOSTILE["control"]) == "lid\\x1b]0;pwned\\x07\\x1b[31m red\\x08\\x08\\x9b2J\\x0d\\u202eevil\\x00"
    assert inert.terminal("a\nb\tc") == "a\nb\tc" and inert.terminal("a\nb", newlines=False) == "a\\x0ab"


def test_markup_prints_every_name_as_written_in_rich():
    from rich.console import Console

    for name in HOSTILE.values():
        console = Console(record=True, width=20_000, color_system=None)
        console.print(f"[bold]{inert.markup(name)}[/bold]")
        assert console.export_text().rstrip("\n") == inert.terminal(name)


def test_html_text_and_markdown_text_leave_no_tag():
    for name in HOSTILE.values():
        for text in (inert.html_text(name), inert.markdown_text(name)):
            assert "<" not in text and ">" not in text and not CONTROL.search(text)
    assert inert.html_text('"\'') == "&quot;&#x27;"
    assert inert.markdown_text("a|b*c*[d]") == "a\\|b\\*c\\*\\[d\\]"


def test_one_line_keeps_the_first_line_without_a_traceback():
    msg = "HTTP 500: litellm.InternalServerError: boom\nTraceback (most recent call last):\n  File \"x.py\", line 1\nValueError"
    assert inert.one_line(msg) == "HTTP 500: litellm.InternalServerError: boom"
    assert inert.one_line("x Traceback (most recent call last): y") == "x"
    assert len(inert.one_line(HOSTILE["long"])) == inert.MAX_LINE and inert.one_line(HOSTILE["long"]).endswith("...")
    assert not CONTROL.search(inert.one_line(HOSTILE["control"]))


def test_a_figure_draws_names_as_text_never_as_mathtext():
    """A joint named with ``$`` in a report figure: drawn as the characters it has (matplotlib raised on it as
    mathtext, which lost the whole report)."""
    from asset2sim.tasks.evaluation.plots import new_figure, styled, svg_bytes

    @styled
    def draw(label: str) -> bytes:
        fig, axes = new_figure(1, 1, 400, 200, title=label)
        axes[0][0].plot([0, 1], [0, 1], label=label)
        axes[0][0].set(title=label, xlabel=label)
        axes[0][0].legend()
        return svg_bytes(fig)

    svg = draw(HOSTILE["mathtext"]).decode()
    assert r"\frac{1}{0}" in svg and "a$b" in svg


def test_failure_evidence_escapes_names_and_failure_text():
    """The report's "Why it failed" evidence (a failed task attempt here; robust-rest trials and sweeps share the
    heading helper) with a joint named with HTML: escaped, no tag from the name."""
    from asset2sim.tasks.evaluation.failure_evidence import evidence_section

    attempt = {"action": "open", "joint": HOSTILE["html"], "failure": "<svg onload=alert(1)>", "success": False,
               "reached": False, "held": False, "peak_force_n": 1.0, "root_slide_m": 0.0, "root_tilt_rad": 0.0,
               "force_limited": "<b>x</b>"}
    html = evidence_section({}, Path("/nonexistent/mobility.urdf"), 1 / 240, svg=lambda b, alt: "", figure=lambda img, cap: "",
                            task={"attempts": [attempt]}, closed={})
    assert "<img" not in html and "<script" not in html and "<svg" not in html and "<b>x" not in html
    assert inert.html_text(HOSTILE["html"]) in html


def test_audit_md_shows_names_as_text():
    from asset2sim.apps.audit.report_md import render
    from asset2sim.schemas.audit import AuditReport

    fields = {k: f.default for k, f in AuditReport.model_fields.items() if not f.is_required()}
    fields.update(asset_id=HOSTILE["html"], source=HOSTILE["markup"], format="urdf", category=HOSTILE["control"],
                  failure_mode="none", values=[], checks=[], notes=[HOSTILE["html"]], labels={HOSTILE["html"]: "lid"},
                  root_fixed=False, root_source="x", category_reason=None, patch=None)
    report = AuditReport.model_construct(**fields)
    text = render(report)
    assert "<img" not in text and "<script" not in text and not CONTROL.search(text)


def test_command_output_carries_no_control_sequence(tmp_path, capfd):
    """A command's own lines (``demo --asset-out`` naming a folder that holds ESC, OSC and BEL) and its error line
    reach the terminal with every control character escaped."""
    from asset2sim import cli

    folder = tmp_path / ("asset" + HOSTILE["control"].replace("\x00", ""))
    assert cli.main(["demo", "--object", "box_lid", "--asset-out", str(folder), "--no-refine"]) == 0
    assert cli.main(["demo", "--object", HOSTILE["control"].replace("\x00", "") + HOSTILE["markup"]]) == 2
    out, err = capfd.readouterr()
    assert "built demo asset" in out and "DEMO_OBJECT_UNKNOWN" in err
    assert not CONTROL.search(out + err), repr(out + err)
    assert "\\x1b]0;pwned\\x07" in out


def test_libraries_see_no_terminal_through_the_inert_stream_the_commands_consoles_do(monkeypatch):
    """On a terminal, the wrapped streams say they are none (a library's rich handler writes no escape sequences,
    which would be shown as text); the commands' own consoles write to the terminal beneath, styled."""
    import os
    import sys

    from asset2sim.commands import _output

    master, slave = os.openpty()
    try:
        with os.fdopen(slave, "w", closefd=False) as tty:
            wrapped = _output.InertStream(tty)
            assert not wrapped.isatty() and _output.raw(wrapped) is tty and tty.isatty()
            monkeypatch.setattr(sys, "stdout", wrapped)
            assert _output.console().is_terminal
    finally:
        os.close(master)
        os.close(slave)


#: Cells a spreadsheet would run (OWASP "CSV Injection"): a refused manifest id, a category, a prompt.
FORMULAS = ["=cmd|'-C calc'!A0", "+1+cmd|' /C calc'!A0", "-2+3", "@SUM(A1:A9)", "\t=1+1", "\r=1+1"]


def _spreadsheet_cells(path: Path) -> list[str]:
    """Every cell of a CSV file as a spreadsheet reads it (the csv module, the first line included)."""
    import csv

    with open(path, newline="", encoding="utf-8") as fh:
        return [cell for row in csv.reader(fh) for cell in row]


def _no_formula(cells: list[str]) -> None:
    for cell in cells:
        if cell.startswith(inert.FORMULA_START):
            float(cell)  # a number (-0.5) is shown as one; anything else starting so would be run


def test_the_benchmark_writes_no_formula_cell(tmp_path):
    """A manifest whose rows are all refused (ids and categories a spreadsheet runs): ``results.csv`` and
    ``summary.csv`` hold them as text (a leading '), read back cell by cell as a spreadsheet would."""
    from asset2sim.apps.benchmark import benchmark

    manifest = tmp_path / "manifest.csv"
    ids = FORMULAS[:4]  # (a leading tab or carriage return is stripped from an id: those two are categories here)
    rows = "".join(f'"{i}","{c}","{c}",,,0.5,\n' for i, c in zip(ids, FORMULAS[2:]))
    manifest.write_text("id,category,prompt,task,notes,reference_scale,x\n" + rows)
    records = benchmark.run_benchmark(manifest, ["defaults"], tmp_path / "bench", reports=False)
    assert {r["id"] for r in records} == set(ids) and all(r["error"] for r in records)
    benchmark.write_benchmark_outputs(records, ["defaults"], tmp_path / "bench", {"manifest": str(manifest)})
    cells = _spreadsheet_cells(tmp_path / "bench" / "results.csv")
    assert {"'" + i for i in ids} <= set(cells), cells
    _no_formula(cells)
    _no_formula(_spreadsheet_cells(tmp_path / "bench" / "summary.csv"))


def test_every_csv_is_written_through_the_spreadsheet_guard():
    """No module writes CSV but through :func:`asset2sim.inert.csv_text` (a DataFrame) or :func:`~asset2sim.inert.csv_cell`
    (each cell of a ``csv.writer`` row), so no writer added later forgets it."""
    root = Path(__file__).resolve().parents[2]
    found = []
    for folder in ("asset2sim", "tasks", "flows", "apps", "schemas"):
        for path in (root / folder).rglob("*.py"):
            text = path.read_text()
            if path.name == "inert.py":
                continue
            for m in re.finditer(r"\.to_csv\(|csv\.writer\(|csv\.DictWriter\(", text):
                if m.group(0).startswith("csv.") and "csv_cell(" in text:
                    continue
                found.append(f"{path.relative_to(root)}: {m.group(0)}")
    assert found == []
    assert [inert.csv_cell(f) for f in FORMULAS] == ["'" + f for f in FORMULAS]
    assert inert.csv_cell(-0.5) == -0.5 and inert.csv_cell("lid") == "lid"


def test_every_html_page_carries_the_content_security_policy():
    """Every page asset2sim writes or serves declares the one policy (no script, no plugin, no form or base to another
    site) in its ``<head>``: the report's and the benchmark's pages (``html_blocks.page``) and the rating app's, whose
    responses carry it as a header too; a module that starts an HTML document without it fails here."""
    from asset2sim.apps.realism import rating_app
    from asset2sim.tasks.evaluation.html_blocks import page

    head = page("t", "<p>b</p>").split("</head>")[0]
    assert inert.CSP_META in head and "script-src" not in inert.CONTENT_SECURITY_POLICY
    assert "default-src 'none'" in inert.CONTENT_SECURITY_POLICY
    assert rating_app._HEADERS["Content-Security-Policy"].startswith(inert.CONTENT_SECURITY_POLICY)
    root = Path(__file__).resolve().parents[2]
    for folder in ("asset2sim", "tasks", "flows", "apps"):
        for path in (root / folder).rglob("*.py"):
            text = path.read_text()
            if re.search(r"<!doctype html", text, re.I) and "CSP_META" not in text:
                raise AssertionError(f"{path.relative_to(root)} writes an HTML page without CSP_META")
