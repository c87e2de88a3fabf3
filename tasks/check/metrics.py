"""Physical-robustness metrics (penetration Phi, rest stability, oscillation, ...) with the SPEC's
definitions, in any engine; each metric's definition: ``docs/design/metrics.md``, "Physical robustness".
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from asset2sim.engines.base import SimSession
from asset2sim.frames import quat_angle
from asset2sim.schemas.config import SimConventions
from asset2sim.schemas.metrics import unit
from asset2sim.schemas.report import MetricResult


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
    initial_root_quat: np.ndarray | None = None
    """Root pose (3,) m and (4,) xyzw as placed, before settling."""


def penetration(session: SimSession) -> MetricResult:
    """Phi at the session's current state, mm, with the colliding link pairs (``details.pairs``)."""
    phi, pairs = session.self_penetration()
    return MetricResult(
        name="penetration", value=phi * 1000.0, unit=unit("penetration"), passed=None,
        threshold="reported (no pass/fail threshold)",
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
    pos[0], quat[0] = p0, q0
    q = session.joint_positions()
    for n in names:
        joints[n][0] = q[n]
    for i in range(1, n_test + 1):
        session.step(1)
        pos[i], quat[i] = session.root_pose()
        q = session.joint_positions()
        for n in names:
            joints[n][i] = q[n]
        if not all(map(math.isfinite, (*pos[i], *quat[i]))):  # as np.isfinite over both rows, without its per-call cost
            diverged = True
            pos, quat = pos[: i + 1], quat[: i + 1]
            joints = {n: v[: i + 1] for n, v in joints.items()}
            break
    return RestTrace(
        t=np.arange(len(pos)) * conv.timestep, root_pos=pos, root_quat=quat, joints=joints,
        joint_types=dict(session.joint_types), p0=np.asarray(p0, float), q0=np.asarray(q0, float), settle_joints=settle,
        initial_joints=initial, diverged=diverged or not (np.all(np.isfinite(p0)) and np.all(np.isfinite(q0))),
        initial_root_pos=np.asarray(r0_pos, float), initial_root_quat=np.asarray(r0_quat, float))


def rest_stability(trace: RestTrace, conventions: SimConventions | None = None, engine: str = "pybullet") -> MetricResult:
    """D_pos (m) and D_ori (rad) of a :class:`RestTrace`; value is D_pos in m."""
    conv = conventions or SimConventions()
    threshold = f"D_pos <= {conv.stability_pos_tol} m and D_ori <= {conv.stability_ori_tol} rad"
    if trace.diverged:
        return MetricResult(name="rest_stability", value=None, unit=unit("rest_stability"), passed=False,
                            threshold=threshold, details={"diverged": True}, engine=engine)
    d_pos = float(np.max(np.linalg.norm(trace.root_pos - trace.p0, axis=1)))
    d_ori = float(max(quat_angle(trace.q0, q) for q in trace.root_quat))
    passed = d_pos <= conv.stability_pos_tol and d_ori <= conv.stability_ori_tol
    return MetricResult(name="rest_stability", value=d_pos, unit=unit("rest_stability"), passed=passed, threshold=threshold,
                        details={"D_pos_m": d_pos, "D_ori_rad": d_ori, "diverged": False}, engine=engine)


#: Largest root rotation during settling, rad, before the object counts as fallen over (not a SPEC metric).
SETTLE_TILT_LIMIT = 0.05


def settle_tilt(trace: RestTrace, engine: str = "pybullet") -> MetricResult:
    """Root rotation (rad) between placement and the end of settling; fails
    above :data:`SETTLE_TILT_LIMIT` (the object fell over while settling)."""
    if trace.initial_root_quat is None or trace.diverged:
        return MetricResult(name="settle_tilt", value=None, unit=unit("settle_tilt"), passed=not trace.diverged, engine=engine,
                            threshold=f"<= {SETTLE_TILT_LIMIT} rad", details={"diverged": trace.diverged})
    tilt = quat_angle(trace.initial_root_quat, trace.q0)
    drop = float(np.linalg.norm(trace.p0 - trace.initial_root_pos))
    return MetricResult(name="settle_tilt", value=tilt, unit=unit("settle_tilt"), passed=tilt <= SETTLE_TILT_LIMIT,
                        threshold=f"root rotation while settling <= {SETTLE_TILT_LIMIT} rad (asset2sim check, not SPEC)",
                        details={"tilt_rad": tilt, "displacement_m": drop}, engine=engine)


def count_sign_changes(q: np.ndarray) -> int:
    """Sign changes of the step-to-step motion of q (N,), exact zeros skipped."""
    d = np.diff(np.asarray(q, float))
    s = np.sign(d)
    s = s[s != 0]
    if len(s) < 2:
        return 0
    return int(np.count_nonzero(s[1:] != s[:-1]))


def oscillation(trace: RestTrace, conventions: SimConventions | None = None, engine: str = "pybullet") -> MetricResult:
    """Joint oscillation during T_test; value = number of failing joints."""
    conv = conventions or SimConventions()
    per_joint = {}
    failing = []
    for name, q in trace.joints.items():
        q = np.asarray(q, float)
        if not np.all(np.isfinite(q)):
            per_joint[name] = {"sign_changes": None, "amplitude": None, "failed": True, "diverged": True}
            failing.append(name)
            continue
        changes = count_sign_changes(q)
        amp = float(np.max(q) - np.min(q)) if len(q) else 0.0
        prismatic = trace.joint_types.get(name) == "prismatic"
        limit = conv.oscillation_amp_prismatic if prismatic else conv.oscillation_amp_revolute
        failed = changes >= conv.oscillation_sign_changes and amp > limit
        per_joint[name] = {"sign_changes": changes, "amplitude": amp, "unit": "m" if prismatic else "rad",
                           "amplitude_limit": limit, "failed": failed}
        if failed:
            failing.append(name)
    return MetricResult(
        name="oscillation", value=float(len(failing)), unit=unit("oscillation"), passed=not failing and not trace.diverged,
        threshold=(f"no joint with >= {conv.oscillation_sign_changes} sign changes and peak-to-peak amplitude > "
                   f"{conv.oscillation_amp_revolute} rad / {conv.oscillation_amp_prismatic} m"),
        details={"joints": per_joint, "failing": failing}, engine=engine)


def joint_drift(trace: RestTrace) -> dict[str, float]:
    """Largest |q(t) - q_initial| over settling and test per joint (rad or m)."""
    out = {}
    for name, q in trace.joints.items():
        q0 = trace.initial_joints.get(name, float(q[0]))
        allq = np.concatenate([trace.settle_joints.get(name, np.empty(0)), q])
        out[name] = float(np.max(np.abs(allq - q0))) if len(allq) else 0.0
    return out
