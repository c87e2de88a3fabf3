"""Does the MJCF export hold its initial state as MJX and host scenes run it (no no-slip pass)?

    python benchmarks/bench_mjx_hold.py [--root out/bench_refine] [--ids 100221,148] [--no-mjx] [--x64] [--contacts ground]
    python benchmarks/bench_mjx_hold.py --root DIR --rollouts ROLLOUTS [--contacts ground]  # MJX column: mjx_rollout.py's

For every output folder under ROOT (as written by ``benchmarks/bench_refine.py``) the MJCF is exported
(``export_mjcf``) and the written file is loaded with ``mujoco.MjModel.from_xml_path``, reset to its keyframe
``initial`` and stepped for the robust-rest window (the SPEC's settle 1 s + test 2 s at 1/240 s, 720 steps) with
no other change, in three ways (``--export-only`` writes the exports and stops):

- ``defaults``: host MuJoCo, every joint's friction solver parameters set back to MuJoCo's defaults
  (``solreffriction`` 0.02 1, ``solimpfriction`` 0.9 0.95 0.001 0.5 2: the export before it wrote its own), no no-slip;
- ``mujoco``: host MuJoCo, the file as written;
- ``mjx``: ``mujoco.mjx.step`` (JAX, on this machine's CPU) in one compiled loop, the file as written; JAX's
  default float32, or float64 with ``--x64``; or, with ``--rollouts``, the positions ``benchmarks/mjx_rollout.py``
  saved for the same files on another machine (a GPU's MJX, as learners run it; writes ROOT/mjx_hold_rollouts.json;
  each saved run names its contacts, which must be the ones asked here, and its matmul precision).

``--contacts ground`` runs every column with the object's own geoms colliding with the world's (the ground) only
(:func:`ground_contacts_only`): MJX compiles one collision function per pair of distinct meshes, and an object of many
convex pieces (a stapler's 80) does not finish compiling on a CPU. It first steps the file as written and with its
self-contacts off in host MuJoCo and prints the largest difference of any position over the whole run (the
``self-contacts`` column): where it is 0, the object's parts touched nothing of their own and the MJX column measures
the same motion as the file would make.

It also steps on to :data:`CREEP_TIME` s after the settle: every joint with friction must move at most 1 degree
(2 mm) there (the creep column, the largest per object in degrees or mm). A run holds when every joint with limits comes to rest inside its robust-rest band around the keyframe (max(0.02 rad
or 2 mm, 5 % of its range), not moving over the last 0.5 s: ``metrics.joint_settling``) and a free root is at rest
over the 2 s test (D_pos <= 1 mm, D_ori <= 0.01 rad: ``metrics.rest_stability``). Prints one row per object (the
worst joint's settled/band) and the counts; writes ROOT/mjx_hold.json (``--x64``: ROOT/mjx_hold_x64.json).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))

from mjx_rollout import ground_contacts_only, step_mjx

from asset2sim.engines.mjcf.aids import DEFAULT_SOLIMP, DEFAULT_SOLREF

#: Creep: every joint with friction moves at most CREEP_BOUND degrees (hinge) or mm (slide) over CREEP_TIME s after
#: the settle.
CREEP_TIME = 10.0
CREEP_BOUND = {"hinge": 1.0, "slide": 2.0}


def trace_of(m, qpos: np.ndarray, q0: np.ndarray):
    """A :class:`~asset2sim.tasks.check.metrics.RestTrace` of positions ``qpos`` (N, nq) stepped from keyframe ``q0``."""
    import mujoco

    from asset2sim.schemas.config import SimConventions
    from asset2sim.tasks.check.metrics import RestTrace

    conv = SimConventions()
    n_set = round(conv.settle_time / conv.timestep)
    free = m.njnt and int(m.jnt_type[0]) == int(mujoco.mjtJoint.mjJNT_FREE)
    joints, types, limits, settle, initial = {}, {}, {}, {}, {}
    for j in range(m.njnt):
        kind = int(m.jnt_type[j])
        if kind not in (int(mujoco.mjtJoint.mjJNT_HINGE), int(mujoco.mjtJoint.mjJNT_SLIDE)):
            continue
        name, a = mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_JOINT, j), int(m.jnt_qposadr[j])
        settle[name], joints[name] = qpos[:n_set, a], qpos[n_set - 1:, a]
        types[name] = "prismatic" if kind == int(mujoco.mjtJoint.mjJNT_SLIDE) else "revolute"
        limits[name] = tuple(float(x) for x in m.jnt_range[j]) if m.jnt_limited[j] else (-np.inf, np.inf)
        initial[name] = float(q0[a])
    test = qpos[n_set - 1:]
    pos = test[:, 0:3] if free else np.zeros((len(test), 3))
    quat = test[:, [4, 5, 6, 3]] if free else np.tile([0.0, 0.0, 0.0, 1.0], (len(test), 1))
    return RestTrace(t=np.arange(len(test)) * conv.timestep, root_pos=pos, root_quat=quat, joints=joints, joint_types=types,
                     p0=pos[0], q0=quat[0], settle_joints=settle, initial_joints=initial, joint_limits=limits,
                     diverged=not bool(np.all(np.isfinite(qpos))))


def step_host(m, d, n: int) -> np.ndarray:
    """Positions (n, nq) of ``n`` ``mj_step``s."""
    import mujoco

    out = np.empty((n, m.nq))
    for i in range(n):
        mujoco.mj_step(m, d)
        out[i] = d.qpos
    return out


def window_steps() -> tuple[int, int, int]:
    """(steps of the robust-rest window, of the settle, of a run: the settle and :data:`CREEP_TIME`) at the SPEC's
    time step."""
    from asset2sim.schemas.config import SimConventions

    conv = SimConventions()
    n_rest = round((conv.settle_time + conv.test_time) / conv.timestep)
    n_set = round(conv.settle_time / conv.timestep)
    return n_rest, n_set, max(n_rest, n_set + round(CREEP_TIME / conv.timestep))


def load(xml: Path, ground_only: bool = False):
    """(model, data at the keyframe ``initial``) of the file ``xml``, with :func:`ground_contacts_only` when asked."""
    import mujoco

    from asset2sim.engines.mjcf.base import mujoco_messages

    with mujoco_messages():
        m = mujoco.MjModel.from_xml_path(str(xml))
    if ground_only:
        ground_contacts_only(m)
    d = mujoco.MjData(m)
    mujoco.mj_resetDataKeyframe(m, d, mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_KEY, "initial"))
    mujoco.mj_forward(m, d)
    return m, d


def self_contact_effect(xml: Path, ground_only: np.ndarray) -> float:
    """Largest difference of any position (rad or m) between a host MuJoCo run of ``xml`` as written and
    ``ground_only``, the positions (n, nq) of the same run with :func:`ground_contacts_only` (:func:`window_steps`)."""
    return float(np.abs(step_host(*load(xml), len(ground_only)) - ground_only).max())


def hold(xml: Path, how: str, rollout: Path | None = None, ground_only: bool = False, positions: bool = False) -> dict:
    """One run of the file ``xml`` (``how``: defaults, mujoco, mjx) -> {"holds", "worst", "d_pos", "d_ori", "wall_s"};
    ``rollout``: with ``mjx``, the positions of an ``mjx_rollout.py`` run of the same file instead of a run here;
    ``ground_only``: the object's geoms collide with the ground only (:func:`ground_contacts_only`); ``positions``: the
    run's positions (n, nq) under "qpos" too."""
    import mujoco

    from asset2sim.schemas.config import SimConventions
    from asset2sim.tasks.check import metrics

    m, d = load(xml, ground_only)
    if how == "defaults":
        m.dof_solref[:] = DEFAULT_SOLREF
        m.dof_solimp[:] = DEFAULT_SOLIMP
    q0 = d.qpos.copy()
    conv = SimConventions()
    n_rest, n_set, n = window_steps()
    t0 = time.perf_counter()
    device = "host"
    if how == "mjx" and rollout is not None:
        saved = np.load(rollout)
        qpos, wall, device = saved["qpos"], float(saved["wall_s"]), f"{saved['device']} {saved['dtype']}"
        contacts = str(saved["contacts"]) if "contacts" in saved else "all"
        if len(qpos) != n or not np.allclose(saved["q0"], q0) or contacts != ("ground" if ground_only else "all"):
            raise ValueError(f"{rollout}: not {n} steps of {xml} from its keyframe with these contacts ({contacts})")
        if "precision" in saved:
            device += f" matmul {saved['precision']}"
    else:
        qpos = step_mjx(m, d, n) if how == "mjx" else step_host(m, d, n)
        wall = time.perf_counter() - t0
    creep = {}  # joint with friction -> how far it moved over CREEP_TIME after the settle (deg or mm)
    for j in range(m.njnt):
        kind = int(m.jnt_type[j])
        if kind in (int(mujoco.mjtJoint.mjJNT_HINGE), int(mujoco.mjtJoint.mjJNT_SLIDE)) and m.dof_frictionloss[m.jnt_dofadr[j]] > 0:
            a = int(m.jnt_qposadr[j])
            moved = float(np.abs(qpos[n_set:, a] - qpos[n_set - 1, a]).max())
            hinge = kind == int(mujoco.mjtJoint.mjJNT_HINGE)
            creep[mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_JOINT, j)] = (float(np.degrees(moved)) if hinge else 1e3 * moved,
                                                                          CREEP_BOUND["hinge" if hinge else "slide"])
    whole, qpos = qpos, qpos[:n_rest]
    trace = trace_of(m, qpos, q0)
    settling = metrics.joint_settling(trace)
    joints_held = all(s.held for s in settling.values())
    free = bool(m.njnt) and int(m.jnt_type[0]) == int(mujoco.mjtJoint.mjJNT_FREE)
    rest = metrics.rest_stability(trace, conv) if free else None
    worst = max(settling.items(), key=lambda kv: kv[1].settled / kv[1].band, default=None)
    out = {"holds": bool(joints_held and (rest is None or rest.passed)),
           "worst": None if worst is None else {"joint": worst[0], "settled": worst[1].settled, "band": worst[1].band,
                                                "held": worst[1].held},
           "d_pos": None if rest is None else rest.details.get("D_pos_m"), "d_ori": None if rest is None else rest.details.get("D_ori_rad"),
           "creep": creep, "creep_ok": all(v <= b for v, b in creep.values()),
           "options": {"noslip_iterations": int(m.opt.noslip_iterations), "cone": int(m.opt.cone)}, "wall_s": wall,
           "device": device}
    if positions:
        out["qpos"] = whole
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--root", type=Path, default=ROOT / "out" / "bench_refine")
    ap.add_argument("--ids", default="")
    ap.add_argument("--no-mjx", action="store_true", help="host MuJoCo only")
    ap.add_argument("--x64", action="store_true", help="MJX in float64 (jax_enable_x64; JAX's default is float32)")
    ap.add_argument("--rollouts", type=Path, default=None,
                    help="grade the MJX column from ROLLOUTS/<id>.npz (benchmarks/mjx_rollout.py, e.g. on a GPU machine)")
    ap.add_argument("--export-only", action="store_true", help="write each folder's mjcf/ export and stop")
    ap.add_argument("--contacts", choices=("all", "ground"), default="all",
                    help="ground: the object's geoms collide with the ground only (the module docstring)")
    args = ap.parse_args(argv)
    if args.x64:
        import jax

        jax.config.update("jax_enable_x64", True)
    from asset2sim.formats.mjcf.export import export_mjcf

    folders = sorted(p for p in args.root.iterdir() if (p / "mobility.urdf").is_file())
    if args.ids:
        wanted = set(args.ids.split(","))
        folders = [p for p in folders if p.name in wanted]
    hows = ["defaults", "mujoco"] + ([] if args.no_mjx else ["mjx"])
    rows = {}
    print("object | " + " | ".join(hows) + " | worst joint settled/band (mjx or mujoco) | mjx wall s")
    if args.export_only:
        for folder in folders:
            print(export_mjcf(folder))
        return 0
    for folder in folders:
        xml = export_mjcf(folder)
        saved = args.rollouts / f"{folder.name}.npz" if args.rollouts else None
        if saved is not None and not saved.is_file():
            print(f"{folder.name} | no rollout in {args.rollouts}", flush=True)
            continue
        ground = args.contacts == "ground"
        row = {how: hold(xml, how, saved, ground, positions=ground and how == "mujoco") for how in hows}
        if ground:  # the host run with the ground's contacts only against the file as written
            row["self_contacts"] = self_contact_effect(xml, row["mujoco"].pop("qpos"))
        rows[folder.name] = row
        if saved is not None:
            print(f"{folder.name} | mjx rollout: {row['mjx']['device']}", flush=True)
        last = row[hows[-1]]
        w = last["worst"]
        worst = "-" if w is None else f"{w['joint']} {w['settled']:.4f}/{w['band']:.3f}"
        wall = f"{row['mjx']['wall_s']:.1f}" if "mjx" in row else "-"
        creep = " | ".join(f"{max((v for v, _ in row[h]['creep'].values()), default=0.0):.3f}" + ("" if row[h]["creep_ok"] else " CREEPS")
                           for h in hows)
        effect = f" | self-contacts {row['self_contacts']:.3g}" if ground else ""
        print(f"{folder.name} | " + " | ".join("holds" if row[h]["holds"] else "MOVES" for h in hows) + f" | {worst} | {wall} | creep {creep}"
              + effect, flush=True)
    counts = {h: sum(r[h]["holds"] for r in rows.values()) for h in hows}
    print("holding: " + ", ".join(f"{h} {c}/{len(rows)}" for h, c in counts.items()))
    print(f"creep within 1 deg / 2 mm in {CREEP_TIME:g} s: "
          + ", ".join(f"{h} {sum(r[h]['creep_ok'] for r in rows.values())}/{len(rows)}" for h in hows))
    name = "mjx_hold_rollouts.json" if args.rollouts else "mjx_hold_x64.json" if args.x64 else "mjx_hold.json"
    name = name.replace(".json", "_ground.json") if args.contacts == "ground" else name
    (args.root / name).write_text(json.dumps({"rows": rows, "counts": counts}, indent=1, default=float))
    return 0


if __name__ == "__main__":
    sys.exit(main())
