"""Refine time and peak memory against the number of mesh faces (the face cap).

Builds the corpus's valid asset (``tests/corpus_builder.py``) with its moving
``lid`` link's mesh (visual and collision) replaced by a closed UV sphere of
about N triangles, runs ``asset2sim refine`` on it in a child process (the
offline estimator, extras included as in the flow) and prints, per N, the
wall time (s) and the child's peak resident memory (MiB, ``ru_maxrss``). A
least-squares line through the points gives seconds and MiB per million
faces, and the face count at which one asset would reach the flow's time
limit (``catalog.yaml`` ``run.time_limit_seconds``) or the per-asset memory
budget.

    .venv/bin/python benchmarks/bench_mesh_cap.py                 # 12.5k .. 200k faces
    .venv/bin/python benchmarks/bench_mesh_cap.py --faces 20000 80000 --no-extras

Keep N <= ~200k on a shared 2-core machine (about a minute per point);
extrapolate beyond. The numbers are recorded in ``docs/design/validation.md``
("Face cap").
"""

from __future__ import annotations

import argparse
import math
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from tests import corpus_builder as cb  # noqa: E402  (a script next to the project)

#: per-asset memory budget, MiB: the flow runs ``run.workers`` = 2 assets at
#: once and the machine must stay well under 24 GiB.
MEMORY_BUDGET_MIB = 8 * 1024
TIME_LIMIT_S = 1800.0


def sphere_obj(n_faces: int, center=(0.5, -0.5, 0.025), radius=(0.5, 0.5, 0.025)) -> str:
    """A closed UV ellipsoid with about ``n_faces`` triangles as OBJ text
    (``2 * rings * segments`` minus the pole fans), file units metres."""
    seg = max(8, int(round(math.sqrt(n_faces / 2.0))))
    rings = max(4, int(round(n_faces / (2.0 * seg))))
    th = np.linspace(0.0, math.pi, rings + 1)[1:-1]
    ph = np.linspace(0.0, 2.0 * math.pi, seg, endpoint=False)
    T, P = np.meshgrid(th, ph, indexing="ij")
    xyz = np.stack([np.sin(T) * np.cos(P), np.sin(T) * np.sin(P), np.cos(T)], -1).reshape(-1, 3)
    xyz = np.vstack([[0, 0, 1], xyz, [0, 0, -1]]) * np.asarray(radius) + np.asarray(center)
    faces = []
    ring = lambda r, s: 2 + r * seg + (s % seg)  # 1-based OBJ index
    for s in range(seg):
        faces.append((1, ring(0, s), ring(0, s + 1)))
        faces.append((len(xyz), ring(rings - 2, s + 1), ring(rings - 2, s)))
    for r in range(rings - 2):
        for s in range(seg):
            a, b, c, d = ring(r, s), ring(r, s + 1), ring(r + 1, s + 1), ring(r + 1, s)
            faces += [(a, d, c), (a, c, b)]
    lines = [f"v {x:.7f} {y:.7f} {z:.7f}" for x, y, z in xyz]
    lines += [f"f {a} {b} {c}" for a, b, c in faces]
    return "\n".join(lines) + "\n"


def build(folder: Path, n_faces: int) -> int:
    """The valid asset with a ~``n_faces`` lid; returns the total face count."""
    m = cb.valid_model()
    cb._mesh("lid", "meshes/lid_big.obj")(m)
    cb.write_asset(folder, m)
    text = sphere_obj(n_faces)
    (folder / "meshes" / "lid_big.obj").write_text(text)
    return text.count("\nf ") + 12 + 12  # lid + base box + drawer box


def run_one(asset: Path, out: Path, extras: bool) -> tuple[float, float, int]:
    """(wall s, peak RSS MiB of the child, exit status)."""
    cmd = [sys.executable, "-m", "asset2sim", "refine", str(asset), "--out", str(out), "-q"]
    if not extras:
        cmd.append("--no-extras")
    before = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    t = time.perf_counter()
    proc = subprocess.run(cmd, capture_output=True, text=True, env={**os.environ, "MPLBACKEND": "Agg"})
    wall = time.perf_counter() - t
    peak = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    if peak <= before:  # ru_maxrss is the max over all children so far
        peak = before
    if proc.returncode not in (0, 3):
        sys.stderr.write(proc.stderr[-2000:])
    return wall, peak / 1024.0, proc.returncode


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--faces", type=int, nargs="+", default=[12_500, 25_000, 50_000, 100_000, 200_000])
    ap.add_argument("--no-extras", action="store_true", help="skip MJCF export, renders and the HTML report")
    args = ap.parse_args(argv)
    rows = []
    print(f"{'faces':>9} {'wall s':>8} {'peak MiB':>9} status")
    with tempfile.TemporaryDirectory(prefix="bench_mesh_cap_") as tmp:
        # sizes ascending: ru_maxrss of children is a running maximum
        for n in sorted(args.faces):
            asset = Path(tmp) / f"a{n}"
            total = build(asset, n)
            wall, mib, rc = run_one(asset, Path(tmp) / f"out{n}", not args.no_extras)
            rows.append((total, wall, mib))
            print(f"{total:>9} {wall:>8.1f} {mib:>9.0f} {rc}", flush=True)
    if len(rows) >= 2:
        f = np.array([r[0] for r in rows], float) / 1e6
        t_fit = np.polyfit(f, [r[1] for r in rows], 1)
        m_fit = np.polyfit(f, [r[2] for r in rows], 1)
        print(f"time   ~ {t_fit[1]:.1f} s + {t_fit[0]:.0f} s per million faces")
        print(f"memory ~ {m_fit[1]:.0f} MiB + {m_fit[0]:.0f} MiB per million faces")
        for label, fit, limit in (("time limit", t_fit, TIME_LIMIT_S), ("memory budget", m_fit, MEMORY_BUDGET_MIB)):
            if fit[0] > 0:
                print(f"{label} {limit:g} reached at ~{(limit - fit[1]) / fit[0]:.2f} million faces")
    return 0


if __name__ == "__main__":
    sys.exit(main())
