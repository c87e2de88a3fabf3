"""Questions people ask of the Parquet result catalog.

Every function takes the DataFrame of :meth:`asset2sim.catalog.ResultCatalog.read`
(one row per asset per run, with the partition columns ``dataset`` and ``run``)
and returns a small DataFrame or dict; nothing here prints.

Definitions used throughout:

- a row *passes all checks* when ``failure_mode == "none"`` (refined, rest
  stable, not oscillating, penetration resolved);
- ``stability_pass_rate`` / ``oscillation_pass_rate`` are over rows that have
  that verdict (failed chains without a measurement are left out), all other
  rates over every row of the run;
- runs are ordered by their id, which starts with the UTC start time.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any, Iterable

from asset2sim.catalog import ResultCatalog
from asset2sim.schemas.report import FAILURE_MODES
from asset2sim.tasks.check.verdict import MISSING_FAILURE_MODE


def load(catalog_root: Path | str, dataset: str | None = None, run: str | None = None):
    """Rows of the catalog at ``catalog_root`` (optionally one dataset / run)."""
    return ResultCatalog(catalog_root).read(dataset, run)


def runs(df) -> "Any":
    """One line per (dataset, run): first start time, assets, done, skipped,
    failed, sorted chronologically."""
    import pandas as pd

    if df.empty:
        return pd.DataFrame(columns=["dataset", "run", "started_at", "assets", "done", "skipped", "failed"])
    g = df.groupby(["dataset", "run"], sort=True)
    out = g.agg(
        started_at=("started_at", "min"),
        assets=("asset_id", "count"),
        done=("status", lambda s: int((s == "done").sum())),
        skipped=("status", lambda s: int((s == "skipped").sum())),
        failed=("status", lambda s: int((s == "failed").sum())),
    ).reset_index()
    return out.sort_values(["dataset", "run"]).reset_index(drop=True)


def latest_run(df, dataset: str | None = None) -> str | None:
    """Id of the most recent run (of ``dataset`` when given), None when empty."""
    if dataset is not None:
        df = df[df["dataset"] == dataset]
    if df.empty:
        return None
    return str(sorted(df["run"].unique())[-1])


def failure_modes(df, by: str | Iterable[str] = "category", run: str | None = None):
    """Counts of each failure mode (columns, the fixed vocabulary in order,
    plus ``total``) per value of ``by`` (rows; e.g. ``category``, ``run``,
    ``("run", "category")``), with a ``total`` row. ``run`` restricts to one run.

    Raises:
        KeyError: ``by`` names a column the catalog does not have.
    """
    import pandas as pd

    keys = [by] if isinstance(by, str) else list(by)
    for k in keys:
        if k not in df.columns:
            raise KeyError(f"no catalog column {k!r}; columns: {list(df.columns)}")
    if run is not None:
        df = df[df["run"] == run]
    if df.empty:
        return pd.DataFrame(columns=[*keys, *FAILURE_MODES, "total"]).set_index(keys)
    d = df.copy()
    for k in keys:
        d[k] = d[k].fillna("(unknown)")
    d["failure_mode"] = pd.Categorical(d["failure_mode"].fillna(MISSING_FAILURE_MODE), categories=list(FAILURE_MODES))
    table = pd.crosstab([d[k] for k in keys], d["failure_mode"], dropna=False)
    table = table.reindex(columns=list(FAILURE_MODES), fill_value=0)
    table = table.loc[table.sum(axis=1) > 0]
    table["total"] = table.sum(axis=1)
    total = table.sum(axis=0).to_frame().T
    total.index = pd.MultiIndex.from_tuples([("total",) * len(keys)], names=keys) if len(keys) > 1 else pd.Index(["total"], name=keys[0])
    return pd.concat([table, total]).astype(int)


def _rate(series) -> float | None:
    s = series.dropna()
    if len(s) == 0:
        return None
    return float(s.astype(bool).mean())


def run_summary(df) -> dict[str, Any]:
    """Numbers of one run's rows (pass rates as fractions in [0, 1], penetration
    mm, seconds): what MLflow logs as the run's metrics."""
    n = int(len(df))
    out: dict[str, Any] = {
        "assets": n,
        "done": int((df["status"] == "done").sum()) if n else 0,
        "skipped": int((df["status"] == "skipped").sum()) if n else 0,
        "failed": int((df["status"] == "failed").sum()) if n else 0,
    }
    if n == 0:
        out.update(pass_rate_all=None, stability_pass_rate=None, oscillation_pass_rate=None)
        out["failure_modes"] = {m: 0 for m in FAILURE_MODES}
        return out
    modes = df["failure_mode"].fillna(MISSING_FAILURE_MODE)
    out["failure_modes"] = {m: int((modes == m).sum()) for m in FAILURE_MODES}
    out["pass_rate_all"] = float((modes == "none").mean())
    out["stability_pass_rate"] = _rate(df["rest_stable"])
    out["oscillation_pass_rate"] = _rate(df["oscillation_pass"])
    pen = df["penetration_mm"].dropna().astype(float)
    out["penetration_mm_mean"] = float(pen.mean()) if len(pen) else None
    out["penetration_mm_std"] = float(pen.std(ddof=0)) if len(pen) else None
    pa = df["prompt_alignment"].dropna().astype(float)
    out["prompt_alignment_mean"] = float(pa.mean()) if len(pa) else None
    worked = df[df["status"] == "done"]
    out["queries_per_asset"] = float(worked["model_queries"].fillna(0).mean()) if len(worked) else 0.0
    out["tokens_total"] = int(df["tokens"].fillna(0).sum())
    wall = df["wall_seconds"].dropna().astype(float)
    out["asset_seconds_total"] = float(wall.sum())
    out["asset_seconds_mean"] = float(wall.mean()) if len(wall) else None
    out["asset_seconds_max"] = float(wall.max()) if len(wall) else None
    return out


def pass_rates_over_time(df, dataset: str | None = None):
    """Per run (chronological): start time, assets, and the pass rates
    (all checks, rest stability, oscillation) with mean penetration (mm)."""
    import pandas as pd

    if dataset is not None:
        df = df[df["dataset"] == dataset]
    rows = []
    for (ds, run), g in df.groupby(["dataset", "run"], sort=True):
        s = run_summary(g)
        rows.append(
            {
                "dataset": ds,
                "run": run,
                "started_at": g["started_at"].min(),
                "assets": s["assets"],
                "pass_rate_all": s["pass_rate_all"],
                "stability_pass_rate": s["stability_pass_rate"],
                "oscillation_pass_rate": s["oscillation_pass_rate"],
                "penetration_mm_mean": s.get("penetration_mm_mean"),
                "failed": s["failed"],
            }
        )
    return pd.DataFrame(
        rows,
        columns=["dataset", "run", "started_at", "assets", "pass_rate_all", "stability_pass_rate",
                 "oscillation_pass_rate", "penetration_mm_mean", "failed"],
    )  # fmt: skip


def slowest_assets(df, n: int = 10, run: str | None = None):
    """The ``n`` rows with the longest wall time (s), with their slowest stage.
    Skipped rows (no work done) are left out."""
    import pandas as pd

    if run is not None:
        df = df[df["run"] == run]
    df = df[df["status"] != "skipped"]
    cols = ["dataset", "run", "asset_id", "category", "status", "failure_mode", "wall_seconds", "slowest_stage", "slowest_stage_seconds"]
    if df.empty:
        return pd.DataFrame(columns=cols)
    d = df.sort_values("wall_seconds", ascending=False).head(int(n)).copy()

    def slowest(js: str | None) -> tuple[str | None, float | None]:
        try:
            stages = {k: float(v) for k, v in json.loads(js or "{}").items() if "." in k}
        except ValueError:
            return None, None
        if not stages:
            return None, None
        k = max(stages, key=stages.get)
        return k, stages[k]

    pairs = [slowest(js) for js in d["stage_seconds"]]
    d["slowest_stage"] = [p[0] for p in pairs]
    d["slowest_stage_seconds"] = [p[1] for p in pairs]
    return d[cols].reset_index(drop=True)


def verdict_changes(df, run_a: str, run_b: str):
    """Assets whose verdict differs between runs ``run_a`` and ``run_b``
    (failure mode, rest stability or oscillation), or that are in only one of
    them. Columns ``asset_id``, ``category``, ``<field>_a``, ``<field>_b``, ``change``.

    Raises:
        KeyError: a run id is not in the catalog.
    """
    import pandas as pd

    present = set(df["run"].unique()) if not df.empty else set()
    for r in (run_a, run_b):
        if r not in present:
            raise KeyError(f"run {r!r} is not in the catalog")
    fields = ["failure_mode", "rest_stable", "oscillation_pass", "status"]
    a = df[df["run"] == run_a].set_index("asset_id")
    b = df[df["run"] == run_b].set_index("asset_id")
    rows = []
    for aid in sorted(set(a.index) | set(b.index)):
        ra = a.loc[aid] if aid in a.index else None
        rb = b.loc[aid] if aid in b.index else None
        rec: dict[str, Any] = {"asset_id": aid, "category": (rb if rb is not None else ra)["category"]}
        for f in fields:
            rec[f"{f}_a"] = None if ra is None else ra[f]
            rec[f"{f}_b"] = None if rb is None else rb[f]
        if ra is None or rb is None:
            rec["change"] = "only in " + (run_b if ra is None else run_a)
        else:
            diffs = [f for f in ("failure_mode", "rest_stable", "oscillation_pass") if not _same(ra[f], rb[f])]
            if not diffs:
                continue
            rec["change"] = ", ".join(f"{f}: {ra[f]} -> {rb[f]}" for f in diffs)
        rows.append(rec)
    cols = ["asset_id", "category", *[f"{f}_{s}" for f in fields for s in ("a", "b")], "change"]
    return pd.DataFrame(rows, columns=cols)


def _same(x: Any, y: Any) -> bool:
    import pandas as pd

    if pd.isna(x) and pd.isna(y):
        return True
    return bool(x == y)


def failed_assets(df, run: str | None = None):
    """Rows of ``run`` that did not pass all checks, with their error (first line)."""
    import pandas as pd

    if run is not None:
        df = df[df["run"] == run]
    d = df[df["failure_mode"].fillna(MISSING_FAILURE_MODE) != "none"]
    cols = ["asset_id", "category", "status", "failure_mode", "error"]
    if d.empty:
        return pd.DataFrame(columns=cols)
    d = d[cols].copy()
    d["error"] = d["error"].fillna("").map(lambda e: e.splitlines()[0][:160] if e else "")
    return d.reset_index(drop=True)
