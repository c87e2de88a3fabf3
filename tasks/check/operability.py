"""Operability: every movable part a person handles is moved by a hand across
its range, both ways, against its own friction, damping, springs and gravity,
with an effort inside the real operating range of that part
(``asset2sim/priors/operating_forces.yaml``, :func:`~asset2sim.tasks.check.force_ranges.operating_range`).
Definition (session, hand, grasp, pass rule): ``docs/design/metrics.md``, "operability".

The session has the root fixed (a mounted asset as it is used; a free one held
by the other hand), gravity on, no ground, the asset's springs acting, and the
other movable joints held at the initial state. Each handled part is put at its
closed end and pushed open, then pushed closed, by a hand:

- **where**: the grasp point of :func:`~asset2sim.tasks.check.contact_points.contact_point_rule`
  (a handle's centre, a door's far edge, a drawer's front), lever r its distance from the axis
  (a knob's rim where it is grasped on its axis: :func:`~asset2sim.tasks.check.contact_points.grasp_lever`);
- **how hard**: at most the top of the part's operating range F (N; a torque range T N m bounds
  F r too), rising from 0 over ``ramp_time``, easing off as the part nears the hand's speed, and changing
  at most at the rise's rate;
- **how fast**: the hand's speed v at the grasp point (0.25 m/s, ISO 10218-1 reduced speed,
  :class:`~asset2sim.tasks.check.gripper.GripperLimits`).

A stroke passes when the part gets to ``reach_fraction`` of its range (95 %,
the SPEC sweep's) in time, or where the hand stops short with another link in
the part's way (geometry stops it there: :class:`~asset2sim.tasks.check.blockers.Blocker`).
The effort a part needs is also computed along each stroke from the joint
model the simulators use: E(q) = f + c v / r + max(0, -s Q(q)), f Coulomb
friction, c damping, s the stroke's direction, Q the generalised force of
gravity and the spring; its peak, as a force at the grasp point E / r (N) and a
torque about the axis (N m), must lie inside the part's range. The part is
operable when both strokes pass.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from asset2sim.engines.base import SimSession
from asset2sim.engines.quiet import quiet_stdout
from asset2sim.engines.source import SimObject
from asset2sim.schemas.metrics import unit
from asset2sim.schemas.report import MetricResult
from asset2sim.tasks.check.blockers import Blocker
from asset2sim.tasks.check.contact_points import contact_point_rule, grasp_lever, joint_frame_axis, subtree
from asset2sim.tasks.geometry.limits import rigid_group
from asset2sim.tasks.interpret.operating_forces import ForceRange, load_operating_forces, operating_range
from asset2sim.tasks.check.gripper import GripperLimits
from asset2sim.tasks.check.stroke import reach_stroke
from asset2sim.tasks.check.sweep import HOLD_FORCE, REACH_FRACTION
from asset2sim.tasks.interpret.part_priors import handled
from asset2sim.tasks.synthesize.physics import G as GRAVITY
from asset2sim.urdf import UrdfModel

#: Joint types a hand moves along a range.
RANGED = ("revolute", "prismatic")


@dataclass(frozen=True)
class OperabilityConfig:
    """The hand (units on every field)."""

    #: speed of the hand at the grasp point, m/s (ISO 10218-1:2011 5.6 reduced speed, as the task's gripper)
    hand_speed: float = GripperLimits().max_speed_m_s
    #: shortest time allowed for one stroke, s
    min_time: float = 4.0
    #: a stroke may take this many times the path length / ``hand_speed``, s
    time_factor: float = 2.0
    #: share of the range a stroke must cover (the SPEC sweep's 95 %)
    reach_fraction: float = REACH_FRACTION
    #: time over which the hand's force rises from 0 to its limit, s
    ramp_time: float = 0.25
    #: positions along the range where the needed effort is computed
    samples: int = 11
    #: force limit of the holds of the other joints, N m or N
    hold_force: float = HOLD_FORCE


@dataclass
class Stroke:
    """One push of a part, ``open`` or ``close``. Fractions of the opening range; effort in N m
    (revolute) or N (prismatic); force at the grasp point N; torque about the axis N m."""

    action: str
    target: float
    reached: float
    time: float | None
    needed_effort: float
    needed_force_n: float
    needed_torque_nm: float | None
    at_fraction: float
    #: the link in the part's way where the hand stopped short (geometry stops it there)
    stopped_by: str | None = None
    diverged: bool = False
    passed: bool = False
    failure: str = ""


@dataclass
class PartOperability:
    """One handled part's strokes and the range they are judged against."""

    joint: str
    joint_type: str
    link: str
    label: str | None
    rule: str
    #: distance (m) of the grasp point from the axis (revolute)
    lever: float | None
    #: the hand's force limit at the grasp point, N
    hand_force_n: float
    force_range_n: tuple[float, float] | None
    torque_range_nm: tuple[float, float] | None
    range_of: str
    sources: list[str]
    estimate: bool
    strokes: list[Stroke] = field(default_factory=list)

    @property
    def passed(self) -> bool:
        return bool(self.strokes) and all(s.passed for s in self.strokes)

    @property
    def peak_force_n(self) -> float:
        return max((s.needed_force_n for s in self.strokes), default=0.0)

    @property
    def peak_torque_nm(self) -> float | None:
        return max((s.needed_torque_nm for s in self.strokes if s.needed_torque_nm is not None), default=None)

    def summary(self) -> dict[str, Any]:
        """JSON-able dict."""
        out = {("lever_m" if k == "lever" else k): v for k, v in self.__dict__.items() if k != "strokes"}
        out.update(force_range_n=list(self.force_range_n) if self.force_range_n else None,
                   torque_range_nm=list(self.torque_range_nm) if self.torque_range_nm else None, peak_force_n=self.peak_force_n,
                   peak_torque_nm=self.peak_torque_nm, passed=self.passed, strokes=[dict(s.__dict__) for s in self.strokes])
        return out


@dataclass
class OperabilityRun:
    """Every handled part of one asset in one engine; ``skipped`` joint -> why it was not pushed."""

    engine: str
    parts: list[PartOperability] = field(default_factory=list)
    skipped: dict[str, str] = field(default_factory=dict)


def range_force(rng_: ForceRange, where: str, lever: float | None) -> tuple[float, str]:
    """(upper end of the force range, or of the torque range / ``lever`` where smaller, N; what set it)."""
    force, bound = float("inf"), ""
    if rng_.force_n is not None:
        force, bound = rng_.force_n[1], f"force range of {where}"
    if rng_.torque_nm is not None and lever is not None and rng_.torque_nm[1] / lever < force:
        force, bound = rng_.torque_nm[1] / lever, f"torque range of {where}"
    return force, bound


def gravity_force(session: SimSession, model: UrdfModel, joint: str, links: list[str]) -> float:
    """Generalised gravity force Q (N m or N; > 0 pushes q up) of ``links`` on ``joint``:
    a . sum((c_i - o) x m_i g), prismatic a . sum(m_i g)."""
    o, a = joint_frame_axis(session, joint, session.joint_child[joint])
    g = np.array([0.0, 0.0, -GRAVITY])
    q = 0.0
    for ln in links:
        lk = model.links.get(ln)
        if lk is None or lk.inertial is None or not lk.inertial.mass:
            continue
        p, Rl = session.link_frame(ln)
        c = np.asarray(p, float) + np.asarray(Rl, float) @ lk.inertial.com()
        f = lk.inertial.mass * g
        q += float(a @ f) if session.joint_types[joint] == "prismatic" else float(a @ np.cross(c - o, f))
    return q


def operate_part(session: SimSession, model: UrdfModel, joint: str, closed: tuple[float, float, float],
                 blocker: Blocker, *, category: str | None, label: str | None,
                 config: OperabilityConfig | None = None) -> PartOperability:
    """Push one part open from its closed end and closed again (module docstring) in a fixed-root session with
    gravity (stepped in place from the session's initial state, its springs acting; the joint's state is
    restored at the end). ``closed``: (q_closed rad or m, direction +-1, open range R > 0); ``blocker``: finds
    the link in the part's way where the hand stops short (:class:`~asset2sim.tasks.check.blockers.Blocker`).

    Raises:
        KeyError: ``joint`` is not a movable joint of the session.
        ValueError: R <= 0; the part has no geometry to grasp; its operating range bounds neither the force nor, for a
            revolute part, the torque.
    """
    cfg = config or OperabilityConfig()
    state = session.options.initial_state
    qc, d, rng = closed
    if not rng > 0:
        raise ValueError(f"joint {joint!r}: open range must be > 0, got {rng}")
    jt = session.joint_types[joint]
    table = load_operating_forces()
    r_, where = operating_range(category, label, table)
    session.set_joint_positions({**state, joint: qc + d * 0.5 * rng})
    link, point, rule = contact_point_rule(session, joint, model, opening_direction=d)
    lever = None if jt == "prismatic" else grasp_lever(session, joint, link, point, model)
    hand_f, _ = range_force(r_, "", lever)  # the force range's top, lowered where the torque range's top bounds F r
    if not np.isfinite(hand_f):
        raise ValueError("a part needs a force range" + ("" if lever is None else " or a torque range"))
    hand_f = float(hand_f)
    effort = hand_f * lever if lever is not None else hand_f
    speed = cfg.hand_speed / lever if lever else cfg.hand_speed
    time_limit = max(cfg.min_time, cfg.time_factor * rng * (lever or 1.0) / cfg.hand_speed)
    links = [ln for ln in subtree(model, session.joint_child[joint]) if ln in session.link_names]
    held = [o for o in session.joint_types if o != joint]
    own = rigid_group(model, model.joint(joint).parent)  # the parent's side: never collided with the part
    part = PartOperability(joint=joint, joint_type=jt, link=link, label=label, rule=rule, lever=lever, hand_force_n=hand_f,
                           force_range_n=r_.force_n, torque_range_nm=r_.torque_nm, range_of=where,
                           sources=[table.sources[s] for s in r_.sources], estimate=r_.estimate)
    fractions = np.linspace(0.0, 1.0, max(2, cfg.samples))
    spring, jm = session.options.springs.get(joint), model.joint(joint)
    dt = session.options.conventions.timestep
    rate = effort * dt / cfg.ramp_time  # the most the hand's force changes in one step, N m or N
    saved = session.save_state()
    reached_open = 0.0  # where the opening stroke left the part: the closing stroke starts there
    try:
        for action, sign, target in (("open", 1.0, cfg.reach_fraction), ("close", -1.0, 1.0 - cfg.reach_fraction)):
            # the peak effort the stroke needs over the fractions from the initial state, its springs acting: f + c w +
            # max(0, -s Q), f and c the joint's friction and damping, w the hand's joint speed, Q the generalised force
            # of gravity on the links (gravity_force) plus the joint's spring; at: the opening fraction where it peaks
            need, at = 0.0, float(fractions[0])
            for fr in fractions:
                session.set_joint_positions({**state, joint: qc + d * fr * rng})
                load = gravity_force(session, model, joint, links)
                if spring is not None:
                    load += spring.force(session.joint_state(joint)[0])
                e = jm.friction + jm.damping * speed + max(0.0, -sign * d * load)
                if e > need:
                    need, at = float(e), float(fr)
            session.set_joint_positions(dict(state))
            session.set_joint_positions({**state, joint: qc if action == "open" else qc + d * reached_open * rng})
            # the hand's force eases off near its speed and changes at most at the rate that raises it from 0 to its
            # limit over ramp_time (a hand's force builds and relaxes over time): on a light part a force that follows
            # the speed step by step would switch between full and none every step, and in PyBullet that chatter
            # against the joint's friction motor stalls the part (a 27 g lamp arm stopped at 14 % of its range under
            # 2.5 N m against 0.63 N m of friction)
            hand, s = [0.0], sign * d

            def law(k, q, qd):
                ease = float(np.clip((speed - s * qd) / (0.5 * speed), 0.0, 1.0))
                hand[0] = float(np.clip(effort * ease, hand[0] - rate, hand[0] + rate))
                session.apply_joint_effort(joint, s * hand[0])

            push = reach_stroke(session, joint, closed, target, sign, time_limit, law, held=held, hold_force=cfg.hold_force)
            reached, diverged = push.far, push.diverged
            t = None if push.steps is None else push.steps * dt
            if push.steps == push.limit:  # reached at the last reading: the time limit itself
                t = time_limit
            stop = None
            if t is None and not diverged and need <= effort:  # as far as geometry lets it: a link in the way?
                # the parent's side is not collided with the part's first link only: the links below it meet it
                q = session.joint_positions()
                stop = blocker(q, links[:1], own | set(links)) or blocker(q, links[1:], set(links))
            if action == "open":
                reached_open = reached if np.isfinite(reached) else 0.0
            force, torque = (need / lever, need) if lever else (need, None)
            why = ["diverged"] if diverged else []
            if t is None and stop is None and not diverged:
                why.append(f"a {hand_f:.3g} N hand at the {rule} got it only to {reached:.0%} open")
            if r_.force_n is not None and force > r_.force_n[1]:
                why.append(f"needs {force:.3g} N at the {rule} (range {r_.force_n[0]:g}-{r_.force_n[1]:g} N, {where})")
            if torque is not None and r_.torque_nm is not None and torque > r_.torque_nm[1]:
                why.append(f"needs {torque:.3g} N m (range {r_.torque_nm[0]:g}-{r_.torque_nm[1]:g} N m, {where})")
            part.strokes.append(Stroke(action=action, target=float(target), reached=float(reached), time=t,
                                       needed_effort=need, needed_force_n=float(force), needed_torque_nm=torque,
                                       at_fraction=at, stopped_by=stop, diverged=diverged, passed=not why,
                                       failure="; ".join(why)))
            if diverged:
                break
    finally:
        session.restore_state(saved)
        session.discard_state(saved)
        for o in [joint, *held]:
            session.release_joint(o)
    return part


def run_operability(engine: str, obj: SimObject, closed: dict[str, tuple[float, float, float]], *,
                    category: str | None = None, labels: dict[str, str | None] | None = None,
                    config: OperabilityConfig | None = None) -> OperabilityRun:
    """Every handled part of ``closed`` (joint -> (q_closed, direction, open range), rad or m) of ``obj`` pushed by a
    hand (:func:`operate_part`) in one fresh session of ``engine``: root fixed, gravity on, no ground, the springs
    acting; ``labels``: link -> semantic label.

    Raises:
        EngineUnavailable: the engine is not installed; whatever loading ``obj.source`` raises.
    """
    cfg = config or OperabilityConfig()
    model = obj.source.model(mode="lenient")
    labels = dict(labels or {})
    run = OperabilityRun(engine)
    with quiet_stdout():
        session = obj.open(engine, fixed_base=True, gravity=True, ground=False)
    blocker = Blocker(session, obj.source, obj.conventions)
    try:
        for name, c in closed.items():
            if name not in session.joint_types or session.joint_types[name] not in RANGED:
                run.skipped[name] = "not a ranged movable joint in this engine"
                continue
            if not c[2] > 0:
                run.skipped[name] = "no opening range"
                continue
            label = labels.get(session.joint_child[name])
            if not handled(label):
                run.skipped[name] = f"a {label} is not operated by hand"
                continue
            try:
                run.parts.append(operate_part(session, model, name, c, blocker, category=category, label=label,
                                              config=cfg))
            except ValueError as exc:
                run.skipped[name] = str(exc)
    finally:
        blocker.close()
        session.close()
    return run


def operability_metric(run: OperabilityRun) -> MetricResult:
    """The ``operability`` metric: value = parts not operable; passes iff every handled part is (None when none was
    pushed); ``details["efforts"]`` joint -> the peak force (N) and torque (N m) and their range."""
    failing = [p.joint for p in run.parts if not p.passed]
    failures = [f"{p.joint} ({p.label or 'unlabelled'}) {s.action}: {s.failure}" for p in run.parts for s in p.strokes if not s.passed]
    parts = {p.joint: p.summary() for p in run.parts}
    efforts = {j: {"label": s["label"], "peak_force_n": round(s["peak_force_n"], 4),
                   "peak_torque_nm": None if s["peak_torque_nm"] is None else round(s["peak_torque_nm"], 4),
                   **{k: s[k] for k in ("force_range_n", "torque_range_nm", "range_of", "passed")}} for j, s in parts.items()}
    return MetricResult(
        name="operability", value=float(len(failing)), unit=unit("operability"), passed=(not failing) if run.parts else None,
        threshold=("root fixed, gravity on, the other joints held: every handled part pushed by a hand from its closed end "
                   f"to >= {REACH_FRACTION:.0%} open and back (or as far as geometry lets it), the effort it needs "
                   "(friction, damping at the hand's speed, springs, gravity) inside its real operating range "
                   "(asset2sim/priors/operating_forces.yaml)"),
        details={"parts": parts, "failing": failing, "failures": failures,
                 "efforts": efforts, "skipped": run.skipped},
        engine=run.engine)
