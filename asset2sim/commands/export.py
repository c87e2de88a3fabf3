"""``asset2sim export OUT --format mjcf|usd``: write ``OUT/mjcf/mobility.xml``
or ``OUT/usd/mobility.usd``, read it back and check it against the folder's
files; ``--parity ENGINES`` also runs the physical checks in those engines.
Exit status: 0 checked (and parity passes), 1 a check or parity verdict
fails, 2 the folder cannot be exported, 4 the output cannot be written.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from asset2sim.commands._status import INVALID_REQUEST, CommandError, parse_engines
from asset2sim.engines.registry import available_engines
from asset2sim.refined_asset import RefinedAsset
from asset2sim.tasks.check.parity import evaluate_engines, parity_table
from asset2sim import output_folder
from asset2sim.formats import FORMATS
from asset2sim.formats.mjcf.export import check_mjcf, export_mjcf
from asset2sim.formats.usd.check import check_usd
from asset2sim.formats.usd.export import export_usd
from asset2sim.output_folder import URDF_NAME

NAME = "export"
HELP = "Export an output folder for other simulators (MJCF for MuJoCo, USD for Isaac Sim and Newton), optionally checking parity across engines."

#: This command's exit statuses (``--help`` lists them with those of every command: 2 usage, 70, 130).
EXITS = {
    0: "checked (and parity passes)",
    1: "a check or parity verdict fails",
    2: "the folder cannot be exported",
    4: "the output cannot be written",
}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("out", type=Path, help="output folder (mobility.urdf, initial_state.json, overlay.json)")
    parser.add_argument("--format", "-f", choices=FORMATS, default="mjcf", help="export format (default: mjcf)")
    parser.add_argument("--no-visuals", action="store_true", help="collision geometry only (no visual meshes)")
    parser.add_argument("--parity", metavar="ENGINES", help=(
        "also run the physical checks (penetration, rest stability, oscillation) in these engines, e.g. pybullet,physx,mujoco"))


def _fmt(v, spec: str = ".3g") -> str:
    if v is None:
        return "-"
    if isinstance(v, bool):
        return "pass" if v else "FAIL"
    return format(v, spec)


def run(args: argparse.Namespace) -> int:
    out = args.out
    parity = parse_engines(args.parity, "--parity") if args.parity else []
    if not (out / URDF_NAME).is_file():
        raise CommandError(INVALID_REQUEST, "NOT_AN_OUTPUT_FOLDER", out, "has no mobility.urdf (not an output folder)")
    asset = RefinedAsset(out)
    if args.format == "usd":  # write OUT/usd/mobility.usd, read it back and print the check
        with output_folder.adopting(out):
            build = export_usd(asset, visuals=not args.no_visuals, check=False)
        check = check_usd(build.path, asset)
        print(f"wrote       {build.path}")
        print(f"read back   {check.links} links, {check.joints} movable joints; largest relative difference "
              f"{check.max_rel_error:.1e} (binary32 attributes)")
        print(f"root        {'fixed (root_joint to the world)' if build.fixed_root else 'free'}")
        for note in build.notes[:5]:
            print(f"note        {note}")
        return 0
    if "mujoco" not in available_engines():
        raise CommandError.invalid("ENGINE_UNAVAILABLE",
                                   "MuJoCo is not installed; install the extra: pip install 'asset2sim[mujoco]'")

    with output_folder.adopting(out):  # the MJCF files become the output folder's own
        path = export_mjcf(asset, visuals=not args.no_visuals, check=False)
    check = check_mjcf(path, asset.urdf_path, asset.initial_state, fixed_base=asset.root.fixed)
    print(f"wrote       {path}")
    print(f"total mass  {check.total_mass:.6g} kg (URDF {check.urdf_mass:.6g} kg)")
    print(f"inertials   largest COM difference {check.max_com_error:.1e} m, tensor {check.max_inertia_error:.1e} kg*m^2")
    state = ", ".join(f"{k}={v:.4g}" for k, v in check.keyframe.items()) or "(no movable joints)"
    print(f"keyframe    'initial': {state}")
    status = 0
    if parity:
        rows = parity_table(evaluate_engines(out, parity))
        print()
        print(f"{'engine':<10} {'pen. mm':>9} {'deepest mm':>10} {'rest':>5} {'D_pos m':>9} {'D_ori rad':>9} {'osc':>5}  notes")
        for r in rows:
            if r["status"] != "ok":
                print(f"{r['engine']:<10} {r['status']}: {r['reason']}")
                if r["status"] == "error":
                    status = 1
                continue
            notes = "; ".join(r["engine_notes"][:2]) + (" ..." if len(r["engine_notes"]) > 2 else "")
            fail = f" ({', '.join(r['failing_joints'])})" if r["failing_joints"] else ""
            print(f"{r['engine']:<10} {_fmt(r['penetration_mm'], '.3f'):>9} {_fmt(r['max_depth_mm'], '.3f'):>10} "
                  f"{_fmt(r['rest_stability']):>5} {_fmt(r['D_pos_m'], '.1e'):>9} {_fmt(r['D_ori_rad'], '.1e'):>9} "
                  f"{_fmt(r['oscillation']):>5}{fail}  {notes}")
            if r["rest_stability"] is False or r["oscillation"] is False:
                status = 1
    return status

