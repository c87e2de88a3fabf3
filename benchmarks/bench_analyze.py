"""Time (and check the accuracy of) the mesh-analysis stage,
``asset2sim.tasks.geometry.analyze``, on every object of the dataset.

Usage::

    python benchmarks/bench_analyze.py [DATASET_DIR] [--repeat N] [--ids ID ...]
        [--voxels-per-axis N] [--links] [--accuracy]

DATASET_DIR defaults to ``../shared/datasets/partnet_mobility`` relative to
the project root. Extraction (URDF parsing) is done once per object and not
timed; every analysis starts from an empty mesh cache, so reading the OBJ
files is inside the timed region. Printed per object: wall seconds of the
first run, the minimum over ``--repeat`` runs, and CPU seconds of the process
for the first run (the machine is shared, so CPU time is the steadier number);
then the medians.

``--links`` also prints every link's volume, volume / bounding-box volume and
volume method.

``--accuracy`` prints the numbers quoted in ``docs/design/mesh_analysis.md``:
analytic shapes (voxel estimate vs exact, over random grid shifts and
rotations), real links whose collision pieces are watertight (voxel estimate
vs exact), and the reproducibility of the voxel estimate on every real
non-watertight link under random grid shifts (coefficient of variation).
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_DATA = ROOT.parent / "shared" / "datasets" / "partnet_mobility"


def _timings(data: Path, ids: list[str], repeat: int, options: dict, show_links: bool) -> None:
    import numpy as np

    from asset2sim.tasks.geometry.analyze import analyze_asset
    from asset2sim.tasks.ingest.extract import extract_asset

    analyze_asset(extract_asset(data / ids[0]), **options)  # warm-up: imports
    firsts, bests, cpus = [], [], []
    print(f"{'id':>8} {'links':>5} {'files':>5} {'MB':>6} {'faces':>8} {'first s':>8} {'min s':>8} {'cpu s':>7}")
    for oid in ids:
        asset = extract_asset(data / oid)
        files = {g.path for link in asset.links for g in (link.collisions or link.visuals) if g.path is not None}
        mb = sum(p.stat().st_size for p in files if p.is_file()) / 1e6
        times = []
        for i in range(max(1, repeat)):
            c0, t0 = time.process_time(), time.perf_counter()
            result = analyze_asset(asset, **options)
            times.append(time.perf_counter() - t0)
            if i == 0:
                cpus.append(time.process_time() - c0)
        firsts.append(times[0])
        bests.append(min(times))
        faces = sum(g.n_faces for g in result.values())
        print(f"{oid:>8} {len(result):5d} {len(files):5d} {mb:6.2f} {faces:8d} {times[0]:8.3f} {min(times):8.3f} {cpus[-1]:7.3f}")
        if show_links:
            for name, g in result.items():
                bbox = float(np.prod(g.extents))
                ratio = g.volume / bbox if bbox > 0 else float("nan")
                print(f"{'':>10}{name:<10} V={g.volume:.4g} m^3  V/bbox={ratio:.3f}  A={g.area:.4g} m^2  {g.volume_method}")
    print(f"median wall s (first run): {statistics.median(firsts):.3f}   max {max(firsts):.3f}   total {sum(firsts):.2f}")
    print(f"median wall s (min of {max(1, repeat)}): {statistics.median(bests):.3f}   max {max(bests):.3f}   total {sum(bests):.2f}")
    print(f"median cpu s (first run):  {statistics.median(cpus):.3f}   max {max(cpus):.3f}   total {sum(cpus):.2f}")


def _analytic_shapes():
    """(name, vertices, faces, volume, inertia per kg about com) of test shapes."""
    import numpy as np
    import trimesh

    def grid_tray(t):
        """Open box 0.4 x 0.3 x 0.2 with walls t, as 17 disjoint cells of a
        rectilinear grid (touching cells: internal faces are inside the
        solid). Exact moments by adding the cells' box moments."""
        a, b, c = 0.4, 0.3, 0.2
        xs, ys, zs = [0, t, a - t, a], [0, t, b - t, b], [0, t, c]
        cells = [
            (np.array([xs[i], ys[j], zs[k]]), np.array([xs[i + 1], ys[j + 1], zs[k + 1]]))
            for i in range(3) for j in range(3) for k in range(2) if (i, j, k) != (1, 1, 1)
        ]
        solid = trimesh.util.concatenate([trimesh.creation.box(bounds=[lo, hi]) for lo, hi in cells])
        vols = np.array([np.prod(hi - lo) for lo, hi in cells])
        centers = np.array([(lo + hi) / 2 for lo, hi in cells])
        vol = float(vols.sum())
        com = vols @ centers / vol
        second = sum(v * (np.diag((hi - lo) ** 2 / 12) + np.outer(c0 - com, c0 - com))
                     for v, c0, (lo, hi) in zip(vols, centers, cells)) / vol
        return solid, vol, np.trace(second) * np.eye(3) - second

    out = []
    a = 0.3
    quads = []
    for ax in range(3):
        u, w = [k for k in range(3) if k != ax]
        for sgn in (-1, 1):
            q = np.zeros((4, 3))
            q[:, ax] = sgn * a / 2
            s = a / 2 * 0.99
            q[:, u] = [-s, s, s, -s]
            q[:, w] = [-s, -s, s, s]
            quads.append(q)
    v = np.concatenate(quads)
    f = np.concatenate([np.array([[0, 1, 2], [0, 2, 3]]) + 4 * i for i in range(6)])
    out.append(("cube soup (6 quads, 1% gaps)", v, f, a**3, np.eye(3) * a * a / 6))
    sph = trimesh.creation.icosphere(subdivisions=5, radius=0.2)
    out.append(("sphere (icosphere 5)", sph.vertices, sph.faces, sph.volume, sph.moment_inertia / sph.mass))
    cyl = trimesh.creation.cylinder(radius=0.05, height=0.6, sections=256)
    out.append(("rod 0.1 x 0.6", cyl.vertices, cyl.faces, cyl.volume, cyl.moment_inertia / cyl.mass))
    for t in (0.01, 0.002):
        solid, vol, inertia = grid_tray(t)
        out.append((f"open box, walls {t * 1000:g} mm", solid.vertices, solid.faces, vol, inertia))
    return out


def _accuracy(data: Path, ids: list[str], voxels_per_axis: int) -> None:
    import numpy as np
    import trimesh

    from asset2sim.tasks.geometry import analyze as an
    from asset2sim.tasks.ingest.extract import extract_asset

    rng = np.random.default_rng(0)
    print(f"analytic shapes, voxel estimate vs exact (voxels_per_axis={voxels_per_axis}), 8 random grid shifts each:")
    print(f"{'shape':<32} {'orientation':<11} {'mode':<9} {'volume err % mean +- sd':>24} {'max |I err| %':>13} {'cpu ms':>7}")
    for name, v, f, vol, inertia in _analytic_shapes():
        for rotate in (False, True):
            for sub in (True, False):
                errs, ierrs, cpu = [], [], 0.0
                for _ in range(8):
                    r = trimesh.transformations.random_rotation_matrix(rng.random(3))[:3, :3] if rotate else np.eye(3)
                    c0 = time.process_time()
                    sm = an.voxel_properties(np.asarray(v) @ r.T, np.asarray(f), voxels_per_axis=voxels_per_axis,
                                             grid_shift=tuple(rng.random(3)), subvoxel=sub)
                    cpu += time.process_time() - c0
                    errs.append(sm.volume / vol - 1)
                    est = np.trace(sm.second) * np.eye(3) - sm.second
                    ref = r @ inertia @ r.T
                    ierrs.append(np.abs(est - ref).max() / np.abs(ref).max())
                print(f"{name:<32} {'random' if rotate else 'axis':<11} {'subvoxel' if sub else 'half':<9} "
                      f"{100 * np.mean(errs):+10.2f} +- {100 * np.std(errs):5.2f}      {100 * max(ierrs):13.2f} {1000 * cpu / 8:7.0f}")

    print("\nreal links with watertight collision pieces: voxel estimate vs exact")
    links = []
    for oid in ids:
        asset = extract_asset(data / oid)
        cache = an.MeshCache()
        for link in asset.links:
            surf = an.link_surface(link, cache=cache)
            if surf is not None:
                links.append((oid, link.name, surf))
    for oid, name, surf in links:
        exact = an.watertight_properties(surf.vertices, surf.faces)
        if exact is None:
            continue
        vox = an.voxel_properties(surf.vertices, surf.faces, voxels_per_axis=voxels_per_axis)
        size = float(np.max(surf.vertices.max(0) - surf.vertices.min(0)))
        print(f"  {oid:>7} {name:<8} exact {exact.volume:.5f} m^3  voxel {vox.volume:.5f} m^3  "
              f"err {100 * (vox.volume / exact.volume - 1):+.2f}%  com shift {100 * np.linalg.norm(vox.com - exact.com) / size:.2f}% of size")

    print("\nreal non-watertight links: reproducibility under 5 random grid shifts (links enclosing volume)")
    shifts = [tuple(rng.random(3)) for _ in range(5)]
    for sub in (True, False):
        cvs, coms = [], []
        for oid, name, surf in links:
            if an.watertight_properties(surf.vertices, surf.faces) is not None:
                continue
            area = an.surface_properties(surf.vertices, surf.faces)[0]
            res = [an.voxel_properties(surf.vertices, surf.faces, voxels_per_axis=voxels_per_axis, grid_shift=s, subvoxel=sub)
                   for s in shifts]
            vols = np.array([r.volume for r in res])
            if vols.mean() < an.OPEN_SHELL_FRACTION * area * res[0].pitch:
                continue
            size = float(np.max(surf.vertices.max(0) - surf.vertices.min(0)))
            cvs.append(vols.std() / vols.mean())
            c = np.array([r.com for r in res])
            coms.append(float(np.max(np.linalg.norm(c - c.mean(0), axis=1))) / size)
        cvs, coms = np.array(cvs), np.array(coms)
        print(f"  {'subvoxel' if sub else 'half':<9} links {len(cvs)}: volume CV median {100 * np.median(cvs):.2f}%  "
              f"p90 {100 * np.percentile(cvs, 90):.2f}%  max {100 * cvs.max():.2f}%; com spread max "
              f"{100 * coms.max():.2f}% of size")

    fine = 2 * voxels_per_axis
    print(f"\nreal non-watertight links: voxels_per_axis={voxels_per_axis} vs {fine} (links enclosing volume)")
    devs, names = [], []
    for oid, name, surf in links:
        if an.watertight_properties(surf.vertices, surf.faces) is not None:
            continue
        area = an.surface_properties(surf.vertices, surf.faces)[0]
        hi = an.voxel_properties(surf.vertices, surf.faces, voxels_per_axis=fine, max_voxels=40_000_000)
        if hi.volume < an.OPEN_SHELL_FRACTION * area * hi.pitch:
            continue
        lo = an.voxel_properties(surf.vertices, surf.faces, voxels_per_axis=voxels_per_axis)
        devs.append(lo.volume / hi.volume - 1)
        names.append(f"{oid}/{name}")
    devs = np.abs(np.array(devs))
    worst = np.argsort(devs)[::-1][:3]
    print(f"  links {len(devs)}: |V/V_fine - 1| median {100 * np.median(devs):.2f}%  p90 {100 * np.percentile(devs, 90):.2f}%  "
          f"max {100 * devs.max():.2f}% (worst: {', '.join(f'{names[i]} {100 * devs[i]:.1f}%' for i in worst)})")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("data", nargs="?", type=Path, default=DEFAULT_DATA)
    parser.add_argument("--repeat", type=int, default=1)
    parser.add_argument("--ids", nargs="*", default=None)
    parser.add_argument("--voxels-per-axis", type=int, default=None)
    parser.add_argument("--links", action="store_true")
    parser.add_argument("--accuracy", action="store_true")
    args = parser.parse_args(argv)

    from asset2sim.tasks.geometry.analyze import VOXELS_PER_AXIS

    if not args.data.is_dir():
        print(f"dataset folder not found: {args.data}", file=sys.stderr)
        return 2
    ids = args.ids or sorted(p.name for p in args.data.iterdir() if (p / "mobility.urdf").is_file())
    vpa = args.voxels_per_axis or VOXELS_PER_AXIS
    print(f"voxels_per_axis={vpa}, {len(ids)} objects")
    if args.accuracy:
        _accuracy(args.data, ids, vpa)
    else:
        _timings(args.data, ids, args.repeat, {"voxels_per_axis": vpa}, args.links)
    return 0


if __name__ == "__main__":
    sys.exit(main())
