"""Questions people ask of the Parquet result catalog.

Every function takes the DataFrame of :meth:`asset2sim.flows.catalog.ResultCatalog.read`
(one row per asset per run, with ``dataset`` and ``run``); the aggregating ones other than
:func:`run_summary` also take the Arrow table of :meth:`~asset2sim.flows.catalog.ResultCatalog.read_table`.
A row *passes all checks* when ``failure_mode == "none"``; ``stability_pass_rate`` /
``oscillation_pass_rate`` are over the rows with that verdict, other rates over every row;
runs are ordered by id (UTC start time first).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any, Iterable

from asset2sim.flows.catalog import ResultCatalog, plain_strings
from asset2sim.schemas.report import FAILURE_MODES
from asset2sim.tasks.check.verdict import MISSING_FAILURE_MODE


def _is_table(obj) -> bool:
    """True for a :class:`pyarrow.Table` (not a pandas DataFrame)."""
    return hasattr(obj, "schema") and hasattr(obj, "num_rows") and not hasattr(obj, "iloc")


def _frame(df, run: str | None):
    """``df`` (a DataFrame or an Arrow table) as a DataFrame, only the rows of ``run`` when given."""
    if _is_table(df):
        df = plain_strings(df).to_pandas()
    return df if run is None else df[df["run"] == run]


def _value_counts(arr) -> dict[Any, int]:
    import pyarrow.compute as pc

    return {d["values"]: int(d["counts"]) for d in pc.value_counts(arr).to_pylist()}


def load(catalog_root: Path | str, dataset: str | None = None, run: str | None = None):
    """Rows of the catalog at ``catalog_root`` (optionally one dataset / run)."""
    return ResultCatalog(catalog_root).read(dataset, run)


def latest_run(df, dataset: str | None = None) -> str | None:
    """Id of the most recent run (of ``dataset`` when given), None when empty."""
    if dataset is not None:
        df = df[df["dataset"] == dataset]
    return None if df.empty else str(max(df["run"].unique()))


def failure_modes(df, by: str | Iterable[str] = "category", run: str | None = None):
    """Counts of each failure mode (columns in vocabulary order, plus
    ``total``) per value of ``by`` (e.g. ``category``, ``("run", "category")``),
    with a ``total`` row; ``run``: one run only.

    Raises:
        KeyError: ``by`` names a column the catalog does not have.
    """
    import numpy as np
    import pandas as pd
    import pyarrow as pa
    import pyarrow.compute as pc

    keys = [by] if isinstance(by, str) else list(by)
    columns = df.schema.names if _is_table(df) else list(df.columns)
    for k in keys:
        if k not in columns:
            raise KeyError(f"no catalog column {k!r}; columns: {list(columns)}")
    if not _is_table(df):  # a DataFrame: counted in Arrow too
        df = pa.Table.from_pandas(df[list(dict.fromkeys([*keys, *(["run"] if run else []), "failure_mode"]))], preserve_index=False)
    # rows per (keys..., failure mode), missing key values as ``(unknown)``
    df = plain_strings(df)
    if run is not None:
        df = df.filter(pc.equal(df["run"], run))
    cols = {k: pc.fill_null(df[k] if pa.types.is_string(df[k].type) else df[k].cast(pa.string()), "(unknown)") for k in keys}
    cols["failure_mode"] = pc.fill_null(df["failure_mode"], MISSING_FAILURE_MODE)
    grouped = pa.table(cols).group_by([*keys, "failure_mode"]).aggregate([([], "count_all")]).to_pandas()
    counts = grouped.sort_values([*keys, "failure_mode"]).set_index([*keys, "failure_mode"])["count_all"]
    if len(counts) == 0:
        return pd.DataFrame(columns=[*keys, *FAILURE_MODES, "total"]).set_index(keys)
    table = counts.unstack("failure_mode", fill_value=0)
    table = table.reindex(columns=list(FAILURE_MODES), fill_value=0)
    table.columns = pd.Index([str(c) for c in table.columns], name="failure_mode")
    table = table.loc[table.sum(axis=1) > 0].astype(np.int64)
    table["total"] = table.sum(axis=1)
    total = table.sum(axis=0).to_frame().T
    total.index = pd.MultiIndex.from_tuples([("total",) * len(keys)], names=keys) if len(keys) > 1 else pd.Index(["total"], name=keys[0])
    return pd.concat([table, total]).astype(int)


def _rate(series) -> float | None:
    """The mean of a nullable boolean column (object True/False/None) over its non-null values; None when none."""
    s = series.astype("boolean").astype("Float64").astype(float).dropna()
    return float(s.mean()) if len(s) else None


#: Columns :func:`status_counts` reads.
COUNT_COLUMNS = ("status", "failure_mode")


def status_counts(df) -> dict[str, Any]:
    """The counting part of :func:`run_summary` (``assets``, ``done``,
    ``skipped``, ``failed``, ``failure_modes``, ``pass_rate_all``), from the
    columns :data:`COUNT_COLUMNS` alone; a DataFrame or an Arrow table."""
    import pyarrow as pa
    import pyarrow.compute  # noqa: F401  (pa.compute)

    t = df if _is_table(df) else pa.Table.from_pandas(df[list(COUNT_COLUMNS)], preserve_index=False)
    n = int(t.num_rows)
    st = _value_counts(t["status"]) if n else {}
    modes = _value_counts(pa.compute.fill_null(t["failure_mode"], MISSING_FAILURE_MODE)) if n else {}
    return {
        "assets": n, "done": st.get("done", 0), "skipped": st.get("skipped", 0), "failed": st.get("failed", 0),
        "failure_modes": {m: modes.get(m, 0) for m in FAILURE_MODES},
        "pass_rate_all": (modes.get("none", 0) / n) if n else None,
    }  # fmt: skip


def run_summary(df) -> dict[str, Any]:
    """Numbers of one run's rows (pass rates as fractions in [0, 1], penetration
    mm, seconds) of a DataFrame: what MLflow logs as the run's metrics."""
    counts = status_counts(df)
    out: dict[str, Any] = {k: counts[k] for k in ("assets", "done", "skipped", "failed")}
    if not len(df):
        out.update(pass_rate_all=None, stability_pass_rate=None, oscillation_pass_rate=None, failure_modes=counts["failure_modes"])
        return out
    pen, wall = df["penetration_mm"].dropna().astype(float), df["wall_seconds"].dropna().astype(float)
    worked = df[df["status"] == "done"]
    out.update(
        failure_modes=counts["failure_modes"],
        pass_rate_all=counts["pass_rate_all"],
        stability_pass_rate=_rate(df["rest_stable"]),
        oscillation_pass_rate=_rate(df["oscillation_pass"]),
        penetration_mm_mean=_stat(pen, "mean"),
        penetration_mm_std=_stat(pen, "std", ddof=0),
        prompt_alignment_mean=_stat(df["prompt_alignment"].dropna().astype(float), "mean"),
        queries_per_asset=float(worked["model_queries"].fillna(0).mean()) if len(worked) else 0.0,
        tokens_total=int(df["tokens"].fillna(0).sum()),
        asset_seconds_total=float(wall.sum()),
        asset_seconds_mean=_stat(wall, "mean"),
        asset_seconds_max=_stat(wall, "max"),
    )
    return out


def _stat(values, how: str, **kwargs) -> float | None:
    """``values.<how>(**kwargs)`` (a float Series' mean, std, max) as a float; None when there are no values."""
    return float(getattr(values, how)(**kwargs)) if len(values) else None


#: Columns :func:`pass_rates_over_time` reads.
PASS_RATE_COLUMNS = ("status", "failure_mode", "rest_stable", "oscillation_pass", "penetration_mm", "started_at")


def pass_rates_over_time(df, dataset: str | None = None):
    """Per run (chronological): start time, assets, the pass rates (all
    checks, rest stability, oscillation) and mean penetration (mm); one group-by in Arrow (a DataFrame is read
    as an Arrow table first)."""
    import pandas as pd
    import pyarrow as pa
    import pyarrow.compute as pc

    cols = ["dataset", "run", "started_at", "assets", "pass_rate_all", "stability_pass_rate",
            "oscillation_pass_rate", "penetration_mm_mean", "failed"]  # fmt: skip
    t = plain_strings(df) if _is_table(df) else pa.Table.from_pandas(df[["dataset", "run", *PASS_RATE_COLUMNS]], preserve_index=False)
    if dataset is not None:
        t = t.filter(pc.equal(t["dataset"], dataset))
    if t.num_rows == 0:
        return pd.DataFrame(columns=cols)
    work = pa.table({
        "dataset": t["dataset"], "run": t["run"], "started_at": t["started_at"],
        "pass": pc.equal(pc.fill_null(t["failure_mode"], MISSING_FAILURE_MODE), "none").cast(pa.float64()),
        "stable": t["rest_stable"].cast(pa.float64()), "osc": t["oscillation_pass"].cast(pa.float64()),
        "pen": t["penetration_mm"].cast(pa.float64()), "failed": pc.equal(t["status"], "failed").cast(pa.int64()),
    })  # fmt: skip
    agg = work.group_by(["dataset", "run"]).aggregate([
        ("started_at", "min"), ("pass", "count"), ("pass", "mean"), ("stable", "mean"),
        ("osc", "mean"), ("pen", "mean"), ("failed", "sum"),
    ]).to_pandas()  # fmt: skip
    out = pd.DataFrame({
        "dataset": agg["dataset"], "run": agg["run"], "started_at": agg["started_at_min"],
        "assets": agg["pass_count"].astype(int), "pass_rate_all": agg["pass_mean"],
        **{col: agg[f"{key}_mean"].astype(object).where(agg[f"{key}_mean"].notna(), None)
           for col, key in (("stability_pass_rate", "stable"), ("oscillation_pass_rate", "osc"), ("penetration_mm_mean", "pen"))},
        "failed": agg["failed_sum"].astype(int),
    })  # fmt: skip
    return out.sort_values(["dataset", "run"]).reset_index(drop=True)[cols]


#: Columns :func:`slowest_assets` reads.
SLOWEST_COLUMNS = ("asset_id", "category", "status", "failure_mode", "wall_seconds", "stage_seconds")


def slowest_assets(df, n: int = 10, run: str | None = None):
    """The ``n`` rows with the longest wall time (s), with their slowest stage.
    Skipped rows (no work done) are left out."""
    import pandas as pd

    df = _frame(df, run)
    df = df[df["status"] != "skipped"]
    cols = ["dataset", "run", "asset_id", "category", "status", "failure_mode", "wall_seconds", "slowest_stage", "slowest_stage_seconds"]
    if df.empty:
        return pd.DataFrame(columns=cols)
    d = df.loc[pd.to_numeric(df["wall_seconds"], errors="coerce").nlargest(int(n)).index].copy()

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


def slowest_in_catalog(store: ResultCatalog, dataset: str | None = None, runs: str | list[str] | None = None, n: int = 10):
    """:func:`slowest_assets` straight from the catalog in two passes: the
    ``n``-th longest wall time from the numeric columns, then only the rows
    at or above it with their text columns."""
    import pyarrow.compute as pc
    import pyarrow.dataset as pads

    worked = ~(pads.field("status") == "skipped") & pads.field("wall_seconds").is_valid()
    t = store.read_table(dataset, runs, columns=["status", "wall_seconds"], filter=worked)
    if t.num_rows == 0:
        return slowest_assets(store.read_table(dataset, runs, columns=[*SLOWEST_COLUMNS], limit=0), n)
    idx = pc.select_k_unstable(t, k=min(int(n), t.num_rows), sort_keys=[("wall_seconds", "descending")])
    threshold = pc.min(t["wall_seconds"].take(idx)).as_py()
    top = store.read_table(dataset, runs, columns=[*SLOWEST_COLUMNS], filter=worked & (pads.field("wall_seconds") >= threshold))
    return slowest_assets(top, n)


#: Columns :func:`verdict_changes` reads.
CHANGE_COLUMNS = ("asset_id", "category", "status", "failure_mode", "rest_stable", "oscillation_pass")


def verdict_changes(df, run_a: str, run_b: str):
    """Assets whose verdict (failure mode, rest stability or oscillation)
    differs between runs ``run_a`` and ``run_b``, or that are in only one of
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
    cols = ["asset_id", "category", *[f"{f}_{s}" for f in fields for s in ("a", "b")], "change"]
    a, b = (df[df["run"] == r][["asset_id", "category", *fields]].drop_duplicates("asset_id", keep="last")
            for r in (run_a, run_b))
    m = a.merge(b, on="asset_id", how="outer", suffixes=("_a", "_b"), indicator=True)
    if m.empty:
        return pd.DataFrame(columns=cols)
    m["category"] = m["category_b"].where(m["category_b"].notna(), m["category_a"])
    change = pd.Series([""] * len(m), index=m.index, dtype=object)
    change[m["_merge"] == "left_only"] = "only in " + run_a
    change[m["_merge"] == "right_only"] = "only in " + run_b
    both = m["_merge"] == "both"
    differs = {}
    for f in ("failure_mode", "rest_stable", "oscillation_pass"):
        xa, xb = m[f"{f}_a"], m[f"{f}_b"]
        differs[f] = both & ~((xa.isna() & xb.isna()) | (xa.astype(object) == xb.astype(object)).fillna(False).astype(bool))
    for idx in m.index[differs["failure_mode"] | differs["rest_stable"] | differs["oscillation_pass"]]:
        change[idx] = ", ".join(f"{f}: {m.at[idx, f + '_a']} -> {m.at[idx, f + '_b']}" for f, differ in differs.items() if differ[idx])
    m["change"] = change
    m = m[m["change"] != ""]
    out = m[cols].sort_values("asset_id").reset_index(drop=True)
    return out.astype(object).where(out.notna(), None)


def failed_assets(df, run: str | None = None, limit: int | None = None):
    """Rows of ``run`` that did not pass all checks (the first ``limit`` when
    given), with their error (first line)."""
    import pandas as pd

    df = _frame(df, run)
    d = df[df["failure_mode"].fillna(MISSING_FAILURE_MODE) != "none"]
    cols = ["asset_id", "category", "status", "failure_mode", "error"]
    if d.empty:
        return pd.DataFrame(columns=cols)
    if limit is not None:
        d = d.head(int(limit))
    d = d[cols].copy()
    d["error"] = d["error"].fillna("").map(lambda e: e.splitlines()[0][:160] if e else "")
    return d.reset_index(drop=True)
