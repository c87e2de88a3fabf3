"""The audit on planted errors and on asset trees: how many planted errors are flagged, how many correct values
are, and what an audit of a package's asset tree finds, with the time it takes.

    python benchmarks/bench_audit.py                       # the planted MJCF folder (tests/planted_assets.py)
    python benchmarks/bench_audit.py --tree PATH [--no-sim] # also a package's asset tree (robosuite's objects ...)

Prints, per planted object, the values flagged and whether each is the planted one; then, per tree, the failure
modes per category and the implausible values per quantity, from the audit catalog.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _planted(work: Path, simulate: bool) -> tuple[int, int, int]:
    sys.path.insert(0, str(ROOT))
    from asset2sim.apps.audit.batch import audit_one, find_assets
    from tests.planted_assets import cabinet, storage_box, trash_can, write_mjcf, write_planted_folder

    inputs = work / "planted"
    expected = write_planted_folder(inputs)
    for name, part, file in (("correct_box", storage_box(), "storage_box"), ("correct_cabinet", cabinet(), "cabinet"),
                             ("correct_trash_can", trash_can(), "trash_can")):
        write_mjcf(inputs / name, file, part)
    t0 = time.perf_counter()
    rows = {r.asset_id: r for r in (audit_one(t, work / "planted-audit", simulate=simulate) for t in find_assets([inputs]))}
    seconds = time.perf_counter() - t0
    caught = wrong = 0
    for name, row in sorted(rows.items()):
        planted = expected.get(name)
        flagged = list(row.implausible)
        hit = planted is not None and f"{planted[0]}: {planted[1]}" in flagged
        extra = [f for f in flagged if planted is None or not (f.startswith(planted[0] + ":") or (f == "object: mass" and planted[1] == "mass"))]
        caught += hit
        wrong += len(extra)
        print(f"{name:26s} planted: {planted[2] if planted else '-':44s} caught: {'yes' if hit else ('-' if planted is None else 'NO')}"
              f"  other flags: {extra or '-'}  declared checks: {'pass' if row.declared_passed else row.declared_failures or '-'}")
    print(f"planted errors caught: {caught} of {len(expected)}; correct values flagged: {wrong}; "
          f"{len(rows)} assets in {seconds:.1f} s ({'with' if simulate else 'without'} simulation)")
    return caught, len(expected), wrong


def _tree(path: Path, work: Path, simulate: bool) -> None:
    import pandas as pd

    from asset2sim.flows import audit_catalog
    from asset2sim.apps.audit.batch import audit_one, find_assets

    out = work / "tree-audit"
    t0 = time.perf_counter()
    targets = find_assets([path])
    rows = [audit_one(t, out, simulate=simulate) for t in targets]
    seconds = time.perf_counter() - t0
    files = audit_catalog.write_audit_catalog(out, rows)
    assets, values = pd.read_parquet(files["assets"]), pd.read_parquet(files["values"])
    print(f"\n{path}: {len(rows)} assets in {seconds:.1f} s")
    print(audit_catalog.failure_modes_by_category(assets).to_string())
    bad = audit_catalog.implausible_by_category(values)
    print(bad.to_string() if not bad.empty else "no implausible values")
    for r in rows:
        print(f"  {r.asset_id:40s} {r.failure_mode:24s} {'; '.join(r.implausible) or r.error[:120]}")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--tree", type=Path, action="append", default=[], help="a package's asset tree to audit (repeatable)")
    ap.add_argument("--no-sim", action="store_true", help="skip the simulation checks")
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="bench-audit-") as tmp:
        caught, planted, wrong = _planted(Path(tmp), not args.no_sim)
        for tree in args.tree:
            _tree(tree, Path(tmp) / tree.name, not args.no_sim)
    return 0 if caught == planted and wrong == 0 else 1


if __name__ == "__main__":
    sys.exit(main())
