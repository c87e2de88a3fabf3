"""The springs that hold a part where a friction hinge or slide alone would not, each sized to the part's own load
(the input's kinematics at the output's scale): a closer (a self-closing part), a counterbalance (a door opening
downward), a lid support (a heavy hinged lid) and a sash balance (a part on a vertical slide), and what they need to
know of the part: whether its closed end is a stop (:func:`stopped_shut`) and the lever to its far edge
(:func:`far_edge`). :func:`~asset2sim.tasks.synthesize.joint_dynamics.joint_dynamics_for` chooses among them. Loads in
N m (revolute) or N (prismatic), output units.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from asset2sim.engines.base import SimSession
from asset2sim.schemas.overlay import LinkPhysics
from asset2sim.tasks.geometry.closed_state import ClosedState
from asset2sim.tasks.interpret.operating_forces import operating_range
from asset2sim.tasks.interpret.part_labels import canonical_label
from asset2sim.tasks.synthesize import physics, set_down
from asset2sim.tasks.synthesize.context import EstimationContext


#: Opening fractions near the closed end where friction also holds a joint gravity pushes open (probes release at <= 0.10).
CLOSED_HOLD_FRACTIONS = (0.0, 0.05, 0.10)


@dataclass(frozen=True, slots=True)
class SpringHold:
    """A part held by a spring (a closer, a counterbalance, a lid support, a sash balance): ``spring`` (k N m/rad
    or N/m, reference q_s rad or m), ``hold`` (the load friction still holds, N m or N) and ``note`` (one line)."""

    spring: tuple[float, float]
    hold: float
    note: str


#: Share of a closer's preload that friction may take, so that it still returns the part to its closed end.
CLOSER_FRICTION_SHARE = 0.2
#: Share of its range within which a part's closed end counts as on the limit a closer presses it onto.
CLOSER_STOP_SHARE = 0.01


def closer(ctx: EstimationContext, load: physics.JointLoad, cs: ClosedState, unit: float, hold: float, pushes: np.ndarray,
           closed_load: float, stopped: bool, *, hand: float, free: bool, floor: float, what: str) -> SpringHold:
    """The spring of a self-closing part (a door closer, a self-closing lid or slide): it presses the part into its
    closed end with a preload F0 and pulls F1 at its far end, rate k = (F1 - F0) / R about a reference F0 / k beyond
    the closed end (R: the range), so that the part returns shut from anywhere in its range against friction of at
    most :data:`CLOSER_FRICTION_SHARE` x F0 on top of the joint's least friction ``floor`` (N m or N:
    :func:`~asset2sim.tasks.synthesize.physics.friction_floor`, which the joint gets unless its slide sets its own), F0
    at least :data:`CLOSER_FLOOR_MARGIN` x that floor.

    - F1 = 2 F0 (a preloaded coil spring compressed over twice its preload travel), flattened where that passes
      :data:`CLOSER_EFFORT_SHARE` x ``hand`` down to :data:`CLOSER_PROGRESSION` x F0 (a gas spring's flat curve), so
      that the hand that opens it keeps the rest of its range for the part's weight, its friction and its damping;
      past that, the operability check judges the part (and says what remains).
    - F0 is sized to the part's weight, as door closers are (sizes 1-7 by the door's width and weight, EN 1154):
      ``set_down.LEAN_SAFETY`` x the load of the part's weight at the set-down's lean
      (:func:`~asset2sim.tasks.synthesize.set_down.lean_load`), no more than lets F1 stay within the hand's share
      (F0 <= the share / :data:`CLOSER_PROGRESSION`); on a free-standing object (``free``: the only kind the SPEC's
      robust rest sets down) at least what that lean needs (a part its weight presses shut: only a lean that lifts it
      off, ``lean_load(on_stop=True)``). And the pull at every opening fraction f of ``pushes`` outpulls
      ``physics.HOLD_SAFETY`` x the load pushing the part open there: F0 (1 + (F1/F0 - 1) f) (a drop-down door that
      shuts itself from fully open needs a spring a hand may not open: the check says so).

    ``pushes``: the loads (N m or N, >= 0) pushing the part open at :data:`OPENING_LOAD_FRACTIONS`
    (:func:`opening_loads`); ``what``: the spring as its note names it (a push button's return spring is such a
    closer); ``hold``: the largest load (N m or N) either way near the state, and pushing it open near its closed end;
    ``hand``: the top of the part's operating range at its grasp (N m at :func:`far_edge` for a hinge, N for a slide;
    0: unknown, no cap).

    A part with no stop at its closed end (``stopped`` False: neither its limit there nor another part, as a lid rests
    on its box's rim, :func:`stopped_shut`; a handle or lever that turns on past it, a joint without limits: nothing
    for a preload to press it onto) gets a return spring centred on its closed end instead, as spring-return handles
    and levers have. With F0 = max(``physics.HOLD_SAFETY`` x ``hold``, the weight-sized preload above) it pulls twice
    F0 at the far end, stiffer where the set-down lean would move it more than half its robust-rest band or where its
    pull at the band's edge would be less than :data:`CLOSER_FLOOR_MARGIN` x ``floor``, against friction of
    :data:`CLOSER_FRICTION_SHARE` x that pull, so that it comes back within its band. Its reference q_s = q_closed -
    ``closed_load`` / k carries the part's weight there (``closed_load``: the gravity load at the closed end, N m or N,
    as :func:`physics.joint_loads` signs it).

    Returns:
        the spring and the friction's hold load.
    """
    rng = max(cs.open_range * unit, 1e-9)
    frac = np.asarray(OPENING_LOAD_FRACTIONS)
    lean = max(set_down.lean_load(load, on_stop=stopped and load.gravity_load * cs.direction < 0), 0.0) if free else 0.0
    cap = CLOSER_EFFORT_SHARE * hand if hand > 0 else np.inf
    sized = max(set_down.LEAN_SAFETY * lean, min(set_down.LEAN_SAFETY * set_down.lean_load(load), cap / CLOSER_PROGRESSION))

    prismatic = load.joint in ctx.prismatic
    least_pull = CLOSER_FLOOR_MARGIN * floor  # the least friction the joint gets, overcome

    def least(ratio: float) -> float:  # the preload whose pull outpulls the opening loads everywhere, at F1 / F0 = ratio
        need = physics.HOLD_SAFETY * pushes / (1.0 + (ratio - 1.0) * frac)
        return float(max(sized, float(need.max(initial=0.0)), least_pull, 1e-6))

    closed_at = cs.position(0.0) * unit
    u = "N" if prismatic else "N m"
    if stopped:
        preload = least(2.0)
        far = 2.0 * preload
        if far > cap:  # flattened: the preload that holds with the flattest curve, its pull as near the cap as it goes
            preload = least(CLOSER_PROGRESSION)
            far = max(CLOSER_PROGRESSION * preload, min(cap, 2.0 * preload))
        k = (far - preload) / rng
        ref = float(closed_at - cs.direction * preload / k)
        why = (f"{what} presses it shut with {preload:.3g} {u} and pulls {far:.3g} {u} fully open "
               f"(k = {k:.4g} about {ref:.4g}" + (f"; a hand works it with up to {hand:.3g} {u}" if hand > 0 else "") + ")")
        return SpringHold((float(k), ref), CLOSER_FRICTION_SHARE * preload / physics.HOLD_SAFETY, why)
    preload = max(sized, physics.HOLD_SAFETY * hold, 1e-6)
    band = set_down.joint_band(cs.lower * unit, cs.upper * unit, prismatic)
    k = max(2.0 * preload / rng, set_down.LEAN_SAFETY * lean / (0.5 * band), least_pull / band)
    why = (f"self-closing: its closed end {closed_at:.4g} is no stop (it {'slides' if prismatic else 'turns'} on past it), so a "
           f"return spring centred there, k = {k:.4g} {'N/m' if prismatic else 'N m/rad'}, returns it within its band")
    return SpringHold((float(k), float(closed_at - closed_load / k)), CLOSER_FRICTION_SHARE * k * band / physics.HOLD_SAFETY,
                      why)


#: Least ratio of a closer's pull where it must move its part (its preload; a centred spring's pull at its band's edge)
#: to the joint's least friction (:func:`~asset2sim.tasks.synthesize.physics.friction_floor`), which its closer
#: overcomes on top of its own share: released there, the part moves against both.
CLOSER_FLOOR_MARGIN = 2.0
#: Most of the top of a part's operating range that its closer may pull at its far end: half, the hand keeping the
#: other half for the part's weight, its friction and its damping (the stiff word's share is a quarter,
#: :data:`~asset2sim.tasks.synthesize.joint_dynamics.STIFF_EFFORT_SHARE`).
CLOSER_EFFORT_SHARE = 0.5
#: Least ratio of a closer's far-end pull to its preload: a gas spring's progression (its force fully compressed over
#: fully extended), 1.2-1.4 for the springs of furniture and lids (Stabilus, "Lift-O-Mat: design and selection"); a
#: constant-force (negator) spring's is about 1.
CLOSER_PROGRESSION = 1.25


def opening_loads(ctx: EstimationContext, name: str, gravity: Callable[[float], float]) -> np.ndarray:
    """Gravity loads (N m, or N for a slide; 0 where none) that push joint ``name``'s part open at
    :data:`OPENING_LOAD_FRACTIONS` of its range (shape (11,)); ``gravity(f)``: the gravity load on the joint with its
    part at opening fraction f, the other joints at the state (:func:`gravity_at`). A closer returns the part from
    wherever it is left, so it must outpull them (:func:`closer`)."""
    return np.array([max(0.0, gravity(f) * ctx.closed[name].direction) for f in OPENING_LOAD_FRACTIONS])


#: Opening fractions at which :func:`opening_load` weighs a self-closing part.
OPENING_LOAD_FRACTIONS = tuple(float(f) for f in np.linspace(0.0, 1.0, 11))


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


#: Parts that carry a counterbalance spring when they open downward (canonical labels: a door, a drop-front
#: lid; a toggle or a lever is thrown over its centre instead).
COUNTERBALANCE_LABELS = frozenset({"door", "lid"})


#: Opening fractions at which gravity must push a part open for it to count as opening downward (:func:`counterbalance`).
DOWNWARD_FRACTIONS = (0.25, 0.5, 0.75, 1.0)


def counterbalance(ctx: EstimationContext, name: str, gravity: Callable[[float], float], hold_fractions) -> SpringHold | None:
    """The counterbalance spring of a hinged door or lid (:data:`COUNTERBALANCE_LABELS`) that opens downward (an
    oven's or a dishwasher's drop-down door, a drop-front desk lid): gravity pushes it open at every one of
    :data:`DOWNWARD_FRACTIONS`. Such doors
    carry their weight on door-balance springs (torsion or extension springs through a link, in every
    consumer range and dishwasher); modelled as a torsion spring about the hinge with its rest position at
    the closed end and the rate k = |tau_g(open end)| / R that balances the weight moment fully open (R the
    opening range, rad). Friction then holds only what the spring leaves: the largest |tau_g + tau_s| over
    ``hold_fractions`` and the closed end. ``gravity(f)``: the gravity load on the joint (N m) with its part at
    opening fraction f, the other joints at the state (:func:`gravity_at`).

    Returns:
        the spring (k N m/rad, q_s rad) and hold load (N m), or None when the part does not open downward.
    """
    cs = ctx.closed[name]
    open_loads = [gravity(f) * cs.direction for f in DOWNWARD_FRACTIONS]
    if not all(t > 0 for t in open_loads) or not cs.open_range > 0:
        return None
    k = open_loads[-1] / cs.open_range
    hold = max(abs(gravity(f) * cs.direction - k * f * cs.open_range)
               for f in sorted({*(float(f) for f in hold_fractions), *CLOSED_HOLD_FRACTIONS}))
    why = (f"counterbalance spring of a door opening downward (door-balance springs of ranges and dishwashers): "
           f"k = {k:.4g} N m/rad at rest closed balances the {open_loads[-1]:.3g} N m weight moment fully open")
    return SpringHold((float(k), float(cs.position(0.0))), float(hold), why)


#: Share of the top of its operating force range above which the force that lifts a hinged lid or door its weight
#: presses shut (its weight moment over the lever to its far edge) calls for a lid support (:func:`lid_support`).
LID_SUPPORT_SHARE = 0.5
#: Opening fractions a lid support is fitted over (the whole range, both ends included).
SUPPORT_FRACTIONS = tuple(float(f) for f in np.linspace(0.0, 1.0, 11))


def lid_support(ctx: EstimationContext, name: str, scale: float, gravity: Callable[[float], float],
                hold_fractions) -> SpringHold | None:
    """The lid support of a hinged lid or door (:data:`COUNTERBALANCE_LABELS`) that a hand could hardly move against its
    weight unaided: its largest weight moment over its range, over the lever to its far edge, is more than
    :data:`LID_SUPPORT_SHARE` of the top of its operating range (a chest's or a large case's lid). Such lids ride on
    lid supports, torsion or gas springs sized to the lid's torque (weight x distance to its centre of gravity;
    lid-stay makers select them so, e.g. Sugatsune's HG-JH lid stays, and ASTM F834 asks a toy chest's lid support to
    hold it in any position). Modelled as a torsion spring about the hinge whose torque is the straight line in the
    opening fraction f that best cancels the weight moment tau(f) over :data:`SUPPORT_FRACTIONS` (the Chebyshev line:
    slope -(tau(1) - tau(0)), offset half way between the largest and smallest remainder); friction then holds the
    largest remainder, and the largest over ``hold_fractions`` around the state. ``gravity(f)``: the gravity load on
    the joint (N m) with its part at opening fraction f, the other joints at the state (:func:`gravity_at`); ``scale``:
    the output's.

    Returns:
        the spring (k N m/rad, q_s rad) and hold load (N m), or None when the part does not need one.
    """
    cs = ctx.closed[name]
    lever = far_edge(ctx, name, scale)
    if not cs.open_range > 0 or not lever > 0:
        return None
    tau = np.array([cs.direction * gravity(f) for f in SUPPORT_FRACTIONS])
    top = (operating_range(ctx.category, part_label(ctx, name))[0].force_n or (0.0, np.inf))[1]
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
    hold = max(float(remainder.max()), *(abs(cs.direction * gravity(x) + offset + slope * x) for x in hold_fractions))
    why = (f"lid support (a torsion or gas spring sized to the lid's torque, as lid stays are): k = {k:.4g} N m/rad about "
           f"{q_s:.4g} rad carries the weight moment (up to {np.abs(tau).max():.3g} N m, {np.abs(tau).max() / lever:.3g} N at its "
           f"far edge against a hand's {top:g} N) to within {remainder.max():.3g} N m over its range")
    return SpringHold((float(k), q_s), float(hold), why)


def gravity_at(ctx: EstimationContext, kin: SimSession, links: dict[str, LinkPhysics], state: dict[str, float], scale: float,
               name: str, f: float, unit: float = 1.0) -> float:
    """The gravity load on joint ``name`` (N m, or N for a slide; as :func:`physics.joint_loads` signs it) with its part
    at opening fraction ``f`` of its range (``ctx.closed``; ``unit``: the scale of a slide's positions), the other
    joints at ``state`` (output units; ``kin``, the input's kinematics session, posed for the load)."""
    st = {**state, name: ctx.closed[name].position(float(f)) * unit}
    loads = physics.joint_loads(kin, links, st, scale, {name: ctx.subtrees[name]}, root_rotation=ctx.root_rotation)
    return loads[name].gravity_load


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
    why = (f"balance of a part on a vertical slide (sash balances of hung windows, counterbalances of lift-up doors): "
           f"k = {k:.4g} N/m about {q_s:.4g} m carries the {abs(load.gravity_load):.3g} N weight at mid-travel, "
           f"+-{BALANCE_VARIATION:.0%} from end to end")
    return SpringHold((float(k), float(q_s)), float(BALANCE_VARIATION * abs(load.gravity_load)), why)


def part_label(ctx: EstimationContext, joint: str) -> str | None:
    """Canonical part label of ``joint``'s child link, None when unlabelled."""
    return canonical_label(ctx.joint_label(joint))
