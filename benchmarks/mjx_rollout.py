"""MJX rollouts of MJCF exports from their ``initial`` keyframe, on whatever device JAX has (a GPU where there is one).

    python benchmarks/mjx_rollout.py --root DIR --out ROLLOUTS [--ids 102703,11178] [--steps 2640] [--x64]
                                     [--contacts ground] [--precision highest]
    python benchmarks/bench_mjx_hold.py --root DIR --rollouts ROLLOUTS [--contacts ground]    # grade them

Needs only ``mujoco``, ``mujoco-mjx`` and ``jax`` (no asset2sim), so that it runs where learners run MJX, on a GPU
machine. For every ``DIR/<id>/mjcf/mobility.xml`` (the MJCF export, ``asset2sim export-mjcf`` or
``bench_mjx_hold.py --export-only``) the file is loaded as written, reset to its keyframe ``initial`` and stepped
``--steps`` times with ``mujoco.mjx.step`` (the first step alone, the rest in one ``jax.lax.scan``), in JAX's default
float32 or float64 with ``--x64``. The default 2,640 steps are ``bench_mjx_hold.py``'s run at 1/240 s: the settle (1 s)
and its creep window (10 s).

``--contacts ground`` lets the object's geoms collide with the ground only (:func:`ground_contacts_only`; MJX compiles
one collision function per pair of distinct meshes). ``--precision`` sets ``jax_default_matmul_precision``: JAX's
``default`` lets a GPU compute float32 products in TensorFloat-32 (Ampere and later; JAX's "Matmul precision" page),
``highest`` asks for full float32, as MuJoCo Playground sets it (its issue #86: TF32 changed its training results).
Writes ``ROLLOUTS/<id>.npz``: ``qpos`` (steps, nq), ``q0`` (nq,), the device, dtype, contacts, precision and wall
seconds (compilation included); prints one row per object.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np


def step_mjx(m, d, n: int) -> np.ndarray:
    """Positions (n, nq) of ``n`` ``mjx.step``s of model ``m`` from data ``d`` (host MuJoCo structs): the first alone
    (under ``jax_enable_x64`` the data MJX puts holds int32 contact indices its step returns as int64, which a scan's
    carry refuses), the rest in one ``jax.lax.scan``."""
    import jax
    import jax.numpy as jnp
    from mujoco import mjx

    mx, dx = mjx.put_model(m), mjx.put_data(m, d)
    dx = jax.jit(mjx.step)(mx, dx)
    first = dx.qpos

    def body(dx, _):
        dx = mjx.step(mx, dx)
        return dx, dx.qpos

    _, traj = jax.jit(lambda dx: jax.lax.scan(body, dx, None, length=n - 1))(dx)
    return np.asarray(jnp.concatenate([first[None], traj]), float)


def ground_contacts_only(m) -> None:
    """Let the geoms of model ``m``'s bodies collide with the world body's geoms (the ground) and nothing else: each
    colliding object geom gets contype 2 and conaffinity 0, each colliding world geom contype 1 and conaffinity 2
    (MuJoCo collides two geoms where contype of one and conaffinity of the other share a bit). In place."""
    for i in range(m.ngeom):
        if m.geom_contype[i] or m.geom_conaffinity[i]:
            m.geom_contype[i], m.geom_conaffinity[i] = (1, 2) if m.geom_bodyid[i] == 0 else (2, 0)


def rollout(xml: Path, n: int, ground_only: bool = False) -> tuple[np.ndarray, np.ndarray, float]:
    """(positions (n, nq), keyframe positions (nq,), wall s) of ``n`` MJX steps of ``xml`` from its keyframe ``initial``;
    ``ground_only``: with :func:`ground_contacts_only`."""
    import mujoco

    m = mujoco.MjModel.from_xml_path(str(xml))
    if ground_only:
        ground_contacts_only(m)
    d = mujoco.MjData(m)
    mujoco.mj_resetDataKeyframe(m, d, mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_KEY, "initial"))
    mujoco.mj_forward(m, d)
    q0 = d.qpos.copy()
    t0 = time.perf_counter()
    qpos = step_mjx(m, d, n)
    return qpos, q0, time.perf_counter() - t0


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--root", type=Path, required=True, help="folders <id>/mjcf/mobility.xml")
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--ids", default="")
    ap.add_argument("--steps", type=int, default=2640, help="bench_mjx_hold.py's run: settle 1 s + creep 10 s at 1/240 s")
    ap.add_argument("--x64", action="store_true", help="float64 (jax_enable_x64); JAX's default is float32")
    ap.add_argument("--contacts", choices=("all", "ground"), default="all", help="ground: the object's geoms collide with "
                    "the ground only")
    ap.add_argument("--precision", choices=("default", "highest"), default="default",
                    help="jax_default_matmul_precision (default: JAX's, TF32 on recent GPUs)")
    args = ap.parse_args(argv)
    import jax

    if args.x64:
        jax.config.update("jax_enable_x64", True)
    if args.precision != "default":
        jax.config.update("jax_default_matmul_precision", args.precision)
    device = str(jax.devices()[0])
    args.out.mkdir(parents=True, exist_ok=True)
    xmls = sorted(args.root.glob("*/mjcf/mobility.xml"))
    if args.ids:
        wanted = set(args.ids.split(","))
        xmls = [x for x in xmls if x.parent.parent.name in wanted]
    print(f"device {device}, jax {jax.__version__}, {'float64' if args.x64 else 'float32'}, matmul precision {args.precision}, "
          f"contacts {args.contacts}, {args.steps} steps, {len(xmls)} files", flush=True)
    for xml in xmls:
        oid = xml.parent.parent.name
        try:
            qpos, q0, wall = rollout(xml, args.steps, args.contacts == "ground")
        except Exception as exc:  # noqa: BLE001 - recorded; the next file goes on
            print(f"{oid} | failed: {type(exc).__name__}: {exc}", flush=True)
            continue
        np.savez(args.out / f"{oid}.npz", qpos=qpos, q0=q0, device=device, dtype="float64" if args.x64 else "float32",
                 contacts=args.contacts, precision=args.precision, wall_s=wall)
        print(f"{oid} | {wall:.1f} s | finite {bool(np.all(np.isfinite(qpos)))}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
