"""Operability benchmark: refines the manifest rows with their requests (and,
with ``--task``, their manipulation tasks) and prints, per category, the effort
each handled part needs (peak force at the grasp point, N; peak torque about
the axis, N m) against its real operating range, how many outputs are
interaction-ready with every part operable, and how often each stability
mechanism was used (friction held at the cap a hand overcomes, a counterbalance
spring, a part that could not be held within its range).

    python benchmarks/bench_operability.py [--manifest PATH] [--ids 19179,12085] [--task]
        [--prompt ID=TEXT ...] [--jobs J] [--out DIR]

``--prompt ID=TEXT`` replaces the request of one row (repeatable), to vary
the requests of the real objects. Each case's outcome is read from its
``report.json`` (final metrics; the operability tier's ``details``) and its
``overlay.json`` (springs and their notes). Writes DIR/cases.json.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections import defaultdict
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_MANIFEST = ROOT.parent / "shared" / "datasets" / "partnet_mobility" / "manifest.csv"


def guarded(case: dict, measure) -> dict:
    """``case`` with what ``measure(res)`` adds to its copy ``res``; a refine's failure becomes ``mode`` (its
    failure mode) and ``error``, any other exception the mode ``crash``; ``seconds`` the wall time."""
    from asset2sim.tasks.refine import RefineError

    t0 = time.perf_counter()
    res = dict(case)
    try:
        measure(res)
    except RefineError as exc:
        res["mode"] = exc.failure_mode
        res["error"] = str(exc)[:300]
    except Exception as exc:  # a crash is a failure mode of its own
        res["mode"] = "crash"
        res["error"] = f"{type(exc).__name__}: {exc}"[:300]
    res["seconds"] = time.perf_counter() - t0
    return res


def run_case(case: dict, out_root: str) -> dict:
    """Refine one case (``case``: id, category, prompt, task, folder); returns it with its outcome."""
    return guarded(case, lambda res: _measure(res, Path(out_root) / (case["id"] + ("_task" if case.get("task") else ""))))


def _measure(res: dict, out: Path) -> None:
    """Refine ``res``'s case into ``out``; its verdict, operability and joint dynamics into ``res``."""
    from asset2sim.schemas.config import RefineConfig
    from asset2sim.tasks.refine import refine_asset

    r = refine_asset(res["folder"], res["prompt"], out, RefineConfig(), category=res["category"], task=res.get("task") or None,
                     skip_if_complete=False, extras=False, overwrite=True).report
    res["mode"] = r.failure_mode
    op = next((m for m in r.metrics if m.name == "operability" and m.engine == "pybullet"), None)
    res["operable"] = None if op is None else op.passed
    res["parts"] = {} if op is None else {
        j: {k: p[k] for k in ("label", "rule", "lever_m", "peak_force_n", "peak_torque_nm", "force_range_n", "torque_range_nm",
                              "range_of", "passed")} for j, p in (op.details.get("parts") or {}).items()}
    res["failures"] = [] if op is None else list(op.details.get("failures") or [])
    ov = json.loads((out / "overlay.json").read_text())
    res["joints"] = {n: {"friction": d["friction"], "damping": d["damping"], "stiffness": d["stiffness"],
                         "holding": d.get("holding"), "source": d.get("source", "")} for n, d in ov["joints"].items()}


def mechanisms(case: dict) -> list[str]:
    """The holding mechanisms of a case's overlay (each joint's ``holding.mechanism``), and where friction met a
    hand's cap or the hold floor beyond the range."""
    out = []
    for d in (case.get("joints") or {}).values():
        src = d.get("source", "")
        if (d.get("holding") or {}).get("mechanism"):
            out.append(d["holding"]["mechanism"])
        if "friction capped at" in src:
            out.append("friction at a hand's cap")
        if "is below what holds the requested state" in src or "hold floor" in src:
            out.append("held beyond the range (not operable)")
    return out


#: Smallest static load (N m or N) a hold margin is reported over.
LEAST_LOAD = 1e-3


def hold_margins(case: dict) -> list[float]:
    """Each joint's hold margin: its friction over the largest static load it was sized to hold (``holding.static_load``:
    the gravity load around its state, the set-down's lean), where there is one of at least :data:`LEAST_LOAD` (a
    mounted door on a vertical hinge has none)."""
    out = []
    for d in (case.get("joints") or {}).values():
        load = (d.get("holding") or {}).get("static_load") or 0.0
        if load >= LEAST_LOAD:
            out.append(float(d["friction"]) / load)
    return out


def effort_shares(case: dict) -> list[float]:
    """Each handled part's peak operating force over the top of its range (<= 1: a hand inside its range works it)."""
    return [p["peak_force_n"] / p["force_range_n"][1] for p in (case.get("parts") or {}).values()
            if p.get("force_range_n") and p["force_range_n"][1] > 0]


def _med(xs: list[float]) -> float:
    xs = sorted(xs)
    return xs[len(xs) // 2] if xs else float("nan")


def category_lines(results: list[dict], name=lambda c: c["category"]) -> list[str]:
    """Per category (``name``: a case's row label): ready rate, hold margin (friction over the largest static load:
    median, least), operating effort over the top of its range (median, most)."""
    by_cat: dict[str, list[dict]] = defaultdict(list)
    for c in results:
        by_cat[name(c)].append(c)
    lines = [f"{'category':34} {'ready':>11} {'hold margin med/min':>20} {'effort/range med/max':>21}"]
    for cat in sorted(by_cat):
        cs = by_cat[cat]
        ready = sum(1 for c in cs if c.get("mode") == "none")
        margins = [m for c in cs for m in hold_margins(c)]
        shares = [x for c in cs for x in effort_shares(c)]
        lines.append(f"{cat:34} {ready:4d}/{len(cs):<3d}{100.0 * ready / len(cs):4.0f}% "
                     f"{_med(margins):9.2f} {min(margins, default=float('nan')):9.2f} "
                     f"{_med(shares):10.2f} {max(shares, default=float('nan')):10.2f}")
    return lines


def report(results: list[dict]) -> str:
    """The printed tables."""
    lines = []
    ready = [c for c in results if c.get("mode") == "none"]
    op_ready = [c for c in ready if c.get("operable") is not False]
    lines.append(f"cases {len(results)}; interaction-ready {len(ready)}; of those every handled part operable {len(op_ready)}")
    lines.append("\nper category: ready, hold margin (friction over the largest static load), operating effort over its range")
    lines += category_lines(results)
    lines.append("\nper category: parts operable / parts; peak force N (median, max) against the range's top")
    by_cat: dict[str, list[dict]] = defaultdict(list)
    for c in results:
        by_cat[c["category"]].append(c)
    lines.append(f"{'category':18} {'ready':>6} {'cases':>6} {'parts ok':>9} {'med N':>7} {'max N':>7} {'range N':>9} {'max N m':>8}")
    for cat in sorted(by_cat):
        cs = by_cat[cat]
        parts = [p for c in cs for p in (c.get("parts") or {}).values()]
        forces = sorted(p["peak_force_n"] for p in parts)
        torques = [p["peak_torque_nm"] for p in parts if p.get("peak_torque_nm") is not None]
        tops = sorted({p["force_range_n"][1] for p in parts if p.get("force_range_n")})
        med = forces[len(forces) // 2] if forces else float("nan")
        lines.append(f"{cat:18} {sum(1 for c in cs if c.get('mode') == 'none'):6d} {len(cs):6d} "
                     f"{sum(1 for p in parts if p['passed']):4d}/{len(parts):<4d} {med:7.2f} {max(forces, default=float('nan')):7.2f} "
                     f"{'/'.join(f'{t:g}' for t in tops):>9} {max(torques, default=float('nan')):8.2f}")
    lines.append("\nper part")
    for c in results:
        for j, p in (c.get("parts") or {}).items():
            rng = p.get("force_range_n") or [None, None]
            jd = (c.get("joints") or {}).get(j, {})
            torque = "" if p.get("peak_torque_nm") is None else f", {p['peak_torque_nm']:.2f} N m"
            lines.append(f"  {c['id']:>8} {c['category']:16} {j:10} {str(p.get('label')):12} {p['peak_force_n']:7.2f} N"
                         f" (<= {rng[1]} N{torque})"
                         f" friction {jd.get('friction', float('nan')):.3g} damping {jd.get('damping', float('nan')):.3g}"
                         f" stiffness {jd.get('stiffness', 0.0):.3g} {'ok' if p['passed'] else 'NOT OPERABLE'}")
    counts: dict[str, int] = defaultdict(int)
    for c in results:
        for m in set(mechanisms(c)):
            counts[m] += 1
    lines.append("\nstability mechanisms (cases using each)")
    for m, n in sorted(counts.items()):
        lines.append(f"  {m:40} {n}")
    lines.append("\nverdicts")
    for c in results:
        lines.append(f"  {c['id']:>8} {c['category']:16} {c.get('mode'):24} operable={c.get('operable')} {c['seconds']:6.1f} s"
                     f"  {c['prompt']!r}" + (f" task={c['task']!r}" if c.get("task") else "")
                     + (f"  {c['error'][:160]}" if c.get("error") else ""))
        for f in c.get("failures") or []:
            lines.append(f"           {f}")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--manifest", type=Path, default=DEFAULT_MANIFEST)
    ap.add_argument("--out", type=Path, default=ROOT / "out" / "bench_operability")
    ap.add_argument("--ids", default="", help="comma-separated subset of object ids")
    ap.add_argument("--task", action="store_true", help="refine with each row's task too (refine --task)")
    ap.add_argument("--prompt", action="append", default=[], help="ID=TEXT: another request for that row")
    ap.add_argument("--jobs", type=int, default=1)
    args = ap.parse_args(argv)
    from asset2sim.tasks.ingest.manifest import read_manifest

    rows = read_manifest(args.manifest)
    ids = {s for s in args.ids.split(",") if s}
    prompts = dict(p.split("=", 1) for p in args.prompt)
    cases = [{"id": r.id, "category": r.category, "prompt": prompts.get(r.id, r.prompt), "task": r.task if args.task else "",
              "folder": str(r.folder)} for r in rows if not ids or r.id in ids]
    args.out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    if args.jobs > 1:
        with ProcessPoolExecutor(args.jobs) as pool:
            results = list(pool.map(run_case, cases, [str(args.out)] * len(cases)))
    else:
        results = [run_case(c, str(args.out)) for c in cases]
    (args.out / "cases.json").write_text(json.dumps(results, indent=1, default=str))
    print(report(results))
    print(f"\n{len(results)} cases in {time.perf_counter() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
