"""The probes' pusher (:mod:`asset2sim.tasks.check.probes`): a hand that pushes
the moving link at its far corner through a bounded spring-damper, the time it
may push, the other hand that holds the body, and the probe's knobs.

Definitions (re-derivable; see ``docs/design/metrics.md``):

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
- Push for at most max(``push_time``, ramp + 1.5 * travel / ``push_speed``)
  s, ramp = max(``ramp_time``, ``min_force`` / (k v_des)), travel the distance the
  push point covers to the target
  (|q_target - q0| times the lever; m), so a long lid pushed at its far corner
  has time to arrive (the pusher stops early once the object slid or tipped),
  but never longer than ``max_push_time`` (30 s, :data:`MAX_PUSH_TIME`:
  bounds the probe's cost when a part lies far from its axis or is very
  light; a note says when the cap cut the push), then release (no force) for
  ``release_time`` s.
"""

from __future__ import annotations

from contextlib import contextmanager
from dataclasses import dataclass

import numpy as np

from asset2sim.engines.base import EngineUnsupported
from asset2sim.tasks.check.contact_points import joint_frame_axis
from asset2sim.tasks.geometry.limits import rigid_group
from asset2sim.urdf import UrdfModel

#: Push time allowed per unit of travel time at ``push_speed`` (dimensionless).
TRAVEL_TIME_MARGIN = 1.5
#: Longest push of one probe, s of simulated time, whatever the travel and the
#: force ramp ask (``ProbeConfig.max_push_time``; the asked time grows with the
#: lever and with 1 / the part's effective mass): it bounds a probe's cost (a
#: stapler whose parts lay 95 m from their axes asked 924 s per probe). The
#: largest household part needs far less: a "very large" door (the Door prior
#: 2.1 x 0.9 m times 1.7: a lever of about 1.5 m) opened 1.57 rad travels
#: 2.4 m, 1 + 1.5 x 2.4 / 0.25 = 15 s; twice that is the cap.
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


@dataclass(frozen=True)
class Pusher:
    """The force law of one probe's hand (module docstring, "Force law")."""

    f_max: float
    """largest force, N"""
    stiffness: float
    """k, N/m"""
    damping: float
    """c, N s/m"""
    ramp: float
    """time a stuck part's force takes to reach ``min_force``, at least ``ramp_time``, s"""
    speed: float
    """v_des, m/s"""

    def step(self, lead: float, v: float, dt: float) -> tuple[float, float]:
        """(lead, force) after a step of ``dt`` s with the push point moving at
        ``v`` m/s: how far the hand runs ahead of the push point, m, and the
        force it pushes with, N."""
        lead = float(np.clip(lead + (self.speed - v) * dt, 0.0, self.f_max / self.stiffness))
        return lead, float(np.clip(self.stiffness * lead + self.damping * (self.speed - v), 0.0, self.f_max))


def pusher_for(session, joint: str, cfg: ProbeConfig, weight: float, model: UrdfModel | None = None) -> Pusher:
    """The hand that probes ``joint`` of a body weighing ``weight`` N (module
    docstring: F_max, "Stiffness"; ``model`` as :func:`effective_mass`)."""
    dt = session.options.conventions.timestep
    f_max = max(cfg.min_force, cfg.force_factor * weight)
    m_eff = effective_mass(session, joint, model)
    stiffness = min(f_max / (cfg.push_speed * cfg.ramp_time), m_eff * (PUSHER_OMEGA_DT / dt) ** 2)
    damping = 2.0 * float(np.sqrt(stiffness * m_eff))
    ramp = max(cfg.ramp_time, cfg.min_force / (stiffness * cfg.push_speed))
    return Pusher(f_max, stiffness, damping, ramp, cfg.push_speed)


def push_geometry(session, joint: str) -> tuple[np.ndarray, np.ndarray, float | None]:
    """Push point (3,) m, unit direction (3,) that increases q, lever (m) or None."""
    link = session.joint_child[joint]
    o, a = joint_frame_axis(session, joint, link)
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
    _, _, lever = push_geometry(session, joint)
    if lever is None:
        return max(sum(held[ln].mass for ln in rigid if ln in held), 1e-4)
    o, a = joint_frame_axis(session, joint, child)
    inertia = 0.0
    for ln in rigid:
        h = held.get(ln)
        if h is None or not h.mass > 0:
            continue
        p, Rl = session.link_frame(ln)
        c = np.asarray(p, float) + np.asarray(Rl, float) @ np.asarray(h.com, float) - o
        d2 = float(c @ c - (c @ a) ** 2)
        inertia += float(np.min(h.principal)) + h.mass * max(d2, 0.0)
    return max(inertia / lever**2, 1e-4)


@contextmanager
def root_held(session, max_force: float | None, notes: list[str]):
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
