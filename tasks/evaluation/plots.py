"""Figures for the evaluation report and the benchmark pages, drawn with matplotlib (its SVG backend, no
display): each returns a standalone SVG document as UTF-8 bytes, or None when there is nothing to draw. Time in
s since the start of settling unless stated. :func:`styled`, :func:`new_figure` and :func:`svg_bytes` are the
helpers the report's other figures (:mod:`asset2sim.tasks.evaluation.failure_evidence`) share.
"""

from __future__ import annotations

import functools
import io
import threading
from typing import Any

import numpy as np

from asset2sim.frames import quat_angle
from asset2sim.tasks.check.probes import reached_fraction
from asset2sim import library_dirs

SVG_MIME = "image/svg+xml"  # the media type of every figure here (``data:`` URIs)
#: Pixels per inch of the figures (their sizes are given in px).
DPI = 100.0
#: Most points drawn per scatter series (:func:`thinned`); the points are drawn as an image inside the SVG.
MAX_SCATTER = 1500
#: matplotlib settings while drawing and saving: compact fonts, text kept as text, ids salted with a fixed string so
#: the same figure gives the same bytes (``svg.hashsalt``; matplotlib's default is random per run), and mathtext off:
#: labels carry names from the input (a joint named ``a$b$`` is text, never a formula that fails to parse).
STYLE = {"font.size": 8.0, "axes.titlesize": 9.0, "legend.fontsize": 7.0, "svg.fonttype": "none", "svg.hashsalt": "asset2sim",
         "axes.grid": True, "grid.alpha": 0.3, "text.parse_math": False}


#: One figure drawn at a time in a process: matplotlib's settings (``rc_context``) are global, so two threads drawing
#: at once would swap each other's.
_DRAWING = threading.RLock()


def styled(draw):
    """``draw`` (a function making a figure) run under :data:`STYLE` (matplotlib's ``rc_context``: the settings hold
    for the figures it makes and leave the caller's matplotlib as it was), one at a time per process."""

    @functools.wraps(draw)
    def run(*args, **kwargs):
        library_dirs.configure()  # before matplotlib's first import: its folders in asset2sim's cache, not ~/.config
        import matplotlib

        with _DRAWING, matplotlib.rc_context(STYLE):
            return draw(*args, **kwargs)

    return run


#: Margins of a figure's axes, px: left of each column (tick labels and the axis label), right of it (a right-hand
#: axis's), below each row (tick labels and the x label) and above it (the panel's title); fixed, so no layout engine
#: measures the text at every save (matplotlib's constrained layout took half of a figure's time).
MARGINS_PX = {"left": 76.0, "right": 60.0, "bottom": 40.0, "top": 26.0}


def new_figure(rows: int, cols: int, width: float, row_height: float, title: str = ""):
    """A matplotlib ``Figure`` ``width`` px wide and ``row_height`` px per row, :data:`MARGINS_PX` around each of
    its axes, with the axes, an array (rows, cols) of ``Axes``; ``title`` above them all."""
    from matplotlib.figure import Figure

    top_px = 26.0 if title else 0.0
    height = row_height * rows + top_px
    m = MARGINS_PX
    fig = Figure(figsize=(width / DPI, height / DPI), dpi=DPI)
    cell_w, cell_h = width / cols - m["left"] - m["right"], row_height - m["bottom"] - m["top"]
    axes = fig.subplots(rows, cols, squeeze=False, gridspec_kw={
        "left": m["left"] / width, "right": 1.0 - m["right"] / width, "bottom": m["bottom"] / height,
        "top": 1.0 - (top_px + m["top"]) / height, "wspace": (m["left"] + m["right"]) / cell_w, "hspace": (m["bottom"] + m["top"]) / cell_h})
    if title:
        fig.suptitle(title, y=1.0 - 6.0 / height, va="top", fontsize=10, fontweight="bold")
    return fig, axes


def svg_bytes(fig) -> bytes:
    """The SVG document of ``fig`` (from its ``<svg`` element, no XML prolog), UTF-8, the same bytes for the same
    figure under :func:`styled` (no date, ids salted with a fixed string)."""
    buf = io.BytesIO()
    fig.savefig(buf, format="svg", metadata={"Date": None, "Creator": None})
    out = buf.getvalue()
    return out[out.index(b"<svg"):]


def legend(ax, twin=None, loc: str = "upper right") -> None:
    """One legend of ``ax``'s labelled lines and those of its right-hand axis ``twin`` (None: none)."""
    handles, labels = ax.get_legend_handles_labels()
    if twin is not None:
        h2, l2 = twin.get_legend_handles_labels()
        handles, labels = handles + h2, labels + l2
    if handles:
        ax.legend(handles, labels, loc=loc)


def thinned(points: np.ndarray) -> np.ndarray:
    """At most :data:`MAX_SCATTER` of ``points`` (k, ...), an even stride over them in their order (the first kept)."""
    return points[:: max(1, -(-len(points) // MAX_SCATTER))]


@styled
def plot_object(point_cloud: dict[str, np.ndarray]) -> bytes | None:
    """Front (x-z), side (y-z) and top (x-y) views of the collision vertices per
    link (``point_cloud``: link -> (N, 3) m, world, initial state); None without points."""
    pts = {k: np.asarray(v, float) for k, v in point_cloud.items() if len(v)}
    if not pts:
        return None
    fig, axes = new_figure(1, 3, 1100, 360, "collision geometry at the initial state (ground z = 0)")
    views = [(0, 2, "front: x (m)", "z (m)"), (1, 2, "side: y (m)", "z (m)"), (0, 1, "top: x (m)", "y (m)")]
    for n, (ax, (i, j, xl, yl)) in enumerate(zip(axes[0], views)):
        for k, (name, v) in enumerate(sorted(pts.items())):
            v = thinned(v)
            ax.scatter(v[:, i], v[:, j], s=2.0, color=f"C{k % 10}", label=name, linewidths=0, rasterized=True)
        if n < 2:
            ax.axhline(0.0, color="k", lw=0.8)
        ax.set(xlabel=xl, ylabel=yl, aspect="equal")
        ax.set_adjustable("datalim")
        if n == 0:
            legend(ax)
    return svg_bytes(fig)


@styled
def plot_root_drift(root_series: np.ndarray, trace, dt: float, settle_steps: int) -> bytes:
    """Root displacement |p(t) - p(0)| (mm) over settle + test (``root_series``
    (K, 3) m), and the test's |p - p0| (mm) and rotation (rad) from the ``trace``
    (:class:`asset2sim.tasks.check.metrics.RestTrace`); ``dt`` s, ``settle_steps`` in T_set."""
    fig, ((a, b),) = new_figure(1, 2, 1100, 320)
    a.set(title="root drift, settle + test", xlabel="time (s)", ylabel="root displacement from start (mm)")
    root_series = np.asarray(root_series, float)
    if len(root_series):
        t = np.arange(1, len(root_series) + 1) * dt
        a.plot(t, np.linalg.norm(root_series - root_series[0], axis=1) * 1000.0, color="C0", lw=1.2)
        a.axvline(settle_steps * dt, color="gray", ls="--", label="end of settling")
        legend(a)
    b.set(title="rest test (T_test)", xlabel="time since end of settling (s)", ylabel="mm")
    r = b.twinx()
    r.set_ylabel("rad")
    dp = np.linalg.norm(np.asarray(trace.root_pos) - np.asarray(trace.p0), axis=1) * 1000.0
    ang = np.array([quat_angle(trace.q0, q) for q in trace.root_quat])
    b.plot(trace.t, dp, color="C0", lw=1.2, label="D_pos(t) (mm)")
    b.axhline(1.0, color="C0", ls=":", label="1 mm threshold")
    r.plot(trace.t, ang, color="C3", lw=1.2, label="D_ori(t) (rad)")
    r.axhline(0.01, color="C3", ls=":", label="0.01 rad threshold")
    legend(b, r, "upper left")
    return svg_bytes(fig)


@styled
def plot_joints(joint_series: dict[str, np.ndarray], joint_types: dict[str, str], dt: float, settle_steps: int,
                closed: dict[str, float] | None = None) -> bytes | None:
    """Each movable joint's position over settle + test (rad or m). None without joints."""
    if not joint_series:
        return None
    fig, axes = new_figure(len(joint_series), 1, 1100, 190, "joint trajectories during the rest test")
    for k, (ax, name) in enumerate(zip(axes[:, 0], joint_series)):
        q = np.asarray(joint_series[name], float)
        unit = "m" if joint_types.get(name) == "prismatic" else "rad"
        ax.set(ylabel=f"{name} ({unit})", xlabel="time (s); dashed line: end of settling" if k == len(joint_series) - 1 else "")
        ax.plot(np.arange(1, len(q) + 1) * dt, q, color="C0", lw=1.2)
        ax.axvline(settle_steps * dt, color="gray", ls="--")
        if closed and name in closed:
            ax.axhline(closed[name], color="k", ls=":", label="closed end")
            legend(ax)
    return svg_bytes(fig)


@styled
def plot_probes(probes: list[Any]) -> bytes | None:
    """Per probe: joint position (rad or m) and pusher force (N) over time, with the target and the release moment; root
    displacement (mm). None without probes."""
    if not probes:
        return None
    fig, axes = new_figure(len(probes), 2, 1200, 260)
    for (a, b), pr in zip(axes, probes):
        tr = pr.trace
        t, q, f = (np.asarray(tr.get(k, []), float) for k in ("t", "q", "force"))
        ph = np.asarray(tr.get("phase", []))
        unit = "m" if pr.joint_type == "prismatic" else "rad"
        a.set(title=f"{pr.action} {pr.joint}: {'ok' if pr.success else pr.failure}", xlabel="time since the push started (s)", ylabel=unit)
        a.plot(t, q, color="C0", lw=1.2, label=f"{pr.joint} ({unit})")
        a.axhline(pr.target, color="C0", ls=":", label="target")
        if pr.target_fraction != pr.start_fraction:  # the position where the probe counts the target reached
            at = reached_fraction(pr.action, pr.target_fraction)
            a.axhline(pr.start + (at - pr.start_fraction) * (pr.target - pr.start) / (pr.target_fraction - pr.start_fraction),
                      color="C2", ls="--", label="counts as reached")
        if np.any(ph > 0):
            a.axvline(t[int(np.argmax(ph > 0))], color="gray", ls="--", label="release")
        r = a.twinx()
        r.set_ylabel("N")
        r.plot(t, f, color="C1", lw=1.0, label="force (N)")
        legend(a, r)
        b.set(title="object motion during the probe (slide threshold 5 mm)", xlabel="time since the push started (s)",
              ylabel="root displacement (mm)")
        b.plot(t, np.asarray(tr.get("root_disp", []), float) * 1000.0, color="C2", lw=1.2)
        b.axhline(5.0, color="C2", ls=":")
    return svg_bytes(fig)


@styled
def plot_method_summary(summary: dict[str, dict[str, Any]]) -> bytes | None:
    """Bar chart of pass rates (%) per method: rest stability, oscillation,
    probes, all checks. ``summary``: method -> row of the benchmark table."""
    if not summary:
        return None
    keys = [("rest_stability_pass", "rest stability"), ("oscillation_pass", "oscillation"),
            ("probes_pass", "probes"), ("all_pass", "all checks")]
    fig, ((ax,),) = new_figure(1, 1, 900, 320)
    width = 0.8 / len(summary)
    x = np.arange(len(keys))
    for i, m in enumerate(summary):
        ax.bar(x + (i - (len(summary) - 1) / 2) * width, [100.0 * (summary[m].get(k) or 0.0) for k, _ in keys], width,
               label=m, color=f"C{i % 10}")
    ax.set(xticks=x, xticklabels=[lab for _, lab in keys], ylabel="pass rate (%)", ylim=(0.0, 105.0))
    legend(ax)
    return svg_bytes(fig)
