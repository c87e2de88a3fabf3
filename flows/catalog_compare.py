"""A run compared with the previous run of its dataset (the latest earlier
run id holding rows), judged against ``catalog.yaml`` ``results.regression``
(:class:`asset2sim.flows.catalog.RegressionSettings`).

An asset *passes* when its failure mode is ``none``; it *regressed* when it
passed before and does not now, *improved* the other way, *changed* when it
failed both times differently. Pass-rate and metric drifts are over the
assets both runs hold; a metric's drift is ``mean(this) - mean(previous)``
over the common assets with both values, its *worsening* that drift where
lower is better and minus it where higher is better. A run is a regression
when any limit is exceeded. :func:`comparison_lines` gives the text.
"""

from __future__ import annotations

import json
from collections import Counter
from pathlib import Path
from typing import Any, Literal

from pydantic import BaseModel

from asset2sim import atomic
from asset2sim.flows.catalog import ResultCatalog
from asset2sim.flows.catalog_config import RegressionSettings
from asset2sim.flows.tracking import new_figure, write_png
from asset2sim.tasks.check.verdict import MISSING_FAILURE_MODE
from asset2sim.inert import csv_text, plot_text

#: Metric columns compared between runs: column -> (unit, True when higher is better).
COMPARED_METRICS: dict[str, tuple[str, bool]] = {
    "penetration_mm": ("mm", False),
    "d_pos_m": ("m", False),
    "d_ori_rad": ("rad", False),
    "rest_stable": ("fraction", True),
    "oscillation_pass": ("fraction", True),
    "prompt_alignment": ("score", True),
    "scale_deviation_pct": ("%", False),
    "wall_seconds": ("s", False),
}
#: Columns a comparison reads.
COMPARE_COLUMNS = ("asset_id", "category", "status", "failure_mode", *COMPARED_METRICS)


class VerdictFlip(BaseModel):
    """One asset whose verdict differs between the runs."""

    asset_id: str
    category: str | None = None
    before: str
    after: str
    direction: Literal["regressed", "improved", "changed"]


class MetricDrift(BaseModel):
    """One metric's means over the common assets (``n`` with both values),
    ``drift`` = after - before, ``worsening`` (see the module docstring),
    the limit from ``catalog.yaml`` (None: none) and whether it was exceeded."""

    column: str
    unit: str
    n: int
    before: float | None = None
    after: float | None = None
    drift: float | None = None
    worsening: float | None = None
    limit: float | None = None
    exceeded: bool = False


class RunComparison(BaseModel):
    """This run against the previous run of its dataset."""

    dataset: str
    run: str
    previous_run: str | None = None
    assets: int = 0
    previous_assets: int = 0
    common_assets: int = 0
    pass_rate: float | None = None
    previous_pass_rate: float | None = None
    common_pass_rate: float | None = None
    previous_common_pass_rate: float | None = None
    pass_rate_drift: float | None = None
    regressed: int = 0
    improved: int = 0
    changed: int = 0
    flips: list[VerdictFlip] = []
    metrics: list[MetricDrift] = []
    exceeded: bool = False
    reasons: list[str] = []
    nothing_done: bool = False
    """The run reused every asset's earlier result: not compared, no drift recorded."""

    @property
    def status(self) -> str:
        """``nothing_done``, ``no_previous_run``, ``regressed`` (a limit exceeded) or ``ok``."""
        if self.nothing_done:
            return "nothing_done"
        if self.previous_run is None:
            return "no_previous_run"
        return "regressed" if self.exceeded else "ok"

    def tags(self) -> dict[str, str]:
        """MLflow tags of the comparison (``regression.*``)."""
        return {
            "regression.status": self.status,
            "regression.previous_run": self.previous_run or "",
            "regression.regressed_assets": str(self.regressed),
            "regression.improved_assets": str(self.improved),
            "regression.pass_rate_drift": "" if self.pass_rate_drift is None else f"{self.pass_rate_drift:.4f}",
            "regression.reasons": "; ".join(self.reasons)[:5000],
        }

    def metrics_for_tracking(self) -> dict[str, float]:
        """Numbers of the comparison for the run's metrics (finite only; none for a run that did no work)."""
        if self.nothing_done:
            return {}
        out = {"regressed_assets": float(self.regressed), "improved_assets": float(self.improved)}
        if self.pass_rate_drift is not None:
            out["pass_rate_drift"] = float(self.pass_rate_drift)
        for m in self.metrics:
            if m.drift is not None:
                out[f"drift_{m.column}"] = float(m.drift)
        return out


def did_work(store: ResultCatalog, dataset: str, run: str) -> bool:
    """Whether ``run`` refined or failed at least one asset (a rerun that reused every earlier result did not)."""
    return any(s != "skipped" for s in store.read_table(dataset, run, columns=["status"])["status"].to_pylist())


def previous_run(store: ResultCatalog, dataset: str, run: str) -> str | None:
    """The latest run of ``dataset`` before ``run`` (by id) that did work (:func:`did_work`); None when there is none."""
    earlier = [r for d, r in store.runs(dataset) if r < run]
    return next((r for r in reversed(earlier) if did_work(store, dataset, r)), None)


def _pass_rate(df) -> float | None:
    """The share of ``df``'s rows that pass all checks; None for no rows."""
    return float((df["failure_mode"].fillna(MISSING_FAILURE_MODE) == "none").mean()) if len(df) else None


def _as_float(series):
    """A catalog column as floats (booleans 1/0, null as NaN)."""
    import pandas as pd

    if series.dtype == object or str(series.dtype) in ("bool", "boolean"):
        series = series.map(lambda v: None if v is None or (isinstance(v, float) and v != v) else float(v))
    return pd.to_numeric(series, errors="coerce")


def compare_runs(previous, current, *, dataset: str, run: str, previous_run_id: str | None,
                 settings: RegressionSettings | None = None) -> RunComparison:
    """Compare the rows of ``current`` (DataFrame of one run, the columns of
    :data:`COMPARE_COLUMNS` at least) with ``previous`` (the previous run's,
    or None) under ``settings`` (default: :class:`RegressionSettings`).

    Raises:
        KeyError: a column of :data:`COMPARE_COLUMNS` is missing.
    """
    settings = settings or RegressionSettings()
    out = RunComparison(dataset=dataset, run=run, previous_run=previous_run_id, assets=int(len(current)))
    out.pass_rate = _pass_rate(current)
    if previous is None or previous_run_id is None:
        return out
    out.previous_assets, out.previous_pass_rate = int(len(previous)), _pass_rate(previous)
    a, b = (df[list(COMPARE_COLUMNS)].drop_duplicates("asset_id", keep="last").set_index("asset_id")
            for df in (previous, current))
    both = a.join(b, how="inner", lsuffix="_a", rsuffix="_b")
    out.common_assets = int(len(both))
    if len(both):
        ma, mb = (both[f"failure_mode_{s}"].fillna(MISSING_FAILURE_MODE) for s in "ab")
        out.previous_common_pass_rate, out.common_pass_rate = float((ma == "none").mean()), float((mb == "none").mean())
        out.pass_rate_drift = out.common_pass_rate - out.previous_common_pass_rate
        for aid, rec in both[ma != mb].sort_index().iterrows():
            before, after = ma[aid], mb[aid]
            direction = "regressed" if before == "none" else ("improved" if after == "none" else "changed")
            cat = rec["category_b"] if isinstance(rec["category_b"], str) else rec["category_a"]
            out.flips.append(VerdictFlip(asset_id=str(aid), category=cat if isinstance(cat, str) else None,
                                         before=before, after=after, direction=direction))
        directions = Counter(f.direction for f in out.flips)
        out.regressed, out.improved, out.changed = (directions[d] for d in ("regressed", "improved", "changed"))
        reused = (both["status_a"] == "skipped") | (both["status_b"] == "skipped")
        for col, (unit, higher_better) in COMPARED_METRICS.items():
            va, vb = _as_float(both[f"{col}_a"]), _as_float(both[f"{col}_b"])
            ok = va.notna() & vb.notna()
            if col == "wall_seconds":  # a reused result took no time of its own: not a speed-up
                ok &= ~reused
            m = MetricDrift(column=col, unit=unit, n=int(ok.sum()), limit=settings.max_metric_drift.get(col))
            if m.n:
                m.before, m.after = float(va[ok].mean()), float(vb[ok].mean())
                m.drift = m.after - m.before
                m.worsening = -m.drift if higher_better else m.drift
                m.exceeded = m.limit is not None and m.worsening > m.limit
            out.metrics.append(m)
    if out.regressed > settings.max_regressed_assets:
        names = ", ".join(f.asset_id for f in out.flips if f.direction == "regressed")
        out.reasons.append(f"{out.regressed} asset(s) no longer pass all checks (limit {settings.max_regressed_assets}): {names}")
    if out.pass_rate_drift is not None and -out.pass_rate_drift > settings.max_pass_rate_drop + 1e-12:
        out.reasons.append(f"pass rate over the {out.common_assets} common assets fell by {-100 * out.pass_rate_drift:.1f} "
                           f"points (limit {100 * settings.max_pass_rate_drop:.1f})")
    out.reasons += [f"mean {m.column} worsened by {m.worsening:.4g} {m.unit} (limit {m.limit:.4g})"
                    for m in out.metrics if m.exceeded]
    unknown = sorted(set(settings.max_metric_drift) - set(COMPARED_METRICS))
    if unknown:
        out.reasons.append(f"results.regression.max_metric_drift names unknown metric(s) {unknown}; known: {sorted(COMPARED_METRICS)}")
    out.exceeded = bool(out.reasons)
    return out


def compare_with_previous(store: ResultCatalog, dataset: str, run: str,
                          settings: RegressionSettings | None = None) -> RunComparison:
    """:func:`compare_runs` of ``run`` against :func:`previous_run` read from ``store``; a run that did no
    work (every asset reused) is not compared (``nothing_done``): its figures would only echo the earlier run's."""
    cols = list(COMPARE_COLUMNS)
    current = store.read(dataset, run, columns=cols)
    nothing_done = bool(len(current)) and not (current["status"] != "skipped").any()
    prev_id = None if nothing_done else previous_run(store, dataset, run)
    previous = None if prev_id is None else store.read(dataset, prev_id, columns=cols)
    out = compare_runs(previous, current, dataset=dataset, run=run, previous_run_id=prev_id, settings=settings)
    out.nothing_done = nothing_done
    return out


def _pct(v: float | None) -> str:
    return "n/a" if v is None else f"{100 * v:.1f}%"


def comparison_lines(cmp: RunComparison, max_flips: int = 20) -> list[str]:
    """The comparison as text lines for a terminal or a log."""
    if cmp.nothing_done:
        return ["regression check: nothing to do in this run (every asset's earlier result reused); not compared"]
    if cmp.previous_run is None:
        return [f"regression check: no earlier run of dataset {cmp.dataset} to compare with"]
    head = "REGRESSION" if cmp.exceeded else "no regression"
    lines = [
        f"regression check against run {cmp.previous_run}: {head}",
        f"  pass rate (all checks) {_pct(cmp.previous_pass_rate)} -> {_pct(cmp.pass_rate)} "
        f"({cmp.previous_assets} -> {cmp.assets} assets); over the {cmp.common_assets} common assets "
        f"{_pct(cmp.previous_common_pass_rate)} -> {_pct(cmp.common_pass_rate)}"
        + ("" if cmp.pass_rate_drift is None else f" ({100 * cmp.pass_rate_drift:+.1f} points)"),
        f"  verdict flips: {cmp.regressed} regressed, {cmp.improved} improved, {cmp.changed} changed failure mode",
    ]
    lines += [f"    {f.direction:9s} {f.asset_id} ({f.category or '?'}): {f.before} -> {f.after}" for f in cmp.flips[:max_flips]]
    if len(cmp.flips) > max_flips:
        lines.append(f"    ... and {len(cmp.flips) - max_flips} more (verdict_flips.csv)")
    drifts = [m for m in cmp.metrics if m.drift is not None and (m.drift != 0 or m.exceeded)]
    if drifts:
        lines.append("  metric drift (mean over common assets):")
        for m in drifts:
            mark = "  EXCEEDS LIMIT" if m.exceeded else ""
            lines.append(f"    {m.column:20s} {m.before:.4g} -> {m.after:.4g} {m.unit} ({m.drift:+.4g}){mark}")
    return lines + [f"  ! {r}" for r in cmp.reasons]


def pass_rate_figure(history, current_run: str, title: str):
    """A matplotlib Figure: the pass rates per run (all checks, rest
    stability, oscillation; fractions) in run order, ``current_run`` marked.
    ``history``: :func:`asset2sim.flows.queries.pass_rates_over_time`."""
    fig, ax = new_figure(7.0, 3.6)
    x = list(range(len(history)))
    for col, label, color in (("pass_rate_all", "all checks", "#4caf50"), ("stability_pass_rate", "rest stability", "#2196f3"),
                              ("oscillation_pass_rate", "oscillation", "#9c27b0")):
        ys = [None if v is None or v != v else 100 * float(v) for v in history[col]] if len(history) else []
        ax.plot(x, ys, marker="o", markersize=3, label=label, color=color)
    for i, r in enumerate(history["run"] if len(history) else []):
        if r == current_run:
            ax.axvline(i, color="#999999", linestyle="--", linewidth=0.8)
    step = max(1, len(history) // 12)
    ax.set_xticks(x[::step])
    ax.set_xticklabels([plot_text(str(r)[:15]) for r in list(history["run"])[::step]], rotation=30, ha="right", fontsize=7)
    ax.set_ylim(-2, 102)
    ax.set_ylabel("pass rate (%)")
    ax.set_title(plot_text(title))  # a dataset's name: never mathtext
    ax.legend(fontsize=7, loc="lower left")
    fig.tight_layout()
    return fig


def write_comparison_artifacts(cmp: RunComparison, history, out_dir: Path | str) -> dict[str, Path]:
    """Write ``comparison.json`` (the :class:`RunComparison`),
    ``verdict_flips.csv`` and ``pass_rate_over_runs.png`` (``history``:
    :func:`asset2sim.flows.queries.pass_rates_over_time` of the dataset) into
    ``out_dir`` atomically; returns name -> path."""
    import pandas as pd

    out_dir = Path(out_dir)
    data = cmp.model_dump(mode="json")
    data["status"] = cmp.status
    paths = {"comparison.json": atomic.write_text(out_dir / "comparison.json", json.dumps(data, indent=2) + "\n")}
    flips = pd.DataFrame([f.model_dump() for f in cmp.flips], columns=list(VerdictFlip.model_fields))
    paths["verdict_flips.csv"] = atomic.write_text(out_dir / "verdict_flips.csv", csv_text(flips))
    fig = pass_rate_figure(history, cmp.run, f"{cmp.dataset}: pass rate over runs")
    paths["pass_rate_over_runs.png"] = write_png(out_dir / "pass_rate_over_runs.png", fig)
    return paths


def comparison_summary(cmp: RunComparison) -> dict[str, Any]:
    """The comparison as the flow's summary holds it (plain JSON values)."""
    return {**{k: getattr(cmp, k) for k in ("status", "exceeded", "previous_run", "regressed", "improved", "pass_rate_drift")},
            "reasons": list(cmp.reasons), "lines": comparison_lines(cmp)}
