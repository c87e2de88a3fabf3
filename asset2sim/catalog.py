"""The pipeline's two catalogs: ``catalog.yaml`` (what to refine) and the
Parquet result catalog (what came out).

``catalog.yaml`` (:class:`CatalogConfig`) declares datasets (where the raw
assets are, the manifest of requests, whether the project generates them), the
estimator and its settings, run settings (workers, per-asset time limit,
isolation), the schedule of the nightly run, the tracking store and where
results go. Relative paths are relative to the folder of ``catalog.yaml`` (the
*project root*).

The result catalog (:class:`ResultCatalog`) is a folder of Parquet files
partitioned Hive-style by dataset and run::

    <catalog_root>/dataset=<name>/run=<run_id>/<asset_id>.parquet   one row each
    <catalog_root>/dataset=<name>/run=<run_id>/_run.json            run metadata

Each row file is written atomically (:mod:`asset2sim.atomic`: temporary file,
fsync, rename), so appending a row never leaves a half-written file and
concurrent readers see either the old or the new state. Readers
(:meth:`ResultCatalog.read`) use :mod:`pyarrow.dataset`, which ignores the
``_``/``.``-prefixed files. The row schema is :data:`ROW_SCHEMA`; units are in
the column names (``_mm``, ``_m``, ``_rad``, ``_kg``, ``_seconds``).
"""

from __future__ import annotations

import json
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterable, Literal

import yaml
from pydantic import BaseModel, ConfigDict, Field, ValidationError

from asset2sim import atomic
from asset2sim.schemas.catalog import ROW_COLUMNS, ROW_STATUSES, CatalogRow, arrow_schema
from asset2sim.schemas.config import RefineConfig
from asset2sim.tasks.ingest import partnet_mobility

# --------------------------------------------------------------------------- config


class CatalogError(ValueError):
    """``catalog.yaml`` or a manifest is missing or invalid; the message names the file."""


class DatasetConfig(BaseModel):
    """One dataset of ``catalog.yaml``.

    ``root``: folder holding one sub-folder per asset (relative to the project
    root). ``manifest``: CSV with columns ``id`` and ``prompt`` (required),
    ``category``, ``reference_scale``, ``time_limit_seconds`` (optional, the
    last overrides the run's per-asset limit); default ``<root>/manifest.csv``.
    ``generate``: ``demo`` builds the project's own demo assets into ``root``
    on first use (:mod:`asset2sim.demo_assets`). ``reference``: measure the
    reference metrics (scale deviation) against ``reference_gensim2.json`` in
    the asset folders when present.
    """

    model_config = ConfigDict(extra="forbid")
    root: str
    manifest: str | None = None
    generate: Literal["demo"] | None = None
    reference: bool = False
    description: str = ""


class EstimatorSettings(BaseModel):
    """Estimator and its settings; ``retries``/``retry_delay_seconds`` apply to
    model calls only (a failing offline estimator is not retried)."""

    model_config = ConfigDict(extra="forbid")
    name: str = "offline"
    model: str | None = None
    retries: int = Field(default=2, ge=0)
    retry_delay_seconds: float = Field(default=10.0, ge=0.0)


class RunSettings(BaseModel):
    """How a flow run executes.

    ``workers``: Dask workers of the local cluster (count; None = CPU count).
    ``time_limit_seconds``: wall-time limit per asset (s), over all its stages.
    ``isolation``: ``process`` runs each asset's stages in a child process that
    is killed at the time limit (a crash or hang costs only that asset);
    ``memory_limit_mb``: address-space limit of that child process (MiB,
    ``RLIMIT_AS``; None = no limit): an asset that needs more fails alone with
    a memory error instead of taking the machine's memory from the others
    (default 8192: a 1,000,000-triangle asset, the validator's cap, peaks near
    3.3 GiB, ``benchmarks/bench_mesh_cap.py``);
    ``none`` runs them in the Dask worker (Prefect's timeout, which cannot
    interrupt a long native call). ``evaluate``: run the metrics stage
    (``tasks.evaluate``: penetration, rest stability, oscillation, prompt
    alignment, scale deviation) on each output. ``probes``: include the
    scripted probes in it. ``extras``: write the MJCF export, renders and
    HTML report of each asset (SPEC output). ``refine_function``: ``module:function`` with the
    signature of :func:`asset2sim.tasks.refine.refine_asset`.
    """

    model_config = ConfigDict(extra="forbid")
    workers: int | None = Field(default=2, ge=1)
    time_limit_seconds: float = Field(default=1800.0, gt=0.0)
    memory_limit_mb: int | None = Field(default=8192, ge=256)
    isolation: Literal["process", "none"] = "process"
    evaluate: bool = True
    probes: bool = False
    extras: bool = True
    refine_function: str = "asset2sim.tasks.refine:refine_asset"


class ScheduleSettings(BaseModel):
    """The nightly deployment: cron expression, IANA time zone, dataset."""

    model_config = ConfigDict(extra="forbid")
    cron: str = "0 2 * * *"
    timezone: str = "UTC"
    dataset: str | None = None
    deployment_name: str = "nightly"


class TrackingSettings(BaseModel):
    """MLflow: ``uri`` (None = ``MLFLOW_TRACKING_URI`` or ``sqlite:///<project>/mlflow.db``),
    ``experiment`` name, ``artifact_root`` for new experiments (relative to
    the project root), ``enabled``."""

    model_config = ConfigDict(extra="forbid")
    enabled: bool = True
    uri: str | None = None
    experiment: str = "asset2sim"
    artifact_root: str = "mlruns"


class CatalogConfig(BaseModel):
    """Contents of ``catalog.yaml``."""

    model_config = ConfigDict(extra="forbid")
    version: int = 1
    default_dataset: str
    output_root: str = "data/refined"
    catalog_root: str = "data/catalog"
    datasets: dict[str, DatasetConfig]
    estimator: EstimatorSettings = Field(default_factory=EstimatorSettings)
    refine: dict[str, Any] = Field(default_factory=dict)
    """Overrides of :class:`asset2sim.schemas.config.RefineConfig` fields."""
    run: RunSettings = Field(default_factory=RunSettings)
    schedule: ScheduleSettings = Field(default_factory=ScheduleSettings)
    tracking: TrackingSettings = Field(default_factory=TrackingSettings)


@dataclass(frozen=True)
class Catalog:
    """A loaded ``catalog.yaml``: the validated config and the project root."""

    path: Path
    config: CatalogConfig

    @property
    def project_root(self) -> Path:
        return self.path.parent

    def resolve(self, rel: str | Path) -> Path:
        """A path of the catalog, absolute (relative ones are relative to the project root)."""
        p = Path(rel).expanduser()
        return p if p.is_absolute() else (self.project_root / p).resolve()

    def dataset(self, name: str | None = None) -> tuple[str, DatasetConfig]:
        """``(name, config)`` of dataset ``name`` (default: ``default_dataset``).

        Raises:
            CatalogError: no such dataset.
        """
        name = name or self.config.default_dataset
        if name not in self.config.datasets:
            raise CatalogError(f"{self.path}: no dataset {name!r}; known: {sorted(self.config.datasets)}")
        return name, self.config.datasets[name]

    def dataset_root(self, name: str | None = None) -> Path:
        return self.resolve(self.dataset(name)[1].root)

    def manifest_path(self, name: str | None = None) -> Path:
        ds = self.dataset(name)[1]
        return self.resolve(ds.manifest) if ds.manifest else self.resolve(ds.root) / "manifest.csv"

    @property
    def output_root(self) -> Path:
        return self.resolve(self.config.output_root)

    @property
    def catalog_root(self) -> Path:
        return self.resolve(self.config.catalog_root)

    def refine_config(self):
        """The :class:`~asset2sim.schemas.config.RefineConfig` of this catalog
        (estimator and model from ``estimator``, other fields from ``refine``).

        Raises:
            CatalogError: an unknown or invalid ``refine`` field.
        """
        fields = dict(self.config.refine)
        fields.setdefault("estimator", self.config.estimator.name)
        fields.setdefault("model", self.config.estimator.model)
        try:
            return RefineConfig(**fields)
        except ValidationError as exc:
            raise CatalogError(f"{self.path}: invalid 'refine' settings: {exc}") from exc


def load_catalog(path: Path | str) -> Catalog:
    """Read and validate ``catalog.yaml``.

    Raises:
        CatalogError: the file is missing, not YAML, or does not match
            :class:`CatalogConfig` (the message names the field).
    """
    path = Path(path).expanduser().resolve()
    try:
        data = yaml.safe_load(path.read_text())
    except OSError as exc:
        raise CatalogError(f"{path}: cannot read the catalog: {exc}") from exc
    except yaml.YAMLError as exc:
        raise CatalogError(f"{path}: not valid YAML: {exc}") from exc
    if not isinstance(data, dict):
        raise CatalogError(f"{path}: expected a mapping at the top level")
    try:
        config = CatalogConfig.model_validate(data)
    except ValidationError as exc:
        raise CatalogError(f"{path}: {exc}") from exc
    if config.default_dataset not in config.datasets:
        raise CatalogError(f"{path}: default_dataset {config.default_dataset!r} is not among the datasets")
    return Catalog(path=path, config=config)


@dataclass(frozen=True)
class ManifestEntry:
    """One request of a manifest: asset id, prompt, the asset folder, optional
    category, reference scale (dimensionless) and time limit (s), and the
    1-based line of the manifest where its row starts."""

    asset_id: str
    prompt: str
    asset_dir: Path
    category: str | None = None
    reference_scale: float | None = None
    time_limit_seconds: float | None = None
    line: int | None = None


def _entry(r: partnet_mobility.ManifestRow) -> ManifestEntry:
    return ManifestEntry(
        asset_id=r.id,
        prompt=r.prompt,
        asset_dir=r.folder,
        category=r.category or None,
        reference_scale=r.reference_scale,
        time_limit_seconds=r.time_limit_seconds,
        line=r.line,
    )


def read_manifest_entries(
    manifest: Path | str, root: Path | str
) -> tuple[list[ManifestEntry], list[partnet_mobility.ManifestRowError]]:
    """Usable entries of a manifest CSV and the typed errors of its bad rows
    (:class:`~asset2sim.tasks.ingest.partnet_mobility.ManifestRowError`: line,
    id when known, code, message), each in file order; asset folders under
    ``root``. Parsed by
    :func:`asset2sim.tasks.ingest.partnet_mobility.read_manifest_rows`: a bad
    row (too long for the CSV reader, a missing/unsafe/duplicate id, no
    prompt column, an invalid number) never hides the others.

    Raises:
        CatalogError: the manifest is missing or unreadable, not UTF-8 text,
            or has no ``id`` / ``prompt`` column.
    """
    manifest = Path(manifest)
    try:
        reading = partnet_mobility.read_manifest_rows(manifest, root)
    except OSError as exc:
        raise CatalogError(f"{manifest}: cannot read the manifest: {exc}") from exc
    except partnet_mobility.ManifestError as exc:
        raise CatalogError(str(exc)) from exc
    return [_entry(r) for r in reading.rows], list(reading.errors)


def read_manifest(manifest: Path | str, root: Path | str) -> list[ManifestEntry]:
    """Entries of a manifest CSV (columns ``id``, ``prompt``; optional
    ``category``, ``reference_scale``, ``time_limit_seconds``), asset folders
    under ``root``, all or nothing (:func:`read_manifest_entries` keeps the
    good rows of a manifest with bad ones).

    Raises:
        CatalogError: missing file or columns, an empty/duplicate/unsafe id
            (ids name folders and files: letters, digits, ``_.-``), or a
            ``reference_scale`` / ``time_limit_seconds`` that is not a positive
            number (the first bad row, naming the file and line).
    """
    entries, errors = read_manifest_entries(manifest, root)
    if errors:
        more = f" (and {len(errors) - 1} more bad row(s))" if len(errors) > 1 else ""
        raise CatalogError(errors[0].message + more)
    return entries


# ----------------------------------------------------------------------- Parquet rows

#: The Parquet schema of a row, derived from :class:`~asset2sim.schemas.catalog.CatalogRow`.
_schema = arrow_schema

_PART_RE = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.\-]*$")


def _check_part(kind: str, value: str) -> str:
    if not _PART_RE.match(value or ""):
        raise ValueError(f"invalid {kind} name {value!r} (letters, digits, '_.-' only)")
    return value


class ResultCatalog:
    """The Parquet result catalog under ``root`` (see the module docstring)."""

    def __init__(self, root: Path | str):
        self.root = Path(root)

    def run_dir(self, dataset: str, run: str) -> Path:
        return self.root / f"dataset={_check_part('dataset', dataset)}" / f"run={_check_part('run', run)}"

    def append_row(self, dataset: str, run: str, row: CatalogRow | dict[str, Any]) -> Path:
        """Write one row (a :class:`~asset2sim.schemas.catalog.CatalogRow`, or a
        dict with its keys; missing keys are null) atomically as
        ``<asset_id>.parquet`` of the run's partition.

        Writing the same asset again in the same run replaces its row.

        Raises:
            ValueError: unknown columns, a bad status, an invalid id/name, or a
                value of the wrong type.
        """
        import pyarrow as pa
        import pyarrow.parquet as pq

        if not isinstance(row, CatalogRow):
            extra = set(row) - set(ROW_COLUMNS)
            if extra:
                raise ValueError(f"unknown catalog column(s): {sorted(extra)}")
            if row.get("status") not in ROW_STATUSES:
                raise ValueError(f"status must be one of {ROW_STATUSES}, got {row.get('status')!r}")
            row = CatalogRow.model_validate(row)
        aid = _check_part("asset", row.asset_id)
        values = {name: [v] for name, v in row.model_dump().items()}
        table = pa.Table.from_pydict(values, schema=_schema())
        buf = pa.BufferOutputStream()
        pq.write_table(table, buf, compression="zstd")
        return atomic.write_bytes(self.run_dir(dataset, run) / f"{aid}.parquet", buf.getvalue().to_pybytes())

    def write_run_info(self, dataset: str, run: str, info: dict[str, Any]) -> Path:
        """Write the run's metadata ``_run.json`` atomically (replacing it)."""
        return atomic.write_json(self.run_dir(dataset, run) / "_run.json", info)

    def run_info(self, dataset: str, run: str) -> dict[str, Any] | None:
        p = self.run_dir(dataset, run) / "_run.json"
        try:
            return json.loads(p.read_text())
        except (OSError, ValueError):
            return None

    def runs(self, dataset: str | None = None) -> list[tuple[str, str]]:
        """``(dataset, run)`` partitions present, sorted by dataset then run id
        (run ids start with a UTC time stamp, so this is chronological)."""
        out = []
        if not self.root.is_dir():
            return out
        for d in sorted(self.root.glob("dataset=*")):
            name = d.name.split("=", 1)[1]
            if dataset is not None and name != dataset:
                continue
            for r in sorted(d.glob("run=*")):
                out.append((name, r.name.split("=", 1)[1]))
        return out

    def read(self, dataset: str | None = None, run: str | None = None, columns: Iterable[str] | None = None):
        """All rows (optionally of one dataset / run) as a pandas DataFrame with
        the partition columns ``dataset`` and ``run``; empty (with every column)
        when there are none."""
        import pandas as pd
        import pyarrow as pa
        import pyarrow.dataset as pads

        part_schema = pa.schema([("dataset", pa.string()), ("run", pa.string())])
        full = pa.unify_schemas([_schema(), part_schema])
        files = []
        for ds_name, run_id in self.runs(dataset):
            if run is not None and run_id != run:
                continue
            files += sorted(str(p) for p in self.run_dir(ds_name, run_id).glob("*.parquet"))
        if not files:
            return pd.DataFrame({n: pd.Series(dtype="object") for n in list(full.names)})
        dset = pads.dataset(
            files,
            schema=full,
            format="parquet",
            partitioning=pads.partitioning(part_schema, flavor="hive"),
            partition_base_dir=str(self.root),
        )
        cols = None if columns is None else list(dict.fromkeys([*columns, "dataset", "run"]))
        df = dset.to_table(columns=cols).to_pandas()
        return df.sort_values(["dataset", "run", "asset_id"]).reset_index(drop=True)

    def finished(self, dataset: str) -> dict[str, dict[str, Any]]:
        """Latest finished result per ``asset_id|input_hash|config_hash`` key of
        ``dataset``: the row (dict) of the most recent run in which the asset
        was done (or skipped, pointing at an earlier output)."""
        df = self.read(dataset)
        out: dict[str, dict[str, Any]] = {}
        if df.empty:
            return out
        df = df[df["status"].isin(["done", "skipped"])]
        for rec in df.sort_values("run").to_dict("records"):
            rec = {k: _plain(v) for k, v in rec.items()}
            out[result_key(rec["asset_id"], rec["input_hash"], rec["config_hash"])] = rec
        return out


def _plain(v: Any) -> Any:
    """A catalog value as plain JSON-able Python (NaN/NaT -> None, numpy
    scalars -> Python, timestamps -> ISO text)."""
    import pandas as pd

    if v is None:
        return None
    if isinstance(v, pd.Timestamp):
        return None if pd.isna(v) else v.isoformat()
    try:
        if pd.isna(v):
            return None
    except (TypeError, ValueError):
        pass
    if hasattr(v, "item"):
        return v.item()
    return v


def result_key(asset_id: str, input_hash: str | None, config_hash: str | None) -> str:
    """Key identifying a result: the same asset, input and configuration."""
    return f"{asset_id}|{input_hash or ''}|{config_hash or ''}"
