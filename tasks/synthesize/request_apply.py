"""Apply a parsed request to one object: the joints a phrase names
(:mod:`asset2sim.tasks.interpret.named_parts`), the opening fractions numbers and ends ask
(:mod:`.opening_fractions`; beyond the limit: the limit, warned), the scale of
sizes in numbers, masses, materials and explicit joint parameters
(``docs/guide/requests.md``); the checks of an overlay against the request are
:mod:`.request_findings`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from asset2sim.schemas.overlay import Inertia, JointDynamics, LinkPhysics
from asset2sim.schemas.request import BAND_INTERVAL, BAND_TARGET, JointStateRequest, PartProperty, RequestSpec
from asset2sim.tasks.interpret import part_priors
from asset2sim.prior_tables import MaterialPrior, load_priors
from asset2sim.tasks.interpret.named_parts import (count_warnings, joints_named, joints_of, link_named, moving_parts, stand_ins,
                                                  state_targets, unit_fits)
from asset2sim.tasks.interpret.state_words import OTHERS
from asset2sim.tasks.synthesize.opening_fractions import falls_open, fraction_for

if TYPE_CHECKING:  # typing only: the context module imports this stage's parser
    from asset2sim.engines.base import SimSession
    from asset2sim.tasks.synthesize.context import EstimationContext

#: Relative tolerance of a numeric request (5 %).
NUMBER_TOLERANCE = 0.05
#: Smallest half-width of a numeric target's interval (opening fraction).
MIN_TOLERANCE = 0.005
#: Half-width of an end target's interval (opening fraction).
END_TOLERANCE = 0.02


@dataclass
class JointTarget:
    """What the request asks of one joint, resolved: band, target and acceptance interval (opening fractions)."""

    joint: str
    band: str
    fraction: float
    interval: tuple[float, float]
    kind: str = "band"
    asked: float | None = None
    """The number asked (rad, m or fraction), None for bands and ends."""
    phrase: str = ""
    note: str = ""


@dataclass
class StateResolution:
    """Bands of every movable joint, the targets of numbers and ends, notes and warnings."""

    bands: dict[str, str]
    targets: dict[str, JointTarget] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    addressed: set[str] = field(default_factory=set)
    """joints a phrase of the request set (the others are closed by default)"""
    requests: dict[str, JointStateRequest] = field(default_factory=dict)
    """joint -> the request (phrase) whose state it has"""
    unapplied: list[tuple[str, str]] = field(default_factory=list)
    """(phrase, why) of every state phrase applied to no joint: it names no part of the object (and none stands
    in), an ordinal beyond the count, a number that cannot be applied, every part it names set by a later phrase"""


def task_relevant_joints(ctx: EstimationContext) -> list[str]:
    """Movable joints whose moving part tasks manipulate, by the category's priority (``part_priors.task_relevant_joints``)."""
    return part_priors.task_relevant_joints(ctx.category, [(j.name, ctx.joint_label(j.name))
                                                           for j in ctx.asset.movable_joints()])[0]


def band_of(f: float) -> str:
    """The band of opening fraction ``f``: of those whose interval holds it (else all), the nearest target."""
    inside = [b for b, (lo, hi) in BAND_INTERVAL.items() if lo <= f <= hi]
    return min(inside or list(BAND_TARGET), key=lambda b: abs(BAND_TARGET[b] - f))


def _target(joint: str, f: float, kind: str, asked: float | None, phrase: str, note: str) -> JointTarget:
    """The target of opening fraction ``f``: its band and acceptance interval, +-:data:`END_TOLERANCE` for an end,
    else +-5 % of ``f`` (at least :data:`MIN_TOLERANCE`), within [0, 1]."""
    tol = END_TOLERANCE if kind == "end" else max(NUMBER_TOLERANCE * f, MIN_TOLERANCE)
    return JointTarget(joint=joint, band=band_of(f), fraction=f, interval=(max(0.0, f - tol), min(1.0, f + tol)), kind=kind,
                       asked=asked, phrase=phrase, note=note)


def resolve_states(ctx: EstimationContext, kin: SimSession, scale: float) -> StateResolution:
    """Band per movable joint and the targets of numbers and ends at the overlay's ``scale``; joints not
    addressed are closed; a request naming a part (or a joint) overrides one that names none ("half open"),
    else a later request for a joint overrides an earlier one. Acceptance: +-5 % of a number
    (at least :data:`MIN_TOLERANCE`), +-:data:`END_TOLERANCE` of an end. Phrases applied to no joint are in
    ``unapplied``, why with each (not a phrase naming no part, "half open", that phrases naming parts refine);
    ``requests`` says which phrase set each joint. ``kin``, the input's kinematics session, is moved for
    ordinals and ends and left at the closed state."""
    res = StateResolution(bands={})
    relevant = task_relevant_joints(ctx)
    named: list[tuple[JointStateRequest, list[str]]] = []
    cannot: list[tuple[JointStateRequest, str, str]] = []
    for jr in sorted(ctx.request.joint_states, key=lambda jr: jr.names_part):  # a part named wins over a request for "it", in any order
        before = len(res.warnings)
        joints = state_targets(ctx, jr, relevant, res.warnings, res.notes)
        named.append((jr, joints))
        if not joints and not jr.names_part and jr.band == "closed" and jr.target is None:
            res.notes.append(f"'{jr.phrase}': this {ctx.category} has no part that opens: it is closed as it is")
        elif not joints:
            endless = [f"{ctx.joint_label(n) or 'part'} ({n})" for n in relevant
                       if ctx.asset.joint(n).type == "continuous"]
            why = res.warnings[-1].removeprefix("WARNING: ") if len(res.warnings) > before else (
                f"names joint {jr.joint}, not a movable joint of this object" if jr.selector == "joint"
                else f"this {ctx.category}'s {' and '.join(endless)} turn{'s' if len(endless) == 1 else ''} without end (a "
                     f"continuous joint): no closed or open end to be '{jr.phrase}' at" if endless
                else f"this {ctx.category} has no task-relevant movable part")
            res.unapplied.append((jr.phrase, why))
        for t in joints:
            res.bands[t] = jr.band
            res.addressed.add(t)
            res.requests[t] = jr
            res.targets.pop(t, None)
            label = ctx.joint_label(t) or ""
            if jr.target is None:
                if jr.bare and falls_open(ctx, kin, t):  # a drop-down door open rests on its open stop
                    res.bands[t] = "fully"
                    res.notes.append(f"{t} ({label or 'part'}): '{jr.phrase}': its weight carries it open (it opens downward, "
                                     f"a drop-down door), so it is open resting on its open stop: fully open")
                continue
            f, why = fraction_for(ctx, kin, t, jr.target, scale, label)
            if f is None:
                res.warnings.append(f"WARNING: {t} ({label}): '{jr.phrase}' cannot be applied: {why}; the nominal band '{jr.band}' is used")
                cannot.append((jr, t, f"{t} ({label}): cannot be applied: {why}"))
                continue
            if f > 1.0 + 1e-9 or f < -1e-9:
                res.warnings.append(f"WARNING: {t} ({label}): '{jr.phrase}' is beyond the joint's limit ({why}, fraction {f:.3g}); set to the "
                                    + ("limit" if f > 1 else "closed end"))
                f = float(np.clip(f, 0.0, 1.0))
            res.targets[t] = _target(t, f, jr.target.kind, jr.target.value, jr.phrase, why)
            res.bands[t] = res.targets[t].band
            res.notes.append(f"{t} ({label}): '{jr.phrase}' -> opening fraction {f:.4g} ({why})")
    for j in ctx.asset.movable_joints():
        res.bands.setdefault(j.name, "closed")
    res.unapplied += [(jr.phrase, why) for jr, t, why in cannot if res.requests.get(t) is jr]
    res.unapplied += _replaced(named, res.requests)
    res.warnings += count_warnings(ctx)
    if closed_state := ctx.closed_state():
        kin.set_joint_positions(closed_state)
    return res


def _replaced(named: list[tuple[JointStateRequest, list[str]]], requests: dict[str, JointStateRequest]) -> list[tuple[str, str]]:
    """(phrase, why) of the phrases naming parts whose every joint a later phrase of the request set (``named``:
    (request, its joints) in resolution order; ``requests``: joint -> the request that won it). A phrase naming no
    part ("half open") refined by one naming a part, a phrase a typed override (``selector`` joint) replaced, and
    "the others closed" where no other part is left (the phrase asks for the parts the others did not set), are not
    among them."""
    out = []
    for jr, joints in named:
        if not joints or not jr.names_part or jr.selector == "joint" or any(requests.get(t) is jr for t in joints) \
                or OTHERS.match(jr.phrase):
            continue
        winners = [requests[t] for t in joints if t in requests]
        if all(w.selector == "joint" for w in winners):
            continue
        later = ", ".join(dict.fromkeys(f"'{w.phrase}'" for w in winners if w.selector != "joint"))
        out.append((jr.phrase, f"every part it names ({', '.join(joints)}) is set by the later {later}"))
    return out


def retarget(targets: dict[str, JointTarget], old: dict, new: dict) -> dict[str, JointTarget]:
    """``targets`` with every angle and distance re-resolved after a joint's closed end or range moved from
    ``old`` to ``new`` (joint -> ``ClosedState``, output units: the output's collision pieces, limits clipped to
    the geometry): the same opening from the new closed end (rad, or m), as a fraction of the new range (at most
    the range), with its acceptance interval and band; fractions and ends are fractions of whatever range the part
    has and stay. Unchanged joints keep their target."""
    out = dict(targets)
    for n, t in targets.items():
        a, b = old.get(n), new.get(n)
        if t.kind not in ("angle", "distance") or a is None or b is None or not b.open_range > 0:
            continue
        if abs(a.q_closed - b.q_closed) <= 1e-12 and abs(a.open_range - b.open_range) <= 1e-12 and a.direction == b.direction:
            continue
        f = float(np.clip(t.fraction * a.open_range / b.open_range, 0.0, 1.0))
        out[n] = _target(t.joint, f, t.kind, t.asked, t.phrase, f"{t.note}; the output's closed end or range moved: the same "
                         f"opening placed from its closed end ({f:.3g} of its range)")
    return out


def scale_from_sizes(ctx: EstimationContext) -> tuple[float, str] | None:
    """(scale, note) of an override, else the geometric mean over the sizes in numbers of value / closed
    extent along the named dimension; None without either."""
    if ctx.request.scale is not None:
        return float(ctx.request.scale), f"scale given by the user: --scale {ctx.request.scale:g}"
    sizes = ctx.request.sizes
    if not sizes:
        return None
    along = _extents(ctx)
    extents = [max(float(along[sz.dimension]), 1e-12) for sz in sizes]
    ratios = [(sz.value / e) ** (1.0 / 3.0) if sz.dimension == "volume" else sz.value / e for sz, e in zip(sizes, extents)]
    parts = [(f"'{sz.phrase}': a container's volume, taken as the closed object's outer volume (convex hull; its walls make "
              f"the inside a little smaller) {e:.4g} at scale 1 -> ({sz.value:.4g} / {e:.4g})^(1/3) = {r:.4g}")
             if sz.dimension == "volume" else f"'{sz.phrase}': {sz.dimension} {e:.4g} at scale 1 -> {r:.4g}"
             for sz, e, r in zip(sizes, extents, ratios)]
    s = float(np.exp(np.mean(np.log(ratios))))
    note = "size in numbers: " + "; ".join(parts) + f" -> s = {s:.4g}"
    if len(ratios) > 1 and max(ratios) / min(ratios) > 1 + NUMBER_TOLERANCE:
        note += (f"; WARNING: the sizes ask for different scales ({min(ratios):.4g}..{max(ratios):.4g}); one uniform scale "
                 "cannot meet them all (geometric mean used)")
    return s, note


def size_residuals(ctx: EstimationContext, scale: float) -> list[tuple[str, float, float]]:
    """(phrase, asked, obtained) of every size in numbers at ``scale``: m, or m^3 for a volume."""
    along = _extents(ctx)
    return [(sz.phrase, sz.value, float(along[sz.dimension]) * scale ** (3 if sz.dimension == "volume" else 1)) for sz in ctx.request.sizes]


def _extents(ctx: EstimationContext) -> dict:
    """The closed extent (m, scale 1) per size dimension: height z, width / depth the larger / smaller horizontal;
    ``volume`` the closed object's convex-hull volume (m^3, ``ctx.closed_volume``)."""
    ext = np.asarray(ctx.closed_extents, float)
    if ctx.root_rotation is not None:
        ext = np.abs(np.asarray(ctx.root_rotation, float)) @ ext
    return {"height": ext[2], "width": max(ext[0], ext[1]), "depth": min(ext[0], ext[1]),
            "length": float(ext.max()), "largest": float(ext.max()),
            "volume": float(ctx.closed_volume or 0.0)}


def requested_material(ctx: EstimationContext, link: str) -> MaterialPrior | None:
    """The material the request names for ``link``: a part's over the body's over the whole object's."""
    ranked = [(0 if p.label is None else (1 if p.label == "body" else 2), p.material) for p in ctx.request.properties
              if p.material is not None and link_named(ctx, link, p.label)]
    best = max(reversed(ranked), key=lambda t: t[0], default=None)  # of equal ranks the last named
    return None if best is None else load_priors().materials[best[1]]


def _missing_parts(ctx: EstimationContext) -> list[tuple[str, str, list[str] | None, str]]:
    """(phrase, why, stand-in joints, how they stand in) of every mass or material naming a part the object lacks
    (no stand-ins), then of every joint parameter naming a part no joint carries."""
    links = [ln.name for ln in ctx.asset.links]
    out = [(p.phrase, f"names a '{p.label}' but this {ctx.category} has no such part", None, "") for p in ctx.request.properties
           if p.label not in (None, "body") and not any(link_named(ctx, ln, p.label) for ln in links)]
    for d in ctx.request.dynamics_values:
        if d.label is not None and not joints_named(ctx, d.label):
            to, how = stand_ins(ctx, d.label, task_relevant_joints(ctx))
            out.append((d.phrase, f"names a '{d.label}' but no part of this {ctx.category} carries that label", to, how))
    return out


def unmatched_properties(ctx: EstimationContext) -> list[str]:
    """Warnings for masses, materials and joint parameters naming a part the object lacks."""
    return [f"WARNING: '{phrase}' {why}; its moving parts: {moving_parts(ctx)}; " + (f"applied to {how} {to}" if to else "not applied")
            for phrase, why, to, how in _missing_parts(ctx)]


def unapplied_properties(ctx: EstimationContext) -> list[tuple[str, str]]:
    """(phrase, why) of every mass or material naming a part the object lacks, and every joint parameter naming a
    part no joint carries and none stands in for (:func:`unmatched_properties` warns of both)."""
    return [(phrase, f"{why} (its moving parts: {moving_parts(ctx)})") for phrase, why, to, _ in _missing_parts(ctx) if not to]


def scaled_link(lp: LinkPhysics, f: float, note: str) -> LinkPhysics:
    """``lp`` with mass and inertia tensor times ``f`` (center of mass unchanged), ``note`` added to its source."""
    return lp.model_copy(update={"mass": lp.mass * f, "inertia": Inertia.from_matrix(lp.inertia.matrix() * f), "source": lp.source + note})


def range_target(mass: float, mass_range: tuple[float, float]) -> float:
    """The mass (kg) a range asked for gives ``mass`` (kg): itself inside ``mass_range`` (low, high), else the nearer
    end: a range is met anywhere in it, so the estimate is moved only as far as the range needs."""
    lo, hi = mass_range
    return min(max(float(mass), float(lo)), float(hi))


@dataclass(frozen=True, slots=True)
class AskedMasses:
    """The links with the masses a request asks (:func:`apply_masses`): ``links`` (link -> physics, kg),
    ``notes`` (one line per change or warning) and ``total_asked`` (whether the request set the total mass)."""

    links: dict[str, LinkPhysics]
    notes: list[str]
    total_asked: bool


def whole_masses(spec: RequestSpec) -> tuple[PartProperty | None, PartProperty | None]:
    """The first mass and the first range of masses (kg) ``spec`` asks for the whole object, None where it asks none."""
    whole = [p for p in spec.properties if p.label is None]
    return next((p for p in whole if p.mass is not None), None), next((p for p in whole if p.mass_range is not None), None)


def apply_masses(ctx: EstimationContext, links: dict[str, LinkPhysics], plausible: tuple[float, float]) -> AskedMasses:
    """Masses in numbers and words on the links (inertia scaled alike): per-part masses first, then the total
    (other links scaled), else "heavy" / "light" at 0.9 x the upper / 1.1 x the lower plausible end."""
    notes: list[str] = []
    out = dict(links)
    fixed: set[str] = set()
    for p in ctx.request.properties:
        if (p.mass is None and p.mass_range is None) or p.label is None:
            continue
        names = [n for n in out if link_named(ctx, n, p.label)]
        if not names:
            continue
        m = sum(out[n].mass for n in names)
        want = p.mass if p.mass is not None else range_target(m, p.mass_range)
        f = want / max(m, 1e-12)
        for n in names:
            out[n] = scaled_link(out[n], f, f"; x{f:.4g} to the requested {want:g} kg of the {p.label} ('{p.phrase}')")
        fixed.update(names)
        notes.append(f"'{p.phrase}': {p.label} links {names} {m:.4g} -> {want:.4g} kg")
    total, rng = whole_masses(ctx.request)
    total_req = None if total is None else total.mass
    why = None
    if total_req is None and rng is not None:
        now = sum(lp.mass for lp in out.values())
        total_req = range_target(now, rng.mass_range)
        where = "lies in" if total_req == now else "brought to the nearer end of"
        why = f"'{rng.phrase}': the estimate {now:.4g} kg {where} the {rng.mass_range[0]:g}-{rng.mass_range[1]:g} kg asked"
        if total_req == now:
            notes.append(why + "; kept")
            return AskedMasses(out, notes, True)
    lo, hi = plausible
    if total_req is None and (level := ctx.request.mass_level) is not None:
        total_req = 0.9 * hi if level == "heavy" else 1.1 * lo
        why = f"'{level}': {'0.9 x the upper' if level == 'heavy' else '1.1 x the lower'} end of the plausible {lo:.3g}-{hi:.3g} kg"
    if total_req is None:
        return AskedMasses(out, notes, bool(fixed))
    fixed_mass = sum(out[n].mass for n in fixed)
    free = [n for n in out if n not in fixed]
    free_mass = sum(out[n].mass for n in free)
    if not free or total_req <= fixed_mass:
        notes.append(f"WARNING: the requested total {total_req:.4g} kg is not above the parts' requested masses ({fixed_mass:.4g} kg); total left at {sum(lp.mass for lp in out.values()):.4g} kg")
        return AskedMasses(out, notes, True)
    f = (total_req - fixed_mass) / max(free_mass, 1e-12)
    for n in free:
        out[n] = scaled_link(out[n], f, f"; x{f:.4g} to the requested total {total_req:.4g} kg")
    notes.append((why or "requested total mass") + f": {fixed_mass + free_mass:.4g} -> {total_req:.4g} kg")
    if not (lo <= total_req <= hi):
        notes.append(f"note: the requested {total_req:.4g} kg is outside the plausible {lo:.3g}-{hi:.3g} kg for this {ctx.category}; kept as asked")
    return AskedMasses(out, notes, True)


def apply_dynamics_values(ctx: EstimationContext, joints: dict[str, JointDynamics], relevant: list[str],
                          state: dict[str, float]) -> tuple[dict[str, JointDynamics], list[str]]:
    """Explicit damping / friction / stiffness on the joints they name (else ``relevant``) whose motion fits
    the unit; a stiffness gets its spring reference at ``state`` (output units)."""
    notes: list[str] = []
    out = dict(joints)
    for d in ctx.request.dynamics_values:
        names = joints_of(ctx, d, relevant)
        if d.label is not None and not names:  # no such part: warned by unmatched_properties
            continue
        applied = []
        for n in names:
            if n not in out or not unit_fits(d, n in ctx.prismatic):
                continue
            upd: dict = {d.quantity: float(d.value), "source": out[n].source + f"; {d.quantity} {d.value:g} from the request ('{d.phrase}')"}
            if d.quantity == "stiffness":
                upd["spring_reference"] = float(state.get(n, 0.0)) if d.value > 0 else None
            out[n] = out[n].model_copy(update=upd)
            applied.append(n)
        notes.append(f"'{d.phrase}' set on {applied}" if applied
                     else f"WARNING: '{d.phrase}' fits no joint ({d.motion} unit; joints {names}); not applied")
    return out, notes


def prompt_fields(spec: RequestSpec) -> dict:
    """The parts of a parsed request beyond bands, as JSON for a model's prompt (SI; materials with density)."""
    mats = load_priors().materials
    return {
        "sizes_m": [s.model_dump() for s in spec.sizes],
        "masses_and_materials": [{**p.model_dump(), "density": None if p.material is None else mats[p.material].density}
                                 for p in spec.properties],
        "mass_level": spec.mass_level, "joint_parameters": [d.model_dump() for d in spec.dynamics_values],
        "part_counts": dict(spec.part_counts), "parser_warnings": list(spec.warnings), "ignored_words": list(spec.ignored),
    }
