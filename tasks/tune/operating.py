"""How hard a joint may be to operate: the bounds escalation
(:func:`asset2sim.tasks.tune.escalation.escalate`) keeps friction and damping to: the probe's
cap, the operating budget with a task (``docs/design/metrics.md``, "Operable friction") and the
tilt floor, the friction before escalation plus ``TILT_MARGIN`` m_s g r sin(theta) (prismatic:
without r); every joint's caps in one value (:func:`operating_limits`).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterator
from dataclasses import dataclass, field

import numpy as np

from asset2sim.engines.base import SimSession, Spring
from asset2sim.engines.loading import overlay_springs
from asset2sim.engines.quiet import quiet_stdout
from asset2sim.engines.source import SimObject
from asset2sim.schemas.asset import AssetDescription, LinkGeometry
from asset2sim.schemas.overlay import JointDynamics, Overlay
from asset2sim.schemas.request import BAND_INTERVAL
from asset2sim.tasks.check import sweep
from asset2sim.tasks.check.blockers import fixed_root_options
from asset2sim.tasks.check.contact_points import contact_point_rule, grasp_lever, grasp_side, joint_frame_axis, off_axis, subtree
from asset2sim.tasks.ingest.mesh_checks import box_corners
from asset2sim.tasks.interpret.operating_forces import ForceRange, operating_range
from asset2sim.tasks.interpret.part_priors import handled
from asset2sim.tasks.check.gripper import GripperLimits
from asset2sim.tasks.check.gripper_motion import TaskConfig
from asset2sim.tasks.check.operability import gravity_force, range_force
from asset2sim.tasks.check.probes import CLOSE_TARGET, OPEN_TARGET
from asset2sim.tasks.check.pusher import ProbeConfig
from asset2sim.tasks.interpret.task_words import task_actions
from asset2sim.tasks.check.task_tier import link_labels
from asset2sim.tasks.geometry import limits
from asset2sim.tasks.geometry.closed_state import subtree_links
from asset2sim.tasks.synthesize.physics import G as GRAVITY, max_stable_friction
from asset2sim.urdf import UrdfModel

TILT_MARGIN = 2.0
"""Safety factor on the tilt's extra gravity load (dimensionless)."""
OPERABLE_SHARE = 0.7
"""Share of the operating effort that friction plus gravity may take (dimensionless)."""
VERTICAL_SHARE = TaskConfig().vertical_share
"""A push whose direction is at least this much vertical (|t_z| / |t| >= 0.5: within 60 deg of vertical) presses
the object into the ground or lifts it rather than sliding it, as the task's gripper does
(:attr:`~asset2sim.tasks.check.gripper_motion.TaskConfig.vertical_share`): no ground-friction bound (dimensionless)."""


def operating_effort(overlay: Overlay, asset: AssetDescription, joint: str, geometry: dict[str, LinkGeometry]) -> float:
    """Largest effort the probe applies to ``joint``: F_max r (N*m), prismatic
    F_max (N); ``geometry``: link -> boxes at scale 1 in the link frame.

    Raises:
        KeyError: ``joint`` is not in ``asset``.
    """
    cfg = ProbeConfig()
    f_max = max(cfg.min_force, cfg.force_factor * sum(lp.mass for lp in overlay.links.values()) * GRAVITY)
    if asset.joint(joint).type == "prismatic":
        return float(f_max)
    return float(f_max * push_lever(overlay, asset, joint, geometry))


def _unit_axis(asset: AssetDescription, joint: str) -> np.ndarray:
    a = np.asarray(asset.joint(joint).axis, float)
    return a / max(float(np.linalg.norm(a)), 1e-12)


def push_lever(overlay: Overlay, asset: AssetDescription, joint: str, geometry: dict[str, LinkGeometry]) -> float:
    """Distance (m) from ``joint``'s axis to its child's farthest box corner; 0 without geometry.

    Raises:
        KeyError: ``joint`` is not in ``asset``.
    """
    g = geometry.get(asset.joint(joint).child)
    if g is None:
        return 0.0
    lo, hi = np.asarray(g.bbox_min, float), np.asarray(g.bbox_max, float)
    return float(off_axis(box_corners(lo, hi), 0.0, _unit_axis(asset, joint)).max()) * float(overlay.scale)


def com_lever(overlay: Overlay, asset: AssetDescription, joint: str) -> float:
    """Distance (m) from ``joint``'s axis to its child link's center of mass (the overlay's); 0 without one.

    Raises:
        KeyError: ``joint`` is not in ``asset``.
    """
    lp = overlay.links.get(asset.joint(joint).child)
    if lp is None:
        return 0.0
    return float(off_axis(np.asarray(lp.com, float)[None, :], 0.0, _unit_axis(asset, joint))[0])


def friction_caps(overlay: Overlay, asset: AssetDescription, geometry: dict[str, LinkGeometry]) -> dict[str, float]:
    """Probe's friction cap (N*m or N) per movable joint of ``overlay``
    (module docstring), at least its friction (before escalation).

    Raises:
        KeyError: a joint of ``overlay`` is not in ``asset``.
    """
    caps: dict[str, float] = {}
    for name, d, sub_mass, lever in _movable(overlay, asset):
        cap = OPERABLE_SHARE * operating_effort(overlay, asset, name, geometry) - sub_mass * GRAVITY * lever
        if d.inertia_axis:  # above it the engine's friction motor locks the joint (a light handle)
            cap = min(cap, max_stable_friction(d.inertia_axis))
        caps[name] = float(max(cap, d.friction))
    return caps


def tilt_floors(overlay: Overlay, asset: AssetDescription, tilt: float) -> dict[str, float]:
    """Tilt floor (N*m or N) per movable joint of ``overlay`` for a tilt of
    ``tilt`` rad (module docstring), from its friction.

    Raises:
        KeyError: a joint of ``overlay`` is not in ``asset``.
    """
    return {name: float(d.friction + TILT_MARGIN * sub_mass * GRAVITY * lever * np.sin(abs(tilt)))
            for name, d, sub_mass, lever in _movable(overlay, asset)}


def _movable(overlay: Overlay, asset: AssetDescription) -> Iterator[tuple[str, JointDynamics, float, float]]:
    """(joint, dynamics, subtree mass kg, lever to the child's COM m (1 prismatic)) per movable joint of ``overlay``."""
    for name, d in overlay.joints.items():
        jd = asset.joint(name)
        if jd.type not in ("revolute", "continuous", "prismatic"):
            continue
        sub_mass = sum(overlay.links[ln].mass for ln in subtree_links(asset, jd.child) if ln in overlay.links)
        lever = 1.0 if jd.type == "prismatic" else com_lever(overlay, asset, name)
        yield name, d, sub_mass, lever


#: Coulomb friction between a free object and the ground: the SPEC ground friction of task execution.
GROUND_FRICTION = 0.25
#: Share of the allowed operating force that friction, damping at top speed and gravity may take.
BUDGET_SHARE = 0.95
#: Share of the budget that friction may take; the rest is damping at the gripper's top speed.
FRICTION_SHARE = 0.75
#: Friction never capped below this multiple of the gravity load at the requested state.
HOLD_MARGIN = 1.2
#: Opening fraction up to which a part counts as shut (the closed band's top, ``schemas.request.BAND_INTERVAL``).
CLOSED_FRACTION = BAND_INTERVAL["closed"][1]
#: Opening fractions sampled along a task's path (per path, including ends).
PATH_SAMPLES = 5


@dataclass(frozen=True)
class OperatingBudget:
    """How hard one joint may be to operate by the task's gripper (SI units; :func:`operating_budgets`)."""

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
    """friction (N m or N) below which the requested state does not hold (0 for parts moving freely)"""

    @property
    def unit(self) -> str:
        """Unit of the joint's friction, budget and loads: N (prismatic) or N m."""
        return "N" if self.joint_type == "prismatic" else "N m"


def ground_friction(model: UrdfModel) -> float:
    """Ground friction mu of ``model``: :data:`GROUND_FRICTION`, or 0.5 x the smallest
    ``<contact><lateral_friction>`` a link writes (PyBullet's plane has 0.5)."""
    vals = [0.5 * float(lk.contact["lateral_friction"]) for lk in model.links.values()
            if "lateral_friction" in (lk.contact or {})]
    return float(min(vals, default=GROUND_FRICTION))


def operating_budgets(obj: SimObject, overlay: Overlay, closed: dict[str, tuple[float, float, float]], *,
                      category: str | None, labels: dict[str, str | None], actions: tuple[str, ...] = ("close", "open"),
                      ground: bool = True, free_moving: bool = False, whole: bool = False) -> dict[str, OperatingBudget]:
    """The operating budget of every movable joint of ``closed`` in the written
    asset ``obj`` at its state: how much friction and damping the task's
    gripper (:class:`~asset2sim.tasks.check.gripper.GripperLimits`) can overcome with a real operating force.
    Definition (grasp, path samples, allowed force, budget B, friction and damping caps):
    ``docs/design/metrics.md``, "Operable friction".
    ``closed``: joint -> (q_closed, direction +-1, open range); ``labels``: link
    -> semantic label; ``obj.fixed_base``: the root held (no ground bound), else free;
    ``ground``: apply the ground bound to a free object; ``whole``: each action along the whole range (the
    operability tier's strokes, :mod:`asset2sim.tasks.check.operability`) rather than the task's path. The joints'
    springs are the overlay's about ``obj.state`` (:func:`~asset2sim.engines.loading.overlay_springs`).

    Raises:
        EngineUnavailable; whatever loading ``obj.source`` raises.
    """
    source, state, free = obj.source, dict(obj.state), not obj.fixed_base
    model = source.model(mode="lenient")
    springs = overlay_springs(overlay, state)
    mu = ground_friction(model)
    out: dict[str, OperatingBudget] = {}
    with quiet_stdout():
        session = source.open("pybullet", fixed_root_options(state, obj.conventions))
    try:
        total = sum(float(m) for m in session.link_masses().values())
        for name, (qc, d, rng) in closed.items():
            if name not in session.joint_child or name not in overlay.joints or not rng > 0 or session.joint_types[name] not in (
                    "revolute", "continuous", "prismatic"):
                continue
            # the task's grasp at the state
            session.set_joint_positions(dict(state))
            side = grasp_side(session, name, model, root_fixed=not free)
            link, point, rule = contact_point_rule(session, name, model, opening_direction=d, side=side)
            moving = subtree(model, session.joint_child[name])
            if side == "parent":  # the gripper moves the rest of the object: same relative motion
                moving = [ln for ln in session.link_names if ln not in moving]
            grasp = _Grasp(side, link, point, rule, moving)
            range_of = operating_range(category, labels.get(session.joint_child[name]) if grasp.side == "child" else None)
            tight = _tightest(session, model, name, (qc, d, rng), (actions, whole), grasp, range_of,
                              (mu, total) if free and ground else None, springs.get(name), free_moving,
                              overlay.joints[name].inertia_axis)
            session.set_joint_positions(dict(state))
            if tight is not None:
                out[name] = tight
    finally:
        session.close()
    return out


@dataclass(frozen=True)
class _Grasp:
    """Where the task's gripper grasps a joint (``point`` (3,) m in ``link``'s frame) and the links it moves."""

    side: str
    link: str
    point: np.ndarray
    rule: str
    moving: list[str]


def _spring_force(spring: Spring | None, q: float) -> float:
    """Generalised force (N m or N) of ``spring`` at ``q``; 0 without one."""
    return 0.0 if spring is None else float(spring.force(q))


def _paths(f_state: float, actions: tuple[str, ...], whole: bool) -> list[tuple[str, np.ndarray]]:
    """(action, opening fractions it moves the joint through) of each of ``actions`` from the opening fraction
    ``f_state``: the task's paths (from the far side when already at the target), or with ``whole`` the whole range
    each way."""
    paths = []
    for action in actions:
        if whole:
            fractions = np.linspace(0.0, 1.0, 2 * PATH_SAMPLES + 1)
        elif action == "close":
            fractions = np.linspace(f_state if f_state > CLOSE_TARGET + 0.05 else OPEN_TARGET, CLOSE_TARGET, PATH_SAMPLES)
        else:
            fractions = np.linspace(f_state if f_state < OPEN_TARGET - 0.05 else 0.0, OPEN_TARGET, PATH_SAMPLES)
        paths.append((action, fractions))
    return paths


def _tightest(session: SimSession, model: UrdfModel, joint: str, closed: tuple[float, float, float],
              paths: tuple[tuple[str, ...], bool], grasp: _Grasp, range_of: tuple[ForceRange, str],
              ground: tuple[float, float] | None, spring: Spring | None, free_moving: bool,
              inertia: float | None) -> OperatingBudget | None:
    """The tightest budget over the paths of ``paths`` ((actions, whole) as :func:`_paths` takes them, from the session's
    initial state; None without a sample),
    Q of gravity and of the joint's ``spring``, and its caps (:func:`operating_budgets`): friction takes
    :data:`FRICTION_SHARE` of it, damping at the top speed of the task's gripper
    (:class:`~asset2sim.tasks.check.gripper.GripperLimits`) the rest (the lever and speed at the last sample).
    ``range_of``: the part's operating range and where it comes from; ``ground``: (mu, whole mass kg) where the
    ground bound applies; ``inertia``: the joint's axis inertia (kg m^2 or kg), which bounds its friction."""
    qc, d, rng = closed
    state = session.options.initial_state
    prismatic = session.joint_types[joint] == "prismatic"
    f_state = float(d * (state.get(joint, qc) - qc) / rng)
    lever = budget = q_state = None
    least, least_bound = float("inf"), ""
    side = 1.0 if grasp.side == "child" else -1.0  # Q of the parent side pushes q the other way
    for action, fractions in _paths(f_state, *paths):
        s_motion = (-d if action == "close" else d) * side
        for f in fractions:
            session.set_joint_positions({**state, joint: qc + d * f * rng})
            t, lever = _grasp_motion(session, joint, grasp, prismatic, model)
            force, bound = range_force(*range_of, lever)
            hand = BUDGET_SHARE * force * (lever or 1.0)
            fg = _ground_force(t, s_motion, *ground) if ground is not None else None
            if fg is not None and fg < force:
                force, bound = fg, f"ground friction mu={ground[0]:g} of the free object (M={ground[1]:.3g} kg)"
            qg = gravity_force(session, model, joint, grasp.moving) + side * _spring_force(spring, qc + d * f * rng)
            if q_state is None:
                session.set_joint_positions(dict(state))
                q_signed = side * (gravity_force(session, model, joint, grasp.moving)
                                   + side * _spring_force(spring, state.get(joint, qc)))
                # a part asked shut that gravity presses into its closed end rests on it: no hold floor
                q_state = 0.0 if f_state <= CLOSED_FRACTION and q_signed * -d > 0 else abs(q_signed)
            b = hand + qg * s_motion
            if budget is None or b < budget:
                budget = b
            if force < least:
                least, least_bound = force, bound
    if budget is None:
        return None
    speed, room = GripperLimits().max_speed_m_s / (lever or 1.0), max(budget, 0.0)
    fcap = FRICTION_SHARE * room
    dcap = (1.0 - FRICTION_SHARE) * room / speed
    conflict = ""
    floor = 0.0 if free_moving else HOLD_MARGIN * (q_state or 0.0)
    if fcap < floor:  # friction takes what holding the state needs, damping the rest of the budget
        if floor > room:
            conflict = (f"{joint}: the operating budget {room:.3g} {'N' if prismatic else 'N m'} "
                        f"({least_bound}) is below what holds the requested state ({floor:.3g}): friction kept at the hold floor")
        fcap = floor
        dcap = min(dcap, max(budget - floor, 0.0) / speed)
    if inertia:
        fcap = min(fcap, max_stable_friction(inertia))
    return OperatingBudget(joint=joint, joint_type=session.joint_types[joint], link=grasp.link, rule=grasp.rule, lever=lever,
                           force_n=float(least), bound=least_bound, budget=float(budget), speed=float(speed),
                           gravity_state=float(q_state or 0.0), friction_cap=float(fcap), damping_cap=float(dcap),
                           conflict=conflict, hold_floor=float(floor))


def _grasp_motion(session: SimSession, joint: str, grasp: _Grasp, prismatic: bool,
                  model: UrdfModel) -> tuple[np.ndarray, float | None]:
    """How the grasp point moves as q grows at the session's state: (direction t (3,) m/rad or m/m, lever >= 1e-3 m
    (:func:`~asset2sim.tasks.check.contact_points.grasp_lever`; None for a prismatic joint))."""
    o, a = joint_frame_axis(session, joint, session.joint_child[joint])
    lo, Rl = session.link_frame(grasp.link)
    p = np.asarray(lo, float) + np.asarray(Rl, float) @ np.asarray(grasp.point, float)
    if prismatic:
        return a, None
    return np.cross(a, p - o), grasp_lever(session, joint, grasp.link, grasp.point, model)


def _ground_force(t: np.ndarray, s_motion: float, mu: float, total: float) -> float | None:
    """mu M g / (h - mu v), N: the push along ``s_motion`` ``t`` the
    ground friction still resists; None where the gripper presses or lifts (a vertical share of the push of
    :data:`VERTICAL_SHARE` or more) or h <= mu v."""
    nt = max(float(np.linalg.norm(t)), 1e-12)
    horiz = float(np.linalg.norm(t[:2])) / nt
    down = max(0.0, -s_motion * float(t[2]) / nt)  # a push with a downward part loads the ground more
    if abs(float(t[2])) / nt < VERTICAL_SHARE and horiz - mu * down > 0:
        return mu * total * GRAVITY / (horiz - mu * down)
    return None


def bound_overlay(overlay: Overlay, budgets: dict[str, OperatingBudget]) -> tuple[Overlay, list[str]]:
    """``overlay`` with every joint's friction and damping lowered to its budget's
    caps where above them. Returns (overlay, notes, one per change and per conflict)."""
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
        note = (f"; operable: friction {d.friction:.3g} -> {fr:.3g} {b.unit}, damping {d.damping:.3g} -> {dm:.3g} "
                f"(operating force <= {b.force_n:.3g} N: {b.bound})")
        ov.joints[name] = d.model_copy(update={"friction": fr, "damping": dm, "source": d.source + note})
        notes.append(f"{name}{note[1:]}")
    return ov, notes


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
    cfg = sweep.SweepConfig()
    source, initial_state = obj.source, dict(obj.state)
    subtrees = limits.subtrees(source.model())
    caps: dict[str, float] = {}
    with source.open("pybullet", fixed_root_options(initial_state, obj.conventions, dict(obj.springs))) as session:
        for name, (qc, d, rng) in closed.items():
            if name not in session.joint_types or not rng > 0:
                continue
            session.set_joint_positions({**initial_state, name: qc})
            e = sweep.effort_limit(session, name, subtrees.get(name, [session.joint_child[name]]), rng, cfg, qc, d)
            caps[name] = e * cfg.time_limit / (DAMPED_SPEED_MARGIN * rng)
    return caps


@dataclass
class OperatingLimits:
    """What escalation keeps to: joint -> friction cap and damping cap (N m
    or N; N m s/rad or N s/m) and the budgets they come from."""

    friction_caps: dict[str, float]
    damping_caps: dict[str, float]
    budgets: dict[str, OperatingBudget] = field(default_factory=dict)
    hand_caps: dict[str, float] = field(default_factory=dict)
    """joint -> the friction (N m or N) a hand inside the part's range still moves both ways over the whole range
    (the operability tier's): no step of the dynamics search goes above it"""


def operating_limits(obj: SimObject, overlay: Overlay, asset: AssetDescription, geometry: dict[str, LinkGeometry],
                     closed: dict[str, tuple[float, float, float]], *, category: str | None, task: str | None,
                     free_moving: bool, joints: list[str] | None) -> OperatingLimits:
    """Friction and damping caps of every movable joint of the written asset ``obj`` (its root as mounted): the
    operating budget (:func:`operating_budgets`) of a hand inside the part's real
    range, both ways with the root fixed, for every handled part
    (:func:`~asset2sim.tasks.interpret.part_priors.handled`) where the closed ends are known, the tighter of it and
    the task gripper's for the task's ``joints``; else the probe's cap
    (:func:`friction_caps`); damping at most what the joint sweep's drive still
    moves (:func:`damping_caps`).

    Raises:
        EngineUnavailable; whatever loading ``obj.source`` raises.
    """
    labels = link_labels(asset)
    hand = {n: c for n, c in closed.items() if handled(labels.get(asset.joint(n).child))}
    # every handled part, both ways, root fixed (the operability tier's hand); a task's joints also as its gripper meets them
    budgets = operating_budgets(dataclasses.replace(obj, fixed_base=True), overlay, hand, category=category,
                                labels=labels, free_moving=free_moving, whole=True) if hand else {}
    hand_caps = {n: b.friction_cap for n, b in budgets.items()}
    sel = {n: c for n, c in closed.items() if joints is None or n in joints}
    if sel and task:
        for n, b in operating_budgets(obj, overlay, sel, category=category, labels=labels,
                                      actions=task_actions(task), free_moving=free_moving).items():
            if n not in budgets or b.budget < budgets[n].budget:
                budgets[n] = b
    caps = {**friction_caps(overlay, asset, geometry), **{n: b.friction_cap for n, b in budgets.items()}}
    dcaps = {n: b.damping_cap for n, b in budgets.items()}
    if closed:  # what the joint sweep's drive still moves through the range in time
        for name, c in damping_caps(obj, closed).items():
            dcaps[name] = min(c, dcaps.get(name, c))
    return OperatingLimits(friction_caps=caps, damping_caps=dcaps, budgets=budgets, hand_caps=hand_caps)
