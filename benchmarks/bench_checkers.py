"""Third-party checkers over refined output folders: urdf_parser_py (ROS),
urdf-validator, Drake (parse, finalize, spatial inertias valid, damping held)
and mjcf-doctor (on mjcf/mobility.xml); simcheck when named (``--checkers
simcheck``: it simulates, minutes an object). Prints one row per object and the
counts; opt-in (extra ``checkers``: ``pip install 'asset2sim[checkers]'``, Drake
about 170 MB).

    python benchmarks/bench_checkers.py OUTPUT_ROOT [--ids 9912,7236] [--checkers drake,mjcf-doctor]

Folders without ``mjcf/mobility.xml`` are exported first (``export_mjcf``).
Writes OUTPUT_ROOT/checkers.json.
"""

from __future__ import annotations

import argparse
import json
import sys
from dataclasses import asdict
from pathlib import Path


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("root", type=Path)
    ap.add_argument("--ids", default="")
    ap.add_argument("--checkers", default="")
    args = ap.parse_args(argv)

    from asset2sim.engines.quiet import quiet_stdout
    from asset2sim.tasks.check.third_party import CHECKERS, MJCF_PATH, OPT_IN, run_checkers
    from asset2sim.formats.mjcf.export import export_mjcf

    names = args.checkers.split(",") if args.checkers else [n for n in CHECKERS if n not in OPT_IN]
    folders = sorted(p.parent for p in args.root.glob("*/mobility.urdf"))
    if args.ids:
        keep = set(args.ids.split(","))
        folders = [f for f in folders if f.name in keep]
    counts = {n: {"ran": 0, "clean": 0, "errors": 0, "warnings": 0, "codes": {}} for n in names}
    out = []
    for f in folders:
        if "mjcf-doctor" in names and not (f / MJCF_PATH).is_file():
            try:
                with quiet_stdout():
                    export_mjcf(f)
            except Exception as exc:  # reported by the checker as a missing file
                print(f"{f.name:>7} MJCF export failed: {exc}", flush=True)
        res = run_checkers(f, names)
        cells, row = [], {"id": f.name}
        for n in names:
            r = res[n]
            if isinstance(r, str):
                cells.append(f"{n}: {r[:60]}")
                row[n] = r
                continue
            c = counts[n]
            c["ran"] += 1
            c["clean"] += r.passed
            c["errors"] += len(r.errors)
            c["warnings"] += len(r.warnings)
            for w in r.errors + r.warnings:
                key = w.split(":")[0][:60] if n != "drake" else ("joint friction not supported" if "friction" in w else w[:60])
                c["codes"][key] = c["codes"].get(key, 0) + 1
            cells.append(f"{n}: {len(r.errors)}E {len(r.warnings)}W")
            row[n] = asdict(r)
        print(f"{f.name:>7}  " + "  ".join(cells), flush=True)
        for n in names:
            r = res[n]
            if not isinstance(r, str):
                for e in r.errors:
                    print(f"          {n} ERROR {e[:200]}", flush=True)
        out.append(row)
    print()
    print("checker          ran  clean (no errors)  errors  warnings")
    for n, c in counts.items():
        print(f"{n:<15} {c['ran']:>4} {c['clean']:>8}/{len(folders):<8} {c['errors']:>6} {c['warnings']:>9}")
        for k, v in sorted(c["codes"].items(), key=lambda kv: -kv[1]):
            print(f"{'':<17}{v:>4} x {k}")
    (args.root / "checkers.json").write_text(json.dumps(out, indent=1, default=str))
    return 0


if __name__ == "__main__":
    sys.exit(main())
