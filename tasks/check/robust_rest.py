"""Robust rest: does the object come back to rest, with its joints held, after the small disturbances
of being put down (:data:`TRIALS`)? Definition: ``docs/design/metrics.md``, "robust_rest".
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from asset2sim.engines.base import EngineUnsupported, SimSession
from asset2sim.engines.source import SimObject
from asset2sim.frames import axis_angle_matrix, matrix_quat_wxyz, quat_wxyz_matrix, quat_wxyz_to_xyzw, quat_xyzw_to_wxyz
from asset2sim.schemas.config import REST_BAND_FLOORS, REST_BAND_RANGE_SHARE, SimConventions
from asset2sim.schemas.metrics import unit
from asset2sim.schemas.report import MetricResult
from asset2sim.tasks.check import metrics, support
from asset2sim.tasks.geometry.limits import subtrees

#: The trials, in order.
TRIALS: tuple[str, ...] = ("drop", "tilt+x", "tilt-x", "tilt+y", "tilt-y", "nudge")


@dataclass
class RobustRestConfig:
    """Robust-rest knobs (units on every field)."""

    #: lift before the drop, m (SPEC: 2 cm)
    drop_height: float = 0.02
    #: tilt about each horizontal axis, rad (SPEC: 5 deg)
    tilt: float = math.radians(5.0)
    #: horizontal root speed of the nudge, m/s
    nudge_speed: float = 0.05
    #: floor of the band a revolute joint must come to rest in around its initial state, rad (SPEC: max(0.02 rad,
    #: 5 % of its range))
    joint_tol_revolute: float = REST_BAND_FLOORS["revolute"]
    #: ... of a prismatic joint, m (SPEC: max(2 mm, 5 % of its range))
    joint_tol_prismatic: float = REST_BAND_FLOORS["prismatic"]
    #: share of a joint's range the band takes where that is more than the floor (dimensionless, SPEC: 5 %)
    joint_band_share: float = REST_BAND_RANGE_SHARE
    #: largest change of the body's up direction, rad
    topple_tol: float = 0.05
    #: settling allowed after T_set while the disturbed object still moves, s
    recovery_time: float = 3.0
    trials: tuple[str, ...] = TRIALS
    #: joints the request asks to move freely ("swings freely", "slides easily"): graded for coming to rest, not for
    #: holding their state under a disturbance (SPEC, robust rest); their undisturbed hold is the rest test's
    free_joints: tuple[str, ...] = ()


@dataclass
class Trial:
    """One disturbance and what followed. Lengths m, angles rad."""

    name: str
    passed: bool | None
    d_pos: float | None = None
    d_ori: float | None = None
    topple: float | None = None
    #: joint -> where it came to rest, |q_end - q_initial| (rad or m): the graded value
    joint_drift: dict[str, float] = field(default_factory=dict)
    #: joint -> its largest excursion |q(t) - q_initial| while the object landed and settled (reported, not graded)
    joint_peak: dict[str, float] = field(default_factory=dict)
    #: joint -> its band (rad or m): max(floor, 5 % of its range)
    joint_tolerance: dict[str, float] = field(default_factory=dict)
    #: joint -> ``"rad"`` or ``"m"``
    joint_units: dict[str, str] = field(default_factory=dict)
    #: joints still moving at the end of the test (:attr:`~asset2sim.tasks.check.metrics.JointSettling.moving`)
    moving_joints: list[str] = field(default_factory=list)
    failing_joints: list[str] = field(default_factory=list)
    #: joints the object rolls on: their drift is recorded, not graded
    rolling: list[str] = field(default_factory=list)
    #: joints the request asks to move freely: graded for coming to rest, their drift recorded, not graded
    free: list[str] = field(default_factory=list)
    diverged: bool = False
    failure: str = ""
    #: The rest test that followed the disturbance (for the report's evidence; not in :meth:`summary`).
    trace: metrics.RestTrace | None = field(default=None, repr=False, compare=False)
    #: The root's orientation (4,) xyzw at rest before the disturbance.
    reference_quat: np.ndarray | None = field(default=None, repr=False, compare=False)

    def summary(self) -> dict[str, Any]:
        """JSON-able dict (the trace left out)."""
        return {k: v for k, v in self.__dict__.items() if k not in ("trace", "reference_quat")}


def world_vertices(session: SimSession) -> np.ndarray:
    """Collision vertices (k, 3) of every link in the world, m (:func:`~asset2sim.tasks.check.support.link_world_vertices`)."""
    pts = [support.link_world_vertices(session, ln) for ln in session.link_names]
    return np.concatenate(pts) if pts else np.zeros((0, 3))


def tilt_pose(session: SimSession, axis: np.ndarray, angle: float) -> tuple[np.ndarray, np.ndarray]:
    """Root pose (position (3,) m, quaternion (4,) xyzw) of the object turned by
    ``angle`` (rad) about world ``axis`` (3,) through the centre of its
    footprint, shifted so its lowest collision vertex is at z = 0."""
    pos, quat = session.root_pose()
    pts = world_vertices(session)
    if not len(pts):
        raise ValueError("no collision geometry: the object cannot be tilted on the ground")
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    pivot = np.array([0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1]), lo[2]])
    Rt = axis_angle_matrix(axis, angle)
    R0 = quat_wxyz_matrix(quat_xyzw_to_wxyz(quat))
    new_pos = pivot + Rt @ (pos - pivot)
    new_quat = quat_wxyz_to_xyzw(matrix_quat_wxyz(Rt @ R0))
    low = float(np.min(((pts - pivot) @ Rt.T)[:, 2] + pivot[2]))  # lowest vertex after the turn
    return new_pos - np.array([0.0, 0.0, low]), new_quat


def up_change(q_ref: np.ndarray, q_now: np.ndarray) -> float:
    """Angle (rad) between world z and the body's up direction (world z at ``q_ref``) at ``q_now`` (xyzw)."""
    R0 = quat_wxyz_matrix(quat_xyzw_to_wxyz(q_ref))
    R1 = quat_wxyz_matrix(quat_xyzw_to_wxyz(q_now))
    up = R1 @ (R0.T @ np.array([0.0, 0.0, 1.0]))
    return float(math.acos(max(-1.0, min(1.0, up[2] / max(np.linalg.norm(up), 1e-12)))))


def _disturb(session: SimSession, name: str, cfg: RobustRestConfig) -> None:
    pos, quat = session.root_pose()
    if name == "drop":
        session.set_root_pose(pos + np.array([0.0, 0.0, cfg.drop_height]), quat)
    elif name.startswith("tilt"):
        p, q = tilt_pose(session, np.eye(3)[0 if name.endswith("x") else 1], (1.0 if name[4] == "+" else -1.0) * cfg.tilt)
        session.set_root_pose(p, q)
        try:  # exact: the lowest collision point of the tilted object on z = 0
            session.place_on_ground()
        except EngineUnsupported:  # the engine settles it from the tilt
            pass
    elif name == "nudge":
        session.set_root_velocity(np.array([cfg.nudge_speed, 0.0, 0.0]), np.zeros(3))
    else:
        raise ValueError(f"unknown robust-rest trial {name!r}; known: {', '.join(TRIALS)}")


def run_trial(session: SimSession, name: str, initial_state: dict[str, float], q_ref: np.ndarray,
              conventions: SimConventions, config: RobustRestConfig, rolling: list[str] | tuple[str, ...] = ()) -> Trial:
    """Disturb the session by trial ``name``, run the rest test and grade it
    (module docstring). ``rolling``: joints whose drift is not graded; ``config.free_joints``: joints graded only for
    coming to rest (still moving fails), where they settle recorded.

    Raises:
        EngineUnsupported: the engine cannot perform the disturbance.
        ValueError: unknown trial.
    """
    _disturb(session, name, config)
    trace = metrics.run_rest_test(session, conventions, recovery_time=config.recovery_time)
    stab = metrics.rest_stability(trace, conventions, engine=session.engine)
    settling = metrics.joint_settling(trace, {"revolute": config.joint_tol_revolute, "prismatic": config.joint_tol_prismatic},
                                      initial=initial_state, timestep=conventions.timestep, share=config.joint_band_share)
    free = [j for j in settling if j in config.free_joints and j not in rolling]
    failing = [j for j, s in settling.items() if j not in rolling and (s.moving if j in free else not s.held)]
    diverged = trace.diverged
    topple = None if diverged else up_change(q_ref, trace.root_quat[-1])
    why = []
    if diverged:
        why.append("diverged")
    elif not stab.passed:
        why.append(f"not at rest (D_pos {stab.details['D_pos_m']:.2g} m, D_ori {stab.details['D_ori_rad']:.2g} rad)")
    if topple is not None and topple > config.topple_tol:
        why.append(f"toppled ({topple:.2f} rad)")
    if failing:
        why.append("joints not held: " + ", ".join(
            f"{j} settled {settling[j].settled:.3g} of {settling[j].band:.3g}" + (" and still moving" if settling[j].moving else "")
            for j in failing))
    graded = [j for j in settling if j not in rolling and j not in free]
    return Trial(
        name=name, passed=not why, d_pos=stab.details.get("D_pos_m"), d_ori=stab.details.get("D_ori_rad"),
        topple=topple, joint_drift={j: s.settled for j, s in settling.items()}, joint_peak={j: s.peak for j, s in settling.items()},
        joint_tolerance={j: settling[j].band for j in graded},
        joint_units={j: "m" if trace.joint_types.get(j) == "prismatic" else "rad" for j in settling},
        moving_joints=[j for j in [*graded, *free] if settling[j].moving], failing_joints=failing,
        rolling=[j for j in trace.joints if j in rolling], free=free,
        diverged=diverged, failure="; ".join(why), trace=trace, reference_quat=np.asarray(q_ref, float))


@dataclass
class RobustRestRun:
    """Every trial in one engine."""

    engine: str
    trials: list[Trial] = field(default_factory=list)
    #: why the whole metric was skipped (fixed root)
    skipped: str | None = None


def run_robust_rest(engine: str, obj: SimObject, config: RobustRestConfig | None = None) -> RobustRestRun:
    """Every trial of ``config`` in one session of ``engine`` opened on ``obj`` as for the SPEC rest test. A root
    fixed as mounted (``obj.fixed_base``) is skipped.

    Raises:
        EngineUnavailable: the engine is not installed; whatever loading raises.
    """
    cfg = config or RobustRestConfig()
    run = RobustRestRun(engine)
    if obj.fixed_base:
        run.skipped = "root fixed as the asset declares: a mounted object is not dropped, tilted or nudged"
        return run
    with obj.open(engine) as session:
        rolling = support.rolling_joints(session, subtrees(obj.source.model(mode="lenient")))
        run.trials = run_trials(session, dict(obj.state), obj.conventions, cfg, rolling)
    return run


def run_trials(session: SimSession, initial_state: dict[str, float], conventions: SimConventions | None = None,
               config: RobustRestConfig | None = None, rolling: list[str] | tuple[str, ...] = ()) -> list[Trial]:
    """Every trial of ``config`` on an open session, each from its present
    placement; a disturbance the engine cannot perform is skipped (``passed`` None)."""
    cfg = config or RobustRestConfig()
    conv = conventions or SimConventions()
    _, q_ref = session.root_pose()
    saved = session.save_state()
    trials = []
    for name in cfg.trials:
        session.restore_state(saved)
        try:
            trials.append(run_trial(session, name, initial_state, q_ref, conv, cfg, rolling))
        except EngineUnsupported as exc:
            trials.append(Trial(name=name, passed=None, failure=f"skipped: {exc}"))
    session.discard_state(saved)
    return trials


def robust_rest_metric(run: RobustRestRun, config: RobustRestConfig | None = None) -> MetricResult:
    """The ``robust_rest`` metric: value = failed trials; passes iff none failed (None when all were skipped)."""
    cfg = config or RobustRestConfig()
    done = [t for t in run.trials if t.passed is not None]
    failed = [t for t in done if not t.passed]
    return MetricResult(
        name="robust_rest", value=float(len(failed)) if done else None, unit=unit("robust_rest"),
        passed=(not failed) if done else None,
        threshold=(f"after a {cfg.drop_height * 100:g} cm drop, {math.degrees(cfg.tilt):g} deg tilts about x and y and a "
                   f"{cfg.nudge_speed:g} m/s nudge: at rest (D_pos <= 1e-3 m, D_ori <= 1e-2 rad), up within "
                   f"{cfg.topple_tol:g} rad, every joint come to rest within max({cfg.joint_tol_revolute:g} rad / "
                   f"{cfg.joint_tol_prismatic * 1000:g} mm, {cfg.joint_band_share:.0%} of its range) of its state; a part "
                   "the request asks to move freely comes to rest, wherever it settles"),
        details={"trials": {t.name: t.summary() for t in run.trials},
                 "free_moving": {j: "the request asks it to move freely: graded for coming to rest, not for holding its state "
                                    "under a disturbance (its undisturbed hold: state_hold)" for j in cfg.free_joints},
                 "failures": [f"{t.name}: {t.failure}" for t in failed],
                 "skipped": run.skipped or [t.name for t in run.trials if t.passed is None]},
        engine=run.engine)


def toppled(metric: MetricResult) -> bool:
    """Whether a trial of a ``robust_rest`` metric toppled the object (up
    direction more than ``topple_tol`` rad off the vertical); False when none measured it.

    Raises:
        ValueError: ``metric`` is not a ``robust_rest`` metric.
    """
    if metric.name != "robust_rest":
        raise ValueError(f"not a robust_rest metric: {metric.name!r}")
    tol = RobustRestConfig().topple_tol
    trials = metric.details.get("trials") or {}
    return any(t.get("topple") is not None and float(t["topple"]) > tol for t in trials.values())
