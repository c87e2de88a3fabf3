"""Model calls per asset over the manifest for the model-backed methods, with a
local fake OpenAI-compatible server that answers validly (no network).

    python benchmarks/bench_llm_calls.py [--manifest PATH] [--ids 103275,7236]
        [--methods asset2sim,direct,ivw] [--out DIR] [--estimator-only]

- ``asset2sim``: the full refine pipeline (``refine_asset`` with
  ``--estimator openai``; extras off), calls counted at the server and from
  ``report.model_queries``; ``--estimator-only`` stops after the estimator
  (same calls, much faster).
- ``direct``: :func:`asset2sim.tasks.synthesize.llm_estimator.direct_overlay` (1 call).
- ``ivw``: :func:`asset2sim.tasks.synthesize.llm_estimator.ivw_overlay` (5 views x 5 calls).

Every method starts with an empty reply cache, so every call is counted.
Prints a line per object and method, then mean +- std (min..max) calls per
asset; writes DIR/summary.json. Goals: <= 1.5 (asset2sim; the
research had 2.26), exactly 1 (direct) and 25 (ivw).
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_MANIFEST = ROOT.parent / "shared" / "datasets" / "partnet_mobility" / "manifest.csv"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--manifest", type=Path, default=DEFAULT_MANIFEST)
    ap.add_argument("--ids", default="", help="comma-separated subset of ids")
    ap.add_argument("--methods", default="asset2sim,direct,ivw")
    ap.add_argument("--out", type=Path, default=ROOT / "out" / "bench_llm_calls")
    ap.add_argument("--estimator-only", action="store_true", help="asset2sim: run the estimator only, not the whole refine pipeline")
    args = ap.parse_args(argv)
    if not args.manifest.is_file():
        print(f"manifest not found: {args.manifest}", file=sys.stderr)
        return 2
    sys.path.insert(0, str(ROOT))
    from tests.fake_openai_server import FakeOpenAIServer

    from asset2sim.schemas.config import RefineConfig
    from asset2sim.tasks.synthesize import backends
    from asset2sim.tasks.synthesize import llm_estimator as le
    from asset2sim.tasks.synthesize.context import build_context
    from asset2sim.models.errors import LLMError
    from asset2sim.tasks.refine import RefineError, refine_asset

    rows = list(csv.DictReader(args.manifest.open()))
    if args.ids:
        keep = set(args.ids.split(","))
        rows = [r for r in rows if r["id"] in keep]
    methods = [m for m in args.methods.split(",") if m]
    unknown = set(methods) - {"asset2sim", "direct", "ivw"}
    if unknown:
        print(f"unknown methods {sorted(unknown)}", file=sys.stderr)
        return 2
    results: dict[str, list[dict]] = {m: [] for m in methods}
    with FakeOpenAIServer(lifetime_s=6 * 3600, max_requests=100_000) as srv:
        for method in methods:
            os.environ["ASSET2SIM_LLM_CACHE_DIR"] = tempfile.mkdtemp(prefix=f"bench_llm_{method}_")  # every call counted
            client = le.make_client("openai", "m", srv.url)
            for row in rows:
                src = args.manifest.parent / row["id"]
                n0 = srv.n_chat
                t0 = time.perf_counter()
                rec = {"id": row["id"], "category": row["category"]}
                try:
                    if method == "asset2sim" and not args.estimator_only:
                        res = refine_asset(
                            src, row["prompt"], args.out / method / row["id"],
                            RefineConfig(estimator="openai", model="m", base_url=srv.url),
                            category=row["category"] or None, skip_if_complete=False, extras=False,
                        )
                        rec.update(report_queries=res.report.model_queries, failure_mode=res.report.failure_mode,
                                   scale=res.report.scale)
                    else:
                        with build_context(src, row["prompt"], category=row["category"] or None, asset_id=row["id"]) as (ctx, kin):
                            if method == "asset2sim":
                                ov = backends.get_estimator("openai", model="m", base_url=srv.url).estimate(ctx, kin).overlay
                            elif method == "direct":
                                ov = le.direct_overlay(ctx, kin, client)
                            else:
                                ov = le.ivw_overlay(ctx, kin, client)
                        rec.update(report_queries=ov.estimator.queries, scale=ov.scale, failure_mode="none")
                except (RefineError, LLMError) as exc:
                    rec.update(error=f"{type(exc).__name__}: {exc}", failure_mode=getattr(exc, "failure_mode", "estimator_failure"))
                rec["calls"] = srv.n_chat - n0
                rec["seconds"] = round(time.perf_counter() - t0, 2)
                results[method].append(rec)
                print(
                    f"{method:<9} {row['id']:>7} {row['category']:<17} calls {rec['calls']:>3}  "
                    f"reported {rec.get('report_queries', '-')!s:>3}  {rec['seconds']:7.1f}s  {rec.get('failure_mode', '')}"
                    + (f"  {rec['error'][:120]}" if "error" in rec else ""),
                    flush=True,
                )
    summary = {}
    print()
    print(f"{'method':<10} {'assets':>6} {'mean calls':>11} {'std':>6} {'min':>4} {'max':>4} {'total':>6}  failures")
    for method, recs in results.items():
        calls = [r["calls"] for r in recs]
        if not calls:
            continue
        fails = [f"{r['id']}:{r['failure_mode']}" for r in recs if r.get("failure_mode") not in ("none", None)]
        mean = statistics.fmean(calls)
        sd = statistics.pstdev(calls) if len(calls) > 1 else 0.0
        summary[method] = {"assets": len(calls), "mean_calls": mean, "std_calls": sd, "min": min(calls), "max": max(calls),
                           "total": sum(calls), "failures": fails, "per_asset": recs}
        print(f"{method:<10} {len(calls):>6} {mean:>11.3f} {sd:>6.2f} {min(calls):>4} {max(calls):>4} {sum(calls):>6}  {', '.join(fails) or '-'}")
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "summary.json").write_text(json.dumps(summary, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
