"""Passive behaviour probes: a scripted pusher tries to close / open a joint.

The cheap stand-in for the thesis's policies (SPEC, "Behavioral fidelity"). A
probe runs in a simulator session (PyBullet in the evaluation) under the SPEC's conventions (root free on the ground,
or fixed where the output folder declares the asset mounted: ``initial_state.json``
"root", ``tasks.interpret.mounting``; gravity, passive joints) and applies a force on the moving link, as a finger
would, while **the other hand holds the body**: by default
(``ProbeConfig.hold_body``) the equal and opposite force acts on the root link
at the same point, so the push is internal to the object; and a body light
enough for a hand to lift (weight <= ``ProbeConfig.hold_force``, 22.2 N, the
ADA's 5 lbf below) is gripped: the root is held where it settled by a
bounded hold (``SimSession.hold_root``: a fixed constraint to the world of at
most that force) through the push and the observation after release, as when
a person holds a USB stick while swivelling its cover or a pocket knife while
opening its blade. Why the grip as well as the reaction: the reaction cancels
the push but not the forces from outside the object that the part's motion
brings (the ground's friction on a cover dragged over the table) nor the
reaction to the part's angular momentum (a blade swung about a vertical
axis yaws the handle); on light objects they slid or turned the body 5 mm /
0.05 rad while the part moved freely (``tests/tasks/check/test_probes.py``, a
USB-sized swivel: 5 g stick, 15 g cover; generated USB stick and pocket
knife of the unseen-category runs). A heavier object stands on its own and
a hand only steadies it: the reaction alone, so a part that drags on the
floor and pulls the body along still fails (a door modelled flush with the
floor: ``tasks.state.ground_clearance``). The object counts as moved when
it slides or tips anyway (the grip overpowered). Whether a *free* object
can be operated with a realistic force without sliding or tipping (a heavy
lid opened past the body's footprint) is the task-execution metric's
question (root free, one gripper); whether it rests at its requested state,
the rest tiers'. An engine without a bounded hold gets the reaction only (a
note).
``hold_body=False`` gives the external push (the pusher alone; the object's
ground friction must resist it).

Definitions (re-derivable; see ``docs/metrics.md``):

- Push point c: for a revolute joint the corner of the moving link's collision
  AABB (world, m) farthest from the axis (where a hand or a gripper opens a
  lid, a door or a handle: the issue's "point of the moving link farthest
  from the axis"); for a prismatic joint the AABB's centre. For a
  revolute joint with axis a (unit, world) through the link frame origin o, the
  lever r = (c - o) - ((c - o).a) a; the push direction is +-(a x r)/|a x r|
  and the generalised torque is F |r|. For a prismatic joint the direction is
  +-a. The sign points from the current position towards the target.
- Force law (a hand moving at v_des, coupled to the part by a spring-damper,
  the impedance model of a hand or a gripper): the hand runs ahead of the push
  point by s, s_{k+1} = clip(s_k + (v_des - v) dt, 0, F_max / k), and pushes
  with F = clip(k s + c (v_des - v), 0, F_max); v the speed of the push point
  along the direction (m/s), v_des = ``push_speed``. A stuck joint sees the
  force ramp to F_max in F_max / (k v_des) s; a free one is pushed at about
  v_des without overshoot.
- Stiffness k = min(F_max / (v_des * ramp_time), m_eff omega^2) and damping
  c = 2 sqrt(k m_eff) (critical damping of the hand-part spring), omega =
  ``PUSHER_OMEGA_DT`` / dt: the spring acts explicitly on the engine's step dt,
  and a stiffness set by the whole object's weight made a light part (a
  toilet's flush lever, 5 g of effective mass on a 50 kg toilet) jump 0.14 rad
  in one step, slam into its stop and bounce back. With omega dt = 0.25 and
  critical damping the step is stable for an effective mass up to 4 times below
  m_eff (explicit step of a spring-damper: |z| < 1 for the characteristic
  polynomial z^2 - (2 - a) z + (1 - a + b), a = c dt / m, b = k dt^2 / m, iff
  b < a < 2 + b / 2; Jury's criterion, e.g. Franklin, Powell & Workman,
  *Digital Control of Dynamic Systems*, 3rd ed. 1998, section 4.5). m_eff is a
  lower bound of the part's effective mass at the push point: for a revolute
  joint (I_min + m d^2) / r^2 summed over the links rigid with the child (I_min
  the smallest principal moment about the link's COM, d the COM's distance
  from the axis, r the lever: the parallel-axis theorem with the smallest
  moment), for a prismatic joint their mass.
- F_max = max(``min_force``, ``force_factor`` * m_total * g) (N); ``min_force``
  = 22.2 N (5 lbf), the largest force the 2010 ADA Standards for Accessible
  Design (section 309.4, operable parts) allow a control to need: any hand can
  apply it, so a light object's part that needs up to this much is operable.
  A stuck part sees the force ramp at k v_des: a light part's bounded
  stiffness ramps slower than ``ramp_time``, and the push lasts at least
  until ``min_force`` is reached (ramp below), so every part is pushed with
  at least the ADA force before it counts as not moving (within the push
  cap ``max_push_time``: a part lighter than about 1 g at the push point
  ramps longer than that, and its probe's note says the cap cut it).
- Targets as opening fractions f (0 closed, 1 fully open, from the geometric
  closed end): close -> f = 0.05, reached at f <= 0.10; open -> f = 0.6,
  reached at f >= 0.55 (f = 0.9 / 0.85 when the joint starts beyond 0.55);
  an open target beyond where the floor stops the part (``floor_stop``) is
  that stop.
- The object first settles freely for ``settle_time`` s; the push starts from
  there (root pose and joint position at that moment are the references).
- Push for at most max(``push_time``, ramp + 1.5 * travel / ``push_speed``)
  s, ramp = max(``ramp_time``, ``min_force`` / (k v_des)), travel the distance the
  push point covers to the target
  (|q_target - q0| times the lever; m), so a long lid pushed at its far corner
  has time to arrive (the pusher stops early once the object slid or tipped),
  but never longer than ``max_push_time`` (30 s, :data:`MAX_PUSH_TIME`:
  bounds the probe's cost when a part lies far from its axis or is very
  light; a note says when the cap cut the push), then release (no force) for
  ``release_time`` s.
- Object moved: during the push the object's footprint point (the point below
  the root's origin at the object's lowest height at the start, carried with
  the root) moved horizontally > ``slide_tol`` (m, slid: a tall object that
  rocks a little does not count as sliding) or
  rotated > ``tip_tol`` (rad, tipped).
- Rebound: after release the fraction moved back towards the start by >
  max(0.05, floor / range), floor the SPEC's rest tolerance (0.01 rad, 1 mm:
  ``REBOUND_FLOOR_*``); kept moving: moved on beyond the target by as much or
  ends with |q_dot| > 0.05 rad/s (0.005 m/s).
- A part shut in by another (an open probe stalls before
  ``SHUT_IN_FRACTION`` of its range without the object moving, and the link
  it touches there is placed by other movable joints: a stapler's magazine
  under its closed top, a toilet seat under its lid) is probed again with the
  joints between them lifted towards their open ends, only as far as needed
  (``CLEARING_SHARES`` of the way, in turn) and held there (a zero-velocity
  drive limited to the probe's force at their lever), as a hand lifts the top
  first (the
  joint sweep's rule, :func:`asset2sim.tasks.check.sweep._sweep_clearing`);
  the retry is kept when it succeeds, with a note. Needs the URDF model.
- A probe succeeds iff the target is reached without the object moving and, for
  a close probe, without rebound (a drawer that springs back), unless the
  joint's spring is one its part prior or the request expects (it returns
  by design: a toaster's carriage lever pushed down, a stapler's arm; the
  task-execution check's rule, :func:`asset2sim.tasks.check.task_tier.hold_required_by_label`).
  An open probe's rebound (a lid that falls shut) fails only when the
  request asks the joint to hold its position.
"""

from __future__ import annotations

from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from asset2sim.engines.base import EngineUnsupported
from asset2sim.schemas.report import MetricResult
from asset2sim.tasks.check.support import SupportWatch
from asset2sim.tasks.check.sweep import SHUT_IN_FRACTION, blocking_link, joints_between
from asset2sim.tasks.geometry.limits import rigid_group, subtrees
from asset2sim.urdf import UrdfModel

CLOSE_TARGET, CLOSE_REACHED = 0.05, 0.10
OPEN_TARGET, OPEN_REACHED = 0.6, 0.55
OPEN_FAR_TARGET, OPEN_FAR_REACHED = 0.9, 0.85
REBOUND_FRACTION = 0.05
#: Smallest motion after release that counts as a rebound or as moving on, rad
#: / m: the SPEC's rest-stability tolerances (D_ori <= 0.01 rad, D_pos <= 1 mm;
#: ``tasks.check.metrics``). A 6 mm toilet button pressed 0.3 mm into its stop
#: (the engine's soft limit) comes back 0.7 mm: 11 % of its range, no spring.
REBOUND_FLOOR_REVOLUTE = 0.01
REBOUND_FLOOR_PRISMATIC = 0.001
#: Push time allowed per unit of travel time at ``push_speed`` (dimensionless).
TRAVEL_TIME_MARGIN = 1.5
#: Shares of the way to their open ends that the joints shutting a part in
#: are lifted to, in turn, when that part is probed again (module docstring).
CLEARING_SHARES = (0.25, 0.5, 0.75, 1.0)
#: Longest push of one probe, s of simulated time, whatever the travel and the
#: force ramp ask (``ProbeConfig.max_push_time``). The asked time grows with
#: the lever (travel = opening x lever) and with 1 / the part's effective mass
#: (the ramp of the bounded pusher stiffness): an asset whose parts lie far
#: from their joint axes (mesh ``scale`` 1e-4 on a stapler, the joint origins
#: left in file units: a 95 m lever on a 0.18 m part) asked up to 924 s per
#: probe (222,000 engine steps), and the evaluation behind its HTML report
#: took 10.7 - 17.2 s instead of 1.2 s.
#: The largest household part needs far less: a "very large" door (the
#: Door prior 2.1 x 0.9 m times 1.7: 3.6 m tall, 1.5 m wide, so a lever of
#: about 1.5 m) opened 1.57 rad travels 2.4 m, 1 + 1.5 x 2.4 / 0.25 = 15 s;
#: twice that is the cap. The 12 dev objects' probes reach their targets
#: within 3.1 s. A push cut by the cap says so in the probe's notes.
MAX_PUSH_TIME = 30.0
#: omega dt of the pusher's spring against the part's effective mass (module
#: docstring, "Stiffness"): a quarter of the explicit step's stability limit.
PUSHER_OMEGA_DT = 0.25


@dataclass
class ProbeConfig:
    """Probe knobs (units on every field)."""

    settle_time: float = 0.25
    """free settling before the push, s"""
    push_time: float = 2.0
    """longest push, s, unless the travel needs longer (module docstring)"""
    max_push_time: float = MAX_PUSH_TIME
    """longest push whatever the travel and the ramp ask, s (module docstring):
    bounds a probe's cost (:data:`MAX_PUSH_TIME`)"""
    release_time: float = 0.75
    """observation after release, s"""
    push_speed: float = 0.25
    """desired speed of the push point, m/s"""
    ramp_time: float = 1.0
    """time for a stuck pusher to reach F_max, s"""
    force_factor: float = 2.0
    """F_max = force_factor * total weight (dimensionless) ..."""
    min_force: float = 22.2
    """... but at least this, N (ADA 2010 section 309.4: 5 lbf)"""
    slide_tol: float = 0.005
    """root displacement that counts as the object sliding, m"""
    tip_tol: float = 0.05
    """root rotation that counts as tipping, rad"""
    hold_body: bool = True
    """the other hand holds the body: the push's reaction acts on the root at
    the push point, and a body that weighs at most ``hold_force`` is gripped
    (module docstring); False: an external push only"""
    hold_force: float = 22.2
    """the other hand's force, N: a body weighing at most this is held in
    place by a hold of at most this force (the ADA's 5 lbf, as ``min_force``:
    a hand that applies it can lift such a body)"""
    settle_velocity_revolute: float = 0.05
    """|q_dot| after release that counts as still moving, rad/s"""
    settle_velocity_prismatic: float = 0.005
    """... for prismatic joints, m/s"""


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
    peak_effort: float
    """peak generalised force: N*m (revolute, F*|r|) or N (prismatic)"""
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
        d = {k: v for k, v in self.__dict__.items() if k != "trace"}
        return d




def _push_geometry(session, joint: str) -> tuple[np.ndarray, np.ndarray, float | None]:
    """Push point (3,) m, unit direction (3,) that increases q, lever (m) or None."""
    link = session.joint_child[joint]
    axis_local = session.joint_axis(joint)
    o, R = session.link_frame(link)
    a = R @ axis_local
    a /= max(np.linalg.norm(a), 1e-12)
    lo, hi = session.link_aabb(link)
    c = 0.5 * (lo + hi)
    if session.joint_types[joint] == "prismatic":
        return c, a, None
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
    rr = (corners - o) - np.outer((corners - o) @ a, a)
    # The point of the moving link farthest from the axis (its box's far
    # corner), where a hand or a gripper opens a lid, a door or a handle.
    k = int(np.argmax(np.linalg.norm(rr, axis=1)))
    c, r = corners[k], rr[k]
    lever = float(np.linalg.norm(r))
    t = np.cross(a, r)
    t /= max(np.linalg.norm(t), 1e-12)
    return c, t, max(lever, 1e-4)


def push_budget(cfg: ProbeConfig, ramp: float, travel: float) -> tuple[float, float]:
    """(allowed, asked) push time of one probe, s: asked = max(``push_time``,
    ``ramp`` + ``TRAVEL_TIME_MARGIN`` x ``travel`` / ``push_speed``) (``ramp``
    the force ramp's time, s; ``travel`` the distance the push point covers
    to the target, m); allowed = asked capped at ``max_push_time`` (never
    below ``push_time``), which bounds a probe's engine steps whatever the
    part's lever and effective mass (:data:`MAX_PUSH_TIME`)."""
    asked = max(cfg.push_time, ramp + TRAVEL_TIME_MARGIN * travel / cfg.push_speed)
    return min(asked, max(cfg.max_push_time, cfg.push_time)), asked


def total_mass(session) -> float:
    """Sum of the masses the engine uses for every link of the body, kg."""
    return float(sum(session.link_masses().values()))


def moved_links(session, joint: str, model: UrdfModel | None = None) -> list[str]:
    """The links ``joint`` moves (its child and every link below) by the URDF
    ``model``; the child link alone without a model."""
    if model is not None:
        links = subtrees(model).get(joint)
        if links:
            return [ln for ln in links if ln in session.link_names]
    return [session.joint_child[joint]]


def effective_mass(session, joint: str, model: UrdfModel | None = None) -> float:
    """Lower bound (kg) of the effective mass of ``joint``'s part at the probe's
    push point: for a revolute joint sum (I_min + m d^2) / r^2 over the links
    rigid with the child (module docstring), for a prismatic joint their mass;
    at least 1e-4 kg. From the session's own masses and principal moments
    (:meth:`SimSession.held_physics`) and the current link frames.

    Raises:
        KeyError: unknown joint.
    """
    child = session.joint_child[joint]
    rigid = [ln for ln in (rigid_group(model, child) if model is not None else {child}) if ln in session.link_names]
    held = session.held_physics().links
    _, _, lever = _push_geometry(session, joint)
    if lever is None:
        return max(sum(held[ln].mass for ln in rigid if ln in held), 1e-4)
    o, R = session.link_frame(child)
    a = R @ np.asarray(session.joint_axis(joint), float)
    a /= max(float(np.linalg.norm(a)), 1e-12)
    inertia = 0.0
    for ln in rigid:
        h = held.get(ln)
        if h is None or not h.mass > 0:
            continue
        p, Rl = session.link_frame(ln)
        c = np.asarray(p, float) + np.asarray(Rl, float) @ np.asarray(h.com, float) - np.asarray(o, float)
        d2 = float(c @ c - (c @ a) ** 2)
        inertia += float(np.min(h.principal)) + h.mass * max(d2, 0.0)
    return max(inertia / lever**2, 1e-4)


@contextmanager
def _root_held(session, max_force: float | None, notes: list[str]):
    """The other hand grips the body for the push and the observation after
    release: :meth:`~asset2sim.engines.base.SimSession.hold_root` with the
    hand's force ``max_force`` (N), released on exit; None: the body is not
    gripped. An engine without a bounded root hold gets the push's
    reaction on the root only (a note in ``notes``)."""
    held = False
    if max_force is not None:
        try:
            session.hold_root(max_force)
            held = True
        except EngineUnsupported as exc:
            notes.append(f"the root is not held ({exc}): the push's reaction on the root only")
    try:
        yield
    finally:
        if held:
            session.release_root()


def probe_joint(
    session,
    joint: str,
    *,
    closed: float,
    direction: float,
    open_range: float,
    action: str,
    config: ProbeConfig | None = None,
    holds_position: bool = False,
    model: UrdfModel | None = None,
    returns: bool = False,
    floor_stop: float | None = None,
) -> ProbeResult:
    """Run one probe on ``joint`` of a session from its current state.

    Args:
        session: a :class:`asset2sim.engines.base.SimSession` (root free, on the ground); it is stepped in place.
        joint: movable joint name.
        closed: q_closed, rad or m; ``direction`` +1/-1 the opening direction;
            ``open_range`` > 0 the largest opening from q_closed (rad or m).
        action: ``close`` or ``open``.
        config: probe knobs.
        holds_position: the request asks the joint to hold its position (an
            open probe that falls back then fails).
        model: the session's URDF model (the mass the joint moves and the
            links rigid with its child); None: the child link alone.
        returns: the joint's spring is one its part prior or the request
            expects (:func:`asset2sim.tasks.check.task_tier.hold_required_by_label`):
            a close probe's rebound is its design (a toaster's carriage
            lever, a stapler's arm), noted, not a failure.
        floor_stop: opening (rad or m from ``closed``) at which the floor
            stops the part with the object resting as it is
            (:func:`asset2sim.tasks.state.ground_clearance.floor_stops`);
            an open probe's target is capped there (reached at
            ``OPEN_REACHED / OPEN_TARGET`` of it), with a note. None: no stop.

    Raises:
        ValueError: unknown action or non-positive ``open_range``.
        KeyError: unknown joint.
    """
    if action not in ("close", "open"):
        raise ValueError(f"probe action must be 'close' or 'open', got {action!r}")
    if not open_range > 0:
        raise ValueError(f"joint {joint!r}: open_range must be > 0, got {open_range}")
    cfg = config or ProbeConfig()
    if joint not in session.joint_child:
        raise KeyError(joint)
    link = session.joint_child[joint]
    dt = session.options.conventions.timestep
    jtype = session.joint_types[joint]
    prismatic = jtype == "prismatic"

    def frac(q: float) -> float:
        return float(direction * (q - closed) / open_range)

    def qpos() -> tuple[float, float]:
        return session.joint_state(joint)

    # Let the object come to rest on the ground first, so drift of an object
    # that is unstable by itself is not taken for the push moving it.
    for _ in range(int(round(cfg.settle_time / dt))):
        session.step(1)
    q0, _ = qpos()
    f0 = frac(q0)
    if action == "close":
        f_target, reached_if = CLOSE_TARGET, (lambda f: f <= CLOSE_REACHED)
    elif f0 < OPEN_REACHED:
        f_target, reached_if = OPEN_TARGET, (lambda f: f >= OPEN_REACHED)
    else:
        f_target, reached_if = OPEN_FAR_TARGET, (lambda f: f >= OPEN_FAR_REACHED)
    stop_notes: list[str] = []
    if action == "open" and floor_stop is not None and floor_stop / open_range < f_target:
        f_target = max(floor_stop / open_range, 0.0)  # the floor stops the part before the target
        reached_if = (lambda f, at=f_target * OPEN_REACHED / OPEN_TARGET: f >= at)
        stop_notes.append(f"the floor stops it {f_target:.0%} open (the object resting as it is): the open probe's target")
    q_target = closed + direction * f_target * open_range
    # +1 when the target needs q to increase.
    sign = 1.0 if q_target >= q0 else -1.0
    weight = total_mass(session) * abs(session.options.conventions.gravity)
    f_max = max(cfg.min_force, cfg.force_factor * weight)
    m_eff = effective_mass(session, joint, model)
    stiffness = min(f_max / (cfg.push_speed * cfg.ramp_time), m_eff * (PUSHER_OMEGA_DT / dt) ** 2)
    damping = 2.0 * float(np.sqrt(stiffness * m_eff))
    ramp = max(cfg.ramp_time, cfg.min_force / (stiffness * cfg.push_speed))
    # Sliding is measured where the object stands (the footprint point, carried with the root).
    watch = SupportWatch(session, session.link_names[0])
    # The push may last as long as the travel needs at the push speed (with
    # the force ramp and a 50 % margin), at least ``push_time``: a pusher at
    # a long lid's far corner has a longer arc to cover than at its centre.
    _, _, lever0 = _push_geometry(session, joint)
    travel = abs(q_target - q0) * (lever0 if lever0 is not None else 1.0)
    push_s, asked_s = push_budget(cfg, ramp, travel)
    n_push = int(round(push_s / dt))
    n_rel = int(round(cfg.release_time / dt))
    tr: dict[str, list[float]] = {"t": [], "q": [], "force": [], "root_disp": [], "phase": []}
    force = lead = 0.0  # lead: how far the hand runs ahead of the push point, m
    peak_force = peak_effort = 0.0
    lever_used: float | None = None
    reached = reached_if(f0)
    t_reach = 0.0 if reached else None
    max_disp = max_rot = 0.0
    k = 0
    hold_notes: list[str] = []
    # A body a hand can lift (its weight within the hand's force) is gripped
    # by the other hand; a heavier one stands on its own, steadied only
    # against the push (module docstring).
    gripped = cfg.hold_body and weight <= cfg.hold_force
    with _root_held(session, cfg.hold_force if gripped else None, hold_notes):
        while not reached and k < n_push:
            c, t_dir, lever = _push_geometry(session, joint)
            d = sign * t_dir
            q, qd = qpos()
            # speed of the push point along d
            v = sign * qd * (lever if lever is not None else 1.0)
            lead = float(np.clip(lead + (cfg.push_speed - v) * dt, 0.0, f_max / stiffness))
            force = float(np.clip(stiffness * lead + damping * (cfg.push_speed - v), 0.0, f_max))
            session.apply_link_force(link, force * d, c)
            if cfg.hold_body and link != session.link_names[0]:
                session.apply_link_force(session.link_names[0], -force * d, c)  # the holding hand's reaction
            session.step(1)
            k += 1
            peak_force = max(peak_force, force)
            eff = force * (lever if lever is not None else 1.0)
            if eff >= peak_effort:
                peak_effort, lever_used = eff, lever
            q, qd = qpos()
            xy, rot = watch.current()
            disp = float(np.linalg.norm(xy))
            max_disp, max_rot = max(max_disp, disp), max(max_rot, rot)
            tr["t"].append(k * dt)
            tr["q"].append(q)
            tr["force"].append(force)
            tr["root_disp"].append(disp)
            tr["phase"].append(0.0)
            if not np.isfinite(q):
                break
            if reached_if(frac(q)):
                reached, t_reach = True, k * dt
            elif max_disp > cfg.slide_tol or max_rot > cfg.tip_tol:
                break  # the object moves instead of the joint: the pusher stops
        q_rel, _ = qpos()
        f_rel = frac(q_rel)
        f_min = f_maxv = f_rel
        for i in range(n_rel):
            session.step(1)
            q, qd = qpos()
            f = frac(q)
            f_min, f_maxv = min(f_min, f), max(f_maxv, f)
            tr["t"].append((k + i + 1) * dt)
            tr["q"].append(q)
            tr["force"].append(0.0)
            tr["root_disp"].append(float(np.linalg.norm(watch.current()[0])))
            tr["phase"].append(1.0)
    q_end, qd_end = qpos()
    f_end = frac(q_end)
    # "towards the start": for close the start is more open (larger f).
    tol = max(REBOUND_FRACTION, (REBOUND_FLOOR_PRISMATIC if prismatic else REBOUND_FLOOR_REVOLUTE) / open_range)
    if action == "close":
        rebound = f_maxv - f_rel > tol
        kept = f_rel - f_min > tol
    else:
        rebound = f_rel - f_min > tol
        kept = f_maxv - f_rel > tol
    vlim = cfg.settle_velocity_prismatic if prismatic else cfg.settle_velocity_revolute
    if abs(qd_end) > vlim:
        kept = True
    slid = max_disp > cfg.slide_tol
    tipped = max_rot > cfg.tip_tol
    failure = ""
    if not np.isfinite(q_end):
        failure = "diverged"
    elif not reached:
        failure = "target not reached" + (" (the object moved instead)" if slid or tipped else "")
    elif slid or tipped:
        failure = "the object " + ("slid" if slid else "tipped") + " instead of the joint moving"
    elif action == "close" and rebound and not returns:
        failure = "springs back after release"
    elif action == "open" and rebound and holds_position:
        failure = "does not hold the open position after release"
    notes = stop_notes + hold_notes
    if not reached and push_s < asked_s and k >= n_push:
        notes.append(f"push stopped at the {push_s:.0f} s cap (ProbeConfig.max_push_time): the travel ({travel:.3g} m at the "
                     f"push point, lever {lever0 if lever0 is not None else 0.0:.3g} m) and the force ramp ({ramp:.3g} s) asked "
                     f"{asked_s:.0f} s")
    if action == "open" and rebound and not holds_position:
        notes.append("falls back after release (allowed: the request does not ask it to hold)")
    if action == "close" and rebound and returns:
        notes.append("springs back after release (allowed: a spring its part prior or the request expects returns it)")
    if kept:
        notes.append("keeps moving after release")
    return ProbeResult(
        joint=joint,
        joint_type=jtype,
        action=action,
        start=q0,
        target=float(q_target),
        start_fraction=f0,
        target_fraction=f_target,
        reached=bool(reached),
        time_to_reach=t_reach,
        peak_force=float(peak_force),
        peak_effort=float(peak_effort),
        lever_arm=lever_used,
        max_force=float(f_max),
        root_displacement=float(max_disp),
        root_rotation=float(max_rot),
        slid=bool(slid),
        tipped=bool(tipped),
        release_fraction=float(f_rel),
        final_fraction=float(f_end) if np.isfinite(f_end) else float("nan"),
        rebound=bool(rebound),
        kept_moving=bool(kept),
        success=not failure,
        failure=failure,
        notes=notes,
        trace=tr,
    )


def run_probes(
    session,
    joints: dict[str, tuple[float, float, float]],
    *,
    actions: tuple[str, ...] = ("close", "open"),
    config: ProbeConfig | None = None,
    holds_position: bool = False,
    model: UrdfModel | None = None,
    returns: set[str] | frozenset[str] = frozenset(),
    floor_stops: dict[str, float] | None = None,
) -> list[ProbeResult]:
    """Probe every joint of ``joints`` with every action, each from the
    session's state at call time (saved and restored with the session's
    ``save_state``/``restore_state``; PyBullet: ``saveState``/``restoreState``).

    Args:
        session: a session at the initial state on the ground.
        joints: joint -> (q_closed, direction, open_range).
        actions: which probes.
        config, holds_position: see :func:`probe_joint`.
        model: the session's URDF model: the mass a joint moves, and a part
            shut in by another is probed again with that one open (module
            docstring); None: neither.
        returns: joints whose spring returns them by design (see :func:`probe_joint`).
        floor_stops: joint -> opening where the floor stops it (``floor_stop``
            of :func:`probe_joint`); joints not in it have no stop.

    Returns:
        One :class:`ProbeResult` per joint and action, in order. The session is
        left at the saved state.
    """
    sid = session.save_state()
    out = []
    try:
        for name, (closed, direction, rng) in joints.items():
            for action in actions:
                session.restore_state(sid)
                kw = dict(closed=closed, direction=direction, open_range=rng, action=action, config=config,
                          holds_position=holds_position, model=model, returns=name in returns,
                          floor_stop=(floor_stops or {}).get(name))
                r = probe_joint(session, name, **kw)
                if model is not None and _shut_in(r):
                    retry = _probe_cleared(session, r, joints, model, sid, kw)
                    if retry is not None:
                        r = retry
                out.append(r)
        session.restore_state(sid)
    finally:
        session.discard_state(sid)
    return out


def _shut_in(r: ProbeResult) -> bool:
    """An open probe that stalled near the closed end with the object still."""
    return (r.action == "open" and not r.success and not r.reached and not (r.slid or r.tipped)
            and np.isfinite(r.release_fraction) and r.release_fraction < SHUT_IN_FRACTION)


def _probe_cleared(session, first: ProbeResult, joints: dict[str, tuple[float, float, float]], model: UrdfModel, sid: int,
                   kw: dict) -> ProbeResult | None:
    """The open probe of ``name`` again with the joints between its part and
    the link it stalled against lifted towards their open ends (module docstring); None
    when no other movable joint places that link or the retry fails too. The
    session must be where the first probe left it."""
    name = first.joint
    jd = next((j for j in model.joints if j.name == name), None)
    if jd is None:
        return None
    links = moved_links(session, name, model)
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
    # the other hand lifts them only as far as needed (a stapler whose top is
    # swung fully back tips over): a quarter of the way to their open ends,
    # then half, three quarters, all the way; held there by a zero-velocity
    # drive limited to the probe's force at their lever
    f_max = first.max_force
    for share in CLEARING_SHARES:
        opened = {k: q + share * (end - q) for k, (q, end) in ends.items()}
        session.restore_state(sid)
        session.set_joint_positions(opened)
        for k in opened:
            _, _, lever = _push_geometry(session, k)
            session.drive_joint(k, 0.0, f_max * (lever if lever is not None else 1.0))
        try:
            retry = probe_joint(session, name, **kw)
        finally:
            for k in opened:
                session.release_joint(k)
        if retry.success:
            retry.notes.append(f"{who} is in the way at the initial state (stalled at {max(first.release_fraction, 0.0):.0%} open); "
                               f"probed with {', '.join(sorted(opened))} held {share:.0%} of the way open, as a hand opens it first")
            return retry
    return None


def probes_metric(results: list[ProbeResult], *, engine: str = "pybullet") -> MetricResult:
    """Aggregate probes: value = number of failed probes; passes iff none failed.

    ``passed`` is None when there was nothing to probe.
    """
    failed = [r for r in results if not r.success]
    return MetricResult(
        name="probes",
        value=float(len(failed)),
        unit="failed probes",
        passed=(not failed) if results else None,
        threshold="every close/open probe reaches its target, the body steadied by the other hand (gripped when it "
        "weighs at most 22.2 N), without the object sliding (> 5 mm) or tipping (> 0.05 rad) and a closed joint "
        "does not spring back",
        details={
            "probes": [r.summary() for r in results],
            "failures": [f"{r.joint} {r.action}: {r.failure}" for r in failed],
        },
        engine=engine,
    )
