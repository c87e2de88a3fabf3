"""Physical-robustness metrics (penetration Phi, rest stability, oscillation, ...) with the SPEC's
definitions, in any engine; each metric's definition: ``docs/design/metrics.md``, "Physical robustness".
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field

import numpy as np

from asset2sim.engines.base import SimSession
from asset2sim.frames import quat_angle
from asset2sim.schemas.config import REST_BAND_FLOORS, REST_BAND_RANGE_SHARE, SimConventions
from asset2sim.schemas.metrics import unit
from asset2sim.schemas.report import MetricResult
from asset2sim.tasks.check.verdict import UNRESOLVED_PENETRATION_MM
from asset2sim.tasks.synthesize.set_down import rest_band


@dataclass
class RestTrace:
    """Recording of one rest test: ``t`` (N,) s since the end of settling;
    ``root_pos`` (N, 3) m; ``root_quat`` (N, 4) xyzw; ``joints`` name -> (N,) rad or m;
    ``settle_joints`` name -> (M,) during settling; ``p0``/``q0`` the root pose after settling."""

    t: np.ndarray
    root_pos: np.ndarray
    root_quat: np.ndarray
    joints: dict[str, np.ndarray]
    joint_types: dict[str, str]
    p0: np.ndarray
    q0: np.ndarray
    settle_joints: dict[str, np.ndarray] = field(default_factory=dict)
    initial_joints: dict[str, float] = field(default_factory=dict)
    diverged: bool = False
    initial_root_pos: np.ndarray | None = None
    #: Root pose (3,) m and (4,) xyzw as placed, before settling.
    initial_root_quat: np.ndarray | None = None
    #: joint -> (lower, upper) rad or m as the engine holds them (infinite for a continuous joint).
    joint_limits: dict[str, tuple[float, float]] = field(default_factory=dict)


def root_label(fixed: bool) -> str:
    """How a check held the root: "fixed (mounted)" or "free (on the ground)"."""
    return "fixed (mounted)" if fixed else "free (on the ground)"


def penetration(session: SimSession) -> MetricResult:
    """Phi at the session's current state, mm, with the colliding link pairs (``details.pairs``)."""
    phi, pairs = session.self_penetration()
    return MetricResult(
        name="penetration", value=phi * 1000.0, unit=unit("penetration"), passed=bool(phi * 1000.0 <= UNRESOLVED_PENETRATION_MM),
        threshold=f"<= {UNRESOLVED_PENETRATION_MM:g} mm (self-contact: links that are not parent and child)",
        details={"pairs": [{"link_a": c.link_a, "link_b": c.link_b, "depth_mm": c.depth * 1000.0,
                            "max_depth_mm": c.max_depth * 1000.0, "points": c.points} for c in pairs]},
        engine=session.engine)


#: Length of the windows in which a disturbed object's settling is watched, s.
RECOVERY_WINDOW = 0.25


def run_rest_test(session: SimSession, conventions: SimConventions | None = None, recovery_time: float = 0.0) -> RestTrace:
    """Settle T_set, then record T_test (SPEC), stepping the session in place.
    ``recovery_time`` (s): settling may go on in windows of
    :data:`RECOVERY_WINDOW` s, up to that much more, until a window in which
    the root moved less than half the stability tolerances; 0: the SPEC test exactly.
    """
    conv = conventions or SimConventions()
    n_set = int(round(conv.settle_time / conv.timestep))
    n_test = int(round(conv.test_time / conv.timestep))
    n_window = max(1, int(round(RECOVERY_WINDOW / conv.timestep)))
    n_extra = int(round(max(0.0, float(recovery_time)) / conv.timestep))
    names = list(session.joint_names)
    initial = session.joint_positions()
    r0_pos, r0_quat = session.root_pose()
    settle_rows: list[dict[str, float]] = []
    diverged = False
    for _ in range(n_set):
        session.step(1)
        settle_rows.append(session.joint_positions())
    extra = 0
    while extra < n_extra:  # a disturbed object still moving: settle on, window by window
        w_pos, w_quat = session.root_pose()
        moved = turned = 0.0
        for _ in range(min(n_window, n_extra - extra)):
            session.step(1)
            extra += 1
            settle_rows.append(session.joint_positions())
            p, q = session.root_pose()
            if not (np.all(np.isfinite(p)) and np.all(np.isfinite(q))):
                moved = turned = float("inf")
                break
            moved, turned = max(moved, float(np.linalg.norm(np.asarray(p) - w_pos))), max(turned, quat_angle(w_quat, q))
        quiet = moved <= 0.5 * conv.stability_pos_tol and turned <= 0.5 * conv.stability_ori_tol
        if quiet or not np.isfinite(moved):  # at rest for a window, or diverged (the test records it)
            break
    settle = {n: np.array([row[n] for row in settle_rows], float) for n in names}
    p0, q0 = session.root_pose()
    pos = np.empty((n_test + 1, 3))
    quat = np.empty((n_test + 1, 4))
    joints = {n: np.empty(n_test + 1) for n in names}
    for i in range(n_test + 1):
        if i:
            session.step(1)
        pos[i], quat[i] = session.root_pose()
        q = session.joint_positions()
        for n in names:
            joints[n][i] = q[n]
        if i and not all(map(math.isfinite, (*pos[i], *quat[i]))):  # as np.isfinite over both rows, without its per-call cost
            diverged = True
            pos, quat = pos[: i + 1], quat[: i + 1]
            joints = {n: v[: i + 1] for n, v in joints.items()}
            break
    return RestTrace(
        t=np.arange(len(pos)) * conv.timestep, root_pos=pos, root_quat=quat, joints=joints,
        joint_types=dict(session.joint_types), p0=np.asarray(p0, float), q0=np.asarray(q0, float), settle_joints=settle,
        initial_joints=initial, diverged=diverged or not (np.all(np.isfinite(p0)) and np.all(np.isfinite(q0))),
        initial_root_pos=np.asarray(r0_pos, float), initial_root_quat=np.asarray(r0_quat, float),
        joint_limits={n: (float(lo), float(hi)) for n, (lo, hi) in session.joint_limits.items() if n in names})


def rest_stability(trace: RestTrace, conventions: SimConventions | None = None, engine: str = "pybullet") -> MetricResult:
    """D_pos (m) and D_ori (rad) of a :class:`RestTrace`; value is D_pos in m."""
    conv = conventions or SimConventions()
    result = functools.partial(MetricResult, name="rest_stability", unit=unit("rest_stability"), engine=engine,
                               threshold=f"D_pos <= {conv.stability_pos_tol} m and D_ori <= {conv.stability_ori_tol} rad")
    if trace.diverged:
        return result(value=None, passed=False, details={"diverged": True})
    d_pos = float(np.max(np.linalg.norm(trace.root_pos - trace.p0, axis=1)))
    d_ori = float(max(quat_angle(trace.q0, q) for q in trace.root_quat))
    return result(value=d_pos, passed=d_pos <= conv.stability_pos_tol and d_ori <= conv.stability_ori_tol,
                  details={"D_pos_m": d_pos, "D_ori_rad": d_ori, "diverged": False})


#: Largest root rotation during settling, rad, before the object counts as fallen over (not a SPEC metric).
SETTLE_TILT_LIMIT = 0.05


def settle_tilt(trace: RestTrace, engine: str = "pybullet") -> MetricResult:
    """Root rotation (rad) between placement and the end of settling; fails
    above :data:`SETTLE_TILT_LIMIT` (the object fell over while settling)."""
    result = functools.partial(MetricResult, name="settle_tilt", unit=unit("settle_tilt"), engine=engine)
    if trace.initial_root_quat is None or trace.diverged:
        return result(value=None, passed=not trace.diverged, threshold=f"<= {SETTLE_TILT_LIMIT} rad",
                      details={"diverged": trace.diverged})
    tilt = quat_angle(trace.initial_root_quat, trace.q0)
    return result(value=tilt, passed=tilt <= SETTLE_TILT_LIMIT,
                  threshold=f"root rotation while settling <= {SETTLE_TILT_LIMIT} rad (the object does not fall over as it "
                            "settles)",
                  details={"tilt_rad": tilt, "displacement_m": float(np.linalg.norm(trace.p0 - trace.initial_root_pos))})


def oscillation(trace: RestTrace, conventions: SimConventions | None = None, engine: str = "pybullet") -> MetricResult:
    """Joint oscillation during T_test; value = number of failing joints."""
    conv = conventions or SimConventions()
    per_joint = {}
    for name, q in trace.joints.items():
        q = np.asarray(q, float)
        if not np.all(np.isfinite(q)):
            per_joint[name] = {"sign_changes": None, "amplitude": None, "failed": True, "diverged": True}
            continue
        s = np.sign(np.diff(q))  # the sign changes of the step-to-step motion, exact zeros skipped
        s = s[s != 0]
        changes = int(np.count_nonzero(s[1:] != s[:-1]))
        amp = float(np.max(q) - np.min(q)) if len(q) else 0.0
        prismatic = trace.joint_types.get(name) == "prismatic"
        limit = conv.oscillation_amp_prismatic if prismatic else conv.oscillation_amp_revolute
        failed = changes >= conv.oscillation_sign_changes and amp > limit
        per_joint[name] = {"sign_changes": changes, "amplitude": amp, "unit": "m" if prismatic else "rad",
                           "amplitude_limit": limit, "failed": failed}
    failing = [n for n, j in per_joint.items() if j["failed"]]
    return MetricResult(
        name="oscillation", value=float(len(failing)), unit=unit("oscillation"), passed=not failing and not trace.diverged,
        threshold=(f"no joint with >= {conv.oscillation_sign_changes} sign changes and peak-to-peak amplitude > "
                   f"{conv.oscillation_amp_revolute} rad / {conv.oscillation_amp_prismatic} m"),
        details={"joints": per_joint, "failing": failing}, engine=engine)


#: The last stretch of a recording in which a joint counts as still moving (s) ...
STILL_WINDOW = 0.5
#: ... when it travels more than this share of its band there (dimensionless): a part that creeps or keeps swinging
#: has not come to rest, wherever it happens to be when the recording ends.
STILL_SHARE = 0.25


@dataclass(frozen=True)
class JointSettling:
    """Where one joint came to rest in a recording, against its initial state q0 (rad or m)."""

    #: |q_end - q0|: where it came to rest (the graded value)
    settled: float
    #: max |q(t) - q0| over the recording: its largest excursion (reported, not graded)
    peak: float
    #: max - min of q over the last :data:`STILL_WINDOW` s (rad or m)
    still_motion: float
    #: the band it must settle in (:func:`~asset2sim.tasks.synthesize.set_down.rest_band`)
    band: float

    @property
    def moving(self) -> bool:
        """Still moving at the end: travelled more than :data:`STILL_SHARE` of its band in the last window."""
        return not self.still_motion <= STILL_SHARE * self.band

    @property
    def held(self) -> bool:
        """Came to rest inside its band (finite, not moving)."""
        return bool(self.settled <= self.band and not self.moving)


def joint_settling(trace: RestTrace, floors: dict[str, float] = REST_BAND_FLOORS, initial: dict[str, float] | None = None,
                   timestep: float | None = None, share: float = REST_BAND_RANGE_SHARE) -> dict[str, JointSettling]:
    """:class:`JointSettling` of every joint of ``trace`` over its settling and test, positions clipped to the
    joint's limits (an engine's soft limit lets a joint pressed on it pass it by mm: not a motion).

    Args:
        trace: the recording (``settle_joints`` and ``joints`` (N,) rad or m, ``joint_limits``).
        floors: joint type (``"revolute"``, ``"prismatic"``) -> the band's floor (rad or m; default the SPEC's
            :data:`~asset2sim.schemas.config.REST_BAND_FLOORS`); a continuous joint takes the revolute one.
        initial: joint -> q0 (rad or m); default ``trace.initial_joints``, else the first sample.
        timestep: s between samples (default the recording's ``t`` spacing, else 1/240 s).
        share: the band's share of the joint's range (:func:`~asset2sim.tasks.synthesize.set_down.rest_band`).
    """
    init = trace.initial_joints if initial is None else initial
    dt = timestep or (float(trace.t[1] - trace.t[0]) if len(trace.t) > 1 else 1.0 / 240.0)
    n_still = max(2, int(round(STILL_WINDOW / dt)) + 1)
    out = {}
    for name, q in trace.joints.items():
        allq = np.concatenate([trace.settle_joints.get(name, np.empty(0)), np.asarray(q, float)])
        lo, hi = trace.joint_limits.get(name, (-np.inf, np.inf))
        kind = "prismatic" if trace.joint_types.get(name) == "prismatic" else "revolute"
        band = rest_band(lo, hi, floors[kind], share)
        if not len(allq) or not np.all(np.isfinite(allq)):
            out[name] = JointSettling(float("inf"), float("inf"), float("inf"), band)
            continue
        if lo <= hi:
            allq = np.clip(allq, lo, hi)
        q0 = float(init.get(name, allq[0]))
        tail = allq[-n_still:]
        out[name] = JointSettling(settled=float(abs(allq[-1] - q0)), peak=float(np.max(np.abs(allq - q0))),
                                  still_motion=float(np.max(tail) - np.min(tail)), band=band)
    return out


#: Largest ground penetration during the rest test that passes, m (docs/design/metrics.md, "ground penetration").
GROUND_PENETRATION_TOL = 0.005
#: Explosion thresholds (divergence): root speed m/s, revolute rad/s, prismatic m/s.
EXPLOSION_ROOT_SPEED = 10.0
EXPLOSION_JOINT_SPEED_REVOLUTE = 100.0
EXPLOSION_JOINT_SPEED_PRISMATIC = 10.0
#: Root travel that counts as an explosion: max(1 m, 5 x largest extent).
EXPLOSION_TRAVEL_MIN = 1.0
EXPLOSION_TRAVEL_FACTOR = 5.0


def explosion_speed(joint_type: str | None) -> float:
    """The joint speed that counts as an explosion: m/s for a prismatic joint, else rad/s."""
    return EXPLOSION_JOINT_SPEED_PRISMATIC if joint_type == "prismatic" else EXPLOSION_JOINT_SPEED_REVOLUTE


def ground_penetration(ground: np.ndarray, timestep: float, engine: str = "pybullet") -> MetricResult:
    """``ground_penetration`` (mm): the deepest ground penetration ``ground`` (K,) m over every step of the rest test
    (settling and test), against :data:`GROUND_PENETRATION_TOL`; a non-finite step fails; ``timestep`` s."""
    g = np.asarray(ground, float)
    finite = g[np.isfinite(g)]
    worst = float(np.max(finite)) if len(finite) else 0.0
    at = int(np.argmax(finite)) if len(finite) else 0
    return MetricResult(name="ground_penetration", value=worst * 1000.0, unit=unit("ground_penetration"),
                        passed=bool(worst <= GROUND_PENETRATION_TOL and len(finite) == len(g)),
                        threshold=f"<= {GROUND_PENETRATION_TOL * 1000:g} mm at every step of the rest test",
                        details={"worst_step": at, "worst_time_s": (at + 1) * timestep, "steps": int(len(g))}, engine=engine)


def divergence_check(root: np.ndarray, joints: dict[str, np.ndarray], joint_types: dict[str, str],
                     dt: float, largest_extent: float) -> dict:
    """Divergence (non-finite values or an explosion) of one run: ``root`` (K, 3) m
    and ``joints`` (joint -> (K,)) per step, ``dt`` s, ``largest_extent`` m. Returns
    {diverged, nan, reasons, peak_root_speed m/s, root_travel m, travel_limit, peak_joint_speed}."""
    reasons = []
    nan = not (np.all(np.isfinite(root)) and all(np.all(np.isfinite(v)) for v in joints.values()))
    if nan:
        reasons.append("non-finite pose or joint position")
    r = root[np.all(np.isfinite(root), axis=1)] if len(root) else root
    speed = float(np.max(np.linalg.norm(np.diff(r, axis=0), axis=1)) / dt) if len(r) > 1 else 0.0
    travel = float(np.max(np.linalg.norm(r - r[0], axis=1))) if len(r) else 0.0
    travel_lim = max(EXPLOSION_TRAVEL_MIN, EXPLOSION_TRAVEL_FACTOR * largest_extent)
    if speed > EXPLOSION_ROOT_SPEED:
        reasons.append(f"root speed {speed:.3g} m/s > {EXPLOSION_ROOT_SPEED} m/s")
    if travel > travel_lim:
        reasons.append(f"root travelled {travel:.3g} m > {travel_lim:.3g} m")
    peak = {}
    for n, q in joints.items():
        q = q[np.isfinite(q)]
        peak[n] = v = float(np.max(np.abs(np.diff(q))) / dt) if len(q) > 1 else 0.0
        lim = explosion_speed(joint_types.get(n))
        if v > lim:
            reasons.append(f"joint {n} speed {v:.3g} > {lim}")
    return {"diverged": bool(reasons), "nan": bool(nan), "reasons": reasons, "peak_root_speed": speed, "root_travel": travel,
            "travel_limit": travel_lim, "peak_joint_speed": peak}


def divergence(trace: RestTrace, root: np.ndarray, joints: dict[str, np.ndarray], dt: float, largest_extent: float,
               engine: str = "pybullet") -> MetricResult:
    """``divergence`` of one rest test (:func:`divergence_check` of its per-step ``root`` (K, 3) m and ``joints``
    (joint -> (K,)) series, or the trace's own divergence); ``largest_extent`` m of the object."""
    d = divergence_check(root, joints, trace.joint_types, dt, largest_extent)
    d["nan"] = d["nan"] or trace.diverged
    d["diverged"] = d["diverged"] or trace.diverged
    threshold = (f"finite, root speed <= {EXPLOSION_ROOT_SPEED} m/s, joint speed <= {EXPLOSION_JOINT_SPEED_REVOLUTE} rad/s "
                 f"({EXPLOSION_JOINT_SPEED_PRISMATIC} m/s), root travel <= max({EXPLOSION_TRAVEL_MIN} m, "
                 f"{EXPLOSION_TRAVEL_FACTOR} x largest extent)")
    return MetricResult(name="divergence", value=float(d["diverged"]), unit=unit("divergence"), passed=not d["diverged"],
                        threshold=threshold, details=d, engine=engine)
