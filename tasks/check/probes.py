"""Passive behaviour probes: a scripted pusher (:mod:`asset2sim.tasks.check.pusher`) tries to close /
open a joint while the other hand holds the body. Definition (targets, success, rebound, the retry of a
part shut in by another with ``CLEARING_SHARES``): ``docs/design/metrics.md``, "Behaviour: passive probes".
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np

from asset2sim.schemas.report import MetricResult
from asset2sim.tasks.check.blockers import SHUT_IN_FRACTION, blocking_link, joints_between
from asset2sim.tasks.check.pusher import ProbeConfig, Pusher, push_budget, push_geometry, pusher_for, root_held
from asset2sim.tasks.check.stroke import run_stroke
from asset2sim.tasks.check.support import SupportWatch, rolling_joints
from asset2sim.engines.source import SimObject
from asset2sim.mesh_io import MeshReadError
from asset2sim.tasks.state.ground_clearance import floor_stops
from asset2sim.tasks.geometry.limits import rigid_group, subtrees
from asset2sim.urdf import UrdfModel

CLOSE_TARGET, CLOSE_REACHED = 0.05, 0.10
OPEN_TARGET, OPEN_REACHED = 0.6, 0.55
OPEN_FAR_TARGET, OPEN_FAR_REACHED = 0.9, 0.85
REBOUND_FRACTION = 0.05
#: Smallest motion after release that counts as a rebound or as moving on, rad
#: / m: the SPEC's rest-stability tolerances (D_ori <= 0.01 rad, D_pos <= 1 mm).
REBOUND_FLOOR_REVOLUTE = 0.01
REBOUND_FLOOR_PRISMATIC = 0.001
#: Shares of the way to their open ends that the joints shutting a part in are lifted to, in turn.
CLEARING_SHARES = (0.25, 0.5, 0.75, 1.0)


@dataclass
class ProbeResult:
    """Outcome of one probe. Angles rad, lengths m, forces N, torques N*m."""

    joint: str
    joint_type: str
    action: str
    start: float
    target: float
    start_fraction: float
    target_fraction: float
    reached: bool
    time_to_reach: float | None
    peak_force: float
    #: peak generalised force: N*m (revolute, F*|r|) or N (prismatic)
    peak_effort: float
    lever_arm: float | None
    max_force: float
    root_displacement: float
    root_rotation: float
    slid: bool
    tipped: bool
    release_fraction: float
    final_fraction: float
    rebound: bool
    kept_moving: bool
    success: bool
    failure: str = ""
    notes: list[str] = field(default_factory=list)
    trace: dict[str, list[float]] = field(default_factory=dict, repr=False)

    def summary(self) -> dict[str, Any]:
        """JSON-able dict without the trace."""
        return {k: v for k, v in self.__dict__.items() if k != "trace"}


def probe_joint(session, joint: str, closed: tuple[float, float, float], *, action: str,
                config: ProbeConfig | None = None, holds_position: bool = False, model: UrdfModel | None = None,
                returns: bool = False, floor_stop: float | None = None) -> ProbeResult:
    """Run one probe (``action`` ``close`` / ``open``) on ``joint`` of a session
    (stepped in place) from its current state: ``closed`` (q_c rad or m, direction +-1, open range > 0 rad or
    m). ``holds_position``: an open probe that
    falls back fails; ``model``: the URDF (links rigid with the child);
    ``returns``: a close probe's rebound is by design; ``floor_stop``: opening
    (rad or m) where the floor stops the part, capping an open probe's target.

    Raises:
        ValueError: unknown action or non-positive ``open_range``.
        KeyError: unknown joint.
    """
    closed, direction, open_range = closed
    check_action(session, joint, action, open_range)
    cfg = config or ProbeConfig()
    dt = session.options.conventions.timestep

    def frac(q: float) -> float:
        return float(direction * (q - closed) / open_range)

    # settle first: the drift of an object unstable by itself is not the push's
    for _ in range(int(round(cfg.settle_time / dt))):
        session.step(1)
    q0, _ = session.joint_state(joint)
    f0 = frac(q0)
    # the target: its opening fraction, and whether an opening fraction has reached it
    f_target = CLOSE_TARGET if action == "close" else (OPEN_TARGET if f0 < OPEN_REACHED else OPEN_FAR_TARGET)
    notes: list[str] = []
    if action == "open" and floor_stop is not None and floor_stop / open_range < f_target:
        f_target = max(floor_stop / open_range, 0.0)  # the floor stops the part before the target
        notes.append(f"the floor stops it {f_target:.0%} open (the object resting as it is): the open probe's target")
    at = reached_fraction(action, f_target)
    reached_if = (lambda f: f <= at) if action == "close" else (lambda f: f >= at)
    q_target = closed + direction * f_target * open_range
    sign = 1.0 if q_target >= q0 else -1.0  # +1 when the target needs q to increase
    weight = float(sum(session.link_masses().values())) * abs(session.options.conventions.gravity)  # the engine's masses
    hand = pusher_for(session, joint, cfg, weight, model)
    # Sliding is measured where the object stands (the footprint point, carried with the root).
    watch = SupportWatch(session, session.link_names[0])
    lever0 = push_geometry(session, joint).lever
    travel = abs(q_target - q0) * (lever0 or 1.0)
    push_s, asked_s = push_budget(cfg, hand.ramp, travel)
    n_push = int(round(push_s / dt))
    run = _Run(reached=reached_if(f0))
    run.t_reach = 0.0 if run.reached else None
    # a body a hand can lift is gripped by the other hand; a heavier one is only steadied
    gripped = cfg.hold_body and weight <= cfg.hold_force
    with root_held(session, cfg.hold_force if gripped else None, notes) as held:
        # a gripped body takes the push's reaction through the hold; a steadied one as a force on its root
        _push(session, joint, sign, n_push, reached_if, frac, hand, cfg, watch, run,
              react=cfg.hold_body and not held)
        # the release observed with no force: the opening fraction at release and its extremes after
        run.f_rel = run.f_low = run.f_high = frac(session.joint_state(joint)[0])

        def released(k, q, qd):
            f = frac(q)
            run.f_low, run.f_high = min(run.f_low, f), max(run.f_high, f)
            run.record((run.steps + k) * dt, q, 0.0, float(np.linalg.norm(watch.current()[0])), 1.0)

        run_stroke(session, joint, int(round(cfg.release_time / dt)), record=released)
    q_end, qd_end = session.joint_state(joint)
    f_end = frac(q_end)
    if not run.reached and push_s < asked_s and run.steps >= n_push:
        notes.append(f"push stopped at the {push_s:.0f} s cap (ProbeConfig.max_push_time): the travel ({travel:.3g} m at the "
                     f"push point, lever {lever0 or 0.0:.3g} m) and the force ramp ({hand.ramp:.3g} s) asked "
                     f"{asked_s:.0f} s")
    # how it ended: a rebound (back towards its start after release: for close the start is more open, larger f), kept
    # moving after release, why it failed ("" on success); what is allowed noted
    prismatic = session.joint_types[joint] == "prismatic"
    tol = max(REBOUND_FRACTION, (REBOUND_FLOOR_PRISMATIC if prismatic else REBOUND_FLOOR_REVOLUTE) / open_range)
    went_open, went_shut = run.f_high - run.f_rel > tol, run.f_rel - run.f_low > tol
    rebound, kept = (went_open, went_shut) if action == "close" else (went_shut, went_open)
    kept = kept or abs(qd_end) > (cfg.settle_velocity_prismatic if prismatic else cfg.settle_velocity_revolute)
    slid, tipped = run.max_disp > cfg.slide_tol, run.max_rot > cfg.tip_tol
    failure = ""
    if not np.isfinite(q_end):
        failure = "diverged"
    elif not run.reached:
        failure = "target not reached" + (" (the object moved instead)" if slid or tipped else "")
    elif slid or tipped:
        failure = "the object " + ("slid" if slid else "tipped") + " instead of the joint moving"
    elif action == "close" and rebound and not returns:
        failure = "springs back after release"
    elif action == "open" and rebound and holds_position:
        failure = "does not hold the open position after release"
    if action == "open" and rebound and not holds_position:
        notes.append("falls back after release (allowed: the request does not ask it to hold)")
    if action == "close" and rebound and returns:
        notes.append("springs back after release (allowed: a spring its part prior or the request expects returns it)")
    if kept:
        notes.append("keeps moving after release")
    return ProbeResult(
        joint=joint, joint_type=session.joint_types[joint], action=action, start=q0, target=float(q_target), start_fraction=f0,
        target_fraction=f_target, reached=bool(run.reached), time_to_reach=run.t_reach, peak_force=float(run.peak_force),
        peak_effort=float(run.peak_effort), lever_arm=run.lever, max_force=float(hand.f_max),
        root_displacement=float(run.max_disp), root_rotation=float(run.max_rot), slid=bool(slid),
        tipped=bool(tipped), release_fraction=float(run.f_rel),
        final_fraction=float(f_end) if np.isfinite(f_end) else float("nan"), rebound=bool(rebound), kept_moving=bool(kept),
        success=not failure, failure=failure, notes=notes, trace=run.trace)


def check_action(session, joint: str, action: str, open_range: float, what: str = "probe", unknown: str | None = None) -> None:
    """Raises ValueError (``action`` not close / open, ``open_range`` <= 0) or KeyError (``unknown`` or the joint)."""
    if action not in ("close", "open"):
        raise ValueError(f"{what} action must be 'close' or 'open', got {action!r}")
    if not open_range > 0:
        raise ValueError(f"joint {joint!r}: open_range must be > 0, got {open_range}")
    if joint not in session.joint_child:
        raise KeyError(joint if unknown is None else unknown)


def reached_fraction(action: str, target_fraction: float) -> float:
    """The opening fraction (0 closed .. 1 fully open) at which a probe with ``action`` (close / open) and
    ``target_fraction`` counts its target reached: at most it (close), at least it (open)."""
    if action == "close":
        return CLOSE_REACHED
    reached = {OPEN_TARGET: OPEN_REACHED, OPEN_FAR_TARGET: OPEN_FAR_REACHED}
    return reached.get(target_fraction, target_fraction * OPEN_REACHED / OPEN_TARGET)  # else a target the floor set


@dataclass
class _Run:
    """What a probe's push and release recorded (opening fractions, m, rad, N, N*m or N, s)."""

    reached: bool
    t_reach: float | None = None
    steps: int = 0  # engine steps pushed
    peak_force: float = 0.0
    peak_effort: float = 0.0
    lever: float | None = None  # the lever at the peak effort
    max_disp: float = 0.0
    max_rot: float = 0.0
    f_rel: float = 0.0  # opening fraction at release, and its smallest and largest after
    f_low: float = 0.0
    f_high: float = 0.0
    trace: dict[str, list[float]] = field(default_factory=lambda: {"t": [], "q": [], "force": [], "root_disp": [], "phase": []})

    def record(self, t: float, q: float, force: float, disp: float, phase: float) -> None:
        """One step of the trace (phase 0 push, 1 release)."""
        for key, x in zip(self.trace, (t, q, force, disp, phase)):
            self.trace[key].append(x)


def _push(session, joint: str, sign: float, n_push: int, reached_if: Callable[[float], bool], frac: Callable[[float], float],
          hand: Pusher, cfg: ProbeConfig, watch: SupportWatch, run: _Run, react: bool) -> None:
    """Push ``joint``'s part towards its target (``sign`` +1: q increases) with ``hand`` for at most ``n_push`` steps,
    until reached (``reached_if(frac(q))``, ``frac(q)`` the opening fraction of q, rad or m), or the object slid or
    tipped; ``react``: the push's reaction acts on the root, equal and opposite at the push point."""
    link, root = session.joint_child[joint], session.link_names[0]
    dt = session.options.conventions.timestep
    lead = force = 0.0  # how far the hand runs ahead of the push point, m; its force, N
    lever: float | None = None

    def law(k, q, qd):
        nonlocal lead, force, lever
        push = push_geometry(session, joint)
        c, lever = push.point, push.lever
        d = sign * push.direction
        v = sign * qd * (lever or 1.0)  # speed of the push point along d
        lead, force = hand.step(lead, v, dt)
        session.apply_link_force(link, force * d, c)
        if react and link != root:
            session.apply_link_force(root, -force * d, c)  # the steadying hand's reaction

    def record(k, q, qd):
        run.steps += 1
        run.peak_force = max(run.peak_force, force)
        eff = force * (lever or 1.0)
        if eff >= run.peak_effort:
            run.peak_effort, run.lever = eff, lever
        xy, rot = watch.current()
        disp = float(np.linalg.norm(xy))
        run.max_disp, run.max_rot = max(run.max_disp, disp), max(run.max_rot, rot)
        run.record(run.steps * dt, q, force, disp, 0.0)
        if not np.isfinite(q):
            return True
        if reached_if(frac(q)):
            run.reached, run.t_reach = True, run.steps * dt
            return True
        # the object moves instead of the joint: the pusher stops
        return run.max_disp > cfg.slide_tol or run.max_rot > cfg.tip_tol

    if not run.reached:
        run_stroke(session, joint, n_push, law=law, record=record)


def run_probes(session, joints: dict[str, tuple[float, float, float]], *, actions: tuple[str, ...] = ("close", "open"),
               holds_position: bool = False, model: UrdfModel | None = None,
               returns: set[str] | frozenset[str] = frozenset(), floor_stops: dict[str, float] | None = None
               ) -> list[ProbeResult]:
    """Probe every joint of ``joints`` (joint -> (q_closed, direction,
    open_range)) with every action, each from the session's state at call
    time (saved and restored). ``model``: also retry a part shut in by
    another; ``returns``, ``floor_stops``: per joint, as :func:`probe_joint`.

    Returns:
        One :class:`ProbeResult` per joint and action, in order; the session is left at the saved state.
    """
    sid = session.save_state()
    out = []
    try:
        for name, end in joints.items():
            for action in actions:
                session.restore_state(sid)
                kw = dict(action=action, holds_position=holds_position, model=model,
                          returns=name in returns, floor_stop=(floor_stops or {}).get(name))
                r = probe_joint(session, name, end, **kw)
                # an open probe that stalled near the closed end with the object still: its part shut in by another
                if (model is not None and r.action == "open" and not r.success and not r.reached and not (r.slid or r.tipped)
                        and np.isfinite(r.release_fraction) and r.release_fraction < SHUT_IN_FRACTION):
                    r = _probe_cleared(session, r, joints, model, sid, kw) or r
                out.append(r)
        session.restore_state(sid)
    finally:
        session.discard_state(sid)
    return out


def probe_object(obj: SimObject, closed: dict[str, tuple[float, float, float]], *, actions: tuple[str, ...] = ("close", "open"),
                 holds_position: bool = False, returns: set[str] | frozenset[str] = frozenset()) -> tuple[list[ProbeResult], list[str]]:
    """The passive probes of ``obj`` in a PyBullet session of its own, from its unstepped initial state: every joint of
    ``closed`` (joint -> (q_closed, direction, open range), rad or m) that opens, but a wheel the object stands on
    (the object is rolled, not it), each open probe's target ending where the floor stops the part; ``returns``: joints
    whose close probe rebounds by design (a spring). Returns (results, notes).

    Raises:
        EngineUnavailable; whatever loading ``obj.source`` raises.
    """
    model = obj.source.model(mode="lenient")
    notes: list[str] = []
    with obj.open("pybullet") as session:
        rolling = set(rolling_joints(session, subtrees(model)))
        targets = {n: c for n, c in closed.items() if c[2] > 0 and n not in rolling}
        try:
            stops = floor_stops(model, obj.source.path, dict(obj.state), targets)
        except (OSError, MeshReadError) as exc:
            notes.append(f"probes: where the floor stops the parts was not measured ({exc}): no stop")
            stops = {}
        stops = {n: s for n, s in stops.items() if s / targets[n][2] < OPEN_FAR_TARGET}
        notes += [f"probes: the floor stops {n} {s:.3g} from its closed end, of its {targets[n][2]:.3g} range (the object resting "
                  "as it is): an open probe's target ends there" for n, s in stops.items()]
        return run_probes(session, targets, actions=actions, holds_position=holds_position, model=model, returns=returns,
                          floor_stops=stops), notes


def _probe_cleared(session, first: ProbeResult, joints: dict[str, tuple[float, float, float]], model: UrdfModel, sid: int,
                   kw: dict) -> ProbeResult | None:
    """The open probe again with the joints between its part and the link it
    stalled against lifted towards their open ends; None when no other movable
    joint places that link or every retry fails. The session must be where the first probe left it."""
    name = first.joint
    jd = next((j for j in model.joints if j.name == name), None)
    if jd is None:
        return None
    sub = subtrees(model).get(name)
    links = [ln for ln in sub if ln in session.link_names] if sub else [session.joint_child[name]]
    who = blocking_link(session, links, rigid_group(model, jd.parent))
    if who is None:
        return None
    ends: dict[str, tuple[float, float]] = {}  # joint -> (position now, its open end)
    now = session.joint_positions()
    for k in joints_between(model, jd.child, who):
        if k == name or k not in session.joint_types:
            continue
        if k in joints:
            kc, kd, kr = joints[k]
            if kr > 0:
                ends[k] = (now[k], kc + kd * kr)
        else:  # not probed: the end of its limits farther from where it is
            lo, hi = session.joint_limits[k]
            if np.isfinite(lo) and np.isfinite(hi) and hi > lo:
                ends[k] = (now[k], hi if abs(hi - now[k]) >= abs(now[k] - lo) else lo)
    if not ends:
        return None
    # lifted only as far as needed, held by a zero-velocity drive limited to the probe's force at their lever
    f_max = first.max_force
    for share in CLEARING_SHARES:
        opened = {k: q + share * (end - q) for k, (q, end) in ends.items()}
        session.restore_state(sid)
        session.set_joint_positions(opened)
        for k in opened:
            session.drive_joint(k, 0.0, f_max * (push_geometry(session, k).lever or 1.0))
        try:
            retry = probe_joint(session, name, joints[name], **kw)
        finally:
            for k in opened:
                session.release_joint(k)
        if retry.success:
            retry.notes.append(f"{who} is in the way at the initial state (stalled at {max(first.release_fraction, 0.0):.0%} open); "
                               f"probed with {', '.join(sorted(opened))} held {share:.0%} of the way open, as a hand opens it first")
            return retry
    return None


def probes_metric(results: list[ProbeResult]) -> MetricResult:
    """Aggregate PyBullet's probes: value = failed probes; passes iff none failed (None with nothing probed)."""
    failed = [r for r in results if not r.success]
    return MetricResult(
        name="probes", value=float(len(failed)), unit="failed probes", passed=(not failed) if results else None,
        threshold="every close/open probe reaches its target, the body steadied by the other hand (gripped when it "
        "weighs at most 22.2 N), without the object sliding (> 5 mm) or tipping (> 0.05 rad) and a closed joint "
        "does not spring back",
        details={"probes": [r.summary() for r in results], "failures": [f"{r.joint} {r.action}: {r.failure}" for r in failed]},
        engine="pybullet")
