"""The audit catalog: one Parquet row per audited asset (``audit_assets.parquet``, :class:`AuditRow`) and one per
judged value (``audit_values.parquet``, :class:`ValueVerdict` with the asset id and category), written atomically
into the audit's output folder; and the tables people query them for (failure modes and implausible quantities
per category)."""

from __future__ import annotations

from pathlib import Path

from asset2sim import atomic
from asset2sim.schemas.audit import AuditReport, AuditRow, ValueVerdict
from asset2sim.schemas.catalog import parquet_bytes
from asset2sim.apps.audit.audit import AUDIT_JSON

#: File names of the audit catalog inside the output folder.
ASSETS_PARQUET = "audit_assets.parquet"
VALUES_PARQUET = "audit_values.parquet"
#: The failure modes of an audit row, in table order.
AUDIT_MODES = ("none", "implausible_values", "values_missing", "declared_physics_fails", "audit_failed")


def _write_parquet(path: Path, df) -> None:
    import pyarrow as pa

    atomic.write_bytes(path, parquet_bytes(pa.Table.from_pandas(df, preserve_index=False)))


def values_frame(rows: list[AuditRow]):
    """Every judged value of the audited ``rows`` (read from each asset's ``audit.json``) as a DataFrame: the
    :class:`~asset2sim.schemas.audit.ValueVerdict` columns plus ``asset_id`` and ``category``."""
    import pandas as pd

    records = []
    for row in rows:
        if not row.out_dir or not (Path(row.out_dir) / AUDIT_JSON).is_file():
            continue
        report = AuditReport.model_validate_json(atomic.read_regular(Path(row.out_dir) / AUDIT_JSON))
        records += [{"asset_id": row.asset_id, "category": report.category, **v.model_dump(mode="json")} for v in report.values]
    return pd.DataFrame.from_records(records, columns=["asset_id", "category", *ValueVerdict.model_fields])


def write_audit_catalog(out_root: Path | str, rows: list[AuditRow]) -> dict[str, Path]:
    """``audit_assets.parquet`` and ``audit_values.parquet`` in ``out_root``; returns name -> path.

    Raises:
        OSError: the files cannot be written.
    """
    import pandas as pd

    out_root = Path(out_root)
    out_root.mkdir(parents=True, exist_ok=True)
    assets = pd.DataFrame.from_records([r.model_dump(mode="json") for r in rows], columns=list(AuditRow.model_fields))
    paths = {"assets": out_root / ASSETS_PARQUET, "values": out_root / VALUES_PARQUET}
    _write_parquet(paths["assets"], assets)
    _write_parquet(paths["values"], values_frame(rows))
    return paths


#: The column of :func:`failure_modes_by_category` counting every asset whose declared physics fails a check in
#: simulation, whatever its first failure mode (an asset with implausible values may fail one too).
DECLARED_NOT_READY = "declared_physics_not_ready"


def failure_modes_by_category(assets):
    """Assets per category (rows, plus ``total``) and failure mode (columns :data:`AUDIT_MODES`: each asset once,
    under its first mode), then :data:`DECLARED_NOT_READY`: the assets whose declared physics fails a check in
    simulation, whichever mode came first, so a failing check is never counted as 0 beside an asset that has one;
    from the ``audit_assets`` table."""
    import pandas as pd

    if assets.empty:
        return pd.DataFrame(columns=[*AUDIT_MODES, DECLARED_NOT_READY])
    category = assets["category"].replace("", "(unread)")
    table = pd.crosstab(category, assets["failure_mode"]).reindex(columns=list(AUDIT_MODES), fill_value=0)
    failing = assets["declared_passed"].map(lambda v: bool(v == False))  # noqa: E712 (None, NaN: not run)
    table[DECLARED_NOT_READY] = failing.groupby(category).sum().reindex(table.index, fill_value=0).astype(int)
    table.loc["total"] = table.sum()
    return table


def implausible_by_category(values):
    """Implausible values per category (rows) and quantity (columns), from the ``audit_values`` table."""
    import pandas as pd

    bad = values[values["verdict"] == "implausible"]
    if bad.empty:
        return pd.DataFrame()
    return pd.crosstab(bad["category"], bad["quantity"])
