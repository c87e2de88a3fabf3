"""Overlay synthesis (SPEC stage 2): the helpers every estimator shares (scale,
state bands, plausible mass, joint dynamics from loads). The protocol and
registry are :mod:`.estimator`, the physics :mod:`.physics`."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from asset2sim.schemas.overlay import JointDynamics, LinkPhysics
from asset2sim.schemas.request import BAND_INTERVAL, BAND_TARGET
from asset2sim.tasks.geometry.closed_state import ClosedState
from asset2sim.tasks.ingest import host_conventions, partnet_mobility
from asset2sim.tasks.interpret import priors
from asset2sim.tasks.synthesize import physics, request_apply
from asset2sim.tasks.synthesize.context import EstimationContext


def task_relevant_joints(ctx: EstimationContext) -> list[str]:
    """Movable joints whose moving part tasks manipulate (:func:`request_apply.task_relevant_joints`)."""
    return request_apply.task_relevant_joints(ctx)


def requested_bands(ctx: EstimationContext, scale: float | None = None) -> tuple[dict[str, str], list[str]]:
    """(joint -> band, notes with warnings first) from the request at ``scale`` (default :func:`choose_scale`)."""
    res = request_apply.resolve_states(ctx, choose_scale(ctx)[0] if scale is None else scale)
    return res.bands, res.warnings + res.notes


def state_from_bands(closed: dict[str, ClosedState], bands: dict[str, str], scale: float, prismatic: set[str]) -> dict[str, float]:
    """Joint positions (output units) at each band's target opening fraction."""
    out = {}
    for name, cs in closed.items():
        q = cs.position(BAND_TARGET[bands.get(name, "closed")])
        out[name] = q * scale if name in prismatic else q
    return out


def choose_scale(ctx: EstimationContext) -> tuple[float, str]:
    """(uniform scale s, note): sizes in numbers decide alone; else s is the geometric mean of the ratios
    of the two largest sorted target dimensions (``priors.target_size``) to the closed extents, capped for
    handheld categories so two dimensions fit ``priors.GRASPABLE_WIDTH_M``."""
    sized = request_apply.scale_from_sizes(ctx)
    if sized is not None:
        return sized
    real = host_conventions.real_units(ctx.asset)
    kept, why_not = _real_size(ctx, real)
    if kept is not None:
        return 1.0, kept
    target = priors.target_size(ctx.category, ctx.request)
    dims = np.sort(np.asarray(target.dims, float))[::-1]
    ext = np.maximum(np.sort(np.asarray(ctx.closed_extents, float))[::-1], 1e-9)
    ratios = dims[:2] / ext[:2]
    s = float(np.exp(np.mean(np.log(ratios))))
    note = (
        f"closed extents at scale 1 {np.round(ext, 4).tolist()}; target {np.round(dims, 4).tolist()} m ({target.note})"
        f" -> s = geometric mean of the two largest ratios = {s:.4g}"
    )
    if target.handheld:
        cap = priors.GRASPABLE_WIDTH_M / ext[1]
        if s > cap:
            note += f"; handheld: capped to {cap:.4g} so two dimensions fit a {priors.GRASPABLE_WIDTH_M} m gripper"
            s = cap
    note += f"; {why_not}" if why_not else ""
    return s, note + ('' if partnet_mobility.size_normalized(ctx.asset.staged_from or ctx.asset.urdf_path) else unit_warning(s))


def _real_size(ctx: EstimationContext, real: str | None) -> tuple[str | None, str | None]:
    """(note, None) when an input in real units (``real``: why, :func:`~asset2sim.tasks.ingest.host_conventions.real_units`)
    keeps its size: no size asked (no size words, numbers, ``--size`` or ``--scale``) and its largest closed dimension
    plausible for its category by the audit's rule (:func:`~asset2sim.tasks.interpret.size_priors.plausible_largest_dimension`);
    else (None, why it is rescaled, for the size note; None for a normalized input)."""
    if real is None:
        return None, None
    largest = float(np.max(ctx.closed_extents))
    lo, hi, typical = priors.plausible_largest_dimension(ctx.category)
    what = f"a typical {ctx.category} is {typical:.3g} m" if typical is not None else "a household object"
    if ctx.request.size_class is not None:
        return None, f"{real}, rescaled as asked ({ctx.request.size_class})"
    if lo <= largest <= hi:
        return (f"size kept (scale 1): {real}; largest closed dimension {largest:.4g} m is plausible "
                f"({what}; plausible {lo:.3g}-{hi:.3g} m, the audit's rule)"), None
    return None, (f"{real}, but its largest closed dimension {largest:.4g} m is implausible ({what}; plausible "
                  f"{lo:.3g}-{hi:.3g} m): rescaled")


#: Length units an input's numbers are often written in by mistake for metres: metres per unit -> name.
UNIT_MISTAKES = {0.001: "millimetres", 0.01: "centimetres", 0.0254: "inches"}
#: A scale beyond this factor from 1 is reported as a likely unit mistake (sizes within a category span less).
UNIT_WARNING_FACTOR = 5.0


def unit_warning(scale: float) -> str:
    """``"; WARNING: ..."`` when ``scale`` (output / input size) lies beyond :data:`UNIT_WARNING_FACTOR` from 1 and
    within a factor 1.5 of a unit of :data:`UNIT_MISTAKES` (lengths in that unit read as metres); ``""`` otherwise
    (a model drawn at another size is no unit mistake: the size note says how it was scaled)."""
    if 1.0 / UNIT_WARNING_FACTOR <= scale <= UNIT_WARNING_FACTOR:
        return ""
    unit, per = min(((name, m) for m, name in UNIT_MISTAKES.items()), key=lambda u: abs(np.log(scale / u[1])))
    if abs(np.log(scale / per)) >= np.log(1.5):
        return ""
    guess = f"its lengths look like {unit} read as metres"
    return f"; WARNING: the input is {1.0 / scale:.3g}x its category's typical size ({guess}); rescaled by {scale:.4g}"


def plausible_mass_range(ctx: EstimationContext, scale: float) -> tuple[float, float]:
    """Plausible total mass (kg) as sized: the regular mass range scaled (``priors.scale_mass_range``) by f,
    the geometric mean of scaled closed extents / regular dims over the two largest dimensions."""
    target = priors.target_size(ctx.category, ctx.request)
    cat = priors.category_prior(ctx.category)
    var = cat.variant(target.variant) if target.variant else None
    base_lo, base_hi = var.mass_range if var is not None else cat.mass_range
    base = np.sort(np.asarray(target.base_dims, float))[::-1]
    actual = np.sort(np.asarray(ctx.closed_extents, float) * scale)[::-1]
    f = float(np.exp(np.mean(np.log(np.maximum(actual[:2], 1e-9) / base[:2]))))
    return priors.scale_mass_range(base_lo, base_hi, f)


def request_variant(ctx: EstimationContext) -> str | None:
    """The category variant the request names ("office cabinet"), or None."""
    v = priors.find_variant(ctx.category, ctx.request.text) if ctx.request.text else None
    return v.name if v is not None else None


def link_material(ctx: EstimationContext, label: str | None, link: str | None = None) -> physics.MaterialChoice:
    """The material the request names for ``link``, else the category's prior for ``label``."""
    m = (request_apply.requested_material(ctx, link) if link is not None else None) or priors.material_for(ctx.category, label, request_variant(ctx))
    return physics.material_choice(m)


@dataclass
class JointChoice:
    """Qualitative dynamics choices for one joint; :func:`joint_dynamics_for` turns them into numbers."""

    damping_level: str = "moderate"
    holds_position: bool = False
    spring: bool = False
    stiff: bool = False
    free_moving: bool = False


def joint_dynamics_for(ctx: EstimationContext, links: dict[str, LinkPhysics], state: dict[str, float], scale: float,
                       choices: dict[str, JointChoice], *, source: str) -> dict[str, JointDynamics]:
    """Damping, friction and stiffness of every movable joint from the scaled masses and the kinematics at
    ``state`` (output units), shaped by ``choices`` (``docs/design/refine.md``, "Joint dynamics").

    Friction holds the largest gravity load within 5 % of the range around the state (the whole range when
    holding position) and where gravity pushes the part open at :data:`CLOSED_HOLD_FRACTIONS`; a spring gets
    k = max(3 x 1.5 x hold / range, 2 k_g), reference q_s = q - tau_g / k, and friction 10 % of the load. A shut
    door, drawer or lid has its catch (:func:`catch`). Any other part of an object that is set down (:func:`set_down`),
    open or shut, is also held at the set-down's lean (:func:`physics.lean_load`, x :data:`physics.LEAN_SAFETY`) and
    stopped after its drop (:func:`physics.impact_friction`), as a real hinge or slide holds a part where it was
    left when its object is put down; a part its weight presses onto a stop (:func:`_on_stop`: its open end or its
    closed end, within the SPEC's drift of it) is held there by the stop, its friction only against a lean that
    lifts it off (g sin 5 deg |w_h| - |tau_g| cos 5 deg). A spring or a balance carries its part's load, and a part
    that moves freely is left free.
    """
    prismatic = {j.name for j in ctx.asset.movable_joints() if j.type == "prismatic"}
    rot = ctx.root_rotation
    loads = physics.joint_loads(ctx.session, ctx.asset, links, state, scale, ctx.subtrees, root_rotation=rot)
    out: dict[str, JointDynamics] = {}
    for j in ctx.asset.movable_joints():
        name = j.name
        ch = choices.get(name, JointChoice())
        cs = ctx.closed[name]
        unit = scale if name in prismatic else 1.0
        if ch.holds_position:
            fr = np.linspace(0.0, 1.0, 11)
        else:
            f0 = cs.fraction(state[name] / unit)
            fr = np.clip([f0 - 0.05, f0, f0 + 0.05], 0.0, 1.0)
        hold = 0.0
        for f in fr:
            st = {**state, name: cs.position(float(f)) * unit}
            ld = physics.joint_loads(ctx.session, ctx.asset, links, st, scale, {name: ctx.subtrees[name]}, root_rotation=rot)
            hold = max(hold, abs(ld[name].gravity_load))
        # a part stays shut once closed: friction also holds a load pushing it open near its closed end
        for f in CLOSED_HOLD_FRACTIONS:
            st = {**state, name: cs.position(float(f)) * unit}
            ld = physics.joint_loads(ctx.session, ctx.asset, links, st, scale, {name: ctx.subtrees[name]}, root_rotation=rot)
            if ld[name].gravity_load * cs.direction > 0:
                hold = max(hold, abs(ld[name].gravity_load))
        spring = None
        note = source
        if ch.spring:
            load = loads[name]
            k = max(3.0 * physics.HOLD_SAFETY * max(hold, 1e-6) / max(cs.open_range * unit, 1e-6), load.gravity_stiffness * 2.0)
            ref = float(np.clip(state[name] - load.gravity_load / k, cs.lower * unit, cs.upper * unit))
            spring = (k, ref)
            hold = 0.1 * hold  # the spring carries the load; friction only adds feel
        elif name not in prismatic and not ch.free_moving and _label(ctx, name) in COUNTERBALANCE_LABELS:
            counter = counterbalance(ctx, links, state, scale, name, fr)
            if counter is not None:
                spring, hold, why = counter
                note = f"{source}; {why}"
        elif name in prismatic and not ch.free_moving and _label(ctx, name) in BALANCE_LABELS:
            bal = balance(loads[name], cs, unit)
            if bal is not None:
                spring, hold, why = bal
                note = f"{source}; {why}"
        latch = None if (ch.spring or ch.free_moving) else catch(ctx, links, state, scale, name)
        impact = 0.0
        if spring is None and latch is None and not ch.free_moving and set_down(ctx):
            # a part of a free-standing object without a catch is held by its friction where it was left when the
            # object is set down; one its weight presses onto a stop is held by the stop, friction only against a
            # lean that lifts it off
            ld = loads[name]
            at_stop = _on_stop(ld, cs, state[name], unit, physics.SET_DOWN_DRIFT["prismatic" if name in prismatic else "revolute"])
            hold = max(hold, physics.LEAN_SAFETY / physics.HOLD_SAFETY * physics.lean_load(ld, on_stop=at_stop))
            impact = 0.0 if at_stop else physics.impact_friction(ld, prismatic=name in prismatic)
        dyn = physics.joint_dynamics(loads[name], hold, prismatic=name in prismatic, damping_level=ch.damping_level, stiff=ch.stiff,
                                     free_moving=ch.free_moving, spring=spring, source=note, impact=impact)
        if latch is not None:
            force, position, zone, why = latch
            dyn = dyn.model_copy(update={"catch_force": force, "catch_position": position, "catch_zone": zone,
                                         "source": f"{dyn.source}; {why}"})
        out[name] = dyn
    return out


def _on_stop(load: physics.JointLoad, cs: ClosedState, q: float, unit: float, drift: float) -> bool:
    """Whether a part at ``q`` (rad or m) rests on the stop its weight presses it onto: its gravity load
    ``load.gravity_load`` pushes it open and it lies within ``drift`` (rad or m) of its open end, or it pushes it
    shut and it lies within ``drift`` of its closed end (``cs``'s ends in unscaled units x ``unit``)."""
    push = load.gravity_load * cs.direction
    end = cs.position(1.0) if push > 0 else cs.position(0.0) if push < 0 else None
    return end is not None and abs(end * unit - q) <= drift


#: Holding forces of catches at a part's closed end, N: magnetic cabinet catches pull 2-8 lb (8.9-35.6 N;
#: Monroe Engineering, "Magnetic catches: what is pull force and why does it matter"; light-duty catches for small
#: doors 4-6 lb, engineerfix.com, chosen "to hold the door closed without making it difficult to open").
CATCH_FORCE_N = (8.9, 35.6)
#: A catch is chosen to keep its part shut when the object leans this much (rad): the SPEC's robust-rest tilt,
#: 5 deg, an uneven floor or a bump ...
CATCH_LEAN = math.radians(5.0)
#: ... with this margin on the part's weight along its travel (dimensionless).
CATCH_LEAN_MARGIN = 2.0
#: Travel over which a drawer's stay-closed slide pulls it shut, m: the last 2 in (AWS Architectural Woodwork
#: Standards, 1st ed. 2009, Appendix B, drawer slide selection guide: "self closing / stay closed").
CATCH_ZONE_SLIDE_M = 0.0508
#: Gap at a hinged part's edge within which a magnetic catch pulls it shut, m (estimate: a catch's pull falls
#: to a small part of its rating within a few millimetres of the strike plate).
CATCH_ZONE_HINGE_M = 0.005
#: Shortest catch zone kept (at the catch), m: a state this near the closed end sits on the catch itself.
CATCH_ZONE_MIN_M = 0.001
#: Largest share of the opening travel a catch zone takes (a small drawer's catch acts near its closed end only).
CATCH_ZONE_RANGE_SHARE = 0.25
#: Largest opening fraction of a requested state at which a part gets its catch: the closed band's top
#: (schemas.request BAND_INTERVAL["closed"]); a part asked open is held by its friction, which its catch's
#: breakaway would only take budget from.
CATCH_STATE_FRACTION = BAND_INTERVAL["closed"][1]
#: Parts that close an opening and carry a catch (canonical labels; push buttons and knobs have none).
CATCH_LABELS = frozenset({"door", "drawer", "lid"})
#: Largest natural frequency of a catch's pull on its part, rad/s: 0.5 / dt at the SPEC's dt = 1/240 s (an
#: explicit joint force any stiffer than that diverges); a catch that would be stiffer is not modelled.
CATCH_MAX_RATE = 0.5 * 240.0


def catch(ctx: EstimationContext, links: dict[str, LinkPhysics], state: dict[str, float], scale: float,
          name: str) -> tuple[float, float, float, str] | None:
    """The catch that holds a door, drawer or lid (:data:`CATCH_LABELS`) at its closed end where its own
    weight does not (a drawer, a side-hinged door, a drop-down door): F at the part's front (prismatic, N) or
    at its far edge r from the axis (revolute, F r N m), F = :data:`CATCH_LEAN_MARGIN` x the part's weight
    along its travel at a lean of :data:`CATCH_LEAN` (half of it at a hinge's edge), within the magnetic
    catches' :data:`CATCH_FORCE_N`, pulling it shut over
    :data:`CATCH_ZONE_SLIDE_M` (a stay-closed slide) or :data:`CATCH_ZONE_HINGE_M` / r rad (a magnetic catch
    at the edge), at most :data:`CATCH_ZONE_RANGE_SHARE` of the travel; only where the request leaves the part
    closed (:data:`CATCH_STATE_FRACTION`). None for other parts, parts without a range,
    parts whose weight presses them shut with at least the catch's force (a lid), a zone under
    :data:`CATCH_ZONE_MIN_M`, and a catch stiffer than :data:`CATCH_MAX_RATE` allows for the part's inertia.

    Returns:
        (force N or N m, closed end rad or m, zone rad or m signed with the opening direction, note), or None.
    """
    j = ctx.asset.joint(name)
    cs = ctx.closed[name]
    if j.type not in ("revolute", "prismatic") or not cs.open_range > 0 or _label(ctx, name) not in CATCH_LABELS:
        return None
    prismatic = j.type == "prismatic"
    unit = scale if prismatic else 1.0
    if prismatic:
        lever, zone_m = 1.0, CATCH_ZONE_SLIDE_M
    else:
        pts = ctx.hull_points.get(j.child)
        if pts is None or not len(pts):
            return None
        a = np.asarray(j.axis, float) / max(float(np.linalg.norm(j.axis)), 1e-12)
        p = np.asarray(pts, float) * scale
        lever = float(np.linalg.norm(p - np.outer(p @ a, a), axis=1).max())
        if not lever > 0:
            return None
        zone_m = CATCH_ZONE_HINGE_M
    st = {**state, name: cs.position(0.0) * unit}
    load = physics.joint_loads(ctx.session, ctx.asset, links, st, scale, {name: ctx.subtrees[name]}, root_rotation=ctx.root_rotation)
    # the part's weight along its travel when the object leans: all of it for a slide, about half at a hinge's
    # far edge (its centre of mass half way out)
    lean = CATCH_LEAN_MARGIN * load[name].mass * physics.G * math.sin(CATCH_LEAN) * (1.0 if prismatic else 0.5)
    force = float(np.clip(lean, *CATCH_FORCE_N))
    torque = force * lever
    if -load[name].gravity_load * cs.direction >= torque:  # its weight is its catch
        return None
    if cs.fraction(state[name] / unit) > CATCH_STATE_FRACTION:  # asked open: friction holds it, a catch only costs
        return None
    zone_m = min(zone_m, CATCH_ZONE_RANGE_SHARE * cs.open_range * unit * lever)  # a small part's catch acts near its end
    if zone_m < CATCH_ZONE_MIN_M:
        return None
    zone = cs.direction * zone_m / lever
    inertia = load[name].inertia_axis
    if not inertia > 0 or torque / abs(zone) > inertia * CATCH_MAX_RATE**2:  # too stiff for its inertia at dt
        return None
    why = (f"catch at the closed end ({'stay-closed slide' if prismatic else 'magnetic catch at the far edge'}): "
           f"{force:.3g} N{'' if prismatic else f' at {lever:.3g} m = {torque:.3g} N m'} over {zone_m * 1000:.3g} mm "
           f"(holds the part shut when the object leans {math.degrees(CATCH_LEAN):g} deg, x{CATCH_LEAN_MARGIN:g}, "
           f"within magnetic catches' {CATCH_FORCE_N[0]:g}-{CATCH_FORCE_N[1]:g} N)")
    return float(torque), float(cs.position(0.0) * unit), float(zone), why


#: Parts that carry a counterbalance spring when they open downward (canonical labels: a door, a drop-front
#: lid; a toggle or a lever is thrown over its centre instead).
COUNTERBALANCE_LABELS = frozenset({"door", "lid"})


def set_down(ctx: EstimationContext) -> bool:
    """Whether the object stands free and is set down (the SPEC's robust rest drops and leans it): not when
    its root is fixed (a mounted object: ``ctx.mounting``)."""
    return not (ctx.mounting is not None and ctx.mounting.fixed)


def _label(ctx: EstimationContext, joint: str) -> str | None:
    """Canonical part label of ``joint``'s child link, None when unlabelled."""
    child = ctx.asset.joint(joint).child
    return priors.canonical_label(next((ln.semantic_label for ln in ctx.asset.links if ln.name == child), None))


#: Opening fractions at which gravity must push a part open for it to count as opening downward (:func:`counterbalance`).
DOWNWARD_FRACTIONS = (0.25, 0.5, 0.75, 1.0)


def counterbalance(ctx: EstimationContext, links: dict[str, LinkPhysics], state: dict[str, float], scale: float,
                   name: str, hold_fractions) -> tuple[tuple[float, float], float, str] | None:
    """The counterbalance spring of a hinged door or lid (:data:`COUNTERBALANCE_LABELS`) that opens downward (an
    oven's or a dishwasher's drop-down door, a drop-front desk lid): gravity pushes it open at every one of
    :data:`DOWNWARD_FRACTIONS`. Such doors
    carry their weight on door-balance springs (torsion or extension springs through a link, in every
    consumer range and dishwasher); modelled as a torsion spring about the hinge with its rest position at
    the closed end and the rate k = |tau_g(open end)| / R that balances the weight moment fully open (R the
    opening range, rad). Friction then holds only what the spring leaves: the largest |tau_g + tau_s| over
    ``hold_fractions`` and the closed end.

    Returns:
        ((k N m/rad, q_s rad), hold load N m, note), or None when the part does not open downward.
    """
    cs = ctx.closed[name]
    rot = ctx.root_rotation
    sub = {name: ctx.subtrees[name]}

    def load(f: float) -> float:
        st = {**state, name: cs.position(float(f))}
        return physics.joint_loads(ctx.session, ctx.asset, links, st, scale, sub, root_rotation=rot)[name].gravity_load

    open_loads = [load(f) * cs.direction for f in DOWNWARD_FRACTIONS]
    if not all(t > 0 for t in open_loads) or not cs.open_range > 0:
        return None
    k = open_loads[-1] / cs.open_range
    q_s = cs.position(0.0)
    fractions = sorted({*(float(f) for f in hold_fractions), *CLOSED_HOLD_FRACTIONS})
    hold = max(abs(load(f) * cs.direction - k * f * cs.open_range) for f in fractions)
    why = (f"counterbalance spring of a door opening downward (door-balance springs of ranges and dishwashers): "
           f"k = {k:.4g} N m/rad at rest closed balances the {open_loads[-1]:.3g} N m weight moment fully open")
    return (float(k), float(q_s)), float(hold), why


#: Parts on a vertical slide that ride on a balance (canonical labels): a hung window's sash (coil "constant
#: force" balances, block-and-tackle and spiral balances, or sash weights on cords, each sized to the sash's weight:
#: Swisco, "How to choose the appropriate coil balance strength"; Nationwide Windows glossary, "Sash balance") and a
#: vertical-lift door (the counterbalance springs of overhead and lift-up doors).
BALANCE_LABELS = frozenset({"window", "door"})
#: Least share of a part's weight along its travel for it to ride on a balance: a travel within 60 deg of vertical.
BALANCE_MIN_SHARE = 0.5
#: Variation of a balance's force over the travel, +- share of the part's weight: constant-load supports hold their
#: set load within +-6 % over their whole travel (MSS SP-58, pipe hangers and supports). A constant-force spring's
#: near-constant pull comes from a long, preloaded travel (a coiled steel tape), so the balance is the linear spring
#: whose reference lies far beyond the part's travel and whose force changes by this share from end to end.
BALANCE_VARIATION = 0.06


def balance(load: physics.JointLoad, cs: ClosedState, unit: float) -> tuple[tuple[float, float], float, str] | None:
    """The balance of a part on a vertical slide (:data:`BALANCE_LABELS`): a sash balance of a hung window, a
    lift-up door's counterbalance. Its pull equals the part's weight along the travel at mid-travel and varies
    by +- :data:`BALANCE_VARIATION` of it from end to end: k = 2 v |F_g| / R (N/m, R the travel in m) about the
    reference q_s = q_mid - F_g / k (m, beyond the travel: the preload of a constant-force spring), so friction
    holds only the imbalance v |F_g| at the ends.

    Args:
        load: the joint's loads at the initial state (output units; ``gravity_load`` F_g N along the axis).
        cs: the joint's closed end (input units); ``unit``: the scale s that turns them into metres.

    Returns:
        ((k N/m, q_s m), hold load N, note), or None when the weight along the travel is under
        :data:`BALANCE_MIN_SHARE` of the part's weight or the joint has no travel.
    """
    weight = load.mass * physics.G
    travel = cs.open_range * unit
    if not (travel > 0 and weight > 0 and abs(load.gravity_load) >= BALANCE_MIN_SHARE * weight):
        return None
    k = 2.0 * BALANCE_VARIATION * abs(load.gravity_load) / travel
    q_s = cs.position(0.5) * unit - load.gravity_load / k
    hold = BALANCE_VARIATION * abs(load.gravity_load)
    why = (f"balance of a part on a vertical slide (sash balances of hung windows, counterbalances of lift-up doors): "
           f"k = {k:.4g} N/m about {q_s:.4g} m carries the {abs(load.gravity_load):.3g} N weight at mid-travel, "
           f"+-{BALANCE_VARIATION:.0%} from end to end")
    return (float(k), float(q_s)), float(hold), why


#: Opening fractions near the closed end where friction also holds a joint gravity pushes open (probes release at <= 0.10).
CLOSED_HOLD_FRACTIONS = (0.0, 0.05, 0.10)


def band_intervals(bands: dict[str, str], intervals: dict[str, tuple[float, float]] | None = None) -> dict[str, tuple[float, float]]:
    """Allowed opening-fraction interval per joint for its band; ``intervals`` (asked numbers or ends) win."""
    out = {name: BAND_INTERVAL[b] for name, b in bands.items()}
    out.update(intervals or {})
    return out
