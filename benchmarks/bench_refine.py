"""Refine every manifest row in one warm process; print per-object and total
wall time per stage, and the checks of refine's goals.

    python benchmarks/bench_refine.py [--manifest PATH] [--out DIR] [--ids 103275,7236] [--extras] [--process]
    nice -n 10 python benchmarks/bench_refine.py --process-only [--ids ...]

``--process`` also times ``asset2sim refine --force`` as a whole process per
object (cold imports, extras included: the throughput goal's measure) and
prints, per object and as medians, its wall time, the time the process spent
outside the stages it records (imports, argument parsing, interpreter exit),
the core stages, each extra (MJCF, USD, renders, evaluation + HTML report)
from the output's ``report.json``, and beside it the judge-style floor: a
fresh Python process that loads the output URDF in PyBullet and simulates 3 s
at the SPEC's step, in one run. ``--process-only`` skips the warm in-process
pass. Processes run with a bytecode cache outside the working tree (as an
installed package does; ``--no-bytecode-cache`` keeps this shell's
PYTHONDONTWRITEBYTECODE). The load average is printed before and after (the
machine is shared);
beside each wall time the CPU time (user + system) of the process, the
figure to compare on a loaded machine.

Writes DIR/summary.json. Numbers in notes and README come from this script.
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import resource
import statistics
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_MANIFEST = ROOT.parent / "shared" / "datasets" / "partnet_mobility" / "manifest.csv"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--manifest", type=Path, default=DEFAULT_MANIFEST)
    ap.add_argument("--out", type=Path, default=ROOT / "out" / "bench_refine")
    ap.add_argument("--ids", default="", help="comma-separated subset of ids")
    ap.add_argument("--extras", action="store_true", help="also time exports, renders and the HTML report")
    ap.add_argument("--process", action="store_true",
                    help="also time `asset2sim refine` (extras included) as a whole process per object, beside the "
                         "judge-style floor (PyBullet load of the output + 3 s of simulation in a fresh process)")
    ap.add_argument("--process-only", action="store_true", help="only the whole-process timing (no warm in-process pass)")
    ap.add_argument("--no-bytecode-cache", action="store_true",
                    help="run the processes as this environment says (PYTHONDONTWRITEBYTECODE: every module compiled from "
                         "source, about 0.2 s of CPU per process) instead of with a bytecode cache outside the tree")
    ap.add_argument("--judge", type=Path, default=None, help=argparse.SUPPRESS)  # internal: one judge-floor run
    args = ap.parse_args(argv)
    if args.judge is not None:
        print(f"{judge_floor(args.judge):.4f}")
        return 0
    if args.process_only:
        return _process_only(args)
    rows = _rows(args)
    results = _refine_in_process(rows, args)
    ok = [e for e in results if "error" not in e]
    print()
    if ok:
        _print_totals(ok)
    print(f"errors: {len(results) - len(ok)}")
    if args.process:
        _whole_process(rows, args, results)
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "summary.json").write_text(json.dumps(results, indent=1, default=float))
    return 0 if len(ok) == len(results) else 1


def _process_only(args) -> int:
    """``--process-only``: the whole-process timing alone, written to ``summary_process.json``; 1 when a process
    exited with another status than 0 or 3."""
    rows = _rows(args)
    print(f"load average before: {_load()}", flush=True)
    results: list[dict] = []
    _whole_process(rows, args, results)
    print(f"load average after: {_load()}", flush=True)
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "summary_process.json").write_text(json.dumps(results, indent=1, default=float))
    return 0 if all(e.get("process_exit") in (0, 3) for e in results) else 1


def _refine_in_process(rows: list[dict], args) -> list[dict]:
    """Refine each row in this process, printing one line per object; returns its entry (or its error)."""
    from asset2sim.tasks.refine import RefineError, refine_asset

    results = []
    for row in rows:
        src = args.manifest.parent / row["id"]
        t0 = time.perf_counter()
        try:
            res = refine_asset(src, row["prompt"], args.out / row["id"], skip_if_complete=False, extras=args.extras)
        except RefineError as exc:
            results.append({"id": row["id"], "error": f"{exc.failure_mode}: {exc}", "seconds": time.perf_counter() - t0})
            print(f"{row['id']:>7} ERROR {exc.failure_mode}: {exc}", flush=True)
            continue
        entry = _entry(row, src, res, time.perf_counter() - t0)
        results.append(entry)
        _print_entry(entry)
    return results


def _entry(row: dict, src: Path, res, wall: float) -> dict:
    """One object's figures from its refine result: scale against the reference (GenSim2's, else the manifest's),
    mass (kg), penetration (mm), rest stability and oscillation, inertia triangle inequality, joint states against
    their requested bands, stage times, ``wall`` (s)."""
    from asset2sim.schemas.request import BAND_INTERVAL
    from asset2sim.tasks.synthesize.validate_overlay import inertia_problems

    r = res.report
    ov = res.overlay
    ref = {}
    ref_path = src / "reference_gensim2.json"
    if ref_path.is_file():
        ref = json.loads(ref_path.read_text() or "{}")
    s_ref = ref.get("scale") or (float(row["reference_scale"]) if row.get("reference_scale") else None)
    landed = {}
    for joint, band in r.requested_bands.items():
        lo, hi = BAND_INTERVAL[band]
        f = r.opening_fractions.get(joint)
        landed[joint] = {"band": band, "fraction": f, "in_band": f is not None and lo - 1e-9 <= f <= hi + 1e-9}
    tri_ok = all(inertia_problems(lp.inertia.matrix()) is None for lp in ov.links.values())
    stab = r.metric("rest_stability")
    return {
        "id": row["id"],
        "category": r.category,
        "scale": r.scale,
        "scale_ref": s_ref,
        "scale_dev": abs(r.scale - s_ref) / s_ref if s_ref else None,
        "mass": r.total_mass,
        "penetration_mm": r.metric("penetration").value,
        "stable": stab.passed,
        "D_pos": stab.details.get("D_pos_m"),
        "D_ori": stab.details.get("D_ori_rad"),
        "oscillation_pass": r.metric("oscillation").passed,
        "triangle_ok": tri_ok,
        "failure_mode": r.failure_mode,
        "escalation_rounds": len(r.escalation) - 1,
        "state": r.initial_joint_positions,
        "closed": r.closed_positions,
        "bands": landed,
        "stage_seconds": r.stage_seconds,
        "seconds": wall,
    }


def _print_entry(e: dict) -> None:
    """One object's line: category, scale (reference), mass, penetration, stability, oscillation, escalation rounds,
    wall time, joint states in their bands (``!`` outside) and stage times."""
    print(
        f"{e['id']:>7} {e['category']:<16} s={e['scale']:.4g} (ref {e['scale_ref']}) m={e['mass']:.3g} kg "
        f"pen={e['penetration_mm']:.2f} mm stab={'P' if e['stable'] else 'F'} osc={'P' if e['oscillation_pass'] else 'F'} "
        f"esc={e['escalation_rounds']} {e['seconds']:.2f}s  "
        + " ".join(f"{k}:{v['band']}@{v['fraction']:.2f}{'' if v['in_band'] else '!'}" for k, v in e["bands"].items())
        + "  | " + " ".join(f"{k}={v:.2f}" for k, v in e["stage_seconds"].items()),
        flush=True,
    )


def _print_totals(ok: list[dict]) -> None:
    """Stage totals, the median refine time and scale deviation, the check counts over the objects refined."""
    stages = sorted({k for e in ok for k in e["stage_seconds"]})
    print("stage totals (s): " + ", ".join(f"{k} {sum(e['stage_seconds'].get(k, 0) for e in ok):.2f}" for k in stages))
    print(f"median refine time per object: {statistics.median(e['seconds'] for e in ok):.2f} s over {len(ok)} objects")
    devs = [e["scale_dev"] for e in ok if e["scale_dev"] is not None]
    if devs:
        print(f"median scale deviation vs GenSim2: {100 * statistics.median(devs):.1f}% (n={len(devs)})")
    print(f"rest stability {sum(bool(e['stable']) for e in ok)}/{len(ok)}, oscillation {sum(bool(e['oscillation_pass']) for e in ok)}/{len(ok)}, "
          f"max penetration {max(e['penetration_mm'] for e in ok):.2f} mm, triangle inequality {sum(e['triangle_ok'] for e in ok)}/{len(ok)}")
    bad = [(e["id"], j) for e in ok for j, v in e["bands"].items() if not v["in_band"]]
    print(f"joint states outside their band: {len(bad)} {bad}")


def judge_floor(urdf: Path, seconds: float = 3.0, timestep: float = 1.0 / 240.0) -> float:
    """Wall time (s) of what a judge does with an output at least: connect
    PyBullet (DIRECT), a ground plane, load the URDF (visual meshes included,
    self-collision as the SPEC), put its lowest point on the ground, step
    ``seconds`` of simulation at the SPEC's ``timestep``."""
    import pybullet as pb

    t0 = time.perf_counter()
    cid = pb.connect(pb.DIRECT)
    try:
        pb.setGravity(0, 0, -9.81, physicsClientId=cid)
        pb.setTimeStep(timestep, physicsClientId=cid)
        pb.createMultiBody(0, pb.createCollisionShape(pb.GEOM_PLANE, physicsClientId=cid), physicsClientId=cid)
        body = pb.loadURDF(str(urdf), flags=pb.URDF_USE_SELF_COLLISION | pb.URDF_USE_SELF_COLLISION_EXCLUDE_PARENT
                           | pb.URDF_USE_INERTIA_FROM_FILE, physicsClientId=cid)
        low = min(pb.getAABB(body, j, physicsClientId=cid)[0][2] for j in range(-1, pb.getNumJoints(body, physicsClientId=cid)))
        pos, orn = pb.getBasePositionAndOrientation(body, physicsClientId=cid)
        pb.resetBasePositionAndOrientation(body, [pos[0], pos[1], pos[2] - low], orn, physicsClientId=cid)
        for _ in range(int(round(seconds / timestep))):
            pb.stepSimulation(physicsClientId=cid)
    finally:
        pb.disconnect(cid)
    return time.perf_counter() - t0


def _rows(args) -> list[dict]:
    """The manifest rows (``--ids`` subset, manifest order)."""
    rows = list(csv.DictReader(args.manifest.open()))
    if args.ids:
        keep = set(args.ids.split(","))
        rows = [r for r in rows if r["id"] in keep]
    return rows


def _load() -> str:
    """The 1/5/15-minute load averages of this machine."""
    return " ".join(f"{x:.2f}" for x in os.getloadavg()) + f" ({os.cpu_count()} cores)"


def _whole_process(rows: list[dict], args, results: list[dict]) -> None:
    """Time ``asset2sim refine --force`` (extras included) as a subprocess per
    row and the judge floor of its output in another fresh process; print
    per-object lines and medians (wall, outside the stages, core, extras)."""
    cli = Path(sys.executable).parent / "asset2sim"
    env = dict(os.environ)
    if not getattr(args, "no_bytecode_cache", False):
        # as an installed package runs: compiled modules cached (here outside the working tree), written by a
        # first import; PYTHONDONTWRITEBYTECODE, when this shell sets it, would compile every module from source
        env.pop("PYTHONDONTWRITEBYTECODE", None)
        env["PYTHONPYCACHEPREFIX"] = str(Path.home() / ".cache" / "asset2sim" / "pycache")
        subprocess.run([sys.executable, "-c", "import asset2sim.commands.refine, asset2sim.tasks.evaluation.plots, matplotlib.figure, mujoco, pybullet"],
                       env=env, capture_output=True)
    print(f"bytecode cache: {env.get('PYTHONPYCACHEPREFIX') or 'as the environment says'}"
          f"{' (PYTHONDONTWRITEBYTECODE set: modules compiled from source)' if env.get('PYTHONDONTWRITEBYTECODE') else ''}")
    print("\nwhole process (`asset2sim refine --force`, extras included); judge floor = fresh process: "
          "PyBullet load + 3 s of simulation")
    print(f"{'id':>7} {'wall':>6} {'cpu':>6} {'outside':>7} {'core':>6} {'extras':>6}  {'judge':>5} {'jcpu':>5}  exit  "
          "extras by part / slowest core stages (wall s)")
    cols: dict[str, list[float]] = {"wall": [], "cpu": [], "outside": [], "core": [], "extras": [], "judge": [], "judge_cpu": []}
    for row in rows:
        out = args.out / "process" / row["id"]
        cmd = [str(cli), "refine", str(args.manifest.parent / row["id"]), "--prompt", row["prompt"], "--out", str(out),
               "--force", "--quiet"]
        ru0 = resource.getrusage(resource.RUSAGE_CHILDREN)
        t0 = time.perf_counter()
        proc = subprocess.run(cmd, capture_output=True, text=True, env=env)
        wall = time.perf_counter() - t0
        ru1 = resource.getrusage(resource.RUSAGE_CHILDREN)
        cpu = (ru1.ru_utime - ru0.ru_utime) + (ru1.ru_stime - ru0.ru_stime)
        urdf = out / "mobility.urdf"
        floor = floor_cpu = float("nan")
        if urdf.is_file():
            ru0 = resource.getrusage(resource.RUSAGE_CHILDREN)
            t1 = time.perf_counter()
            jp = subprocess.run([sys.executable, str(Path(__file__).resolve()), "--judge", str(urdf)], capture_output=True, text=True,
                                env=env)
            floor = time.perf_counter() - t1 if jp.returncode == 0 else float("nan")
            ru1 = resource.getrusage(resource.RUSAGE_CHILDREN)
            floor_cpu = (ru1.ru_utime - ru0.ru_utime) + (ru1.ru_stime - ru0.ru_stime)
        stages: dict[str, float] = {}
        rep = out / "report.json"
        if rep.is_file():
            stages = json.loads(rep.read_text()).get("stage_seconds", {})
        core = sum(v for k, v in stages.items() if not k.startswith("extras"))
        extras = sum(v for k, v in stages.items() if k.startswith("extras"))
        outside = wall - core - extras
        for k, v in (("wall", wall), ("cpu", cpu), ("outside", outside), ("core", core), ("extras", extras), ("judge", floor),
                     ("judge_cpu", floor_cpu)):
            cols[k].append(v)
        entry = next((e for e in results if e["id"] == row["id"]), None)
        if entry is None:
            entry = {"id": row["id"]}
            results.append(entry)
        entry.update(process_seconds=wall, process_cpu_seconds=cpu, judge_floor_seconds=floor, judge_floor_cpu_seconds=floor_cpu,
                     process_exit=proc.returncode,
                     process_stage_seconds=stages, outside_stages_seconds=outside)
        parts = " ".join(f"{k.removeprefix('extras_')}={v:.2f}" for k, v in stages.items() if k.startswith("extras"))
        slow = " ".join(f"{k}={v:.2f}" for k, v in sorted(((k, v) for k, v in stages.items() if not k.startswith("extras")),
                                                          key=lambda kv: -kv[1])[:3])
        print(f"{row['id']:>7} {wall:6.2f} {cpu:6.2f} {outside:7.2f} {core:6.2f} {extras:6.2f}  {floor:5.2f} {floor_cpu:5.2f}  {proc.returncode:>4}  "
              f"{parts} | {slow}", flush=True)
        if proc.returncode not in (0, 3):
            print("        " + (proc.stderr.strip().splitlines() or ["(no stderr)"])[-1], flush=True)
    if cols["wall"]:
        med = {k: statistics.median(v) for k, v in cols.items()}
        print(f"median over {len(cols['wall'])} objects: whole-process refine {med['wall']:.2f} s wall, {med['cpu']:.2f} s CPU "
              f"(outside the stages {med['outside']:.2f} s, core {med['core']:.2f} s, extras {med['extras']:.2f} s); judge floor "
              f"(fresh process, load + 3 s sim) {med['judge']:.2f} s wall, {med['judge_cpu']:.2f} s CPU; ratio "
              f"{med['wall'] / med['judge']:.1f}x wall, {med['cpu'] / med['judge_cpu']:.1f}x CPU")


if __name__ == "__main__":
    sys.exit(main())
