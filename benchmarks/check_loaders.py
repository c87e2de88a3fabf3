"""The public loaders give the numbers asset2sim's own check gives.

For every refine output under ``--outputs`` (folders holding
``mobility.urdf`` and ``report.json``): the robust-rest trials (drop, tilts,
nudge) run on the asset loaded by

- ``asset2sim.load_pybullet(out, client)`` into a PyBullet client made as a
  user would (gravity -9.81 m/s^2, 1/240 s), against the ``robust_rest``
  metric ``report.json`` recorded;
- ``asset2sim.load_sapien(out, scene)`` into a user's SAPIEN scene, against
  ``load_sapien(out)`` (the session asset2sim's PhysX checks open);
- ``asset2sim.load_mujoco(out)``, against the MuJoCo session asset2sim's
  checks open (``open_session("mujoco", ...)`` with the same options).

Prints, per output and engine, the largest absolute difference of any trial
number (D_pos m, D_ori rad, topple rad, joint drift rad or m) and whether
every pass/fail verdict agrees; exit status 1 when one differs.

    python benchmarks/check_loaders.py --outputs DIR [--engines pybullet,physx,mujoco]
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import math
from pathlib import Path

import asset2sim
from asset2sim.api import verified_options
from asset2sim.engines.registry import open_session
from asset2sim.tasks.check import robust_rest


def trials(session) -> dict[str, dict]:
    """Every robust-rest trial of the product's configuration on ``session``."""
    return {t.name: {"d_pos": t.d_pos, "d_ori": t.d_ori, "topple": t.topple, "joint_drift": t.joint_drift, "passed": t.passed}
            for t in robust_rest.run_trials(session, dict(session.options.initial_state))}


def compare(a: dict, b: dict) -> tuple[float, bool]:
    """(largest absolute difference of the numbers, every verdict equal) of two trial sets."""
    worst, same = 0.0, set(a) == set(b)
    for name in set(a) & set(b):
        x, y = a[name], b[name]
        same &= x["passed"] == y["passed"]
        pairs = [(x[k], y[k]) for k in ("d_pos", "d_ori", "topple")]
        pairs += [(x["joint_drift"].get(j), y["joint_drift"].get(j)) for j in set(x["joint_drift"]) | set(y["joint_drift"])]
        for u, v in pairs:
            if u is None or v is None:
                same &= u is v
            elif math.isfinite(u) and math.isfinite(v):
                worst = max(worst, abs(u - v))
            else:
                same &= (u == v)
    return worst, same


def pybullet_row(out: Path) -> tuple[float, bool]:
    import pybullet as p

    report = json.loads((out / "report.json").read_text())
    [metric] = [m for m in report["metrics"] if m["name"] == "robust_rest" and m.get("engine", "pybullet") == "pybullet"]
    cid = p.connect(p.DIRECT)
    try:
        p.setGravity(0, 0, -9.81, physicsClientId=cid)
        p.setTimeStep(1 / 240, physicsClientId=cid)
        session = asset2sim.load_pybullet(out, cid)
        mine = trials(session)
        session.close()
    finally:
        p.disconnect(cid)
    recorded = {k: {kk: v.get(kk) for kk in ("d_pos", "d_ori", "topple", "joint_drift", "passed")} for k, v in metric["details"]["trials"].items()}
    return compare(mine, recorded)


def physx_row(out: Path) -> tuple[float, bool]:
    from asset2sim.engines import physx_engine

    own = asset2sim.load_sapien(out)
    expected = trials(own)
    own.close()
    session = asset2sim.load_sapien(out, physx_engine.new_scene())  # a scene of the user's, made with the checks' settings
    mine = trials(session)
    session.close()
    return compare(mine, expected)


def mujoco_row(out: Path) -> tuple[float, bool]:
    session = asset2sim.load_mujoco(out)
    mine = trials(session)
    session.close()
    product = open_session("mujoco", out / "mobility.urdf", verified_options(out))
    expected = trials(product)
    product.close()
    return compare(mine, expected)


ROWS = {"pybullet": (pybullet_row, "pybullet"), "physx": (physx_row, "sapien"), "mujoco": (mujoco_row, "mujoco")}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--outputs", type=Path, required=True, help="folder whose subfolders are refine outputs")
    ap.add_argument("--engines", default="pybullet,physx,mujoco")
    args = ap.parse_args()
    engines = [e for e in args.engines.split(",") if importlib.util.find_spec(ROWS[e][1]) is not None]
    outs = sorted(p.parent for p in args.outputs.glob("*/report.json"))
    bad = 0
    print(f"{'output':<12} " + " ".join(f"{e:>22}" for e in engines))
    for out in outs:
        if json.loads((out / "initial_state.json").read_text()).get("root", {}).get("fixed"):
            print(f"{out.name:<12} " + " ".join(f"{'mounted: no trials':>22}" for _ in engines))
            continue
        cells = []
        for e in engines:
            worst, same = ROWS[e][0](out)
            bad += not (same and worst == 0.0)
            cells.append(f"{worst:>10.3g} {'same' if same else 'DIFFERS':>11}")
        print(f"{out.name:<12} " + " ".join(cells), flush=True)
    print(f"{len(outs)} outputs; {bad} engine rows with any difference")
    return 1 if bad else 0


if __name__ == "__main__":
    raise SystemExit(main())
