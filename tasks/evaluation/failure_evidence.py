"""Evidence of the failing robust-rest trials and joint sweeps for the report: per failing trial, a plot of
what followed the disturbance (the tilt of the object's up direction and each joint's drift, against their
tolerances) and frames of the object as disturbed, after settling and at the end of the test, drawn as it
lay; per failing sweep, the opening over time against the lines that count and frames where it stalled.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Callable

import numpy as np

from asset2sim.frames import quat_wxyz_matrix, quat_xyzw_to_wxyz
from asset2sim.tasks.check.robust_rest import RobustRestConfig, RobustRestRun, Trial
from asset2sim.tasks.check.sweep import JointSweep, SweepConfig, SweepRun
from asset2sim.tasks.evaluation.svg_chart import Panel, figure_svg
from asset2sim.tasks.geometry.render import SceneRenderer

#: The frames drawn of a failing trial: (caption, where in the trace).
FRAMES = ("as disturbed", "after settling", "end of the test")


def failing(runs: dict) -> tuple[list[tuple[str, JointSweep]], list[tuple[str, Trial]]]:
    """(engine, joint sweep) and (engine, trial) of every failing joint sweep and robust-rest trial with a
    recorded trace, in engine order; ``runs``: engine -> the evaluation's engine run (its ``sweep`` and
    ``robust_rest``: the runs the metrics were graded from)."""
    sweeps, trials = [], []
    for engine, run in runs.items():
        sw, rr = getattr(run, "sweep", None), getattr(run, "robust_rest", None)
        sweeps += [(engine, j) for j in sw.joints if not j.passed and j.trace.get("t")] if isinstance(sw, SweepRun) else []
        trials += [(engine, t) for t in rr.trials if t.passed is False and t.trace is not None] if isinstance(rr, RobustRestRun) else []
    return sweeps, trials


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


def sweep_plot(js: JointSweep, config: SweepConfig | None = None) -> bytes:
    """SVG of one joint sweep: the opening fraction over time, opening then closing, against the fractions
    that count as reached (``config.reach_fraction`` open, 1 - it closed)."""
    cfg = config or SweepConfig()
    t, f, ph = (np.asarray(js.trace[k], float) for k in ("t", "fraction", "phase"))
    a = Panel(title=f"sweep of {js.joint}: {js.failure}", xlabel="time since the sweep started (s)",
              ylabel="opening fraction (0 closed, 1 fully open)")
    a.line(t, f, "C0", js.joint)
    a.hline(cfg.reach_fraction, "C2", "--", f"counts as open ({cfg.reach_fraction:.0%})")
    a.hline(1.0 - cfg.reach_fraction, "C1", "--", f"counts as closed ({1.0 - cfg.reach_fraction:.0%})")
    if np.any(ph > 0):
        a.vline(float(t[int(np.argmax(ph > 0))]), "gray", "--", "closing starts")
    return figure_svg([[a]], 1000.0, 260.0).encode()


def sweep_frames(urdf: Path | str, js: JointSweep, others: dict[str, float],
                 size: tuple[int, int] = (200, 200)) -> dict[str, np.ndarray]:
    """The object (root fixed, the other joints at ``others``, rad or m) with the swept joint closed, where
    the opening stalled and where the closing stalled: caption -> (H, W, 3) uint8, perspective view."""
    def at(fraction: float) -> float:
        return js.q_closed + (js.q_far - js.q_closed) * float(fraction)

    shown = {"closed (start)": js.q_closed, f"opened as far as it went ({js.reached_open:.0%})": at(js.reached_open)}
    if np.isfinite(js.reached_closed):
        shown[f"closed as far as it went ({js.reached_closed:.0%} open)"] = at(js.reached_closed)
    out = {}
    with SceneRenderer(urdf, size=size) as r:
        base = {k: v for k, v in others.items() if k in r.joint_names and math.isfinite(v)}
        for caption, q in shown.items():
            if math.isfinite(q):
                r.set_joint_positions({**base, js.joint: q})
                out[caption] = r.render("perspective")
    return out


def task_frames(urdf: Path | str, attempt: dict, closed: dict, others: dict[str, float],
                size: tuple[int, int] = (200, 200)) -> dict[str, np.ndarray]:
    """The part of a failed task attempt (``attempt``: a ``task_execution`` attempt summary) where the
    gripper took it, where it asked it to go and where it was left, the other joints at ``others`` and the
    root as at rest (its slide and tilt are in the table): caption -> (H, W, 3) uint8, perspective view.
    ``closed``: joint -> {q_closed, direction, open_range} (rad or m)."""
    c = closed[attempt["joint"]]

    def at(f: float) -> float:
        return c["q_closed"] + c["direction"] * float(f) * c["open_range"]

    shown = {f"{what} ({100 * attempt[key]:.0f} % open)": at(attempt[key])
             for what, key in (("taken at", "start_fraction"), ("asked for", "target_fraction"), ("left at", "final_fraction"))
             if attempt.get(key) is not None and math.isfinite(attempt[key])}
    out = {}
    with SceneRenderer(urdf, size=size) as r:
        base = {k: v for k, v in others.items() if k in r.joint_names and math.isfinite(v)}
        for caption, q in shown.items():
            r.set_joint_positions({**base, attempt["joint"]: q})
            out[caption] = r.render("perspective")
    return out


def _task_table(attempt: dict) -> str:
    cells = [("reached the target", attempt.get("reached")), ("held after release", attempt.get("held")),
             ("peak gripper force (N)", attempt.get("peak_force_n")), ("object slid (mm)", 1000 * (attempt.get("root_slide_m") or 0.0)),
             ("object tilted (rad)", attempt.get("root_tilt_rad")), ("gripper at its force limit", attempt.get("force_limited"))]
    return ("<table><tr>" + "".join(f"<th>{k}</th>" for k, _ in cells) + "</tr><tr>"
            + "".join(f"<td>{('yes' if v else 'no') if isinstance(v, bool) else f'{v:.3g}' if isinstance(v, float) else v}</td>" for _, v in cells)
            + "</tr></table>")


def _frames(draw: Callable[[], dict[str, np.ndarray]], figure: Callable[[np.ndarray, str], str]) -> str:
    """The frames ``draw`` renders as captioned images, or a note when they cannot be drawn (the plot or
    numbers beside them stand alone)."""
    try:
        return "<div class='views'>" + "".join(figure(img, cap) for cap, img in draw().items()) + "</div>"
    except Exception as exc:
        return f"<p class='small'>frames not drawn ({type(exc).__name__}: {exc})</p>"


def evidence_section(runs: dict, urdf: Path | str, dt: float, svg: Callable[[bytes, str], str],
                     figure: Callable[[np.ndarray, str], str], initial_state: dict[str, float] | None = None,
                     task: dict | None = None, closed: dict | None = None) -> str:
    """HTML of every failing robust-rest trial's and joint sweep's plot and frames, and of every failed task
    attempt's numbers and frames (empty when none failed); ``svg`` and ``figure`` make the HTML of a plot and
    of a captioned image; ``initial_state``: the other joints' positions (rad or m); ``task``: the
    ``task_execution`` metric's details; ``closed``: joint -> {q_closed, direction, open_range}."""
    parts = []
    for attempt in [a for a in (task or {}).get("attempts", []) if not a.get("success")]:
        parts.append(f"<h3>task: {attempt['action']} {attempt['joint']}: {attempt.get('failure', '')}</h3>" + _task_table(attempt))
        parts.append(_frames(lambda: task_frames(urdf, attempt, dict(closed or {}), dict(initial_state or {})), figure))
    sweeps, trials = failing(runs)
    for engine, js in sweeps:
        parts.append(f"<h3>joint sweep of {js.joint} ({engine}): {js.failure}</h3>")
        parts.append(svg(sweep_plot(js), f"sweep {js.joint}"))
        parts.append(_frames(lambda: sweep_frames(urdf, js, dict(initial_state or {})), figure))
    for engine, trial in trials:
        parts.append(f"<h3>robust rest, trial {trial.name} ({engine}): {trial.failure}</h3>")
        parts.append(svg(trial_plot(trial, dt), f"trial {trial.name}"))
        parts.append(_frames(lambda: trial_frames(urdf, trial), figure))
    if not parts:
        return ""
    return "<h2>Why it failed: the failing trials</h2>" + "".join(parts)
