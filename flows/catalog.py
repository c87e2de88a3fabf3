"""The pipeline's two catalogs: ``catalog.yaml`` (what to refine,
:class:`~asset2sim.flows.catalog_config.CatalogConfig`, :func:`load_catalog`, in
:mod:`asset2sim.flows.catalog_config`) and here the Parquet result catalog (what came out,
:class:`ResultCatalog`), on a local folder or an object store
(:mod:`asset2sim.flows.catalog_fs`). Row schema:
:func:`~asset2sim.schemas.catalog.arrow_schema`, versioned; units are in the
column names. docs/design/pipeline.md explains the layout and compaction.
"""

from __future__ import annotations

import contextlib
import json
import re
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterable

from asset2sim.flows import catalog_fs
from asset2sim.flows.catalog_config import CatalogConfig, CatalogError, load_catalog
from asset2sim.schemas.catalog import ROW_COLUMNS, ROW_STATUSES, CatalogRow, arrow_schema, parquet_bytes

#: The configuration side, named here too (``from asset2sim.flows.catalog import load_catalog``).
__all__ = [
    "COMPACTED_NAME", "CatalogConfig", "CatalogError", "Compaction", "ResultCatalog", "load_catalog", "plain_strings",
    "plain_value", "result_key",
]


#: The file a run's partition is compacted into: a name no asset id can take (ids have no ``@``) and
#: that readers do not skip as hidden (pandas, pyarrow and Spark skip names starting with ``_`` or ``.``).
COMPACTED_NAME = "rows@compacted.parquet"
#: The compacted file's name before version 3 of the row schema (hidden from pandas and pyarrow); read,
#: and replaced by :data:`COMPACTED_NAME` at the run's next compaction.
LEGACY_COMPACTED_NAME = "_compacted.parquet"
RUN_INFO_NAME = "_run.json"
#: ``_run.json``'s ``outcome`` of a run that refined nothing: every asset finished before and reused (``skipped``).
NOTHING_TO_DO = "nothing_to_do"

_PART_RE = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.\-]*$")


def _check_part(kind: str, value: str) -> str:
    if not _PART_RE.match(value or ""):
        raise ValueError(f"invalid {kind} name {value!r} (letters, digits, '_.-' only)")
    return value


@dataclass(frozen=True)
class Compaction:
    """What :meth:`ResultCatalog.compact` did: rows in the compacted file,
    loose row files folded in and removed, bytes of the compacted file,
    wall time (s)."""

    dataset: str
    run: str
    rows: int
    files_removed: int
    bytes: int
    seconds: float


@dataclass
class _RunFiles:
    compacted: Any = None  # FileInfo of the compacted file
    loose: dict[str, Any] = field(default_factory=dict)  # asset id -> FileInfo of its row file

    def add(self, name: str, info) -> None:
        """Record file ``info`` named ``name`` when it is the compacted file or a row file."""
        if name == COMPACTED_NAME or (name == LEGACY_COMPACTED_NAME and self.compacted is None):
            self.compacted = info
        elif name.endswith(".parquet") and _PART_RE.match(name):
            self.loose[name[: -len(".parquet")]] = info


class ResultCatalog:
    """The Parquet result catalog under ``root`` (a local folder or a URI such as ``s3://bucket/prefix``,
    :mod:`asset2sim.flows.catalog_fs`), laid out as docs/design/pipeline.md describes: every row in exactly
    one data file; files of older schema versions read with the newer columns null."""

    def __init__(self, root: Path | str):
        self.location = catalog_fs.open_location(root)
        self.root: Path | str = Path(self.location.base) if self.location.local else self.location.uri

    def _run_path(self, dataset: str, run: str) -> str:
        return self.location.join(f"dataset={_check_part('dataset', dataset)}", f"run={_check_part('run', run)}")

    def run_dir(self, dataset: str, run: str) -> Path | str:
        """The run's partition: a local :class:`~pathlib.Path`, or a URI on an object store."""
        return self._shown(self._run_path(dataset, run))

    def _shown(self, path: str) -> Path | str:
        """``path`` of the catalog as callers see it: a local :class:`~pathlib.Path`, or a URI on an object store."""
        return Path(path) if self.location.local else self.location.display(path)

    def append_row(self, dataset: str, run: str, row: CatalogRow | dict[str, Any]) -> Path | str:
        """Write one row (a :class:`~asset2sim.schemas.catalog.CatalogRow`, or a
        dict with its keys; missing keys are null) atomically as
        ``<asset_id>.parquet`` of the run's partition (replacing an earlier one).

        Raises:
            ValueError: unknown columns, a bad status, an invalid id/name, or a
                value of the wrong type.
            OSError: the filesystem refused the write.
        """
        if not isinstance(row, CatalogRow):
            extra = set(row) - set(ROW_COLUMNS)
            if extra:
                raise ValueError(f"unknown catalog column(s): {sorted(extra)}")
            if row.get("status") not in ROW_STATUSES:
                raise ValueError(f"status must be one of {ROW_STATUSES}, got {row.get('status')!r}")
            row = CatalogRow.model_validate(row)
        aid = _check_part("asset", row.asset_id)
        import pyarrow as pa

        table = pa.Table.from_pydict({name: [v] for name, v in row.model_dump().items()}, schema=arrow_schema(with_version=True))
        path = f"{self._run_path(dataset, run)}/{aid}.parquet"
        catalog_fs.write_bytes(self.location, path, _parquet_bytes(table))
        self._drop_compacted_row(dataset, run, aid)  # the row file holds it now: each row in one file
        return self._shown(path)

    def _drop_compacted_row(self, dataset: str, run: str, asset_id: str) -> bool:
        """Rewrite the run's compacted file (atomically) without the row of ``asset_id``; False when it holds none."""
        import pyarrow.fs as pafs

        paths = [f"{self._run_path(dataset, run)}/{name}" for name in (COMPACTED_NAME, LEGACY_COMPACTED_NAME)]
        compacted = next((i for i in self.location.fs.get_file_info(paths) if i.type == pafs.FileType.File), None)
        if compacted is None:  # two stats, not a listing of the partition: cheap for every row a run appends
            return False
        table = self._read_files([compacted.path])
        kept = _without(table, [asset_id])
        if kept.num_rows == table.num_rows:
            return False
        catalog_fs.write_bytes(self.location, compacted.path, _parquet_bytes(kept))
        return True

    def write_run_info(self, dataset: str, run: str, info: dict[str, Any]) -> Path | str:
        """Write the run's metadata ``_run.json`` atomically (replacing it)."""
        path = f"{self._run_path(dataset, run)}/{RUN_INFO_NAME}"
        catalog_fs.write_bytes(self.location, path, (json.dumps(info, indent=2, default=str) + "\n").encode())
        return self._shown(path)

    def run_info(self, dataset: str, run: str) -> dict[str, Any] | None:
        """The run's ``_run.json``; None when absent or unreadable."""
        data = catalog_fs.read_bytes(self.location, f"{self._run_path(dataset, run)}/{RUN_INFO_NAME}")
        try:
            return None if data is None else json.loads(data)
        except ValueError:
            return None

    def import_rows(self, dataset: str, run: str, table) -> Path | str:
        """Write a whole run's rows (a :class:`pyarrow.Table` with catalog
        columns; missing ones null) as its compacted file, replacing the
        partition's rows.

        Raises:
            ValueError: a column the schema does not have, or a value that
                cannot be cast to its column's type.
        """
        import pyarrow as pa

        schema = arrow_schema()
        extra = [c for c in table.schema.names if c not in schema.names]
        if extra:
            raise ValueError(f"unknown catalog column(s): {sorted(extra)}")
        cols = [table[c].cast(f.type) if c in table.schema.names else pa.nulls(table.num_rows, f.type)
                for c, f in zip(schema.names, schema)]  # fmt: skip
        table = pa.Table.from_arrays(cols, schema=schema).sort_by("asset_id")
        for aid in table["asset_id"].unique().to_pylist():
            _check_part("asset", aid)
        path = f"{self._run_path(dataset, run)}/{COMPACTED_NAME}"
        catalog_fs.write_bytes(self.location, path, _parquet_bytes(table))
        for info in self._run_files(dataset, run).loose.values():
            catalog_fs.delete_file(self.location, info.path)
        return self._shown(path)

    def delete_row(self, dataset: str, run: str, asset_id: str) -> bool:
        """Remove the row of ``asset_id`` from the run (its row file, and from
        the compacted file, rewritten atomically without it). False when the
        run held no such row."""
        loose = self._run_files(dataset, run).loose
        removed = asset_id in loose and catalog_fs.delete_file(self.location, loose[asset_id].path)
        return self._drop_compacted_row(dataset, run, asset_id) or removed

    def compact(self, dataset: str, run: str) -> Compaction:
        """Fold the run's row files into its compacted file (sorted by asset
        id; a row file wins), then remove the row files folded in that are
        unchanged since they were read (size and modification time).

        Raises:
            OSError: the filesystem refused a write (the row files then stay).
        """
        import pyarrow as pa

        t0 = time.perf_counter()
        files = self._run_files(dataset, run)
        loose = files.loose
        legacy = files.compacted is not None and files.compacted.base_name == LEGACY_COMPACTED_NAME
        if not loose and not legacy:
            rows = 0 if files.compacted is None else self._read_files([files.compacted.path], ["asset_id"]).num_rows
            size = 0 if files.compacted is None else int(files.compacted.size or 0)
            return Compaction(dataset, run, rows, 0, size, time.perf_counter() - t0)
        new = self._read_files([info.path for info in loose.values()]) if loose else None
        if files.compacted is not None:
            old = _without(self._read_files([files.compacted.path]), loose)
            new = old if new is None else pa.concat_tables([old, new])
        new = new.sort_by("asset_id")
        data = _parquet_bytes(new)
        path = f"{self._run_path(dataset, run)}/{COMPACTED_NAME}"
        catalog_fs.write_bytes(self.location, path, data)
        if legacy:
            catalog_fs.delete_file(self.location, files.compacted.path)
        removed, changed = 0, []
        now = {i.base_name: i for i in catalog_fs.list_files(self.location, self._run_path(dataset, run))}
        for aid, info in loose.items():
            cur = now.get(info.base_name)
            if cur is not None and cur.size == info.size and cur.mtime == info.mtime:
                removed += bool(catalog_fs.delete_file(self.location, info.path))
            elif cur is not None:  # rewritten meanwhile: its row file holds the row, the compacted file must not
                changed.append(aid)
        if changed:
            new = _without(new, changed)
            data = _parquet_bytes(new)
            catalog_fs.write_bytes(self.location, path, data)
        return Compaction(dataset, run, new.num_rows, removed, len(data), time.perf_counter() - t0)

    def runs(self, dataset: str | None = None) -> list[tuple[str, str]]:
        """``(dataset, run)`` partitions present, sorted (chronologically within a dataset)."""
        return sorted(self._partitions(dataset))

    def _partitions(self, dataset: str | None) -> dict[tuple[str, str], _RunFiles]:
        """Every run partition (of ``dataset``) and its row files, from one recursive listing."""
        import pyarrow.fs as pafs

        top = self.location.base if dataset is None else self.location.join(f"dataset={_check_part('dataset', dataset)}")
        out: dict[tuple[str, str], _RunFiles] = {}
        base = self.location.base.rstrip("/")
        for info in catalog_fs.list_files(self.location, top, recursive=True):
            rel = info.path[len(base):].lstrip("/") if info.path.startswith(base) else info.path
            bits = rel.split("/")
            if len(bits) < 2 or not bits[0].startswith("dataset=") or not bits[1].startswith("run="):
                continue
            key = (bits[0].split("=", 1)[1], bits[1].split("=", 1)[1])
            if not all(map(_PART_RE.match, key)):
                continue
            if len(bits) == 2:
                if info.type == pafs.FileType.Directory:
                    out.setdefault(key, _RunFiles())
                continue
            if len(bits) == 3 and info.type == pafs.FileType.File:
                out.setdefault(key, _RunFiles()).add(bits[2], info)
        return out

    def _run_files(self, dataset: str, run: str) -> _RunFiles:
        import pyarrow.fs as pafs

        rf = _RunFiles()
        for info in catalog_fs.list_files(self.location, self._run_path(dataset, run)):
            if info.type == pafs.FileType.File:
                rf.add(info.base_name, info)
        return rf

    def _read_files(self, paths: list[str], columns: list[str] | None = None):
        """Parquet files of the catalog as one table of the current schema (missing columns null)."""
        import pyarrow.dataset as pads

        return pads.dataset(paths, schema=arrow_schema(), format="parquet", filesystem=self.location.fs).to_table(columns=columns)

    def recorded_assets(self, dataset: str, run: str) -> set[str]:
        """Ids of the assets the run has a row for (row files and compacted file)."""
        files = self._run_files(dataset, run)
        ids = set(files.loose)
        if files.compacted is not None:
            ids |= set(self._read_files([files.compacted.path], ["asset_id"])["asset_id"].to_pylist())
        return ids

    def has_row(self, dataset: str, run: str, asset_id: str) -> bool:
        """True when the run holds a row for ``asset_id``."""
        return asset_id in self.recorded_assets(dataset, run)

    def read_table(
        self,
        dataset: str | None = None,
        run: str | Iterable[str] | None = None,
        columns: Iterable[str] | None = None,
        filter: Any = None,
        limit: int | None = None,
    ):
        """Rows as a :class:`pyarrow.Table` with the partition columns
        ``dataset`` and ``run`` (dictionary-encoded): of one dataset, one run
        or a list of runs, only ``columns`` (plus the partition columns), only
        the rows matching ``filter`` (a :mod:`pyarrow.dataset` expression), at
        most ``limit`` rows; each asset of a run once (the row file wins).

        Raises:
            KeyError: a column the catalog does not have.
        """
        import pyarrow as pa
        import pyarrow.dataset as pads

        # step 1: the schema read and the columns asked for
        runs = None if run is None else ({run} if isinstance(run, str) else set(run))
        # the partition columns, dictionary-encoded while scanning (one value per file)
        part_schema = pa.schema([("dataset", pa.dictionary(pa.int32(), pa.string())), ("run", pa.dictionary(pa.int32(), pa.string()))])
        full = pa.unify_schemas([arrow_schema(), part_schema])
        cols = None if columns is None else list(dict.fromkeys([*columns, "dataset", "run"]))
        if cols is not None:
            unknown = [c for c in cols if c not in full.names]
            if unknown:
                raise KeyError(f"no catalog column(s) {unknown}; columns: {list(full.names)}")
        # step 2: the data files of each partition: read as they are, or compacted rows under row files
        plain: list[str] = []  # files read as they are
        overlaid: list[tuple[Any, dict[str, Any]]] = []  # (compacted, loose) needing the row-file-wins rule
        scanned: list[tuple[str, str]] = []
        for (ds_name, run_id), rf in sorted(self._partitions(dataset).items()):
            if runs is not None and run_id not in runs:
                continue
            scanned.append((ds_name, run_id))
            if rf.compacted is not None and rf.loose:
                overlaid.append((rf.compacted, rf.loose))
            else:
                plain += [rf.compacted.path] if rf.compacted is not None else [i.path for _, i in sorted(rf.loose.items())]
        out_schema = full if cols is None else pa.schema([full.field(c) for c in cols])

        # step 3: a scanner over the files, partition values from their paths
        names = {"dataset": {d for d, _ in scanned}, "run": {r for _, r in scanned}}
        partitioning = pads.partitioning(part_schema, flavor="hive",
                                         dictionaries={k: pa.array(sorted(v), pa.string()) for k, v in names.items()})

        def scan(paths: list[str], columns: list[str] | None = cols):
            dset = pads.dataset(
                paths, schema=full, format="parquet", filesystem=self.location.fs,
                partitioning=partitioning, partition_base_dir=self.location.base,
            )  # fmt: skip
            if limit is not None:
                return dset.head(int(limit), columns=columns, filter=filter)
            return dset.to_table(columns=columns, filter=filter)

        # step 4: read; a row file wins over the compacted row of its asset
        tables = [scan(plain)] if plain else []
        with_ids = None if cols is None else list(dict.fromkeys([*cols, "asset_id"]))
        for compacted, loose in overlaid:
            # the compacted rows of the assets that have a row file (which wins)
            old = _without(scan([compacted.path], with_ids), loose)
            tables += [old if cols is None else old.select(cols), scan([i.path for _, i in sorted(loose.items())])]
        # step 5: one table, at most ``limit`` rows
        if not tables:
            return out_schema.empty_table()
        table = pa.concat_tables(tables)
        if limit is not None:
            table = table.slice(0, int(limit))
        return table.replace_schema_metadata({b"asset2sim.sorted": b"1" if not overlaid else b"0"})

    def read(
        self,
        dataset: str | None = None,
        run: str | Iterable[str] | None = None,
        columns: Iterable[str] | None = None,
        filter: Any = None,
    ):
        """Rows (see :meth:`read_table`) as a pandas DataFrame sorted by
        dataset, run and asset id; empty (with every asked column) when there
        are none. ``dataset`` and ``run`` are plain strings."""
        import pandas as pd

        table = self.read_table(dataset, run, columns, filter)
        if table.num_rows == 0:
            return pd.DataFrame({n: pd.Series(dtype="object") for n in table.schema.names})
        table = plain_strings(table)
        if (table.schema.metadata or {}).get(b"asset2sim.sorted") != b"1":  # files scanned in order: sorted already
            table = table.sort_by([(k, "ascending") for k in ("dataset", "run", "asset_id") if k in table.schema.names])
        return table.to_pandas()

    def finished(self, dataset: str, code_hash: str | None = None) -> dict[str, dict[str, Any]]:
        """Latest finished result per ``asset_id|input_hash|config_hash`` key of
        ``dataset``: the row (dict) of the latest run in which the asset was
        done or skipped; ``code_hash``: only rows made by this code (None: any)."""
        import pyarrow.dataset as pads

        expr = pads.field("status").isin(["done", "skipped"])
        if code_hash is not None:
            expr = expr & (pads.field("code_hash") == code_hash)
        # pass 1: the key columns only; the latest run of each key
        keys = self.read_table(dataset, columns=["asset_id", "input_hash", "config_hash"], filter=expr)
        if keys.num_rows == 0:
            return {}
        kdf = plain_strings(keys, ("run",)).select(["asset_id", "input_hash", "config_hash", "run"]).to_pandas()
        kdf["_key"] = _keys(kdf)
        latest = kdf.sort_values("run", kind="stable").drop_duplicates("_key", keep="last")
        # pass 2: whole rows, only of the runs that hold a latest result
        rows = self.read(dataset, sorted(latest["run"].unique()), filter=expr)
        rows = rows.assign(_key=_keys(rows)).merge(latest[["_key", "run"]], on=["_key", "run"], how="inner").drop(columns="_key")
        recs = [{k: plain_value(v) for k, v in rec.items()} for rec in rows.to_dict("records")]
        return {result_key(r["asset_id"], r["input_hash"], r["config_hash"]): r for r in recs}


def plain_strings(table, names=("dataset", "run")):
    """``table`` with its dictionary-encoded partition columns as plain strings."""
    import pyarrow as pa

    for i, name in enumerate(table.schema.names):
        if name in names and pa.types.is_dictionary(table.schema.field(i).type):
            table = table.set_column(i, name, table.column(i).cast(pa.string()))
    return table


def _without(table, asset_ids):
    """``table`` without the rows of ``asset_ids``."""
    import pyarrow as pa
    import pyarrow.compute as pc

    return table.filter(pc.invert(pc.is_in(table["asset_id"], value_set=pa.array(sorted(asset_ids), pa.string()))))


def _parquet_bytes(table) -> bytes:
    table = table.replace_schema_metadata({**(table.schema.metadata or {}), **(arrow_schema(with_version=True).metadata or {})})
    return parquet_bytes(table, compression="zstd")


def plain_value(v: Any) -> Any:
    """A catalog value as plain JSON-able Python (NaN/NaT -> None, numpy
    scalars -> Python, timestamps -> ISO text)."""
    import pandas as pd

    if isinstance(v, pd.Timestamp):
        return None if pd.isna(v) else v.isoformat()
    with contextlib.suppress(TypeError, ValueError):
        if pd.isna(v):
            return None
    return v.item() if hasattr(v, "item") else v


def _keys(df):
    """:func:`result_key` of every row of a DataFrame (a Series)."""
    return df["asset_id"] + "|" + df["input_hash"].fillna("") + "|" + df["config_hash"].fillna("")


def result_key(asset_id: str, input_hash: str | None, config_hash: str | None) -> str:
    """Key identifying a result: the same asset, input and configuration."""
    return f"{asset_id}|{input_hash or ''}|{config_hash or ''}"
