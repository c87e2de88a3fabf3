"""Evaluation timing and an independent re-implementation check.

    python benchmarks/bench_evaluate.py [--manifest M] [--methods human,defaults] [--ids a,b] [--check] [--no-probes]

Builds the cheap baselines (``human``, ``defaults``) of the manifest rows in a
temporary folder, evaluates each with :func:`asset2sim.tasks.evaluation.evaluate.evaluate_asset`
and prints the evaluation time per asset and the median (the goal: <= 1.5 s
per asset without the pipeline's start-up).

``--check`` also recomputes Phi, D_pos, D_ori, the rest-stability and
oscillation verdicts and the ground penetration with :func:`independent_measure`:
plain ``pybullet`` calls written from docs/design/metrics.md sections 2-3, sharing
no code with ``asset2sim.engines`` or ``asset2sim.tasks.check.metrics``, and prints
any disagreement (exit code 1 when there is one).
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_MANIFEST = ROOT.parent / "shared" / "datasets" / "partnet_mobility" / "manifest.csv"


@contextlib.contextmanager
def _quiet():
    """Silence Bullet's C-level prints on fd 1 (argv[0]=, b3Warning)."""
    sys.stdout.flush()
    saved = os.dup(1)
    null = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(null, 1)
        yield
    finally:
        os.dup2(saved, 1)
        os.close(saved)
        os.close(null)


def spec_client():
    """A PyBullet DIRECT client under the SPEC's conventions: time step 1/240 s, gravity -9.81 m/s^2 along z."""
    import pybullet as pb
    from pybullet_utils import bullet_client

    with _quiet():
        c = bullet_client.BulletClient(connection_mode=pb.DIRECT)
    c.setTimeStep(1.0 / 240.0)
    c.setGravity(0, 0, -9.81)
    return c


def place_on_plane(c, body: int, plane: int) -> None:
    """Put ``body`` with its lowest collision point on ``plane`` (z = 0): its lowest AABB point first, then the
    exact smallest signed distance (docs/design/metrics.md, section 2)."""
    low = min(c.getAABB(body, i)[0][2] for i in range(-1, c.getNumJoints(body)))
    pos, orn = c.getBasePositionAndOrientation(body)
    c.resetBasePositionAndOrientation(body, [pos[0], pos[1], pos[2] - low], orn)
    c.performCollisionDetection()
    # search up to the top of the object + 5 cm: Bullet's AABBs of rotated hulls are loose
    top = max(c.getAABB(body, i)[1][2] for i in range(-1, c.getNumJoints(body)))
    pts = c.getClosestPoints(body, plane, max(top, 0.0) + 0.05)
    if pts:
        pos, orn = c.getBasePositionAndOrientation(body)
        c.resetBasePositionAndOrientation(body, [pos[0], pos[1], pos[2] - min(p[8] for p in pts)], orn)
    c.performCollisionDetection()


def load_placed(c, urdf: str | Path, initial_state: dict[str, float]) -> tuple[int, int, dict]:
    """(plane, body, movable) in client ``c``: a ground plane, the URDF loaded free under the SPEC's flags with its
    joints at ``initial_state`` and a zero-velocity motor of force = ``<dynamics friction>`` on each, placed on the
    plane (:func:`place_on_plane`); movable: joint -> (index, prismatic, friction, (lower, upper))."""
    import pybullet as pb

    plane = c.createMultiBody(0, c.createCollisionShape(pb.GEOM_PLANE))
    with _quiet():
        body = c.loadURDF(str(urdf), useFixedBase=False, flags=pb.URDF_USE_SELF_COLLISION
                          | pb.URDF_USE_SELF_COLLISION_EXCLUDE_PARENT | pb.URDF_USE_INERTIA_FROM_FILE)
    movable = {}
    for j in range(c.getNumJoints(body)):
        info = c.getJointInfo(body, j)
        if info[2] in (pb.JOINT_REVOLUTE, pb.JOINT_PRISMATIC):
            movable[info[1].decode()] = (j, info[2] == pb.JOINT_PRISMATIC, float(info[7]), (float(info[8]), float(info[9])))
    for name, (j, _, friction, _) in movable.items():
        if name in initial_state:
            c.resetJointState(body, j, float(initial_state[name]), 0.0)
        c.setJointMotorControl2(body, j, pb.VELOCITY_CONTROL, targetVelocity=0.0, force=friction)
    place_on_plane(c, body, plane)
    return plane, body, movable


def independent_measure(urdf: str | Path, initial_state: dict[str, float], springs: dict[str, tuple[float, float]] | None = None) -> dict:
    """The SPEC's physical metrics from scratch (docs/design/metrics.md, sections 2-3).

    Args:
        urdf: URDF path.
        initial_state: joint name -> position (rad or m).
        springs: joint name -> (stiffness, reference).

    Returns:
        {"phi_mm", "D_pos", "D_ori", "stable", "osc_fail" {joint: bool},
        "osc_pass", "ground_max_mm"}.
    """
    import numpy as np
    import pybullet as pb

    c = spec_client()
    try:
        plane, body, movable = load_placed(c, urdf, initial_state)
        phi = sum(max(0.0, -p[8]) for p in c.getContactPoints(body, body))
        ground = []

        def step():
            for name, (k, qs) in (springs or {}).items():
                j = movable[name][0]
                q = c.getJointState(body, j)[0]
                c.setJointMotorControl2(body, j, pb.TORQUE_CONTROL, force=-k * (q - qs))
            c.stepSimulation()
            ground.append(max([0.0] + [-p[8] for p in c.getContactPoints(body, plane)]))

        for _ in range(240):
            step()
        p0, q0 = c.getBasePositionAndOrientation(body)
        p0, q0 = np.array(p0), np.array(q0)
        traj = {n: [c.getJointState(body, j)[0]] for n, (j, *_) in movable.items()}
        d_pos = d_ori = 0.0
        finite = True
        for _ in range(480):
            step()
            p, q = c.getBasePositionAndOrientation(body)
            p, q = np.array(p), np.array(q)
            if not (np.all(np.isfinite(p)) and np.all(np.isfinite(q))):
                finite = False
                break
            d_pos = max(d_pos, float(np.linalg.norm(p - p0)))
            d_ori = max(d_ori, 2.0 * math.acos(min(1.0, abs(float(np.dot(q0, q))))))
            for n, (j, *_) in movable.items():
                traj[n].append(c.getJointState(body, j)[0])
        osc = {}
        for n, (j, prismatic, *_) in movable.items():
            x = np.array(traj[n])
            s = np.sign(np.diff(x))
            s = s[s != 0]
            changes = int(np.sum(s[1:] != s[:-1])) if len(s) > 1 else 0
            amp = float(x.max() - x.min())
            osc[n] = changes >= 3 and amp > (0.005 if prismatic else 0.05)
        return {
            "phi_mm": phi * 1000.0,
            "D_pos": d_pos,
            "D_ori": d_ori,
            "stable": finite and d_pos <= 1e-3 and d_ori <= 1e-2,
            "osc_fail": osc,
            "osc_pass": finite and not any(osc.values()),
            "ground_max_mm": max(ground) * 1000.0 if ground else 0.0,
        }
    finally:
        c.disconnect()


def compare(ev, ref: dict, rel: float = 1e-9) -> list[str]:
    """Disagreements between an Evaluation (pybullet) and :func:`independent_measure`."""
    out = []
    pen = ev.metric("penetration", "pybullet").value
    rs = ev.metric("rest_stability", "pybullet")
    osc = ev.metric("oscillation", "pybullet")
    gp = ev.metric("ground_penetration", "pybullet").value

    def close(a, b):
        return math.isclose(a, b, rel_tol=rel, abs_tol=1e-12)

    if not close(pen, ref["phi_mm"]):
        out.append(f"Phi {pen} vs {ref['phi_mm']} mm")
    if not close(rs.details.get("D_pos_m", float("nan")), ref["D_pos"]):
        out.append(f"D_pos {rs.details.get('D_pos_m')} vs {ref['D_pos']}")
    if not close(rs.details.get("D_ori_rad", float("nan")), ref["D_ori"]):
        out.append(f"D_ori {rs.details.get('D_ori_rad')} vs {ref['D_ori']}")
    if rs.passed != ref["stable"]:
        out.append(f"rest verdict {rs.passed} vs {ref['stable']}")
    if osc.passed != ref["osc_pass"]:
        out.append(f"oscillation verdict {osc.passed} vs {ref['osc_pass']}")
    if not close(gp, ref["ground_max_mm"]):
        out.append(f"ground {gp} vs {ref['ground_max_mm']} mm")
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--manifest", type=Path, default=DEFAULT_MANIFEST)
    ap.add_argument("--methods", default="human,defaults")
    ap.add_argument("--ids", default=None)
    ap.add_argument("--check", action="store_true")
    ap.add_argument("--no-probes", action="store_true")
    args = ap.parse_args(argv)

    from asset2sim.apps.benchmark.baselines import read_manifest, run_method
    from asset2sim.tasks.evaluation.evaluate import evaluate_asset

    rows = read_manifest(args.manifest)
    if args.ids:
        wanted = set(args.ids.split(","))
        rows = [r for r in rows if r.id in wanted]
    # warm-up (imports, first client) so the timings exclude start-up
    times, bad = [], 0
    with tempfile.TemporaryDirectory() as tmp:
        for method in args.methods.split(","):
            for row in rows:
                out = Path(tmp) / method / row.id
                run_method(method, row, out)
                if not times:
                    evaluate_asset(out, reference=row.folder, prompt=row.prompt, category=row.category, probes=False)
                t0 = time.perf_counter()
                ev = evaluate_asset(out, reference=row.folder, prompt=row.prompt, category=row.category,
                                    probes=not args.no_probes)
                dt = time.perf_counter() - t0
                times.append(dt)
                line = f"{method:9s} {row.id:7s} {row.category:17s} {dt:6.2f} s  ready={ev.passed}"
                if args.check:
                    state = json.loads((out / "initial_state.json").read_text())["initial_joint_positions"]
                    diffs = compare(ev, independent_measure(out / "mobility.urdf", state))
                    bad += bool(diffs)
                    line += "  independent check: " + ("agrees" if not diffs else "; ".join(diffs))
                print(line)
    if times:
        print(f"median evaluation time {statistics.median(times):.2f} s over {len(times)} assets "
              f"(min {min(times):.2f}, max {max(times):.2f}); goal <= 1.5 s")
    if args.check:
        print(f"independent re-implementation: {len(times) - bad} of {len(times)} agree")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
