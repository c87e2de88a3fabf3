"""Compare two flow runs of the same dataset: overlays, initial states,
verdicts, metrics and catalog rows, floats within a relative tolerance.

Used to show that a restructure changed no behaviour: run the flow
on the same dataset with the old and the new code, then

    python benchmarks/compare_runs.py OLD_PROJECT NEW_PROJECT --dataset partnet_dev

where each PROJECT is a project root holding ``data/refined/<dataset>/<run>/``
and ``data/catalog/dataset=<dataset>/run=<run>/`` (the latest run of each is
taken unless ``--old-run`` / ``--new-run`` name one).

Ignored because they cannot be equal between two runs: wall times, run ids,
timestamps, worker names, absolute paths, code version strings, model cost
and token counts of the offline estimator (None both sides anyway).
Prints one line per difference and a summary; exit status 1 when anything
differs.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

import pandas as pd

#: Keys whose values differ between runs by nature (substring match, lower case).
VOLATILE = (
    "seconds", "wall", "time", "run_id", "run", "worker", "created", "started", "finished",
    "code_version", "flow_run", "_at", "duration", "elapsed", "attempt",
)
#: Per-asset files compared as JSON.
JSON_FILES = ("overlay.json", "initial_state.json", "report.json", "evaluation.json")


def _volatile(key: str) -> bool:
    k = key.lower()
    return any(v in k for v in VOLATILE)


def _is_path(v) -> bool:
    return isinstance(v, str) and (v.startswith("/") or v.startswith("file:"))


def compare(a, b, where: str, rtol: float, out: list[str]) -> None:
    """Append a line to ``out`` for every difference between JSON-like values ``a`` and ``b``."""
    if isinstance(a, dict) and isinstance(b, dict):
        for k in sorted(set(a) | set(b), key=str):
            if _volatile(str(k)):
                continue
            if k not in a or k not in b:
                out.append(f"{where}.{k}: only in {'new' if k not in a else 'old'}")
                continue
            compare(a[k], b[k], f"{where}.{k}", rtol, out)
        return
    if isinstance(a, list) and isinstance(b, list):
        if len(a) != len(b):
            out.append(f"{where}: length {len(a)} -> {len(b)}")
            return
        for i, (x, y) in enumerate(zip(a, b)):
            compare(x, y, f"{where}[{i}]", rtol, out)
        return
    if isinstance(a, bool) or isinstance(b, bool) or a is None or b is None:
        if a != b and not (_nan(a) and _nan(b)):
            out.append(f"{where}: {a!r} -> {b!r}")
        return
    if isinstance(a, (int, float)) and isinstance(b, (int, float)):
        fa, fb = float(a), float(b)
        if math.isnan(fa) and math.isnan(fb):
            return
        if not math.isclose(fa, fb, rel_tol=rtol, abs_tol=1e-12):
            out.append(f"{where}: {a!r} -> {b!r}")
        return
    if _is_path(a) and _is_path(b):
        return
    if isinstance(a, str) and isinstance(b, str) and a.startswith(("{", "[")):
        try:
            compare(json.loads(a), json.loads(b), where, rtol, out)
            return
        except ValueError:
            pass
    if a != b:
        out.append(f"{where}: {a!r} -> {b!r}")


def _nan(v) -> bool:
    return v is None or (isinstance(v, float) and math.isnan(v))


def _latest(folder: Path, name: str | None) -> Path:
    if name:
        return folder / name
    runs = sorted(p for p in folder.iterdir() if p.is_dir())
    if not runs:
        raise SystemExit(f"{folder}: no runs")
    return runs[-1]


def _rows(catalog_run: Path) -> dict[str, dict]:
    out = {}
    for f in sorted(catalog_run.glob("*.parquet")):
        df = pd.read_parquet(f)
        for rec in df.to_dict(orient="records"):
            out[str(rec.get("asset_id"))] = {k: (None if isinstance(v, float) and math.isnan(v) else v) for k, v in rec.items()}
    if not out:  # one file per run (compacted catalog)
        for f in sorted(catalog_run.parent.glob(f"{catalog_run.name}*.parquet")):
            for rec in pd.read_parquet(f).to_dict(orient="records"):
                out[str(rec.get("asset_id"))] = rec
    return out


def _print_timing(label: str, rows: dict[str, dict]) -> None:
    """Per-asset worker time of a run (the catalog's ``wall_seconds``: all
    stages of one asset on its worker), s: median, mean, total, and the
    per-stage totals of ``stage_seconds``."""
    walls = sorted(float(r["wall_seconds"]) for r in rows.values() if r.get("wall_seconds") is not None)
    if not walls:
        return
    stages: dict[str, float] = {}
    for r in rows.values():
        raw = r.get("stage_seconds")
        for k, v in (json.loads(raw) if isinstance(raw, str) else (raw or {})).items():
            if v is not None:
                stages[k] = stages.get(k, 0.0) + float(v)
    med = walls[len(walls) // 2] if len(walls) % 2 else 0.5 * (walls[len(walls) // 2 - 1] + walls[len(walls) // 2])
    print(f"{label}: per-asset worker time median {med:.2f} s, mean {sum(walls) / len(walls):.2f} s, "
          f"total {sum(walls):.1f} s over {len(walls)} assets; stage totals "
          + ", ".join(f"{k} {v:.1f}" for k, v in sorted(stages.items()) if "." not in k))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("old", type=Path)
    ap.add_argument("new", type=Path)
    ap.add_argument("--dataset", required=True)
    ap.add_argument("--old-run")
    ap.add_argument("--new-run")
    ap.add_argument("--rtol", type=float, default=1e-9)
    args = ap.parse_args(argv)
    diffs: list[str] = []
    old_run = _latest(args.old / "data" / "refined" / args.dataset, args.old_run)
    new_run = _latest(args.new / "data" / "refined" / args.dataset, args.new_run)
    ids = sorted(p.name for p in old_run.iterdir() if p.is_dir() and not p.name.startswith(("_", ".")))
    for aid in ids:
        for name in JSON_FILES:
            fa, fb = old_run / aid / name, new_run / aid / name
            if not fa.exists() and not fb.exists():
                continue
            if not fa.exists() or not fb.exists():
                diffs.append(f"{aid}/{name}: only in {'new' if not fa.exists() else 'old'}")
                continue
            compare(json.loads(fa.read_text()), json.loads(fb.read_text()), f"{aid}/{name}", args.rtol, diffs)
        files_a = {str(p.relative_to(old_run / aid)) for p in (old_run / aid).rglob("*") if p.is_file()}
        files_b = {str(p.relative_to(new_run / aid)) for p in (new_run / aid).rglob("*") if p.is_file()} if (new_run / aid).is_dir() else set()
        for f in sorted(files_a ^ files_b):
            diffs.append(f"{aid}: file {f} only in {'old' if f in files_a else 'new'}")
    cat_old = _rows(args.old / "data" / "catalog" / f"dataset={args.dataset}" / f"run={old_run.name}")
    cat_new = _rows(args.new / "data" / "catalog" / f"dataset={args.dataset}" / f"run={new_run.name}")
    for aid in sorted(set(cat_old) | set(cat_new)):
        if aid not in cat_old or aid not in cat_new:
            diffs.append(f"catalog {aid}: row only in {'new' if aid not in cat_old else 'old'}")
            continue
        compare(cat_old[aid], cat_new[aid], f"catalog {aid}", args.rtol, diffs)
    for d in diffs:
        print(d)
    _print_timing("old", cat_old)
    _print_timing("new", cat_new)
    print(f"{len(ids)} assets, {len(cat_old)} old / {len(cat_new)} new catalog rows, {len(diffs)} differences "
          f"(rtol {args.rtol}; old {old_run.name}, new {new_run.name})")
    return 1 if diffs else 0


if __name__ == "__main__":
    sys.exit(main())
