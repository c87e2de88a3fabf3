"""Third-party objects as their packages ship them, refined: robosuite's and Meta-World's articulated object files
(unpacked from their wheels; neither package needs to be importable), each with several requests, and the audit
of each refined object's MJCF. Prints per object and request: the verdict, the scale (1 keeps the package's size),
the joint's range in the unit the package compiles it in, the state, the operating effort against its range, the
springs and catches the estimate chose, and whether the host file (and the package's own file holding the object)
was written back.

    pip download robosuite==1.5.2 metaworld==3.1.1 --no-deps -d /tmp/pk
    python -m zipfile -e /tmp/pk/robosuite-1.5.2-py3-none-any.whl /tmp/pk/rs
    python -m zipfile -e /tmp/pk/metaworld-3.1.1-py3-none-any.whl /tmp/pk/mw
    python benchmarks/bench_host_packages.py --robosuite /tmp/pk/rs/robosuite --metaworld /tmp/pk/mw/metaworld [--out DIR]

Writes DIR/cases.json.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))

from bench_operability import guarded  # noqa: E402

#: (package, file under the package's asset folder, requests): the articulated objects of robosuite 1.5.2
#: (``models/assets``) and Meta-World 3.1.1 (``assets``) that their tasks open, close, turn or pull.
OBJECTS = [
    ("robosuite", "objects/door.xml", ["A door.", "A door, slightly open."]),
    ("metaworld", "objects/drawer.xml", ["A drawer.", "A drawer, slightly open."]),
    ("metaworld", "objects/faucet.xml", ["A faucet.", "A faucet, turned halfway."]),
    ("metaworld", "objects/lever.xml", ["A lever.", "A lever, halfway up."]),
    ("metaworld", "objects/coffeemachine.xml", ["A coffee machine."]),
    ("metaworld", "objects/doorlockA.xml", ["A door lock.", "A door lock, halfway turned."]),
    ("metaworld", "objects/window.xml", ["A window.", "A window, slightly open.", "A window, halfway open."]),
    ("metaworld", "objects/window_horiz.xml", ["A window.", "A window, halfway open."]),
]
ASSETS = {"robosuite": Path("models") / "assets", "metaworld": Path("assets")}


def _refine(res: dict, xml: Path, out: Path) -> None:
    from asset2sim.apps.audit.batch import audit_one, find_assets
    from asset2sim.schemas.config import RefineConfig
    from asset2sim.tasks.refine import refine_asset
    from asset2sim.urdf import read_urdf

    r = refine_asset(xml, res["request"], out, RefineConfig(), extras=True, media=False, overwrite=True)
    report = r.report
    res["mode"] = report.failure_mode
    res["scale"] = r.overlay.scale
    model = read_urdf(r.out_dir / "mobility.urdf")
    joints = {}
    efforts = (report.metric("operability").details or {}).get("efforts", {}) if report.metric("operability") else {}
    for j in model.movable_joints:
        dyn = r.overlay.joints.get(j.name)
        e = efforts.get(j.name, {})
        joints[j.name] = {
            "type": j.type, "range": [j.limit.lower, j.limit.upper] if j.limit else None,
            "state": report.initial_joint_positions.get(j.name), "friction": j.dynamics.friction if j.dynamics else None,
            "stiffness": dyn.stiffness if dyn else 0.0, "spring_reference": dyn.spring_reference if dyn else None,
            "mechanism": dyn.holding.mechanism if dyn is not None and dyn.holding is not None else "-",
            "peak_force_n": e.get("peak_force_n"), "peak_torque_nm": e.get("peak_torque_nm"), "range_n": e.get("range"),
        }
    res["joints"] = joints
    host = r.out_dir / "mjcf" / "host"
    res["host_file"] = any(host.glob("*.xml"))
    res["package_files"] = sorted(p.relative_to(host / "files").as_posix() for p in (host / "files").rglob("*.xml")) \
        if (host / "files").is_dir() else []
    (target,) = find_assets([r.out_dir / "mjcf" / "mobility.xml"])
    row = audit_one(target, out.parent / f"{out.name}-audit", simulate=False)
    res["audit"] = row.failure_mode
    res["audit_implausible"] = list(row.implausible)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--robosuite", type=Path, help="robosuite's package folder (holding models/assets)")
    ap.add_argument("--metaworld", type=Path, help="Meta-World's package folder (holding assets)")
    ap.add_argument("--out", type=Path, default=None, help="where the outputs go (default: a temporary folder)")
    args = ap.parse_args(argv)
    packages = {"robosuite": args.robosuite, "metaworld": args.metaworld}
    if not any(packages.values()):
        ap.error("name at least one package folder (--robosuite, --metaworld)")
    work = args.out or Path(tempfile.mkdtemp(prefix="bench-host-"))
    cases = []
    for package, rel, requests in OBJECTS:
        if packages[package] is None:
            continue
        xml = packages[package] / ASSETS[package] / rel
        for i, request in enumerate(requests):
            case = {"package": package, "file": rel, "request": request}
            out = work / package / f"{Path(rel).stem}-{i}"
            cases.append(guarded(case, lambda res, xml=xml, out=out: _refine(res, xml, out)))
            c = cases[-1]
            parts = []
            for name, j in (c.get("joints") or {}).items():
                unit = "m" if j["type"] == "prismatic" else "rad"
                effort = (f"{j['peak_force_n']:.1f} N" if j.get("peak_force_n") is not None else "-")
                rng = j.get("range") or [None, None]
                parts.append(f"{name} [{rng[0]:.4g}, {rng[1]:.4g}] {unit} at {j['state']:.4g}, friction {j['friction']:.3g}, "
                             f"{j['mechanism']}, effort {effort}" if rng[0] is not None else f"{name}: {j['mechanism']}")
            print(f"{package:9s} {rel:26s} {request!r:30s} {c.get('mode', '?'):22s} s={c.get('scale', float('nan')):.3g} "
                  f"host {'yes' if c.get('host_file') else 'no'} files {c.get('package_files') or '-'} "
                  f"audit {c.get('audit', '-')} {c.get('audit_implausible') or ''} | " + "; ".join(parts)
                  + (f" | {c['error']}" if c.get("error") else ""), flush=True)
    ready = sum(c.get("mode") == "none" for c in cases)
    kept = sum(c.get("scale") == 1.0 for c in cases)
    print(f"interaction-ready: {ready} of {len(cases)} (objects: {len({c['file'] for c in cases if c.get('mode') == 'none'})} "
          f"of {len({c['file'] for c in cases})}); size kept (s = 1): {kept} of {len(cases)}; "
          f"audit 'none' on the refined MJCF: {sum(c.get('audit') == 'none' for c in cases)} of {len(cases)}")
    (work / "cases.json").write_text(json.dumps(cases, indent=1, default=str))
    print(f"cases: {work / 'cases.json'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
