"""The audit flow: many assets audited as Prefect tasks fanned out on Dask (a local cluster, or the scheduler at
``dask_address``), the audit catalog written (:mod:`.audit_catalog`) and the run logged to MLflow (counts,
failure modes, implausible values per quantity, the catalog files as artifacts). ``asset2sim audit --flow``
runs it; flows wire, :mod:`asset2sim.apps.audit` decides. Imports Prefect."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

from prefect import flow, task
from prefect.cache_policies import NO_CACHE

from asset2sim.flows import audit_catalog, tracking
from asset2sim.flows.flow_runtime import dask_task_runner, local_cluster_config, prefect_api_for_run
from asset2sim.schemas.audit import AuditRow
from asset2sim.apps.audit.batch import AuditTarget, audit_one, find_assets

__all__ = ["AUDIT_EXPERIMENT", "AUDIT_FLOW_NAME", "audit_flow", "run_audit_flow"]

AUDIT_FLOW_NAME = "asset2sim-audit"
AUDIT_SUBFLOW_NAME = "asset2sim-audit-assets"
#: The MLflow experiment audit runs are logged to.
AUDIT_EXPERIMENT = "asset2sim-audit"

audit_task = task(audit_one, name="audit-asset", cache_policy=NO_CACHE, persist_result=False)


@flow(name=AUDIT_SUBFLOW_NAME, persist_result=False, validate_parameters=False)
def _audit_each(targets: list[AuditTarget], out: str, category: str | None, simulate: bool) -> list[AuditRow]:
    futures = [audit_task.submit(t, out, category=category, simulate=simulate) for t in targets]
    rows = []
    for t, fut in zip(targets, futures):
        try:
            rows.append(fut.result(raise_on_failure=True))
        except BaseException as exc:  # a worker that died: the asset's row says so, the others go on
            rows.append(AuditRow(asset_id=t.asset_id, source=str(t.path), failure_mode="audit_failed",
                                 error=f"{t.path}: the audit task failed: {type(exc).__name__}: {exc}"))
    return rows


@flow(name=AUDIT_FLOW_NAME, persist_result=False, validate_parameters=False)
def audit_flow(paths: list[str], out: str, category: str | None = None, simulate: bool = True, workers: int | None = None,
               dask_address: str | None = None, tracking_uri: str | None = None) -> dict[str, Any]:
    """Audit every asset ``paths`` hold (:func:`~asset2sim.apps.audit.batch.find_assets`) into ``out``; returns the
    run summary (assets, failure modes, implausible values per quantity, catalog paths, MLflow run id) and the
    catalog ``rows`` (:class:`~asset2sim.schemas.audit.AuditRow`)."""
    start = time.perf_counter()
    import pandas as pd

    targets = find_assets(paths)
    runner = dask_task_runner(workers, dask_address, dashboard=False)
    with local_cluster_config(dask_address, False, out):
        rows = _audit_each.with_options(task_runner=runner)(targets, out, category, simulate) if targets else []
    files = audit_catalog.write_audit_catalog(out, rows)
    values = pd.read_parquet(files["values"])
    bad = values[values["verdict"] == "implausible"]
    summary = {"assets": len(rows),
               "failure_modes": {m: sum(r.failure_mode == m for r in rows) for m in audit_catalog.AUDIT_MODES},
               "implausible_by_quantity": bad["quantity"].value_counts().to_dict(),
               "catalog": {k: str(v) for k, v in files.items()}, "seconds": time.perf_counter() - start}
    # one MLflow run in AUDIT_EXPERIMENT (the store of tracking_uri, else MLFLOW_TRACKING_URI, else <out>/mlflow.db):
    # metrics ``assets``, ``<mode>`` counts and ``implausible_<quantity>``; the catalog files as artifacts
    client = tracking.mlflow_client(tracking.resolve_tracking_uri(out, tracking_uri))
    artifacts = (Path(out).resolve() / "mlruns").as_uri()
    with tracking.client_run(client, AUDIT_EXPERIMENT, artifacts, f"audit-{Path(out).name}") as run_id:
        client.log_metric(run_id, "assets", summary["assets"])
        for mode, n in summary["failure_modes"].items():
            client.log_metric(run_id, mode, n)
        for quantity, n in summary["implausible_by_quantity"].items():
            client.log_metric(run_id, f"implausible_{quantity}", int(n))
        for path in files.values():
            client.log_artifact(run_id, str(path))
    return {**summary, "mlflow_run_id": run_id, "rows": rows}


def run_audit_flow(paths: list[str], out: str | Path, *, category: str | None = None, simulate: bool = True,
                   workers: int | None = None, dask_address: str | None = None, tracking_uri: str | None = None) -> dict[str, Any]:
    """Run :func:`audit_flow` in this process with a Prefect API (the configured one, else a temporary server in
    ``out``); call from a ``__main__``-guarded program. Returns the run summary."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    with prefect_api_for_run(out):
        return audit_flow([str(p) for p in paths], str(out), category, simulate, workers, dask_address, tracking_uri)
