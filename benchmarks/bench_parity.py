"""Export MJCF and USD and run the SPEC's metrics in PyBullet, PhysX (SAPIEN),
MuJoCo, MJX, PhysX on the USD (ovphysx) and Newton for every refined output folder under a root (default:
out/bench_refine, as written by benchmarks/bench_refine.py); print the parity
table (loaded, rest stable, oscillation, Phi and deepest point per engine),
the objects where the engines disagree, the holding table (per engine: the
objects whose every joint comes to rest in its band over the rest test, and
every joint with friction pushed alone, root fixed, gravity off, springs
accounted: does it start to move within 20 % of its declared friction,
``asset2sim.tasks.check.breakaway``), and the authored-equals-simulated
table (what each engine holds after loading, against the files).

    python benchmarks/bench_parity.py [--root out/bench_refine] [--ids 103275,7236]
        [--engines pybullet,physx,mujoco,mjx,ovphysx,newton] [--reuse] [--no-authored]

Newton (Kamino on the CPU) takes 1-3 minutes per object. Each (object,
engine) result is stored in FOLDER/parity/ENGINE.json with a hash of the
files it was computed from (every file of the output folder but the stored
results, and the code's git commit); ``--reuse`` takes a stored result whose hash
still matches instead of running the engine again (so Newton can be run per
object in the background, ``--engines newton --ids X``, and the table
assembled afterwards). Writes ROOT/parity.json.
"""

from __future__ import annotations

import argparse
import dataclasses
import hashlib
import json
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
#: The six paths: PyBullet and asset2sim's SAPIEN on the URDF, host MuJoCo (float64, no no-slip pass) and MJX (JAX's
#: float32, the CPU here) on the MJCF's physics, PhysX on the USD export (ovphysx), Newton.
ENGINES = ("pybullet", "physx", "mujoco", "mjx", "ovphysx", "newton")
#: A disagreement in the deepest point (mm) worth explaining: PyBullet's
#: 1 mm margin per shape makes touching hulls read 2 mm there only.
DEPTH_GAP_MM = 2.5


def inputs_hash(folder: Path) -> str:
    """sha256 over what a parity result depends on: every file of the output folder ``folder`` (the URDF, the state,
    the overlay, the meshes, the MJCF and USD exports and the solver aids ``report.json`` names) but the stored
    results under ``parity/``, and the git commit of the code that computes it (a changed engine or check runs
    again)."""
    h = hashlib.sha256()
    commit = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "HEAD"], capture_output=True, text=True)
    h.update(commit.stdout.strip().encode() or b"-")
    for p in sorted(folder.rglob("*")):
        rel = p.relative_to(folder).as_posix()
        if p.is_file() and not rel.startswith("parity/") and p.name != "timings.json":
            h.update(rel.encode() + b"\0" + hashlib.sha256(p.read_bytes()).digest())
    return h.hexdigest()


def parity_rows(folder: Path, engines: list[str], reuse: bool) -> tuple[list[dict], dict[str, float]]:
    """One parity row per engine (``parity_table``), run or reused; and the
    wall seconds per engine that ran."""
    from asset2sim.tasks.check.parity import evaluate_engines, parity_table

    digest = inputs_hash(folder)
    rows, seconds = [], {}
    for e in engines:
        cache = folder / "parity" / f"{e}.json"
        if reuse and cache.is_file():
            stored = json.loads(cache.read_text())
            if stored.get("hash") == digest:
                rows.append(stored["row"])
                continue
        t0 = time.perf_counter()
        row = parity_table(evaluate_engines(folder, [e]))[0]
        seconds[e] = time.perf_counter() - t0
        row["wall_s"] = seconds[e]
        if row["status"] != "skipped":
            cache.parent.mkdir(exist_ok=True)
            cache.write_text(json.dumps({"hash": digest, "row": row}, default=str))
        rows.append(row)
    return rows, seconds


def authored_checks(folder: Path, engines: list[str], reuse: bool) -> list:
    """``held_by_engines`` per engine, stored in FOLDER/parity/authored_ENGINE.json
    with :func:`inputs_hash` (reused with ``reuse``)."""
    from asset2sim.tasks.check.authored import AuthoredCheck, Mismatch, held_by_engines

    digest = inputs_hash(folder)
    out = []
    for e in engines:
        cache = folder / "parity" / f"authored_{e}.json"
        if reuse and cache.is_file():
            stored = json.loads(cache.read_text())
            if stored.get("hash") == digest:
                for c in stored["checks"]:
                    c["mismatches"] = [Mismatch(**m) for m in c["mismatches"]]
                    out.append(AuthoredCheck(**c))
                continue
        checks = held_by_engines(folder, [e])
        cache.parent.mkdir(exist_ok=True)
        cache.write_text(json.dumps({"hash": digest, "checks": [dataclasses.asdict(c) for c in checks]}, default=str))
        out += checks
    return out


def disagreements(rows: list[dict]) -> list[str]:
    """What differs between the engines that ran: load status, the rest and
    oscillation verdicts, and the deepest point beyond :data:`DEPTH_GAP_MM`."""
    ran = [r for r in rows if r["status"] != "skipped"]
    out = []
    if len({r["status"] for r in ran}) > 1:
        out.append("loads: " + ", ".join(f"{r['engine']} {r['status']}" for r in ran))
    ok = [r for r in ran if r["status"] == "ok"]
    for key in ("rest_stability", "oscillation"):
        if len({r[key] for r in ok}) > 1:
            detail = ", ".join(
                f"{r['engine']} {'pass' if r[key] else 'FAIL'}"
                + (f" (D_pos {r['D_pos_m']:.2g} m, D_ori {r['D_ori_rad']:.2g} rad)" if key == "rest_stability" and r["D_pos_m"] is not None else "")
                + (f" ({', '.join(map(str, r['failing_joints']))})" if key == "oscillation" and r["failing_joints"] else "")
                for r in ok
            )
            out.append(f"{key}: {detail}")
    depths = [(r["engine"], r["max_depth_mm"]) for r in ok if r["max_depth_mm"] is not None]
    if depths and max(d for _, d in depths) - min(d for _, d in depths) > DEPTH_GAP_MM:
        out.append("deepest point mm: " + ", ".join(f"{e} {d:.2f}" for e, d in depths))
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--root", type=Path, default=ROOT / "out" / "bench_refine")
    ap.add_argument("--ids", default="")
    ap.add_argument("--engines", default=",".join(ENGINES))
    ap.add_argument("--reuse", action="store_true", help="reuse stored per-engine results whose input hash matches")
    ap.add_argument("--no-authored", action="store_true", help="skip the authored-equals-simulated table")
    ap.add_argument("--no-export", action="store_true", help="do not (re)write mjcf/ and usd/")
    args = ap.parse_args(argv)

    from asset2sim.engines.quiet import quiet_stdout
    from asset2sim.formats.mjcf.export import export_mjcf

    engines = args.engines.split(",")
    folders = sorted(p.parent for p in args.root.glob("*/mobility.urdf"))
    if args.ids:
        keep = set(args.ids.split(","))
        folders = [f for f in folders if f.name in keep]
    counts = {e: {"stable": 0, "osc": 0, "ran": 0, "max_pen": 0.0, "max_depth": 0.0} for e in engines}
    holding = {e: {"objects": 0, "held": 0, "pushed": 0, "breakaway_ok": 0, "ratios": [], "not_measured": set()} for e in engines}
    rows_out = []
    authored_rows = []
    for f in folders:
        t0 = time.perf_counter()
        exports = {}
        if not args.no_export:
            for fmt, fn in (("mjcf", export_mjcf), ("usd", _export_usd)):
                try:
                    with quiet_stdout():
                        fn(f)
                    exports[fmt] = "ok"
                except Exception as exc:  # report and go on
                    exports[fmt] = f"FAILED: {type(exc).__name__}: {str(exc)[:120]}"
        with quiet_stdout():
            rows, seconds = parity_rows(f, engines, args.reuse)
        line = [f"{f.name:>7}"]
        for r in rows:
            c = counts[r["engine"]]
            if r["status"] == "ok":
                c["ran"] += 1
                c["stable"] += bool(r["rest_stability"])
                c["osc"] += bool(r["oscillation"])
                c["max_pen"] = max(c["max_pen"], r["penetration_mm"] or 0.0)
                c["max_depth"] = max(c["max_depth"], r["max_depth_mm"] or 0.0)
                line.append(f"{r['engine']}: {'S' if r['rest_stability'] else 's'}{'O' if r['oscillation'] else 'o'} "
                            + ("depth -" if r["max_depth_mm"] is None else f"depth {r['max_depth_mm']:.2f}"))
                h, brk = holding[r["engine"]], r.get("breakaway") or {}
                h["objects"] += 1
                h["held"] += all((r.get("joints_held") or {}).values())
                if brk.get("measured"):
                    for j in brk["joints"].values():
                        h["pushed"] += 1
                        h["breakaway_ok"] += bool(j["passed"])
                        h["ratios"].append(j["ratio"] if j["ratio"] is not None else float("inf"))
                elif brk:
                    h["not_measured"].add(brk.get("reason", "")[:100])
            else:
                line.append(f"{r['engine']}: {r['status']}")
        dis = disagreements(rows)
        checks = []
        if not args.no_authored:
            with quiet_stdout():
                checks = authored_checks(f, engines, args.reuse)
            for c in checks:
                authored_rows.append({"id": f.name, "engine": c.engine, "source": c.source.split(" ")[0], "status": c.status,
                                      "passed": c.passed, "reason": c.reason, "max_error": c.max_error,
                                      "mismatches": [str(m) for m in c.mismatches]})
        bad = [f"{c.engine}/{c.source.split(' ')[0]}: {c.status} {c.reason[:80]} {'; '.join(map(str, c.mismatches[:3]))}"
               for c in checks if c.passed is False]
        print("  ".join(line) + f"  {time.perf_counter() - t0:.1f}s"
              + (f"  exports {exports}" if any(v != "ok" for v in exports.values()) else ""), flush=True)
        for d in dis:
            print(f"          disagree: {d}", flush=True)
        for b in bad:
            print(f"          authored != simulated: {b}", flush=True)
        rows_out.append({"id": f.name, "exports": exports, "engines": rows, "disagreements": dis})
    print()
    print("engine    loaded  rest-stability  oscillation  max Phi (mm)  max deepest point (mm)")
    for e, c in counts.items():
        print(f"{e:<9} {c['ran']:>3}/{len(folders):<3} {c['stable']:>8} {c['osc']:>13} {c['max_pen']:>14.2f} {c['max_depth']:>14.2f}")
    print()
    print("holding: every joint at rest in its band over the rest test; breakaway of every joint with friction within 20 %")
    print("engine    objects  all joints held  joints pushed  breakaway within 20 %  breakaway / friction (min, max)")
    for e, h in holding.items():
        rng = f"{min(h['ratios']):.3f}, {max(h['ratios']):.3f}" if h["ratios"] else "-"
        why = f"  not measured: {'; '.join(sorted(h['not_measured']))}" if h["not_measured"] else ""
        print(f"{e:<9} {h['objects']:>7} {h['held']:>16} {h['pushed']:>14} {h['breakaway_ok']:>21}  {rng}{why}")
    if authored_rows:
        print()
        print("authored equals simulated (per engine and loaded file; error in units of the tolerance, <= 1 passes)")
        print("engine   file   compared  pass  skipped  error  worst mass  com  inertia  limits  damping  friction  stiffness  position")
        keys = ("mass", "com", "inertia", "limits", "damping", "friction", "stiffness", "position")
        groups: dict[tuple[str, str], list[dict]] = {}
        for r in authored_rows:
            groups.setdefault((r["engine"], r["source"]), []).append(r)
        for (e, src), rs in groups.items():
            comp = [r for r in rs if r["status"] == "ok"]
            worst = {k: max((r["max_error"].get(k, 0.0) for r in comp), default=0.0) for k in keys}
            print(f"{e:<8} {src:<6} {len(comp):>8} {sum(r['passed'] is True for r in rs):>5} {sum(r['status'] == 'skipped' for r in rs):>8}"
                  f" {sum(r['status'] == 'error' for r in rs):>6}      " + "  ".join(f"{worst[k]:.3f}" for k in keys))
    (args.root / "parity.json").write_text(json.dumps({"parity": rows_out, "authored": authored_rows}, indent=1, default=str))
    return 0


def _export_usd(folder: Path):
    from asset2sim.formats.usd.export import export_usd

    return export_usd(folder)


if __name__ == "__main__":
    sys.exit(main())
