"""Joint dynamics of an overlay (SPEC stage 2): the qualitative choices the
request's motion words make per joint (:class:`JointChoice`, :func:`motion_choices`)
and the numbers :func:`joint_dynamics_for` makes of them from the loads the input's
kinematics give: friction that holds, the springs of :mod:`.spring_holds` (closers,
counterbalances, lid supports, sash balances), slides, and the set-down's lean and
landings (``docs/design/refine.md``, "Joint dynamics"). Loads in N m (revolute) or N
(prismatic), output units.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import partial

import numpy as np

from asset2sim.engines.base import SimSession
from asset2sim.schemas.overlay import Holding, JointDynamics, LinkPhysics
from asset2sim.schemas.request import MotionPhrase
from asset2sim.tasks.geometry.closed_state import ClosedState
from asset2sim.prior_tables import load_priors
from asset2sim.tasks.interpret.part_priors import spring_expected
from asset2sim.tasks.interpret.named_parts import joints_of, moving_parts
from asset2sim.tasks.interpret.operating_forces import operating_range
from asset2sim.tasks.synthesize import physics, request_apply, set_down
from asset2sim.tasks.synthesize.context import EstimationContext
from asset2sim.tasks.synthesize.spring_holds import (BALANCE_LABELS, CLOSED_HOLD_FRACTIONS, COUNTERBALANCE_LABELS,
                                                     balance, closer, counterbalance, far_edge, gravity_at, lid_support,
                                                     opening_loads, part_label, stopped_shut)


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
    ``spring_labels``), and every push button or key has one (``ctx.push_buttons``: a keyboard's keys spring back
    whichever key the task presses); a self-closing part gets high damping unless a word says otherwise (a door
    closer is a spring and a hydraulic damper)."""
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
        out[j.name] = JointChoice(
            damping_level=levels[-1] if levels else ("high" if closing else "moderate"), holds_position="hold" in kinds,
            spring=bool(kinds & {"spring", "self_closing"})
            or (j.name in relevant or j.name in ctx.push_buttons) and spring_expected(ctx.category, ctx.joint_label(j.name)),
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
    rot = ctx.root_rotation
    loads = physics.joint_loads(kin, links, state, scale, ctx.subtrees, root_rotation=rot)
    landed = (set_down.landings(kin, links, state, scale, ctx.subtrees, ctx.hull_points, root_rotation=rot)
              if free_standing(ctx) else {})
    out: dict[str, JointDynamics] = {}
    for j in ctx.asset.movable_joints():
        name, linear, load = j.name, j.type == "prismatic", loads[j.name]
        ch = choices.get(name, JointChoice())
        cs = ctx.closed[name]
        unit = scale if linear else 1.0
        gravity = partial(gravity_at, ctx, kin, links, state, scale, name, unit=unit)  # the load at an opening fraction
        if ch.holds_position:
            fr = np.linspace(0.0, 1.0, 11)
        else:
            f0 = cs.fraction(state[name] / unit)
            fr = np.clip([f0 - 0.05, f0, f0 + 0.05], 0.0, 1.0)
        hold, at_closed = 0.0, 0.0
        # a part stays shut once closed: friction also holds a load pushing it open near its closed end
        for f, near_closed in [*((f, False) for f in fr), *((f, True) for f in CLOSED_HOLD_FRACTIONS)]:
            g = gravity(f)
            if near_closed and f == 0.0:
                at_closed = g
            if not near_closed or g * cs.direction > 0:
                hold = max(hold, abs(g))
        band = set_down.joint_band(cs.lower * unit, cs.upper * unit, linear)
        on_stop = _on_stop(load, cs, state[name], unit, band)
        if ch.free_moving and (on_stop or not ch.state_asked):
            hold = 0.0  # asked to move freely, and resting on the stop its weight presses it onto or given no state
        spring = held = balancer = None
        mechanism = "moves freely (asked)" if ch.free_moving else ("friction slide" if linear else "friction hinge")
        if ch.free_moving and ch.state_asked and not on_stop and abs(load.gravity_load) > physics.friction_floor(
                load, linear, True):
            mechanism = HELD_AGAINST_FREE
        note = source + "".join(f"; request '{w.phrase}': {w.kind.replace('_', ' ')}" for w in ch.words)
        on_slide = linear and part_label(ctx, name) in SLIDE_LABELS  # its slide sets its least friction
        # a push button or key resting out of its body: its return spring is preloaded onto that stop
        button = name in ctx.push_buttons and ch.spring and not ch.free_moving
        if ch.self_closing or (button and abs(state[name] - cs.position(0.0) * unit) <= band):
            held = closer(ctx, load, cs, unit, hold, opening_loads(ctx, name, gravity), at_closed,
                          stopped_shut(ctx, kin, state, scale, name), hand=hand_top(ctx, name, scale),
                          free=free_standing(ctx), floor=0.0 if on_slide else physics.friction_floor(load, linear),
                          what="self-closing: a closer spring" if ch.self_closing else "a push button's return spring")
            mechanism = "closer" if ch.self_closing else "return spring"
        elif ch.spring:
            k = max(3.0 * physics.HOLD_SAFETY * max(hold, 1e-6) / max(cs.open_range * unit, 1e-6), load.gravity_stiffness * 2.0)
            ref = float(np.clip(state[name] - load.gravity_load / k, cs.lower * unit, cs.upper * unit))
            spring, mechanism = (k, ref), "return spring"
            hold = 0.1 * hold  # the spring carries the load; friction only adds feel
        elif not linear and part_label(ctx, name) in COUNTERBALANCE_LABELS:  # a word about friction keeps it
            held = balancer = counterbalance(ctx, name, gravity, fr) or lid_support(ctx, name, scale, gravity, fr)
        elif linear and part_label(ctx, name) in BALANCE_LABELS:  # "slides easily" is friction, not the balance
            held = balancer = balance(load, cs, unit)
        if held is not None:
            spring, hold, note = held.spring, held.hold, f"{note}; {held.note}"
        if balanced := balancer is not None:
            mechanism = "balance" if linear else balancer.note.split(" (")[0]
        impact, static, landing = 0.0, hold, ""
        if (spring is None or balanced) and not ch.free_moving and name in landed:
            # a part of a free-standing object is held by its friction where it was left when the object is set
            # down; one its weight presses onto a stop is held by the stop, friction only against a lean that lifts
            # it off (a balanced part's spring carries its weight: only the lean's sideways share is left); each
            # landing's energy is taken within its band, unless it moves the part into a stop
            lean = (set_down.lean_load(load) - abs(load.gravity_load) * math.cos(set_down.SET_DOWN_LEAN) if balanced
                    else set_down.lean_load(load, on_stop=on_stop))
            hold, static = max(hold, set_down.LEAN_SAFETY / physics.HOLD_SAFETY * lean), max(static, lean)
            impact, landing = set_down.landing_friction(landed[name], band, _stops(cs, state[name] / unit, band / unit),
                                                        0.0 if balanced else load.gravity_load)
        slide = on_slide and not ch.free_moving
        dyn = physics.joint_dynamics(load, hold, prismatic=linear, damping_level=ch.damping_level, stiff=ch.stiff,
                                     free_moving=ch.free_moving, spring=spring, source=note, impact=impact, floor=not slide,
                                     stiff_least=stiff_least(ctx, name, scale) if ch.stiff and spring is None else 0.0)
        if slide:
            rides = slide_for(dyn.friction, load.mass * physics.G, requested_slide(ch.words))
            dyn = dyn.model_copy(update={"friction": rides.friction, "source": f"{dyn.source}; {rides.note}"})
            mechanism = f"{rides.kind.replace('_', ' ')} slides"
        elif mechanism == "friction hinge" and not static > 0:
            mechanism = "free hinge"
        out[name] = dyn.model_copy(update={"holding": Holding(mechanism=mechanism, static_load=float(static),
                                                              landing=float(impact), landing_trial=landing)})
    return out


@dataclass(frozen=True, slots=True)
class SlideChoice:
    """The slide a drawer rides on (:func:`slide_for`): ``kind`` (``slides.yaml`` key), ``friction`` (N) and
    ``note`` (one line)."""

    kind: str
    friction: float
    note: str


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
    if joint not in ctx.prismatic or part_label(ctx, joint) not in SLIDE_LABELS:
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


def free_standing(ctx: EstimationContext) -> bool:
    """Whether the object stands free and is set down (the SPEC's robust rest drops and leans it): not when
    its root is fixed (a mounted object: ``ctx.mounting``)."""
    return not (ctx.mounting is not None and ctx.mounting.fixed)


#: Share of the top of a part's operating range that a stiff part (the request's "stiff") takes at least at its far
#: edge (a hinge) or along its slide against its friction alone: a quarter, 5.6 N at a door's edge where ADA 404.2.9
#: allows 22.2 N (a free door's hinge takes under 1 N), so that "stiff" is felt on a part whose weight loads nothing (a
#: door in its frame, a faucet handle), and the hand keeps three quarters of its range for gravity and damping. A part
#: on a spring (a closer, a return spring, a balance) is felt through its spring: "stiff" only doubles its friction.
STIFF_EFFORT_SHARE = 0.25


def stiff_least(ctx: EstimationContext, name: str, scale: float) -> float:
    """Least friction of stiff joint ``name`` (N m, or N for a prismatic joint): :data:`STIFF_EFFORT_SHARE` of
    :func:`hand_top`; 0 where no range is known."""
    return STIFF_EFFORT_SHARE * hand_top(ctx, name, scale)


def hand_top(ctx: EstimationContext, name: str, scale: float) -> float:
    """The top of joint ``name``'s part's operating range (``operating_forces.yaml``) where a hand works it: its force
    range's top at :func:`far_edge` (m, at ``scale``) for a hinge, N m (or its torque range's top), its force range's
    top for a slide, N; 0 where neither is known."""
    rng = operating_range(ctx.category, part_label(ctx, name))[0]
    if rng.torque_nm is not None and name not in ctx.prismatic:
        return float(rng.torque_nm[1])
    return float((rng.force_n or (0.0, 0.0))[1] * (1.0 if name in ctx.prismatic else far_edge(ctx, name, scale)))
