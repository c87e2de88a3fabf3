"""Generalization benchmark: every dev object x a set of requests per
category, plus generated assets; prints the pass rate per category and per
request kind, and the failures by mode.

    python benchmarks/bench_generalization.py [--manifest PATH] [--out DIR]
        [--limit N] [--jobs J] [--ids 148,9748] [--kinds plain,state,size,sized,hinge,closed,open,mount,motion]
        [--no-generated] [--evaluate] [--one-mesh-per-link] [--open-containers] [--against OLD/cases.json]

Corpus: for every manifest object (its category from the
manifest), the requests

- ``plain``:  "A <noun>."
- ``state``:  "A <noun>, <state>." for each state word (closed, slightly open,
  a quarter open, halfway open, mostly open, fully open);
- ``size``:   "A <size> <noun>." for each size word (tiny, very small, small,
  large, very large);
- ``sized``:  a size and a state together, as the manifest's requests ask them: "A <size> <noun>, <state>." for
  very small and large, slightly and halfway open;
- ``hinge``:  "A <noun> with its <part> fully open." for every movable joint's
  part label (``semantics.txt``), once per distinct label;
- ``closed``: "A <noun> with everything closed.";
- ``open``:   "A <noun>, open." (a lone "open": ``mostly``, or resting on its open stop where the part's weight
  carries it open, a drop-down door);
- ``mount``:  "A free-standing <noun>." / "A <noun> mounted on the wall."
  (the mounting override);
- ``motion``: words about how the first task part moves, as people write them: "A <noun> whose <part> swings
  (slides) freely.", "A <noun> with a stiff <part>.", "A <noun> with its <part> half open; the <part> is stiff.",
  "A <noun> whose <part> closes slowly and softly.", "A <noun> with a loose <part>, mostly open." (a loose part
  where its weight turns it: a conflict the as-asked tier names), "A <noun> whose <part> swings (slides) shut on its
  own." and "A <noun> with its <part> half open; the <part> closes by itself." (a closer that shuts the part from the
  state asked: a conflict the as-asked tier names);

and the same kinds on the generated assets (the demo objects of
``asset2sim.demo_assets`` and the failure-mode assets of
``tests/tasks/check/failure_assets.py``: a tall faucet, a laptop whose open
screen tips it, a box whose latch penetrates every closed state; and the
assets of ``tests/unseen_assets.py`` in categories the dev set lacks: a wall
switch, a cart on wheels, a sliding window, pliers, a safe with a dial, a
toaster with a lever and a dial, a capped bottle, a desk with a drawer, a
range oven with a drop-down door, a pot with a lid, a front-loading washing
machine, folding glasses, a swivel USB stick, a kettle, a double-door
cabinet, a wardrobe with two doors over two drawers, a bucket, a pump
dispenser, a desk lamp, a desk fan and a printer with a paper tray; reported as
"(generated, unseen)" per category). <noun> is
the category's first request synonym (``asset2sim/priors/categories.yaml``).

A case passes when ``refine_asset`` reports ``failure_mode == "none"`` (every
post-check: penetration, rest stability, oscillation, state hold), every
requested band's joint is written inside its band (``BAND_INTERVAL`` +-
:data:`BAND_SLACK`) or a design note names the joint and says why (a part
the floor stops, a steadier opening; else ``state_out_of_band``) and, with
``--evaluate``, the evaluation (the interaction tier: probes included) lists
no failures. Cases run in ``--jobs`` worker processes (default 1); ``--limit``
keeps the first N cases (in a deterministic, category-interleaved order so a
small limit still spans categories). ``--one-mesh-per-link`` refines every
object, dev rows and generated, from a copy with each link's meshes merged
into one OBJ of one group (``tests.unseen_assets.one_mesh_per_link``), so
that no convex piece comes for free from a part's own files or the
generator's boxes.
``--open-containers`` refines with ``RefineConfig(open_containers=True)``
and prints the cases whose container was kept open.
Writes DIR/cases.json. ``--against OLD/cases.json`` (a run of the same corpus with other code) then prints every case
whose verdict, joint friction, holding record or source, peak operating force or design, collision and band notes
differ (:func:`compare_cases`; numbers within a relative 1e-9), and how many: a change that should alter no behaviour
shows none.
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import os
import sys
import time
from collections import Counter, defaultdict
from concurrent.futures import ProcessPoolExecutor, as_completed
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_operability import category_lines, guarded, mechanisms  # noqa: E402  (the same case outcome and overlay reading)

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_MANIFEST = ROOT.parent / "shared" / "datasets" / "partnet_mobility" / "manifest.csv"

STATE_WORDS = ["closed", "slightly open", "a quarter open", "halfway open", "mostly open", "fully open"]
SIZE_WORDS = ["tiny", "very small", "small", "large", "very large"]
KINDS = ("plain", "state", "size", "sized", "hinge", "closed", "open", "mount", "motion")


def _noun(category: str) -> str:
    from asset2sim.prior_tables import load_priors

    cats = load_priors().categories
    prior = cats.get(category)
    syn = [s.lstrip("~") for s in (prior.synonyms if prior is not None else [])]
    return syn[0] if syn else category.lower()


def _part_words(src: Path) -> list[str]:
    """Distinct part labels of the movable joints' child links (semantics.txt)."""
    p = src / "semantics.txt"
    if not p.is_file():
        return []
    words = []
    for line in p.read_text().splitlines():
        f = line.split()
        if len(f) >= 3 and f[1] in ("hinge", "slider"):
            w = f[2].replace("rotation_", "").replace("translation_", "").replace("_", " ")
            if w not in words:
                words.append(w)
    return words


def _task_part(category: str, src: Path) -> tuple[str, str] | None:
    """(word, "hinge" or "slider") of the first movable part of semantics.txt whose label has the ``task`` role in
    ``category`` (a lid, a door, a drawer; not a handle, a button or a wheel), or None."""
    from asset2sim.tasks.interpret.part_priors import part_role

    p = src / "semantics.txt"
    for line in (p.read_text().splitlines() if p.is_file() else []):
        f = line.split()
        if len(f) >= 3 and f[1] in ("hinge", "slider") and part_role(category, f[2]) == "task":
            return f[2].replace("rotation_", "").replace("translation_", "").replace("_", " "), f[1]
    return None


def requests_for(category: str, src: Path, kinds: tuple[str, ...] = KINDS) -> list[tuple[str, str]]:
    """(request kind, request text) for one object."""
    n = _noun(category)
    out: list[tuple[str, str]] = []
    if "plain" in kinds:
        out.append(("plain", f"A {n}."))
    if "state" in kinds:
        out += [(f"state:{w}", f"A {n}, {w}.") for w in STATE_WORDS]
    if "size" in kinds:
        out += [(f"size:{w}", f"A {w} {n}.") for w in SIZE_WORDS]
    if "sized" in kinds:
        out += [(f"sized:{z}, {w}", f"A {z} {n}, {w}.") for w in ("slightly open", "halfway open") for z in ("very small", "large")]
    if "hinge" in kinds:
        out += [("hinge:fully open", f"A {n} with its {w} fully open.") for w in _part_words(src)]
    if "closed" in kinds:
        out.append(("everything closed", f"A {n} with everything closed."))
    if "open" in kinds:
        out.append(("open", f"A {n}, open."))
    if "mount" in kinds:
        out += [("mount:free-standing", f"A free-standing {n}."), ("mount:wall", f"A {n} mounted on the wall.")]
    part = _task_part(category, src) if "motion" in kinds else None
    if part is not None:  # words about how the part moves, as people write them
        w, move = part[0], "swings" if part[1] == "hinge" else "slides"
        out += [("motion:free", f"A {n} whose {w} {move} freely."), ("motion:stiff", f"A {n} with a stiff {w}."),
                ("motion:stiff state", f"A {n} with its {w} half open; the {w} is stiff."),
                ("motion:soft close", f"A {n} whose {w} closes slowly and softly."),
                ("motion:loose state", f"A {n} with a loose {w}, mostly open."),
                ("motion:self-closing", f"A {n} whose {w} {'swings' if part[1] == 'hinge' else 'slides'} shut on its own."),
                ("motion:self-closing state", f"A {n} with its {w} half open; the {w} closes by itself.")]
    return out


def build_corpus(manifest: Path, gen_root: Path | None, kinds: tuple[str, ...], ids: set[str],
                 one_mesh_root: Path | None = None) -> list[dict]:
    """Every case: {"case", "source", "asset", "category", "kind", "prompt", "generated"}; with ``one_mesh_root``,
    each object (dev row or generated) as :func:`tests.unseen_assets.one_mesh_per_link` rewrites a copy of it (under
    ``one_mesh_root``; the dev rows' folders are never changed)."""
    per_object: list[list[dict]] = []
    rows = list(csv.DictReader(manifest.open())) if manifest.is_file() else []
    objects = [(r["id"], manifest.parent / r["id"], r["category"], False) for r in rows]
    if gen_root is not None:
        sys.path.insert(0, str(ROOT))
        from asset2sim import demo_assets
        from tests import unseen_assets
        from tests.tasks.check import failure_assets

        demo = demo_assets.ensure_demo_dataset(gen_root / "demo")
        for entry in demo_assets.DEMO_OBJECTS:
            objects.append((f"gen:{entry.asset_id}", demo / entry.asset_id, entry.category, True))
        for name, build, cat in (("tall_faucet", failure_assets.build_tall_faucet, "Faucet"),
                                 ("tipping_laptop", failure_assets.build_tipping_laptop, "Laptop"),
                                 ("interlocked_box", failure_assets.build_interlocked_box, "Box")):
            folder = gen_root / name
            if not (folder / "mobility.urdf").is_file():
                build(folder)
            objects.append((f"gen:{name}", folder, cat, True))
        for name, build, cat in unseen_assets.UNSEEN_BUILDERS:  # categories the dev set lacks (or its shapes)
            folder = gen_root / name
            if not (folder / "mobility.urdf").is_file():
                build(folder)
            objects.append((f"gen:{name}", folder, cat, True))
    if one_mesh_root is not None:
        sys.path.insert(0, str(ROOT))
        from tests import unseen_assets

        objects = [(oid, _one_mesh_copy(src, one_mesh_root / oid.replace(":", "_"), unseen_assets), cat, gen)
                   for oid, src, cat, gen in objects if not ids or oid in ids]
    for oid, src, cat, gen in objects:
        if ids and oid not in ids:
            continue
        cases = []
        for k, (kind, prompt) in enumerate(requests_for(cat, src, kinds)):
            cases.append({"case": f"{oid}#{k}", "asset": oid, "source": str(src), "category": cat, "kind": kind,
                          "prompt": prompt, "generated": gen})
        per_object.append(cases)
    out: list[dict] = []  # interleave objects so that --limit spans categories
    for i in range(max((len(c) for c in per_object), default=0)):
        for cases in per_object:
            if i < len(cases):
                out.append(cases[i])
    return out


def _one_mesh_copy(src: Path, dst: Path, unseen_assets) -> Path:
    """``dst``: a copy of the object ``src`` with one OBJ of one group per link (made once)."""
    import shutil

    if not (dst / "mobility.urdf").is_file():
        shutil.rmtree(dst, ignore_errors=True)
        shutil.copytree(src, dst)
        unseen_assets.one_mesh_per_link(dst)
    return dst


#: Opening fraction (of the range) a written state may lie beyond its band's
#: interval (``BAND_INTERVAL``) and still count as in the band.
BAND_SLACK = 0.02


def out_of_band(report) -> list[tuple[str, str]]:
    """Joints of a refine ``report`` whose written opening fraction lies
    outside their requested band (by more than :data:`BAND_SLACK`), each with
    the design note that says why ("" when none names the joint: the state
    is not what was asked, a failure of its own, ``state_out_of_band``)."""
    from asset2sim.schemas.request import BAND_INTERVAL

    out = []
    for joint, band in (report.requested_bands or {}).items():
        f = (report.opening_fractions or {}).get(joint)
        if f is None or band not in BAND_INTERVAL:
            continue
        lo, hi = BAND_INTERVAL[band]
        if lo - BAND_SLACK <= f <= hi + BAND_SLACK:
            continue
        why = next((d for d in report.design_changes if d.startswith((f"{joint}:", f"{joint} ")) or f" {joint} " in d), "")
        out.append((f"{joint} {band} at {f:.2f}", why))
    return out


def run_case(case: dict, out_root: str, evaluate: bool, open_containers: bool = False) -> dict:
    """Refine one case in this process (``open_containers``: :attr:`RefineConfig.open_containers`); returns the
    case with its outcome (a failure as :func:`bench_operability.guarded` records it)."""
    out = Path(out_root) / case["case"].replace(":", "_").replace("#", "_")
    return guarded(case, lambda res: _measure(res, out, evaluate, open_containers))


def _measure(res: dict, out: Path, evaluate: bool, open_containers: bool) -> None:
    """Refine ``res``'s case into ``out``; its verdict, design notes and operability into ``res``."""
    from asset2sim.schemas.config import RefineConfig
    from asset2sim.tasks.refine import refine_asset

    r = refine_asset(res["source"], res["prompt"], out, RefineConfig(open_containers=open_containers),
                     category=res["category"], skip_if_complete=False, extras=evaluate, overwrite=True).report
    res["mode"] = r.failure_mode
    res["mounted"] = bool(r.mounting is not None and r.mounting.fixed)
    res["design"] = list(r.design_changes)
    res["collision"] = list(r.state.collision_changes) if r.state else []
    res["out_of_band"] = out_of_band(r)
    op = next((m for m in r.metrics if m.name == "operability" and m.engine == "pybullet"), None)
    res["operable"] = None if op is None else op.passed
    res["efforts"] = {} if op is None else dict(op.details.get("efforts") or {})
    res["joints"] = {n: {"friction": d["friction"], "holding": d.get("holding"), "source": d.get("source", "")}
                     for n, d in json.loads((out / "overlay.json").read_text())["joints"].items()}
    res["parts"] = res["efforts"]
    res["mechanisms"] = mechanisms(res)
    if res["mode"] == "none" and any(not why for _, why in res["out_of_band"]):
        res["mode"] = "state_out_of_band"
    if evaluate:
        ev_path = out / "evaluation.json"
        failures = json.loads(ev_path.read_text()).get("failures", []) if ev_path.is_file() else ["no evaluation.json"]
        res["evaluation_failures"] = failures
        if res["mode"] == "none" and failures:
            res["mode"] = "evaluation:" + ",".join(sorted(failures))


def compare_cases(old: list[dict], new: list[dict]) -> list[str]:
    """One line per case of ``new`` (``cases.json`` records) whose outcome differs from the same case of ``old``:
    verdict, each joint's friction (N or N m), holding record and source, each part's peak operating force (N), the
    design, collision and band notes, the error; then a summary line. Cases found on one side only are named too."""
    def same(a, b) -> bool:
        if isinstance(a, (int, float)) and isinstance(b, (int, float)):
            return math.isclose(a, b, rel_tol=1e-9, abs_tol=1e-12)
        return a == b

    before = {c["case"]: c for c in old}
    lines, changed = [], 0
    for c in new:
        o = before.pop(c["case"], None)
        if o is None or o["prompt"] != c["prompt"]:
            lines.append(f"  {c['case']} {c['prompt']!r}: not in the earlier run")
            continue
        diffs = [f"verdict {o['mode']} -> {c['mode']}"] if o["mode"] != c["mode"] else []
        ja, jb = o.get("joints") or {}, c.get("joints") or {}
        diffs += [f"{j}.{k}" for j in sorted(set(ja) | set(jb)) for k in ("friction", "holding", "source")
                  if not same((ja.get(j) or {}).get(k), (jb.get(j) or {}).get(k))]
        ea, eb = o.get("efforts") or {}, c.get("efforts") or {}
        diffs += [f"{j} peak force" for j in sorted(set(ea) | set(eb))
                  if not same((ea.get(j) or {}).get("peak_force_n"), (eb.get(j) or {}).get("peak_force_n"))]
        diffs += [k for k in ("design", "collision", "out_of_band", "error") if o.get(k) != c.get(k)]
        if diffs:
            changed += 1
            lines.append(f"  {c['case']} {c['prompt']!r}: " + ", ".join(diffs))
    lines += [f"  {k}: only in the earlier run" for k in sorted(before)]
    return lines + [f"against the earlier run: {changed} of {len(new)} cases differ, {len(before)} missing"]


def _table(title: str, groups: dict[str, list[dict]]) -> list[str]:
    lines = [f"\n{title}", f"{'':28} {'pass':>6} {'n':>5} {'rate':>7}"]
    for key in sorted(groups):
        g = groups[key]
        ok = sum(1 for c in g if c["mode"] == "none")
        lines.append(f"{key:28} {ok:6d} {len(g):5d} {100.0 * ok / len(g):6.1f}%")
    return lines


def operability_table(results: list[dict]) -> list[str]:
    """Per category: cases interaction-ready with every handled part operable, the parts' peak operating
    forces (N; median and max) against the top of their ranges, and how often each stability mechanism was used."""
    lines = ["\noperability per category (ready = interaction-ready; parts: operable / pushed; forces N)",
             f"{'':28} {'ready':>6} {'n':>5} {'parts':>9} {'median':>7} {'max':>7} {'range top':>10}"]
    groups: dict[str, list[dict]] = defaultdict(list)
    for c in results:
        if c["mode"] != "invalid_input":
            groups[c["category"] + (" (generated)" if c["generated"] else "")].append(c)
    for key in sorted(groups):
        g = groups[key]
        parts = [e for c in g for e in (c.get("efforts") or {}).values()]
        f = sorted(e["peak_force_n"] for e in parts)
        tops = sorted({e["force_range_n"][1] for e in parts if e.get("force_range_n")})
        lines.append(f"{key:28} {sum(1 for c in g if c['mode'] == 'none'):6d} {len(g):5d} "
                     f"{sum(1 for e in parts if e['passed']):4d}/{len(parts):<4d} {f[len(f) // 2] if f else float('nan'):7.2f} "
                     f"{max(f, default=float('nan')):7.2f} {'/'.join(f'{t:g}' for t in tops):>10}")
    ready_bad = [c for c in results if c["mode"] == "none" and c.get("operable") is False]
    lines.append(f"interaction-ready with a part not operable: {len(ready_bad)}")
    used = Counter(m for c in results for m in set(c.get("mechanisms") or []))
    lines.append("stability mechanisms (cases using each): " + (", ".join(f"{m} {n}" for m, n in sorted(used.items())) or "none"))
    lines.append("\nper category: ready, hold margin (friction over the largest static load), operating effort over its range")
    lines += category_lines([c for c in results if c["mode"] != "invalid_input"],
                            lambda c: c["category"] + (" (generated)" if c["generated"] else ""))
    return lines


def report(results: list[dict]) -> str:
    """The printed summary: pass rate overall, per category, per request kind,
    failures by mode and the failing cases. Refused inputs (``invalid_input``)
    are listed but not counted as valid inputs."""
    valid = [c for c in results if c["mode"] != "invalid_input"]
    ok = sum(1 for c in valid if c["mode"] == "none")
    lines = [f"cases {len(results)}, valid {len(valid)}, passed {ok} ({100.0 * ok / max(len(valid), 1):.1f} % of valid inputs)"]
    by_cat, by_kind = defaultdict(list), defaultdict(list)
    seen = {c["category"] for c in results if not c["generated"]}
    for c in valid:
        by_cat[c["category"] + ("" if not c["generated"] else " (generated)" if c["category"] in seen else " (generated, unseen)")].append(c)
        by_kind[c["kind"]].append(c)
    lines += _table("per category", by_cat)
    lines += _table("per request kind", by_kind)
    modes = Counter(c["mode"] for c in results if c["mode"] != "none")
    lines.append("\nfailures by mode")
    for mode, n in modes.most_common():
        lines.append(f"  {mode:40} {n}")
    fails = [c for c in results if c["mode"] != "none"]
    if fails:
        lines.append("\nfailing cases")
        for c in fails:
            lines.append(f"  {c['asset']:>22} {c['category']:>16} {c['mode']:>24}  {c['prompt']!r}" + (f"  {c['error'][:120]}" if c.get("error") else ""))
    changed = [c for c in results if any(d.startswith("stability by design") for d in c.get("design", []))]
    if changed:
        lines.append(f"\nstability by design changed part masses in {len(changed)} cases: "
                     + ", ".join(f"{c['asset']} {c['prompt']!r}" for c in changed[:20]))
    explained = [c for c in results if c.get("out_of_band") and c["mode"] == "none"]
    if explained:
        lines.append(f"\nwritten outside the requested band with a design note saying why, in {len(explained)} passing cases: "
                     + ", ".join(f"{c['asset']} {c['prompt']!r} ({'; '.join(j for j, _ in c['out_of_band'])})" for c in explained[:20]))
    lines += operability_table(results)
    mounted = [c for c in results if c.get("mounted")]
    lines.append(f"mounted (fixed root) in {len(mounted)} of {len(results)} cases")
    opened = [c for c in results if any("holds an open cavity" in n and "convex pieces (CoACD)" in n for n in c.get("collision", []))]
    if opened:
        ok = sum(1 for c in opened if c["mode"] == "none")
        lines.append(f"a container kept open (--open-containers) in {len(opened)} cases, {ok} of them passing: "
                     + ", ".join(sorted({c['asset'] for c in opened})))
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--manifest", type=Path, default=DEFAULT_MANIFEST)
    ap.add_argument("--out", type=Path, default=ROOT / "out" / "bench_generalization")
    ap.add_argument("--limit", type=int, default=0, help="run only the first N cases (0: all)")
    ap.add_argument("--jobs", type=int, default=1, help="worker processes")
    ap.add_argument("--ids", default="", help="comma-separated subset of object ids (generated: gen:<name>)")
    ap.add_argument("--kinds", default=",".join(KINDS), help="request kinds to include")
    ap.add_argument("--no-generated", action="store_true", help="dev objects only")
    ap.add_argument("--evaluate", action="store_true", help="also run the evaluation (extras; probes) and count its failures")
    ap.add_argument("--open-containers", action="store_true",
                    help="refine with RefineConfig(open_containers=True): containers of one mesh group decomposed, inside open")
    ap.add_argument("--against", type=Path, default=None, help="an earlier run's cases.json to compare case by case")
    ap.add_argument("--one-mesh-per-link", action="store_true",
                    help="every object (dev rows and generated) with each link's meshes merged into one OBJ of one group")
    args = ap.parse_args(argv)
    kinds = tuple(k for k in args.kinds.split(",") if k)
    unknown = set(kinds) - set(KINDS)
    if unknown:
        ap.error(f"unknown kinds {sorted(unknown)}; known: {', '.join(KINDS)}")
    args.out.mkdir(parents=True, exist_ok=True)
    cases = build_corpus(args.manifest, None if args.no_generated else args.out / "generated", kinds,
                         set(filter(None, args.ids.split(","))),
                         one_mesh_root=args.out / "one_mesh" if args.one_mesh_per_link else None)
    if args.limit:
        cases = cases[: args.limit]
    print(f"{len(cases)} cases, {args.jobs} job(s)", flush=True)
    t0 = time.perf_counter()
    results: list[dict] = []
    runs = args.out / "runs"
    if args.jobs <= 1:
        for c in cases:
            results.append(run_case(c, str(runs), args.evaluate, args.open_containers))
            r = results[-1]
            print(f"  {r['mode']:>24} {r['seconds']:6.1f} s  {r['asset']:>22}  {r['prompt']!r}", flush=True)
    else:
        with ProcessPoolExecutor(max_workers=args.jobs) as pool:
            futs = [pool.submit(run_case, c, str(runs), args.evaluate, args.open_containers) for c in cases]
            for f in as_completed(futs):
                r = f.result()
                results.append(r)
                print(f"  {r['mode']:>24} {r['seconds']:6.1f} s  {r['asset']:>22}  {r['prompt']!r}", flush=True)
    order = {c["case"]: i for i, c in enumerate(cases)}
    results.sort(key=lambda r: order[r["case"]])
    (args.out / "cases.json").write_text(json.dumps(results, indent=1))
    print(report(results))
    if args.against is not None:
        print("\n" + "\n".join(compare_cases(json.loads(args.against.read_text()), results)))
    secs = sorted(r["seconds"] for r in results)
    if secs:
        print(f"\nwall {time.perf_counter() - t0:.0f} s; per case median {secs[len(secs) // 2]:.1f} s, max {secs[-1]:.1f} s "
              f"(pid {os.getpid()}, {args.jobs} job(s))")
    return 0


if __name__ == "__main__":
    sys.exit(main())
