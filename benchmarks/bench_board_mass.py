"""Shell mass on the dev rows: for every link of a shell material (``materials.yaml`` ``shell: true``), the link's raw
mass (before the category's total-mass range) under the rule the code uses (a board's part, ``panel: true``, over half
its mesh's area: each sheet drawn with both faces) and under each face counted (A s^2 t) or half of it for every shell,
at the scale and material of a kept refine of the row.

    python benchmarks/bench_board_mass.py [--kept /tmp/s12/keepA] [--ids 19179,20279]

Prints one line per link whose mass either rule changes and the count of rows and links each rule moves.
"""

from __future__ import annotations

import argparse
import json
from dataclasses import replace
from pathlib import Path

from asset2sim.prior_tables import load_priors
from asset2sim.tasks.geometry.analyze import analyze_asset
from asset2sim.tasks.ingest.extract import extract_asset
from asset2sim.tasks.synthesize import physics

DEV = Path(__file__).resolve().parents[2] / "shared" / "datasets" / "partnet_mobility"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--kept", type=Path, default=Path("/tmp/s12/keepA"), help="refined outputs, one folder per row id")
    ap.add_argument("--ids", default="", help="comma-separated subset of row ids")
    args = ap.parse_args()
    mats = {m.name: physics.material_choice(m) for m in load_priors().materials.values()}
    ids = [i for i in args.ids.split(",") if i] or sorted(p.name for p in args.kept.iterdir() if (p / "overlay.json").is_file())
    moved: dict[str, set[str]] = {"boards (the code)": set(), "every shell": set()}
    links = {k: 0 for k in moved}
    for rid in ids:
        ov = json.loads((args.kept / rid / "overlay.json").read_text())
        s = ov["scale"]
        geo = analyze_asset(extract_asset(DEV / rid))
        for ln, lp in ov["links"].items():
            mat, g = mats.get(lp["material"]), geo.get(ln)
            if g is None or mat is None or not mat.shell:
                continue
            both = physics.link_physics(g, s, replace(mat, panel=False)).mass
            rules = {"boards (the code)": physics.link_physics(g, s, mat).mass,
                     "every shell": physics.link_physics(g, s, replace(mat, panel=True)).mass}
            wall = 2 * g.volume / g.area * s if g.volume > 0 else 0.0
            for k, m in rules.items():
                if abs(m / both - 1) > 1e-9:
                    moved[k].add(rid)
                    links[k] += 1
            if any(abs(m / both - 1) > 1e-9 for m in rules.values()):
                print(f"{rid:>7} {ln:<7} {mat.name[:28]:<28} t {mat.wall_thickness * 1e3:5.2g} mm, drawn {wall * 1e3:6.3g} mm: "
                      f"both faces {both:8.4g} kg; " + "; ".join(f"{k} x{m / both:.3f}" for k, m in rules.items()))
    for k in moved:
        print(f"{k}: {len(moved[k])} of {len(ids)} rows, {links[k]} links change: {sorted(moved[k])}")


if __name__ == "__main__":
    main()
