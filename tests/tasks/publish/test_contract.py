"""The output contract's bookkeeping: hashes, completion marker, skip rule, catalog rows."""

from __future__ import annotations

import json
from types import SimpleNamespace

from asset2sim.schemas.config import RefineConfig
from asset2sim.schemas.report import MetricResult, RefineReport
from asset2sim.tasks.ingest.partnet_mobility import ManifestRowError
from asset2sim.tasks.publish.contract import (MARKER_NAME, REPORT_NAME, flow_config_hash, is_complete,
                                              run_hash, write_completion_marker)
from asset2sim.flows.job_records import (JOB_RECORD_NAME, JobRecord, Measurement, Prepared, RefineOutput,
                                         StageRecord, build_manifest_row, build_row, finished_result,
                                         manifest_row_id, refined_output, resumable_output, write_job_record)


def test_hashes_change_with_what_changes_the_result():
    cfg = RefineConfig()
    h = run_hash(cfg, "a laptop", None)
    assert h == run_hash(cfg, "a laptop", None) and len(h) == 16
    assert h != run_hash(cfg, "a closed laptop", None)
    assert h != run_hash(cfg.model_copy(update={"seed": 7}), "a laptop", None)
    kw = dict(refine_function="m:f", evaluate=True, probes=False, extras=True, reference=False, reference_scale=None)
    base = flow_config_hash(h, **kw)
    assert base != flow_config_hash(h, **{**kw, "probes": True}) and base != flow_config_hash("x" * 16, **kw)


def test_marker_covers_every_file_and_the_skip_rule_checks_it(tmp_path):
    out = tmp_path / "out"
    (out / "meshes").mkdir(parents=True)
    (out / "mobility.urdf").write_text("<robot/>")
    (out / "meshes" / "a.obj").write_text("v 0 0 0\n")
    (out / ".x.json.tmp").write_text("torn")
    write_completion_marker(out, "IN", "CFG")
    files = json.loads((out / MARKER_NAME).read_text())["files"]
    assert sorted(files) == ["meshes/a.obj", "mobility.urdf"]
    assert is_complete(out, "IN", "CFG") and not is_complete(out, "IN", "OTHER") and not is_complete(out, "X", "CFG")
    row = {"out_dir": str(out), "refine_config_hash": "CFG"}
    assert finished_result(row, "IN") is row and finished_result(None, "IN") is None
    (out / "meshes" / "a.obj").write_text("v 1 0 0\n")  # a changed file: not complete any more
    assert not is_complete(out, "IN", "CFG") and finished_result(row, "IN") is None


def _job(**kw):
    base = dict(asset_id="lap", prompt="a laptop", category=None, config={"estimator": "offline", "model": None},
                reference_scale=None, code_version="v", run_id="r2", out_dir="/o/lap", evaluate=True)
    return SimpleNamespace(**{**base, **kw})


def _report(failure_mode="none") -> RefineReport:
    return RefineReport(
        asset_id="lap", source="/a", prompt="a laptop", category="Laptop", version="v", input_hash="IN",
        config_hash="RC", estimator="offline", scale=0.5, total_mass=1.25, initial_joint_positions={"j": 0.25},
        metrics=[MetricResult(name="penetration", value=0.5, unit="mm"),
                 MetricResult(name="rest_stability", value=1e-5, unit="m", passed=True, details={"D_pos_m": 1e-5, "D_ori_rad": 2e-4}),
                 MetricResult(name="oscillation", value=0.0, unit="joints", passed=True)],
        failure_mode=failure_mode, stage_seconds={"extract": 0.1},
    )  # fmt: skip


def test_rows_from_typed_stage_records():
    prep = Prepared(ok=True, seconds=0.5, input_hash="IN", config_hash="C", refine_config_hash="RC", category="Laptop", worker="w")
    refined = StageRecord(status="ok", seconds=2.0, value=RefineOutput(report=_report(), out_dir="/o/lap", tokens=0))
    measured = StageRecord(status="ok", seconds=1.0, value=Measurement(columns={"rest_stable": False, "d_pos_m": 0.1, "prompt_alignment": 0.5}))
    row = build_row(_job(), prep, refined, measured, started_at=1.0, finished_at=2.0)
    assert row.status == "done" and row.failure_mode == "none"  # the refine's verdict: the metrics stage never decides again
    assert row.penetration_mm == 0.5 and row.d_pos_m == 0.1 and row.d_ori_rad == 2e-4 and row.prompt_alignment == 0.5
    assert row.scale == 0.5 and row.total_mass_kg == 1.25 and json.loads(row.initial_state) == {"j": 0.25}
    assert json.loads(row.stage_seconds) == {"prepare": 0.5, "refine": 2.0, "refine.extract": 0.1, "metrics": 1.0}
    assert row.wall_seconds == 3.5

    failed = build_row(_job(), prep, StageRecord(status="timeout", seconds=9.0, error="killed"), None)
    assert failed.status == "failed" and failed.failure_mode == "timeout"
    bad = build_row(_job(), Prepared(ok=False, seconds=0.1, failure_mode="invalid_input", error="no mesh"), None, None)
    assert bad.failure_mode == "invalid_input" and bad.error == "prepare: no mesh"
    lost = build_row(_job(), None, None, None)
    assert lost.failure_mode == "crash" and "no result" in lost.error

    earlier = row.model_dump() | {"failure_mode": "none", "source_run": "r1"}
    skipped = build_row(_job(), prep.model_copy(update={"skip": earlier}), None, None)
    assert skipped.status == "skipped" and skipped.source_run == "r1" and skipped.model_queries == 0
    assert skipped.penetration_mm == 0.5 and skipped.failure_mode == "none"


def test_a_complete_folder_of_an_earlier_run_is_resumable_for_the_same_job_only(tmp_path):
    out, work = tmp_path / "run1" / "lap", tmp_path / "run1" / ".work" / "lap"
    out.mkdir(parents=True)
    (out / "mobility.urdf").write_text("<robot/>")
    (out / REPORT_NAME).write_text(_report().model_dump_json())
    write_completion_marker(out, "IN", "RCFG")
    rec = JobRecord(job={"asset_id": "lap", "run_id": "run1", "out_dir": str(out)}, input_hash="IN",
                    config_hash="FCFG", refine_config_hash="RCFG")
    write_job_record(work, rec)
    cands = [JobRecord.model_validate_json((work / JOB_RECORD_NAME).read_bytes()).model_dump(mode="json")]
    assert resumable_output(cands, "IN", "FCFG", "RCFG") == rec
    assert resumable_output(cands, "CHANGED", "FCFG", "RCFG") is None  # another input
    assert resumable_output(cands, "IN", "OTHER", "RCFG") is None  # other flow settings (extras, refine function ...)
    assert resumable_output(cands, "IN", "FCFG", "OTHER") is None  # another request or refine configuration
    assert resumable_output([{"junk": 1}, *cands], "IN", "FCFG", "RCFG") == rec
    value = refined_output(out)  # the refine stage's value, read from the typed report
    assert value.skipped and value.report == _report() and value.out_dir == str(out) and value.tokens == 0
    (out / "mobility.urdf").write_text("<robot name='edited'/>")  # no longer complete
    assert resumable_output(cands, "IN", "FCFG", "RCFG") is None


def test_rows_of_bad_manifest_rows_have_unique_ids_and_their_own_failure_mode():
    taken = {"box", "manifest-line-4"}
    errs = [
        ManifestRowError(3, "big", "MANIFEST_ROW_TOO_LARGE", "m.csv:3 (id big): too long"),
        ManifestRowError(4, "../x", "MANIFEST_INVALID_ID", "m.csv:4: invalid asset id '../x'"),
        ManifestRowError(5, "box", "MANIFEST_DUPLICATE_ID", "m.csv:5: duplicate asset id 'box'"),
        ManifestRowError(6, None, "MANIFEST_MISSING_ID", "m.csv:6: row without id"),
    ]
    ids = [manifest_row_id(e, taken) for e in errs]
    assert ids == ["big", "manifest-line-4-2", "manifest-line-5", "manifest-line-6"]
    row = build_manifest_row(errs[1], asset_id=ids[1], run_id="r1", config={"estimator": "offline"}, code_version="v")
    assert row.status == "failed" and row.failure_mode == "invalid_manifest_row"
    assert row.error.startswith("manifest: MANIFEST_INVALID_ID: m.csv:4") and row.source_run == "r1"


def test_the_row_lists_the_output_folders_clips(tmp_path):
    """The catalog's ``clips`` column: the videos ``clips/clips.json`` lists, relative to the output folder; empty
    without clips, and carried over to a row that reuses an earlier result."""
    from asset2sim.schemas.realism import Clip, ClipSet

    out = tmp_path / "lap"
    (out / "clips").mkdir(parents=True)
    clip = Clip(joint="j", motion="sweep", view="front", video="sweep_00_front.webm", poster="sweep_00_front_poster.png",
                fps=10.0, n_frames=12, duration_s=1.1, width=224, height=168)
    (out / "clips" / "clips.json").write_text(ClipSet(clips=[clip]).model_dump_json())
    prep = Prepared(ok=True, seconds=0.5, input_hash="IN", config_hash="C", refine_config_hash="RC", category="Laptop", worker="w")
    refined = StageRecord(status="ok", seconds=2.0, value=RefineOutput(report=_report(), out_dir=str(out), tokens=0))
    row = build_row(_job(), prep, refined, None)
    assert json.loads(row.clips) == ["clips/sweep_00_front.webm"]
    bare = build_row(_job(), prep, StageRecord(status="ok", seconds=2.0, value=RefineOutput(report=_report(), out_dir=str(tmp_path / "none"), tokens=0)), None)
    assert json.loads(bare.clips) == []
    skipped = build_row(_job(), prep.model_copy(update={"skip": row.model_dump() | {"source_run": "r1"}}), None, None)
    assert json.loads(skipped.clips) == ["clips/sweep_00_front.webm"]
