"""Joint dynamics of an overlay (SPEC stage 2): the qualitative choices the
request's motion words make per joint (:class:`JointChoice`, :func:`motion_choices`)
and the numbers :func:`joint_dynamics_for` makes of them from the loads the input's
kinematics give: friction that holds, closers, counterbalances, lid supports, sash
balances, slides, and the set-down's lean and landings (``docs/design/refine.md``,
"Joint dynamics"). Loads in N m (revolute) or N (prismatic), output units.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from asset2sim.engines.base import SimSession
from asset2sim.schemas.overlay import Holding, JointDynamics, LinkPhysics
from asset2sim.schemas.request import MotionPhrase
from asset2sim.tasks.geometry.closed_state import ClosedState
from asset2sim.prior_tables import load_priors
from asset2sim.tasks.interpret.part_labels import canonical_label
from asset2sim.tasks.interpret.part_priors import spring_expected
from asset2sim.tasks.interpret.named_parts import joints_of, moving_parts
from asset2sim.tasks.interpret.operating_forces import operating_range
from asset2sim.tasks.synthesize import physics, request_apply, set_down
from asset2sim.tasks.synthesize.context import EstimationContext


@dataclass
class JointChoice:
    """Qualitative dynamics choices for one joint; :func:`joint_dynamics_for` turns them into numbers."""

    damping_level: str = "moderate"
    holds_position: bool = False
    spring: bool = False
    stiff: bool = False
    free_moving: bool = False
    self_closing: bool = False
    """a spring that returns the part to its closed end (a door closer, a self-closing slide)"""
    words: tuple[MotionPhrase, ...] = ()
    """the request's words about this part's motion that made these choices"""
    state_asked: bool = True
    """whether the request asks a state of this part: one asked to move freely and given none has no friction that
    holds it against its weight (it starts where its weight leaves it: ``tasks/refine.py``, ``_attempt``)"""


#: The holding mechanism of a part asked to move freely at a state its own weight moves it from (the load there above
#: a free part's friction floor, :func:`~asset2sim.tasks.synthesize.physics.friction_floor`): friction holds it where
#: it was asked, which a freely moving part lacks; the as-asked tier names the conflict between the two phrases
#: (SPEC, robust rest; :func:`asset2sim.tasks.check.as_asked.as_asked_tier`).
HELD_AGAINST_FREE = "held by friction against its weight (asked to move freely)"

#: Damping level each motion word asks (the last of a part's words wins, as the parser's damping does).
WORD_DAMPING = {"free": "low", "low_damping": "low", "high_damping": "high", "soft_close": "high", "moderate_damping": "moderate"}


def motion_choices(ctx: EstimationContext, relevant: list[str] | set[str]) -> tuple[dict[str, JointChoice], list[tuple[str, str]]]:
    """(joint -> :class:`JointChoice`, (phrase, why) of each word naming a part the object lacks) from the request's
    words about motion (``ctx.request.motions``): a word naming a part applies to that part's joints, or to the one
    its ordinal names ("the main door": :func:`~asset2sim.tasks.interpret.named_parts.joints_of`), one naming none to
    the ``relevant`` joints (the
    task's parts). A relevant joint's category may expect a return spring (a stapler's arm; ``categories.yaml``
    ``spring_labels``); a self-closing part gets high damping unless a word says otherwise (a door closer is a spring
    and a hydraulic damper)."""
    relevant = list(relevant)
    applied: dict[str, list[MotionPhrase]] = {j.name: [] for j in ctx.asset.movable_joints()}
    missing = []
    for word in ctx.request.motions:
        why: list[str] = []
        names = joints_of(ctx, word, relevant, why)
        if word.label is not None and not names:
            missing.append((word.phrase, why[-1].removeprefix("WARNING: ") if why else
                            f"names a '{word.label}' but this {ctx.category} has no such moving part (its moving parts: {moving_parts(ctx)})"))
        for n in names:
            if n in applied:
                applied[n].append(word)
    out = {}
    for j in ctx.asset.movable_joints():
        words = applied[j.name]
        kinds = {w.kind for w in words}
        levels = [WORD_DAMPING[w.kind] for w in words if w.kind in WORD_DAMPING]
        closing = "self_closing" in kinds
        label = ctx.asset.link(j.child).semantic_label
        out[j.name] = JointChoice(
            damping_level=levels[-1] if levels else ("high" if closing else "moderate"), holds_position="hold" in kinds,
            spring=bool(kinds & {"spring", "self_closing"}) or (j.name in relevant and spring_expected(ctx.category, label)),
            stiff="stiff" in kinds, free_moving="free" in kinds, self_closing=closing, words=tuple(words))
    return out, missing


def joint_dynamics_for(ctx: EstimationContext, kin: SimSession, links: dict[str, LinkPhysics], state: dict[str, float],
                       scale: float, choices: dict[str, JointChoice], *, source: str) -> dict[str, JointDynamics]:
    """Damping, friction and stiffness of every movable joint from the scaled masses and the kinematics at
    ``state`` (output units; ``kin``, the input's kinematics session, posed for the loads and landings), shaped
    by ``choices`` (``docs/design/refine.md``, "Joint dynamics").

    Friction holds the largest gravity load within 5 % of the range around the state (the whole range when
    holding position) and where gravity pushes the part open at :data:`CLOSED_HOLD_FRACTIONS`; a spring gets
    k = max(3 x 1.5 x hold / range, 2 k_g), reference q_s = q - tau_g / k, and friction 10 % of the load. Any
    other part of a free-standing object (:func:`free_standing`), open or shut, is also held at the set-down's lean
    (:func:`~asset2sim.tasks.synthesize.set_down.lean_load`, x ``set_down.LEAN_SAFETY``) and stopped within its
    band after each landing of the drop and the tilts (:func:`~asset2sim.tasks.synthesize.set_down.landing_friction`),
    as a real hinge or slide holds a part where it was left when its object is put down; a part its weight presses
    onto a stop (:func:`_on_stop`: its open end or its closed end, within its band) is held there by the stop, its
    friction only against a lean that lifts it off (g sin 5 deg |w_h| - |tau_g| cos 5 deg), and a landing that
    moves a part into a stop moves nothing. A spring or a balance carries its part's load, and a part that moves
    freely is left free of the friction that holds it: a word about friction or damping ("slides easily") never
    removes the counterbalance or sash balance that holds a part against gravity.
    """
    prismatic = {j.name for j in ctx.asset.movable_joints() if j.type == "prismatic"}
    rot = ctx.root_rotation
    loads = physics.joint_loads(kin, links, state, scale, ctx.subtrees, root_rotation=rot)
    landed = (set_down.landings(kin, links, state, scale, ctx.subtrees, ctx.hull_points, root_rotation=rot)
              if free_standing(ctx) else {})
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
        hold, at_closed = 0.0, 0.0
        # a part stays shut once closed: friction also holds a load pushing it open near its closed end
        for f, near_closed in [*((f, False) for f in fr), *((f, True) for f in CLOSED_HOLD_FRACTIONS)]:
            st = {**state, name: cs.position(float(f)) * unit}
            ld = physics.joint_loads(kin, links, st, scale, {name: ctx.subtrees[name]}, root_rotation=rot)
            if near_closed and f == 0.0:
                at_closed = ld[name].gravity_load
            if not near_closed or ld[name].gravity_load * cs.direction > 0:
                hold = max(hold, abs(ld[name].gravity_load))
        band = set_down.joint_band(cs.lower * unit, cs.upper * unit, name in prismatic)
        on_stop = _on_stop(loads[name], cs, state[name], unit, band)
        if ch.free_moving and (on_stop or not ch.state_asked):
            hold = 0.0  # asked to move freely, and resting on the stop its weight presses it onto or given no state
        spring, balanced = None, False
        mechanism = "moves freely (asked)" if ch.free_moving else ("friction slide" if name in prismatic else "friction hinge")
        if ch.free_moving and ch.state_asked and not on_stop and abs(loads[name].gravity_load) > physics.friction_floor(
                loads[name], name in prismatic, True):
            mechanism = HELD_AGAINST_FREE
        note = source + "".join(f"; request '{w.phrase}': {w.kind.replace('_', ' ')}" for w in ch.words)
        if ch.self_closing:
            held = closer(ctx, loads[name], cs, unit, hold, at_closed, stopped_shut(ctx, kin, state, scale, name))
            spring, hold = held.spring, held.hold
            note, mechanism = f"{note}; {held.note}", "closer"
        elif ch.spring:
            load = loads[name]
            k = max(3.0 * physics.HOLD_SAFETY * max(hold, 1e-6) / max(cs.open_range * unit, 1e-6), load.gravity_stiffness * 2.0)
            ref = float(np.clip(state[name] - load.gravity_load / k, cs.lower * unit, cs.upper * unit))
            spring, mechanism = (k, ref), "return spring"
            hold = 0.1 * hold  # the spring carries the load; friction only adds feel
        elif name not in prismatic and _label(ctx, name) in COUNTERBALANCE_LABELS:  # a word about friction keeps it
            counter = counterbalance(ctx, kin, links, state, scale, name, fr) or lid_support(ctx, kin, links, state, scale, name, fr)
            if counter is not None:
                spring, hold = counter.spring, counter.hold
                note, balanced, mechanism = f"{note}; {counter.note}", True, counter.note.split(" (")[0]
        elif name in prismatic and _label(ctx, name) in BALANCE_LABELS:  # "slides easily" is friction, not the balance
            bal = balance(loads[name], cs, unit)
            if bal is not None:
                spring, hold = bal.spring, bal.hold
                note, balanced, mechanism = f"{note}; {bal.note}", True, "balance"
        impact, static, landing = 0.0, hold, ""
        if (spring is None or balanced) and not ch.free_moving and name in landed:
            # a part of a free-standing object is held by its friction where it was left when the object is set
            # down; one its weight presses onto a stop is held by the stop, friction only against a lean that lifts
            # it off (a balanced part's spring carries its weight: only the lean's sideways share is left); each
            # landing's energy is taken within its band, unless it moves the part into a stop
            ld = loads[name]
            lean = (set_down.lean_load(ld) - abs(ld.gravity_load) * math.cos(set_down.SET_DOWN_LEAN) if balanced
                    else set_down.lean_load(ld, on_stop=on_stop))
            hold, static = max(hold, set_down.LEAN_SAFETY / physics.HOLD_SAFETY * lean), max(static, lean)
            impact, landing = set_down.landing_friction(landed[name], band, _stops(cs, state[name] / unit, band / unit),
                                                        0.0 if balanced else ld.gravity_load)
        slide = name in prismatic and _label(ctx, name) in SLIDE_LABELS and not ch.free_moving
        dyn = physics.joint_dynamics(loads[name], hold, prismatic=name in prismatic, damping_level=ch.damping_level, stiff=ch.stiff,
                                     free_moving=ch.free_moving, spring=spring, source=note, impact=impact, floor=not slide,
                                     stiff_least=stiff_least(ctx, name, scale, name in prismatic) if ch.stiff and spring is None else 0.0)
        if slide:
            rides = slide_for(dyn.friction, loads[name].mass * physics.G, requested_slide(ch.words))
            dyn = dyn.model_copy(update={"friction": rides.friction, "source": f"{dyn.source}; {rides.note}"})
            mechanism = f"{rides.kind.replace('_', ' ')} slides"
        elif mechanism == "friction hinge" and not static > 0:
            mechanism = "free hinge"
        out[name] = dyn.model_copy(update={"holding": Holding(mechanism=mechanism, static_load=float(static),
                                                              landing=float(impact), landing_trial=landing)})
    return out


@dataclass(frozen=True, slots=True)
class SpringHold:
    """A part held by a spring (a closer, a counterbalance, a lid support, a sash balance): ``spring`` (k N m/rad
    or N/m, reference q_s rad or m), ``hold`` (the load friction still holds, N m or N) and ``note`` (one line)."""

    spring: tuple[float, float]
    hold: float
    note: str


@dataclass(frozen=True, slots=True)
class SlideChoice:
    """The slide a drawer rides on (:func:`slide_for`): ``kind`` (``slides.yaml`` key), ``friction`` (N) and
    ``note`` (one line)."""

    kind: str
    friction: float
    note: str


#: Share of a closer's preload that friction may take, so that it still returns the part to its closed end.
CLOSER_FRICTION_SHARE = 0.2
#: Share of its range within which a part's closed end counts as on the limit a closer presses it onto.
CLOSER_STOP_SHARE = 0.01


def closer(ctx: EstimationContext, load: physics.JointLoad, cs: ClosedState, unit: float, hold: float,
           closed_load: float = 0.0, stopped: bool = True) -> SpringHold:
    """The spring of a self-closing part (a door closer, a self-closing lid or slide): it presses the part into its
    closed end with a preload F0 = max(``physics.HOLD_SAFETY`` x ``hold``, ``set_down.LEAN_SAFETY`` x the set-down
    lean's load) and pulls twice that at its far end: rate k = F0 / R about a reference one range R beyond the
    closed end (a preloaded closer spring; door closers are adjustable in size 1-6 by the door's width and weight,
    EN 1154), so that the part returns shut from anywhere in its range against friction of at most
    :data:`CLOSER_FRICTION_SHARE` x F0.

    A part with no stop at its closed end (``stopped`` False: neither its limit there nor another part, as a lid rests
    on its box's rim, :func:`stopped_shut`; a handle or lever that turns on past it, a joint without limits: nothing
    for a preload to press it onto) gets a return spring centred on its closed end instead, as spring-return handles
    and levers have: it pulls twice F0 at the far end, stiffer where that lets the set-down lean move it more than half
    its robust-rest band, against friction of :data:`CLOSER_FRICTION_SHARE` x its pull at the band's edge, so that it
    comes back within its band; its reference q_s = q_closed - ``closed_load`` / k carries the part's weight there
    (``closed_load``: the gravity load at the closed end, N m or N, as :func:`physics.joint_loads` signs it).

    Returns:
        the spring and the friction's hold load.
    """
    rng = max(cs.open_range * unit, 1e-9)
    lean = set_down.lean_load(load)
    preload = max(physics.HOLD_SAFETY * hold, set_down.LEAN_SAFETY * lean, 1e-6)
    prismatic = ctx.asset.joint(load.joint).type == "prismatic"
    closed_at = cs.position(0.0) * unit
    if stopped:
        k = preload / rng
        ref = float(closed_at - cs.direction * rng)
        why = (f"self-closing: a closer spring presses it shut with {preload:.3g} {'N' if prismatic else 'N m'} "
               f"(k = {k:.4g} about {ref:.4g}, twice that fully open)")
        return SpringHold((float(k), ref), CLOSER_FRICTION_SHARE * preload / physics.HOLD_SAFETY, why)
    band = set_down.joint_band(cs.lower * unit, cs.upper * unit, prismatic)
    k = max(2.0 * preload / rng, set_down.LEAN_SAFETY * lean / (0.5 * band))
    why = (f"self-closing: its closed end {closed_at:.4g} is no stop (it {'slides' if prismatic else 'turns'} on past it), so a "
           f"return spring centred there, k = {k:.4g} {'N/m' if prismatic else 'N m/rad'}, returns it within its band")
    return SpringHold((float(k), float(closed_at - closed_load / k)), CLOSER_FRICTION_SHARE * k * band / physics.HOLD_SAFETY,
                      why)


def stopped_shut(ctx: EstimationContext, kin: SimSession, state: dict[str, float], scale: float, name: str) -> bool:
    """Whether something stops joint ``name``'s part at its closed end (``ctx.closed``): the end is on its limit
    (within :data:`CLOSER_STOP_SHARE` of its range), or, posed that share of its range past it in ``kin`` (the input's
    kinematics session; the other joints at ``state``, output units at ``scale``), the part's links sit deeper in
    another link of the object (parent included: a lid on its box's rim) than at the closed end, by more than
    :data:`STOP_DEPTH_SHARE` of the travel of its far edge (a hinge) or of the part (a slide). The session is left
    at ``state``."""
    cs = ctx.closed[name]
    limit = cs.lower if cs.direction > 0 else cs.upper
    step = CLOSER_STOP_SHARE * cs.open_range
    if not np.isfinite(limit) or abs(cs.q_closed - limit) <= step:
        return bool(np.isfinite(limit))
    kinds = {j.name: j.type for j in ctx.asset.movable_joints()}
    base = {j: (q / scale if kinds.get(j) == "prismatic" else q) for j, q in state.items() if j in kinds}
    mine = [ln for ln in ctx.subtrees[name] if kin.link_has_collision(ln)]
    others = [ln.name for ln in ctx.asset.links if ln.name not in ctx.subtrees[name] and kin.link_has_collision(ln.name)]

    def depth(q: float) -> float:
        kin.set_joint_positions({**base, name: q})
        return max((-min(kin.link_distances(a, b, 0.0), default=0.0) for a in mine for b in others), default=0.0)

    travel = step * (1.0 if kinds[name] == "prismatic" else far_edge(ctx, name, 1.0))
    sinks = depth(cs.q_closed - cs.direction * step) - depth(cs.q_closed)
    kin.set_joint_positions(base)
    return sinks > STOP_DEPTH_SHARE * travel


#: Share of a part's travel past its closed end that it must sink further into another link for that end to count as
#: a stop (:func:`stopped_shut`): a lid turned past its box's rim sinks into it by nearly all of its far edge's travel.
STOP_DEPTH_SHARE = 0.25


def _on_stop(load: physics.JointLoad, cs: ClosedState, q: float, unit: float, drift: float) -> bool:
    """Whether a part at ``q`` (rad or m) rests on the stop its weight presses it onto: its gravity load
    ``load.gravity_load`` pushes it open and it lies within ``drift`` (rad or m) of its open end, or it pushes it
    shut and it lies within ``drift`` of its closed end (``cs``'s ends in unscaled units x ``unit``)."""
    push = load.gravity_load * cs.direction
    end = cs.position(1.0) if push > 0 else cs.position(0.0) if push < 0 else None
    return end is not None and abs(end * unit - q) <= drift


#: Parts that slide on drawer slides or runners (canonical labels; ``asset2sim/priors/slides.yaml``).
SLIDE_LABELS = frozenset({"drawer", "tray", "shelf"})


def requested_slide(words) -> str | None:
    """The kind of slide the request's words about a part name (the last; ``slides.yaml`` key), or None."""
    return next((w.mechanism for w in reversed(list(words)) if w.kind == "slides"), None)


def slide_for(friction: float, weight: float, requested: str | None = None) -> SlideChoice:
    """The slide a drawer rides on (``asset2sim/priors/slides.yaml``, smoothest first):
    the ``requested`` kind, else the first whose upper coefficient carries the ``friction`` (N) holding needs; the
    friction moved into that kind's range, mu_lo to mu_hi of the drawer's ``weight`` (N, its normal load on a
    horizontal slide). Where no kind carries it, the stiffest at its upper end: the check then says what remains."""
    table = load_priors().slides
    kinds = list(table.items())
    key, sp = next(((k, v) for k, v in kinds if k == requested), None) or next(
        ((k, v) for k, v in kinds if v.friction_coefficient[1] * weight >= friction), kinds[-1])
    lo, hi = (c * weight for c in sp.friction_coefficient)
    f = float(np.clip(friction, lo, hi))
    why = (f"{key.replace('_', ' ')} slides ({'as asked' if requested else 'the smoothest that holds it'}: mu "
           f"{sp.friction_coefficient[0]:g}-{sp.friction_coefficient[1]:g} of its {weight:.3g} N weight; {sp.source.strip()}): "
           f"friction {f:.3g} N = mu {f / max(weight, 1e-12):.3g}" + (f" (holding asked {friction:.3g} N)" if abs(f - friction) > 1e-9 else ""))
    return SlideChoice(key, f, why)


def slide_cap(ctx: EstimationContext, joint: str, mass: float) -> float | None:
    """The most friction (N) a drawer-like part (:data:`SLIDE_LABELS`) of ``mass`` kg may have: the upper end of the
    kind of slide the request names for it, else of the stiffest kind (no real slide is stiffer); None for other
    joints."""
    if ctx.asset.joint(joint).type != "prismatic" or _label(ctx, joint) not in SLIDE_LABELS:
        return None
    choices, _ = motion_choices(ctx, request_apply.task_relevant_joints(ctx))
    table = load_priors().slides
    key = requested_slide(choices[joint].words) if joint in choices else None
    sp = table[key] if key in table else list(table.values())[-1]
    return float(sp.friction_coefficient[1] * mass * physics.G)


def _stops(cs: ClosedState, q: float, band: float) -> tuple[bool, bool]:
    """(down, up): whether a part at ``q`` rests on its lower / upper limit (within ``band``; ``cs``'s limits and ``q``,
    ``band`` in the same units), so that a landing moving it that way moves nothing."""
    return bool(q - cs.lower <= band), bool(cs.upper - q <= band)


#: Parts that carry a counterbalance spring when they open downward (canonical labels: a door, a drop-front
#: lid; a toggle or a lever is thrown over its centre instead).
COUNTERBALANCE_LABELS = frozenset({"door", "lid"})


def free_standing(ctx: EstimationContext) -> bool:
    """Whether the object stands free and is set down (the SPEC's robust rest drops and leans it): not when
    its root is fixed (a mounted object: ``ctx.mounting``)."""
    return not (ctx.mounting is not None and ctx.mounting.fixed)


def _label(ctx: EstimationContext, joint: str) -> str | None:
    """Canonical part label of ``joint``'s child link, None when unlabelled."""
    return canonical_label(ctx.asset.link(ctx.asset.joint(joint).child).semantic_label)


#: Opening fractions at which gravity must push a part open for it to count as opening downward (:func:`counterbalance`).
DOWNWARD_FRACTIONS = (0.25, 0.5, 0.75, 1.0)


def counterbalance(ctx: EstimationContext, kin: SimSession, links: dict[str, LinkPhysics], state: dict[str, float],
                   scale: float, name: str, hold_fractions) -> SpringHold | None:
    """The counterbalance spring of a hinged door or lid (:data:`COUNTERBALANCE_LABELS`) that opens downward (an
    oven's or a dishwasher's drop-down door, a drop-front desk lid): gravity pushes it open at every one of
    :data:`DOWNWARD_FRACTIONS`. Such doors
    carry their weight on door-balance springs (torsion or extension springs through a link, in every
    consumer range and dishwasher); modelled as a torsion spring about the hinge with its rest position at
    the closed end and the rate k = |tau_g(open end)| / R that balances the weight moment fully open (R the
    opening range, rad). Friction then holds only what the spring leaves: the largest |tau_g + tau_s| over
    ``hold_fractions`` and the closed end.

    Returns:
        the spring (k N m/rad, q_s rad) and hold load (N m), or None when the part does not open downward.
    """
    cs = ctx.closed[name]
    rot = ctx.root_rotation
    sub = {name: ctx.subtrees[name]}

    def load(f: float) -> float:
        st = {**state, name: cs.position(float(f))}
        return physics.joint_loads(kin, links, st, scale, sub, root_rotation=rot)[name].gravity_load

    open_loads = [load(f) * cs.direction for f in DOWNWARD_FRACTIONS]
    if not all(t > 0 for t in open_loads) or not cs.open_range > 0:
        return None
    k = open_loads[-1] / cs.open_range
    q_s = cs.position(0.0)
    fractions = sorted({*(float(f) for f in hold_fractions), *CLOSED_HOLD_FRACTIONS})
    hold = max(abs(load(f) * cs.direction - k * f * cs.open_range) for f in fractions)
    why = (f"counterbalance spring of a door opening downward (door-balance springs of ranges and dishwashers): "
           f"k = {k:.4g} N m/rad at rest closed balances the {open_loads[-1]:.3g} N m weight moment fully open")
    return SpringHold((float(k), float(q_s)), float(hold), why)


#: Share of the top of its operating force range above which the force that lifts a hinged lid or door its weight
#: presses shut (its weight moment over the lever to its far edge) calls for a lid support (:func:`lid_support`).
LID_SUPPORT_SHARE = 0.5
#: Opening fractions a lid support is fitted over (the whole range, both ends included).
SUPPORT_FRACTIONS = tuple(float(f) for f in np.linspace(0.0, 1.0, 11))


def lid_support(ctx: EstimationContext, kin: SimSession, links: dict[str, LinkPhysics], state: dict[str, float],
                scale: float, name: str, hold_fractions) -> SpringHold | None:
    """The lid support of a hinged lid or door (:data:`COUNTERBALANCE_LABELS`) that a hand could hardly move against its
    weight unaided: its largest weight moment over its range, over the lever to its far edge, is more than
    :data:`LID_SUPPORT_SHARE` of the top of its operating range (a chest's or a large case's lid). Such lids ride on
    lid supports, torsion or gas springs sized to the lid's torque (weight x distance to its centre of gravity;
    lid-stay makers select them so, e.g. Sugatsune's HG-JH lid stays, and ASTM F834 asks a toy chest's lid support to
    hold it in any position). Modelled as a torsion spring about the hinge whose torque is the straight line in the
    opening fraction f that best cancels the weight moment tau(f) over :data:`SUPPORT_FRACTIONS` (the Chebyshev line:
    slope -(tau(1) - tau(0)), offset half way between the largest and smallest remainder); friction then holds the
    largest remainder, and the largest over ``hold_fractions`` around the state.

    Returns:
        the spring (k N m/rad, q_s rad) and hold load (N m), or None when the part does not need one.
    """
    cs = ctx.closed[name]
    lever = far_edge(ctx, name, scale)
    if not cs.open_range > 0 or not lever > 0:
        return None
    rot, sub = ctx.root_rotation, {name: ctx.subtrees[name]}

    def opening_load(f: float) -> float:
        st = {**state, name: cs.position(float(f))}
        return cs.direction * physics.joint_loads(kin, links, st, scale, sub, root_rotation=rot)[name].gravity_load

    tau = np.array([opening_load(f) for f in SUPPORT_FRACTIONS])
    top = (operating_range(ctx.category, _label(ctx, name))[0].force_n or (0.0, np.inf))[1]
    if np.abs(tau).max() / lever <= LID_SUPPORT_SHARE * top:
        return None
    f = np.asarray(SUPPORT_FRACTIONS)
    slope = -(tau[-1] - tau[0])
    rest = tau + slope * f
    offset = -0.5 * (rest.max() + rest.min())
    k = -slope / cs.open_range
    if not k > 0:
        return None
    q_s = float(cs.position(0.0) + cs.direction * offset / k)
    remainder = np.abs(rest + offset)
    hold = max(float(remainder.max()), *(abs(opening_load(x) + offset + slope * x) for x in hold_fractions))
    why = (f"lid support (a torsion or gas spring sized to the lid's torque, as lid stays are): k = {k:.4g} N m/rad about "
           f"{q_s:.4g} rad carries the weight moment (up to {np.abs(tau).max():.3g} N m, {np.abs(tau).max() / lever:.3g} N at its "
           f"far edge against a hand's {top:g} N) to within {remainder.max():.3g} N m over its range")
    return SpringHold((float(k), q_s), float(hold), why)


def far_edge(ctx: EstimationContext, name: str, scale: float) -> float:
    """Lever (m) of a hand at the far edge of revolute joint ``name``'s part: the largest distance of its link's hull
    points (``ctx.hull_points``, input units, joint frame) from the axis at ``scale``; 0 without hull points."""
    j = ctx.asset.joint(name)
    pts = ctx.hull_points.get(j.child)
    if pts is None or not len(pts):
        return 0.0
    a_ = np.asarray(j.axis, float) / max(float(np.linalg.norm(j.axis)), 1e-12)
    p = np.asarray(pts, float) * scale
    return float(np.linalg.norm(p - np.outer(p @ a_, a_), axis=1).max())


#: Share of the top of a part's operating range that a stiff part (the request's "stiff") takes at least at its far
#: edge (a hinge) or along its slide against its friction alone: a quarter, 5.6 N at a door's edge where ADA 404.2.9
#: allows 22.2 N (a free door's hinge takes under 1 N), so that "stiff" is felt on a part whose weight loads nothing (a
#: door in its frame, a faucet handle), and the hand keeps three quarters of its range for gravity and damping. A part
#: on a spring (a closer, a return spring, a balance) is felt through its spring: "stiff" only doubles its friction.
STIFF_EFFORT_SHARE = 0.25


def stiff_least(ctx: EstimationContext, name: str, scale: float, prismatic: bool) -> float:
    """Least friction of stiff joint ``name`` (N m, or N for a prismatic joint): :data:`STIFF_EFFORT_SHARE` of the top
    of its operating range (``operating_forces.yaml``): its force range's top at :func:`far_edge` for a hinge (or its
    torque range's top), its force range's top for a slide; 0 where neither is known."""
    rng = operating_range(ctx.category, _label(ctx, name))[0]
    if rng.torque_nm is not None and not prismatic:
        return STIFF_EFFORT_SHARE * rng.torque_nm[1]
    return STIFF_EFFORT_SHARE * (rng.force_n or (0.0, 0.0))[1] * (1.0 if prismatic else far_edge(ctx, name, scale))


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


def balance(load: physics.JointLoad, cs: ClosedState, unit: float) -> SpringHold | None:
    """The balance of a part on a vertical slide (:data:`BALANCE_LABELS`): a sash balance of a hung window, a
    lift-up door's counterbalance. Its pull equals the part's weight along the travel at mid-travel and varies
    by +- :data:`BALANCE_VARIATION` of it from end to end: k = 2 v |F_g| / R (N/m, R the travel in m) about the
    reference q_s = q_mid - F_g / k (m, beyond the travel: the preload of a constant-force spring), so friction
    holds only the imbalance v |F_g| at the ends.

    Args:
        load: the joint's loads at the initial state (output units; ``gravity_load`` F_g N along the axis).
        cs: the joint's closed end (input units); ``unit``: the scale s that turns them into metres.

    Returns:
        the spring (k N/m, q_s m) and hold load (N), or None when the weight along the travel is under
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
    return SpringHold((float(k), float(q_s)), float(hold), why)


#: Opening fractions near the closed end where friction also holds a joint gravity pushes open (probes release at <= 0.10).
CLOSED_HOLD_FRACTIONS = (0.0, 0.05, 0.10)
