"""Compare the post-check of two ``bench_flow.py`` runs of the same dataset: how many post-check rounds each asset
needed, the post-check's seconds, every verdict that changed, and the hand's peak operating force on every operated
part (the operability check's ``peak_force_n`` against its ``force_range_n``).

    .venv/bin/python benchmarks/compare_escalation.py OLD_WORK NEW_WORK [--list-first]

``OLD_WORK`` and ``NEW_WORK`` are the ``--work`` folders of two ``bench_flow.py`` runs (their ``refined/``
outputs are read; the newest run of each asset is taken). Prints the rounds histogram of each, the number of assets
whose first post-check passed (one round), what failed at the first post-check of the others (``--list-first``: per
asset, the checks and the robust-rest trials with their largest joint drift, rad or m), the post-check's total
seconds, each changed failure mode or readiness tier, and the operated parts whose peak force moved by more than
:data:`FORCE_CHANGE` either way, with the median share of the force range and the number of parts above
:data:`HIGH_SHARE` of it.
"""

from __future__ import annotations

import argparse
import collections
import json
import statistics
import sys
from pathlib import Path

#: A peak operating force that moved by more than this share is listed (dimensionless).
FORCE_CHANGE = 0.05
#: Share of a part's force range above which its peak force counts as high (dimensionless).
HIGH_SHARE = 0.8


def load_run(work: Path) -> dict[str, dict]:
    """Asset -> {rounds, failure_mode, readiness, post_check_s, peaks: joint -> (peak N, top of range N)} of the
    newest output of each asset under ``work/refined``."""
    out: dict[str, tuple[float, dict]] = {}
    for report in sorted(work.glob("refined/*/*/*/report.json")):
        folder = report.parent
        try:
            rep = json.loads(report.read_text())
            times = json.loads((folder / "timings.json").read_text()).get("stage_seconds", {})
        except (OSError, ValueError):
            continue
        peaks = {}
        for m in rep.get("metrics", []):
            if m.get("name") != "operability":
                continue
            for joint, part in ((m.get("details") or {}).get("parts") or {}).items():
                top = (part.get("force_range_n") or [None, None])[1]
                if part.get("peak_force_n") is not None and top:
                    peaks[joint] = (float(part["peak_force_n"]), float(top))
        row = {"rounds": len(rep.get("escalation", [])), "failure_mode": rep.get("failure_mode") or "none",
               "readiness": rep.get("readiness", {}), "post_check_s": float(times.get("post_check", 0.0)), "peaks": peaks,
               "first_failed": first_round_failures(rep)}
        mtime = report.stat().st_mtime
        if folder.name not in out or mtime > out[folder.name][0]:
            out[folder.name] = (mtime, row)
    return {k: v for k, (_, v) in out.items()}


def first_round_failures(report: dict) -> list[str]:
    """What failed at the first post-check of an output's ``report.json`` (its ``escalation[0]``): each failed
    check (``name(engine)``), and for robust rest each failed trial with its largest joint drift (rad or m)."""
    rounds = report.get("escalation") or []
    if len(rounds) <= 1:
        return []
    out = []
    for m in rounds[0].get("metrics", []):
        if m.get("passed") is not False:
            continue
        out.append(f"{m.get('name')}({m.get('engine', '')})")
        for trial, t in ((m.get("details") or {}).get("trials") or {}).items() if m.get("name") == "robust_rest" else ():
            if not t.get("passed", True):
                drift = max((t.get("joint_drift") or {}).values(), default=0.0)
                out.append(f"{trial} {','.join(t.get('failing_joints') or [])} {drift:.3g}")
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("old", type=Path)
    ap.add_argument("new", type=Path)
    ap.add_argument("--list-first", action="store_true", help="list each new output's first post-check failures")
    args = ap.parse_args(argv)
    old, new = load_run(args.old), load_run(args.new)
    if not old or not new:
        print(f"no outputs under {args.old if not old else args.new}/refined")
        return 1
    for name, run in (("old", old), ("new", new)):
        hist = collections.Counter(r["rounds"] for r in run.values())
        print(f"{name}: {len(run)} assets, post-check rounds {dict(sorted(hist.items()))}, first post-check passed "
              f"{hist.get(1, 0)}, post-check {sum(r['post_check_s'] for r in run.values()):.0f} s in all")
        causes = collections.Counter(c.split(" ")[0] for r in run.values() for c in r["first_failed"])
        print(f"  what failed at the first post-check of the {sum(r['rounds'] > 1 for r in run.values())} that needed "
              f"more (checks, robust-rest trials): {dict(causes.most_common())}")
    if args.list_first:
        print("first post-check failures (new):")
        for asset in sorted(new):
            if new[asset]["first_failed"]:
                print(f"  {asset} ({new[asset]['rounds']} rounds): {'; '.join(new[asset]['first_failed'])}")
    print("verdicts that changed:")
    changed = 0
    for asset in sorted(set(old) & set(new)):
        a, b = old[asset], new[asset]
        tiers = {t: (a["readiness"].get(t), b["readiness"].get(t)) for t in sorted(set(a["readiness"]) | set(b["readiness"]))
                 if a["readiness"].get(t) != b["readiness"].get(t)}
        if a["failure_mode"] != b["failure_mode"] or tiers:
            changed += 1
            print(f"  {asset}: {a['failure_mode']} -> {b['failure_mode']} {tiers} (rounds {a['rounds']} -> {b['rounds']})")
    if not changed:
        print("  none")
    shares = {"old": [], "new": []}
    up, down = [], []
    for asset in sorted(set(old) & set(new)):
        for joint in sorted(set(old[asset]["peaks"]) & set(new[asset]["peaks"])):
            (fa, top_a), (fb, top_b) = old[asset]["peaks"][joint], new[asset]["peaks"][joint]
            shares["old"].append(fa / top_a)
            shares["new"].append(fb / top_b)
            if fb > fa * (1 + FORCE_CHANGE):
                up.append((fb - fa, asset, joint, fa, fb, top_b))
            elif fb < fa * (1 - FORCE_CHANGE):
                down.append((fa - fb, asset, joint, fa, fb, top_b))
    n = len(shares["old"])
    print(f"peak operating force on {n} operated parts: {len(down)} lower, {len(up)} higher (more than "
          f"{FORCE_CHANGE:.0%} either way)")
    for name in ("old", "new"):
        s = shares[name]
        if s:
            print(f"  {name}: median share of the force range {statistics.median(s):.2f}, above {HIGH_SHARE:.0%} of it: "
                  f"{sum(x > HIGH_SHARE for x in s)}")
    for label, rows in (("higher", up), ("lower", down)):
        for _, asset, joint, fa, fb, top in sorted(rows, reverse=True):
            print(f"  {label}: {asset} {joint}: {fa:.1f} -> {fb:.1f} N of {top:.1f} N")
    return 0


if __name__ == "__main__":
    sys.exit(main())
