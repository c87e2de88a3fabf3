"""MJX rollouts of MJCF exports from their ``initial`` keyframe, on whatever device JAX has (a GPU where there is one).

    python benchmarks/mjx_rollout.py --root DIR --out ROLLOUTS [--ids 102703,11178] [--steps 720] [--x64]
    python benchmarks/bench_mjx_hold.py --root DIR --rollouts ROLLOUTS     # grade them

Needs only ``mujoco``, ``mujoco-mjx`` and ``jax`` (no asset2sim), so that it runs where learners run MJX, on a GPU
machine. For every ``DIR/<id>/mjcf/mobility.xml`` (the MJCF export, ``asset2sim export-mjcf`` or
``bench_mjx_hold.py --export-only``) the file is loaded as written, reset to its keyframe ``initial`` and stepped
``--steps`` times with ``mujoco.mjx.step`` (the first step alone, the rest in one ``jax.lax.scan``), in JAX's default
float32 or float64 with ``--x64``. Writes ``ROLLOUTS/<id>.npz``: ``qpos`` (steps, nq), ``q0`` (nq,), the device, dtype
and wall seconds (compilation included); prints one row per object.
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


def rollout(xml: Path, n: int) -> tuple[np.ndarray, np.ndarray, float]:
    """(positions (n, nq), keyframe positions (nq,), wall s) of ``n`` MJX steps of ``xml`` from its keyframe ``initial``."""
    import mujoco

    m = mujoco.MjModel.from_xml_path(str(xml))
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
    ap.add_argument("--steps", type=int, default=720, help="the robust-rest window: settle 1 s + test 2 s at 1/240 s")
    ap.add_argument("--x64", action="store_true", help="float64 (jax_enable_x64); JAX's default is float32")
    args = ap.parse_args(argv)
    import jax

    if args.x64:
        jax.config.update("jax_enable_x64", True)
    device = str(jax.devices()[0])
    args.out.mkdir(parents=True, exist_ok=True)
    xmls = sorted(args.root.glob("*/mjcf/mobility.xml"))
    if args.ids:
        wanted = set(args.ids.split(","))
        xmls = [x for x in xmls if x.parent.parent.name in wanted]
    print(f"device {device}, {'float64' if args.x64 else 'float32'}, {args.steps} steps, {len(xmls)} files", flush=True)
    for xml in xmls:
        oid = xml.parent.parent.name
        try:
            qpos, q0, wall = rollout(xml, args.steps)
        except Exception as exc:  # noqa: BLE001 - recorded; the next file goes on
            print(f"{oid} | failed: {type(exc).__name__}: {exc}", flush=True)
            continue
        np.savez(args.out / f"{oid}.npz", qpos=qpos, q0=q0, device=device, dtype="float64" if args.x64 else "float32", wall_s=wall)
        print(f"{oid} | {wall:.1f} s | finite {bool(np.all(np.isfinite(qpos)))}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
