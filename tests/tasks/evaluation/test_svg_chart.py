"""SVG charts of the reports: well-formed, scaled, escaped, and drawn from the
data they are given (extremes of long series kept)."""

from __future__ import annotations

import re
import xml.etree.ElementTree as ET

import numpy as np
import pytest

from asset2sim.tasks.evaluation import svg_chart as S

NS = "{http://www.w3.org/2000/svg}"


def _parse(svg: str) -> ET.Element:
    root = ET.fromstring(svg)
    assert root.tag == f"{NS}svg"
    return root


def _points(el: ET.Element) -> np.ndarray:
    return np.array([[float(v) for v in p.split(",")] for p in el.get("points").split()])


@pytest.mark.parametrize("lo,hi", [(0.0, 1.0), (-0.0031, 0.0127), (3.0, 1234.0), (5.0, 5.0), (-2e-6, 0.0)])
def test_nice_ticks_cover_the_range_with_round_steps(lo, hi):
    a, b, ticks = S.nice_ticks(lo, hi)
    assert a <= lo and b >= hi and 2 <= len(ticks) <= 12
    step = ticks[1] - ticks[0]
    mant = step / 10 ** np.floor(np.log10(step))
    assert min(abs(mant - m) for m in (1, 2, 5, 10)) < 1e-6
    lo2, hi2, inner = S.axis_range(lo, hi)
    assert lo2 < min(lo, hi) + 1e-12 and hi2 > max(lo, hi) - 1e-12
    assert all(lo2 - 1e-12 <= t <= hi2 + 1e-12 for t in inner) and len(inner) >= 2


def test_tick_labels_use_the_digits_of_the_step():
    assert S.tick_label(0.25, 0.05) == "0.25"
    assert S.tick_label(2.0, 0.5) == "2.0"
    assert S.tick_label(1500.0, 500.0) == "1500"
    assert S.tick_label(1e-17, 0.1) == "0.0"


def test_reduce_series_keeps_every_extreme_and_the_ends():
    x = np.linspace(0.0, 10.0, 20001)
    y = np.sin(x * 7.0) + 0.001 * x
    y[12345] = 5.0  # one spike must survive
    xr, yr = S.reduce_series(x, y, 200)
    assert len(xr) <= 4 * 200 and len(xr) < len(x)
    assert yr.max() == 5.0 and yr.min() == y.min()
    assert xr[0] == x[0] and xr[-1] == x[-1]
    assert np.all(np.diff(xr) > 0)  # order kept


def test_line_panel_maps_data_onto_the_axes():
    p = S.Panel(title="drift <test> & more", xlabel="time (s)", ylabel="mm")
    p.line([0.0, 1.0, 2.0], [0.0, 2.0, 1.0], "C0", "D_pos")
    p.hline(1.5, "C3", ":", "threshold")
    svg = S.figure_svg([[p]], width=600, row_height=300)
    root = _parse(svg)
    lines = root.findall(f".//{NS}polyline")
    assert len(lines) == 1
    pts = _points(lines[0])
    # x increases to the right, a larger y is higher on the page (smaller pixel y)
    assert pts[0, 0] < pts[1, 0] < pts[2, 0]
    assert pts[1, 1] < pts[2, 1] < pts[0, 1]
    assert lines[0].get("stroke") == S.PALETTE[0]
    texts = [t.text for t in root.iter(f"{NS}text")]
    assert "drift <test> & more" in texts and "time (s)" in texts and "mm" in texts  # escaped in the file, read back
    assert "D_pos" in texts and "threshold" in texts  # legend
    assert "<test>" not in svg


def test_breaks_at_non_finite_values_and_right_axis():
    p = S.Panel(ylabel="rad", ylabel_right="N")
    p.line([0, 1, 2, 3, 4], [0, 1, np.nan, 1, 0])
    p.line([0, 4], [100.0, 200.0], "C1", right=True)
    root = _parse(S.figure_svg([[p]]))
    assert len(root.findall(f".//{NS}polyline")) == 3  # two pieces + the right-axis series
    texts = [t.text for t in root.iter(f"{NS}text")]
    assert "N" in texts and any(t in texts for t in ("100", "150", "200"))


def test_equal_aspect_scatter_and_bars():
    p = S.Panel(equal_aspect=True)
    p.scatter(np.array([0.0, 1.0]), np.array([0.0, 0.1]), 2, "link")
    root = _parse(S.figure_svg([[p]], width=500, row_height=300))
    d = root.findall(f".//{NS}path")[0].get("d")
    xy = np.array([[float(a), float(b)] for a, b in re.findall(r"M(-?[\d.]+) (-?[\d.]+)", d)])
    dx, dy = abs(xy[1, 0] - xy[0, 0]), abs(xy[1, 1] - xy[0, 1])
    assert dx == pytest.approx(10 * dy, rel=0.1)  # 1 m across is 10 times 0.1 m up on the page
    b = S.Panel(ylabel="pass rate (%)")
    b.ylim = (0.0, 105.0)
    b.bars(["rest", "probes"], [("m1", [100.0, 50.0]), ("m2", [0.0, 25.0])])
    rects = _parse(S.figure_svg([[b]])).findall(f".//{NS}rect")
    heights = sorted(float(r.get("height")) for r in rects if r.get("fill") in S.PALETTE[:2] and r.get("width") != "14")
    assert heights[0] == pytest.approx(0.0, abs=0.05) and heights[-1] == pytest.approx(2 * heights[-2], rel=0.02)
