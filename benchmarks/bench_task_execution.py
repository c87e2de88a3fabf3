"""Task execution and force plausibility (docs/design/metrics.md, ``task_execution``,
``operating_force``) on the assets a benchmark wrote, per method and row,
without re-running the methods or the other metrics.

    python benchmarks/bench_task_execution.py --root /tmp/bench21 \
        [--methods defaults,human,direct,asset2sim] [--ids 7119,9912] [--engines pybullet,mujoco]

``--root`` is an ``asset2sim benchmark`` output folder (``<method>/<id>/asset/``)
or a refine batch folder (``<id>/`` output folders; give ``--methods .``).
The manifest's ``task`` of each row is executed exactly as ``evaluate`` does
(the same context, closed ends and metric function); prints one line per
(method, row, engine) and the success and plausibility rates per method, and
writes ROOT/task_execution.json.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from asset2sim.tasks.evaluation.closed_ends import compute_closed
from asset2sim.tasks.evaluation.engine_run import EngineRun
from asset2sim.tasks.evaluation.eval_context import build_context, task_joints
from asset2sim.tasks.evaluation.metric_defs import METRICS
from asset2sim.tasks.check.request_match import labelled_joints
from asset2sim.tasks.check.task_spec import parse_task
from asset2sim.tasks.ingest.partnet_mobility import read_manifest_rows

DATASET = Path(__file__).resolve().parents[1].parent / "shared" / "datasets" / "partnet_mobility"


def measure(folder: Path, row, engines: list[str]) -> dict[str, dict]:
    """engine -> {"task": MetricResult, "force": MetricResult} for one asset folder."""
    ctx = build_context(folder, reference=row.folder, prompt=row.prompt, category=row.category or None)
    pre = labelled_joints(ctx.request, ctx.joints, ctx.semantics, ctx.category)
    ctx.task_joints, _ = task_joints(ctx.joints, ctx.reference_dir, pre)
    ctx.task = parse_task(row.task, ctx.joints, ctx.semantics, ctx.category, ctx.task_joints)
    if not ctx.closed:
        ctx.closed, _ = compute_closed(ctx.urdf, ctx.joints, ctx.task.joints)
    res = METRICS["task_execution"].fn(ctx, {e: EngineRun(e) for e in engines})
    out: dict[str, dict] = {}
    for m in res:
        out.setdefault(m.engine, {})["task" if m.name == "task_execution" else "force"] = m
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--root", required=True, type=Path)
    ap.add_argument("--methods", default="defaults,human,direct,asset2sim")
    ap.add_argument("--ids", default="")
    ap.add_argument("--engines", default="pybullet")
    ap.add_argument("--manifest", type=Path, default=DATASET / "manifest.csv")
    args = ap.parse_args(argv)
    rows = [r for r in read_manifest_rows(args.manifest).rows if not args.ids or r.id in args.ids.split(",")]
    engines = [e for e in args.engines.split(",") if e]
    records = []
    for method in [m for m in args.methods.split(",") if m]:
        for row in rows:
            folder = args.root / row.id if method == "." else args.root / method / row.id / "asset"
            if not folder.exists():
                print(f"{method:10s} {row.id:7s} missing {folder}", flush=True)
                continue
            t0 = time.perf_counter()
            try:
                got = measure(folder, row, engines)
            except Exception as exc:  # one broken asset must not stop the table
                print(f"{method:10s} {row.id:7s} error {type(exc).__name__}: {exc}", flush=True)
                records.append({"method": method, "id": row.id, "error": f"{type(exc).__name__}: {exc}"})
                continue
            for e, d in got.items():
                t, f = d["task"], d["force"]
                atts = t.details.get("attempts", [])
                rec = {"method": method, "id": row.id, "category": row.category, "engine": e, "task": row.task,
                       "task_pass": t.passed, "force_pass": f.passed, "peak_operating_force_n": f.value,
                       "failures": t.details.get("failures", []) + f.details.get("failures", []),
                       "attempts": atts, "skipped": t.details.get("skipped"), "seconds": time.perf_counter() - t0}
                records.append(rec)
                brief = "; ".join(f"{a['joint']} {a['action']} f {a['start_fraction']:.2f}->{a['final_fraction']:.2f} "
                                  f"F_op {a['peak_operating_force_n']:.1f} N (|F| {a['peak_force_n']:.1f}) slide {a['root_slide_m'] * 1e3:.1f} mm tilt {a['root_tilt_rad']:.3f}"
                                  for a in atts)
                print(f"{method:10s} {row.id:7s} {row.category:16s} {e:8s} task {t.passed} force {f.passed} | {brief} | "
                      f"{'; '.join(rec['failures']) or rec['skipped'] or ''} ({rec['seconds']:.1f} s)", flush=True)
    print()
    for method in dict.fromkeys(r["method"] for r in records):
        for e in engines:
            rs = [r for r in records if r["method"] == method and r.get("engine") == e]
            tp = [r["task_pass"] for r in rs if r["task_pass"] is not None]
            fp = [r["force_pass"] for r in rs if r["force_pass"] is not None]
            print(f"{method:10s} {e:8s} task success {sum(tp)}/{len(tp)}"
                  f" ({100 * sum(tp) / max(len(tp), 1):.1f} %), force plausible {sum(fp)}/{len(fp)}"
                  f" ({100 * sum(fp) / max(len(fp), 1):.1f} %)")
    (args.root / "task_execution.json").write_text(json.dumps(records, indent=1, default=str))
    return 0


if __name__ == "__main__":
    sys.exit(main())
