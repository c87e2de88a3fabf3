"""How often each in-process cache of the package answers: every module-level ``cachetools`` cache and
:class:`asset2sim.file_memo.FileMemo` counted over refines of the dev rows in one process, as a flow worker
refines asset after asset.

    .venv/bin/python benchmarks/cache_hits.py [--ids 102990 9912 ...] [--media] [--out DIR]

Each row is refined twice (its own request, then "A <category>."), with an empty on-disk cache of its own
(``ASSET2SIM_CACHE`` under ``--out``), extras on and media off unless ``--media``. Prints each refine's verdict,
then one line per cache: lookups answered (hits) and not (misses). A cache no lookup hits is work for nothing.
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # as the flow's workers (asset2sim.cli), before numpy

import argparse  # noqa: E402
import collections  # noqa: E402
import csv  # noqa: E402
import importlib  # noqa: E402
import pkgutil  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
DEV = ROOT.parent / "shared" / "datasets" / "partnet_mobility"


def count_lookups(packages) -> dict[str, list[int]]:
    """Wrap every module-level cache of ``packages`` (imported first) to count its lookups; returns
    name -> [hits, misses], filled as the caches are used."""
    import cachetools

    from asset2sim import file_memo

    for pkg in packages:
        for m in pkgutil.walk_packages(pkg.__path__, pkg.__name__ + "."):
            if m.name.endswith("__main__"):
                continue
            try:
                importlib.import_module(m.name)
            except ImportError:  # an optional extra not installed (e.g. asset2sim.apps.learn.maniskill without torch)
                continue
    stats: dict[str, list[int]] = collections.defaultdict(lambda: [0, 0])

    def counted_cache(obj, name: str) -> None:
        base = type(obj)

        class Counted(base):
            def __getitem__(self, key):
                try:
                    value = base.__getitem__(self, key)
                except KeyError:
                    stats[name][1] += 1
                    raise
                stats[name][0] += 1
                return value

            def __contains__(self, key):  # a miss when absent; when present, the read that follows is the hit
                found = base.__contains__(self, key)
                if not found:
                    stats[name][1] += 1
                return found

            def get(self, key, default=None):
                if base.__contains__(self, key):
                    stats[name][0] += 1
                    return base.__getitem__(self, key)
                stats[name][1] += 1
                return default

        obj.__class__ = Counted

    def counted_memo(obj, name: str) -> None:
        get = obj.get

        def wrapper(key):
            value = get(key)
            stats[name][0 if value is not None else 1] += 1
            return value

        obj.get = wrapper

    for modname, mod in list(sys.modules.items()):
        if not any(modname == p.__name__ or modname.startswith(p.__name__ + ".") for p in packages):
            continue
        for attr, obj in list(vars(mod).items()):
            if isinstance(obj, cachetools.Cache):
                counted_cache(obj, f"{modname}.{attr}")
            elif isinstance(obj, file_memo.FileMemo):
                counted_memo(obj, f"{modname}.{attr}")
    return stats


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--ids", nargs="*", default=None, help="dev row ids (default: every row)")
    ap.add_argument("--media", action="store_true", help="make the renders, clips and report.html too")
    ap.add_argument("--out", type=Path, default=None, help="work folder (default: a temporary one)")
    args = ap.parse_args(argv)
    out = args.out or Path(tempfile.mkdtemp(prefix="a2s-cache-hits-"))
    os.environ.setdefault("ASSET2SIM_CACHE", str(out / "cache"))

    import asset2sim
    from asset2sim.tasks.refine import refine_asset

    stats = count_lookups([asset2sim])
    with open(DEV / "manifest.csv", newline="") as fh:
        rows = [r for r in csv.DictReader(fh) if args.ids is None or r["id"] in args.ids]
    t = time.perf_counter()
    for r in rows:
        for k, prompt in enumerate((r["prompt"], f"A {r['category'].lower()}.")):
            res = refine_asset(DEV / r["id"], prompt, out / f"{r['id']}_{k}", category=r["category"], media=args.media,
                               skip_if_complete=False, overwrite=True)
            print(f"{r['id']:>8} {res.report.failure_mode:<22} {prompt}", flush=True)
    print(f"{2 * len(rows)} refines in {time.perf_counter() - t:.0f} s")
    for name, (hits, misses) in sorted(stats.items(), key=lambda kv: -kv[1][0]):
        print(f"{hits:9d} hits {misses:9d} misses  {name}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
