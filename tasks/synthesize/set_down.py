"""How a free-standing object is set down, as loads on each joint: the SPEC's robust rest drops the object 2 cm and
tilts it 5 deg about each horizontal axis, both ways, and lets it go; every joint must then come to rest within its
band (:func:`rest_band`). A part stays where it was left when its joint's friction holds

- the lean: |tau_g| cos(d) + g sin(d) |w_h| (:func:`lean_load`; w the load per unit gravity, w . g = tau_g, w_h
  its horizontal part), with :data:`LEAN_SAFETY`;
- each landing: the object stops on the ground and the part carries on with its momentum along its joint,
  p_q = J_q^T M v (v the velocity of every link just before the object stops: sqrt(2 g h) down after the drop, a
  rotation about the footprint edge it falls back on after a tilt, at the speed its fall from 5 deg gives:
  M g dh = I_edge w^2 / 2); friction takes its kinetic energy p_q^2 / (2 I_q) within the band (work-energy theorem),
  :func:`landing_friction`. An instant stop of a rigid object: an upper bound (on the dev rows the simulated part
  carries 0.4-0.9 of this energy; the ground's give, rocking and damping take the rest).

Sources: the SPEC's robust rest (drop height, tilt, band); work-energy theorem and rigid-body momentum (Meriam and
Kraige, Engineering Mechanics: Dynamics, 8th ed., ch. 6). Shapes: positions (3,) m, points (N, 3) m, inertia tensors
(3, 3) kg*m^2.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from asset2sim.frames import axis_angle_matrix
from asset2sim.schemas.config import REST_BAND_FLOORS, REST_BAND_RANGE_SHARE
from asset2sim.schemas.overlay import LinkPhysics
from asset2sim.tasks.synthesize.physics import G, JointLoad

#: How a free-standing object is set down (SPEC, robust rest): dropped from this height, m ...
SET_DOWN_DROP = 0.02
#: ... and leaned this far about each horizontal axis, both ways, and let go, rad (5 deg).
SET_DOWN_LEAN = float(np.radians(5.0))
#: Safety factor on the lean's load (dimensionless): the object is let go leaned and rocks back, so the lean is held
#: with the escalation's tilt-floor margin (``tune.operating.TILT_MARGIN``), not the static ``physics.HOLD_SAFETY``.
LEAN_SAFETY = 2.0
#: The SPEC's set-down trials whose landings :func:`landings` models.
LANDING_TRIALS = ("drop", "tilt+x", "tilt-x", "tilt+y", "tilt-y")


def rest_band(lower: float, upper: float, floor: float, share: float = REST_BAND_RANGE_SHARE) -> float:
    """The band (rad or m) a joint with limits ``lower``..``upper`` (rad or m) must come to rest in around its initial
    state: max(``floor``, ``share`` x its range); ``floor`` alone for a joint without a finite range (SPEC, robust
    rest; floors :data:`~asset2sim.schemas.config.REST_BAND_FLOORS`). E.g. a laptop screen of range 2.18 rad:
    max(0.02, 0.109) = 0.109 rad; a drawer of 0.30 m: 15 mm."""
    span = float(upper) - float(lower)
    return float(max(floor, share * span)) if np.isfinite(span) and span > 0 else float(floor)


def joint_band(lower: float, upper: float, prismatic: bool) -> float:
    """:func:`rest_band` with the SPEC's floor of the joint's type (0.02 rad revolute, 2 mm prismatic)."""
    return rest_band(lower, upper, REST_BAND_FLOORS["prismatic" if prismatic else "revolute"])


def lean_load(load: JointLoad, *, on_stop: bool = False) -> float:
    """Largest |gravity load| (N*m or N) on a joint when its object leans lean = :data:`SET_DOWN_LEAN` in any direction:
    |tau_g| cos(lean) + g sin(lean) |w_h| (module docstring). ``on_stop``: the part rests on the stop its weight
    presses it onto, so only a lean that lifts it off loads the joint: g sin(lean) |w_h| - |tau_g| cos(lean)
    (negative: none does)."""
    pressed = abs(load.gravity_load) * np.cos(SET_DOWN_LEAN)
    lateral = G * np.sin(SET_DOWN_LEAN) * load.lateral_moment
    return float(lateral - pressed if on_stop else pressed + lateral)


@dataclass(frozen=True)
class Landing:
    """What a joint's part carries when its object lands after one set-down trial."""

    trial: str
    """``drop``, ``tilt+x`` ... (:data:`LANDING_TRIALS`)"""
    momentum: float
    """generalised momentum along the joint, kg*m/s (prismatic) or kg*m^2/s (revolute); > 0 moves q up"""
    inertia: float
    """generalised inertia of the moving subtree along the joint, kg or kg*m^2"""

    @property
    def energy(self) -> float:
        """Kinetic energy along the joint right after the object stops, J: p^2 / (2 I)."""
        return 0.5 * self.momentum**2 / self.inertia if self.inertia > 0 else 0.0


@dataclass(frozen=True)
class _Body:
    mass: float
    com: np.ndarray
    inertia: np.ndarray


def landings(session, links: dict[str, LinkPhysics], state: dict[str, float], scale: float,
             subtrees: dict[str, list[str]], hull_points: dict[str, np.ndarray], *,
             root_rotation: np.ndarray | None = None) -> dict[str, list[Landing]]:
    """The :class:`Landing` of every joint of ``subtrees`` in each of :data:`LANDING_TRIALS`.

    Args:
        session: a fixed-base session of the unscaled input asset (kinematics; set to ``state`` here and left so).
        links: the scaled physics of each link (mass kg, inertia kg*m^2 about the COM, COM m in the link frame).
        state: joint -> position, output units (rad or m).
        scale: the uniform scale s of the output.
        subtrees: joint -> the links its joint moves.
        hull_points: link -> (N, 3) collision hull vertices at scale 1 in the link frame: the footprint.
        root_rotation: (3, 3) the resting pose (world = R root); None: upright.

    Returns:
        joint -> its landings (an empty list without mass or footprint).
    """
    R0 = np.eye(3) if root_rotation is None else np.asarray(root_rotation, float)
    session.set_joint_positions({n: (v / scale if session.joint_types.get(n) == "prismatic" else v) for n, v in state.items()})
    bodies: dict[str, _Body] = {}
    pts = []
    frames = {}
    for ln in session.link_names:
        pos, R = session.link_frame(ln)
        pos, R = R0 @ (np.asarray(pos, float) * scale), R0 @ np.asarray(R, float)
        frames[ln] = (pos, R)
        hp = hull_points.get(ln)
        if hp is not None and len(hp):
            pts.append(pos + (np.asarray(hp, float) * scale) @ R.T)
        lp = links.get(ln)
        if lp is not None and lp.mass > 0:
            bodies[ln] = _Body(lp.mass, pos + R @ np.asarray(lp.com, float), R @ lp.inertia.matrix() @ R.T)
    names = [n for n in subtrees if n in session.joint_child]
    out: dict[str, list[Landing]] = {n: [] for n in names}
    if not bodies or not pts:
        return out
    points = np.concatenate(pts)
    total = sum(b.mass for b in bodies.values())
    com = sum(b.mass * b.com for b in bodies.values()) / total
    # as the dropped object reaches the ground: every link at sqrt(2 g h) down, not turning
    drop = np.array([0.0, 0.0, -math.sqrt(2.0 * G * SET_DOWN_DROP)])
    fields = {"drop": {ln: (drop, np.zeros(3)) for ln in bodies},
              **{trial: _tilt_field(trial, bodies, points, com, total) for trial in LANDING_TRIALS[1:]}}
    for name in names:
        o, R = frames[session.joint_child[name]]
        a = R @ np.asarray(session.joint_axis(name), float)
        a = a / max(float(np.linalg.norm(a)), 1e-12)
        prismatic = session.joint_types[name] == "prismatic"
        for trial, field in fields.items():
            if field is None:
                continue
            p = inertia = 0.0
            for ln in (ln for ln in subtrees[name] if ln in bodies):
                b, (v, w) = bodies[ln], field[ln]
                if prismatic:
                    p += b.mass * float(v @ a)
                    inertia += b.mass
                else:
                    t = np.cross(a, b.com - o)
                    p += b.mass * float(t @ v) + float(a @ b.inertia @ w)
                    inertia += b.mass * float(t @ t) + float(a @ b.inertia @ a)
            if inertia > 0:
                out[name].append(Landing(trial, float(p), float(inertia)))
    return out


def _tilt_field(trial: str, bodies: dict[str, _Body], points: np.ndarray, com: np.ndarray,
                total: float) -> dict[str, tuple[np.ndarray, np.ndarray]] | None:
    """link -> (COM velocity, angular velocity) as the object tilted by ``trial`` (as robust rest tilts it: about the
    world axis through its footprint's centre, its lowest point on the ground) falls back flat about the edge it
    rests on; None when the tilted object does not fall back (its centre of mass beyond that edge)."""
    axis = np.eye(3)[0 if trial.endswith("x") else 1]
    sign = 1.0 if trial[4] == "+" else -1.0
    Rt = axis_angle_matrix(axis, sign * SET_DOWN_LEAN)
    pivot = points[int(np.argmin((points @ Rt.T)[:, 2]))].copy()
    pivot[2] = float(points[:, 2].min())
    rise = float((Rt @ (com - pivot))[2] - (com - pivot)[2])
    if not rise > 0:
        return None
    edge = 0.0
    for b in bodies.values():
        r = b.com - pivot
        r = r - (r @ axis) * axis
        edge += float(axis @ b.inertia @ axis) + b.mass * float(r @ r)
    w = -sign * math.sqrt(2.0 * total * G * rise / edge) * axis  # back toward flat
    return {ln: (np.cross(w, b.com - pivot), w) for ln, b in bodies.items()}


def landing_friction(trials: list[Landing], band: float, blocked: tuple[bool, bool] = (False, False),
                     gravity_load: float = 0.0) -> tuple[float, str]:
    """(friction N*m or N beyond the holding friction that stops the part within ``band`` (rad or m) after every
    landing of ``trials``, the trial that needs the most): its energy over the band, p^2 / (2 I) / band (work-energy
    theorem; the holding friction takes the gravity load ``gravity_load``, N*m or N, > 0 pushing q up, where it pushes
    along the landing's motion, and where it pushes against it, it stops the part too: |gravity_load| less).
    ``blocked``: (down, up) whether the part rests on a stop in the direction of decreasing / increasing q, so a
    landing that moves it that way moves nothing. (0, "") when none moves it."""
    if not band > 0:
        return 0.0, ""
    best, which = 0.0, ""
    for t in trials:
        if t.momentum == 0.0 or (blocked[0] and t.momentum < 0) or (blocked[1] and t.momentum > 0):
            continue
        against = max(0.0, -math.copysign(1.0, t.momentum) * gravity_load)
        f = t.energy / band - against
        if f > best:
            best, which = f, t.trial
    return float(best), which
