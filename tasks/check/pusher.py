"""The probes' pusher: a hand that pushes the moving link through a bounded spring-damper, its push
time, the other hand holding the body, and the probe's knobs. Push point, force law, k, c and F_max:
``docs/design/metrics.md``, "Behaviour: passive probes". omega dt = :data:`PUSHER_OMEGA_DT` keeps the
explicit spring-damper step stable (Jury's criterion, Franklin, Powell & Workman, *Digital Control of
Dynamic Systems*, 3rd ed. 1998, section 4.5); ``min_force`` 22.2 N (5 lbf): 2010 ADA Standards for
Accessible Design, section 309.4.
"""

from __future__ import annotations

from contextlib import contextmanager
from dataclasses import dataclass

import numpy as np

from asset2sim.engines.base import EngineUnsupported
from asset2sim.tasks.check.contact_points import joint_frame_axis
from asset2sim.tasks.ingest.mesh_checks import box_corners
from asset2sim.tasks.geometry.limits import rigid_group
from asset2sim.urdf import UrdfModel

#: Push time allowed per unit of travel time at ``push_speed`` (dimensionless).
TRAVEL_TIME_MARGIN = 1.5
#: Longest push of one probe, s of simulated time, whatever the travel and the force ramp ask
#: (``ProbeConfig.max_push_time``): twice the 15 s a very large door (1.5 m lever, 1.57 rad) asks.
MAX_PUSH_TIME = 30.0
#: omega dt of the pusher's spring against the part's effective mass: a quarter of the explicit step's stability limit.
PUSHER_OMEGA_DT = 0.25


@dataclass
class ProbeConfig:
    """Probe knobs (units on every field)."""

    #: free settling before the push, s
    settle_time: float = 0.25
    #: longest push, s, unless the travel needs longer (:func:`push_budget`)
    push_time: float = 2.0
    #: longest push whatever the travel and the ramp ask, s (:data:`MAX_PUSH_TIME`)
    max_push_time: float = MAX_PUSH_TIME
    #: observation after release, s
    release_time: float = 0.75
    #: desired speed of the push point, m/s
    push_speed: float = 0.25
    #: time for a stuck pusher to reach F_max, s
    ramp_time: float = 1.0
    #: F_max = force_factor * total weight (dimensionless) ...
    force_factor: float = 2.0
    #: ... but at least this, N (ADA 2010 section 309.4: 5 lbf)
    min_force: float = 22.2
    #: root displacement that counts as the object sliding, m
    slide_tol: float = 0.005
    #: root rotation that counts as tipping, rad
    tip_tol: float = 0.05
    #: the other hand holds the body: the push's reaction acts on the root, and a body
    #: weighing at most ``hold_force`` is gripped; False: an external push only
    hold_body: bool = True
    #: the other hand's force, N: a body weighing at most this is held by a hold of at most this force (ADA 5 lbf)
    hold_force: float = 22.2
    #: |q_dot| after release that counts as still moving, rad/s
    settle_velocity_revolute: float = 0.05
    #: ... for prismatic joints, m/s
    settle_velocity_prismatic: float = 0.005


@dataclass(frozen=True)
class Pusher:
    """The force law of one probe's hand (``docs/design/metrics.md``, probes, step 3)."""

    #: largest force, N
    f_max: float
    #: k, N/m
    stiffness: float
    #: c, N s/m
    damping: float
    #: time a stuck part's force takes to reach ``min_force``, at least ``ramp_time``, s
    ramp: float
    #: v_des, m/s
    speed: float

    def step(self, lead: float, v: float, dt: float) -> tuple[float, float]:
        """(lead m, force N) after a step of ``dt`` s with the push point moving at ``v`` m/s."""
        lead = float(np.clip(lead + (self.speed - v) * dt, 0.0, self.f_max / self.stiffness))
        return lead, float(np.clip(self.stiffness * lead + self.damping * (self.speed - v), 0.0, self.f_max))


def pusher_for(session, joint: str, cfg: ProbeConfig, weight: float, model: UrdfModel | None = None) -> Pusher:
    """The hand that probes ``joint`` of a body weighing ``weight`` N (:class:`Pusher`), against a lower bound m_eff (kg,
    >= 1e-4) of the effective mass of ``joint``'s part at the push point: revolute, sum (I_min + m d^2) / r^2 over
    the links rigid with the child (I_min the smallest principal moment, d the COM's distance from the axis, r the
    lever: parallel-axis theorem); prismatic, their mass.

    Raises:
        KeyError: unknown joint.
    """
    dt = session.options.conventions.timestep
    f_max = max(cfg.min_force, cfg.force_factor * weight)
    child = session.joint_child[joint]
    rigid = [ln for ln in (rigid_group(model, child) if model is not None else {child}) if ln in session.link_names]
    held = session.held_physics().links
    lever = push_geometry(session, joint).lever
    if lever is None:
        m_eff = max(sum(held[ln].mass for ln in rigid if ln in held), 1e-4)
    else:
        o, a = joint_frame_axis(session, joint, child)
        inertia = 0.0
        for ln in rigid:
            h = held.get(ln)
            if h is None or not h.mass > 0:
                continue
            p, Rl = session.link_frame(ln)
            c = np.asarray(p, float) + np.asarray(Rl, float) @ np.asarray(h.com, float) - o
            inertia += float(np.min(h.principal)) + h.mass * max(float(c @ c - (c @ a) ** 2), 0.0)
        m_eff = max(inertia / lever**2, 1e-4)
    stiffness = min(f_max / (cfg.push_speed * cfg.ramp_time), m_eff * (PUSHER_OMEGA_DT / dt) ** 2)
    damping = 2.0 * float(np.sqrt(stiffness * m_eff))
    ramp = max(cfg.ramp_time, cfg.min_force / (stiffness * cfg.push_speed))
    return Pusher(f_max, stiffness, damping, ramp, cfg.push_speed)


@dataclass(frozen=True, slots=True)
class PushGeometry:
    """Where a hand pushes a joint's part (:func:`push_geometry`): ``point`` (3,) m, unit ``direction`` (3,)
    that increases q, and ``lever`` (m; None for a prismatic joint)."""

    point: np.ndarray
    direction: np.ndarray
    lever: float | None


def push_geometry(session, joint: str) -> PushGeometry:
    """The push point, direction and lever of ``joint``'s child at the session's state."""
    link = session.joint_child[joint]
    o, a = joint_frame_axis(session, joint, link)
    lo, hi = session.link_aabb(link)
    c = 0.5 * (lo + hi)
    if session.joint_types[joint] == "prismatic":
        return PushGeometry(c, a, None)
    corners = box_corners(lo, hi)
    rr = (corners - o) - np.outer((corners - o) @ a, a)
    k = int(np.argmax(np.linalg.norm(rr, axis=1)))
    c, r = corners[k], rr[k]
    lever = float(np.linalg.norm(r))
    t = np.cross(a, r)
    t /= max(np.linalg.norm(t), 1e-12)
    return PushGeometry(c, t, max(lever, 1e-4))


def push_budget(cfg: ProbeConfig, ramp: float, travel: float) -> tuple[float, float]:
    """(allowed, asked) push time of one probe, s: asked = max(``push_time``,
    ``ramp`` + ``TRAVEL_TIME_MARGIN`` ``travel`` / ``push_speed``) (``ramp`` s,
    ``travel`` m to the target); allowed = asked capped at ``max_push_time``
    (never below ``push_time``)."""
    asked = max(cfg.push_time, ramp + TRAVEL_TIME_MARGIN * travel / cfg.push_speed)
    return min(asked, max(cfg.max_push_time, cfg.push_time)), asked


@contextmanager
def root_held(session, max_force: float | None, notes: list[str]):
    """The other hand grips the body (``SimSession.hold_root`` with ``max_force`` N,
    released on exit; None: not gripped); an engine without it gets a note.
    Yields whether the root is held."""
    held = False
    if max_force is not None:
        try:
            session.hold_root(max_force)
            held = True
        except EngineUnsupported as exc:
            notes.append(f"the root is not held ({exc}): the push's reaction on the root only")
    try:
        yield held
    finally:
        if held:
            session.release_root()
