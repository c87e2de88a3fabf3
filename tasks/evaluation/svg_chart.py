"""Small SVG charts for the HTML reports (no plotting library): line, scatter
and bar panels with axes, ticks, grid, reference lines, legends and an
optional right-hand axis, as a standalone SVG document.

Ticks follow Heckbert's "nice numbers" (Graphics Gems, 1990, pp. 61-63);
colours are the Tableau 10 palette (matplotlib's ``tab10``).
"""

from __future__ import annotations

import html
import itertools
import math
from dataclasses import dataclass, field

import numpy as np

#: Tableau 10 (``C0`` .. ``C9``).
PALETTE = ("#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2", "#7f7f7f", "#bcbd22", "#17becf")

DASHES = {"-": "", "--": "6,4", ":": "1.5,3", "-.": "6,3,1.5,3"}
MAX_SCATTER = 1500  # most points drawn per scatter series (an even stride)
FONT = "font-family:system-ui,-apple-system,Segoe UI,Roboto,sans-serif"


def colour(c: str | int) -> str:
    """``"C3"`` or 3 -> the palette's colour; any other string unchanged (CSS colour)."""
    if isinstance(c, int):
        return PALETTE[c % len(PALETTE)]
    if len(c) >= 2 and c[0] == "C" and c[1:].isdigit():
        return PALETTE[int(c[1:]) % len(PALETTE)]
    return c


def nice_number(x: float, round_: bool) -> float:
    """Heckbert's nice number near ``x`` (> 0): 1, 2, 5 or 10 times a power of ten."""
    if not (x > 0 and math.isfinite(x)):
        return 1.0
    e = math.floor(math.log10(x))
    f = x / 10 ** e
    if round_:
        nf = 1 if f < 1.5 else 2 if f < 3 else 5 if f < 7 else 10
    else:
        nf = 1 if f <= 1 else 2 if f <= 2 else 5 if f <= 5 else 10
    return nf * 10 ** e


def _usable(lo: float, hi: float) -> tuple[float, float]:
    """[lo, hi] made drawable: [0, 1] when not finite, widened by half of |lo| (else 0.5) each side when empty."""
    if not (math.isfinite(lo) and math.isfinite(hi)):
        lo, hi = 0.0, 1.0
    if hi - lo <= 1e-12 * max(1.0, abs(lo), abs(hi)):
        pad = 0.5 * abs(lo) if lo != 0 else 0.5
        lo, hi = lo - pad, hi + pad
    return lo, hi


def nice_ticks(lo: float, hi: float, n: int = 5) -> tuple[float, float, list[float]]:
    """(axis low, axis high, tick values) covering [lo, hi] with about ``n`` ticks."""
    lo, hi = _usable(lo, hi)
    step = nice_number(nice_number(hi - lo, False) / max(n - 1, 1), True)
    a, b = math.floor(lo / step) * step, math.ceil(hi / step) * step
    k = int(round((b - a) / step))
    return a, b, [a + i * step for i in range(k + 1)]


def axis_range(lo: float, hi: float, margin: float = 0.04, n: int = 8) -> tuple[float, float, list[float]]:
    """(axis low, axis high, ticks): the data span [lo, hi] widened by
    ``margin`` of its width on each side, with the nice ticks inside it."""
    lo, hi = _usable(lo, hi)
    d = (hi - lo) * margin
    lo, hi = lo - d, hi + d
    _, _, ticks = nice_ticks(lo, hi, n)
    eps = 1e-9 * (hi - lo)
    return lo, hi, [t for t in ticks if lo - eps <= t <= hi + eps]


def tick_label(v: float, step: float) -> str:
    """A tick value printed with the digits its step needs."""
    if abs(v) < step * 1e-9:
        v = 0.0
    if step >= 1 and abs(v) < 1e6:
        return f"{v:.0f}"
    d = max(0, -math.floor(math.log10(step) + 1e-9) + (0 if math.isclose(nice_number(step, True), step, rel_tol=1e-6) else 1))
    if d > 6 or abs(v) >= 1e6:
        return f"{v:.3g}"
    return f"{v:.{d}f}"


def reduce_series(x: np.ndarray, y: np.ndarray, columns: int) -> tuple[np.ndarray, np.ndarray]:
    """At most four points (first, lowest, highest, last) per column of ``columns``
    equal x intervals: the same drawn envelope. x, y: (N,)."""
    n = len(x)
    if n <= 4 * columns or n < 2:
        return x, y
    lo, hi = float(np.nanmin(x)), float(np.nanmax(x))
    if not hi > lo:
        return x[[0, -1]], y[[0, -1]]
    col = np.minimum(((x - lo) / (hi - lo) * columns).astype(int), columns - 1)
    keep = np.zeros(n, bool)
    starts = np.flatnonzero(np.r_[True, col[1:] != col[:-1]])
    ends = np.r_[starts[1:], n]
    yy = np.where(np.isfinite(y), y, 0.0)
    for s, e in zip(starts, ends):
        seg = yy[s:e]
        keep[[s, e - 1, s + int(np.argmin(seg)), s + int(np.argmax(seg))]] = True
    keep |= ~np.isfinite(y)  # breaks stay breaks
    return x[keep], y[keep]


@dataclass
class _Series:
    x: np.ndarray
    y: np.ndarray
    colour: str
    label: str | None
    dash: str
    width: float
    right: bool
    scatter: bool
    size: float


@dataclass
class Panel:
    """One set of axes: add data with :meth:`line`, :meth:`scatter`, :meth:`hline`,
    :meth:`vline`, :meth:`bars`; lay panels out with :func:`figure_svg`."""

    title: str = ""
    xlabel: str = ""
    ylabel: str = ""
    ylabel_right: str = ""
    equal_aspect: bool = False
    legend: str | None = "upper right"  # "upper right", "upper left" or None
    series: list[_Series] = field(default_factory=list)
    hlines: list[tuple[float, str, str, str | None, bool]] = field(default_factory=list)
    vlines: list[tuple[float, str, str, str | None]] = field(default_factory=list)
    bar_groups: list[str] = field(default_factory=list)
    bar_series: list[tuple[str, list[float], str]] = field(default_factory=list)
    ylim: tuple[float, float] | None = None

    def line(self, x, y, colour_: str | int = "C0", label: str | None = None, dash: str = "-", width: float = 1.2,
             right: bool = False) -> "Panel":
        """A polyline (x, y: (N,)); non-finite y values break it; ``right``: on the right-hand axis."""
        self.series.append(_Series(np.asarray(x, float).ravel(), np.asarray(y, float).ravel(), colour(colour_), label,
                                   DASHES.get(dash, ""), width, right, False, 0.0))
        return self

    def scatter(self, x, y, colour_: str | int = "C0", label: str | None = None, size: float = 1.2) -> "Panel":
        """Points (x, y: (N,)) as dots of radius ``size`` px."""
        self.series.append(_Series(np.asarray(x, float).ravel(), np.asarray(y, float).ravel(), colour(colour_), label,
                                   "", 0.0, False, True, size))
        return self

    def hline(self, y: float, colour_: str | int = "k", dash: str = ":", label: str | None = None, right: bool = False) -> "Panel":
        """A horizontal reference line at ``y`` (on the right-hand axis with ``right``)."""
        self.hlines.append((float(y), "#000" if colour_ == "k" else colour(colour_), DASHES.get(dash, ""), label, right))
        return self

    def vline(self, x: float, colour_: str | int = "gray", dash: str = "--", label: str | None = None) -> "Panel":
        """A vertical reference line at ``x``."""
        self.vlines.append((float(x), "#000" if colour_ == "k" else colour(colour_), DASHES.get(dash, ""), label))
        return self

    def bars(self, groups: list[str], series: list[tuple[str, list[float]]]) -> "Panel":
        """Grouped bars: one group per name in ``groups``, one bar per (label, values) in ``series``."""
        self.bar_groups = list(groups)
        self.bar_series = [(lab, [float(v) for v in vals], PALETTE[i % len(PALETTE)]) for i, (lab, vals) in enumerate(series)]
        return self


def _span(values: list[np.ndarray], extra: list[float]) -> tuple[float, float]:
    vals = [f for f in (v[np.isfinite(v)] for v in values) if len(f)]
    ext = [e for e in extra if math.isfinite(e)]
    lo = min([float(v.min()) for v in vals] + ext, default=0.0)
    hi = max([float(v.max()) for v in vals] + ext, default=1.0)
    return lo, hi


class _Canvas:
    def __init__(self) -> None:
        self.parts: list[str] = []

    def text(self, x: float, y: float, s: str, size: int = 11, anchor: str = "middle", rotate: bool = False,
             weight: str = "normal", fill: str = "#222") -> None:
        tr = f' transform="rotate(-90 {x:.1f} {y:.1f})"' if rotate else ""
        self.parts.append(f'<text x="{x:.1f}" y="{y:.1f}" font-size="{size}" text-anchor="{anchor}" fill="{fill}" '
                          f'font-weight="{weight}"{tr}>{html.escape(s)}</text>')

    def line(self, x1: float, y1: float, x2: float, y2: float, stroke: str, width: float = 1.0, dash: str = "",
             opacity: float = 1.0) -> None:
        d = f' stroke-dasharray="{dash}"' if dash else ""
        o = f' stroke-opacity="{opacity}"' if opacity < 1 else ""
        self.parts.append(f'<line x1="{x1:.1f}" y1="{y1:.1f}" x2="{x2:.1f}" y2="{y2:.1f}" stroke="{stroke}" '
                          f'stroke-width="{width}"{d}{o}/>')


@dataclass
class _Axes:
    """A panel's plot area (x, y, width, height px) and its axes: x, left y and right y (low, high, ticks)."""

    ax: float
    ay: float
    aw: float
    ah: float
    xlo: float
    xhi: float
    xt: list[float]
    ylo: float
    yhi: float
    yt: list[float]
    rlo: float = 0.0
    rhi: float = 1.0
    rt: list[float] = field(default_factory=list)

    def px(self, x):
        """Data x -> px."""
        return self.ax + (np.asarray(x, float) - self.xlo) / (self.xhi - self.xlo) * self.aw

    def py(self, y, r=False):
        """Data y (on the right-hand axis with ``r``) -> px."""
        lo, hi = (self.rlo, self.rhi) if r else (self.ylo, self.yhi)
        return self.ay + self.ah - (np.asarray(y, float) - lo) / (hi - lo) * self.ah


def _panel_svg(cv: _Canvas, p: Panel, x0: float, y0: float, w: float, h: float, clip_id: str) -> None:
    """Draw panel ``p`` in the cell (x0, y0, w, h) px."""
    twin = any(s.right for s in p.series) or any(hl[4] for hl in p.hlines)
    a = _axes(p, x0, y0, w, h, twin)
    cv.parts.append(f'<rect x="{a.ax:.1f}" y="{a.ay:.1f}" width="{a.aw:.1f}" height="{a.ah:.1f}" fill="#fff" stroke="#333" stroke-width="0.8"/>')
    _ticks(cv, p, a, twin)
    cv.parts.append(f'<clipPath id="{clip_id}"><rect x="{a.ax:.1f}" y="{a.ay:.1f}" width="{a.aw:.1f}" height="{a.ah:.1f}"/></clipPath>'
                    f'<g clip-path="url(#{clip_id})">')
    _bars(cv, p, a)
    for s in p.series:
        _series(cv, s, a)
    for y, col, dash, _, r in p.hlines:
        yy = float(a.py(y, r))
        cv.line(a.ax, yy, a.ax + a.aw, yy, col, 0.9, dash)
    for x, col, dash, _ in p.vlines:
        xx = float(a.px(x))
        cv.line(xx, a.ay, xx, a.ay + a.ah, col, 0.9, dash)
    cv.parts.append("</g>")
    _labels(cv, p, a, x0, y0, twin)
    _legend(cv, p, a)


def _axes(p: Panel, x0: float, y0: float, w: float, h: float, twin: bool) -> _Axes:
    """The plot area inside the cell (x0, y0, w, h) px, its margins left for the labels, and the axes of ``p``'s data."""
    ml, mr, mt, mb = 62.0, (62.0 if twin else 14.0), (22.0 if p.title else 10.0), 40.0
    ax, ay, aw, ah = x0 + ml, y0 + mt, max(w - ml - mr, 20.0), max(h - mt - mb, 20.0)
    if p.bar_groups:
        xlo, xhi, xt = -0.5, len(p.bar_groups) - 0.5, []
        ylo, yhi, yt = nice_ticks(*(p.ylim or _span([np.asarray(v) for _, v, _ in p.bar_series], [0.0])))
        if p.ylim:
            ylo, yhi = p.ylim
            yt = [t for t in yt if ylo - 1e-9 <= t <= yhi + 1e-9]
    else:
        xlo, xhi, xt = axis_range(*_span([s.x for s in p.series], [v[0] for v in p.vlines]))
        ylo, yhi, yt = axis_range(*_span([s.y for s in p.series if not s.right], [hl[0] for hl in p.hlines if not hl[4]]))
        if p.equal_aspect:  # same m per px on both axes: widen the narrower span about its centre
            sx, sy = (xhi - xlo) / aw, (yhi - ylo) / ah
            if sx > sy:
                c = 0.5 * (ylo + yhi)
                ylo, yhi = c - 0.5 * sx * ah, c + 0.5 * sx * ah
                _, _, yt = axis_range(ylo, yhi, 0.0)
            else:
                c = 0.5 * (xlo + xhi)
                xlo, xhi = c - 0.5 * sy * aw, c + 0.5 * sy * aw
                _, _, xt = axis_range(xlo, xhi, 0.0)
    a = _Axes(ax, ay, aw, ah, xlo, xhi, xt, ylo, yhi, yt)
    if twin:
        a.rlo, a.rhi, a.rt = axis_range(*_span([s.y for s in p.series if s.right], [hl[0] for hl in p.hlines if hl[4]]))
    return a


def _ticks(cv: _Canvas, p: Panel, a: _Axes, twin: bool) -> None:
    """Grid lines, ticks and tick labels of the left axis, the x axis (group names under bars) and, with ``twin``, the right axis."""
    ystep, xstep, rstep = (t[1] - t[0] if len(t) > 1 else 1.0 for t in (a.yt, a.xt, a.rt))  # tick spacings
    for t in a.yt:
        yy = float(a.py(t))
        cv.line(a.ax, yy, a.ax + a.aw, yy, "#b0b0b0", 0.6, opacity=0.5)
        cv.line(a.ax - 4, yy, a.ax, yy, "#333", 0.8)
        cv.text(a.ax - 6, yy + 4, tick_label(t, ystep), 10, "end")
    if p.bar_groups:
        for i, g in enumerate(p.bar_groups):
            cv.text(float(a.px(i)), a.ay + a.ah + 14, g, 10)
    else:
        for t in a.xt:
            xx = float(a.px(t))
            cv.line(xx, a.ay, xx, a.ay + a.ah, "#b0b0b0", 0.6, opacity=0.5)
            cv.line(xx, a.ay + a.ah, xx, a.ay + a.ah + 4, "#333", 0.8)
            cv.text(xx, a.ay + a.ah + 14, tick_label(t, xstep), 10)
    if twin:
        for t in a.rt:
            yy = float(a.py(t, True))
            cv.line(a.ax + a.aw, yy, a.ax + a.aw + 4, yy, "#333", 0.8)
            cv.text(a.ax + a.aw + 6, yy + 4, tick_label(t, rstep), 10, "start")


def _bars(cv: _Canvas, p: Panel, a: _Axes) -> None:
    """``p``'s grouped bars: 0.8 of each group's width shared by its bars, from max(0, axis low) up."""
    if not p.bar_groups:
        return
    bw = 0.8 / max(len(p.bar_series), 1)
    for j, (_, vals, col) in enumerate(p.bar_series):
        for i, v in enumerate(vals):
            x1 = float(a.px(i - 0.4 + j * bw))
            x2 = float(a.px(i - 0.4 + (j + 1) * bw))
            y1, y2 = float(a.py(max(v, a.ylo))), float(a.py(max(a.ylo, 0.0)))
            cv.parts.append(f'<rect x="{x1:.1f}" y="{min(y1, y2):.1f}" width="{x2 - x1:.1f}" height="{abs(y2 - y1):.1f}" fill="{col}"/>')


def _series(cv: _Canvas, s: _Series, a: _Axes) -> None:
    """One series: a path of dots, or polylines (reduced to the plot's width, broken at non-finite points)."""
    if s.scatter:
        ok = np.flatnonzero(np.isfinite(s.x) & np.isfinite(s.y))
        ok = ok[:: max(1, -(-len(ok) // MAX_SCATTER))]  # an even stride through the points
        xs, ys = a.px(s.x[ok]), a.py(s.y[ok])
        # one path of tiny squares: far smaller than one <circle> per point
        d = "".join(f"M{x:.0f} {y:.0f}h{s.size:g}v{s.size:g}h-{s.size:g}z" for x, y in _unique_px(xs, ys))
        cv.parts.append(f'<path d="{d}" fill="{s.colour}"/>')
        return
    xr, yr = reduce_series(s.x, s.y, int(a.aw))
    xs, ys = a.px(xr), a.py(yr, s.right)
    runs = itertools.groupby(zip(xs, ys, np.isfinite(xs) & np.isfinite(ys)), key=lambda p: p[2])  # broken at non-finite points
    segs = [[f"{x:.1f},{y:.1f}" for x, y, _ in run] for finite, run in runs if finite]
    d = f' stroke-dasharray="{s.dash}"' if s.dash else ""
    for seg in segs:
        cv.parts.append(f'<polyline points="{" ".join(seg)}" fill="none" stroke="{s.colour}" stroke-width="{s.width}"'
                        f' stroke-linejoin="round"{d}/>')


def _labels(cv: _Canvas, p: Panel, a: _Axes, x0: float, y0: float, twin: bool) -> None:
    """The panel's title and axis labels (the right one only with ``twin``)."""
    if p.title:
        cv.text(a.ax + a.aw / 2, y0 + 15, p.title, 11)
    if p.xlabel:
        cv.text(a.ax + a.aw / 2, a.ay + a.ah + 31, p.xlabel, 11)
    if p.ylabel:
        cv.text(x0 + 13, a.ay + a.ah / 2, p.ylabel, 11, rotate=True)
    if p.ylabel_right and twin:
        cv.text(a.ax + a.aw + 52, a.ay + a.ah / 2, p.ylabel_right, 11, rotate=True)


def _legend(cv: _Canvas, p: Panel, a: _Axes) -> None:
    """A legend box of every labelled series, reference line and bar series, in the corner ``p.legend`` names."""
    entries = [(s.label, s.colour, s.dash, s.scatter) for s in p.series if s.label]
    entries += [(lab, col, dash, False) for _, col, dash, lab, _ in p.hlines if lab]
    entries += [(lab, col, dash, False) for _, col, dash, lab in p.vlines if lab]
    entries += [(lab, col, "", True) for lab, _, col in p.bar_series]
    if not (entries and p.legend):
        return
    lw = 34 + 6.2 * max(len(e[0]) for e in entries)
    lx = a.ax + a.aw - lw - 6 if p.legend == "upper right" else a.ax + 6
    ly = a.ay + 6
    cv.parts.append(f'<rect x="{lx:.1f}" y="{ly:.1f}" width="{lw:.1f}" height="{14 * len(entries) + 6}" fill="#fff" '
                    f'fill-opacity="0.85" stroke="#ccc" stroke-width="0.6"/>')
    for k, (lab, col, dash, dot) in enumerate(entries):
        yy = ly + 12 + 14 * k
        if dot:
            cv.parts.append(f'<rect x="{lx + 8:.1f}" y="{yy - 7:.1f}" width="14" height="8" fill="{col}"/>')
        else:
            cv.line(lx + 6, yy - 3, lx + 26, yy - 3, col, 1.4, dash)
        cv.text(lx + 30, yy, lab, 10, "start")


def _unique_px(xs: np.ndarray, ys: np.ndarray) -> list[tuple[float, float]]:
    """Points rounded to whole pixels, duplicates dropped (order kept)."""
    if not len(xs):
        return []
    q = np.stack([np.round(xs), np.round(ys)], axis=1)
    _, idx = np.unique(q, axis=0, return_index=True)
    return [tuple(q[i]) for i in sorted(idx)]


def figure_svg(rows: list[list[Panel]], width: float = 1000.0, row_height: float = 300.0, title: str = "") -> str:
    """An SVG document of ``rows`` of panels (each row split evenly across ``width`` px, ``row_height`` px high)."""
    top = 26.0 if title else 0.0
    height = top + row_height * len(rows)
    cv = _Canvas()
    for i, row in enumerate(rows):
        cw = width / max(len(row), 1)
        for j, p in enumerate(row):
            _panel_svg(cv, p, j * cw, top + i * row_height, cw, row_height, f"c{i}_{j}")
    if title:
        cv.text(width / 2, 18, title, 13, weight="600")
    return (f'<svg xmlns="http://www.w3.org/2000/svg" width="{width:.0f}" height="{height:.0f}" '
            f'viewBox="0 0 {width:.0f} {height:.0f}" style="{FONT}"><rect width="100%" height="100%" fill="#fff"/>'
            + "".join(cv.parts) + "</svg>")
