"""Count the solver aids a set of refined outputs declares: every ``solver_aids`` entry of each output's
``report.json`` (kind, element: the joint or geom it was written to, and the criterion that needed it), per kind and
per output.

    .venv/bin/python benchmarks/solver_aids.py ROOT [--list]

``ROOT`` holds one refined output folder per asset (``ROOT/<id>/report.json``; e.g. the ``--keep`` folder of
``bench_determinism.py``). Prints the count per kind, the outputs with none, and with ``--list`` each output's aids as
``kind:element``. Exit status 1 when no ``report.json`` is found.
"""

from __future__ import annotations

import argparse
import collections
import json
import sys
from pathlib import Path


def aids_of(report: object) -> list[dict]:
    """Every ``solver_aids`` entry anywhere in a report record (one list per engine or export that declares some)."""
    found: list[dict] = []
    if isinstance(report, dict):
        for key, value in report.items():
            found.extend(value if key == "solver_aids" and isinstance(value, list) else aids_of(value))
    elif isinstance(report, list):
        for item in report:
            found.extend(aids_of(item))
    return found


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("root", type=Path)
    ap.add_argument("--list", action="store_true", help="print each output's aids")
    args = ap.parse_args(argv)
    reports = sorted(args.root.glob("*/report.json"))
    if not reports:
        print(f"no */report.json under {args.root}", file=sys.stderr)
        return 1
    kinds: collections.Counter[str] = collections.Counter()
    none: list[str] = []
    for path in reports:
        aids = aids_of(json.loads(path.read_text()))
        kinds.update(a.get("kind", "?") for a in aids)
        if not aids:
            none.append(path.parent.name)
        if args.list:
            print(f"{path.parent.name}: " + (", ".join(f"{a.get('kind')}:{a.get('element')}" for a in aids) or "none"))
    print(f"{len(reports)} outputs; aids per kind: " + ", ".join(f"{k} {n}" for k, n in kinds.most_common()))
    print(f"outputs with none: {len(none)} ({', '.join(none)})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
