"""The request corpus (``tests/data/request_corpus.yaml``): loading, the
comparison of a parse with its expected parse, and the check of a refined
output against the expected outcome. Used by
``tests/tasks/interpret/test_request_corpus.py`` and
``benchmarks/bench_request.py``.

Entry format (YAML list)::

    - object: "7119" | "demo:<id>" | "gen:toaster" | "gen:chest" | "unseen:toaster" | "unseen:bottle" | "unseen:dispenser"
      text: the request
      phenomena: [synonym, ordinal, ...]   # hand-written entries (PHENOMENA); rates per phenomenon in the benchmark
      parse:            # every field has a default; all are compared
        states: ["door=halfway", "drawer#0=closed", "door#0@left_right=mostly",
                 "door=angle:30deg", "drawer=distance:0.1", "door=fraction:0.6", "lever=end:high"]
        size: small               # size class (default none)
        sizes: ["height:0.3"]     # m
        props: ["object:mass=2;material=solid_wood", "door:material=glass"]
        mass_level: heavy | light
        damping: low | moderate | high          (default moderate)
        flags: [spring, holds, stiff, free]
        dyn: ["[label:]damping=0.5/rotational"]
        counts: ["drawer:2"]
        pose: lying_flat | sideways | upright
        warnings: n               # parser warnings (contradictions, unused numbers)
        ignored: [...]            # compared only when given
      outcome:          # optional: checked on the refined output
        joints: {joint: band | "angle:30deg" | "distance:0.1" | "fraction:0.6" | "end:high" | "end:low"}
        size: "height:0.3"        # the closed object's extent at the output scale (m), 5 %
        mass: 2.0                 # total kg, 5 %
        materials: {link: materials.yaml key}
        damping: low              # damping level of the task-relevant joints
        dyn: {joint: "damping=0.05"}  # 5 %
        warnings: [substring, ...]    # each in some warning of report.request
      apply:            # optional: the request resolved on the object's joints, no refine (apply_misses)
        joints: {joint: band | "end:high" | "angle:30deg" | "distance:0.1" | "fraction:0.4"}
        unapplied: [phrase, ...]      # the phrases applied to no joint, in order
"""

from __future__ import annotations

import math
from functools import lru_cache
from pathlib import Path
from typing import Callable

import numpy as np
import yaml

from asset2sim.demo_assets import ensure_demo_dataset
from asset2sim.engines.base import SessionOptions
from asset2sim.engines.registry import open_session
from asset2sim.schemas.request import BAND_INTERVAL, RequestSpec
from asset2sim.prior_tables import load_priors
from asset2sim.tasks.interpret.request import parse_request
from asset2sim.tasks.refine import RefineResult, refine_asset
from asset2sim.tasks.synthesize.context import build_context
from tests.conftest import SHARED
from asset2sim.tasks.synthesize import estimate, request_apply
from tests import unseen_assets
from tests.tasks.interpret.request_assets import build_three_drawer_cabinet, build_toaster

CORPUS = Path(__file__).resolve().parents[2] / "data" / "request_corpus.yaml"
DEV = SHARED  # tests.conftest.SHARED: the dev dataset folder
TOLERANCE = 0.05


def load_corpus() -> list[dict]:
    """The corpus entries, each with an ``id`` (r001 ...) added."""
    entries = yaml.safe_load(CORPUS.read_text())
    for i, e in enumerate(entries):
        e["id"] = f"r{i + 1:03d}"
    return entries


def _num(text: str) -> float:
    """"30deg" -> radians; other numbers as written."""
    if text.endswith("deg"):
        return math.radians(float(text[:-3]))
    return float(text)


def _g(v: float) -> str:
    return f"{v:.4g}"


def _norm_state(s: str) -> str:
    head, val = s.split("=", 1)
    if ":" in val:
        kind, x = val.split(":", 1)
        if kind != "end":
            x = _g(_num(x))
        val = f"{kind}:{x}"
    return f"{head}={val}"


def expected_parse(entry: dict) -> dict:
    """The expected parse of an entry, normalised (see the module docstring)."""
    p = entry.get("parse") or {}
    props = []
    for s in p.get("props", []):
        label, rest = s.split(":", 1)
        kv = dict(x.split("=") for x in rest.split(";"))
        if "mass" in kv:
            kv["mass"] = _g(float(kv["mass"]))
        props.append(label + ":" + ";".join(f"{k}={kv[k]}" for k in ("mass", "material") if k in kv))
    dyn = []
    for s in p.get("dyn", []):
        label, rest = (s.split(":", 1) if ":" in s.split("=")[0] else ("", s))
        q, vm = rest.split("=")
        v, motion = vm.split("/")
        dyn.append(f"{label + ':' if label else ''}{q}={_g(float(v))}/{motion}")
    out = {
        "states": sorted(_norm_state(s) for s in p.get("states", [])),
        "size": p.get("size"),
        "sizes": sorted(f"{s.split(':')[0]}:{_g(float(s.split(':')[1]))}" for s in p.get("sizes", [])),
        "props": sorted(props),
        "mass_level": p.get("mass_level"),
        "damping": p.get("damping", "moderate"),
        "flags": sorted(p.get("flags", [])),
        "dyn": sorted(dyn),
        "counts": sorted(p.get("counts", [])),
        "pose": p.get("pose"),
        "warnings": int(p.get("warnings", 0)),
    }
    if "ignored" in p:
        out["ignored"] = list(p["ignored"])
    return out


def parse_key(spec: RequestSpec, with_ignored: bool) -> dict:
    """A parse in the corpus' normalised form."""
    states = []
    for js in spec.joint_states:
        head = (js.label if js.selector == "label" else "all") + ("" if js.ordinal is None else f"#{js.ordinal}") + (
            "" if js.order == "vertical" else f"@{js.order}")
        t = js.target
        if t is None:
            val = js.band
        elif t.kind == "end":
            val = f"end:{t.end}"
        else:
            val = f"{t.kind}:{_g(t.value)}"
        states.append(f"{head}={val}")
    props = []
    for p in spec.properties:
        props.append((p.label or "object") + ":" + ";".join(
            x for x in ((f"mass={_g(p.mass)}" if p.mass is not None else ""), (f"material={p.material}" if p.material else "")) if x))
    flags = [n for n, on in (("free", spec.free_moving), ("holds", spec.holds_position), ("spring", spec.spring), ("stiff", spec.stiff)) if on]
    out = {
        "states": sorted(states),
        "size": spec.size_class,
        "sizes": sorted(f"{s.dimension}:{_g(s.value)}" for s in spec.sizes),
        "props": sorted(props),
        "mass_level": spec.mass_level,
        "damping": spec.damping,
        "flags": sorted(flags),
        "dyn": sorted(f"{d.label + ':' if d.label else ''}{d.quantity}={_g(d.value)}/{d.motion}" for d in spec.dynamics_values),
        "counts": sorted(f"{k}:{v}" for k, v in spec.part_counts.items()),
        "pose": spec.pose_hint,
        "warnings": len(spec.warnings),
    }
    if with_ignored:
        out["ignored"] = list(spec.ignored)
    return out


def parse_misses(entries: list[dict], parse: Callable[[str], RequestSpec] = parse_request) -> list[str]:
    """One line per entry whose parse (by ``parse``, default the offline parser) differs from the expected one
    (the differing fields: expected vs got)."""
    misses = []
    for e in entries:
        exp = expected_parse(e)
        got = parse_key(parse(e["text"]), "ignored" in exp)
        diff = {k: (exp[k], got[k]) for k in exp if exp[k] != got[k]}
        if diff:
            misses.append(f"{e['id']} {e['text']!r}: " + "; ".join(f"{k}: expected {a}, got {b}" for k, (a, b) in diff.items()))
    return misses


# ------------------------------------------------------------------ outcomes
def asset_folder(obj: str, scratch: Path) -> Path:
    """The folder of a corpus object: a dev asset, a demo asset (built under
    ``scratch``) or a generated one."""
    if obj.startswith("demo:"):
        return ensure_demo_dataset(scratch / "demo") / obj[5:]
    builders = {"gen:toaster": build_toaster, "gen:chest": build_three_drawer_cabinet,
                "unseen:toaster": unseen_assets.build_toaster, "unseen:bottle": unseen_assets.build_bottle,
                "unseen:dispenser": unseen_assets.build_dispenser}
    if obj in builders:
        folder = scratch / obj.replace(":", "_")
        if not (folder / "mobility.urdf").exists():
            builders[obj](folder)
        return folder
    return DEV / obj


#: Phenomena of the hand-written entries (``phenomena:``); the others count as ``general``.
PHENOMENA = ("synonym", "ordinal", "quantifier", "compound", "negation", "hedge", "fraction", "unit", "volume", "missing_part")


def phenomena_of(entry: dict) -> list[str]:
    """The entry's phenomena (``general`` without any)."""
    return list(entry.get("phenomena") or ["general"])


def apply_misses(entry: dict, scratch: Path) -> list[str]:
    """What the request resolved on the entry's object misses of its ``apply`` expectation (joint -> band, or
    ``kind:value`` of the target: ``end:high``, ``angle:30deg``, ``distance:0.1`` m at the chosen scale,
    ``fraction:0.4``; ``unapplied``: the phrases applied to no joint, in order). No refine: the parse and
    ``request_apply.resolve_states`` at ``estimate.choose_scale``."""
    want = entry.get("apply") or {}
    out: list[str] = []
    with build_context(asset_folder(entry["object"], scratch), entry["text"]) as (ctx, kin):
        scale, _ = estimate.choose_scale(ctx)
        res = request_apply.resolve_states(ctx, kin, scale)
    for j, exp in (want.get("joints") or {}).items():
        t = res.targets.get(j)
        if ":" not in exp:
            if res.bands.get(j) != exp or t is not None:
                out.append(f"{j}: band {res.bands.get(j)}" + (f" (target {t.kind} {t.fraction:.3g})" if t else "") + f", expected {exp}")
            continue
        kind, x = exp.split(":", 1)
        if t is None or t.kind != kind:
            out.append(f"{j}: {'no target' if t is None else t.kind}, expected {exp}")
        elif kind == "end":
            if res.requests[j].target.end != x:
                out.append(f"{j}: end {res.requests[j].target.end}, expected {x}")
        elif kind == "fraction" and abs(t.fraction - _num(x)) > 1e-3 or kind != "fraction" and abs((t.asked or 0.0) - _num(x)) > 1e-6:
            out.append(f"{j}: {kind} {t.fraction if kind == 'fraction' else t.asked:.4g}, expected {_num(x):.4g}")
    got = [p for p, _ in res.unapplied]
    if "unapplied" in want and got != list(want["unapplied"]):
        out.append(f"not applied {got}, expected {want['unapplied']}")
    return out


def parse_rates(entries: list[dict], parse: Callable[[str], RequestSpec] = parse_request) -> dict[str, tuple[int, int]]:
    """phenomenon -> (entries whose parse by ``parse`` matches the expected one; entries) over ``entries``; the
    parse alone, not the joints it sets on the object."""
    bad = {m.split(" ", 1)[0] for m in parse_misses(entries, parse)}
    out: dict[str, list[int]] = {}
    for e in entries:
        for ph in phenomena_of(e):
            c = out.setdefault(ph, [0, 0])
            c[0] += e["id"] not in bad
            c[1] += 1
    return {k: (v[0], v[1]) for k, v in out.items()}


def rates_by_phenomenon(entries: list[dict], scratch: Path) -> dict[str, tuple[int, int]]:
    """phenomenon -> (entries whose parse and, when given, application match; entries) over ``entries``."""
    parse_bad = {m.split(" ", 1)[0] for m in parse_misses(entries)}
    out: dict[str, list[int]] = {}
    for e in entries:
        ok = e["id"] not in parse_bad and (not e.get("apply") or not apply_misses(e, scratch))
        for ph in phenomena_of(e):
            c = out.setdefault(ph, [0, 0])
            c[0] += ok
            c[1] += 1
    return {k: (v[0], v[1]) for k, v in out.items()}


@lru_cache(maxsize=64)
def closed_extents(folder: str) -> tuple[float, float, float]:
    """(3,) closed extents at scale 1 of an input asset (root frame)."""
    with build_context(Path(folder), "") as (ctx, kin):
        return tuple(float(x) for x in ctx.closed_extents)


def _extent(ext: tuple[float, float, float], dim: str, scale: float) -> float:
    horiz = sorted(ext[:2], reverse=True)
    return scale * {"height": ext[2], "width": horiz[0], "depth": horiz[1]}.get(dim, max(ext))


def _link_z(out_dir: Path, joint: str, q: float, state: dict[str, float]) -> tuple[float, float, float]:
    """(z at q, min z, max z) of the joint's child link box center over its
    limits, in the written output (world frame, resting pose and scale applied)."""
    with open_session("pybullet", out_dir / "mobility.urdf", SessionOptions(fixed_base=True, gravity=False, ground=False)) as s:
        lo, hi = s.joint_limits[joint]
        child = s.joint_child[joint]
        zs = []
        for x in [q] + list(np.linspace(lo, hi, 41)):
            s.set_joint_positions({**state, joint: float(x)})
            a, b = s.link_aabb(child)
            zs.append(0.5 * (a[2] + b[2]))
    return zs[0], min(zs[1:]), max(zs[1:])


def outcome_misses(entry: dict, result: RefineResult, folder: Path) -> list[str]:
    """What the refined output misses of the entry's expected outcome."""
    out: list[str] = []
    want = entry.get("outcome") or {}
    r = result.report
    fr = r.opening_fractions
    for j, exp in (want.get("joints") or {}).items():
        f = fr.get(j)
        q = r.initial_joint_positions.get(j)
        if f is None or q is None:
            out.append(f"{j}: no state")
            continue
        if exp in BAND_INTERVAL:
            lo, hi = BAND_INTERVAL[exp]
            if not lo - 1e-6 <= f <= hi + 1e-6:
                out.append(f"{j}: opening fraction {f:.3g} not in {exp} [{lo}, {hi}]")
            continue
        kind, x = exp.split(":", 1)
        if kind == "end":
            z, zmin, zmax = _link_z(result.out_dir, j, q, r.initial_joint_positions)
            tol = 0.05 * (zmax - zmin)
            if (x == "high" and z < zmax - tol) or (x == "low" and z > zmin + tol):
                out.append(f"{j}: '{x}' but its child link's z {z:.4g} in [{zmin:.4g}, {zmax:.4g}]")
            continue
        v = _num(x)
        got = f if kind == "fraction" else abs(q - r.closed_positions[j])
        if abs(got - v) > TOLERANCE * abs(v) + 1e-9:
            out.append(f"{j}: {kind} {got:.4g}, asked {v:.4g} (> 5 %)")
    if "size" in want:
        dim, v = want["size"].split(":")
        got = _extent(closed_extents(str(folder)), dim, r.scale)
        if abs(got - float(v)) > TOLERANCE * float(v):
            out.append(f"size {dim}: {got:.4g} m, asked {v}")
    if "mass" in want and abs(r.total_mass - want["mass"]) > TOLERANCE * want["mass"]:
        out.append(f"total mass {r.total_mass:.4g} kg, asked {want['mass']}")
    mats = load_priors().materials
    for link, key in (want.get("materials") or {}).items():
        lp = result.overlay.links.get(link)
        if lp is None or abs(lp.density - mats[key].density) > 1e-6:
            out.append(f"link {link}: density {None if lp is None else lp.density}, asked {key} ({mats[key].density})")
    if "damping" in want:
        rel = [jd for jd in result.overlay.joints.values() if f"({want['damping']})" in jd.source]
        if not rel:
            out.append(f"no joint with damping level {want['damping']}")
    explained = {q.what for q in (r.request.quantities if r.request else []) if not q.within_tolerance and q.why}
    for j, exp in (want.get("dyn") or {}).items():
        q_, v = exp.split("=")
        got = getattr(result.overlay.joints[j], q_)
        if abs(got - float(v)) > TOLERANCE * float(v) and f"{j} {q_}" not in explained:
            out.append(f"{j}: {q_} {got:.4g}, asked {v}, and the report does not say why")
    warnings = r.request.warnings if r.request else []
    for sub in want.get("warnings") or []:
        if not any(sub in w for w in warnings):
            out.append(f"no warning naming {sub!r} in {warnings}")
    return out


def run_outcome(entry: dict, scratch: Path) -> list[str]:
    """Refine the entry's object for its text (no extras) and return the misses."""
    folder = asset_folder(entry["object"], scratch)
    out_dir = scratch / "out" / entry["id"]
    category = "Toaster" if entry["object"] == "gen:toaster" else None
    result = refine_asset(folder, entry["text"], out_dir, category=category, extras=False, skip_if_complete=False, overwrite=True)
    return outcome_misses(entry, result, folder)
