"""Joint sweep (physical executability): can every movable joint be driven
through its range and back? Definition (session, drive law, pass rule, the
clearing re-sweep :func:`_sweep_clearing`): ``docs/design/metrics.md``, "joint_sweep".
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from asset2sim.engines.base import SimSession
from asset2sim.engines.source import SimObject
from asset2sim.schemas.metrics import unit
from asset2sim.schemas.report import MetricResult
from asset2sim.tasks.check.blockers import SHUT_IN_FRACTION, Blocker, fixed_root_options, joints_between
from asset2sim.tasks.check.contact_points import joint_frame_axis
from asset2sim.tasks.ingest.mesh_checks import box_corners
from asset2sim.tasks.check.metrics import EXPLOSION_JOINT_SPEED_PRISMATIC, EXPLOSION_JOINT_SPEED_REVOLUTE
from asset2sim.tasks.check.stroke import Reach, reach_stroke
from asset2sim.tasks.geometry import limits
from asset2sim.tasks.synthesize.physics import G
from asset2sim.urdf import UrdfModel

#: Fraction of the range that counts as reached (SPEC: >= 95 % both ways).
REACH_FRACTION = 0.95
#: Force limit (N*m or N) of the zero-velocity drive that holds the joints not swept: far
#: above any part's operating force (a second hand or a fixture holding the rest), so they do not yield.
HOLD_FORCE = 1000.0


@dataclass
class SweepConfig:
    """Sweep knobs (units on every field)."""

    #: nominal time for a full traverse, s: v_max = range / traverse_time
    traverse_time: float = 1.0
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
    #: per step: ``t`` (s), ``fraction`` (opening fraction), ``phase`` (0 opening, 1 closing); for the report,
    #: not in :meth:`summary`
    trace: dict[str, list[float]] = field(default_factory=dict, repr=False, compare=False)

    def summary(self) -> dict[str, Any]:
        """JSON-able dict (the trace left out)."""
        d = {k: v for k, v in self.__dict__.items() if k != "trace"}
        d["worst_pair"] = list(self.worst_pair) if self.worst_pair else None
        return d


def _lever(session: SimSession, joint: str, links: list[str]) -> float:
    """Largest distance (m, >= 1e-3) of ``links``' collision vertices from ``joint``'s axis."""
    o, a = joint_frame_axis(session, joint, session.joint_child[joint])
    best = 1e-3
    for ln in links:
        v = session.link_collision_vertices(ln)
        if not len(v):
            lo, hi = session.link_aabb(ln)
            v_w = box_corners(lo, hi)
        else:
            p, Rl = session.link_frame(ln)
            v_w = v @ Rl.T + p
        r = v_w - o
        r = r - np.outer(r @ a, a)
        best = max(best, float(np.max(np.linalg.norm(r, axis=1))))
    return best


def effort_limit(session: SimSession, joint: str, links: list[str], open_range: float, cfg: SweepConfig) -> float:
    """Drive force limit E = f_w m_sub g L + k R (N*m or N): m_sub the engine's
    masses of ``links``, L their largest distance from the axis (1 for
    prismatic), k the session's spring stiffness, R = ``open_range`` (rad or m)."""
    masses = session.link_masses()
    m_sub = float(sum(masses.get(ln, 0.0) for ln in links))
    lever = 1.0 if session.joint_types[joint] == "prismatic" else _lever(session, joint, links)
    spring = session.options.springs.get(joint)
    k = spring.stiffness if spring is not None else 0.0
    return float(cfg.weight_factor * m_sub * G * lever + k * open_range)


#: Speed margin of :func:`damping_caps`: the damped speed E / c covers the range this many times in the time limit.
DAMPED_SPEED_MARGIN = 2.0


def damping_caps(obj: SimObject, closed: dict[str, tuple[float, float, float]]) -> dict[str, float]:
    """Joint -> the largest viscous damping (N m s/rad or N s/m) with which
    the sweep's drive still traverses the range in time: c_max = E T /
    (``DAMPED_SPEED_MARGIN`` R), E :func:`effort_limit` at the closed end, T
    :attr:`SweepConfig.time_limit`, R the range of ``closed`` (joint ->
    (q_closed, direction, R), rad or m). Measured in a fixed-root,
    gravity-free PyBullet session of ``obj``; joints with no range are left out.

    Raises:
        EngineUnavailable: PyBullet is not installed; whatever loading ``obj.source`` raises.
    """
    cfg = SweepConfig()
    source, initial_state = obj.source, dict(obj.state)
    model = source.model()
    subtrees = limits.subtrees(model)
    caps: dict[str, float] = {}
    with source.open("pybullet", fixed_root_options(initial_state, obj.conventions, dict(obj.springs))) as session:
        for name, (qc, _, rng) in closed.items():
            if name not in session.joint_types or not rng > 0:
                continue
            session.set_joint_positions({**initial_state, name: qc})
            links = subtrees.get(name, [session.joint_child[name]])
            e = effort_limit(session, name, links, rng, cfg)
            caps[name] = e * cfg.time_limit / (DAMPED_SPEED_MARGIN * rng)
    return caps


def _deepest(session: SimSession) -> tuple[float, tuple[str, str] | None]:
    _, pairs = session.self_penetration()
    if not pairs:
        return 0.0, None
    worst = max(pairs, key=lambda c: c.max_depth)
    return float(worst.max_depth), (worst.link_a, worst.link_b)


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
    v_max = open_range / cfg.traverse_time
    limit = effort_limit(session, joint, links, open_range, cfg)
    session.set_joint_positions({**initial_state, joint: closed})
    vdiv = EXPLOSION_JOINT_SPEED_PRISMATIC if jtype == "prismatic" else EXPLOSION_JOINT_SPEED_REVOLUTE  # the divergence metric's
    max_pen, worst = _deepest(session)
    trace: dict[str, list[float]] = {"t": [], "fraction": [], "phase": []}

    def penetration(k, q, qd):
        nonlocal max_pen, worst
        d, pair = _deepest(session)
        if d > max_pen:
            max_pen, worst = d, pair

    def drive(goal: float) -> Reach:
        def law(k, q, qd):
            v = float(np.clip(cfg.position_gain * (goal - q), -v_max, v_max))
            session.drive_joint(joint, v, limit)

        sign = 1.0 if goal == q_far else -1.0
        target = cfg.reach_fraction if sign > 0 else 1.0 - cfg.reach_fraction
        r = reach_stroke(session, joint, (closed, direction, open_range), target, sign,
                         cfg.time_limit, law, held=held, hold_force=cfg.hold_force, max_speed=vdiv,
                         record=penetration)
        t0 = trace["t"][-1] + dt if trace["t"] else 0.0
        trace["t"] += [t0 + k * dt for k in range(len(r.fractions))]
        trace["fraction"] += r.fractions
        trace["phase"] += [float(sign < 0)] * len(r.fractions)
        return r

    # PyBullet applies springs by torque control, which makes the holds drift: the others stay passive
    hold = cfg.hold_others and not (any(sp.stiffness > 0 for sp in session.options.springs.values())
                                     and session.traits.springs_by_torque)
    held = [o for o in session.joint_types if o != joint] if hold else []
    try:
        out = drive(q_far)
        back = Reach(0) if out.diverged else drive(closed)
    finally:
        for o in [joint, *held]:
            session.release_joint(o)
    diverged = out.diverged or back.diverged
    t_out, t_back = (None if r.steps is None else r.steps * dt for r in (out, back))
    failure = ["diverged"] if diverged else []
    if t_out is None and not diverged:
        failure.append(f"reached only {out.far:.0%} of the range opening")
    if t_back is None and not diverged:
        failure.append(f"closed back only to {back.far:.0%} open")
    if max_pen >= cfg.max_penetration:
        failure.append(f"self-penetration {max_pen * 1000:.1f} mm" + (f" ({worst[0]} / {worst[1]})" if worst else ""))
    return JointSweep(
        joint=joint, joint_type=jtype, q_closed=float(closed), q_far=float(q_far), open_range=float(open_range),
        effort_limit=limit, reached_open=float(out.far), reached_closed=float(back.far),
        time_open=t_out, time_close=t_back,
        max_penetration=max_pen, worst_pair=worst, diverged=diverged, passed=not failure, failure="; ".join(failure),
        trace=trace)


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
    stops it, swept again with the joints between moved (:func:`_clearing_ends`).
    Returns the first retry that passes (``range_note`` says what moved), else the first sweep."""
    qc, d, rng = closed[name]
    sweep = functools.partial(sweep_joint, session, name, closed=qc, direction=d, open_range=rng, links=links, config=cfg)
    first = sweep(initial_state=initial_state)
    opened = first.time_open is not None
    if first.passed or first.diverged or not np.isfinite(first.reached_open):
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
    for end, word in _clearing_ends(first):
        moved = {k: closed[k][0] + end * closed[k][1] * closed[k][2] for k in between}
        if not moved or all(abs(moved[k] - initial_state.get(k, closed[k][0])) < 1e-9 for k in moved):
            continue
        session.restore_state(saved)
        second = sweep(initial_state={**initial_state, **moved})
        if second.passed:
            where = (f"of closing at the initial state ({'pushed into it' if pushed else f'stalled at {stall:.0%}'} on the way back)"
                     if opened else f"at the initial state (stalled at {stall:.0%})")
            second.range_note = f"{who} is in the way {where}; swept with {', '.join(sorted(moved))} {word}"
            return second
    return first


def _clearing_ends(first: JointSweep) -> tuple[tuple[float, str], ...]:
    """(share of the way to the open end, its name) of each retry of ``first``, in turn."""
    if first.time_open is not None:
        return ((0.0, "closed"),)
    if first.reached_open < SHUT_IN_FRACTION:
        return ((0.0, "closed"), (1.0, "open"))
    return ((1.0, "open"),)


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
    # a held joint's spring load is taken by its hold: one session per set of acting springs
    groups: dict[tuple[str, ...], list[str]] = {}
    for name in closed:
        key = ((name,) if name in springs else ()) if cfg.hold_others else tuple(sorted(springs))
        groups.setdefault(key, []).append(name)
    for key, names in groups.items():
        session = source.open(engine, fixed_root_options(initial_state, conv, {n: springs[n] for n in key}))
        blocker = Blocker(session, source, conv)
        try:
            saved = session.save_state()
            for name in names:
                qc, d, rng = closed[name]
                if name not in session.joint_types:
                    run.skipped[name] = "not a movable joint in this engine"
                    continue
                if not rng > 0:
                    run.skipped[name] = "no opening range"
                    continue
                session.restore_state(saved)
                links = subtrees.get(name, [session.joint_child[name]])
                if cfg.hold_others:
                    run.joints.append(_sweep_clearing(session, model, name, closed, links, initial_state, cfg, saved, blocker))
                else:
                    run.joints.append(sweep_joint(session, name, closed=qc, direction=d, open_range=rng,
                                                  links=links, initial_state=initial_state, config=cfg))
            session.discard_state(saved)
        finally:
            blocker.close()
            session.close()
    order = list(closed)
    run.joints.sort(key=lambda j: order.index(j.joint))
    return run


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
                 "failures": [f"{j.joint}: {j.failure}" for j in run.joints if not j.passed], "skipped": run.skipped},
        engine=run.engine)


def blocked_stops(metric: MetricResult) -> dict[str, tuple[float, float]]:
    """Joint -> (position where the ``joint_sweep`` ``metric`` stalled, position
    it was driven to), rad or m: on the way out when the far end was not
    reached, else on the way back. Joints that passed, diverged or only
    penetrated are left out."""
    out = {}
    for name, j in (metric.details.get("joints") or {}).items():
        if j["passed"] or j["diverged"]:
            continue
        if j["time_open"] is None:
            f, goal = j["reached_open"], j["q_far"]
        elif j["time_close"] is None:
            f, goal = j["reached_closed"], j["q_closed"]
        else:
            continue
        if np.isfinite(f):
            out[name] = (float(j["q_closed"] + (j["q_far"] - j["q_closed"]) * f), float(goal))
    return out


def blocked_positions(metric: MetricResult) -> dict[str, float]:
    """Joint -> the position (rad or m) where the sweep stopped short (:func:`blocked_stops`)."""
    return {name: stall for name, (stall, _goal) in blocked_stops(metric).items()}


def sweep_score(metric: MetricResult) -> tuple[float, float]:
    """Sort key of ``joint_sweep`` results, lower is better: (failing joints,
    summed shortfall of the failing joints, each way >= 0, non-finite = 1,
    rounded to 0.01)."""
    short = 0.0
    for j in (metric.details.get("joints") or {}).values():
        if j["passed"]:
            continue
        out, back = j["reached_open"], j["reached_closed"]
        short += max(0.0, REACH_FRACTION - out) if np.isfinite(out) else 1.0
        short += max(0.0, back - (1.0 - REACH_FRACTION)) if np.isfinite(back) else 1.0
    return float(metric.value), round(short, 2)
