"""The benchmark: every method on every manifest row, evaluated
(:func:`run_benchmark`), flattened (:func:`evaluation_record`), tabulated
(:func:`summarize`, :func:`benchmark_tables`) and written beside the SPEC's
numbers to beat (:func:`write_benchmark_outputs`, :data:`RESEARCH_NUMBERS`).
"""

from __future__ import annotations

import io
import math
import statistics
from pathlib import Path
from typing import Any, Callable

from asset2sim import output_folder
from asset2sim.atomic import jsonable, write_bytes, write_json, write_text
from asset2sim.output_paths import raise_refusal
from asset2sim.inert import csv_text
from asset2sim.schemas.evaluation import Evaluation
from asset2sim.tasks.check.verdict import readiness
from asset2sim.apps.benchmark.baselines import available_methods, run_method
from asset2sim.tasks.evaluation.evaluate import evaluate_asset
from asset2sim.tasks.ingest.partnet_mobility import ManifestRow, ManifestRowError, read_manifest_rows
from asset2sim.tasks.evaluation.plots import plot_method_summary
from asset2sim.tasks.evaluation.benchmark_pages import _PASS_RATES, render_benchmark_index, render_benchmark_summary
from asset2sim.package_data import package_yaml

#: The SPEC's "Numbers to beat" (thesis results, 9-object set, Isaac Sim): ``research_numbers.yaml`` beside this module.
RESEARCH_NUMBERS: list[dict[str, str]] = package_yaml(__package__, "research_numbers.yaml")

#: Metrics flattened into one benchmark record (their names are the column prefixes).
RECORD_METRICS = ("penetration", "ground_penetration", "rest_stability", "oscillation", "divergence", "state_hold",
                  "scale_deviation", "initial_joint_deviation", "total_mass", "prompt_alignment", "probes",
                  "joint_sweep", "robust_rest", "task_execution", "operating_force")

#: The record's column of each pass rate of the summary (``_PASS_RATES``) whose key is not that column's name.
_RATE_COLUMNS = {"sweep_pass": "joint_sweep_pass", "task_pass": "task_execution_pass", "force_pass": "operating_force_pass"}


def evaluation_record(ev: Evaluation, row: ManifestRow, method: str, *, engine: str = "pybullet") -> dict[str, Any]:
    """One flat benchmark record of an evaluation: each :data:`RECORD_METRICS` value (``<name>``) and verdict
    (``<name>_pass``), D_pos/D_ori, ``ready`` (:func:`asset2sim.tasks.check.verdict.readiness` over every engine), its
    failures and ``tier_<name>`` verdicts, all_pass, time (s)."""
    rec: dict[str, Any] = {"id": row.id, "category": row.category, "method": method, "error": None}
    for name in RECORD_METRICS:
        m = ev.metric(name, engine)
        rec[name] = None if m is None else m.value
        rec[f"{name}_pass"] = None if m is None else m.passed
    rs = ev.metric("rest_stability", engine)
    rec.update({k: rs.details.get(k) if rs else None for k in ("D_pos_m", "D_ori_rad")}, scale=ev.scale)
    ready = readiness(list(ev.metrics))  # every engine evaluated: the verdict report.html shows
    rec["ready"] = ready.ready and not any(f.startswith("engine@") for f in ev.failures)
    rec["ready_failures"] = ";".join(ready.failures)
    rec.update({f"tier_{tier}": verdict for tier, verdict in ready.tiers.items()})
    return {**rec, "all_pass": bool(ev.passed), "failures": ";".join(ev.failures), "seconds": ev.seconds}


def _mean_sd(vals: list[float]) -> tuple[float | None, float | None]:
    v = [float(x) for x in vals if x is not None and math.isfinite(float(x))]
    if not v:
        return None, None
    mean = sum(v) / len(v)
    sd = math.sqrt(sum((x - mean) ** 2 for x in v) / (len(v) - 1)) if len(v) > 1 else 0.0
    return mean, sd


def _rate(vals: list[Any]) -> tuple[float | None, int]:
    v = [bool(x) for x in vals if x is not None]
    return (sum(v) / len(v) if v else None), len(v)


def summarize(records: list[dict[str, Any]], methods: list[str]) -> dict[str, dict[str, Any]]:
    """The thesis table per method: mean and sample sd (ddof = 1) of penetration (mm; all and Toilet+Stapler rows), scale
    deviation (%), initial joint deviation; pass rates over the assets with a verdict; mean prompt alignment; median
    evaluation time (s); ``errors``: assets not produced."""
    out: dict[str, dict[str, Any]] = {}
    for m in methods:
        rs = [r for r in records if r["method"] == m]
        ok = [r for r in rs if not r.get("error")]
        ts = [r for r in ok if (r.get("category") or "").lower() in ("toilet", "stapler")]
        row: dict[str, Any] = {"n": len(rs), "errors": len(rs) - len(ok)}
        for key, column, among in (("pen", "penetration", ok), ("pen_ts", "penetration", ts), ("scale", "scale_deviation", ok),
                                   ("init", "initial_joint_deviation", ok)):
            row[f"{key}_mean"], row[f"{key}_sd"] = _mean_sd([r[column] for r in among])
        row["prompt_mean"], _ = _mean_sd([r["prompt_alignment"] for r in ok])
        for key, n_key in _PASS_RATES:
            row[key], row[n_key] = _rate([r.get(_RATE_COLUMNS.get(key, key)) for r in ok])
        row["all_pass"], _ = _rate([r["all_pass"] for r in ok])
        secs = [r["seconds"] for r in ok if r.get("seconds") is not None]
        row["median_seconds"] = statistics.median(secs) if secs else None
        out[m] = row
    return out


def run_benchmark(manifest: Path | str, methods: list[str], out_dir: Path | str, *, rows: list[str] | None = None, seed: int = 0,
                  engines: tuple[str, ...] = ("pybullet",), reports: bool = True,
                  progress: Callable[[str, str, str], None] | None = None) -> list[dict[str, Any]]:
    """Run every method on every manifest row and evaluate each result into
    ``out_dir/<method>/<id>/`` (``asset/``, ``evaluation.json``, ``report.html``).
    A row that cannot be read, produced or evaluated becomes a record with
    ``error`` set (``id`` its id or ``line <n>``); the others go on.

    ``rows``: restrict to these ids; ``seed``: passed to the methods;
    ``reports``: write each ``report.html``; ``progress``: callback(method, id,
    message). Returns the records (:func:`evaluation_record` plus
    ``method_seconds``, ``report``, ``thesis_set``), manifest order per method.
    Raises KeyError: an unknown method. ManifestError / OSError: the manifest cannot be read."""
    known = available_methods()
    for m in methods:
        if m not in known:
            raise KeyError(f"unknown method {m!r}; known: {sorted(known)}")
    out_dir = Path(out_dir)
    reading = read_manifest_rows(manifest)  # a bad row becomes an error record; the others run
    lines = sorted([r.line or 0 for r in reading.rows] + [e.line for e in reading.errors])
    thesis = {r.id for r in reading.rows if (r.line or 0) in lines[:9]}
    sel: list[ManifestRow | ManifestRowError] = sorted(
        [r for r in reading.rows if rows is None or r.id in rows]
        + [e for e in reading.errors if rows is None or e.id in rows], key=lambda r: r.line or 0)
    say = progress or (lambda m, i, msg: None)
    records = []
    with output_folder.guarding(out_dir):  # no method's or evaluation's file through a symlinked subfolder
        for method in methods:
            for row in sel:
                if isinstance(row, ManifestRowError):
                    rec = {"id": row.id or f"line {row.line}", "category": None, "method": method,
                           "thesis_set": row.line in lines[:9], "error": f"manifest row {row.code}: {row.message}"}
                    records.append(rec)
                    say(method, rec["id"], rec["error"])
                    continue
                folder = out_dir / method / row.id
                base: dict[str, Any] = {"id": row.id, "category": row.category, "method": method, "thesis_set": row.id in thesis}
                res = None
                try:
                    res = run_method(method, row, folder / "asset", seed=seed)
                    # ev.seconds is measured before evaluation.json / report.html are written
                    ev = evaluate_asset(folder / "asset", reference=row.folder, prompt=row.prompt, engines=engines,
                                        seed=seed, category=row.category or None, method=method,
                                        out_dir=folder, write_report=reports, task=row.task or None, probes=True)
                except Exception as exc:
                    raise_refusal(exc)
                    error = f"{type(exc).__name__}: {exc}"
                    rec = dict(base, error=error if res is None else f"evaluation failed: {error}")
                    records.append(rec)
                    say(method, row.id, f"method failed: {error}" if res is None else rec["error"])
                    continue
                rec = evaluation_record(ev, row, method)
                rec.update(base, method_seconds=res.seconds, model_queries=res.model_queries,
                           report=f"{method}/{row.id}/report.html" if reports else None)
                records.append(rec)
                say(method, row.id, f"{'pass' if rec['all_pass'] else 'fail: ' + rec['failures']} ({ev.seconds:.2f} s)")
    return records


def benchmark_tables(records: list[dict[str, Any]], methods: list[str]) -> dict[str, dict[str, dict[str, Any]]]:
    """:func:`summarize` of the thesis set (first 9 manifest rows) and of all rows."""
    return {"thesis set (first 9 manifest rows)": summarize([r for r in records if r.get("thesis_set")], methods),
            "all rows": summarize(records, methods)}


def write_benchmark_outputs(records: list[dict[str, Any]], methods: list[str], out_dir: Path | str,
                            meta: dict[str, Any]) -> dict[str, Path]:
    """Write ``results.json``/``.csv``/``.parquet`` (one record per object and method), ``summary.json``/``.csv``/``.html``
    and ``index.html`` into ``out_dir`` atomically; returns name -> path (``results.parquet`` skipped,
    ``meta['parquet_error']`` set, when it cannot be written)."""
    import pandas as pd  # heavy; only the benchmark's tables need it

    out_dir = Path(out_dir)
    records = jsonable(records)
    tables = jsonable(benchmark_tables(records, methods))
    paths = {"results.json": write_json(out_dir / "results.json", {"meta": meta, "records": records}),
             "summary.json": write_json(out_dir / "summary.json", {"meta": meta, "tables": tables, "research": RESEARCH_NUMBERS})}
    df = pd.DataFrame(records)
    paths["results.csv"] = write_text(out_dir / "results.csv", csv_text(df))  # no cell a spreadsheet runs
    try:
        buf = io.BytesIO()
        df.astype({c: "string" for c in ("failures", "error", "report") if c in df}).to_parquet(buf, index=False)
        paths["results.parquet"] = write_bytes(out_dir / "results.parquet", buf.getvalue())
    except Exception as exc:  # CSV/JSON are the record; parquet is for the catalog
        meta["parquet_error"] = f"{type(exc).__name__}: {exc}"
    flat = [dict(subset=s, method=m, **row) for s, t in tables.items() for m, row in t.items()]
    paths["summary.csv"] = write_text(out_dir / "summary.csv", csv_text(pd.DataFrame(flat)))
    paths["summary.html"] = write_text(out_dir / "summary.html", render_benchmark_summary(
        tables, RESEARCH_NUMBERS, meta, plot_method_summary(tables["all rows"])))
    paths["index.html"] = write_text(out_dir / "index.html", render_benchmark_index(records, meta))
    return paths
