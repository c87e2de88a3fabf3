"""Evidence of the failing robust-rest trials for the report: per failing trial, a plot of what followed
the disturbance (the tilt of the object's up direction and each joint's drift, against their tolerances)
and frames of the object as disturbed, after settling and at the end of the test, drawn as it lay.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Callable

import numpy as np

from asset2sim.frames import quat_wxyz_matrix, quat_xyzw_to_wxyz
from asset2sim.tasks.check.robust_rest import RobustRestConfig, RobustRestRun, Trial
from asset2sim.tasks.evaluation.svg_chart import Panel, figure_svg
from asset2sim.tasks.geometry.render import SceneRenderer

#: The frames drawn of a failing trial: (caption, where in the trace).
FRAMES = ("as disturbed", "after settling", "end of the test")


def failing_trials(runs: dict) -> list[tuple[str, Trial]]:
    """(engine, trial) of every failing robust-rest trial with a recorded trace, in engine then trial order;
    ``runs``: engine -> the evaluation's engine run (its ``robust_rest``: the run the metric was graded from)."""
    out = []
    for engine, run in runs.items():
        rr = getattr(run, "robust_rest", None)
        if isinstance(rr, RobustRestRun):
            out += [(engine, t) for t in rr.trials if t.passed is False and t.trace is not None]
    return out


def _tilt(q_ref: np.ndarray, quats: np.ndarray) -> np.ndarray:
    """Angle (rad) between world z and the body's up direction (world z at ``q_ref``), per quaternion (N, 4) xyzw."""
    R0 = quat_wxyz_matrix(quat_xyzw_to_wxyz(q_ref))
    ups = np.array([quat_wxyz_matrix(quat_xyzw_to_wxyz(q)) @ (R0.T @ np.array([0.0, 0.0, 1.0])) for q in quats])
    return np.arccos(np.clip(ups[:, 2] / np.maximum(np.linalg.norm(ups, axis=1), 1e-12), -1.0, 1.0))


def trial_plot(trial: Trial, dt: float, config: RobustRestConfig | None = None) -> bytes:
    """SVG of one trial: the tilt (rad) of the up direction at placement, after settling and over the test,
    against the topple tolerance; each joint's position (rad or m) over settling and test, with its
    tolerance band around the initial state. Time 0: the end of settling."""
    cfg = config or RobustRestConfig()
    tr = trial.trace
    q_ref = trial.reference_quat if trial.reference_quat is not None else tr.q0
    a = Panel(title=f"{trial.name}: {trial.failure or 'passed'}", xlabel="time since the end of settling (s)",
              ylabel="tilt of the up direction (rad)")
    n_settle = max((len(v) for v in tr.settle_joints.values()), default=0)
    t_place = -n_settle * dt
    placed = _tilt(q_ref, np.asarray([tr.initial_root_quat]))[0] if tr.initial_root_quat is not None else math.nan
    a.line(np.array([t_place, 0.0]), np.array([placed, _tilt(q_ref, np.asarray([tr.q0]))[0]]), "C7", "settling (placement to rest)")
    a.line(np.asarray(tr.t, float), _tilt(q_ref, np.asarray(tr.root_quat)), "C3", "test")
    a.hline(cfg.topple_tol, "C3", ":", f"topple tolerance {cfg.topple_tol:g} rad")
    rows = [[a]]
    for j, q in tr.joints.items():
        settle = np.asarray(tr.settle_joints.get(j, np.empty(0)), float)
        t = np.concatenate([t_place + dt * np.arange(len(settle)), np.asarray(tr.t, float)[: len(q)]])
        unit = "m" if tr.joint_types.get(j) == "prismatic" else "rad"
        b = Panel(title=f"joint {j}: drift {trial.joint_drift.get(j, math.nan):.3g} {unit}", xlabel="time since the end of settling (s)",
                  ylabel=f"{j} ({unit})")
        b.line(t, np.concatenate([settle, np.asarray(q, float)]), "C0")
        q0 = tr.initial_joints.get(j, float(settle[0]) if len(settle) else float(q[0]))
        tol = trial.joint_tolerance.get(j)
        if tol is not None:
            b.hline(q0 + tol, "C0", ":", f"tolerance +-{tol:g} {unit}")
            b.hline(q0 - tol, "C0", ":")
        b.vline(0.0, "gray", "--", "end of settling")
        rows.append([b])
    return figure_svg(rows[:4], 1000.0, 240.0).encode()


def trial_frames(urdf: Path | str, trial: Trial, size: tuple[int, int] = (200, 200)) -> dict[str, np.ndarray]:
    """The object as disturbed, after settling and at the end of the test (:data:`FRAMES`), turned as it lay
    relative to its rest before the trial, perspective view: caption -> (H, W, 3) uint8.

    Raises:
        as :class:`~asset2sim.tasks.geometry.render.SceneRenderer`.
    """
    tr = trial.trace
    q_ref = trial.reference_quat if trial.reference_quat is not None else tr.q0
    R_ref = quat_wxyz_matrix(quat_xyzw_to_wxyz(q_ref))
    first = {j: float(v[0]) for j, v in tr.settle_joints.items() if len(v)}
    settled = {j: float(v[-1]) for j, v in tr.settle_joints.items() if len(v)}
    last = {j: float(v[-1]) for j, v in tr.joints.items() if len(v)}
    poses = [(tr.initial_root_quat if tr.initial_root_quat is not None else tr.q0, first or tr.initial_joints),
             (tr.q0, settled), (tr.root_quat[-1], last)]
    out = {}
    with SceneRenderer(urdf, size=size) as r:
        for caption, (quat, joints) in zip(FRAMES, poses):
            r.set_joint_positions({k: v for k, v in joints.items() if k in r.joint_names and math.isfinite(v)})
            r.turn_root(quat_wxyz_matrix(quat_xyzw_to_wxyz(quat)) @ R_ref.T)
            out[caption] = r.render("perspective")
    return out


def evidence_section(runs: dict, urdf: Path | str, dt: float, svg: Callable[[bytes, str], str],
                     figure: Callable[[np.ndarray, str], str]) -> str:
    """HTML of every failing robust-rest trial's plot and frames (empty when none failed); ``svg`` and
    ``figure`` make the HTML of a plot and of a captioned image."""
    parts = []
    for engine, trial in failing_trials(runs):
        parts.append(f"<h3>robust rest, trial {trial.name} ({engine}): {trial.failure}</h3>")
        parts.append(svg(trial_plot(trial, dt), f"trial {trial.name}"))
        try:
            frames = trial_frames(urdf, trial)
            parts.append("<div class='views'>" + "".join(figure(img, cap) for cap, img in frames.items()) + "</div>")
        except Exception as exc:  # the plot stands alone
            parts.append(f"<p class='small'>frames not drawn ({type(exc).__name__}: {exc})</p>")
    if not parts:
        return ""
    return "<h2>Why it failed: the failing trials</h2>" + "".join(parts)
