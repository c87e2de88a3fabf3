"""report.html and the benchmark pages: self-contained, complete, escaped."""

from __future__ import annotations

import base64
import json
import re
from pathlib import Path

import pytest

from asset2sim.tasks.evaluation.evaluate import evaluate_asset
from asset2sim.tasks.evaluation.benchmark_pages import render_benchmark_index, render_benchmark_summary
from asset2sim.tasks.evaluation.parameter_table import parameter_rows
from tests.conftest import SHARED, needs_shared


def _drawer(folder: Path, with_overlay: bool) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    inert = '<inertial><mass value="{m}"/><inertia ixx="0.05" iyy="0.05" izz="0.05" ixy="0" ixz="0" iyz="0"/></inertial>'
    box = '<collision><geometry><box size="{x} {y} {z}"/></geometry></collision><visual><geometry><box size="{x} {y} {z}"/></geometry></visual>'
    (folder / "mobility.urdf").write_text(
        '<?xml version="1.0"?><robot name="cab">'
        f'<link name="carcass">{inert.format(m=20)}{box.format(x=0.4, y=0.4, z=0.3)}</link>'
        f'<link name="drawer">{inert.format(m=1)}{box.format(x=0.2, y=0.3, z=0.1)}</link>'
        '<joint name="slide" type="prismatic"><parent link="carcass"/><child link="drawer"/><origin xyz="0.31 0 0"/>'
        '<axis xyz="1 0 0"/><limit lower="0" upper="0.3"/><dynamics damping="2" friction="1"/></joint></robot>'
    )
    (folder / "initial_state.json").write_text(json.dumps({"initial_joint_positions": {"slide": 0.1}}))
    if with_overlay:
        (folder / "overlay.json").write_text(json.dumps({
            "scale": 0.8, "category": "StorageFurniture", "estimator": {"name": "offline"},
            "links": {"carcass": {"mass": 20, "inertia": {"ixx": 0.05, "iyy": 0.05, "izz": 0.05}, "com": [0, 0, 0],
                                  "material": "MDF <wood>", "density": 700, "source": "geometry + MDF prior"}},
            "joints": {"slide": {"damping": 2.0, "friction": 0.5, "stiffness": 0.0, "source": "estimator prior"}},
        }))
        (folder / "report.json").write_text(json.dumps({
            "asset_id": "cab", "escalation": [{"round": 1, "changes": {"slide": {"friction": 1.0}}, "metrics": []}],
            "state": {"method": "local search"},
        }))
    return folder


@pytest.fixture(scope="module")
def report(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("rep")
    ev = evaluate_asset(_drawer(tmp / "cab", True), prompt="A small <cabinet> with its drawer slightly open & smooth.",
                        out_dir=tmp / "out", write_report=True, probes=True)
    return ev, (tmp / "out" / "report.html").read_text()


def test_report_is_self_contained(report):
    _, html = report
    assert html.startswith("<!DOCTYPE html>")
    # no external resources: every src is inline data, no stylesheet or script links
    srcs = re.findall(r'src="([^"]*)"', html)
    assert srcs and all(s.startswith(("data:image/png;base64,", "data:image/svg+xml;base64,")) for s in srcs)
    assert "<link " not in html and "<script" not in html and "http://" not in html and "https://" not in html


def test_report_shows_views_plots_verdicts_probes_and_parameters(report):
    ev, html = report
    # object at its initial state (renders, or the geometry plot until they exist), rest test plots, probe plot
    assert html.count("data:image/png;base64,") + html.count("data:image/svg+xml;base64,") >= 4
    # the figures are SVG documents with the axes' units and the run's data drawn
    figs = [base64.b64decode(s).decode() for s in re.findall(r'src="data:image/svg\+xml;base64,([^"]*)"', html)]
    assert len(figs) >= 3 and all(f.startswith("<svg ") and "</svg>" in f for f in figs)
    assert any("D_pos(t) (mm)" in f and "1 mm threshold" in f for f in figs)  # rest test
    assert any("slide (m)" in f for f in figs)  # joint trajectory
    assert any("root displacement (mm)" in f for f in figs)  # probes
    assert all(re.search(r"<g id=\"(line2d|PathCollection)_\d+\">\s*<path d=", f) for f in figs)  # data drawn in each
    for section in ("Object at its initial state", "Verdicts", "Rest test", "Prompt alignment", "Passive probes",
                    "Physical parameters"):
        assert section in html
    for m in ev.metrics:
        assert f"<td>{m.name}</td>" in html
    assert "D_pos &lt;= 0.001 m and D_ori &lt;= 0.01 rad" in html  # thresholds shown, escaped
    assert "close" in html and "open" in html  # probe rows


def test_report_escapes_user_text(report):
    _, html = report
    assert "A small &lt;cabinet&gt; with its drawer slightly open &amp; smooth." in html
    assert "<cabinet>" not in html
    assert "MDF &lt;wood&gt;" in html


def test_parameter_table_has_value_unit_and_source(report):
    ev, _ = report
    rows = {(r["where"], r["parameter"]): r for r in parameter_rows(ev)}
    assert rows[("global", "scale")]["value"] == 0.8 and rows[("global", "scale")]["source"] == "overlay.json"
    assert rows[("link carcass", "mass")]["unit"] == "kg"
    assert rows[("link carcass", "mass")]["source"] == "geometry + MDF prior"
    assert rows[("joint slide", "damping")]["unit"] == "N*s/m"
    assert rows[("joint slide", "damping")]["source"] == "estimator prior"
    # friction was raised by escalation; the URDF value (1.0) is what is simulated
    fr = rows[("joint slide", "friction")]
    assert fr["value"] == 1.0 and fr["source"].startswith("changed after check round 1") and fr["unit"] == "N"
    assert rows[("joint slide", "initial position")]["source"].startswith("refinement")
    assert rows[("joint slide", "initial position")]["unit"] == "m"


def test_parameter_table_without_overlay_names_engine_defaults(tmp_path):
    f = _drawer(tmp_path / "raw", False)
    (f / "mobility.urdf").write_text((f / "mobility.urdf").read_text().replace(
        '<inertial><mass value="1"/><inertia ixx="0.05" iyy="0.05" izz="0.05" ixy="0" ixz="0" iyz="0"/></inertial>', ""))
    ev = evaluate_asset(f, probes=False)
    rows = {(r["where"], r["parameter"]): r for r in parameter_rows(ev)}
    assert rows[("link drawer", "mass")]["value"] == 1.0
    assert rows[("link drawer", "mass")]["source"].startswith("engine default")
    assert rows[("link carcass", "mass")]["source"] == "URDF <inertial>"
    assert rows[("joint slide", "damping")]["source"] == "URDF <dynamics>"


def test_benchmark_pages(tmp_path):
    records = [
        {"id": "1", "category": "Box", "method": "human", "error": None, "all_pass": True, "penetration": 1.0,
         "penetration_pass": None, "rest_stability": 1e-4, "rest_stability_pass": True, "oscillation": 0.0,
         "oscillation_pass": True, "report": "human/1/report.html", "seconds": 0.4},
        {"id": "1", "category": "Box", "method": "defaults", "error": None, "all_pass": False, "rest_stability": 0.2,
         "rest_stability_pass": False, "report": None},
        {"id": "2", "category": "Box", "method": "direct", "error": "BaselineError: <boom>"},
    ]
    idx = render_benchmark_index(records, {"manifest": "m.csv"})
    assert idx.count("<tr>") == 4  # header + 3 rows
    assert "class='pass'>pass" in idx and "class='fail'>FAIL" in idx
    assert "href='human/1/report.html'" in idx and "&lt;boom&gt;" in idx
    tables = {"all rows": {"human": {"pen_ts_mean": 15.0, "pen_ts_sd": 2.0, "rest_stability_pass": 8 / 9, "rest_n": 9,
                                     "oscillation_pass": 1.0, "osc_n": 9, "errors": 0}}}
    from asset2sim.apps.benchmark.benchmark import RESEARCH_NUMBERS

    page = render_benchmark_summary(tables, RESEARCH_NUMBERS, {"manifest": "m.csv", "methods": ["human"], "seed": 0, "rows": 9})
    assert "15 &plusmn; 2" in page and "88.9%" in page and "Human (GenSim2)" in page and "thesis method" in page


def test_the_media_of_a_refined_folder_present_its_record(tmp_path, demo_root, refine_once):
    """The media phase of a refine's output (``asset2sim report``): its checks run again only to draw the evidence;
    report.html shows the verdict and metrics evaluation.json records and is titled by the refine."""
    from asset2sim.tasks.evaluation.evaluate import recorded_evaluation, write_media

    out = refine_once(demo_root / "box_lid", "a box with its lid slightly open", extras=True, media=False).copy_to(tmp_path / "box")
    recorded = json.loads((out / "evaluation.json").read_text())
    ev = recorded_evaluation(out)
    assert ev.failure_mode == recorded["failure_mode"] and [m.name for m in ev.metrics] == [m["name"] for m in recorded["metrics"]]
    assert ev._runs["pybullet"].trace is not None  # the rest test drawn in the report
    path = write_media(ev, out, clips=False)
    assert path == out / "report.html" and "<h1>asset2sim refine: " in path.read_text()
    assert json.loads((out / "evaluation.json").read_text()) == recorded  # the record is not written again


@needs_shared
def test_a_failing_asset_shows_the_failing_trials_plot_and_frames(tmp_path):
    """The raw trash can (no physics) fails robust rest: its report, titled by
    the command that wrote it, shows each failing trial's plot and the object
    as disturbed, after settling and at the end, with positions in degrees and
    percent open."""
    from asset2sim.tasks.evaluation.evaluate import evaluate_asset
    from asset2sim.tasks.evaluation.failure_evidence import FRAMES

    ev = evaluate_asset(SHARED / "102181", out_dir=tmp_path / "ev", write_report=True, engines=("pybullet",))
    rr = ev.metric("robust_rest")
    assert rr.passed is False
    html = (tmp_path / "ev" / "report.html").read_text()
    assert "<h1>asset2sim evaluate: 102181</h1>" in html and "Why it failed: the evidence" in html
    failing = [name for name, t in rr.details["trials"].items() if t["passed"] is False]
    for name in failing:
        assert f"robust rest, trial {name} (pybullet)" in html and f"alt=\"trial {name}\"" in html
    assert html.count(">as disturbed</figcaption>") == len(failing) and all(f">{c}</figcaption>" in html for c in FRAMES)
    assert " deg from closed (" in html and "% open)" in html  # joint states from their closed ends


@needs_shared
@pytest.mark.slow  # end to end: a dev object refined on its own
def test_a_refine_report_says_what_asset2sim_changed_and_why(tmp_path):
    from asset2sim.tasks.refine import refine_asset

    refine_asset(SHARED / "103275", "I want a slightly open stapler.", tmp_path / "out")
    html = (tmp_path / "out" / "report.html").read_text()
    assert "<h1>asset2sim refine: 103275</h1>" in html and "<h2>What asset2sim changed</h2>" in html
    section = html.split("<h2>What asset2sim changed</h2>")[1].split("<h2>")[0]
    for what in ("scale", "total mass", "joint_1 limits", "joint_1 initial position", "collision pieces", "root"):
        assert f"<td>{what}</td>" in section, what
    assert "input (103275), perspective" in section and "output, perspective" in section  # the input named by its file
    assert "it runs into link_2" in section  # the clipped limit's reason
    assert "the request: slightly open" in section
    assert "deg from closed, " in section and "% open" in section  # the joint state from its closed end
    assert "As asked: every part and state the request names is applied" in html
    assert "Why it failed" not in html  # it passes every tier


@needs_shared
@pytest.mark.slow  # end to end: a dev object evaluated with its report
def test_a_failing_joint_sweep_shows_its_opening_over_time_and_where_it_stalled(tmp_path):
    """The raw two-drawer cabinet (no physics): a drawer does not close back
    under the sweep's drive; the report plots its opening against the lines
    that count and draws it closed, opened and where the closing stalled."""
    ev = evaluate_asset(SHARED / "19179", out_dir=tmp_path / "ev", write_report=True, engines=("pybullet",), probes=False)
    sw = ev.metric("joint_sweep")
    assert sw.passed is False
    html = (tmp_path / "ev" / "report.html").read_text()
    for joint in sw.details["failing"]:
        assert f"joint sweep of {joint} (pybullet)" in html and f"alt=\"sweep {joint}\"" in html
    assert ">closed (start)</figcaption>" in html and "closed as far as it went (" in html


@needs_shared
def test_a_failed_task_attempt_shows_its_numbers_and_where_the_part_was_taken_asked_and_left():
    from asset2sim.tasks.evaluation.failure_evidence import evidence_section
    from asset2sim.engines.source import UrdfFile
    from asset2sim.tasks.geometry.urdf_closed import measure_closed

    urdf = SHARED / "101668" / "mobility.urdf"
    c = measure_closed(UrdfFile(urdf))["joint_2"]
    closed = {"joint_2": {"q_closed": c.q_closed, "direction": c.direction, "open_range": c.open_range}}
    attempt = {"joint": "joint_2", "action": "close", "success": False, "failure": "the object slid before the target was reached",
               "start_fraction": 0.65, "target_fraction": 0.05, "final_fraction": 0.64, "reached": False, "held": False,
               "peak_force_n": 11.7, "root_slide_m": 0.00665, "root_tilt_rad": 1e-4, "force_limited": False}
    seen = []
    html = evidence_section({}, urdf, 1 / 240, lambda svg, alt: "", lambda img, cap: seen.append((img.shape, cap)) or cap,
                            {}, {"attempts": [attempt, {**attempt, "joint": "joint_0", "success": True}]}, closed)
    assert "task: close joint_2: the object slid" in html and "<td>6.65</td>" in html and "joint_0" not in html
    assert [cap for _, cap in seen] == ["taken at (65 % open)", "asked for (5 % open)", "left at (64 % open)"]
    assert all(shape == (200, 200, 3) for shape, _ in seen)


def test_clips_go_to_each_kind_of_part_before_a_second_of_one_kind():
    """Four buttons asked by the task and a door: a button and the door get clips before a second button; without
    a task, one of each kind (door, button, knob) first."""
    from asset2sim.tasks.evaluation.evaluate import clip_joints

    labels = {"door": "door", "b1": "button", "b2": "button", "b3": "button", "b4": "button", "k1": "knob", "u": None}
    assert clip_joints(["b1", "b2", "b3", "b4"], ["door", "b1", "b2", "b3", "b4"], labels)[:4] == ["b1", "door", "b2", "b3"]
    assert clip_joints([], ["door", "b1", "b2", "b3", "b4", "k1"], labels)[:3] == ["door", "b1", "k1"]
    assert clip_joints(["gone"], ["u", "b1"], labels) == ["u", "b1"]  # a task joint without a sweep gets none
