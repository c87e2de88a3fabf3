"""The benchmark as a Prefect flow: one task per method, the records appended
to a Parquet catalog (``method`` a column), the tables and pass-rate chart
logged to MLflow.

    from asset2sim.flows.benchmark_flow import run_benchmark_flow
    run_benchmark_flow("manifest.csv", ["defaults", "human"], "bench/")

Prefect and MLflow are imported inside (the package imports without them).
The work itself is :func:`asset2sim.tasks.benchmark.benchmark.run_benchmark` and
:func:`asset2sim.tasks.benchmark.benchmark.write_benchmark_outputs`; the flow adds the
orchestration, the catalog and the tracking.
"""

from __future__ import annotations

import time
import uuid
from pathlib import Path
from typing import Any


def append_to_catalog(records: list[dict[str, Any]], catalog: Path | str, run_id: str) -> Path:
    """Append the benchmark records to the Parquet file ``catalog`` (created
    when missing) with columns ``run_id`` and ``kind = "benchmark"`` added;
    written atomically. Returns the path."""
    import io

    import pandas as pd

    from asset2sim.atomic import write_bytes

    catalog = Path(catalog)
    df = pd.DataFrame(records)
    df.insert(0, "run_id", run_id)
    df.insert(1, "kind", "benchmark")
    if catalog.is_file():
        df = pd.concat([pd.read_parquet(catalog), df], ignore_index=True)
    for c in ("failures", "error", "report"):
        if c in df:
            df[c] = df[c].astype("string")
    buf = io.BytesIO()
    df.to_parquet(buf, index=False)
    return write_bytes(catalog, buf.getvalue())


def log_to_mlflow(tables: dict[str, dict[str, dict[str, Any]]], files: dict[str, Path], meta: dict[str, Any],
                  tracking_uri: str | None) -> str | None:
    """Log the thesis tables (one metric per method and column) and the
    benchmark files as artifacts to MLflow; returns the MLflow run id, or None
    when MLflow is not installed."""
    try:
        import mlflow
    except ImportError:
        return None
    if tracking_uri:
        mlflow.set_tracking_uri(tracking_uri)
    mlflow.set_experiment("asset2sim-benchmark")
    with mlflow.start_run(run_name=f"benchmark-{meta.get('run_id', '')}") as run:
        mlflow.log_params({k: str(v) for k, v in meta.items() if k in ("manifest", "methods", "seed", "rows", "engines", "run_id")})
        for subset, table in tables.items():
            tag = "thesis" if subset.startswith("thesis") else "all"
            for method, row in table.items():
                for k, v in row.items():
                    if isinstance(v, (int, float)) and v is not None:
                        mlflow.log_metric(f"{tag}.{method}.{k}", float(v))
        for name in ("summary.html", "index.html", "summary.csv", "results.csv"):
            if name in files:
                mlflow.log_artifact(str(files[name]))
        return run.info.run_id


def run_benchmark_flow(
    manifest: str | Path,
    methods: list[str],
    out: str | Path,
    *,
    ids: list[str] | None = None,
    seed: int = 0,
    engines: tuple[str, ...] = ("pybullet",),
    reports: bool = True,
    catalog: str | Path | None = None,
    tracking_uri: str | None = None,
) -> dict[str, Any]:
    """Run the benchmark as a Prefect flow (see module docstring).

    Args:
        manifest, methods, out, ids, seed, engines, reports: as
            :func:`asset2sim.tasks.benchmark.benchmark.run_benchmark`.
        catalog: Parquet file the records are appended to (default
            ``out/catalog.parquet``).
        tracking_uri: MLflow tracking URI (default ``sqlite:///<out>/mlflow.db``).

    Returns:
        {"run_id", "records", "tables", "files", "catalog", "mlflow_run"}.

    Raises:
        ImportError: Prefect is not installed (``pip install asset2sim[pipeline]``).
    """
    from prefect import flow, task

    from asset2sim.tasks.benchmark.benchmark import benchmark_tables, run_benchmark, write_benchmark_outputs

    out = Path(out)

    @task(name="benchmark-method")
    def method_task(method: str) -> list[dict[str, Any]]:
        return run_benchmark(manifest, [method], out, rows=ids, seed=seed, engines=engines, reports=reports)

    @flow(name="asset2sim-benchmark")
    def benchmark_flow() -> dict[str, Any]:
        run_id = time.strftime("%Y%m%dT%H%M%S") + "-" + uuid.uuid4().hex[:6]
        records: list[dict[str, Any]] = []
        for m in methods:
            records += method_task(m)
        meta = {"manifest": str(manifest), "methods": list(methods), "seed": seed, "engines": list(engines),
                "rows": len({r["id"] for r in records}), "run_id": run_id}
        files = write_benchmark_outputs(records, list(methods), out, meta)
        tables = benchmark_tables(records, list(methods))
        cat = append_to_catalog(records, catalog or out / "catalog.parquet", run_id)
        ml = log_to_mlflow(tables, files, meta, tracking_uri or f"sqlite:///{(out / 'mlflow.db').resolve()}")
        return {"run_id": run_id, "records": records, "tables": tables, "files": files, "catalog": cat, "mlflow_run": ml}

    return benchmark_flow()
