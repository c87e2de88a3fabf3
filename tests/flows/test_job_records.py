"""The catalog row's post-check rounds: how many rounds a refine ran and what started each one after the first,
read from the report's escalation; a skipped row carries the rounds of the result it reuses."""

from __future__ import annotations

import json

from asset2sim.flows.job_records import Prepared, RefineOutput, StageRecord, build_row, extra_rounds
from asset2sim.flows.stages import AssetJob
from asset2sim.schemas.catalog import CatalogRow
from asset2sim.schemas.report import EscalationRound, MetricResult, RefineReport


def _rest(passed: bool, failing: tuple[str, ...] = ()) -> MetricResult:
    trials = {t: {"name": t, "passed": t not in failing} for t in ("drop", "tilt+x", "tilt+y", "nudge")}
    return MetricResult(name="robust_rest", value=None, unit="trials", passed=passed, details={"trials": trials})


def _report(rounds: list[EscalationRound]) -> RefineReport:
    return RefineReport(asset_id="a", source="/in/a", prompt="A box.", category="Box", version="0", input_hash="i",
                        config_hash="c", estimator="offline", scale=1.0, total_mass=1.0, initial_joint_positions={},
                        metrics=rounds[-1].metrics if rounds else [], escalation=rounds)


def _job() -> AssetJob:
    return AssetJob(dataset="d", run_id="r", asset_id="a", prompt="A box.", asset_dir="/in/a", out_dir="/out/a",
                    work_dir="/w/a", metrics_dir="/m/a", evaluate=False)


def _row(report: RefineReport) -> CatalogRow:
    refined = StageRecord(status="ok", value=RefineOutput(report=report, out_dir="/out/a"), seconds=1.0)
    return build_row(_job(), Prepared(ok=True, seconds=0.1), refined, None)


def test_rounds_and_what_started_each_extra_round():
    sweep = MetricResult(name="joint_sweep", value=1.0, unit="fraction", passed=False)
    rounds = [
        EscalationRound(round=0, metrics=[_rest(False, ("tilt+y", "drop")), sweep], reason="initial post-check"),
        EscalationRound(round=1, metrics=[_rest(True)], changes={"j": {"friction": 0.2}}, reason="friction up"),
        EscalationRound(round=2, metrics=[_rest(True)], reason="the last round's setting checked again with the joint sweep"),
    ]
    row = _row(_report(rounds))
    assert row.postcheck_rounds == 3
    assert json.loads(row.extra_rounds) == [
        {"round": 1, "after": ["robust_rest(pybullet): drop, tilt+y", "joint_sweep(pybullet)"], "reason": "friction up"},
        {"round": 2, "after": [], "reason": "the last round's setting checked again with the joint sweep"},
    ]


def test_a_first_post_check_that_decided_is_one_round_and_no_extra():
    row = _row(_report([EscalationRound(round=0, metrics=[_rest(True)], reason="initial post-check")]))
    assert row.postcheck_rounds == 1 and json.loads(row.extra_rounds) == []
    assert extra_rounds(_report([])) == []
    assert _row(_report([])).postcheck_rounds is None  # no post-check recorded: unknown, not zero


def test_a_skipped_row_keeps_the_rounds_of_the_result_it_reuses():
    done = _row(_report([EscalationRound(round=0, metrics=[_rest(False, ("nudge",))]),
                         EscalationRound(round=1, metrics=[_rest(True)], reason="damping up")]))
    prev = {**done.model_dump(mode="json"), "run": "earlier"}
    row = build_row(_job(), Prepared(ok=True, seconds=0.1, skip=prev), None, None)
    assert row.status == "skipped" and row.postcheck_rounds == 2 and row.extra_rounds == done.extra_rounds


def test_a_published_rows_clips_are_read_before_the_local_copy_goes(tmp_path):
    """With an output store the row's ``out_dir`` is the store's URI; the clips column comes from the worker's folder,
    read by the publish stage before it removes the local copy."""
    from asset2sim import atomic
    from asset2sim.flows.stages import publish_stage
    from asset2sim.schemas.realism import Clip, ClipSet

    out = tmp_path / "work" / "a"
    (out / "clips").mkdir(parents=True)
    (out / "clips" / "sweep_00_front.webm").write_bytes(b"webm")
    clip = Clip(joint="j", motion="sweep", view="front", video="sweep_00_front.webm", poster="p.png", fps=30.0,
                n_frames=2, duration_s=0.1, width=8, height=8)
    atomic.write_json(out / "clips" / "clips.json", ClipSet(clips=[clip]).model_dump(mode="json"))
    job = AssetJob(dataset="d", run_id="r", asset_id="a", prompt="A box.", asset_dir="/in/a", out_dir=str(out),
                   work_dir=str(tmp_path / "w"), metrics_dir=str(tmp_path / "m"), out_uri=str(tmp_path / "store" / "a"))
    refined = StageRecord(status="ok", value=RefineOutput(report=_report([]), out_dir=str(out)))
    published = publish_stage(job, refined)
    assert published.status == "ok" and published.value["clips"] == ["clips/sweep_00_front.webm"]
    assert (tmp_path / "store" / "a" / "clips" / "sweep_00_front.webm").is_file()
