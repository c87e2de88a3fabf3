"""The pipeline's configuration catalog: ``catalog.yaml`` (what to refine, :class:`CatalogConfig`, read by
:func:`load_catalog`; relative paths are relative to its folder, the *project root*) and the dataset
manifests it names (:func:`read_manifest_entries`). Raises :class:`CatalogError` on a bad file.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

from pydantic import Field, ValidationError

from asset2sim.schemas import Strict
from asset2sim.flows import catalog_fs
from asset2sim.inert import field_errors
from asset2sim.input_files import InputFileError, load_yaml
from asset2sim.schemas.config import RefineConfig
from asset2sim.tasks.ingest import partnet_mobility


class CatalogError(ValueError):
    """``catalog.yaml`` or a manifest is missing or invalid; the message names the file."""


class DatasetConfig(Strict):
    """One dataset of ``catalog.yaml``: ``root`` (one sub-folder per asset),
    ``manifest`` (CSV with ``id``, ``prompt`` and optional ``category``,
    ``reference_scale``, ``time_limit_seconds``; default ``<root>/manifest.csv``),
    ``generate: demo`` (build the demo assets into ``root`` on first use),
    ``reference`` (measure scale deviation against the assets' references)."""

    root: str
    manifest: str | None = None
    generate: Literal["demo"] | None = None
    reference: bool = False
    description: str = ""


class EstimatorSettings(Strict):
    """Estimator and its settings; ``retries``/``retry_delay_seconds`` apply to
    model calls only (a failing offline estimator is not retried)."""

    name: str = "offline"
    model: str | None = None
    retries: int = Field(2, ge=0)
    retry_delay_seconds: float = Field(10.0, ge=0.0)


class RunSettings(Strict):
    """How a flow run executes: ``workers`` (local Dask workers; None = CPU
    count); ``time_limit_seconds`` per asset (s, all stages); ``isolation``:
    ``process`` (each stage in a child forked from a per-worker stage server,
    :mod:`asset2sim.flows.forkserver`, killed at the limit), ``spawn`` (a fresh
    Python per stage) or ``none`` (in the worker); ``memory_limit_mb`` of that
    child (MiB, ``RLIMIT_AS``; None = none); ``evaluate`` (the metrics stage),
    ``probes``, ``extras`` (MJCF and USD exports, renders, clips, HTML report; ``deferred``: the exports with
    each asset, the media (renders, clips, HTML report) after every asset's verdict, :func:`asset2sim.flows.refine_flow.media_phase`); ``refine_function``
    (``module:function`` like :func:`asset2sim.tasks.refine.refine_asset`);
    ``dask_host`` (where the local cluster listens; default loopback only) and
    ``dashboard`` (false: no HTTP pages), both ignored with a Dask address."""

    workers: int | None = Field(2, ge=1)
    time_limit_seconds: float = Field(1800.0, gt=0.0)
    memory_limit_mb: int | None = Field(8192, ge=256)
    isolation: Literal["process", "spawn", "none"] = "process"
    evaluate: bool = True
    probes: bool = False
    extras: bool | Literal["deferred"] = True
    refine_function: str = "asset2sim.tasks.refine:refine_asset"
    dask_host: str = Field("127.0.0.1", min_length=1)
    dashboard: bool = True


class ScheduleSettings(Strict):
    """The nightly deployment: cron expression, IANA time zone, dataset."""

    cron: str = "0 2 * * *"
    timezone: str = "UTC"
    dataset: str | None = None
    deployment_name: str = "nightly"


class TrackingSettings(Strict):
    """MLflow: ``uri`` (None = ``MLFLOW_TRACKING_URI`` or ``sqlite:///<project>/mlflow.db``),
    ``experiment``, ``artifact_root`` of new experiments, ``enabled``."""

    enabled: bool = True
    uri: str | None = None
    experiment: str = "asset2sim"
    artifact_root: str = "mlruns"


class RegressionSettings(Strict):
    """When a run counts as a regression against the previous run
    (:mod:`asset2sim.flows.catalog_compare`): ``max_regressed_assets`` (count),
    ``max_pass_rate_drop`` over the common assets (fraction), ``max_metric_drift``
    per compared metric column (its unit; rates as fractions); ``fail_flow``:
    the flow then fails (exit status 5)."""

    max_regressed_assets: int = Field(0, ge=0)
    max_pass_rate_drop: float = Field(0.0, ge=0.0, le=1.0)
    max_metric_drift: dict[str, float] = {}
    fail_flow: bool = True


class ResultsSettings(Strict):
    """The result catalog's policies: ``code_change`` (``rerun``: a change of
    the package source redoes finished assets; ``keep``: reuse them),
    ``compact`` (one Parquet file per run once it ended), ``regression``."""

    code_change: Literal["rerun", "keep"] = "rerun"
    compact: bool = True
    regression: RegressionSettings = RegressionSettings()


class CatalogConfig(Strict):
    """Contents of ``catalog.yaml``. ``catalog_root`` is a path (relative to
    the project root) or a URI (``s3://bucket/prefix``, :mod:`asset2sim.flows.catalog_fs`)."""

    version: int = 1
    default_dataset: str
    output_root: str = "data/refined"
    catalog_root: str = "data/catalog"
    output_store: str | None = None  # a URI or path the workers upload to (asset2sim.flows.store); None: output_root
    datasets: dict[str, DatasetConfig]
    estimator: EstimatorSettings = EstimatorSettings()
    refine: dict[str, Any] = {}  # RefineConfig fields
    run: RunSettings = RunSettings()
    schedule: ScheduleSettings = ScheduleSettings()
    tracking: TrackingSettings = TrackingSettings()
    results: ResultsSettings = ResultsSettings()


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

    def _location(self, root: str) -> Path | str:
        """``root`` as written when it is a URI other than ``file://``, else resolved as a path."""
        return root if catalog_fs.is_uri(root) and not root.startswith("file://") else self.resolve(root.removeprefix("file://"))

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
    def catalog_root(self) -> Path | str:
        """The result catalog's root: an absolute local path, or the URI as written."""
        return self._location(self.config.catalog_root)

    @property
    def output_store(self) -> str | None:
        """The output store: the URI as written, an absolute path, or None (outputs under ``output_root``)."""
        return str(self._location(self.config.output_store)) if self.config.output_store else None

    def refine_config(self):
        """The :class:`~asset2sim.schemas.config.RefineConfig` of this catalog
        (estimator and model from ``estimator``, other fields from ``refine``).

        Raises:
            CatalogError: an unknown or invalid ``refine`` field.
        """
        fields = {"estimator": self.config.estimator.name, "model": self.config.estimator.model, **self.config.refine}
        try:
            return RefineConfig(**fields)
        except ValidationError as exc:
            raise CatalogError(f"{self.path}: invalid 'refine' settings: {field_errors(exc)}") from exc


def load_catalog(path: Path | str) -> Catalog:
    """Read and validate ``catalog.yaml``.

    Raises:
        CatalogError: the file is missing, not YAML, or does not match
            :class:`CatalogConfig` (the message names the field).
    """
    path = Path(path).expanduser().resolve()
    try:  # a regular file under 1 MiB, at most 64 YAML aliases (asset2sim.input_files.load_yaml)
        data = load_yaml(path, what="catalog")
    except InputFileError as exc:
        cause = FileNotFoundError(str(exc)) if exc.code == "INPUT_NOT_FOUND" else exc  # the commands say where to run
        raise CatalogError(f"{path}: cannot read the catalog ({exc.code}): {exc}") from cause
    if not isinstance(data, dict):
        raise CatalogError(f"{path}: expected a mapping at the top level")
    try:
        config = CatalogConfig.model_validate(data)
    except ValidationError as exc:
        raise CatalogError(f"{path}: {field_errors(exc)}") from exc
    if config.default_dataset not in config.datasets:
        raise CatalogError(f"{path}: default_dataset {config.default_dataset!r} is not among the datasets")
    return Catalog(path=path, config=config)


@dataclass(frozen=True)
class ManifestEntry:
    """One request of a manifest: asset id, prompt, asset folder, optional
    category, reference scale and time limit (s), and its 1-based line."""

    asset_id: str
    prompt: str
    asset_dir: Path
    category: str | None = None
    reference_scale: float | None = None
    time_limit_seconds: float | None = None
    line: int | None = None


def read_manifest_entries(
    manifest: Path | str, root: Path | str
) -> tuple[list[ManifestEntry], list[partnet_mobility.ManifestRowError]]:
    """Usable entries of a manifest CSV (asset folders under ``root``) and the
    typed errors of its bad rows (:class:`~asset2sim.tasks.ingest.partnet_mobility.ManifestRowError`),
    each in file order (:func:`asset2sim.tasks.ingest.partnet_mobility.read_manifest_rows`).

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
    entries = [ManifestEntry(r.id, r.prompt, r.folder, r.category or None, r.reference_scale, r.time_limit_seconds, r.line)
               for r in reading.rows]
    return entries, list(reading.errors)
