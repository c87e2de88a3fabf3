"""The report's figures (matplotlib, SVG): well-formed standalone documents, the same bytes for the same data,
text kept as text and escaped, long point clouds thinned, and the caller's matplotlib settings left alone."""

from __future__ import annotations

import xml.etree.ElementTree as ET
from concurrent.futures import ThreadPoolExecutor
from types import SimpleNamespace

import matplotlib
import numpy as np

from asset2sim.tasks.check.robust_rest import Trial
from asset2sim.tasks.evaluation import failure_evidence, plots

NS = "{http://www.w3.org/2000/svg}"


def _texts(svg: bytes) -> list[str]:
    root = ET.fromstring(svg)
    assert root.tag == f"{NS}svg"
    return ["".join(t.itertext()) for t in root.iter(f"{NS}text")]


def _probe(success: bool) -> SimpleNamespace:
    t = np.linspace(0.0, 2.0, 481)
    return SimpleNamespace(action="open", joint="door <hinge>", joint_type="revolute", success=success,
                           failure="" if success else "stalled at 40 %", target=1.2, start=0.0, target_fraction=0.9,
                           start_fraction=0.0, trace={"t": t, "q": 1.2 * (1 - np.exp(-3 * t)), "force": 5 * np.exp(-t),
                                                      "phase": (t > 1.5).astype(int), "root_disp": 0.001 * t})


def test_a_figure_is_one_standalone_svg_with_its_text_escaped_and_the_same_bytes_twice():
    a, b = plots.plot_probes([_probe(True), _probe(False)]), plots.plot_probes([_probe(True), _probe(False)])
    assert a == b  # no date, ids salted with a fixed string
    assert a.startswith(b"<svg ") and a.rstrip().endswith(b"</svg>")
    texts = _texts(a)
    assert "open door <hinge>: stalled at 40 %" in texts and "force (N)" in texts and "counts as reached" in texts
    assert b"door &lt;hinge&gt;" in a


def test_point_clouds_are_thinned_to_the_scatter_limit_and_drawn_as_images():
    rng = np.random.default_rng(0)
    base = rng.random((20000, 3))
    kept = plots.thinned(base)
    assert len(kept) <= plots.MAX_SCATTER and len(kept) > plots.MAX_SCATTER * 0.9
    assert np.array_equal(kept[0], base[0]) and np.array_equal(kept[1], base[len(base) // plots.MAX_SCATTER + 1])
    lid = rng.random((300, 3))
    assert np.array_equal(plots.thinned(lid), lid)
    svg = plots.plot_object({"base": base, "lid": lid + [0, 0, 1]})
    assert svg.count(b"<image ") >= 3 and len(svg) < 2_000_000  # a raster of the points in each view, not 60,000 elements
    assert "base" in _texts(svg) and "lid" in _texts(svg) and "front: x (m)" in _texts(svg)
    assert plots.plot_object({"base": np.zeros((0, 3))}) is None


def test_the_callers_matplotlib_settings_are_left_as_they_were_and_threads_draw_the_same_bytes():
    before = dict(matplotlib.rcParams)
    summary = {"ours": {"rest_stability_pass": 1.0, "all_pass": 0.5}, "baseline": {"all_pass": 0.25}}
    one = plots.plot_method_summary(summary)
    assert dict(matplotlib.rcParams) == before
    with ThreadPoolExecutor(4) as pool:  # each figure under the style, none under another's
        assert set(pool.map(lambda _: plots.plot_method_summary(summary), range(8))) == {one}
    assert dict(matplotlib.rcParams) == before and "rest stability" in _texts(one) and "baseline" in _texts(one)


def test_a_failing_trial_plots_the_tilt_and_each_joint_against_its_tolerance():
    t = np.arange(1, 241) / 240.0
    trace = SimpleNamespace(q0=np.array([0, 0, 0, 1.0]), initial_root_quat=np.array([0, 0.0436, 0, 0.999]), t=t,
                            root_quat=np.tile([0, 0, 0, 1.0], (240, 1)), joints={"slide": 0.004 * t},
                            settle_joints={"slide": np.zeros(30)}, joint_types={"slide": "prismatic"}, initial_joints={"slide": 0.0})
    trial = Trial(name="tilt+y", passed=False, joint_drift={"slide": 0.004}, joint_tolerance={"slide": 0.002},
                  failing_joints=["slide"], failure="joints not held: slide 0.004", trace=trace)
    texts = _texts(failure_evidence.trial_plot(trial, 1 / 240))
    assert "tilt+y: joints not held: slide 0.004" in texts and "joint slide: drift 0.004 m" in texts
    assert "tolerance +-0.002 m" in texts and "end of settling" in texts
