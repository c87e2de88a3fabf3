"""The benchmark's HTML pages: the summary in the thesis' layout beside the SPEC's numbers
(:func:`render_benchmark_summary`) and the index of the per-asset reports (:func:`render_benchmark_index`).
"""

from __future__ import annotations

from typing import Any

from asset2sim.tasks.evaluation.html_blocks import TEXTS, fmt, page, svg_tag, table
from asset2sim.tasks.evaluation.report_changes import esc


def _pm(mean: float | None, sd: float | None = None, pct: bool = False) -> str:
    if mean is None:
        return "-"
    k = 100.0 if pct else 1.0
    s = f"{mean * k:.3g}"
    if sd is not None:
        s += f" &plusmn; {sd * k:.3g}"
    return s + ("%" if pct else "")


#: The summary's pass-rate columns: (statistic, count of assets with a verdict), in column order.
_PASS_RATES = (("rest_stability_pass", "rest_n"), ("oscillation_pass", "osc_n"), ("probes_pass", "probes_n"),
               ("sweep_pass", "sweep_n"), ("robust_rest_pass", "robust_n"), ("task_pass", "task_n"), ("force_pass", "force_n"),
               ("ready", "ready_n"))


def render_benchmark_summary(tables: dict[str, dict[str, dict[str, Any]]], research: list[dict[str, str]],
                             meta: dict[str, Any], chart: bytes | None = None) -> str:
    """Thesis-layout tables per subset (``tables``: subset -> method -> row) beside the SPEC's numbers."""
    cols = TEXTS["benchmark_columns"]
    parts = [f"<h1>asset2sim benchmark</h1><p class='meta'>{esc(meta.get('manifest'))} &middot; methods "
             f"{esc(', '.join(meta.get('methods', [])))} &middot; seed {esc(meta.get('seed'))} &middot; "
             f"{esc(meta.get('rows'))} rows &middot; <a href='index.html'>per-object index</a></p>"]
    for subset, rows in tables.items():
        cells = []
        for method, r in rows.items():
            def spread(key: str) -> str:
                """The row's mean and standard deviation of ``key``."""
                return _pm(r.get(f"{key}_mean"), r.get(f"{key}_sd"))

            row = [spread("pen_ts"), spread("pen"),
                   *(_pm(r.get(rate), pct=True) + f" ({r.get(n, 0)})" for rate, n in _PASS_RATES),
                   spread("scale") + ("%" if r.get("scale_mean") is not None else ""), spread("init"),
                   _pm(r.get("prompt_mean"), pct=True), _pm(r.get("all_pass"), pct=True), fmt(r.get("median_seconds"), 3),
                   esc(r.get("realism", "not rated"))]
            err = f" <span class='small'>({r.get('errors')} failed to produce)</span>" if r.get("errors") else ""
            cells.append(f"\n<tr><td>{esc(method)}{err}</td>" + "".join(f"<td class='num'>{c}</td>" for c in row) + "</tr>")
        parts.append(f"<h2>{esc(subset)}</h2>" + table(["method", *cols], [*cells, "\n"]))
    parts.append("<h2>Research numbers (thesis 9-object set, Isaac Sim)</h2>" + table(
        research[0], ("<tr>" + "".join(f"<td>{esc(v)}</td>" for v in r.values()) + "</tr>" for r in research)))
    if chart:
        parts.append("<h2>Pass rates</h2>" + svg_tag(chart, "pass rates"))
    parts.append(TEXTS["benchmark_note"])
    return page("asset2sim benchmark", "\n".join(parts))


def render_benchmark_index(records: list[dict[str, Any]], meta: dict[str, Any]) -> str:
    """One colour-coded row per object and method, linking to each ``report.html``."""
    head = TEXTS["index_columns"]
    rows = []
    for r in records:
        lead = f"<tr><td>{esc(r['id'])}</td><td>{esc(r.get('category'))}</td><td>{esc(r['method'])}</td>"
        if r.get("error"):
            rows.append(f"{lead}<td class='fail' colspan='{len(head) - 3}'>{esc(r['error'])}</td></tr>")
            continue

        def v(name: str) -> str:
            p = r.get(f"{name}_pass")
            cls = "na" if p is None else ("pass" if p else "fail")
            return f"<td class='{cls}'>{fmt(r.get(name))}</td>"

        link = f"<a href='{esc(r['report'])}'>report</a>" if r.get("report") else "-"
        rows.append(
            f"{lead}<td class='{'pass' if r.get('all_pass') else 'fail'}'>{'pass' if r.get('all_pass') else 'FAIL'}</td>"
            + "".join(map(v, ("penetration", "rest_stability", "oscillation", "ground_penetration", "divergence", "state_hold",
                              "probes", "total_mass")))
            + f"<td class='num'>{fmt(r.get('scale_deviation'))}</td><td class='num'>{fmt(r.get('initial_joint_deviation'))}</td>"
            f"<td class='num'>{fmt(r.get('prompt_alignment'))}</td><td class='num'>{fmt(r.get('seconds'), 3)}</td><td>{link}</td></tr>"
        )
    return page("asset2sim benchmark index", f"<h1>Benchmark index</h1><p class='meta'>{esc(meta.get('manifest'))} &middot; "
                 "<a href='summary.html'>summary table</a> &middot; green pass, red fail, grey reported without threshold</p>"
                 + table(head, rows))
