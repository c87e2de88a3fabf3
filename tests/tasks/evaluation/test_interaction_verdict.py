"""Interaction-readiness under manipulation: the joint sweep and robust rest
run in every engine through the protocol, and the terminal, report.json,
report.html and the exit status give one verdict (tasks.check.verdict)."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

from asset2sim.cli import main
from asset2sim.engines.registry import available_engines
from tests.contract_asset import write_contract_asset
from asset2sim.tasks.evaluation.evaluate import evaluate_asset
from asset2sim.tasks.ingest import partnet_mobility
from tests.conftest import SHARED, needs_shared

ENGINES = tuple(e for e in ("pybullet", "physx", "mujoco") if e in available_engines())


def _badge(html: Path) -> str:
    return re.findall(r"<span class='badge (?:pass|fail)'>([^<]*)<", html.read_text())[0]


def test_manipulation_metrics_run_in_every_installed_engine(tmp_path):
    # the lid held wide open (1.2 rad) by its friction, out of the post's way
    a = write_contract_asset(tmp_path / "a", lid_angle=1.2, post_height=0.0, lid_friction=2.0)
    ev = evaluate_asset(a.root, engines=ENGINES, probes=False)
    for name in ("joint_sweep", "robust_rest"):
        got = {m.engine: m for m in ev.metrics if m.name == name}
        assert set(got) == set(ENGINES), name
        assert all(m.passed for m in got.values()), {e: m.details.get("failures") for e, m in got.items()}
    # every movable joint is swept, not only the task-relevant ones
    assert set(ev.metric("joint_sweep", "pybullet").details["joints"]) == {"lid_hinge", "post_slide"}


def test_a_lid_that_falls_fails_robust_rest_in_every_engine(tmp_path):
    a = write_contract_asset(tmp_path / "a", lid_angle=0.4, post_height=0.0, lid_friction=0.02)
    ev = evaluate_asset(a.root, engines=ENGINES, probes=False)
    assert {m.engine for m in ev.metrics if m.name == "robust_rest" and m.passed is False} == set(ENGINES)
    assert not ev.passed


@pytest.mark.slow  # end to end: the command line, every tier and report.html
def test_demo_is_interaction_ready_on_every_tier_and_says_so_everywhere(tmp_path, capsys):
    out = tmp_path / "demo"
    assert main(["demo", "--out", str(out)]) == 0
    verdict = [ln for ln in capsys.readouterr().out.splitlines() if ln.startswith("verdict")][0]
    report = json.loads((out / "report.json").read_text())
    assert report["failure_mode"] == "none"
    # the demo's manifest gives the task "close the box lid": task execution and force plausibility run too
    assert report["task"] == "close the box lid"
    assert set(report["readiness"]) >= {"rest", "penetration", "sweep", "robust_rest", "task", "force", "request"}
    assert all(v is True for v in report["readiness"].values()), report["readiness"]  # every tier measured and passed
    assert "task pass" in verdict and "force pass" in verdict
    assert "interaction-ready" in verdict and "FAIL" not in verdict
    assert _badge(out / "report.html").startswith("interaction-ready")


@pytest.mark.slow  # end to end: the command line
def test_an_asset_written_but_not_ready_exits_3_and_every_output_agrees(tmp_path, capsys):
    """A latch bar fixed to the body holds the closed lid down: the lid
    cannot be driven open from its closed end (joint sweep) although the
    object rests well, and no other joint's position frees it."""
    a = write_contract_asset(tmp_path / "src", lid_friction=0.02, latch=True)
    (a.root / "initial_state.json").unlink()
    (a.root / "overlay.json").unlink()
    out = tmp_path / "out"
    assert main(["refine", str(a.root), "--prompt", "A box with its lid slightly open.", "--out", str(out)]) == 3
    verdict = [ln for ln in capsys.readouterr().out.splitlines() if ln.startswith("verdict")][0]
    report = json.loads((out / "report.json").read_text())
    ev = json.loads((out / "evaluation.json").read_text())
    assert report["failure_mode"] == "blocked_joint"
    assert report["readiness"]["sweep"] is False
    assert f"NOT READY: {report['failure_mode']}" in verdict and "sweep FAIL" in verdict
    badge = _badge(out / "report.html")
    assert badge.startswith("NOT READY") and "joint_sweep@pybullet" in badge
    assert "joint_sweep@pybullet" in ev["failures"]


@needs_shared
@pytest.mark.parametrize("obj, prompt, task, joints, rule", [
    ("102703", "A very small toilet with its lid fully open.", "close the toilet lid", ["joint_2"], "part label 'lid' in semantics.txt"),
    ("103275", "I want a slightly open stapler.", "press the stapler", ["joint_1"], "whole object: every task-relevant joint"),
])
@pytest.mark.slow  # end to end: dev objects refined and evaluated
def test_the_post_check_and_the_outputs_evaluation_operate_the_same_joints(obj, prompt, task, joints, rule, tmp_path):
    """One verdict without the input beside the output: the output carries
    the input's part labels (semantics.txt) and its evaluation picks the
    task's joints by refine's own rule (a part the task names; else the
    category's task-relevant parts: the stapler's lid, not its body or
    base). Before, the toilet's evaluation fell back to every joint (flush
    lever, pump lid) and the stapler's tipped it over pressing its body
    joint: task_failed, while the post-check said pass."""
    out = tmp_path / "out"
    rc = main(["refine", str(SHARED / obj), "--prompt", prompt, "--task", task, "--out", str(out)])
    assert (out / "semantics.txt").read_text() == partnet_mobility.format_semantics(partnet_mobility.read_semantics(SHARED / obj))
    report = json.loads((out / "report.json").read_text())
    ev = json.loads((out / "evaluation.json").read_text())
    post = [m for m in report["metrics"] if m["name"] == "task_execution" and m["engine"] == "pybullet"][0]
    task_ev = [m for m in ev["metrics"] if m["name"] == "task_execution"][0]
    for m in (post, task_ev):
        assert [a["joint"] for a in m["details"]["attempts"]] == joints and m["details"]["joints_rule"] == rule
    assert report["readiness"]["task"] is post["passed"] is task_ev["passed"]
    assert rc == (0 if report["failure_mode"] == "none" else 3)
