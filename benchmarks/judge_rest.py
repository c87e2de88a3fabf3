"""An independent robust-rest judge: what a third party sees who loads an output's files with plain PyBullet.

    python benchmarks/judge_rest.py ROOT [--compare]

For every output folder under ROOT (a folder with ``mobility.urdf`` and ``initial_state.json``), the SPEC's robust
rest written from the SPEC alone, with plain ``pybullet`` calls and no code of ``asset2sim`` (the loading and
placement of ``bench_evaluate.py``): the URDF under the SPEC's flags, each joint's ``<dynamics friction>`` as a
zero-velocity motor and its damping as Bullet reads it, the springs of ``overlay.json`` (stiffness about
``spring_reference``) as a torque each step, nothing else of ``overlay.json``; a root the folder declares fixed is
skipped. Trials: dropped 2 cm, tilted 5 deg about x and y both ways (about the world axis through the centre of the
box around the links' collision shapes at ground level, then put down with its lowest point on the ground) and let
go; settle 1 s (and up to 3 s more while the root still moves), then 2 s of test. A trial passes when the root is at
rest over the test (D_pos <= 1 mm, D_ori <= 0.01 rad), upright (its up direction within 0.05 rad), and every joint
with limits (a continuous joint, a wheel, may roll) came to rest within max(0.02 rad or 2 mm, 5 % of its range) of its initial state, travelling less than a quarter of
that over the last 0.5 s.

``--compare`` prints beside each verdict the output's own robust-rest verdict in ``report.json`` (its drop and tilt
trials) and counts the agreements. The judge is also :func:`judge_folder` for tests.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_evaluate import load_placed, place_on_plane, spec_client  # noqa: E402  (the same loading and placement)

TRIALS = ("drop", "tilt+x", "tilt-x", "tilt+y", "tilt-y")
DT = 1.0 / 240.0


def _springs(folder: Path, state: dict[str, float]) -> dict[str, tuple[float, float]]:
    """joint -> (stiffness, reference) of ``overlay.json`` (reference: the initial state where it names none)."""
    p = folder / "overlay.json"
    if not p.is_file():
        return {}
    joints = json.loads(p.read_text()).get("joints") or {}
    return {n: (float(j["stiffness"]), float(j["spring_reference"] if j.get("spring_reference") is not None else state.get(n, 0.0)))
            for n, j in joints.items() if float(j.get("stiffness") or 0.0) > 0}


def _quat_angle(a, b) -> float:
    d = abs(sum(x * y for x, y in zip(a, b)))
    return 2.0 * math.acos(min(1.0, d))


def _tilt(c, body: int, plane: int, axis: tuple[float, float, float], angle: float) -> None:
    """Turn the body by ``angle`` about world ``axis`` through the centre of its links' box at its lowest z, then put it
    down on the plane."""
    import numpy as np

    boxes = [c.getAABB(body, i) for i in range(-1, c.getNumJoints(body))]
    lo = np.min([b[0] for b in boxes], axis=0)
    hi = np.max([b[1] for b in boxes], axis=0)
    pivot = np.array([(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, lo[2]])
    turn = c.getQuaternionFromAxisAngle(axis, angle)
    pos, orn = c.getBasePositionAndOrientation(body)
    R = np.array(c.getMatrixFromQuaternion(turn)).reshape(3, 3)
    new_pos = pivot + R @ (np.array(pos) - pivot)
    _, new_orn = c.multiplyTransforms([0, 0, 0], turn, [0, 0, 0], orn)
    c.resetBasePositionAndOrientation(body, new_pos.tolist(), new_orn)
    place_on_plane(c, body, plane)


def judge_folder(folder: str | Path) -> dict:
    """The judge's robust rest of one output folder: {"skipped": reason} for a root declared fixed, else
    {"passed": bool, "trials": {trial: {"passed", "d_pos", "d_ori", "upright", "joints": {joint: {"settled", "band",
    "still"}}}}} (lengths m, angles rad)."""
    import numpy as np
    import pybullet as pb

    folder = Path(folder)
    info = json.loads((folder / "initial_state.json").read_text())
    if (info.get("root") or {}).get("fixed"):
        return {"skipped": "root fixed as the folder declares"}
    state = {k: float(v) for k, v in (info.get("initial_joint_positions") or {}).items()}
    springs = _springs(folder, state)
    c = spec_client()
    try:
        plane, body, movable = load_placed(c, folder / "mobility.urdf", state)
        saved = c.saveState()
        q_start = {n: c.getJointState(body, j)[0] for n, (j, *_) in movable.items()}
        _, up_ref = c.getBasePositionAndOrientation(body)
        trials = {}
        for trial in TRIALS:
            c.restoreState(saved)
            if trial == "drop":
                pos, orn = c.getBasePositionAndOrientation(body)
                c.resetBasePositionAndOrientation(body, [pos[0], pos[1], pos[2] + 0.02], orn)
            else:
                axis = (1.0, 0.0, 0.0) if trial.endswith("x") else (0.0, 1.0, 0.0)
                _tilt(c, body, plane, axis, math.radians(5.0) * (1 if trial[4] == "+" else -1))

            def step() -> None:
                for name, (k, qs) in springs.items():
                    j = movable[name][0]
                    c.setJointMotorControl2(body, j, pb.TORQUE_CONTROL, force=-k * (c.getJointState(body, j)[0] - qs))
                c.stepSimulation()

            for _ in range(240):
                step()
            for _ in range(12):  # up to 3 s more, in 0.25 s windows, while the root still moves
                p0, o0 = c.getBasePositionAndOrientation(body)
                moved = turned = 0.0
                for _ in range(60):
                    step()
                    p, o = c.getBasePositionAndOrientation(body)
                    moved = max(moved, float(np.linalg.norm(np.subtract(p, p0))))
                    turned = max(turned, _quat_angle(o0, o))
                if moved <= 0.5e-3 and turned <= 0.5e-2:
                    break
            p0, o0 = c.getBasePositionAndOrientation(body)
            d_pos = d_ori = 0.0
            tail = {n: [] for n in movable}
            for i in range(480):
                step()
                p, o = c.getBasePositionAndOrientation(body)
                d_pos = max(d_pos, float(np.linalg.norm(np.subtract(p, p0))))
                d_ori = max(d_ori, _quat_angle(o0, o))
                if i >= 480 - 121:
                    for n, (j, *_) in movable.items():
                        tail[n].append(c.getJointState(body, j)[0])
            R0 = np.array(c.getMatrixFromQuaternion(up_ref)).reshape(3, 3)
            R1 = np.array(c.getMatrixFromQuaternion(o)).reshape(3, 3)
            up = R1 @ (R0.T @ np.array([0.0, 0.0, 1.0]))
            upright = math.acos(max(-1.0, min(1.0, float(up[2])))) <= 0.05
            joints = {}
            for n, (j, prismatic, _, (lo, hi)) in movable.items():
                if not lo <= hi:  # a continuous joint (Bullet reads no limits): a wheel may roll as the object lands
                    continue
                q = np.clip(tail[n], lo, hi)
                band = max(0.002 if prismatic else 0.02, 0.05 * (hi - lo) if hi > lo else 0.0)
                settled = abs(float(q[-1]) - state.get(n, q_start[n]))
                still = float(np.max(q) - np.min(q)) <= 0.25 * band
                joints[n] = {"settled": settled, "band": band, "still": still, "held": settled <= band and still}
            ok = d_pos <= 1e-3 and d_ori <= 1e-2 and upright and all(v["held"] for v in joints.values())
            trials[trial] = {"passed": ok, "d_pos": d_pos, "d_ori": d_ori, "upright": upright, "joints": joints}
        return {"passed": all(t["passed"] for t in trials.values()), "trials": trials}
    finally:
        c.disconnect()


def product_verdict(folder: Path) -> tuple[bool | None, dict[str, bool]]:
    """(the output's own robust-rest verdict on the judge's trials, trial -> passed) from its ``report.json``."""
    report = json.loads((folder / "report.json").read_text())
    rr = next((m for m in report.get("metrics") or [] if m["name"] == "robust_rest" and m.get("engine") == "pybullet"), None)
    if rr is None or rr.get("passed") is None:
        return None, {}
    trials = {k: bool(v.get("passed")) for k, v in (rr["details"].get("trials") or {}).items() if k in TRIALS}
    return all(trials.values()), trials


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("root", type=Path)
    ap.add_argument("--compare", action="store_true")
    a = ap.parse_args(argv)
    folders = sorted(p.parent for p in a.root.rglob("initial_state.json") if (p.parent / "mobility.urdf").is_file())
    judged = agree = passed = 0
    for f in folders:
        v = judge_folder(f)
        if "skipped" in v:
            print(f"{f.relative_to(a.root)}: skipped ({v['skipped']})")
            continue
        judged += 1
        passed += v["passed"]
        worst = [f"{t}: {n} {j['settled']:.4g} of {j['band']:.4g}" + ("" if j["still"] else " moving")
                 for t, tv in v["trials"].items() for n, j in tv["joints"].items() if not j["held"]]
        line = f"{str(f.relative_to(a.root)):40s} judge {'PASS' if v['passed'] else 'FAIL'}"
        if a.compare and (f / "report.json").is_file():
            own, _ = product_verdict(f)
            agree += own == v["passed"]
            line += f"  product {'-' if own is None else 'PASS' if own else 'FAIL'}"
        print(line + ("  " + "; ".join(worst[:3]) if worst else ""))
    print(f"judged {judged}, passed {passed}" + (f", agreeing with the product {agree}" if a.compare else ""))
    return 0


if __name__ == "__main__":
    sys.exit(main())
