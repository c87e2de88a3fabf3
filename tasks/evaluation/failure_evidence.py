"""Evidence of every failing tier for the report: per failing robust-rest trial, a plot of what followed the
disturbance (the tilt of the object's up direction and each joint's drift, against their tolerances) and frames of
the object as disturbed, after settling and at the end of the test, drawn as it lay; per failing sweep, the opening
over time against the lines that count and frames where it stalled; per failing penetration, the two parts inside
each other drawn in colour at the initial state (and, for a child inside its parent, at its modelled pose); per
failing operability stroke, the part where the hand took it, where the hand stopped and where it needed the most.
"""

from __future__ import annotations

import contextlib
import math
from pathlib import Path
from typing import Callable

import numpy as np

from asset2sim.frames import quat_wxyz_matrix, quat_xyzw_to_wxyz
from asset2sim.tasks.check.robust_rest import RobustRestConfig, RobustRestRun, Trial, up_change
from asset2sim.tasks.check.sweep import JointSweep, SweepConfig, SweepRun
from asset2sim.tasks.check.failure_reasons import penetration_failures
from asset2sim.tasks.evaluation.clips import set_pose
from asset2sim.tasks.evaluation.html_blocks import table
from asset2sim.tasks.evaluation.plots import legend, new_figure, styled, svg_bytes
from asset2sim.tasks.geometry.render import SceneRenderer
from asset2sim.inert import html_text, one_line

#: The frames drawn of a failing trial: (caption, where in the trace).
FRAMES = ("as disturbed", "after settling", "end of the test")
#: Size (width, height) of a frame, pixels.
FRAME_SIZE = (200, 200)
#: A frame: (caption, joint positions rad or m, root rotation (3, 3) from its rest).
Pose = tuple[str, dict[str, float], np.ndarray]


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


@styled
def trial_plot(trial: Trial, dt: float) -> bytes:
    """SVG of one trial: the tilt (rad) of the up direction at placement, after settling and over the test,
    against the topple tolerance; each joint's position (rad or m) over settling and test (the first three), with
    its tolerance band around the initial state. Time 0: the end of settling."""
    cfg = RobustRestConfig()
    tr = trial.trace
    q_ref = trial.reference_quat if trial.reference_quat is not None else tr.q0
    joints = list(tr.joints.items())[:3]
    fig, axes = new_figure(1 + len(joints), 1, 1000.0, 240.0)
    a = axes[0, 0]
    a.set(title=f"{trial.name}: {trial.failure or 'passed'}", xlabel="time since the end of settling (s)",
          ylabel="tilt of the up direction (rad)")
    t_place = -max((len(v) for v in tr.settle_joints.values()), default=0) * dt
    placed = up_change(q_ref, tr.initial_root_quat) if tr.initial_root_quat is not None else math.nan
    a.plot([t_place, 0.0], [placed, up_change(q_ref, tr.q0)], color="C7", label="settling (placement to rest)")
    a.plot(np.asarray(tr.t, float), [up_change(q_ref, q) for q in tr.root_quat], color="C3", label="test")
    a.axhline(cfg.topple_tol, color="C3", ls=":", label=f"topple tolerance {cfg.topple_tol:g} rad")
    legend(a)
    for b, (j, q) in zip(axes[1:, 0], joints):
        settle = np.asarray(tr.settle_joints.get(j, np.empty(0)), float)
        t = np.concatenate([t_place + dt * np.arange(len(settle)), np.asarray(tr.t, float)[: len(q)]])
        unit = "m" if tr.joint_types.get(j) == "prismatic" else "rad"
        b.set(title=f"joint {j}: drift {trial.joint_drift.get(j, math.nan):.3g} {unit}", xlabel="time since the end of settling (s)",
              ylabel=f"{j} ({unit})")
        b.plot(t, np.concatenate([settle, np.asarray(q, float)]), color="C0")
        q0 = tr.initial_joints.get(j, float(settle[0]) if len(settle) else float(q[0]))
        tol = trial.joint_tolerance.get(j)
        if tol is not None:
            b.axhline(q0 + tol, color="C0", ls=":", label=f"tolerance +-{tol:g} {unit}")
            b.axhline(q0 - tol, color="C0", ls=":")
        b.axvline(0.0, color="gray", ls="--", label="end of settling")
        legend(b)
    return svg_bytes(fig)


def trial_poses(trial: Trial) -> list[Pose]:
    """The object as disturbed, after settling and at the end of the test (:data:`FRAMES`), turned as it lay
    relative to its rest before the trial."""
    tr = trial.trace
    q_ref = trial.reference_quat if trial.reference_quat is not None else tr.q0
    R_ref = quat_wxyz_matrix(quat_xyzw_to_wxyz(q_ref))
    first = {j: float(v[0]) for j, v in tr.settle_joints.items() if len(v)}
    settled = {j: float(v[-1]) for j, v in tr.settle_joints.items() if len(v)}
    last = {j: float(v[-1]) for j, v in tr.joints.items() if len(v)}
    poses = [(tr.initial_root_quat if tr.initial_root_quat is not None else tr.q0, first or tr.initial_joints),
             (tr.q0, settled), (tr.root_quat[-1], last)]
    return [(caption, joints, quat_wxyz_matrix(quat_xyzw_to_wxyz(quat)) @ R_ref.T) for caption, (quat, joints) in zip(FRAMES, poses)]


@styled
def sweep_plot(js: JointSweep) -> bytes:
    """SVG of one joint sweep: the opening fraction over time, opening then closing, against the fractions
    that count as reached (the sweep's ``reach_fraction`` open, 1 - it closed)."""
    cfg = SweepConfig()
    t, f, ph = (np.asarray(js.trace[k], float) for k in ("t", "fraction", "phase"))
    fig, ((a,),) = new_figure(1, 1, 1000.0, 260.0)
    a.set(title=f"sweep of {js.joint}: {js.failure}", xlabel="time since the sweep started (s)",
          ylabel="opening fraction (0 closed, 1 fully open)")
    a.plot(t, f, color="C0", label=js.joint)
    a.axhline(cfg.reach_fraction, color="C2", ls="--", label=f"counts as open ({cfg.reach_fraction:.0%})")
    a.axhline(1.0 - cfg.reach_fraction, color="C1", ls="--", label=f"counts as closed ({1.0 - cfg.reach_fraction:.0%})")
    if np.any(ph > 0):
        a.axvline(float(t[int(np.argmax(ph > 0))]), color="gray", ls="--", label="closing starts")
    legend(a)
    return svg_bytes(fig)


def sweep_poses(js: JointSweep, others: dict[str, float]) -> list[Pose]:
    """The object (root fixed, the other joints at ``others``, rad or m) with the swept joint closed, where
    the opening stalled and where the closing stalled."""
    def at(fraction: float) -> float:
        return js.q_closed + (js.q_far - js.q_closed) * float(fraction)

    shown = {"closed (start)": js.q_closed, f"opened as far as it went ({js.reached_open:.0%})": at(js.reached_open)}
    if np.isfinite(js.reached_closed):
        shown[f"closed as far as it went ({js.reached_closed:.0%} open)"] = at(js.reached_closed)
    return [(caption, {**others, js.joint: q}, np.eye(3)) for caption, q in shown.items() if math.isfinite(q)]


def task_poses(attempt: dict, closed: dict, others: dict[str, float]) -> list[Pose]:
    """The part of a failed task attempt (``attempt``: a ``task_execution`` attempt summary) where the
    gripper took it, where it asked it to go and where it was left, the other joints at ``others`` and the
    root as at rest (its slide and tilt are in the table); ``closed``: joint -> {q_closed, direction,
    open_range} (rad or m)."""
    c = closed[attempt["joint"]]
    return [(f"{what} ({100 * attempt[key]:.0f} % open)", {**others, attempt["joint"]: _opened(c, attempt[key])}, np.eye(3))
            for what, key in (("taken at", "start_fraction"), ("asked for", "target_fraction"), ("left at", "final_fraction"))
            if attempt.get(key) is not None and math.isfinite(attempt[key])]


#: Colours of the two parts of a failing penetration (the first link, the second), and of every other link.
PAIR_COLORS = ((0.85, 0.15, 0.1, 1.0), (0.15, 0.35, 0.9, 1.0))
OTHER_COLOR = (0.86, 0.86, 0.86, 1.0)


def operability_failures(metrics: list) -> list[tuple[str, dict, dict]]:
    """(engine, part summary, stroke) of every failing operability stroke (``operability`` details: the part and
    the stroke as :func:`~asset2sim.tasks.check.operability.operability_metric` records them)."""
    return [(m.engine, part, s) for m in metrics if m.name == "operability" and m.passed is False
            for part in (m.details.get("parts") or {}).values()
            for s in part.get("strokes") or [] if not s.get("passed", True)]


def operability_poses(part: dict, stroke: dict, closed: dict, others: dict[str, float]) -> list[Pose]:
    """The part of a failing stroke where the hand took it (closed for an opening stroke, open for a closing
    one), where the hand stopped and where the stroke needed the most effort, the other joints at ``others``
    (rad or m) and the root fixed as the tier holds it; ``closed``: joint -> {q_closed, direction, open_range}."""
    c = closed.get(part["joint"])
    if not c or not c.get("open_range"):
        return []
    opening = stroke.get("action") == "open"
    shown = {f"the hand took it ({'closed' if opening else 'open'})": 0.0 if opening else 1.0,
             f"the hand stopped ({100 * float(stroke.get('reached') or 0.0):.0f} % open)": stroke.get("reached")}
    if stroke.get("at_fraction") is not None:
        shown[f"it needed the most here ({100 * float(stroke['at_fraction']):.0f} % open)"] = stroke["at_fraction"]
    return [(caption, {**others, part["joint"]: _opened(c, f)}, np.eye(3))
            for caption, f in shown.items() if f is not None and math.isfinite(float(f))]


def _opened(closed: dict, fraction: float) -> float:
    """The joint position (rad or m) at opening ``fraction`` of its ``closed`` end ({q_closed, direction, open_range})."""
    return closed["q_closed"] + closed["direction"] * float(fraction) * closed["open_range"]


def draw_poses(renderer: SceneRenderer, poses: list[Pose], highlight: tuple[str, str] | None = None) -> dict[str, np.ndarray]:
    """caption -> (H, W, 3) uint8 perspective render of each pose (every joint a pose names set, the root
    turned by its rotation); with ``highlight`` (two links of a penetration), those links in :data:`PAIR_COLORS` and
    the others grey, each drawn from the perspective and the front view (``caption, view``), the asset's own colours
    back afterwards."""
    out = {}
    views = ("perspective", "front") if highlight is not None else ("perspective",)
    if highlight is not None:
        renderer.color_links(dict(zip(highlight, PAIR_COLORS)), OTHER_COLOR)
    try:
        for caption, joints, rotation in poses:
            set_pose(renderer, joints, None, None)
            renderer.turn_root(rotation)
            for view in views:
                out[caption if len(views) == 1 else f"{caption}, {view}"] = renderer.render(view)
    finally:
        if highlight is not None:
            renderer.color_links(None)
    return out


def _h3(text: str) -> str:
    """A heading of the evidence: ``text`` (names and failure text from the run) escaped."""
    return f"<h3>{html_text(text)}</h3>"


def _one_row(cells: list[tuple[str, object]]) -> str:
    """A table of one row: (header, value) ``cells``, a float to 3 digits, a truth as yes / no, None as ``-``."""
    def text(v: object) -> object:
        return "-" if v is None else ("yes" if v else "no") if isinstance(v, bool) else f"{v:.3g}" if isinstance(v, float) else v
    return table((k for k, _ in cells), ["<tr>", *(f"<td>{html_text(text(v))}</td>" for _, v in cells), "</tr>"])


def evidence_section(runs: dict, urdf: Path | str, dt: float, svg: Callable[[bytes, str], str],
                     figure: Callable[[np.ndarray, str], str], initial_state: dict[str, float] | None = None,
                     task: dict | None = None, closed: dict | None = None, metrics: list | None = None,
                     modelled_state: dict[str, float] | None = None) -> str:
    """HTML of the evidence of every failing tier (empty when none failed), the frames drawn by one renderer of
    ``urdf``: each failing penetration's two parts in colour (at the initial state and, for a child inside its
    parent, at ``modelled_state``, every joint at 0 clipped to its limits), each failing operability stroke's
    numbers and frames (where the hand took the part, where it stopped, where it needed the most), each failed task
    attempt's numbers and frames, each failing joint sweep's and robust-rest trial's plot and frames. ``svg`` and
    ``figure`` make the HTML of a plot and of a captioned image; ``initial_state``: the joints' positions (rad or
    m); ``task``: the ``task_execution`` metric's details; ``closed``: joint -> {q_closed, direction, open_range};
    ``metrics``: the evaluation's metrics (the penetration and operability measures)."""
    others, closed = dict(initial_state or {}), dict(closed or {})
    items: list[tuple[str, Callable[[], list[Pose]], tuple[str, str] | None]] = []  # (the HTML before the frames, poses, colours)
    for f in penetration_failures(metrics or []):
        if f.link_a is None:  # a measure that names no pair: nothing to draw
            continue
        a, b, nested = f.link_a, f.link_b, f.kind == "parent-child"
        what = f"'{b}' inside its parent '{a}'" if nested else f"'{a}' and '{b}'"
        poses: list[Pose] = [("at the initial state", others, np.eye(3))]
        if nested:
            poses.append(("as modelled", dict(modelled_state or {}), np.eye(3)))
        items.append((_h3(f"penetration ({f.kind}, {f.metric.engine}): {what}, {f.depth_mm:.1f} mm deep at the initial state")
                      + f"<p class='small'>{html_text(a)} in red, {html_text(b)} in blue, every other part grey.</p>",
                      lambda poses=poses: poses, (a, b)))
    for engine, part, stroke in operability_failures(metrics or []):
        items.append((_h3(f"operability of {part['joint']} ({part.get('label') or 'unlabelled'}, {engine}): "
                          f"{stroke['action']}: {stroke.get('failure', '')}")
                      + _one_row([("stroke", stroke.get("action")),
                                  ("asked to", f"{100 * float(stroke.get('target') or 0):.0f} % open"),
                                  ("reached", f"{100 * float(stroke.get('reached') or 0):.0f} % open"),
                                  ("force it needed (N)", stroke.get("needed_force_n")),
                                  ("the hand's range (N)", (part.get("force_range_n") or [None, None])[1]),
                                  ("torque it needed (N m)", stroke.get("needed_torque_nm")),
                                  ("stopped by", stroke.get("stopped_by") or "-")]),
                      lambda p=part, s=stroke: operability_poses(p, s, closed, others), None))
    for attempt in [a for a in (task or {}).get("attempts", []) if not a.get("success")]:
        items.append((_h3(f"task: {attempt['action']} {attempt['joint']}: {attempt.get('failure', '')}")
                      + _one_row([("reached the target", attempt.get("reached")), ("held after release", attempt.get("held")),
                                  ("peak gripper force (N)", attempt.get("peak_force_n")),
                                  ("object slid (mm)", 1000 * (attempt.get("root_slide_m") or 0.0)),
                                  ("object tilted (rad)", attempt.get("root_tilt_rad")),
                                  ("gripper at its force limit", attempt.get("force_limited"))]),
                      lambda a=attempt: task_poses(a, closed, others), None))
    sweeps, trials = failing(runs)
    for engine, js in sweeps:
        items.append((_h3(f"joint sweep of {js.joint} ({engine}): {js.failure}") + svg(sweep_plot(js), f"sweep {js.joint}"),
                      lambda js=js: sweep_poses(js, others), None))
    for engine, trial in trials:
        items.append((_h3(f"robust rest, trial {trial.name} ({engine}): {trial.failure}") + svg(trial_plot(trial, dt), f"trial {trial.name}"),
                      lambda trial=trial: trial_poses(trial), None))
    if not items:
        return ""
    parts = ["<h2>Why it failed: the evidence</h2>"]
    with contextlib.ExitStack() as stack:
        try:
            renderer, error = stack.enter_context(SceneRenderer(urdf, size=FRAME_SIZE)), None
        except Exception as exc:  # the plots and numbers stand alone
            renderer, error = None, exc
        for head, poses, highlight in items:
            parts.append(head)
            try:
                if renderer is None:
                    raise error
                drawn = draw_poses(renderer, poses(), highlight)
                parts.append("<div class='views'>" + "".join(figure(img, cap) for cap, img in drawn.items()) + "</div>")
            except Exception as exc:
                parts.append(f"<p class='small'>frames not drawn ({type(exc).__name__}: {html_text(one_line(exc))})</p>")
    return "".join(parts)
