"""How hard a joint may be to operate: the friction escalation may not exceed.

Escalation (:func:`asset2sim.tasks.check.postcheck.escalate`) raises joint
friction until the requested state holds through robust rest. Unbounded, it
makes parts nobody can open (a laptop screen needing 4 N*m, a drawer needing
130 N): the state holds, the asset is useless for manipulation. This module
bounds the friction by what the probe (:mod:`asset2sim.tasks.check.probes`),
the evaluation's stand-in for a hand or a robot's gripper, can apply.

Definitions (SI units; ``docs/design/metrics.md``, section "Operable friction"):

- Operating force F_max = max(``min_force``, ``force_factor`` * M g): the
  probe's force limit (:class:`asset2sim.tasks.check.pusher.ProbeConfig`;
  ``min_force`` 22.2 N = 5 lbf, the 2010 ADA Standards for Accessible Design,
  section 309.4, the largest force an operable part may need), M the total
  mass of the object (kg), g = 9.81 m/s^2.
- Lever r (revolute joints): the distance from the joint axis to where the
  probe pushes: the corner of the child link's box farthest from the axis
  (:func:`asset2sim.tasks.check.pusher.push_geometry` uses the world box of
  the engine; here the box in the link's own frame,
  :class:`asset2sim.schemas.asset.LinkGeometry`, times the overlay's scale).
  Operating effort E = F_max r (N*m); prismatic joints: E = F_max (N).
- Gravity load L: the weight of the moving subtree m_s g times the distance
  from the axis to the child link's center of mass (revolute, the worst case:
  that lever horizontal) or m_s g (prismatic, a vertical slide's worst case).
- Friction cap = min(``OPERABLE_SHARE`` * E - L, the friction above which
  the engine's friction motor locks the joint,
  :func:`asset2sim.tasks.synthesize.physics.max_stable_friction`: F dt / I
  beyond Bullet's joint speed clamp), at least the joint's friction before
  escalation (escalation never lowers a value).
- Tilt floor: a joint that robust rest's tilts move needs friction for the
  extra gravity load a tilt by theta adds: at least the friction before
  escalation plus ``TILT_MARGIN`` m_s g r sin(theta) (revolute, r the lever
  to the child's center of mass; the change of m_s g r cos(phi) when phi
  moves by theta is at most m_s g r sin(theta)) or ``TILT_MARGIN`` m_s g
  sin(theta) (prismatic, a horizontal slide tilted by theta). Escalation by
  factors alone never reaches it from a friction near zero (a horizontal
  drawer's or handle's estimate).
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from asset2sim.engines.base import SimSession
from asset2sim.engines.quiet import quiet_stdout
from asset2sim.engines.registry import open_session
from asset2sim.schemas.asset import AssetDescription, LinkGeometry
from asset2sim.schemas.config import SimConventions
from asset2sim.schemas.overlay import JointDynamics, Overlay
from asset2sim.tasks.check.blockers import fixed_root_options
from asset2sim.tasks.check.contact_points import contact_point_rule, grasp_side, joint_frame_axis, subtree
from asset2sim.tasks.check.force_ranges import ForceRange, operating_range
from asset2sim.tasks.check.gripper import GripperLimits
from asset2sim.tasks.check.probes import CLOSE_TARGET, OPEN_TARGET
from asset2sim.tasks.check.pusher import ProbeConfig
from asset2sim.tasks.geometry.closed_state import subtree_links
from asset2sim.tasks.synthesize.physics import max_stable_friction
from asset2sim.urdf import UrdfModel, read_urdf

GRAVITY = 9.81
"""m/s^2"""
TILT_MARGIN = 2.0
"""Safety factor on the tilt's extra gravity load (dimensionless): static
friction must also stop the motion the tilt has already started."""
OPERABLE_SHARE = 0.7
"""Share of the operating effort that friction plus gravity may take
(dimensionless): the rest is the margin the probe needs to accelerate the part
and to cover the difference between its push point (the child link's box
centre) and the center of mass used here."""


def operating_effort(overlay: Overlay, asset: AssetDescription, joint: str, geometry: dict[str, LinkGeometry],
                     config: ProbeConfig | None = None) -> float:
    """Largest effort the probe applies to ``joint``: F_max r (N*m) for a
    revolute joint, F_max (N) for a prismatic one (module docstring).

    Args:
        overlay: the overlay (link masses kg, ``scale``).
        asset: the description of the same asset (joint axes, tree).
        joint: a movable joint of ``asset``.
        geometry: link -> :class:`LinkGeometry` (boxes at scale 1, link frame).
        config: the probe's force limits (default :class:`ProbeConfig`).

    Raises:
        KeyError: ``joint`` is not in ``asset``.
    """
    cfg = config or ProbeConfig()
    jd = asset.joint(joint)
    total = sum(lp.mass for lp in overlay.links.values())
    f_max = max(cfg.min_force, cfg.force_factor * total * GRAVITY)
    if jd.type == "prismatic":
        return float(f_max)
    return float(f_max * push_lever(overlay, asset, joint, geometry))


def _unit_axis(asset: AssetDescription, joint: str) -> np.ndarray:
    a = np.asarray(asset.joint(joint).axis, float)
    return a / max(float(np.linalg.norm(a)), 1e-12)


def _off_axis(points: np.ndarray, a: np.ndarray) -> np.ndarray:
    """Distances (N,) m of ``points`` (N, 3) from the axis through the origin along unit ``a`` (3,)."""
    return np.linalg.norm(points - np.outer(points @ a, a), axis=1)


def push_lever(overlay: Overlay, asset: AssetDescription, joint: str, geometry: dict[str, LinkGeometry]) -> float:
    """Distance (m) from ``joint``'s axis to the probe's push point on its
    child link (module docstring); 0 when the child has no geometry.

    Raises:
        KeyError: ``joint`` is not in ``asset``.
    """
    g = geometry.get(asset.joint(joint).child)
    if g is None:
        return 0.0
    lo, hi = np.asarray(g.bbox_min, float), np.asarray(g.bbox_max, float)
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
    return float(_off_axis(corners, _unit_axis(asset, joint)).max()) * float(overlay.scale)


def com_lever(overlay: Overlay, asset: AssetDescription, joint: str) -> float:
    """Distance (m) from ``joint``'s axis to its child link's center of mass
    (the overlay's, link frame = joint frame, URDF convention); 0 when the
    child has no physics in the overlay.

    Raises:
        KeyError: ``joint`` is not in ``asset``.
    """
    lp = overlay.links.get(asset.joint(joint).child)
    if lp is None:
        return 0.0
    return float(_off_axis(np.asarray(lp.com, float)[None, :], _unit_axis(asset, joint))[0])


def friction_caps(overlay: Overlay, before: Overlay, asset: AssetDescription, geometry: dict[str, LinkGeometry],
                  config: ProbeConfig | None = None) -> dict[str, float]:
    """Largest joint friction (N*m or N) escalation may set, per movable joint
    of ``overlay`` (module docstring): ``OPERABLE_SHARE`` * E - L, but at
    least the friction of ``before`` (the overlay before any escalation).

    Raises:
        KeyError: a joint of ``overlay`` is not in ``asset``.
    """
    caps: dict[str, float] = {}
    for name, d, sub_mass, lever, floor in _movable(overlay, before, asset):
        cap = OPERABLE_SHARE * operating_effort(overlay, asset, name, geometry, config) - sub_mass * GRAVITY * lever
        if d.inertia_axis:  # above it the engine's friction motor locks the joint (a light handle)
            cap = min(cap, max_stable_friction(d.inertia_axis))
        caps[name] = float(max(cap, floor))
    return caps


def tilt_floors(overlay: Overlay, before: Overlay, asset: AssetDescription, tilt: float) -> dict[str, float]:
    """Friction (N*m or N) a movable joint of ``overlay`` needs to hold
    through a tilt of ``tilt`` rad (module docstring, "Tilt floor"), from the
    friction of ``before`` (the overlay before escalation).

    Raises:
        KeyError: a joint of ``overlay`` is not in ``asset``.
    """
    return {name: float(base + TILT_MARGIN * sub_mass * GRAVITY * lever * np.sin(abs(tilt)))
            for name, _, sub_mass, lever, base in _movable(overlay, before, asset)}


def _movable(overlay: Overlay, before: Overlay, asset: AssetDescription) -> Iterator[tuple[str, JointDynamics, float, float, float]]:
    """(joint, its dynamics, the mass its subtree moves, kg, the lever to its
    child's center of mass, m (1 for prismatic), its friction in ``before``,
    N*m or N) per movable joint of ``overlay``. Raises KeyError as the callers."""
    for name, d in overlay.joints.items():
        jd = asset.joint(name)
        if jd.type not in ("revolute", "continuous", "prismatic"):
            continue
        sub_mass = sum(overlay.links[ln].mass for ln in subtree_links(asset, jd.child) if ln in overlay.links)
        lever = 1.0 if jd.type == "prismatic" else com_lever(overlay, asset, name)
        yield name, d, sub_mass, lever, (before.joints[name].friction if name in before.joints else d.friction)


# ------------------------------------------------------------------ operating budget
#: Coulomb friction between a free object and the ground (dimensionless): the
#: SPEC ground friction of task execution (PyBullet's default lateral friction
#: 0.5 of the link times the plane's 0.5; ``docs/design/metrics.md``, "task_execution" 1),
#: or 0.5 x the ``<contact><lateral_friction>`` a link writes.
GROUND_FRICTION = 0.25
#: Share of the allowed operating force that friction, damping at the
#: gripper's top speed and gravity may take (dimensionless); the rest covers
#: accelerating the part and the gripper's tracking transients.
BUDGET_SHARE = 0.95
#: Share of the budget left after gravity that friction may take; the rest is
#: damping at the gripper's top speed (dimensionless).
FRICTION_SHARE = 0.75
#: Friction never capped below this multiple of the gravity load at the
#: requested state (dimensionless): below it the state does not hold at all.
HOLD_MARGIN = 1.2
#: Opening fractions sampled along a task's path (per path, including ends).
PATH_SAMPLES = 5


@dataclass(frozen=True)
class OperatingBudget:
    """How hard one joint may be to operate by the task's gripper (SI units;
    module docstring of :func:`operating_budgets`)."""

    joint: str
    joint_type: str
    link: str
    """the grasped link"""
    rule: str
    """contact point rule (handle, far edge, front)"""
    lever: float | None
    """distance (m) of the grasp point from the axis (revolute)"""
    force_n: float
    """the operating force allowed at the grasp point along the motion, N (the tightest sample)"""
    bound: str
    """what set ``force_n``: the category/part range, its torque, or the ground friction"""
    budget: float
    """friction plus damping at top speed the task may meet: N m or N"""
    speed: float
    """the gripper's top speed at the grasp point: rad/s (v_max / lever) or m/s"""
    gravity_state: float
    """|gravity load| (N m or N) at the requested state"""
    friction_cap: float
    damping_cap: float
    conflict: str = ""
    """non-empty where the budget cannot hold the requested state (the friction cap is then the hold floor)"""
    hold_floor: float = 0.0
    """friction (N m or N) below which the requested state does not hold: HOLD_MARGIN |Q| at the
    state, 0 where the request asks the parts to move freely"""


def _gravity_force(session: SimSession, model: UrdfModel, joint: str, links: list[str]) -> float:
    """Generalised gravity force Q on ``joint`` (N m or N; > 0 pushes q up)
    of the links ``links`` at the session's state: a . sum((c_i - o) x m_i g)
    (revolute) or a . sum(m_i g) (prismatic), c_i the centres of mass."""
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


def ground_friction(model: UrdfModel) -> float:
    """Ground friction mu of ``model`` on the SPEC ground plane
    (:data:`GROUND_FRICTION`, or 0.5 x the smallest ``<contact><lateral_friction>``
    a link writes: PyBullet multiplies it by the plane's 0.5)."""
    vals = [0.5 * float(lk.contact["lateral_friction"]) for lk in model.links.values()
            if "lateral_friction" in (lk.contact or {})]
    return float(min(vals)) if vals else GROUND_FRICTION


def _task_path(f_state: float, action: str) -> np.ndarray:
    """Opening fractions a task moves the joint through (task_execution's start
    rule: a joint already at the target starts from the far side)."""
    if action == "close":
        start = f_state if f_state > CLOSE_TARGET + 0.05 else OPEN_TARGET
        return np.linspace(start, CLOSE_TARGET, PATH_SAMPLES)
    start = f_state if f_state < OPEN_TARGET - 0.05 else 0.0
    return np.linspace(start, OPEN_TARGET, PATH_SAMPLES)


def operating_budgets(urdf: Path | str, state: dict[str, float], overlay: Overlay,
                      closed: dict[str, tuple[float, float, float]], *, category: str | None,
                      labels: dict[str, str | None], actions: tuple[str, ...] = ("close", "open"),
                      free: bool = True, ground: bool = True, free_moving: bool = False, engine: str = "pybullet",
                      limits: GripperLimits | None = None, conventions: SimConventions | None = None,
                      vertical_share: float = 0.5) -> dict[str, OperatingBudget]:
    """The operating budget of every movable joint of ``closed`` in the written
    asset ``urdf`` at ``state``: how much friction and damping the task's
    gripper (:mod:`asset2sim.tasks.check.task_execution`) can overcome with a
    real operating force. Definitions (``docs/design/metrics.md``, "Operable friction"):

    - Grasp as the task: the side (:func:`~asset2sim.tasks.check.contact_points.grasp_side`),
      the contact point (:func:`~asset2sim.tasks.check.contact_points.contact_point_rule`),
      its lever r from the axis (revolute).
    - Path: the task's actions (close / open) from the state (or the far side
      where the state already meets the target) to the target fraction,
      :data:`PATH_SAMPLES` fractions each.
    - Allowed operating force at each sample: F = min(the category/part's
      force range's upper end, its torque range's upper end / r
      (:func:`asset2sim.tasks.check.force_ranges.operating_range`), and, for a
      free object whose grasp point moves within 60 deg of horizontal (the
      gripper pushes along the path; nearer vertical it presses or lifts),
      mu M g / (h - mu v): the force whose horizontal part h F the ground
      friction mu (M g + v F) still resists (mu :func:`ground_friction`, M the
      whole mass, h the horizontal and v the downward share of the motion
      direction)).
    - Gravity against the motion L_g = -Q s (Q :func:`_gravity_force` of the
      moving subtree, s the sign of the motion; negative where gravity helps).
    - Budget B = min over samples of (BUDGET_SHARE F_h r - L_g) (prismatic:
      F_h instead of F_h r), F_h the hand's bound (the ranges) only: the
      ground bound is not modelled into the caps (where gravity or a spring
      moves the part the gripper guides rather than pushes, which this model
      does not see: stapler 102990 closed from the far side at 2.4 N without
      sliding where mu M g = 1.1 N); ``force_n`` (the tightest F, ground
      included) is what :func:`asset2sim.tasks.check.task_tier.relieve`
      compares a measured slide with. Friction cap = FRICTION_SHARE B, damping cap =
      (1 - FRICTION_SHARE) B / w, w = v_max / r rad/s (prismatic v_max m/s),
      v_max the gripper's top speed; the friction cap is at most
      :func:`~asset2sim.tasks.synthesize.physics.max_stable_friction` and,
      unless the request asks the part to move freely, at least HOLD_MARGIN
      |Q| at the state (``conflict`` says so where the budget is smaller).

    Args:
        urdf: the written asset; ``state``: its joint positions (rad or m).
        overlay: its overlay (``inertia_axis`` of the joints).
        closed: joint -> (q_closed, opening direction +-1, open range), output units.
        category, labels: the category and link -> semantic label (force ranges).
        actions: the task's actions (both without a task).
        free: the root is free on the ground (False: mounted, no ground bound).
        ground: apply the ground bound to a free object (False: the other
            hand holds the body, as the probes do).
        free_moving: the request asks the parts to move freely (no hold floor).

    Raises:
        EngineUnavailable; whatever loading ``urdf`` raises.
    """
    lim = limits or GripperLimits()
    model = read_urdf(urdf, mode="lenient")
    mu = ground_friction(model)
    out: dict[str, OperatingBudget] = {}
    with quiet_stdout():
        session = open_session(engine, urdf, fixed_root_options(state, conventions))
    try:
        total = sum(float(m) for m in session.link_masses().values())
        for name, (qc, d, rng) in closed.items():
            if name not in session.joint_child or name not in overlay.joints or not rng > 0:
                continue
            if session.joint_types[name] not in ("revolute", "continuous", "prismatic"):
                continue
            grasp = _grasp(session, model, name, d, state, free)
            child = session.joint_child[name]
            rng_, where = operating_range(category, labels.get(child) if grasp.side == "child" else None)
            best, lever, q_state = _tightest(session, model, name, (qc, d, rng), state, actions, grasp, rng_, where,
                                             (mu, total) if free and ground else None, vertical_share)
            session.set_joint_positions(dict(state))
            if best is not None:
                out[name] = _budget(name, session.joint_types[name], grasp, lever, best, q_state, lim, free_moving,
                                    overlay.joints[name].inertia_axis)
    finally:
        session.close()
    return out


@dataclass(frozen=True)
class _Grasp:
    """Where the task's gripper grasps a joint: ``side`` and ``rule`` of
    :func:`~asset2sim.tasks.check.contact_points.contact_point_rule`, the
    grasp ``point`` (3,) m in ``link``'s frame, and the links it moves."""

    side: str
    link: str
    point: np.ndarray
    rule: str
    moving: list[str]


def _grasp(session: SimSession, model: UrdfModel, joint: str, direction: float, state: dict[str, float],
           free: bool) -> _Grasp:
    """The task's grasp of ``joint`` at ``state`` (the session is set there)."""
    session.set_joint_positions(dict(state))
    side = grasp_side(session, joint, model, root_fixed=not free)
    link, point, rule = contact_point_rule(session, joint, model, opening_direction=direction, side=side)
    moving = subtree(model, session.joint_child[joint])
    if side == "parent":  # the gripper moves the rest of the object: same relative motion
        moving = [ln for ln in session.link_names if ln not in moving]
    return _Grasp(side, link, point, rule, moving)


def _tightest(session: SimSession, model: UrdfModel, joint: str, closed: tuple[float, float, float],
              state: dict[str, float], actions: tuple[str, ...], grasp: _Grasp, rng_: ForceRange, where: str,
              ground: tuple[float, float] | None, vertical_share: float
              ) -> tuple[tuple[float, float, str] | None, float | None, float | None]:
    """Over the samples of the task's paths (:func:`_task_path`): ((smallest
    budget B, N m or N; smallest allowed force F, N; what bounds that F), the
    grasp point's lever at the last sample, m (None: prismatic), |Q| at
    ``state``, N m or N); (None, None, None) without samples. ``ground``:
    (mu, the whole mass M kg) where the ground bound applies, else None."""
    qc, d, rng = closed
    prismatic = session.joint_types[joint] == "prismatic"
    f_state = float(d * (state.get(joint, qc) - qc) / rng)
    lever = None
    best: tuple[float, float, str] | None = None  # (budget, force, bound)
    q_state = None
    for action in actions:
        s_motion = (-d if action == "close" else d) * (1.0 if grasp.side == "child" else -1.0)
        for f in _task_path(f_state, action):
            session.set_joint_positions({**state, joint: qc + d * f * rng})
            t, nt, lever = _grasp_motion(session, joint, grasp, prismatic)
            force, bound = _range_force(rng_, where, lever)
            hand = BUDGET_SHARE * force * (lever if lever is not None else 1.0)
            fg = _ground_force(t, nt, s_motion, *ground, vertical_share) if ground is not None else None
            if fg is not None and fg < force:
                force, bound = fg, f"ground friction mu={ground[0]:g} of the free object (M={ground[1]:.3g} kg)"
            qg = _gravity_force(session, model, joint, grasp.moving)
            if q_state is None:
                session.set_joint_positions(dict(state))
                q_state = abs(_gravity_force(session, model, joint, grasp.moving))
            b = hand + qg * s_motion
            if best is None or b < best[0]:
                best = (b, best[1] if best else float("inf"), best[2] if best else "")
            if force < best[1]:
                best = (best[0], force, bound)
    return best, lever, q_state


def _grasp_motion(session: SimSession, joint: str, grasp: _Grasp, prismatic: bool) -> tuple[np.ndarray, float, float | None]:
    """(direction t (3,) of the grasp point's motion as q grows, |t| (at
    least 1e-12), the grasp point's distance from the axis, at least 1e-3 m
    (None: prismatic)) at the session's state."""
    o, a = joint_frame_axis(session, joint, session.joint_child[joint])
    lo, Rl = session.link_frame(grasp.link)
    p = np.asarray(lo, float) + np.asarray(Rl, float) @ np.asarray(grasp.point, float)
    if prismatic:
        return a, max(float(np.linalg.norm(a)), 1e-12), None
    rv = (p - o) - float((p - o) @ a) * a
    t = np.cross(a, p - o)
    return t, max(float(np.linalg.norm(t)), 1e-12), max(float(np.linalg.norm(rv)), 1e-3)


def _range_force(rng_: ForceRange, where: str, lever: float | None) -> tuple[float, str]:
    """(the upper end of the force range of ``where``, or of its torque
    range / ``lever`` where smaller, N (inf without either); what set it)."""
    force, bound = float("inf"), ""
    if rng_.force_n is not None:
        force, bound = rng_.force_n[1], f"force range of {where}"
    if rng_.torque_nm is not None and lever is not None and rng_.torque_nm[1] / lever < force:
        force, bound = rng_.torque_nm[1] / lever, f"torque range of {where}"
    return force, bound


def _ground_force(t: np.ndarray, nt: float, s_motion: float, mu: float, total: float, vertical_share: float) -> float | None:
    """mu M g / (h - mu v), N: the force along the motion ``s_motion`` ``t`` (|t| =
    ``nt``) whose horizontal share h the ground friction ``mu`` of the free
    object of ``total`` mass M (kg) still resists, v its downward share; None
    where the gripper presses or lifts (``vertical_share``) or h <= mu v."""
    horiz = float(np.linalg.norm(t[:2])) / nt
    down = max(0.0, -s_motion * float(t[2]) / nt)  # a push with a downward part loads the ground more
    if abs(float(t[2])) / nt < vertical_share and horiz - mu * down > 0:
        return mu * total * GRAVITY / (horiz - mu * down)
    return None


def _budget(name: str, jtype: str, grasp: _Grasp, lever: float | None, best: tuple[float, float, str],
            q_state: float | None, lim: GripperLimits, free_moving: bool, inertia: float | None) -> OperatingBudget:
    """The caps of ``name``'s tightest budget ``best`` (:func:`operating_budgets`)."""
    budget, force, bound = best
    speed = lim.max_speed_m_s / lever if lever is not None else lim.max_speed_m_s
    fcap = FRICTION_SHARE * max(budget, 0.0)
    dcap = (1.0 - FRICTION_SHARE) * max(budget, 0.0) / speed
    conflict = ""
    floor = 0.0 if free_moving else HOLD_MARGIN * (q_state or 0.0)
    if fcap < floor:
        conflict = (f"{name}: the operating budget {max(budget, 0.0):.3g} {'N' if jtype == 'prismatic' else 'N m'} "
                    f"({bound}) is below what holds the requested state ({floor:.3g}): friction kept at the hold floor")
        fcap = floor
    if inertia:
        fcap = min(fcap, max_stable_friction(inertia))
    return OperatingBudget(joint=name, joint_type=jtype, link=grasp.link, rule=grasp.rule, lever=lever, force_n=float(force),
                           bound=bound, budget=float(budget), speed=float(speed), gravity_state=float(q_state or 0.0),
                           friction_cap=float(fcap), damping_cap=float(dcap), conflict=conflict, hold_floor=float(floor))


def bound_overlay(overlay: Overlay, budgets: dict[str, OperatingBudget]) -> tuple[Overlay, list[str]]:
    """``overlay`` with every joint's friction and damping lowered to its
    operating budget's caps where above them (friction never below the hold
    floor: :func:`operating_budgets`). Returns (overlay, notes, one per change
    and per conflict)."""
    ov = overlay.model_copy(deep=True)
    notes: list[str] = []
    for name, b in budgets.items():
        d = ov.joints.get(name)
        if d is None:
            continue
        fr, dm = min(d.friction, b.friction_cap), min(d.damping, b.damping_cap)
        if b.conflict:
            notes.append(b.conflict)
        if fr == d.friction and dm == d.damping:
            continue
        unit = "N" if b.joint_type == "prismatic" else "N m"
        note = (f"; operable: friction {d.friction:.3g} -> {fr:.3g} {unit}, damping {d.damping:.3g} -> {dm:.3g} "
                f"(operating force <= {b.force_n:.3g} N: {b.bound})")
        ov.joints[name] = d.model_copy(update={"friction": fr, "damping": dm, "source": d.source + note})
        notes.append(f"{name}{note[1:]}")
    return ov, notes
