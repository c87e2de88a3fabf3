"""Throughput of the dataset flow on real objects, the verdict's phase and the media phase apart.

    .venv/bin/python benchmarks/bench_flow.py [--requests 5] [--workers 2] [--work DIR] [--media now|deferred] [--cache off]
    .venv/bin/python benchmarks/bench_flow.py --requests 1 --cache off      # objects as unseen: each refined once, cold
    .venv/bin/python benchmarks/bench_flow.py --work DIR --report-only      # the tail of a kept run, again

1. Builds a dataset of the dev rows (``../shared/datasets/partnet_mobility/manifest.csv``) times ``--requests``
   requests per object: the row's own request (its task written to the manifest; a flow runs no task tier), then
   "A <noun>.", "A <noun>, halfway open.", "A <noun>, fully open." and "A small <noun>." (``bench_generalization``'s
   nouns), each as its own asset folder (a copy: the flow keys assets by folder) under ``DIR/raw``; 21 x 5 = 105
   assets by default.
2. Runs the flow (``run_refine_flow``, what ``make flow`` runs) over it with ``--workers`` workers, every check on
   (the metrics stage included) and, by default, ``run.extras: deferred``: every asset's verdict and exports first,
   then the media phase (renders, clips, HTML report) of every output in children at lower CPU priority.
3. Prints the load average before and after, assets per hour of the first phase (over the flow's assets phase),
   from the run's request to its last verdict (:func:`to_last_verdict`: the start-up included, as a person running
   the flow meets it) and of the media phase, per-stage seconds per asset from the catalog's ``stage_seconds`` (the stage children
   are single-threaded: wall s of a stage = its core-seconds on an idle core) as median / p90 / p99, each asset's
   first-phase wall time median / p90 / p99 with p99 / median and max / median (and the same of its CPU time: the
   figure to compare on a loaded machine), the failure modes, and the tail: every asset above
   :data:`TAIL_FACTOR` times the median (wall or CPU) with the stage that took most of its time (the output's
   ``timings.json``) and the CoACD decompositions its report names, and how the start order fitted the run
   (:func:`order_check`: geometry bytes against cold wall time, the workers' busy share, when the first refine began);
   the post-check rounds per asset (median, p90, max, how many the first post-check decided) and what started each
   extra round (the catalog's ``postcheck_rounds`` and ``extra_rounds``: :func:`rounds`); and the CPU of every process
   of the flow by role (driver, Prefect server, Dask workers, stage servers ...: ``flow_cpu.FlowCpu``) beside the
   refine children's, over the first phase from the flow's start to its last row and from its first row to its last,
   with the share of the machine that refines nothing; and the :data:`SLOWEST` slowest assets (wall) with the stage
   that took most of each, in wall and in CPU s (``timings.json``'s ``stage_seconds`` and ``stage_cpu_seconds``);
   writes ``DIR/summary.json``.

``--requests 1 --cache off`` refines objects as a user meets them for the first time: one request each (the row's
own) and the on-disk cache off (``ASSET2SIM_CACHE=off``, :mod:`asset2sim.array_cache`), so no geometry, piece or
CoACD decomposition is reused between the requests of an object or between the flow's stages (by default the run
has an empty cache of its own, which an object's later requests and its metrics stage read).

Goals: >= 2,000 assets an hour for the first phase on 2 cores, post-check rounds median 1, p99 <= 6x and max <= 10x
the median, less than 8 % of the machine on processes that refine nothing. Numbers from a loaded machine (see the
load average printed) are upper bounds of the cost.
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import re
import shutil
import statistics
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))
DEV = ROOT.parent / "shared" / "datasets" / "partnet_mobility"

from bench_flow_synthetic import _load, flow_times  # noqa: E402
from bench_generalization import _noun  # noqa: E402
from flow_cpu import FlowCpu, print_report  # noqa: E402

#: An asset above this many times the median first-phase time (wall or CPU) is listed in the tail.
TAIL_FACTOR = 3.0
#: The slowest assets (wall) listed with the stage that took most of each.
SLOWEST = 5

#: The requests of each object after its own (``{n}``: the category's noun).
VARIANTS = ("A {n}.", "A {n}, halfway open.", "A {n}, fully open.", "A small {n}.")


def build_dataset(manifest: Path, raw: Path, requests: int) -> list[dict]:
    """Copy every row's asset folder ``requests`` times under ``raw`` (``<id>_r<k>``) and write ``raw/manifest.csv``
    with the row's request and task first, then :data:`VARIANTS`. Returns the manifest rows."""
    with open(manifest, newline="") as fh:
        src = list(csv.DictReader(fh))
    raw.mkdir(parents=True, exist_ok=True)
    rows = []
    for r in src:
        prompts = [(r["prompt"], r.get("task", ""))] + [(v.format(n=_noun(r["category"])), "") for v in VARIANTS]
        for k, (prompt, task) in enumerate(prompts[:requests]):
            aid = f"{r['id']}_r{k}"
            if not (raw / aid).is_dir():
                shutil.copytree(manifest.parent / r["id"], raw / aid)
            rows.append({"id": aid, "category": r["category"], "prompt": prompt, "task": task})
    with open(raw / "manifest.csv", "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=["id", "category", "prompt", "task"], lineterminator="\n")
        w.writeheader()
        w.writerows(rows)
    return rows


def write_catalog(work: Path, workers: int, media: str) -> Path:
    """``work/catalog.yaml`` over ``work/raw`` (tracking off, metrics on, extras ``deferred`` or on)."""
    from asset2sim.flows.stages import prepare_prefect_environment

    config = {"version": 1, "default_dataset": "dev", "output_root": "refined", "catalog_root": "catalog",
              "datasets": {"dev": {"root": "raw", "manifest": "raw/manifest.csv"}},
              "run": {"workers": workers, "time_limit_seconds": 900, "evaluate": True,
                      "extras": "deferred" if media == "deferred" else True},
              "tracking": {"enabled": False}, "results": {"code_change": "keep"}}
    path = work / "catalog.yaml"
    path.write_text(json.dumps(config))  # JSON is YAML
    prepare_prefect_environment(work)
    return path


def quantiles(values: list[float]) -> tuple[float, float, float]:
    """(median, p90, p99) of ``values`` (nearest-rank; zeros when empty)."""
    if not values:
        return 0.0, 0.0, 0.0
    s = sorted(values)

    def q(p: float) -> float:
        return s[min(len(s) - 1, max(0, int(round(p * len(s) + 0.5)) - 1))]

    return statistics.median(s), q(0.9), q(0.99)


def tail(df, factor: float = TAIL_FACTOR) -> dict:
    """The first phase's spread over a run's catalog rows ``df``: per asset wall and CPU s (:func:`flow_times`);
    their median, p99 / median and max / median; and every asset above ``factor`` times either median, slowest
    CPU first, with its failure mode, the stage of its refine that took longest (``timings.json`` in its output,
    wall s) and the number of convex pieces CoACD made that its report keeps."""
    times = flow_times(df)
    wall = {a: t[0] for a, t in times.items()}
    cpu = {a: t[1] for a, t in times.items()}
    out: dict = {}
    for name, vals in (("wall", wall), ("cpu", cpu)):
        med, _, p99 = quantiles(list(vals.values()))
        out[name] = {"median": med, "p99": p99, "max": max(vals.values(), default=0.0),
                     "p99_over_median": p99 / med if med else None,
                     "max_over_median": max(vals.values(), default=0.0) / med if med else None}
    rows = {r["asset_id"]: r for r in df.to_dict("records")}

    def entry(aid: str) -> dict:
        folder = Path(str(rows[aid].get("out_dir") or ""))
        stages, stages_cpu, coacd = {}, {}, 0
        try:
            timings = json.loads((folder / "timings.json").read_text())
            stages, stages_cpu = timings["stage_seconds"], timings.get("stage_cpu_seconds") or {}
            notes = json.dumps(json.loads((folder / "report.json").read_text()).get("state", {}).get("collision_changes", []))
            coacd = sum(int(n) for n in re.findall(r"replaced by (\d+) convex pieces \(CoACD\)", notes))
        except (OSError, ValueError, KeyError, AttributeError):
            pass
        top = max(stages.items(), key=lambda kv: kv[1], default=("-", 0.0))
        top_cpu = max(stages_cpu.items(), key=lambda kv: kv[1], default=("-", 0.0))
        return {"asset": aid, "wall_s": wall[aid], "wall_x": wall[aid] / (out["wall"]["median"] or 1.0), "cpu_s": cpu[aid],
                "cpu_x": cpu[aid] / (out["cpu"]["median"] or 1.0), "failure_mode": rows[aid].get("failure_mode") or "none",
                "top_stage": top[0], "top_stage_s": top[1], "top_cpu_stage": top_cpu[0], "top_cpu_stage_s": top_cpu[1],
                "coacd_pieces": coacd}

    out["above"] = [e for e in map(entry, sorted(times, key=lambda a: -cpu[a])) if e["wall_x"] > factor or e["cpu_x"] > factor]
    out["slowest"] = [entry(a) for a in sorted(times, key=lambda a: -wall[a])[:SLOWEST]]
    return out


def to_last_verdict(df, run_info: dict, summary: dict) -> dict | None:
    """Objects per hour as a person running the flow meets them: from the run's request (``_run.json``'s
    ``requested_at``, before the Prefect server starts) to the last row's ``finished_at`` (each row is recorded as its
    asset's chain ends), and the start-up before the first asset (the Prefect server and the flow run: from the
    request to the flow body's start, ``flow_started_epoch``; the Dask cluster and the stage servers: the run's
    ``dask_startup_seconds`` and ``stage_servers_seconds``). None without those records."""
    import pandas as pd

    requested, started = run_info.get("requested_at"), summary.get("flow_started_epoch")
    if requested is None or started is None or not len(df):
        return None
    seconds = float(pd.to_datetime(df["finished_at"]).max().timestamp()) - float(requested)
    return {"assets": len(df), "seconds": seconds, "assets_per_hour": len(df) / seconds * 3600 if seconds > 0 else None,
            "prefect_s": float(started) - float(requested), "dask_s": float(summary.get("dask_startup_seconds") or 0.0),
            "stage_servers_s": float(summary.get("stage_servers_seconds") or 0.0)}


def print_to_last(t: dict) -> None:
    """Print :func:`to_last_verdict`'s figures."""
    print(f"  from the request to the last verdict: {t['assets']} assets in {t['seconds']:.1f} s = "
          f"{t['assets_per_hour'] or 0:.0f} assets/hour; before the first asset: the Prefect server and the flow run "
          f"{t['prefect_s']:.1f} s, the Dask cluster {t['dask_s']:.1f} s, the stage servers {t['stage_servers_s']:.1f} s")


def order_check(df, raw: Path, workers: int, phase_s: float) -> dict:
    """How well the flow's start order (:mod:`asset2sim.flows.job_order`, largest geometry first) fits the run: the
    Spearman rank correlation of each object's geometry bytes (``folder_listing`` of its folder under ``raw``) and the
    wall s of its first request (``_r0``, refined cold), and the workers' busy share, the summed asset wall s over
    ``workers`` x ``phase_s`` (the rest is start-up and a worker waiting at the end), and when the first refine began,
    s after the first asset was submitted (the prepares and the workers' imports before it)."""
    import pandas as pd

    from asset2sim.flows.job_order import folder_listing

    cold = df[df["asset_id"].str.endswith("_r0")]
    sizes = pd.Series([float(folder_listing(raw / a)[1]) for a in cold["asset_id"]])
    walls = pd.Series([float(w or 0.0) for w in cold["wall_seconds"]])
    rho = float(sizes.rank().corr(walls.rank())) if len(sizes) >= 3 else None
    busy = float(df["wall_seconds"].fillna(0.0).sum()) / (workers * phase_s) if phase_s else None
    started = pd.to_datetime(df["finished_at"]) - pd.to_timedelta(df["wall_seconds"].fillna(0.0), unit="s")
    first_refine = float((started.min() - pd.to_datetime(df["started_at"]).min()).total_seconds()) if len(df) else None
    return {"bytes_wall_rank_correlation": rho, "objects": len(sizes), "busy_share": busy, "first_refine_s": first_refine}


def print_order(o: dict) -> None:
    """Print :func:`order_check`'s figures."""
    print(f"  start order: rank correlation of geometry bytes and cold wall s {o['bytes_wall_rank_correlation'] or 0:.2f} "
          f"over {o['objects']} objects; workers busy {100 * (o['busy_share'] or 0):.0f} % of the first phase, "
          f"the first refine {o['first_refine_s'] or 0:.1f} s after the first submission")


def print_tail(t: dict, factor: float = TAIL_FACTOR) -> None:
    """Print :func:`tail`'s figures."""
    for name in ("wall", "cpu"):
        q = t[name]
        print(f"  per asset {name}: median {q['median']:.2f} s, p99 {q['p99']:.2f} s = {q['p99_over_median'] or 0:.2f}x, "
              f"max {q['max']:.2f} s = {q['max_over_median'] or 0:.2f}x the median")
    for title, listed in ((f"above {factor:g}x the median (wall or CPU), slowest CPU first", t["above"]),
                          (f"the {SLOWEST} slowest (wall)", t.get("slowest", []))):
        print(f"  {title}:")
        for e in listed:
            print(f"    {e['asset']:<12} wall {e['wall_s']:6.2f} s ({e['wall_x']:4.1f}x) CPU {e['cpu_s']:6.2f} s ({e['cpu_x']:4.1f}x) "
                  f"{e['failure_mode']:<18} longest stage {e['top_stage']} {e['top_stage_s']:.2f} s"
                  + (f", most CPU {e['top_cpu_stage']} {e['top_cpu_stage_s']:.2f} s" if e.get("top_cpu_stage", "-") != "-" else "")
                  + (f", CoACD pieces kept {e['coacd_pieces']}" if e["coacd_pieces"] else ""))


def rounds(df) -> dict:
    """Post-check rounds per asset of a run's catalog rows ``df`` (``postcheck_rounds``; for rows written before the
    column, ``report.json`` in ``out_dir``): median, p90, max, the histogram, how many assets their first post-check
    decided, and what started the extra rounds (``extra_rounds``: each check that failed the round before, robust
    rest's trials apart; a round started with nothing failed, by the first words of its reason)."""
    import collections

    from asset2sim.flows.job_records import extra_rounds
    from asset2sim.tasks.publish.contract import read_report_json

    per_asset: dict[str, int] = {}
    causes: collections.Counter = collections.Counter()
    trials: collections.Counter = collections.Counter()
    for rec in df.to_dict("records"):
        n, extra = rec.get("postcheck_rounds"), rec.get("extra_rounds")
        if (n is None or n != n) and rec.get("status") == "done" and rec.get("out_dir"):
            try:
                report = read_report_json(Path(str(rec["out_dir"])))
                n, extra = len(report.escalation), json.dumps(extra_rounds(report))
            except (OSError, ValueError):
                continue
        if n is None or n != n:
            continue
        per_asset[rec["asset_id"]] = int(n)
        for r in json.loads(extra or "[]"):
            for check in r["after"] or [f"nothing failed: {' '.join(r['reason'].split()[:6])}"]:
                name, _, failing = check.partition(": ")
                causes[name] += 1
                for t in filter(None, failing.split(", ")) if name.startswith("robust_rest") else ():
                    trials[t] += 1
    vals = list(per_asset.values())
    med, p90, _ = quantiles([float(v) for v in vals])
    hist = collections.Counter(vals)
    return {"assets": len(vals), "median": med, "p90": p90, "max": max(vals, default=0),
            "histogram": dict(sorted(hist.items())), "first_decided": hist.get(1, 0),
            "first_decided_share": hist.get(1, 0) / len(vals) if vals else None,
            "extra_rounds": sum(v - 1 for v in vals), "started_by": dict(causes.most_common()),
            "robust_rest_trials": dict(trials.most_common())}


def print_rounds(r: dict) -> None:
    """Print :func:`rounds`'s figures."""
    print(f"  post-check rounds per asset: median {r['median']:g}, p90 {r['p90']:g}, max {r['max']} over {r['assets']} "
          f"assets {r['histogram']}; the first post-check decided {r['first_decided']} "
          f"({100 * (r['first_decided_share'] or 0):.0f} %)")
    if r["extra_rounds"]:
        print(f"  what started the {r['extra_rounds']} extra rounds (failed the round before): "
              + ", ".join(f"{k} {v}" for k, v in r["started_by"].items())
              + (f"; robust-rest trials failed: " + ", ".join(f"{k} {v}" for k, v in r["robust_rest_trials"].items())
                 if r["robust_rest_trials"] else ""))


def report_only(work: Path) -> int:
    """``--report-only``: :func:`print_to_last` and :func:`print_tail` of the latest run recorded under ``work`` (a
    kept ``--work``), and :func:`print_order` where its ``summary.json`` is kept too."""
    from asset2sim.flows.catalog import ResultCatalog
    from asset2sim.flows.catalog_config import load_catalog

    cat = ResultCatalog(load_catalog(work / "catalog.yaml").catalog_root)
    runs = sorted(r for d, r in cat.runs("dev"))
    if not runs:
        print(f"no run recorded under {work}")
        return 1
    df = cat.read("dev", runs[-1])
    print(f"run {runs[-1]}: {len(df)} assets")
    info = cat.run_info("dev", runs[-1]) or {}
    to_last = to_last_verdict(df, info, info.get("summary") or {})
    if to_last:
        print_to_last(to_last)
    t = tail(df)
    print_tail(t)
    print_rounds(rounds(df))
    (work / "tail.json").write_text(json.dumps(t, indent=1))
    summary = work / "summary.json"
    if summary.is_file():  # the run's first phase and workers, for the start order's fit
        s = json.loads(summary.read_text())
        o = order_check(df, work / "raw", int(s.get("workers") or 2), float(s["assets_phase_s"]))
        print_order(o)
    return 0


def _phase_marks(cpu: FlowCpu):
    """A progress listener that takes ``cpu``'s snapshots "first row" and "last row" (every asset of the run
    recorded: the end of the first phase, before the media phase)."""
    seen = {"total": 0, "rows": 0}

    def on(event) -> None:
        if event.kind == "run_started":
            seen["total"] = event.total
        elif event.kind == "asset_finished":
            seen["rows"] += 1
            if seen["rows"] == 1:
                cpu.snapshot("first row")
            if seen["rows"] == seen["total"]:
                cpu.snapshot("last row")

    return on


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--manifest", type=Path, default=DEV / "manifest.csv")
    ap.add_argument("--requests", type=int, default=5, help="requests per object, 1-5 (default 5: 105 assets)")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--media", choices=("deferred", "now"), default="deferred",
                    help="deferred (default): run.extras deferred; now: media with each asset")
    ap.add_argument("--cache", choices=("fresh", "off"), default="fresh",
                    help="fresh (default): an empty on-disk cache of the run's own; off: none (ASSET2SIM_CACHE=off)")
    ap.add_argument("--work", type=Path, default=None, help="work folder (default: a temporary one, removed)")
    ap.add_argument("--report-only", action="store_true", help="with --work: print the tail of the run kept there")
    args = ap.parse_args(argv)
    if args.report_only:
        if args.work is None:
            ap.error("--report-only needs --work DIR")
        return report_only(args.work)
    work = args.work or Path(tempfile.mkdtemp(prefix="a2s-bench-flow-"))
    os.environ.setdefault("ASSET2SIM_CACHE", "off" if args.cache == "off" else str(work / "cache"))  # else empty, its own
    try:
        rows = build_dataset(args.manifest, work / "raw", max(1, min(len(VARIANTS) + 1, args.requests)))
        catalog = write_catalog(work, args.workers, args.media)
        from asset2sim import flow_progress
        from asset2sim.flows.catalog import ResultCatalog
        from asset2sim.flows.catalog_config import load_catalog
        from asset2sim.flows.refine_flow import run_refine_flow

        print(f"dataset: {len(rows)} assets ({args.requests} requests x {len(rows) // max(1, args.requests)} objects), "
              f"on-disk cache {os.environ['ASSET2SIM_CACHE']}; load before: {_load()}", flush=True)
        t0 = time.perf_counter()
        with FlowCpu() as cpu, flow_progress.listening(_phase_marks(cpu)):
            summary = run_refine_flow(catalog, workers=args.workers)
        wall = time.perf_counter() - t0
        store = ResultCatalog(load_catalog(catalog).catalog_root)
        df = store.read("dev", summary["run"])
        to_last = to_last_verdict(df, store.run_info("dev", summary["run"]) or {}, summary)
        worked = int(summary["done"]) + int(summary["failed"])
        assets_s = float(summary["assets_seconds"])
        media_s, made = float(summary.get("media_seconds") or 0.0), int(summary.get("media_made") or 0)
        per_asset = [v[0] for v in flow_times(df).values()]
        med, p90, p99 = quantiles(per_asset)
        stages: dict[str, list[float]] = {}
        for st in df["stage_seconds"]:
            for k, v in json.loads(st or "{}").items():
                if k.startswith("refine.") or k in ("prepare", "metrics"):
                    stages.setdefault(k, []).append(float(v))
        out = {"assets": len(rows), "done": summary["done"], "failed": summary["failed"], "wall_s": wall,
               "assets_phase_s": assets_s, "first_phase_assets_per_hour": worked / assets_s * 3600 if assets_s else None,
               "media_s": media_s, "media_made": made,
               "media_assets_per_hour": made / media_s * 3600 if media_s else None,
               "per_asset_s": {"median": med, "p90": p90, "p99": p99, "p99_over_median": p99 / med if med else None},
               "stages_s": {k: dict(zip(("median", "p90", "p99"), quantiles(v))) for k, v in sorted(stages.items())},
               "failure_modes": df["failure_mode"].fillna("none").value_counts().to_dict(), "tail": tail(df),
               "workers": args.workers, "media": args.media, "cache": os.environ["ASSET2SIM_CACHE"], "load_after": _load(),
               "order": order_check(df, work / "raw", args.workers, assets_s), "rounds": rounds(df), "to_last_verdict": to_last,
               "cpu": {k: cpu.report(a, "last row") for k, a in (("first_phase", "start"), ("assets", "first row"))
                       if a in cpu.snapshots and "last row" in cpu.snapshots}}
        print(f"flow: {worked} assets refined in {wall:.1f} s wall (assets phase {assets_s:.1f} s); load after: {_load()}")
        print(f"  first phase (verdict, evaluation, exports): {out['first_phase_assets_per_hour'] or 0:.0f} assets/hour "
              f"(goal >= 2000)")
        if to_last:
            print_to_last(to_last)
        if args.media == "deferred":
            print(f"  media phase (renders, clips, report.html): {made} outputs in {media_s:.1f} s = "
                  f"{out['media_assets_per_hour'] or 0:.0f} assets/hour")
        print(f"  per asset: median {med:.2f} s, p90 {p90:.2f} s, p99 {p99:.2f} s = {p99 / med if med else 0:.2f}x the "
              "median (goal <= 6x)")
        print_rounds(out["rounds"])
        prepare_s = sum(json.loads(st or "{}").get("cpu.prepare", 0.0) for st in df["stage_seconds"])
        for key, title in (("first_phase", "the first phase from the flow's start to its last row"),
                           ("assets", "from its first row to its last")):
            if key in out["cpu"]:
                print_report(out["cpu"][key], title, prepare_s if key == "first_phase" else None)
        print_tail(out["tail"])
        print_order(out["order"])
        print("  stage seconds per asset (median / p90 / p99):")
        for k, q in out["stages_s"].items():
            if q["p99"] >= 0.05:
                print(f"    {k:<28} {q['median']:7.3f} {q['p90']:7.3f} {q['p99']:7.3f}")
        print("  failure modes: " + ", ".join(f"{k} {v}" for k, v in out["failure_modes"].items()))
        (work / "summary.json").write_text(json.dumps(out, indent=1))
        print(f"wrote {work / 'summary.json'}")
    finally:
        if args.work is None:
            shutil.rmtree(work, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
