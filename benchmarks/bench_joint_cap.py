"""Refine time and peak memory against the number of movable joints (the joint cap).

Generates many-joint assets, runs ``asset2sim refine`` on each in a child
process, cold (``ASSET2SIM_CACHE=off``; the offline estimator, ``--no-extras`` unless ``--extras``) under
``/usr/bin/time``-like accounting (wall time, peak resident memory of the
child from ``ru_maxrss``) and a per-run timeout, and prints one row per
asset with the stage times of its ``report.json``. Shapes:

- ``chain``: a base and N revolute links in a chain (the links of the joint cap's
  end-to-end check: one 1.05 x 0.03 x 0.725 m box mesh of 12 triangles per
  link, each link 1 cm above its parent), so that every pair of links that
  are not parent and child overlaps: the worst case for the self-penetration
  queries (all N^2/2 pairs penetrate) and for the rest test's contacts;
- ``star``: a base box and N lids hinged on it, all at the same place (again
  every pair of lids overlaps: the worst case for a flat tree);
- ``chain-apart`` / ``star-apart``: the same trees with the links spaced so
  that no two links touch (a realistic keyboard-like or drawer-bank asset:
  the cost is the bookkeeping, not the contacts);
- ``keyboard``: the generated keyboard of ``tests/unseen_assets.py`` (PartNet-Mobility's layout, a base and keys on
  sliders a fifth of their pitch apart) with N keys in 6 rows (3 below 12), refined as "A keyboard.".

A least-squares fit of log(seconds) on log(N) per shape gives the growth
exponent and the N at which one asset would reach the flow's per-asset time
limit (``catalog.yaml`` ``run.time_limit_seconds``) on this machine. The
chosen cap (``tasks/ingest/findings.py`` ``MAX_MOVABLE_JOINTS``, checked in
``tasks/ingest/tree_checks.py``) and the
measurement are recorded in ``docs/design/validation.md`` ("Joint cap").

    .venv/bin/python benchmarks/bench_joint_cap.py                       # default sizes
    .venv/bin/python benchmarks/bench_joint_cap.py --shapes chain --joints 5 10 20 --timeout 600

Runs past ``--timeout`` are printed as ``>timeout`` (and extrapolated by the
fit of the finished ones); sizes above the cap are refused by validation
(exit status 1, left out of the fit). Keep the sizes small on a shared 2-core machine.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # tests.unseen_assets, for the keyboard

#: flow's per-asset limit (``catalog.yaml`` ``run.time_limit_seconds``), s
TIME_LIMIT_S = 1800.0

_BOX_OBJ = """mtllib original-1.mtl
o piece0
v -0.525000 0.225000 -0.350000
v 0.525000 0.225000 -0.350000
v -0.525000 0.255000 -0.350000
v 0.525000 0.255000 -0.350000
v -0.525000 0.225000 0.375000
v 0.525000 0.225000 0.375000
v -0.525000 0.255000 0.375000
v 0.525000 0.255000 0.375000
usemtl material_0
f 1 5 7
f 1 7 3
f 2 4 8
f 2 8 6
f 1 2 6
f 1 6 5
f 3 7 8
f 3 8 4
f 1 3 4
f 1 4 2
f 5 6 8
f 5 8 7
"""
_MTL = "newmtl material_0\nKd 0.6 0.6 0.6\n"
_INERTIAL = (
    '<inertial><mass value="0.1"/><inertia ixx="1e-3" iyy="1e-3" izz="1e-3" ixy="0" ixz="0" iyz="0"/></inertial>'
)


def _link(name: str, mesh: bool = True) -> str:
    if not mesh:
        return f'<link name="{name}"/>'
    g = '<geometry><mesh filename="textured_objs/original-1.obj"/></geometry>'
    return f'<link name="{name}"><visual>{g}</visual><collision>{g}</collision>{_INERTIAL}</link>'


def build(folder: Path, shape: str, n: int) -> Path:
    """Write a ``shape`` asset with ``n`` revolute joints under ``folder``
    (``mobility.urdf`` + one box mesh); returns ``folder``.

    ``shape``: chain, star, chain-apart, star-apart or keyboard (module docstring).
    Lengths in metres, limits +-0.5 rad.
    """
    if shape == "keyboard":
        from tests.unseen_assets import build_keyboard

        rows = 6 if n >= 12 else 3
        return build_keyboard(folder, rows=rows, cols=max(1, n // rows))
    apart = shape.endswith("-apart")
    parts = ['<?xml version="1.0"?>', '<robot name="bench">']
    star = shape.startswith("star")
    parts.append(_link("base", mesh=star))
    for i in range(n):
        parts.append(_link(f"link_{i}"))
        parent = "base" if star or i == 0 else f"link_{i - 1}"
        if star:
            xyz = f"{1.2 * (i + 1) if apart else 0.0} 0 0.01"
        else:
            xyz = f"0 0 {0.8 if apart else 0.01}"
        parts.append(
            f'<joint name="joint_{i}" type="revolute"><origin xyz="{xyz}"/><axis xyz="1 0 0"/>'
            f'<parent link="{parent}"/><child link="link_{i}"/><limit lower="-0.5" upper="0.5"/></joint>'
        )
    parts.append("</robot>")
    (folder / "textured_objs").mkdir(parents=True, exist_ok=True)
    (folder / "textured_objs" / "original-1.obj").write_text(_BOX_OBJ)
    (folder / "textured_objs" / "original-1.mtl").write_text(_MTL)
    (folder / "mobility.urdf").write_text("\n".join(parts) + "\n")
    return folder


def run_one(asset: Path, out: Path, extras: bool, timeout: float, prompt: str = "slightly open") -> dict:
    """Refine ``asset`` in a child process; returns wall s, peak RSS MiB,
    exit status (None on timeout) and the report's stage seconds."""
    cmd = [sys.executable, "-m", "asset2sim", "refine", str(asset), "--out", str(out), "-q",
           "-p", prompt, "--force"]
    if not extras:
        cmd.append("--no-extras")
    t = time.perf_counter()
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
                            env={**os.environ, "MPLBACKEND": "Agg", "ASSET2SIM_CACHE": "off"})  # cold, as an unseen object
    try:
        _, err = proc.communicate(timeout=timeout)
        rc = proc.returncode
    except subprocess.TimeoutExpired:
        proc.kill()
        _, err = proc.communicate()
        rc = None
    wall = time.perf_counter() - t
    # ru_maxrss of RUSAGE_CHILDREN is the largest child so far: run sizes ascending
    peak = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024.0
    stages = {}
    timings = out / "timings.json"  # the stage seconds a refine writes beside report.json
    if rc is not None and timings.is_file():
        stages = json.loads(timings.read_text()).get("stage_seconds", {})
    if rc not in (0, 3, None):
        sys.stderr.write(err[-2000:])
    return {"wall": wall, "mib": peak, "rc": rc, "stages": stages}


def fit(rows: list[tuple[int, float]]) -> tuple[float, float] | None:
    """(exponent k, coefficient a) of seconds ~ a * N^k by least squares on
    the logarithms; None with fewer than two points."""
    if len(rows) < 2:
        return None
    x = np.log([r[0] for r in rows])
    y = np.log([max(r[1], 1e-3) for r in rows])
    k, c = np.polyfit(x, y, 1)
    return float(k), float(np.exp(c))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--shapes", nargs="+", default=["chain", "star", "chain-apart", "star-apart"])
    ap.add_argument("--joints", type=int, nargs="+", default=[5, 10, 20, 32])
    ap.add_argument("--timeout", type=float, default=600.0, help="seconds per refine")
    ap.add_argument("--extras", action="store_true", help="include MJCF export, renders and the HTML report")
    args = ap.parse_args(argv)
    stage_names = ["closed_state", "refine_state", "post_check"]
    print(f"{'shape':>12} {'joints':>6} {'wall s':>8} {'peak MiB':>9} {'rc':>4}  " + " ".join(f"{s:>12}" for s in stage_names))
    with tempfile.TemporaryDirectory(prefix="bench_joint_cap_") as tmp:
        for shape in args.shapes:
            done: list[tuple[int, float]] = []
            for n in sorted(args.joints):
                asset = build(Path(tmp) / f"{shape}{n}", shape, n)
                r = run_one(asset, Path(tmp) / f"out_{shape}{n}", args.extras, args.timeout,
                            "A keyboard." if shape == "keyboard" else "slightly open")
                st = " ".join(f"{r['stages'].get(s, float('nan')):>12.1f}" for s in stage_names)
                wall = f"{r['wall']:>8.1f}" if r["rc"] is not None else f">{args.timeout:>7.0f}"
                print(f"{shape:>12} {n:>6} {wall} {r['mib']:>9.0f} {str(r['rc']):>4}  {st}", flush=True)
                if r["rc"] is None:
                    break  # larger sizes would time out too
                if r["rc"] not in (0, 3):
                    continue  # refused (e.g. above the cap) or failed: not a timing
                done.append((n, r["wall"]))
            f = fit([d for d in done if d[0] >= 10] or done)
            if f is not None:
                k, a = f
                n_lim = (TIME_LIMIT_S / a) ** (1.0 / k) if k > 0 else float("inf")
                print(f"{shape:>12}: seconds ~ {a:.3g} * N^{k:.2f}; the {TIME_LIMIT_S:g} s limit is reached at N ~ {n_lim:.0f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
