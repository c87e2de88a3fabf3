"""Do the files refine writes load where their users load them? Over output
folders (each holding ``mobility.urdf``): MuJoCo's URDF importer on the URDF,
the MJCF (``mjcf/mobility.xml``, or converted in memory when absent) dropped
from 5 cm, the collision pieces, the parent-child containment at the initial
state (the depth of the child's vertices inside the parent's pieces, and the
penetration an engine colliding the pair reports: the hulls' separating-axis
depth, PyBullet's and MuJoCo's closest points), fixed-joint limits and the
lightest link. Prints one row per object and
the counts.

    python benchmarks/bench_simulator_files.py OUTPUT_ROOT [--ids 9912,7236] [--convert]

``--convert``: convert every URDF to MJCF in memory (the current converter)
instead of loading the ``mjcf/`` an earlier run wrote.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import tempfile
from pathlib import Path

import numpy as np

#: Drop height (m) above the resting placement, and simulated time (s).
DROP_HEIGHT = 0.05
DROP_TIME = 1.0


def signed_volume(path: Path) -> float:
    """Signed volume (m^3, file units) of an OBJ's triangles: > 0 when the
    faces of a closed mesh wind outward."""
    from asset2sim.mesh_io import read_mesh

    mesh = read_mesh(path)
    v, f = mesh.vertices, mesh.faces
    t = np.asarray(v, float)[np.asarray(f, int)]
    return float(np.einsum("ij,ij->i", t[:, 0], np.cross(t[:, 1], t[:, 2])).sum() / 6.0)


def drop_test(xml_path: Path | None, build) -> dict:
    """Compile the MJCF (``xml_path`` or the in-memory ``build``), start at
    the keyframe lifted by :data:`DROP_HEIGHT`, simulate :data:`DROP_TIME`;
    returns compile error / max contacts / MuJoCo warnings / lowest point."""
    import mujoco

    from asset2sim.engines.mjcf import lowest_point, mujoco_messages

    out = {"compiles": False, "max_contacts": 0, "warnings": [], "lowest_m": None, "error": ""}
    try:
        with mujoco_messages() as caught:
            m = mujoco.MjModel.from_xml_path(str(xml_path)) if xml_path else mujoco.MjModel.from_xml_string(build.xml, assets=build.assets())
    except Exception as exc:
        out["error"] = str(exc).splitlines()[0][:200]
        return out
    out["compiles"] = True
    out["ngeom"] = int(m.ngeom)
    d = mujoco.MjData(m)
    if m.nkey:
        mujoco.mj_resetDataKeyframe(m, d, 0)
    free = m.njnt and m.jnt_type[0] == mujoco.mjtJoint.mjJNT_FREE
    out["free"] = bool(free)
    if free:
        d.qpos[2] += DROP_HEIGHT
    try:
        with mujoco_messages() as caught:
            for _ in range(int(DROP_TIME / m.opt.timestep)):
                mujoco.mj_step(m, d)
                out["max_contacts"] = max(out["max_contacts"], int(d.ncon))
    except Exception as exc:
        out["error"] = str(exc).splitlines()[0][:200]
    out["warnings"] = sorted({w.split(":")[0][:80] for w in caught})
    bad = [i for i in range(len(d.warning)) if d.warning[i].number > 0]
    out["warnings"] += [mujoco.mjtWarning(i).name for i in bad]
    mujoco.mj_forward(m, d)
    out["lowest_m"] = lowest_point(m, d)
    # arena: MuJoCo's default memory unless the file sets <size memory> (ours does not)
    out["arena_bytes"] = int(m.narena)
    out["arena_max_used_bytes"] = int(d.maxuse_arena)
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("root", type=Path, help="folder of output folders (or one output folder)")
    ap.add_argument("--ids", default="")
    ap.add_argument("--convert", action="store_true")
    args = ap.parse_args(argv)

    folders = [args.root] if (args.root / "mobility.urdf").is_file() else sorted(p.parent for p in args.root.glob("*/mobility.urdf"))
    if args.ids:
        keep = set(args.ids.split(","))
        folders = [f for f in folders if f.name in keep]
    rows = []
    for f in folders:
        row, state = _file_checks(f)
        rows.append(row)
        if _mjcf_checks(f, state, row, args.convert):
            print(json.dumps(row), flush=True)
    _print_counts(rows)
    return 0


def _file_checks(f: Path) -> tuple[dict, dict]:
    """The row of output folder ``f`` as far as its URDF goes: MuJoCo's importer, the collision pieces (count per
    link, flat groups, inside-out files), penetration (:func:`_penetration_checks`), fixed-joint limits, the lightest
    link; returns (row, initial state)."""
    import mujoco

    from asset2sim.engines.loading import collision_pieces, read_urdf
    from asset2sim.refined_asset import read_initial_state
    from asset2sim.engines.mjcf import mujoco_messages

    urdf_path = f / "mobility.urdf"
    row = {"id": f.name}
    try:
        with mujoco_messages():
            mujoco.MjModel.from_xml_path(str(urdf_path))
        row["urdf_mujoco"] = "ok"
    except Exception as exc:
        row["urdf_mujoco"] = str(exc).splitlines()[0][:120]
    model = read_urdf(urdf_path)
    state = read_initial_state(f)
    pieces, notes = collision_pieces(model)
    row["max_pieces_per_link"] = max((len(v) for v in pieces.values()), default=0)
    row["flat_groups"] = sum("is flat" in n for n in notes)
    # collision-only files (generated pieces) must be closed and wound outward
    visual_files = {v.path.resolve() for ln in model.links.values() for v in ln.visuals if v.kind == "mesh" and v.path}
    inside_out = sum(
        1 for ln in model.links.values() for c in ln.collisions
        if c.kind == "mesh" and c.path is not None and c.path.resolve() not in visual_files
        and c.path.suffix.lower() == ".obj" and signed_volume(c.path) <= 0
    )
    row["inside_out"] = inside_out
    _penetration_checks(row, urdf_path, model, pieces, state)
    row["fixed_limit_incomplete"] = sum(
        1 for j in model.joints if j.type == "fixed" and j.limit is not None and (j.limit.effort is None or j.limit.velocity is None)
    )
    masses = [ln.inertial.mass for ln in model.links.values() if ln.inertial is not None and (ln.collisions or ln.visuals)]
    row["min_link_mass_g"] = round(min(masses) * 1000, 3) if masses else None
    row["min_mass_ratio"] = round(min(masses) / sum(masses), 5) if masses else None
    return row, state


def _penetration_checks(row: dict, urdf_path: Path, model, pieces: dict, state: dict) -> None:
    """Into ``row``: the deepest child inside its parent's hull pieces at the initial state (mm, and the pair), and
    the same pairs' penetration as an engine colliding them sees it (mm)."""
    from asset2sim.tasks.check.parent_child import parent_child_penetration
    from asset2sim.engines.source import UrdfFile
    from asset2sim.tasks.assemble.convex_pieces import Piece
    from asset2sim.tasks.assemble.piece_penetration import containment_depths, parent_child_depths

    hulls = {}
    for name, plist in pieces.items():
        hulls[name] = []
        for p in plist:
            if p.kind != "hull":
                continue
            pts = p.points @ p.origin[:3, :3].T + p.origin[:3, 3]
            try:
                hulls[name].append(Piece.of(pts))
            except Exception:
                pass
    depths = containment_depths(model, hulls, state)
    worst = max(depths.items(), key=lambda kv: kv[1], default=(("", ""), 0.0))
    row["contain_mm"] = round(worst[1] * 1000, 2)
    row["contain_pair"] = "/".join(worst[0])
    # the same pairs as an engine that collides them sees them: the hulls' penetration depth
    # (separating axes), PyBullet's and MuJoCo's closest points with the margins removed
    sat = parent_child_depths(model, hulls, state)
    row["pc_sat_mm"] = round(max(sat.values(), default=0.0) * 1000, 2)
    for e in ("pybullet", "mujoco"):
        m = parent_child_penetration(UrdfFile(urdf_path), state, e)
        row[f"pc_{e}_mm"] = round(m.value, 2)
        if e == "pybullet":
            row["pc_pairs"] = m.details["pairs"]


def _mjcf_checks(f: Path, state: dict, row: dict, convert: bool) -> bool:
    """Into ``row``: the MJCF's 5 cm drop (:func:`drop_test`; the ``mjcf/`` file, or the URDF converted in memory
    with ``convert`` or without one). False when the conversion failed (``row["mjcf"]`` says why)."""
    from asset2sim.engines.base import SessionOptions
    from asset2sim.engines.mjcf import urdf_to_mjcf
    from asset2sim.refined_asset import springs_from_overlay
    from asset2sim.refined_asset import read_root

    urdf_path = f / "mobility.urdf"
    xml = f / "mjcf" / "mobility.xml"
    build = None
    if convert or not xml.is_file():
        try:
            with tempfile.TemporaryDirectory():
                fixed = read_root(f).fixed  # a mounted asset converts as export_mjcf writes it: no free joint
                build = urdf_to_mjcf(urdf_path, SessionOptions(initial_state=state, springs=springs_from_overlay(f, state),
                                                               fixed_base=fixed, ground=not fixed), visuals=True)
            xml = None
        except Exception as exc:
            row["mjcf"] = f"convert failed: {str(exc)[:120]}"
            return False
    drop = drop_test(xml, build)
    row["mjcf_compiles"] = drop["compiles"]
    row["drop_max_contacts"] = drop["max_contacts"]
    row["drop_warnings"] = ",".join(drop["warnings"])
    row["drop_error"] = drop["error"]
    row["arena_used_pct"] = round(100.0 * drop.get("arena_max_used_bytes", 0) / max(drop.get("arena_bytes", 0), 1), 2) if drop["compiles"] else None
    row["root_free"] = drop.get("free")
    row["drop_lowest_mm"] = None if drop["lowest_m"] is None or not math.isfinite(drop["lowest_m"]) else round(drop["lowest_m"] * 1000, 1)
    return True


def _print_counts(rows: list[dict]) -> None:
    """The counts over all output folders."""
    n = len(rows)
    print(f"\n{n} outputs")
    print(f"MuJoCo loads the URDF: {sum(r['urdf_mujoco'] == 'ok' for r in rows)}/{n}")
    print(f"MJCF compiles: {sum(bool(r.get('mjcf_compiles')) for r in rows)}/{n}")
    print(f"5 cm drop without MuJoCo warnings or errors: {sum(r.get('mjcf_compiles') and not r['drop_warnings'] and not r['drop_error'] for r in rows)}/{n}")
    print(f"drop max contacts: max {max((r.get('drop_max_contacts', 0) for r in rows), default=0)}; "
          f"largest share of MuJoCo's default arena used: {max((r.get('arena_used_pct') or 0 for r in rows), default=0)} %; "
          f"lowest point after the drop (free roots): min {min((r['drop_lowest_mm'] for r in rows if r.get('root_free') and r.get('drop_lowest_mm') is not None), default=None)} mm "
          f"(below about -5 mm: fell into the floor); fixed roots (mounted, not dropped): {sum(r.get('root_free') is False for r in rows)}")
    print(f"flat collision groups: {sum(r['flat_groups'] for r in rows)}; inside-out collision files: {sum(r['inside_out'] for r in rows)}")
    print(f"max pieces per link: {max((r['max_pieces_per_link'] for r in rows), default=0)}")
    print(f"parts > 2 mm inside the parent's hull: {sum(r['contain_mm'] > 2 for r in rows)}/{n} (max {max((r['contain_mm'] for r in rows), default=0)} mm)")
    for key, what in (("pc_sat_mm", "hull penetration depth (separating axes)"), ("pc_pybullet_mm", "PyBullet closest points - 2 mm margins"),
                      ("pc_mujoco_mm", "MuJoCo mj_geomDistance")):
        print(f"child penetrating its parent > 2 mm, pair collided, {what}: {sum(r[key] > 2 for r in rows)}/{n} "
              f"(max {max((r[key] for r in rows), default=0)} mm)")
    print(f"fixed joints with an incomplete <limit>: {sum(r['fixed_limit_incomplete'] for r in rows)}")
    ms = [r["min_link_mass_g"] for r in rows if r["min_link_mass_g"] is not None]
    print(f"lightest link: {min(ms) if ms else None} g")


if __name__ == "__main__":
    sys.exit(main())
