"""``audit.md``: an audit report as Markdown for people (the verdicts, the simulation checks on the declared
and patched physics, and the changes the patch makes: the diff a reviewer reads)."""

from __future__ import annotations

from asset2sim.inert import markdown_text as md
from asset2sim.schemas.audit import AuditReport, ValueVerdict
from asset2sim.tasks.check.verdict import readiness


def _num(v: float | None) -> str:
    return "-" if v is None else f"{v:.4g}"


def _row(v: ValueVerdict) -> str:
    verdict = v.verdict.replace("_", " ") + (f" (x{v.factor:.3g})" if v.verdict == "implausible" and v.factor not in (None, 0) else "")
    band = "-" if v.low is None and v.high is None else f"{_num(v.low) if v.low is not None else '0'} - {_num(v.high) if v.high is not None else 'inf'}"
    return (f"| {md(v.where)} | {md(v.quantity)} | {_num(v.declared)} | {_num(v.estimate)} | {band} | {md(v.unit)} | **{md(verdict)}** | "
            f"{md(v.reason)} |")


def changes(report: AuditReport) -> list[ValueVerdict]:
    """The values the patch changes."""
    return [v for v in report.values if v.patched is not None]


def render(report: AuditReport) -> str:
    """The report as Markdown text."""
    bad = report.implausible
    lines = [f"# Audit of {md(report.asset_id)}", "",
             f"- input: {md(report.source)} ({report.format.upper()})",
             f"- category: {md(report.category)} ({md(report.category_reason or 'given')})",
             f"- root: {'fixed (mounted)' if report.root_fixed else 'free (on the ground)'}; {md(report.root_source)}",
             f"- verdict: **{report.failure_mode}**: {len(bad)} implausible of {len(report.values)} values judged",
             ""]
    if report.labels:
        lines += ["Part labels used: " + ", ".join(f"{md(k)} = {md(v)}" for k, v in report.labels.items()), ""]
    lines += ["## Values", "", "| where | quantity | declared | estimate | plausible | unit | verdict | why |",
              "|---|---|---|---|---|---|---|---|", *(_row(v) for v in report.values), ""]
    lines += ["## Simulation checks", ""]
    if not report.checks:
        lines += ["Not run.", ""]
    for c in report.checks:
        state = ("could not run: " + c.error) if c.error else readiness(list(c.metrics)).line()  # refine's words
        lines.append(f"- {md(c.physics)} physics: {md(state)}")
        for m in c.metrics:
            lines.append(f"  - {md(m.name)}: {_num(m.value)} {md(m.unit)} ({'pass' if m.passed else 'FAIL' if m.passed is False else 'n/a'}; "
                         f"{md(m.threshold)})")
    lines.append("")
    lines += ["## Changes in the patch", ""]
    diff = changes(report)
    if not diff:
        lines += ["None: every judged value is kept.", ""]
    else:
        lines += [f"Patched file: {md(report.patch)}" if report.patch else "No patch written (no output folder).", "",
                  "| where | quantity | declared | patched | unit | why |", "|---|---|---|---|---|---|"]
        lines += [f"| {md(v.where)} | {md(v.quantity)} | {_num(v.declared)} | {_num(v.patched)} | {md(v.unit)} | "
                  f"{md(v.verdict.replace('_', ' '))}: {md(v.reason)} |" for v in diff]
        lines += ["", "Inertia rows give the tensor's trace; center-of-mass rows the distance from the geometric center of mass.", ""]
    if report.notes:
        lines += ["## Notes", "", *(f"- {md(n)}" for n in report.notes), ""]
    return "\n".join(lines)
