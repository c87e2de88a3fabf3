"""CPU seconds of one object refined cold, stage by stage: each dev row refined as an unseen object (the on-disk
cache off, ``ASSET2SIM_CACHE=off``) in a fresh process, with the flow's first phase (verdict and exports, media
deferred), so that nothing one refine made serves the next.

    nice -n 10 .venv/bin/python benchmarks/bench_cold_cpu.py [--ids 9912,102990] [--work DIR] [--warm] [--subdivide N]

Prints per row the verdict (``report.json``'s ``failure_mode``), the CPU seconds (user + system) of the refine call and of each stage (``timings.json``'s
``stage_cpu_seconds``), then the totals; imports and interpreter start-up are outside the figures. Each row's process
has the environment Dask's nanny gives the flow's workers (:data:`WORKER_ENV`, unless set already): one OpenMP thread
(CoACD's), one BLAS thread. The lazy imports of the refine (SAPIEN, MuJoCo, OpenUSD, SciPy's parts) and its tables
count unless ``--warm``, which makes them first as the flow's stage servers do before they fork a refine
(:func:`asset2sim.flows.forkserver.warm_tables` after its modules): what a flow pays per object.

``--subdivide N`` refines copies of the rows whose every OBJ has each triangle split into four, N times (the same
shapes in 4^N times the faces; normals, texture coordinates and materials dropped): unseen PartNet-Mobility objects
often carry denser meshes than the dev rows, and the copies show which costs grow with the faces.
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DEV = ROOT.parent / "shared" / "datasets" / "partnet_mobility"
#: What Dask's nanny sets in the flow's workers (``distributed.nanny.pre-spawn-environ``), inherited by their stage children.
WORKER_ENV = {"OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1", "MALLOC_TRIM_THRESHOLD_": "65536"}


def _subdivided(folder: Path, dest: Path, times: int) -> Path:
    """A copy of the asset ``folder`` at ``dest`` whose every ``textured_objs/*.obj`` has each triangle split into
    four ``times`` times (``trimesh.remesh.subdivide``; read and written by :mod:`asset2sim.mesh_io`, vertices and
    faces only). Returns ``dest``."""
    import shutil

    import trimesh

    from asset2sim import mesh_io

    shutil.rmtree(dest, ignore_errors=True)
    shutil.copytree(folder, dest)
    for obj in sorted((dest / "textured_objs").glob("*.obj")):
        mesh = mesh_io.read_mesh(obj)
        v, f = mesh.vertices, mesh.faces
        for _ in range(times):
            v, f = trimesh.remesh.subdivide(v, f)
        obj.write_bytes(mesh_io.obj_bytes(v, f))
    return dest


def _one(folder: Path, prompt: str, out: Path, warm: bool = False) -> None:
    """Refine the row at ``folder`` cold in this process (``warm``: its imports made first, as a stage server's);
    print a JSON line: the refine's CPU s and the stages' CPU s."""
    os.environ["ASSET2SIM_CACHE"] = "off"
    from asset2sim.tasks.refine import refine_asset

    if warm:
        import contextlib
        import importlib

        from asset2sim.flows import forkserver

        for mod in (*forkserver.WARM_MODULES, *forkserver.PROJECT_MODULES):
            with contextlib.suppress(Exception):
                importlib.import_module(mod)
        forkserver.warm_tables()

    c0 = time.process_time()
    refine_asset(folder, prompt, out, skip_if_complete=False, extras=True, media=False)
    cpu = time.process_time() - c0
    stages = json.loads((out / "timings.json").read_text())["stage_cpu_seconds"]
    verdict = json.loads((out / "report.json").read_text()).get("failure_mode")
    print(json.dumps({"cpu": cpu, "stages": stages, "verdict": verdict}))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--manifest", type=Path, default=DEV / "manifest.csv")
    ap.add_argument("--ids", default="", help="comma-separated subset of ids")
    ap.add_argument("--work", type=Path, default=None, help="output folder (default: a temporary one)")
    ap.add_argument("--warm", action="store_true", help="import what the flow's stage servers import before timing")
    ap.add_argument("--subdivide", type=int, default=0, metavar="N", help="refine copies with every triangle split in four N times")
    ap.add_argument("--one", nargs=3, help=argparse.SUPPRESS)  # internal: FOLDER PROMPT OUT, one row in this process
    args = ap.parse_args(argv)
    if args.one:
        _one(Path(args.one[0]), args.one[1], Path(args.one[2]), args.warm)
        return 0
    rows = list(csv.DictReader(args.manifest.open()))
    wanted = [i.strip() for i in args.ids.split(",") if i.strip()]
    rows = [r for r in rows if not wanted or r["id"] in wanted]
    work = args.work or Path(tempfile.mkdtemp(prefix="a2s-cold-cpu-"))
    print(f"load {' '.join(f'{x:.2f}' for x in os.getloadavg())}; CPU s per row, cache off, media deferred, "
          f"{os.environ.get('OMP_NUM_THREADS', WORKER_ENV['OMP_NUM_THREADS'])} OpenMP thread(s)" + (", imports warm" if args.warm else "")
          + (f", meshes subdivided {args.subdivide}x (4^{args.subdivide} x the faces)" if args.subdivide else ""))
    total: dict[str, float] = {}
    for r in rows:
        folder = _subdivided(DEV / r["id"], work / "inputs" / r["id"], args.subdivide) if args.subdivide else DEV / r["id"]
        proc = subprocess.run([sys.executable, __file__, "--one", str(folder), r["prompt"], str(work / r["id"]), *(["--warm"] * args.warm)],
                              capture_output=True, text=True, env={**WORKER_ENV, **os.environ})
        if proc.returncode != 0:
            print(f"{r['id']:>7} failed: {proc.stderr.strip().splitlines()[-1:]}")
            continue
        res = json.loads(proc.stdout.strip().splitlines()[-1])
        total["refine"] = total.get("refine", 0.0) + res["cpu"]
        for k, v in res["stages"].items():
            total[k] = total.get(k, 0.0) + v
        print(f"{r['id']:>7} {r['category']:<16} {res['verdict']:<24} {res['cpu']:6.2f} | "
              + " ".join(f"{k}={v:.2f}" for k, v in res["stages"].items() if v >= 0.05), flush=True)
    print("total   " + " ".join(f"{k}={v:.2f}" for k, v in total.items() if v >= 0.05))
    return 0


if __name__ == "__main__":
    sys.exit(main())
