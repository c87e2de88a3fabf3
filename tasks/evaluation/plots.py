"""Figures for the evaluation report and the benchmark pages, drawn by
:mod:`asset2sim.tasks.evaluation.svg_chart`: each returns an SVG document as
UTF-8 bytes, or None when there is nothing to draw. Time in s since the start
of settling unless stated.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from asset2sim.frames import quat_angle
from asset2sim.tasks.check.probes import reached_fraction
from asset2sim.tasks.evaluation.svg_chart import Panel, figure_svg

SVG_MIME = "image/svg+xml"  # the media type of every figure here (``data:`` URIs)


def _svg(rows: list[list[Panel]], width: float, row_height: float, title: str = "") -> bytes:
    return figure_svg(rows, width=width, row_height=row_height, title=title).encode("utf-8")


def plot_object(point_cloud: dict[str, np.ndarray], title: str = "") -> bytes | None:
    """Front (x-z), side (y-z) and top (x-y) views of the collision vertices per
    link (``point_cloud``: link -> (N, 3) m, world, initial state); None without points."""
    pts = {k: np.asarray(v, float) for k, v in point_cloud.items() if len(v)}
    if not pts:
        return None
    views = [(0, 2, "front: x (m)", "z (m)"), (1, 2, "side: y (m)", "z (m)"), (0, 1, "top: x (m)", "y (m)")]
    panels = []
    for n, (i, j, xl, yl) in enumerate(views):
        p = Panel(xlabel=xl, ylabel=yl, equal_aspect=True, legend="upper right" if n == 0 else None)
        for k, (name, v) in enumerate(sorted(pts.items())):
            p.scatter(v[:, i], v[:, j], k, label=name)
        if n < 2:
            p.hline(0.0, "k", "-")
        panels.append(p)
    return _svg([panels], 1100, 360, title or "collision geometry at the initial state (ground z = 0)")


def plot_root_drift(root_series: np.ndarray, trace, dt: float, settle_steps: int) -> bytes:
    """Root displacement |p(t) - p(0)| (mm) over settle + test (``root_series``
    (K, 3) m), and the test's |p - p0| (mm) and rotation (rad) from the ``trace``
    (:class:`asset2sim.tasks.check.metrics.RestTrace`); ``dt`` s, ``settle_steps`` in T_set."""
    a = Panel(title="root drift, settle + test", xlabel="time (s)", ylabel="root displacement from start (mm)")
    root_series = np.asarray(root_series, float)
    if len(root_series):
        t = np.arange(1, len(root_series) + 1) * dt
        a.line(t, np.linalg.norm(root_series - root_series[0], axis=1) * 1000.0, "C0")
        a.vline(settle_steps * dt, "gray", "--", "end of settling")
    b = Panel(title="rest test (T_test)", xlabel="time since end of settling (s)", ylabel="mm", ylabel_right="rad",
              legend="upper left")
    dp = np.linalg.norm(np.asarray(trace.root_pos) - np.asarray(trace.p0), axis=1) * 1000.0
    ang = np.array([quat_angle(trace.q0, q) for q in trace.root_quat])
    b.line(trace.t, dp, "C0", "D_pos(t) (mm)")
    b.hline(1.0, "C0", ":", "1 mm threshold")
    b.line(trace.t, ang, "C3", "D_ori(t) (rad)", right=True)
    b.hline(0.01, "C3", ":", "0.01 rad threshold", right=True)
    return _svg([[a, b]], 1100, 320)


def plot_joints(joint_series: dict[str, np.ndarray], joint_types: dict[str, str], dt: float, settle_steps: int,
                closed: dict[str, float] | None = None) -> bytes | None:
    """Each movable joint's position over settle + test (rad or m). None without joints."""
    if not joint_series:
        return None
    rows = []
    for k, name in enumerate(joint_series):
        q = np.asarray(joint_series[name], float)
        unit = "m" if joint_types.get(name) == "prismatic" else "rad"
        p = Panel(ylabel=f"{name} ({unit})", xlabel="time (s); dashed line: end of settling" if k == len(joint_series) - 1 else "")
        p.line(np.arange(1, len(q) + 1) * dt, q, "C0")
        p.vline(settle_steps * dt, "gray", "--")
        if closed and name in closed:
            p.hline(closed[name], "k", ":", "closed end")
        rows.append([p])
    return _svg(rows, 1100, 190, "joint trajectories during the rest test")


def plot_probes(probes: list[Any]) -> bytes | None:
    """Per probe: joint position (rad or m) and pusher force (N) over time, with the target and the release moment; root
    displacement (mm). None without probes."""
    if not probes:
        return None
    rows = []
    for pr in probes:
        tr = pr.trace
        t, q, f = (np.asarray(tr.get(k, []), float) for k in ("t", "q", "force"))
        ph = np.asarray(tr.get("phase", []))
        unit = "m" if pr.joint_type == "prismatic" else "rad"
        verdict = "ok" if pr.success else pr.failure
        a = Panel(title=f"{pr.action} {pr.joint}: {verdict}", xlabel="time since the push started (s)", ylabel=unit,
                  ylabel_right="N")
        a.line(t, q, "C0", f"{pr.joint} ({unit})")
        a.hline(pr.target, "C0", ":", "target")
        if pr.target_fraction != pr.start_fraction:  # the position where the probe counts the target reached
            at = reached_fraction(pr.action, pr.target_fraction)
            a.hline(pr.start + (at - pr.start_fraction) * (pr.target - pr.start) / (pr.target_fraction - pr.start_fraction),
                    "C2", "--", "counts as reached")
        if len(ph) and np.any(ph > 0):
            a.vline(t[int(np.argmax(ph > 0))], "gray", "--", "release")
        a.line(t, f, "C1", "force (N)", width=1.0, right=True)
        b = Panel(title="object motion during the probe (slide threshold 5 mm)", xlabel="time since the push started (s)",
                  ylabel="root displacement (mm)")
        b.line(t, np.asarray(tr.get("root_disp", []), float) * 1000.0, "C2")
        b.hline(5.0, "C2", ":")
        rows.append([a, b])
    return _svg(rows, 1200, 260)


def plot_method_summary(summary: dict[str, dict[str, Any]]) -> bytes | None:
    """Bar chart of pass rates (%) per method: rest stability, oscillation,
    probes, all checks. ``summary``: method -> row of the benchmark table."""
    if not summary:
        return None
    keys = [("rest_stability_pass", "rest stability"), ("oscillation_pass", "oscillation"),
            ("probes_pass", "probes"), ("all_pass", "all checks")]
    p = Panel(ylabel="pass rate (%)", legend="upper right", ylim=(0.0, 105.0))
    p.bars([lab for _, lab in keys], [(m, [100.0 * (summary[m].get(k) or 0.0) for k, _ in keys]) for m in summary])
    return _svg([[p]], 900, 320)
