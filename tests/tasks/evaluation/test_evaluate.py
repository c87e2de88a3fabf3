"""Tests of asset2sim.tasks.evaluation.evaluate on small generated assets built to pass
and to fail each physical metric (primitive geometry, written per test)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from asset2sim.schemas.metrics import METRIC_INFO
from asset2sim.tasks.check.metrics import divergence_check
from asset2sim.tasks.check.verdict import TIERS
from asset2sim.tasks.evaluation.evaluate import EvaluationError, evaluate_asset

from tests.helpers import tree_hashes

# ------------------------------------------------------------------ URDF builders


def inertial(mass, xyz=(0, 0, 0), i=(0.01, 0.01, 0.01)):
    return (
        f'<inertial><origin xyz="{xyz[0]} {xyz[1]} {xyz[2]}"/><mass value="{mass}"/>'
        f'<inertia ixx="{i[0]}" iyy="{i[1]}" izz="{i[2]}" ixy="0" ixz="0" iyz="0"/></inertial>'
    )


def geom(shape, xyz=(0, 0, 0), rpy=(0, 0, 0)):
    o = f'<origin xyz="{xyz[0]} {xyz[1]} {xyz[2]}" rpy="{rpy[0]} {rpy[1]} {rpy[2]}"/>'
    return f"<collision>{o}<geometry>{shape}</geometry></collision><visual>{o}<geometry>{shape}</geometry></visual>"


def box(x, y, z):
    return f'<box size="{x} {y} {z}"/>'


def sphere(r):
    return f'<sphere radius="{r}"/>'


def cylinder(r, length):
    return f'<cylinder radius="{r}" length="{length}"/>'


def link(name, body=""):
    return f'<link name="{name}">{body}</link>'


def joint(name, jtype, parent, child, xyz=(0, 0, 0), axis=(1, 0, 0), lower=None, upper=None, damping=None, friction=None):
    s = f'<joint name="{name}" type="{jtype}"><parent link="{parent}"/><child link="{child}"/>'
    s += f'<origin xyz="{xyz[0]} {xyz[1]} {xyz[2]}"/><axis xyz="{axis[0]} {axis[1]} {axis[2]}"/>'
    if lower is not None:
        s += f'<limit lower="{lower}" upper="{upper}" effort="100" velocity="10"/>'
    if damping is not None or friction is not None:
        s += f'<dynamics damping="{damping or 0}" friction="{friction or 0}"/>'
    return s + "</joint>"


def write_asset(folder: Path, parts, state=None, overlay=None) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "mobility.urdf").write_text('<?xml version="1.0"?><robot name="t">' + "".join(parts) + "</robot>")
    if state is not None:
        (folder / "initial_state.json").write_text(json.dumps({"initial_joint_positions": state}))
    if overlay is not None:
        (folder / "overlay.json").write_text(json.dumps(overlay))
    return folder


def spring_overlay(joint_name, stiffness, reference, damping=0.0, friction=0.0):
    return {
        "scale": 1.0,
        "estimator": {"name": "test"},
        "joints": {joint_name: {"damping": damping, "friction": friction, "stiffness": stiffness, "spring_reference": reference}},
    }


def evaluate(folder, **kw):
    kw.setdefault("probes", False)
    return evaluate_asset(folder, **kw)


# ------------------------------------------------------------------ penetration


@pytest.mark.parametrize("depth", [0.002, 0.01, 0.03])
def test_penetration_of_two_spheres_equals_the_known_overlap(tmp_path, depth):
    # Two sibling links (both children of the base: self-collision applies),
    # spheres r = 0.05 whose centres are 0.1 - depth apart: one contact point
    # of depth `depth`, so Phi = depth.
    f = write_asset(tmp_path / "a", [
        link("base", inertial(5) + geom(box(0.4, 0.2, 0.05))),
        link("a", inertial(0.5) + geom(sphere(0.05))),
        link("b", inertial(0.5) + geom(sphere(0.05))),
        joint("ja", "fixed", "base", "a", xyz=(-0.05, 0, 0.2)),
        joint("jb", "fixed", "base", "b", xyz=(0.05 - depth, 0, 0.2)),
    ])
    m = evaluate(f).metric("penetration")
    assert m.unit == "mm"
    assert m.value == pytest.approx(depth * 1000, abs=0.05)
    (pair,) = m.details["pairs"]
    assert {pair["link_a"], pair["link_b"]} == {"a", "b"}
    assert pair["points"] == 1


def test_penetration_of_two_boxes_sums_over_contact_points(tmp_path):
    d = 0.004
    f = write_asset(tmp_path / "a", [
        link("base", inertial(5) + geom(box(0.4, 0.2, 0.05))),
        link("a", inertial(0.5) + geom(box(0.1, 0.1, 0.1))),
        link("b", inertial(0.5) + geom(box(0.1, 0.1, 0.1))),
        joint("ja", "fixed", "base", "a", xyz=(-0.05, 0, 0.2)),
        joint("jb", "fixed", "base", "b", xyz=(0.05 - d, 0, 0.2)),
    ])
    m = evaluate(f).metric("penetration")
    (pair,) = m.details["pairs"]
    assert pair["max_depth_mm"] == pytest.approx(4.0, abs=0.05)
    # Phi is the sum over the contact points (SPEC), each at the overlap depth
    assert m.value == pytest.approx(pair["points"] * 4.0, abs=0.2)
    assert pair["points"] >= 2


def test_separated_links_and_parent_child_overlap_give_zero_penetration(tmp_path):
    f = write_asset(tmp_path / "a", [
        link("base", inertial(5) + geom(box(0.4, 0.2, 0.05))),
        link("a", inertial(0.5) + geom(sphere(0.05))),
        link("b", inertial(0.5) + geom(sphere(0.05))),
        # b overlaps its parent a by 1 cm: excluded (SPEC: no link-parent pairs)
        joint("ja", "fixed", "base", "a", xyz=(0, 0, 0.2)),
        joint("jb", "fixed", "a", "b", xyz=(0.09, 0, 0)),
    ])
    m = evaluate(f).metric("penetration")
    assert m.value == 0.0 and m.details["pairs"] == []


# ------------------------------------------------------------------ rest stability


def _cylinder(folder, com):
    return write_asset(folder, [link("base", inertial(2, com) + geom(cylinder(0.1, 0.2), rpy=(math.pi / 2, 0, 0)))])


def test_rounded_base_with_one_sided_mass_drifts_and_fails_rest_stability(tmp_path):
    # a cylinder lying on its side with its COM 6 cm off-axis sideways rocks for ever
    ev = evaluate(_cylinder(tmp_path / "a", (0.06, 0, 0)))
    m = ev.metric("rest_stability")
    assert m.passed is False
    assert m.details["D_pos_m"] > 1e-3 and m.details["D_ori_rad"] > 1e-2
    assert ev.metric("divergence").passed  # drifting is not diverging
    assert not ev.passed and "rest_stability@pybullet" in ev.failures


def test_rounded_base_with_low_com_rests_and_passes(tmp_path):
    m = evaluate(_cylinder(tmp_path / "a", (0, 0, -0.06))).metric("rest_stability")
    assert m.passed is True
    assert m.details["D_pos_m"] <= 1e-3 and m.details["D_ori_rad"] <= 1e-2


# ------------------------------------------------------------------ oscillation / joint hold


def _pendulum(folder, q0, damping):
    # heavy base, a bob on a revolute joint beside it, free of the base and the ground
    return write_asset(folder, [
        link("base", inertial(50, i=(1, 1, 1)) + geom(box(0.4, 0.4, 0.1))),
        link("bob", inertial(1, (0, 0, -0.25), (1e-4, 1e-4, 1e-4)) + geom(sphere(0.03), xyz=(0, 0, -0.25))),
        joint("hinge", "revolute", "base", "bob", xyz=(0.3, 0, 0.35), axis=(0, 1, 0), lower=-1.5, upper=1.5,
              damping=damping, friction=0.0),
    ], state={"hinge": q0})


def test_undamped_pendulum_rings_and_fails_oscillation(tmp_path):
    ev = evaluate(_pendulum(tmp_path / "a", 0.3, 0.0))
    m = ev.metric("oscillation")
    assert m.passed is False
    j = m.details["joints"]["hinge"]
    assert j["sign_changes"] >= 3 and j["amplitude"] > 0.05 and j["unit"] == "rad"
    assert ev.metric("state_hold").passed is False


def test_overdamped_pendulum_creeps_without_ringing(tmp_path):
    ev = evaluate(_pendulum(tmp_path / "a", 0.3, 5.0))
    m = ev.metric("oscillation")
    assert m.passed is True
    assert m.details["joints"]["hinge"]["amplitude"] > 0.05  # it moves, but never back and forth
    assert ev.metric("state_hold").passed is False  # ... and does not hold its initial state


def test_pendulum_at_rest_holds_and_passes(tmp_path):
    ev = evaluate(_pendulum(tmp_path / "a", 0.0, 0.0))
    assert ev.metric("oscillation").passed is True
    assert ev.metric("state_hold").passed is True
    assert ev.metric("rest_stability").passed is True


# ------------------------------------------------------------------ ground penetration


def _slab(folder, soft):
    contact = '<contact><stiffness value="500"/><damping value="50"/></contact>' if soft else ""
    return write_asset(folder, [link("base", inertial(2) + geom(box(0.2, 0.2, 0.1)) + contact)])


def test_soft_contact_sinks_into_the_ground_and_fails(tmp_path):
    m = evaluate(_slab(tmp_path / "a", True)).metric("ground_penetration")
    assert m.passed is False and m.value > 5.0 and m.unit == "mm"


def test_rigid_slab_rests_on_the_ground_and_passes(tmp_path):
    m = evaluate(_slab(tmp_path / "a", False)).metric("ground_penetration")
    assert m.passed is True and m.value < 1.0


# ------------------------------------------------------------------ divergence


def _lid(folder, stiffness):
    return write_asset(folder, [
        link("base", inertial(1) + geom(box(0.2, 0.2, 0.1))),
        link("lid", inertial(0.01, (0.1, 0, 0), (1e-6, 1e-6, 1e-6)) + geom(box(0.2, 0.2, 0.01), xyz=(0.1, 0, 0))),
        joint("hinge", "revolute", "base", "lid", xyz=(-0.1, 0, 0.06), axis=(0, -1, 0), lower=0, upper=2.0),
    ], state={"hinge": 0.5}, overlay=spring_overlay("hinge", stiffness, 1.0))


def test_absurd_spring_explodes_and_fails_divergence(tmp_path):
    ev = evaluate(_lid(tmp_path / "a", 1e9))
    m = ev.metric("divergence")
    assert m.passed is False and m.details["reasons"]


def test_springless_lid_does_not_diverge(tmp_path):
    m = evaluate(_lid(tmp_path / "a", 0.0)).metric("divergence")
    assert m.passed is True and m.details["reasons"] == []


def test_divergence_check_flags_nan_jumps_and_speeds():
    dt = 1 / 240
    root = np.zeros((100, 3))
    assert not divergence_check(root, {"j": np.zeros(100)}, {"j": "revolute"}, dt, 0.3)["diverged"]
    r = root.copy()
    r[50] = np.nan
    d = divergence_check(r, {}, {}, dt, 0.3)
    assert d["diverged"] and d["nan"]
    r = root.copy()
    r[60:, 0] = 0.2  # 0.2 m in one step = 48 m/s
    assert "root speed" in divergence_check(r, {}, {}, dt, 0.3)["reasons"][0]
    q = np.zeros(100)
    q[70:] = 1.0  # 240 rad/s
    d = divergence_check(root, {"j": q}, {"j": "revolute"}, dt, 0.3)
    assert d["diverged"] and "joint j" in d["reasons"][0]
    q = np.linspace(0, 0.01, 100)  # prismatic, slow
    assert not divergence_check(root, {"p": q}, {"p": "prismatic"}, dt, 0.3)["diverged"]


# ------------------------------------------------------------------ the evaluation as a whole


def test_every_tier_and_semantic_measure_is_evaluated_and_written(tmp_path):
    """An evaluation measures every metric of the verdict's tiers a free object without a task or request has, and the
    semantic measures; evaluation.json holds them with the verdict."""
    ev = evaluate_asset(_pendulum(tmp_path / "a", 0.0, 1.0), out_dir=tmp_path / "out")
    names = {m.name for m in ev.metrics}
    tiers = {n for t, (ns, _) in TIERS.items() if t not in ("task", "force") for n in ns}
    assert tiers <= names and names <= set(METRIC_INFO)
    assert {"scale_deviation", "initial_joint_deviation", "total_mass", "prompt_alignment"} <= names and "probes" not in names
    data = json.loads((tmp_path / "out" / "evaluation.json").read_text())
    assert data["asset_id"] == "a" and data["initial_state"] == {"hinge": 0.0} and data["failure_mode"] == ev.failure_mode
    assert data["initial_state_source"] == "initial_state.json"
    assert not (tmp_path / "out" / "report.html").exists()


def test_evaluation_is_deterministic(tmp_path):
    f = _pendulum(tmp_path / "a", 0.3, 0.0)
    a, b = evaluate(f), evaluate(f)
    for ma, mb in zip(a.metrics, b.metrics):
        assert ma.name == mb.name and ma.value == mb.value and ma.passed == mb.passed


def test_missing_initial_state_uses_zero_clipped_to_limits(tmp_path):
    f = write_asset(tmp_path / "a", [
        link("base", inertial(5) + geom(box(0.3, 0.3, 0.1))),
        link("lid", inertial(0.2) + geom(box(0.3, 0.3, 0.01), xyz=(0.15, 0, 0))),
        joint("hinge", "revolute", "base", "lid", xyz=(-0.15, 0, 0.06), axis=(0, -1, 0), lower=0.2, upper=1.0, damping=1.0),
    ])
    ev = evaluate(f)
    assert ev.initial_state == {"hinge": 0.2} and ev.initial_state_source.startswith("none")


def test_unavailable_engine_is_reported_not_hidden(tmp_path):
    """An engine that cannot run is reported as not measured in it, as refine reports it; the verdict is PyBullet's."""
    ev = evaluate(_slab(tmp_path / "a", False), engines=("pybullet", "no_such_engine"))
    m = ev.metric("rest_stability", "no_such_engine")
    assert m is not None and m.value is None and m.passed is None and "skipped" in m.details
    assert ev.failure_mode == "none" and ev.passed


def test_bad_inputs_raise_clear_errors(tmp_path):
    with pytest.raises(EvaluationError, match="no such file"):
        evaluate_asset(tmp_path / "missing")
    (tmp_path / "empty").mkdir()
    with pytest.raises(EvaluationError, match="no mobility.urdf"):
        evaluate_asset(tmp_path / "empty")
    bad = tmp_path / "bad"
    bad.mkdir()
    (bad / "mobility.urdf").write_text("<robot name='x'><link name='a'>")
    with pytest.raises(EvaluationError, match="mobility.urdf"):
        evaluate_asset(bad)
    with pytest.raises(ValueError, match="out_dir"):
        evaluate_asset(_slab(tmp_path / "s", False), write_report=True)
    with pytest.raises(EvaluationError, match="reference"):
        evaluate_asset(_slab(tmp_path / "s2", False), reference=tmp_path / "nope")


# ------------------------------------------------------------------ independent re-implementation


def _independent():
    import importlib.util

    path = Path(__file__).resolve().parents[3] / "benchmarks" / "bench_evaluate.py"
    spec = importlib.util.spec_from_file_location("bench_evaluate", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


@pytest.mark.parametrize("case", ["spheres", "rolling", "resting", "ringing", "damped", "soft", "spring"])
def test_independent_reimplementation_agrees(tmp_path, case):
    """docs/design/metrics.md re-implemented with plain pybullet calls gives the same
    numbers and verdicts as evaluate_asset (pass and fail cases)."""
    bench = _independent()
    springs = None
    if case == "spheres":
        f = write_asset(tmp_path / "a", [
            link("base", inertial(5) + geom(box(0.4, 0.2, 0.05))),
            link("a", inertial(0.5) + geom(sphere(0.05))),
            link("b", inertial(0.5) + geom(sphere(0.05))),
            joint("ja", "fixed", "base", "a", xyz=(-0.05, 0, 0.2)),
            joint("jb", "fixed", "base", "b", xyz=(0.04, 0, 0.2)),
        ])
    elif case == "rolling":
        f = _cylinder(tmp_path / "a", (0.06, 0, 0))
    elif case == "resting":
        f = _cylinder(tmp_path / "a", (0, 0, -0.06))
    elif case == "ringing":
        f = _pendulum(tmp_path / "a", 0.3, 0.0)
    elif case == "damped":
        f = _pendulum(tmp_path / "a", 0.3, 5.0)
    elif case == "soft":
        f = _slab(tmp_path / "a", True)
    else:
        f = write_asset(tmp_path / "a", [
            link("base", inertial(3) + geom(box(0.3, 0.3, 0.1))),
            link("lid", inertial(0.2, (0.15, 0, 0), (1e-3, 1e-3, 1e-3)) + geom(box(0.3, 0.3, 0.01), xyz=(0.15, 0, 0.006))),
            joint("hinge", "revolute", "base", "lid", xyz=(-0.15, 0, 0.05), axis=(0, -1, 0), lower=0, upper=2.0, damping=0.01),
        ], state={"hinge": 0.5}, overlay=spring_overlay("hinge", 2.0, 1.2))
        springs = {"hinge": (2.0, 1.2)}
    ev = evaluate(f)
    state = json.loads((f / "initial_state.json").read_text())["initial_joint_positions"] if (f / "initial_state.json").exists() else {}
    ref = bench.independent_measure(f / "mobility.urdf", state, springs)
    assert bench.compare(ev, ref) == []


def test_independent_comparison_reports_disagreements(tmp_path):
    bench = _independent()
    f = _pendulum(tmp_path / "a", 0.3, 0.0)
    ev = evaluate(f)
    ref = bench.independent_measure(f / "mobility.urdf", {"hinge": 0.3})
    assert bench.compare(ev, ref) == []
    assert bench.compare(ev, dict(ref, phi_mm=ref["phi_mm"] + 1.0))[0].startswith("Phi")
    assert any("oscillation verdict" in d for d in bench.compare(ev, dict(ref, osc_pass=not ref["osc_pass"])))
    # a different initial state is a different measurement
    assert bench.compare(ev, bench.independent_measure(f / "mobility.urdf", {"hinge": 0.0}))


def test_evaluate_command_writes_files_and_sets_the_exit_code(tmp_path, capsys):
    from asset2sim.cli import main

    good = _slab(tmp_path / "good", False)
    assert main(["evaluate", str(good), "--out", str(tmp_path / "o1"), "--no-probes"]) == 0
    assert (tmp_path / "o1" / "evaluation.json").is_file() and (tmp_path / "o1" / "report.html").is_file()
    out = capsys.readouterr().out
    assert "good (Generic): interaction-ready" in out and "rest_stability" in out
    assert "verdict      interaction-ready (rest pass" in out  # refine's words
    bad = _slab(tmp_path / "bad", True)
    assert main(["evaluate", str(bad), "--out", str(tmp_path / "o2"), "--no-probes", "--no-report"]) == 1
    assert not (tmp_path / "o2" / "report.html").exists()
    out = capsys.readouterr().out
    assert "ground_penetration" in out and "NOT READY: unstable (ground_penetration@pybullet" in out
    assert main(["evaluate", str(tmp_path / "missing")]) == 2


def test_evaluate_leaves_a_refine_output_as_it_was(demo_root, tmp_path, capsys, refine_once):
    """``asset2sim evaluate OUT`` without ``--out`` writes beside OUT: every
    file of OUT stays byte-equal and the next identical refine is skipped."""
    from asset2sim.cli import main
    from asset2sim.tasks.refine import refine_asset

    out = refine_once(demo_root / "box_lid", "a box with its lid slightly open", extras=False).copy_to(tmp_path / "box")
    before = tree_hashes(out)
    assert main(["evaluate", str(out), "--no-probes"]) in (0, 1)
    assert tree_hashes(out) == before
    assert (tmp_path / "box-evaluation" / "evaluation.json").is_file() and (tmp_path / "box-evaluation" / "report.html").is_file()
    assert str(tmp_path / "box-evaluation" / "evaluation.json") in capsys.readouterr().out
    assert refine_asset(demo_root / "box_lid", "a box with its lid slightly open", out, extras=False).skipped


def test_a_task_naming_one_of_two_drawers_is_executed_on_the_open_one(tmp_path, refine_once):
    """The generated two-drawer cabinet, refined closed, then one drawer set
    open in its initial_state.json: "close the drawer" is executed on that
    drawer only (task_spec.with_work_to_do), "close the drawers" on both."""
    from asset2sim import demo_assets
    from asset2sim.urdf import read_urdf

    res = refine_once(demo_assets.build_two_drawer_cabinet, "A cabinet, closed.", extras=False)
    out = res.copy_to(tmp_path / "out")  # its initial_state.json changed below
    model = read_urdf(out / "mobility.urdf")
    drawers = sorted(j.name for j in model.movable_joints)
    assert len(drawers) == 2
    closed = res.report.closed_positions
    first = model.joint(drawers[0])
    q_open = closed[drawers[0]] + 0.4 * (first.upper - first.lower)  # 40 % open (closed at the lower end)
    assert abs(closed[drawers[0]] - first.lower) < 1e-6
    state_path = out / "initial_state.json"
    state = json.loads(state_path.read_text())
    state["initial_joint_positions"][drawers[0]] = q_open
    state_path.write_text(json.dumps(state))

    ev = evaluate_asset(out, task="close the drawer", probes=False)
    (task,) = [m for m in ev.metrics if m.name == "task_execution"]
    assert [a["joint"] for a in task.details["attempts"]] == [drawers[0]]
    assert any(f"{drawers[1]} already closed at the initial state" in n for n in ev.notes)
    ev = evaluate_asset(out, task="close the drawers", probes=False)
    (task,) = [m for m in ev.metrics if m.name == "task_execution"]
    assert sorted(a["joint"] for a in task.details["attempts"]) == drawers
