"""The manipulation tiers recorded once and reused only for identical inputs;
the post-check runs the sweep only on a round it may report."""

from __future__ import annotations

import json

import pytest

from tests.conftest import SHARED, needs_shared
from tests.contract_asset import write_contract_asset
from asset2sim.engines.source import SimObject, UrdfFile
from asset2sim.schemas.config import RefineConfig
from asset2sim.tasks.check import postcheck, recorded_runs
from asset2sim.tasks.check.recorded_runs import RecordedRuns
from asset2sim.tasks.check.robust_rest import robust_rest_metric, run_robust_rest
from asset2sim.tasks.check.sweep import run_sweep, sweep_metric
from asset2sim.tasks.evaluation.evaluate import evaluate_asset
from asset2sim.tasks.refine import refine_asset
from asset2sim.tasks.tune.escalation import escalate
from asset2sim.urdf import read_urdf
from tests.tasks.check.failure_assets import build_tall_faucet

CLOSED = {"lid_hinge": (0.0, 1.0, 2.0), "post_slide": (0.0, 1.0, 0.05)}
STATE = {"lid_hinge": 0.4, "post_slide": 0.0}


def test_sweep_is_reused_for_the_same_inputs_and_rerun_for_other_closed_ends(tmp_path):
    a = write_contract_asset(tmp_path, lid_angle=0.4)
    rec = RecordedRuns()
    first = recorded_runs.sweep_run("pybullet", SimObject(UrdfFile(a.urdf), STATE), CLOSED, recorded=rec)
    again = recorded_runs.sweep_run("pybullet", SimObject(UrdfFile(a.urdf), dict(reversed(list(STATE.items())))), CLOSED, recorded=rec)
    assert (rec.hits, rec.misses) == (1, 1)
    assert sweep_metric(again) == sweep_metric(first) == sweep_metric(run_sweep("pybullet", SimObject(UrdfFile(a.urdf), STATE), CLOSED))
    other = {"lid_hinge": (0.0, 1.0, 1.5), "post_slide": (0.0, 1.0, 0.05)}
    shorter = recorded_runs.sweep_run("pybullet", SimObject(UrdfFile(a.urdf), STATE), other, recorded=rec)
    assert (rec.hits, rec.misses) == (1, 2)
    assert shorter.joints[0].open_range == 1.5 != first.joints[0].open_range


def test_robust_rest_is_rerun_when_the_urdf_or_state_changes(tmp_path):
    a = write_contract_asset(tmp_path / "a", lid_angle=0.4)
    rec = RecordedRuns()
    first = recorded_runs.robust_rest_run("pybullet", SimObject(UrdfFile(a.urdf), STATE), recorded=rec)
    again = recorded_runs.robust_rest_run("pybullet", SimObject(UrdfFile(a.urdf), STATE), recorded=rec)
    assert (rec.hits, rec.misses) == (1, 1)
    assert robust_rest_metric(again) == robust_rest_metric(first) == robust_rest_metric(run_robust_rest("pybullet", SimObject(UrdfFile(a.urdf), STATE)))
    again.trials[0].joint_drift.clear()  # a copy: the record is not changed through it
    assert robust_rest_metric(recorded_runs.robust_rest_run("pybullet", SimObject(UrdfFile(a.urdf), STATE), recorded=rec)) == robust_rest_metric(first)
    recorded_runs.robust_rest_run("pybullet", SimObject(UrdfFile(a.urdf), {**STATE, "lid_hinge": 0.5}), recorded=rec)
    assert rec.misses == 2
    # the same path written again with a stiffer hinge: other bytes, another run
    write_contract_asset(tmp_path / "a", lid_angle=0.4, lid_friction=5.0)
    stiff = recorded_runs.robust_rest_run("pybullet", SimObject(UrdfFile(a.urdf), STATE), recorded=rec)
    assert rec.misses == 3
    assert robust_rest_metric(stiff) == robust_rest_metric(run_robust_rest("pybullet", SimObject(UrdfFile(a.urdf), STATE)))


def test_the_declared_root_separates_robust_rest_runs_but_not_sweeps(tmp_path):
    a = write_contract_asset(tmp_path, lid_angle=0.4)
    free, mounted = SimObject(UrdfFile(a.urdf), STATE), SimObject(UrdfFile(a.urdf), STATE, fixed_base=True)
    rec = RecordedRuns()
    assert recorded_runs.robust_rest_run("pybullet", free, recorded=rec).trials
    assert recorded_runs.robust_rest_run("pybullet", mounted, recorded=rec).skipped  # a mounted object is not dropped
    assert (rec.hits, rec.misses) == (0, 2)
    # the sweep holds the root fixed whatever the object declares: one run serves both
    first = recorded_runs.sweep_run("pybullet", free, CLOSED, recorded=rec)
    again = recorded_runs.sweep_run("pybullet", mounted, CLOSED, recorded=rec)
    assert (rec.hits, rec.misses) == (1, 3)
    assert sweep_metric(again) == sweep_metric(first)


def test_sim_object_options_follow_its_root_and_take_changes(tmp_path):
    a = write_contract_asset(tmp_path, lid_angle=0.4)
    state = dict(STATE)
    free = SimObject(UrdfFile(a.urdf), state)
    state["lid_hinge"] = 1.0  # the object keeps its own copy
    assert dict(free.state) == STATE and not isinstance(free.state, dict)
    opts = free.options()
    assert (opts.fixed_base, opts.ground, opts.gravity, opts.initial_state) == (False, True, True, STATE)
    mounted = SimObject(UrdfFile(a.urdf), STATE, fixed_base=True).options()
    assert (mounted.fixed_base, mounted.ground) == (True, False)
    swept = free.options(fixed_base=True, gravity=False, ground=False)
    assert (swept.fixed_base, swept.gravity, swept.ground) == (True, False, False)
    with free.open("pybullet") as session:  # the session starts where the object says
        assert session.joint_positions()["lid_hinge"] == pytest.approx(STATE["lid_hinge"], abs=1e-9)


def _closed(out):
    """Every movable joint closed at its lower limit, opening over its range."""
    return {j.name: (float(j.lower), 1.0, float(j.upper - j.lower))
            for j in read_urdf(out / "mobility.urdf").movable_joints}


@pytest.fixture()
def faucet_out(refine_once):
    """The tall faucet refined (the session's refine that tests/tasks/check/test_mounted_root.py reads too)."""
    return refine_once(build_tall_faucet, "A faucet.", extras=True)


def test_sweep_is_skipped_only_on_a_round_that_is_escalated_whatever_it_says(faucet_out):
    """Free-standing, the tall faucet tips over: the check fails without the
    sweep and escalation changes the overlay, so while the loop escalates the
    sweep is not run, nor are the other engines (the faucet already fails in
    PyBullet); everything escalation reads is the same either way, and on
    the last round (not escalated) the sweep and the other engines are
    measured."""
    out, ov = faucet_out.out_dir, faucet_out.overlay.model_copy(update={"mounting": None})
    state = json.loads((out / "initial_state.json").read_text())["initial_joint_positions"]
    closed = _closed(out)
    cfg = RefineConfig()
    rec = RecordedRuns()
    def escalated(chk):  # as refine's loop: another round whenever escalation changes something
        return bool(escalate(ov, chk, cfg.escalation_factor, {}, {}, {}).changes)

    obj = postcheck.overlay_object(UrdfFile(out / "mobility.urdf"), state, ov, cfg.sim)
    early = postcheck.run_post_check(obj, cfg, closed=closed, escalated=escalated, recorded=rec)
    last = postcheck.run_post_check(obj, cfg, closed=closed, escalated=lambda chk: False, recorded=rec)
    assert not early.passed and not last.passed
    for name in ("joint_sweep", "operability"):  # the sweep and the hand run together, or neither
        assert early.metric(name).passed is None and "not_run" in early.metric(name).details
        assert last.metric(name).passed is not None and "not_run" not in last.metric(name).details
    skipped = ("joint_sweep", "operability")
    assert [m for m in early.metrics if m.name not in skipped] == [m for m in last.metrics if m.name not in skipped]
    assert postcheck.sweep_not_run(early.metrics) and not postcheck.sweep_not_run(last.metrics)
    others = [e for e in cfg.engines if e != "pybullet"]
    assert early.engine_results == {} and sorted(last.engine_results) == sorted(others)
    assert escalate(ov, early, cfg.escalation_factor, {}, {}, {}) == escalate(ov, last, cfg.escalation_factor, {}, {}, {})
    assert rec.hits == 1  # robust rest of the same files taken from the first check


def test_an_output_read_back_is_checked_as_the_post_check_checked_it(faucet_out):
    """The output evaluated afresh (``asset2sim evaluate``: its closed ends, state, springs and root read from its
    files) measures the manipulation tiers the post-check measures on the same object."""
    out = faucet_out.out_dir
    ov = faucet_out.overlay
    state = json.loads((out / "initial_state.json").read_text())["initial_joint_positions"]
    closed = {n: (c["q_closed"], c["direction"], c["open_range"]) for n, c in faucet_out.report.closed_ends.items()}
    check = postcheck.run_post_check(postcheck.overlay_object(UrdfFile(out / "mobility.urdf"), state, ov, RefineConfig().sim),
                                     RefineConfig(), closed=closed, category=faucet_out.report.category)
    fresh = evaluate_asset(out, probes=False)
    pick = lambda ms: [m for m in ms if m.name in ("joint_sweep", "robust_rest")]  # noqa: E731
    assert pick(check.metrics) == pick(fresh.metrics) and len(pick(check.metrics)) == 2


def test_task_attempt_is_reused_for_the_same_inputs_and_rerun_when_one_differs(tmp_path):
    """The task tier's gripper attempt (``recorded_runs.task_run``) comes from the record only when the files, state,
    joints with their closed ends, actions, targets and hold rule are the same; what it reports is what a fresh
    attempt measures."""
    from asset2sim.tasks.check.task_execution import run_task, task_metric

    a = write_contract_asset(tmp_path, lid_angle=0.4)
    lid = {"lid_hinge": CLOSED["lid_hinge"]}
    rec = RecordedRuns()
    first = recorded_runs.task_run("pybullet", SimObject(UrdfFile(a.urdf), STATE), lid, actions=("open",), recorded=rec)
    again = recorded_runs.task_run("pybullet", SimObject(UrdfFile(a.urdf), dict(reversed(list(STATE.items())))), lid, actions=("open",), recorded=rec)
    assert (rec.hits, rec.misses) == (1, 1)
    fresh = run_task("pybullet", SimObject(UrdfFile(a.urdf), STATE), lid, actions=("open",))
    assert task_metric(again) == task_metric(first) == task_metric(fresh)
    assert again.attempts[0].trace["t"] == fresh.attempts[0].trace["t"]  # the motion the clips replay, too
    again.attempts[0].notes.append("changed")  # a copy: the record is not changed through it
    assert recorded_runs.task_run("pybullet", SimObject(UrdfFile(a.urdf), STATE), lid, actions=("open",), recorded=rec).attempts[0].notes == first.attempts[0].notes
    for changed in ({"targets": {"open": 0.5}}, {"hold_required": {"lid_hinge": False}}, {"actions": ("close", "open")}):
        recorded_runs.task_run("pybullet", SimObject(UrdfFile(a.urdf), STATE), lid, **{"actions": ("open",), **changed}, recorded=rec)
    other_end = {"lid_hinge": (0.0, 1.0, 1.5)}
    recorded_runs.task_run("pybullet", SimObject(UrdfFile(a.urdf), STATE), other_end, actions=("open",), recorded=rec)
    assert (rec.hits, rec.misses) == (2, 5)


@needs_shared
def test_refines_evaluation_takes_the_post_checks_task_attempt(tmp_path):
    """Door 8877 refined with its manifest row's task: the gripper's attempt is simulated in the post-check's rounds
    only (refine's evaluation presents the record), and the report's task metric is what evaluating the output afresh
    measures."""
    import csv
    import traceback

    from asset2sim.tasks.check import task_execution

    row = next(r for r in csv.DictReader(open(SHARED / "manifest.csv")) if r["id"] == "8877")
    callers = []
    real = task_execution.run_task

    def counted(*args, **kw):
        callers.append({f.name for f in traceback.extract_stack()})
        return real(*args, **kw)

    task_execution.run_task = counted
    try:
        res = refine_asset(SHARED / "8877", row["prompt"], tmp_path / "out", task=row["task"], reference=SHARED / "8877", media=False)
    finally:
        task_execution.run_task = real
    assert callers and all("run_task_tier" in c for c in callers) and len(callers) == len(res.report.escalation)  # once per round
    ev = json.loads((res.out_dir / "evaluation.json").read_text())
    fresh = evaluate_asset(res.out_dir, task=row["task"], prompt=row["prompt"], reference=SHARED / "8877", probes=False)
    pick = lambda ms: [(m["value"], m["passed"], m["details"].get("attempts")) for m in ms  # noqa: E731
                       if m["name"] == "task_execution"]
    assert pick(ev["metrics"]) and pick(ev["metrics"]) == pick([m.model_dump(mode="json") for m in fresh.metrics])
