"""CoACD's settings against the present ones on the dev objects' meshes: CPU seconds, pieces and the summed volume
of the pieces' convex hulls (a looser fit holds more volume) per mesh, and the totals.

    .venv/bin/python benchmarks/bench_coacd.py --set mcts_iterations=30 [--per-object 2] [--ids 102990 ...]

The present settings are :data:`asset2sim.tasks.geometry.decomposition.COACD_SETTINGS`; ``--set KEY=VALUE``
(repeatable) overrides one of them (a CoACD keyword argument: integers, floats, ``true`` / ``false``). The meshes
are each object's ``--per-object`` largest OBJ files of ``textured_objs/`` between ``--min-faces`` and
``--max-faces`` faces (the refine decomposes a link's part mesh, not a whole object), read as the refine reads them
(:func:`asset2sim.mesh_io.read_mesh`), decomposed by CoACD directly (no cache). CoACD runs on one thread, as in the
flow's workers. A setting that changes the pieces changes outputs: before one is taken, ``bench_flow.py`` and
``compare_escalation.py`` must show every verdict held.
"""

from __future__ import annotations

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")  # as the flow's Dask workers run CoACD, before it is imported

import argparse  # noqa: E402
import csv  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
DEV = ROOT.parent / "shared" / "datasets" / "partnet_mobility"


def _value(text: str):
    """``text`` as a bool, an int or a float."""
    if text.lower() in ("true", "false"):
        return text.lower() == "true"
    try:
        return int(text)
    except ValueError:
        return float(text)


def _hull_volume(pieces) -> float:
    """Summed volume of the convex hulls of ``pieces`` [(vertices (N, 3), faces)], in the mesh's units cubed."""
    from scipy.spatial import ConvexHull
    from scipy.spatial import QhullError

    total = 0.0
    for v, _ in pieces:
        try:
            total += float(ConvexHull(v).volume)
        except (QhullError, ValueError):
            pass  # a flat piece holds no volume
    return total


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="a CoACD setting to compare")
    ap.add_argument("--ids", nargs="*", default=None, help="dev row ids (default: every row)")
    ap.add_argument("--per-object", type=int, default=2, help="largest meshes per object")
    ap.add_argument("--min-faces", type=int, default=150)
    ap.add_argument("--max-faces", type=int, default=5000)
    args = ap.parse_args(argv)
    sys.path.insert(0, str(ROOT))
    import coacd

    from asset2sim.mesh_io import read_mesh
    from asset2sim.tasks.geometry.decomposition import COACD_SETTINGS

    present = dict(COACD_SETTINGS)
    other = dict(present)
    for item in args.set:
        key, sep, text = item.partition("=")
        if not sep:
            ap.error(f"--set {item!r}: expected KEY=VALUE")
        other[key.strip()] = _value(text.strip())
    changed = {k: v for k, v in other.items() if present.get(k) != v}
    coacd.set_log_level("error")
    with open(DEV / "manifest.csv", newline="") as fh:
        ids = [r["id"] for r in csv.DictReader(fh) if args.ids is None or r["id"] in args.ids]
    print(f"present {present}\ncompared {changed or '(the same)'}")
    print(f"{'mesh':44s} {'faces':>6} {'present s':>10} {'pieces':>6} {'compared s':>10} {'pieces':>6} {'volume':>7}")
    t_present = t_other = 0.0
    ratios: list[float] = []
    for obj in ids:
        found = []
        for path in sorted((DEV / obj / "textured_objs").glob("*.obj")):
            mesh = read_mesh(path)
            v, f = mesh.vertices, mesh.faces
            if args.min_faces <= len(f) <= args.max_faces:
                found.append((len(f), path, v, f))
        found.sort(key=lambda c: (-c[0], c[1].name))
        for n_faces, path, v, f in found[: args.per_object]:
            row = []
            for settings in (present, other):
                t = time.process_time()
                pieces = coacd.run_coacd(coacd.Mesh(v, f), **settings)
                row.append((time.process_time() - t, len(pieces), _hull_volume(pieces)))
            (ta, na, va), (tb, nb, vb) = row
            t_present, t_other = t_present + ta, t_other + tb
            ratio = vb / va if va > 0 else float("nan")
            ratios.append(ratio)
            print(f"{obj + '/' + path.name:44s} {n_faces:6d} {ta:10.2f} {na:6d} {tb:10.2f} {nb:6d} {ratio:7.3f}", flush=True)
    if ratios:
        print(f"{len(ratios)} meshes: CPU {t_present:.1f} s present, {t_other:.1f} s compared ({t_other / max(t_present, 1e-9):.2f}x); "
              f"hull volume compared / present {min(ratios):.3f}-{max(ratios):.3f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
