"""A refine run planned: :func:`plan_run` turns a dataset's manifest into one
:class:`~asset2sim.flows.stages.AssetJob` per usable row and one :class:`BadManifestRow` per other row
(:class:`RunPlan`), with earlier results and killed runs' work (:func:`unrecorded_jobs`) for the skip decision;
:func:`make_run_id` and :func:`flow_parameters` name a run and its flow's parameters.
"""

from __future__ import annotations

import uuid
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

from asset2sim.demo_assets import ensure_demo_dataset
from asset2sim.flows import store as store_mod
from asset2sim.flows.catalog import ResultCatalog
from asset2sim.flows.catalog_config import Catalog, CatalogError, ManifestEntry, read_manifest_entries
from asset2sim.flows.job_records import JOB_RECORD_NAME, JobRecord, manifest_row_id
from asset2sim.flows.stages import METRICS_DIRNAME, AssetJob
from asset2sim.tasks.ingest import partnet_mobility
from asset2sim.tasks.ingest.partnet_mobility import ManifestRowError
from asset2sim.tasks.publish.contract import code_version, skip_code_hash


@dataclass
class BadManifestRow:
    """A manifest row that cannot be used: its catalog id and the reader's typed error."""

    asset_id: str
    error: ManifestRowError


@dataclass
class RunPlan:
    """A run's ``jobs`` and ``bad_rows`` (recorded as failed), each in manifest order."""

    jobs: list[AssetJob]
    bad_rows: list[BadManifestRow] = field(default_factory=list)


def make_run_id(now: datetime | None = None) -> str:
    """A run id that sorts chronologically: ``YYYYmmddTHHMMSSZ-xxxxxx`` (UTC)."""
    now = now or datetime.now(timezone.utc)
    return now.strftime("%Y%m%dT%H%M%SZ") + "-" + uuid.uuid4().hex[:6]


def flow_parameters(
    catalog: str | Path = "catalog.yaml",
    dataset: str | None = None,
    workers: int | None = None,
    dask_address: str | None = None,
    out: str | None = None,
) -> dict[str, Any]:
    """The parameters ``make flow`` passes to ``refine_dataset`` (the catalog as an absolute path; ``out`` when given)."""
    return {
        "catalog": str(Path(catalog).expanduser().resolve()),
        "dataset": dataset,
        "workers": workers,
        "dask_address": dask_address,
        **({"out": out} if out else {}),
    }


def plan_run(
    cat: Catalog,
    dataset: str,
    run_id: str,
    *,
    ids: list[str] | None = None,
    limit: int | None = None,
    force: bool = False,
    out_store: str | None = None,
) -> RunPlan:
    """One job per usable manifest row and one :class:`BadManifestRow` per other row (only ``ids``, at most
    ``limit`` rows, in manifest order), with earlier results and killed runs' work for the skip decision (none when
    ``force``). ``out_store``: default ``catalog.yaml`` ``output_store``.

    Raises:
        CatalogError: a missing or unreadable manifest, an unknown dataset, an id in ``ids`` no row has.
    """
    # step 1: the manifest's usable rows and bad rows, in file order
    name, ds = cat.dataset(dataset)
    root = cat.dataset_root(name)
    if ds.generate == "demo":
        ensure_demo_dataset(root)
    entries, errors = read_manifest_entries(cat.manifest_path(name), root)
    taken = {e.asset_id for e in entries}
    bad = [BadManifestRow(manifest_row_id(err, taken), err) for err in errors]
    ordered: list[ManifestEntry | BadManifestRow] = sorted(  # file order
        [*entries, *bad], key=lambda item: item.error.line if isinstance(item, BadManifestRow) else (item.line or 0))
    # step 2: only the ids asked for, at most ``limit`` rows
    if ids:
        known = {it.asset_id for it in ordered} | {b.error.id for b in bad if b.error.id}
        unknown = [i for i in ids if i not in known]
        if unknown:
            raise CatalogError(f"{cat.manifest_path(name)}: unknown id(s) {unknown}")
        wanted = set(ids)
        ordered = [it for it in ordered if it.asset_id in wanted or (isinstance(it, BadManifestRow) and it.error.id in wanted)]
    if limit is not None:
        ordered = ordered[: max(0, int(limit))]
    # step 3: what the skip decision reads: earlier results, killed runs' work
    settings = cat.config.run
    config = cat.refine_config().model_dump(mode="json")
    finished = {} if force else ResultCatalog(cat.catalog_root).finished(
        name, code_hash=skip_code_hash(cat.config.results.code_change))
    store = out_store or cat.output_store
    unrecorded = {} if force or store else unrecorded_jobs(cat, name, run_id)
    run_out = (store_mod.local_work_root() if store else cat.output_root) / name / run_id
    version = code_version()
    # step 4: one job per usable row
    jobs = []
    for e in [it for it in ordered if not isinstance(it, BadManifestRow)]:
        ref_dir = str(e.asset_dir) if ds.reference and partnet_mobility.has_reference(e.asset_dir) else None
        jobs.append(
            AssetJob(
                dataset=name,
                run_id=run_id,
                asset_id=e.asset_id,
                prompt=e.prompt,
                asset_dir=str(e.asset_dir),
                out_dir=str(run_out / e.asset_id),
                work_dir=str(run_out / ".work" / e.asset_id),
                metrics_dir=str(run_out / METRICS_DIRNAME / e.asset_id),
                category=e.category,
                reference_scale=e.reference_scale,
                reference_dir=ref_dir,
                config=config,
                **{k: getattr(settings, k) for k in ("refine_function", "evaluate", "probes", "isolation", "memory_limit_mb")},
                extras=settings.extras is not False, media=settings.extras is True,
                time_limit_seconds=e.time_limit_seconds or settings.time_limit_seconds,
                finished={k: v for k, v in finished.items() if k.startswith(e.asset_id + "|")},
                resumable=unrecorded.get(e.asset_id, []),
                code_version=version,
                out_uri=store_mod.join_uri(store, name, run_id, e.asset_id) if store else None,
                metrics_uri=store_mod.join_uri(store, name, run_id, METRICS_DIRNAME, e.asset_id) if store else None,
            )
        )
    return RunPlan(jobs=jobs, bad_rows=[b for b in ordered if isinstance(b, BadManifestRow)])


def unrecorded_jobs(cat: Catalog, dataset: str, run_id: str) -> dict[str, list[dict[str, Any]]]:
    """Per asset id, the job records (JobRecord dicts, newest run first) that earlier runs of ``dataset`` (all but
    ``run_id``) left in their work folders without writing the asset's catalog row."""
    store = ResultCatalog(cat.catalog_root)
    base = cat.output_root / dataset
    out: dict[str, list[dict[str, Any]]] = {}
    try:
        runs = sorted((p.name for p in base.iterdir() if p.is_dir() and p.name != run_id), reverse=True)
    except OSError:
        return out
    for run in runs:
        work = base / run / ".work"
        if not work.is_dir():
            continue
        try:
            recorded = store.recorded_assets(dataset, run)  # row files and the compacted file
        except ValueError:  # not a run id the catalog could hold
            continue
        for folder in sorted(work.iterdir()):
            if folder.name in recorded or not (folder / JOB_RECORD_NAME).is_file():  # a FIFO or device is never opened
                continue
            try:
                rec = JobRecord.model_validate_json((folder / JOB_RECORD_NAME).read_text())
            except (OSError, ValueError):
                continue
            if rec.job.get("asset_id") == folder.name and rec.job.get("run_id") == run:
                out.setdefault(folder.name, []).append(rec.model_dump(mode="json"))
    return out
