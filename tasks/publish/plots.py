"""Matplotlib figures for the evaluation report, returned as PNG bytes.

Every function imports matplotlib inside (Agg backend, no display) so the
package imports without it. Units on every axis; time in s since the start of
settling unless stated.
"""

from __future__ import annotations

import io
from typing import Any

import numpy as np

from asset2sim.frames import quat_angle


def _plt():
    import matplotlib

    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt

    return plt


def fig_to_png(fig, dpi: int = 90) -> bytes:
    """Render a figure to PNG bytes and close it."""
    plt = _plt()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi, bbox_inches="tight")
    plt.close(fig)
    return buf.getvalue()


def plot_object(point_cloud: dict[str, np.ndarray], title: str = "") -> bytes | None:
    """Front (x-z), side (y-z) and top (x-y) views of the collision vertices
    per link, m, world frame at the initial state. None without points.

    Args:
        point_cloud: link -> (N, 3) m.
    """
    pts = {k: np.asarray(v, float) for k, v in point_cloud.items() if len(v)}
    if not pts:
        return None
    plt = _plt()
    fig, axes = plt.subplots(1, 3, figsize=(11, 3.8))
    views = [(0, 2, "front: x (m)", "z (m)"), (1, 2, "side: y (m)", "z (m)"), (0, 1, "top: x (m)", "y (m)")]
    cmap = plt.get_cmap("tab10")
    for ax, (i, j, xl, yl) in zip(axes, views):
        for k, (name, v) in enumerate(sorted(pts.items())):
            ax.scatter(v[:, i], v[:, j], s=1.5, color=cmap(k % 10), label=name if ax is axes[0] else None)
        ax.set_xlabel(xl)
        ax.set_ylabel(yl)
        ax.set_aspect("equal", adjustable="datalim")
        ax.grid(alpha=0.3)
    axes[0].axhline(0.0, color="k", lw=0.8)
    axes[1].axhline(0.0, color="k", lw=0.8)
    fig.legend(loc="upper right", markerscale=5, fontsize=8)
    fig.suptitle(title or "collision geometry at the initial state (ground z = 0)")
    return fig_to_png(fig)


def plot_root_drift(root_series: np.ndarray, trace, dt: float, settle_steps: int) -> bytes:
    """Root displacement |p(t) - p(0)| (mm) over settle + test, and during the
    test the SPEC's |p - p0| (mm) and rotation angle (rad) from the pose at
    the end of settling.

    Args:
        root_series: (K, 3) m per step.
        trace: :class:`asset2sim.tasks.check.metrics.RestTrace`.
        dt: timestep s; settle_steps: steps in T_set.
    """
    plt = _plt()
    fig, axes = plt.subplots(1, 2, figsize=(11, 3.4))
    if len(root_series):
        t = np.arange(1, len(root_series) + 1) * dt
        d = np.linalg.norm(root_series - root_series[0], axis=1) * 1000.0
        axes[0].plot(t, d, lw=1.2)
        axes[0].axvline(settle_steps * dt, color="gray", ls="--", lw=0.8, label="end of settling")
        axes[0].legend(fontsize=8)
    axes[0].set_xlabel("time (s)")
    axes[0].set_ylabel("root displacement from start (mm)")
    axes[0].set_title("root drift, settle + test")
    axes[0].grid(alpha=0.3)
    ax = axes[1]
    dp = np.linalg.norm(trace.root_pos - trace.p0, axis=1) * 1000.0
    ang = np.array([quat_angle(trace.q0, q) for q in trace.root_quat])
    ax.plot(trace.t, dp, label="D_pos(t) (mm)", color="C0")
    ax.axhline(1.0, color="C0", ls=":", lw=0.8, label="1 mm threshold")
    ax.set_xlabel("time since end of settling (s)")
    ax.set_ylabel("mm")
    ax2 = ax.twinx()
    ax2.plot(trace.t, ang, label="D_ori(t) (rad)", color="C3")
    ax2.axhline(0.01, color="C3", ls=":", lw=0.8, label="0.01 rad threshold")
    ax2.set_ylabel("rad")
    h1, l1 = ax.get_legend_handles_labels()
    h2, l2 = ax2.get_legend_handles_labels()
    ax.legend(h1 + h2, l1 + l2, fontsize=7, loc="upper left")
    ax.set_title("rest test (T_test)")
    ax.grid(alpha=0.3)
    return fig_to_png(fig)


def plot_joints(joint_series: dict[str, np.ndarray], joint_types: dict[str, str], dt: float, settle_steps: int,
                closed: dict[str, float] | None = None) -> bytes | None:
    """Each movable joint's position over settle + test (rad or m). None
    without joints."""
    if not joint_series:
        return None
    plt = _plt()
    n = len(joint_series)
    fig, axes = plt.subplots(n, 1, figsize=(11, 1.9 * n + 0.6), squeeze=False)
    for ax, (name, q) in zip(axes[:, 0], joint_series.items()):
        t = np.arange(1, len(q) + 1) * dt
        unit = "m" if joint_types.get(name) == "prismatic" else "rad"
        ax.plot(t, q, lw=1.2)
        ax.axvline(settle_steps * dt, color="gray", ls="--", lw=0.8)
        if closed and name in closed:
            ax.axhline(closed[name], color="k", ls=":", lw=0.8, label="closed end")
            ax.legend(fontsize=7, loc="upper right")
        ax.set_ylabel(f"{name} ({unit})")
        ax.grid(alpha=0.3)
    axes[-1, 0].set_xlabel("time (s); dashed line: end of settling")
    fig.suptitle("joint trajectories during the rest test")
    return fig_to_png(fig)


def plot_probes(probes: list[Any]) -> bytes | None:
    """Per probe: joint position (rad or m) and pusher force (N) over time, with
    the target and the release moment; root displacement (mm). None without
    probes."""
    if not probes:
        return None
    plt = _plt()
    n = len(probes)
    fig, axes = plt.subplots(n, 2, figsize=(12, 2.6 * n + 0.6), squeeze=False)
    for row, pr in zip(axes, probes):
        tr = pr.trace
        t = np.asarray(tr.get("t", []))
        q = np.asarray(tr.get("q", []))
        f = np.asarray(tr.get("force", []))
        ph = np.asarray(tr.get("phase", []))
        unit = "m" if pr.joint_type == "prismatic" else "rad"
        ax = row[0]
        ax.plot(t, q, color="C0", label=f"{pr.joint} ({unit})")
        ax.axhline(pr.target, color="C0", ls=":", lw=0.8, label="target")
        if len(ph) and np.any(ph > 0):
            ax.axvline(t[np.argmax(ph > 0)], color="gray", ls="--", lw=0.8, label="release")
        ax.set_ylabel(unit)
        ax2 = ax.twinx()
        ax2.plot(t, f, color="C1", lw=1.0, label="force (N)")
        ax2.set_ylabel("N")
        h1, l1 = ax.get_legend_handles_labels()
        h2, l2 = ax2.get_legend_handles_labels()
        ax.legend(h1 + h2, l1 + l2, fontsize=7, loc="upper right")
        verdict = "ok" if pr.success else pr.failure
        ax.set_title(f"{pr.action} {pr.joint}: {verdict}", fontsize=9)
        ax.grid(alpha=0.3)
        ax = row[1]
        ax.plot(t, np.asarray(tr.get("root_disp", [])) * 1000.0, color="C2")
        ax.axhline(5.0, color="C2", ls=":", lw=0.8)
        ax.set_ylabel("root displacement (mm)")
        ax.set_title("object motion during the probe (slide threshold 5 mm)", fontsize=9)
        ax.grid(alpha=0.3)
    axes[-1, 0].set_xlabel("time since the push started (s)")
    axes[-1, 1].set_xlabel("time since the push started (s)")
    fig.subplots_adjust(hspace=0.55, wspace=0.45)
    return fig_to_png(fig)


def plot_method_summary(summary: dict[str, dict[str, Any]]) -> bytes | None:
    """Bar chart of pass rates (%) per method: rest stability, oscillation,
    probes, all checks. ``summary``: method -> row of the benchmark table."""
    if not summary:
        return None
    plt = _plt()
    keys = [("rest_stability_pass", "rest stability"), ("oscillation_pass", "oscillation"),
            ("probes_pass", "probes"), ("all_pass", "all checks")]
    methods = list(summary)
    fig, ax = plt.subplots(figsize=(9, 3.2))
    w = 0.8 / max(len(methods), 1)
    x = np.arange(len(keys))
    for i, m in enumerate(methods):
        vals = [100.0 * (summary[m].get(k) or 0.0) for k, _ in keys]
        ax.bar(x + i * w, vals, w, label=m)
    ax.set_xticks(x + w * (len(methods) - 1) / 2)
    ax.set_xticklabels([lab for _, lab in keys])
    ax.set_ylabel("pass rate (%)")
    ax.set_ylim(0, 105)
    ax.legend(fontsize=8)
    ax.grid(axis="y", alpha=0.3)
    return fig_to_png(fig)
