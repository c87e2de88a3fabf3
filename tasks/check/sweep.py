"""Joint sweep (physical executability): can every movable joint be driven
through its range and back? Definition (session, drive law, pass rule, the
clearing re-sweep :func:`_sweep_clearing`): ``docs/design/metrics.md``, "joint_sweep".
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from asset2sim.engines.base import EngineUnsupported, SimSession
from asset2sim.engines.source import SimObject
from asset2sim.schemas.metrics import unit
from asset2sim.schemas.report import MetricResult
from asset2sim.tasks.check import joint_batches
from asset2sim.tasks.check.blockers import SHUT_IN_FRACTION, Blocker, fixed_root_options, joints_between
from asset2sim.tasks.check.contact_points import joint_frame_axis, off_axis
from asset2sim.tasks.ingest.mesh_checks import box_corners
from asset2sim.tasks.check.metrics import explosion_speed
from asset2sim.tasks.check.stroke import Reach, reach_stroke
from asset2sim.tasks.geometry import limits
from asset2sim.tasks.synthesize.physics import G
from asset2sim.urdf import UrdfModel

#: Fraction of the range that counts as reached (SPEC: >= 95 % both ways).
REACH_FRACTION = 0.95
#: Force limit (N*m or N) of the zero-velocity drive that holds the joints not swept: far
#: above any part's operating force (a second hand or a fixture holding the rest), so they do not yield.
HOLD_FORCE = 1000.0


def shortfall(reached_open: float, reached_closed: float) -> float:
    """How far a sweep fell short of :data:`REACH_FRACTION` each way, summed (opening fractions; >= 0, a
    non-finite way counts 1): 0 for a sweep that reached both ends."""
    out = max(0.0, REACH_FRACTION - reached_open) if np.isfinite(reached_open) else 1.0
    return out + (max(0.0, reached_closed - (1.0 - REACH_FRACTION)) if np.isfinite(reached_closed) else 1.0)


@dataclass
class SweepConfig:
    """Sweep knobs (units on every field)."""

    #: nominal time for a full traverse, s: v_max = range / traverse_time, at least :attr:`least_speed`
    traverse_time: float = 1.0
    #: least traverse speed at the part's far edge, m/s (:func:`traverse_speed`), a 25th of the hand's 0.25 m/s: at 2 mm/s
    #: Bullet's motor does not lift a button of a gram off the stop its closer presses it onto (``docs/design/simulators.md``)
    least_speed: float = 0.01
    #: longest drive each way, s
    time_limit: float = 3.0
    #: k_p of the position loop, 1/s
    position_gain: float = 10.0
    #: force limit in multiples of the moving part's own weight (torque)
    weight_factor: float = 2.0
    #: deepest self-contact point allowed during the sweep, m
    max_penetration: float = 0.005
    #: fraction of the range to reach each way
    reach_fraction: float = REACH_FRACTION
    #: hold the other movable joints at the initial state while one is swept
    hold_others: bool = True
    #: force limit of the hold, N*m or N (beyond the joint's friction)
    hold_force: float = HOLD_FORCE


@dataclass
class JointSweep:
    """One joint's sweep. Positions rad or m; forces N*m or N; depths m."""

    joint: str
    joint_type: str
    q_closed: float
    q_far: float
    open_range: float
    effort_limit: float
    #: largest opening fraction reached on the way out
    reached_open: float
    #: smallest opening fraction reached on the way back
    reached_closed: float
    time_open: float | None
    time_close: float | None
    max_penetration: float
    worst_pair: tuple[str, str] | None
    diverged: bool
    passed: bool
    failure: str = ""
    #: how the range differs from the closed end's (parts held in the way)
    range_note: str = ""
    #: joint -> position (rad or m) of the other joints this sweep moved from the initial state (a retry with the
    #: joints between moved, :func:`_sweep_clearing`); empty: swept from the initial state
    swept_with: dict[str, float] = field(default_factory=dict)
    #: per step: ``t`` (s), ``fraction`` (opening fraction), ``phase`` (0 opening, 1 closing); for the report,
    #: not in :meth:`summary`
    trace: dict[str, list[float]] = field(default_factory=dict, repr=False, compare=False)

    def summary(self) -> dict[str, Any]:
        """JSON-able dict (the trace left out)."""
        d = {k: v for k, v in self.__dict__.items() if k != "trace" and (k != "swept_with" or v)}
        d["worst_pair"] = list(self.worst_pair) if self.worst_pair else None
        return d


def _arm(session: SimSession, joint: str, links: list[str]) -> float:
    """The lever of a force on ``links`` about ``joint``: 1 for a slide; for a hinge the largest distance (m, >= 1e-3)
    of ``links``' collision vertices from ``joint``'s axis."""
    if session.joint_types[joint] == "prismatic":
        return 1.0
    o, a = joint_frame_axis(session, joint, session.joint_child[joint])
    best = 1e-3
    for ln in links:
        v = session.link_collision_vertices(ln)
        if not len(v):
            v_w = box_corners(*session.link_aabb(ln))
        else:
            p, Rl = session.link_frame(ln)
            v_w = v @ Rl.T + p
        best = max(best, float(np.max(off_axis(v_w, o, a))))
    return best


def effort_limit(session: SimSession, joint: str, links: list[str], open_range: float, cfg: SweepConfig,
                 closed: float | None = None, direction: float = 1.0) -> float:
    """Drive force limit E = f_w m_sub g L + P (N*m or N): m_sub the engine's masses of ``links``, L their largest
    distance from the axis (1 for prismatic), P the largest pull of the session's joint spring (stiffness k, reference
    q_s) over the range R = ``open_range`` (rad or m) from the closed end q_c = ``closed`` along ``direction`` d,
    k max(|q_c - q_s|, |q_c + d R - q_s|): k R centred on its closed end, more for a closer preloaded shut (k R without q_c)."""
    masses = session.link_masses()
    m_sub = float(sum(masses.get(ln, 0.0) for ln in links))
    lever = _arm(session, joint, links)
    spring = session.options.springs.get(joint)
    far = open_range if spring is None or closed is None else max(abs(closed - spring.reference),
                                                                  abs(closed + direction * open_range - spring.reference))
    return float(cfg.weight_factor * m_sub * G * lever + (spring.stiffness * far if spring is not None else 0.0))


def traverse_speed(session: SimSession, joint: str, links: list[str], open_range: float, cfg: SweepConfig) -> float:
    """The drive's top speed (rad/s or m/s): ``open_range`` (rad or m) over ``cfg.traverse_time``, at least
    ``cfg.least_speed`` (m/s) at the far edge of ``links`` (over their largest distance from the axis for a hinge)."""
    return max(open_range / cfg.traverse_time, cfg.least_speed / _arm(session, joint, links))


def _deepest(pairs: list) -> tuple[float, tuple[str, str] | None]:
    """The deepest of the self-contact ``pairs``: (its depth m, its links); (0, None) without a pair."""
    if not pairs:
        return 0.0, None
    worst = max(pairs, key=lambda c: c.max_depth)
    return float(worst.max_depth), (worst.link_a, worst.link_b)


def _holds(session: SimSession, cfg: SweepConfig) -> bool:
    """Whether the joints not swept are held: as ``cfg`` asks, but where the engine applies springs by torque control
    (PyBullet), which makes the holds drift: there the others stay passive."""
    return cfg.hold_others and not (any(sp.stiffness > 0 for sp in session.options.springs.values())
                                    and session.traits.springs_by_torque)


def _extend_trace(trace: dict[str, list[float]], fractions: list[float], closing: bool, dt: float) -> None:
    """A stroke's readings (``fractions``, one a step of ``dt`` s) appended to ``trace``; ``closing``: its phase."""
    t0 = trace["t"][-1] + dt if trace["t"] else 0.0
    trace["t"] += [t0 + k * dt for k in range(len(fractions))]
    trace["fraction"] += fractions
    trace["phase"] += [float(closing)] * len(fractions)


def sweep_joint(session: SimSession, joint: str, *, closed: float, direction: float, open_range: float,
                links: list[str], initial_state: dict[str, float], config: SweepConfig | None = None) -> JointSweep:
    """Sweep one joint out and back in a fixed-root, gravity-free session
    (stepped in place; the other joints are put back to ``initial_state``,
    rad or m, first). ``closed`` q_c and ``open_range`` R > 0 (rad or m),
    ``direction`` +-1; ``links``: the links the joint moves.

    Raises:
        KeyError: unknown joint. ValueError: ``open_range`` <= 0.
    """
    if not open_range > 0:
        raise ValueError(f"joint {joint!r}: open_range must be > 0, got {open_range}")
    cfg = config or SweepConfig()
    dt = session.options.conventions.timestep
    jtype = session.joint_types[joint]
    q_far = closed + direction * open_range
    v_max = traverse_speed(session, joint, links, open_range, cfg)
    limit = effort_limit(session, joint, links, open_range, cfg, closed, direction)
    session.set_joint_positions({**initial_state, joint: closed})
    vdiv = explosion_speed(jtype)  # the divergence metric's
    run = _Swept(joint, (closed, direction, open_range), limit, frozenset(links), v_max, vdiv,
                 _deepest(session.self_penetration()[1]))

    def penetration(k, q, qd):
        d, pair = _deepest(session.self_penetration()[1])
        if d > run.deepest[0]:
            run.deepest = (d, pair)

    def drive(goal: float) -> Reach:
        def law(k, q, qd):
            v = float(np.clip(cfg.position_gain * (goal - q), -v_max, v_max))
            session.drive_joint(joint, v, limit)

        sign = 1.0 if goal == q_far else -1.0
        target = cfg.reach_fraction if sign > 0 else 1.0 - cfg.reach_fraction
        r = reach_stroke(session, joint, run.closed, target, sign, cfg.time_limit, law, held=held, hold_force=cfg.hold_force,
                         max_speed=vdiv, record=penetration)
        _extend_trace(run.trace, r.fractions, sign < 0, dt)
        return r

    held = [o for o in session.joint_types if o != joint] if _holds(session, cfg) else []
    try:
        out = drive(q_far)
        run.strokes = [out, Reach(0) if out.diverged else drive(closed)]
    finally:
        for o in [joint, *held]:
            session.release_joint(o)
    return _joint_sweep(run, jtype, dt, cfg)


def _joint_sweep(r: _Swept, jtype: str, dt: float, cfg: SweepConfig) -> JointSweep:
    """The sweep of ``r.joint`` from its two strokes (out, back) and its deepest self-contact (m, pair)."""
    (qc, d, rng), (out, back) = r.closed, r.strokes
    (max_pen, worst), diverged = r.deepest, out.diverged or back.diverged
    t_out, t_back = (None if x.steps is None else x.steps * dt for x in (out, back))
    failure = ["diverged"] if diverged else []
    if t_out is None and not diverged:
        failure.append(f"reached only {out.far:.0%} of the range opening")
    if t_back is None and not diverged:
        failure.append(f"closed back only to {back.far:.1%} open")
    if max_pen >= cfg.max_penetration:
        failure.append(f"self-penetration {max_pen * 1000:.1f} mm" + (f" ({worst[0]} / {worst[1]})" if worst else ""))
    return JointSweep(
        joint=r.joint, joint_type=jtype, q_closed=float(qc), q_far=float(qc + d * rng), open_range=float(rng),
        effort_limit=r.effort, reached_open=float(out.far), reached_closed=float(back.far),
        time_open=t_out, time_close=t_back,
        max_penetration=max_pen, worst_pair=worst, diverged=diverged, passed=not failure, failure="; ".join(failure),
        trace=r.trace)


@dataclass
class _Swept:
    """One joint's sweep in a batch (:func:`sweep_together`): its ends, drive and the stroke under way."""

    joint: str
    closed: tuple[float, float, float]
    effort: float
    links: frozenset[str]
    v_max: float
    max_speed: float
    deepest: tuple[float, tuple[str, str] | None] = (0.0, None)
    strokes: list[Reach] = field(default_factory=list)
    trace: dict[str, list[float]] = field(default_factory=lambda: {"t": [], "fraction": [], "phase": []})
    k: int = 0

    @property
    def sign(self) -> float:
        return 1.0 if len(self.strokes) == 1 else -1.0


def sweep_together(session: SimSession, joints: list[str], closed: dict[str, tuple[float, float, float]],
                   subtrees: dict[str, list[str]], initial_state: dict[str, float],
                   config: SweepConfig | None = None) -> dict[str, JointSweep]:
    """:func:`sweep_joint` of each of ``joints`` at once in one fixed-root, gravity-free session: each joint's strokes,
    drive law, hold and pass rule as alone, the other joints held at ``initial_state`` (rad or m). For parts that
    cannot act on one another (:mod:`~asset2sim.tasks.check.joint_batches`: separate branches of the root, swept
    boxes apart), so each part's motion is the one it has alone. A part's deepest self-contact counts the pairs it
    is in and those of the links no part of the batch moves, as they are now, and the other parts' pairs as they are
    at ``initial_state`` (where they stay while it is swept alone). ``closed``: joint -> (q_closed, direction, open
    range > 0); ``subtrees``: joint -> the links it moves.

    Raises:
        KeyError: a joint of ``joints`` is not one of the session's.
    """
    cfg = config or SweepConfig()
    dt = session.options.conventions.timestep
    limit = int(round(cfg.time_limit / dt))
    # each part's links in the order ``subtrees`` gives them (a part's mass summed in that order, in every process,
    # as a joint swept alone sums them), and as a set to test pairs against
    parts = {j: list(subtrees.get(j, [session.joint_child[j]])) for j in joints}
    moved = {j: frozenset(links) for j, links in parts.items()}
    session.set_joint_positions(dict(initial_state))
    at_rest = session.self_penetration()[1]  # each part's pairs where it stays while another is swept alone
    session.set_joint_positions({**initial_state, **{j: closed[j][0] for j in joints}})
    runs = []
    for j in joints:
        qc, d, rng = closed[j]
        runs.append(_Swept(j, closed[j], effort_limit(session, j, parts[j], rng, cfg, qc, d), moved[j],
                           traverse_speed(session, j, parts[j], rng, cfg),
                           explosion_speed(session.joint_types[j]), strokes=[Reach(limit)]))
    others = {r.joint: [c for c in at_rest if not ({c.link_a, c.link_b} & r.links)
                        and any({c.link_a, c.link_b} & o.links for o in runs if o is not r)] for r in runs}
    batch_links = frozenset().union(*moved.values())

    def deepest(r: _Swept, pairs) -> None:
        d, pair = _deepest([c for c in pairs if {c.link_a, c.link_b} & r.links or not {c.link_a, c.link_b} & batch_links]
                           + others[r.joint])
        if pair is not None and (d > r.deepest[0] or r.deepest[1] is None and r.k == 0):
            r.deepest = (d, pair)

    pairs = session.self_penetration()[1]
    for r in runs:
        deepest(r, pairs)
    hold = _holds(session, cfg)
    if hold:
        for o in session.joint_types:
            if o not in moved:
                session.drive_joint(o, 0.0, cfg.hold_force)
    active = list(runs)
    try:
        while active:
            for r in list(active):
                q, qd = session.joint_state(r.joint)
                while True:  # reach_stroke's reading of the stroke under way, its drive set while it goes on
                    reach, (qc, d, rng) = r.strokes[-1], r.closed
                    target = cfg.reach_fraction if r.sign > 0 else 1.0 - cfg.reach_fraction
                    if r.k >= reach.limit:  # out of time: the last reading may still be at the target
                        reach.last(r.closed, target, r.sign, r.k, q)
                    elif not reach.read(r.closed, target, r.sign, r.max_speed, r.k, q, qd):  # neither reached nor diverged
                        goal = qc + d * rng if r.sign > 0 else qc
                        session.drive_joint(r.joint, float(np.clip(cfg.position_gain * (goal - q), -r.v_max, r.v_max)), r.effort)
                        break
                    # the stroke ended: its readings into the trace; the closing stroke begun after the opening one, or over
                    _extend_trace(r.trace, reach.fractions, r.sign < 0, dt)
                    if len(r.strokes) == 1:
                        r.strokes.append(Reach(0) if reach.diverged else Reach(reach.limit))
                        r.k = 0
                        if not reach.diverged:
                            continue
                    active.remove(r)
                    if hold:
                        session.drive_joint(r.joint, 0.0, cfg.hold_force)
                    break
            if not active:
                break
            session.step(1)
            pairs = session.self_penetration()[1]
            for r in active:
                r.k += 1
                deepest(r, pairs)
    finally:
        for o in session.joint_types:
            session.release_joint(o)
    return {r.joint: _joint_sweep(r, session.joint_types[r.joint], dt, cfg) for r in runs}


@dataclass
class SweepRun:
    """Every joint's sweep in one engine."""

    engine: str
    joints: list[JointSweep] = field(default_factory=list)
    #: joint -> why it was not swept
    skipped: dict[str, str] = field(default_factory=dict)


def _sweep_clearing(session: SimSession, model: UrdfModel, name: str, closed: dict[str, tuple[float, float, float]],
                    links: list[str], initial_state: dict[str, float], cfg: SweepConfig, saved: int,
                    blocker: Blocker) -> JointSweep:
    """:func:`sweep_joint` of ``name``; when a link another movable joint places
    stops it (and ``cfg.hold_others``), swept again with the joints between moved (closed where it opened; where it did
    not, closed then open when it stalled short of ``SHUT_IN_FRACTION``, else open).
    Returns the first retry that passes (``range_note`` says what moved), else the sweep that came nearest to both
    ends (:func:`shortfall`) of the first and the retries that neither diverged nor pushed through a part (the first
    one on a tie, ``swept_with`` naming what a retry moved; ``range_note`` says what each retry moved and reached)."""
    qc, d, rng = closed[name]
    sweep = functools.partial(sweep_joint, session, name, closed=qc, direction=d, open_range=rng, links=links, config=cfg)
    first = sweep(initial_state=initial_state)
    opened = first.time_open is not None
    if not cfg.hold_others or first.passed or first.diverged or not np.isfinite(first.reached_open):
        return first
    jd = model.joint(name)
    own = limits.rigid_group(model, jd.parent)
    pushed = opened and first.time_close is not None and first.max_penetration >= cfg.max_penetration
    if opened and not pushed and (first.time_close is not None or not np.isfinite(first.reached_closed)):
        return first
    session.restore_state(saved)
    if pushed:  # closed back, through the other link: the deepest pair names it
        stall = first.reached_closed
        pair = first.worst_pair or ()
        who = next((b for b in pair if b not in links and b not in own), None) if set(pair) & set(links) else None
    else:
        stall = first.reached_closed if opened else first.reached_open
        who = blocker({**initial_state, name: qc + d * rng * max(stall, 0.0)}, links, own)
    if who is None:
        return first
    between = [k for k in joints_between(model, jd.child, who)
               if k != name and k in closed and k in session.joint_types and closed[k][2] > 0]
    # (share of the way to the open end, its name) of each retry, in turn
    ends = ((0.0, "closed"),) if opened else (((0.0, "closed"), (1.0, "open")) if first.reached_open < SHUT_IN_FRACTION
                                              else ((1.0, "open"),))
    where = (f"of closing at the initial state ({'pushed into it' if pushed else f'stalled at {stall:.0%}'} on the way back)"
             if opened else f"at the initial state (stalled at {stall:.0%})")
    tried, best = [], first
    for end, word in ends:
        moved = {k: closed[k][0] + end * closed[k][1] * closed[k][2] for k in between}
        if not moved or all(abs(moved[k] - initial_state.get(k, closed[k][0])) < 1e-9 for k in moved):
            continue
        session.restore_state(saved)
        second = sweep(initial_state={**initial_state, **moved})
        second.swept_with = moved
        if second.passed:
            second.range_note = f"{who} is in the way {where}; swept with {', '.join(sorted(moved))} {word}"
            return second
        tried.append(f"swept with {', '.join(sorted(moved))} {word}, it {second.failure}")
        if (not second.diverged and second.max_penetration < cfg.max_penetration
                and shortfall(second.reached_open, second.reached_closed) < shortfall(best.reached_open, best.reached_closed)):
            best = second  # the retry that came nearest, through nothing: where it stalled is what a repair clears
    if tried:
        best.range_note = f"{who} is in the way {where}; " + "; ".join(tried)
    return best


def run_sweep(engine: str, obj: SimObject, closed: dict[str, tuple[float, float, float]],
              config: SweepConfig | None = None) -> SweepRun:
    """Sweep every joint of ``closed`` (joint -> (q_closed, direction,
    open_range), rad or m) of ``obj`` in fresh fixed-root, gravity-free sessions of ``engine`` (the root as swept,
    whatever ``obj.fixed_base`` says).

    Raises:
        EngineUnavailable: the engine is not installed; whatever loading raises.
    """
    cfg = config or SweepConfig()
    source, conv, initial_state = obj.source, obj.conventions, dict(obj.state)
    model = source.model()
    subtrees = limits.subtrees(model)
    run = SweepRun(engine)
    springs = dict(obj.springs)
    passed = _passed_together(engine, obj, closed, model, subtrees, cfg) if cfg.hold_others else {}
    run.joints.extend(passed.values())
    # a held joint's spring load is taken by its hold: one session per set of acting springs
    groups: dict[tuple[str, ...], list[str]] = {}
    for name in (n for n in closed if n not in passed):
        key = ((name,) if name in springs else ()) if cfg.hold_others else tuple(sorted(springs))
        groups.setdefault(key, []).append(name)
    for key, names in groups.items():
        session = source.open(engine, fixed_root_options(initial_state, conv, {n: springs[n] for n in key}))
        blocker = Blocker(session, source, conv)
        try:
            saved = session.save_state()
            for name in names:
                if name not in session.joint_types:
                    run.skipped[name] = "not a movable joint in this engine"
                    continue
                if not closed[name][2] > 0:
                    run.skipped[name] = "no opening range"
                    continue
                session.restore_state(saved)
                links = subtrees.get(name, [session.joint_child[name]])
                run.joints.append(_sweep_clearing(session, model, name, closed, links, initial_state, cfg, saved, blocker))
            session.discard_state(saved)
        finally:
            blocker.close()
            session.close()
    order = list(closed)
    run.joints.sort(key=lambda j: order.index(j.joint))
    return run


def _passed_together(engine: str, obj: SimObject, closed: dict[str, tuple[float, float, float]], model: UrdfModel,
                     subtrees: dict[str, list[str]], cfg: SweepConfig) -> dict[str, JointSweep]:
    """The sweeps that pass when the root's branches are swept in batches (:func:`sweep_together`, by
    :func:`~asset2sim.tasks.check.joint_batches.batches` of their swept boxes over the closed end, the open end and
    the initial state; parts with a spring and parts without apart, each batch with its parts' springs, as a part
    alone has its own). A batch where a part diverged gives none (the engine's state is not trusted for the others);
    the rest are swept alone."""
    state, conv, springs = dict(obj.state), obj.conventions, dict(obj.springs)
    candidates = [n for n in joint_batches.root_branches(model, list(closed)) if closed[n][2] > 0]
    if len(candidates) < 2:
        return {}
    with obj.source.open(engine, fixed_root_options(state, conv)) as session:
        candidates = [n for n in candidates if n in session.joint_types]
        try:
            boxes = {n: joint_batches.swept_box(session, n, subtrees.get(n, [session.joint_child[n]]), state,
                                                [closed[n][0], closed[n][0] + closed[n][1] * closed[n][2], state.get(n, closed[n][0])])
                     for n in candidates}
        except EngineUnsupported:  # an engine that reads no link boxes: each part swept alone
            return {}
    passed: dict[str, JointSweep] = {}
    for sprung in (False, True):
        for batch in joint_batches.batches({n: boxes[n] for n in candidates if (n in springs) is sprung}):
            if len(batch) < 2:
                continue
            with obj.source.open(engine, fixed_root_options(state, conv, {n: springs[n] for n in batch if n in springs})) as session:
                swept = sweep_together(session, batch, closed, subtrees, state, cfg)
            if not any(j.diverged for j in swept.values()):
                passed.update({n: j for n, j in swept.items() if j.passed})
    return passed


def sweep_metric(run: SweepRun) -> MetricResult:
    """The ``joint_sweep`` metric: value = failing joints; passes iff none fails (None when none was swept)."""
    cfg = SweepConfig()
    failing = [j.joint for j in run.joints if not j.passed]
    return MetricResult(
        name="joint_sweep", value=float(len(failing)), unit=unit("joint_sweep"), passed=(not failing) if run.joints else None,
        threshold=(f"root fixed; every movable joint driven (force-limited) from its closed end to >= "
                   f"{cfg.reach_fraction:.0%} open and back to <= {1 - cfg.reach_fraction:.0%} within "
                   f"{cfg.time_limit:g} s each way, deepest self-contact < {cfg.max_penetration * 1000:g} mm, no divergence"),
        details={"joints": {j.joint: j.summary() for j in run.joints}, "failing": failing,
                 "failures": [f"{j.joint}: {j.failure}" + (f"; {j.range_note}" if j.range_note else "")
                              for j in run.joints if not j.passed],
                 "skipped": run.skipped},
        engine=run.engine)
