"""Two phases of an output: the verdict's files first, the media (renders, clips, report.html) later, on a real dev
object (box 100221) and through the flow's stage functions; the verdict never changes with the media."""

from __future__ import annotations

import json
import logging
import subprocess
import sys
from pathlib import Path

import pandas as pd
import pytest

from asset2sim.output_folder import EVALUATION_NAME, MARKER_NAME, RECORD_NAME, REPORT_HTML_NAME, REPORT_NAME
from asset2sim.output_paths import OutputError
from asset2sim.schemas.config import RefineConfig
from asset2sim.tasks.publish.contract import is_complete
from asset2sim.tasks.publish.media import make_media, media_pending
from asset2sim.tasks.refine import refine_asset
from tests.conftest import NO_SHARED, SHARED as DEV

BOX = DEV / "100221"
PROMPT = "A box with its lid slightly open."
MEDIA = ("views", "clips", REPORT_HTML_NAME)

pytestmark = pytest.mark.skipif(not BOX.is_dir(), reason=NO_SHARED)


def _files(folder: Path) -> set[str]:
    return {p.relative_to(folder).as_posix() for p in folder.rglob("*") if p.is_file()}


@pytest.fixture(scope="module")
def deferred(tmp_path_factory, refine_factory):
    """A copy of the session's refine of the box with its media deferred (the tests below make its media)."""
    shared = refine_factory(BOX, PROMPT, RefineConfig(), media=False)
    return shared.copy_to(tmp_path_factory.mktemp("media") / "box"), shared.result


def test_deferred_refine_writes_the_verdict_and_exports_but_no_media(deferred):
    out, result = deferred
    report = json.loads((out / REPORT_NAME).read_text())
    assert report["media"] == "deferred" and media_pending(out)
    assert not any((out / m).exists() for m in MEDIA)
    assert (out / EVALUATION_NAME).is_file() and (out / "mjcf").is_dir() and (out / "usd").is_dir()
    assert any(n.startswith("media deferred") and f"asset2sim report {result.out_dir}" in n for n in report["notes"])  # the folder refined
    assert is_complete(out, report["input_hash"], report["config_hash"])
    assert result.report.failure_mode == report["failure_mode"]


@pytest.mark.slow  # end to end: a dev object's media phase, and the object refined again with every extra
def test_media_phase_adds_media_keeps_the_verdict_and_the_folder_complete(deferred, tmp_path):
    out, _ = deferred
    before = json.loads((out / REPORT_NAME).read_text())
    evaluation = (out / EVALUATION_NAME).read_bytes()
    made = make_media(out)
    assert set(made) >= {"views", "html"} and (out / REPORT_HTML_NAME).is_file()
    assert sorted(p.name for p in (out / "views").glob("*.png")) == ["back.png", "front.png", "left.png", "perspective.png", "right.png"]
    after = json.loads((out / REPORT_NAME).read_text())
    assert after["media"] == "done" and not media_pending(out)
    assert not any(n.startswith("media deferred") for n in after["notes"])
    for key in ("failure_mode", "metrics", "readiness", "initial_joint_positions", "overlay" if "overlay" in before else "scale"):
        assert after[key] == before[key], key
    assert (out / EVALUATION_NAME).read_bytes() == evaluation  # the verdict's evaluation is not rewritten
    marker = json.loads((out / MARKER_NAME).read_text())
    assert REPORT_HTML_NAME in marker["files"] and any(f.startswith("views/") for f in marker["files"])
    assert is_complete(out, after["input_hash"], after["config_hash"]) and not (out / RECORD_NAME).exists()
    assert make_media(out) == {}  # done: nothing again without force
    # the same files as a refine that made its media at once (timings aside, nothing else differs in name)
    full = tmp_path / "full"
    refine_asset(BOX, PROMPT, full, RefineConfig())
    assert _files(full) == _files(out)
    assert json.loads((full / REPORT_NAME).read_text())["failure_mode"] == after["failure_mode"]


@pytest.mark.slow  # end to end: a dev object refined twice, the second with every extra
def test_a_refine_with_media_resumes_a_deferred_output(tmp_path, refine_factory):
    out = refine_factory(BOX, PROMPT, RefineConfig(), media=False).copy_to(tmp_path / "box")  # a deferred output
    assert not (out / REPORT_HTML_NAME).exists()
    said = []
    result = refine_asset(BOX, PROMPT, out, RefineConfig(), progress=lambda stage, msg: said.append((stage, msg)))
    assert result.skipped and (out / REPORT_HTML_NAME).is_file() and result.report.media == "done"
    assert any(stage == "media" for stage, _ in said)


@pytest.mark.slow  # end to end: the command line
def test_report_command_and_its_errors(deferred, tmp_path):
    out, _ = deferred
    cmd = [sys.executable, "-m", "asset2sim", "report"]
    empty = tmp_path / "empty"
    empty.mkdir()
    bad = subprocess.run(cmd + [str(empty)], capture_output=True, text=True, timeout=120)
    assert bad.returncode == 4 and "OUTPUT_INCOMPLETE" in bad.stderr and str(empty) in bad.stderr
    with pytest.raises(OutputError) as info:
        make_media(empty)
    assert info.value.code == "OUTPUT_INCOMPLETE"
    again = subprocess.run(cmd + [str(out), "--force", "--no-clips"], capture_output=True, text=True, timeout=300)
    assert again.returncode == 0, again.stderr
    assert "html" in again.stdout and json.loads((out / REPORT_NAME).read_text())["media"] == "done"


@pytest.mark.slow  # end to end: a flow run
def test_the_flow_defers_media_to_its_media_phase(tmp_path):
    """``run.extras: deferred``: the refine stage writes no media and the run's media phase makes them in a child
    process; a folder whose media are made already is left alone."""
    from asset2sim.flows.catalog_config import RunSettings
    from asset2sim.flows.refine_flow import media_phase
    from asset2sim.flows.stages import AssetJob, prepare_asset, refine_stage

    settings = RunSettings(extras="deferred")
    assert settings.extras == "deferred"
    with pytest.raises(ValueError):
        RunSettings(extras="later")
    run = tmp_path / "run"
    job = AssetJob(dataset="dev", run_id="r1", asset_id="100221", prompt=PROMPT, asset_dir=str(BOX),
                   out_dir=str(run / "100221"), work_dir=str(run / ".work" / "100221"),
                   metrics_dir=str(run / "_metrics" / "100221"), config=RefineConfig().model_dump(mode="json"),
                   extras=True, media=False, isolation="none")
    refined = refine_stage(job, prepare_asset(job))
    assert refined.status == "ok", refined.error
    out = Path(job.out_dir)
    assert media_pending(out) and not (out / REPORT_HTML_NAME).exists()
    rows = pd.DataFrame({"out_dir": [str(out), str(tmp_path / "missing")], "media": ["deferred", "deferred"]})
    done = media_phase(logging.getLogger("test"), rows, workers=1)
    assert done["media_made"] == 1 and done["media_failed"] == 0 and (out / REPORT_HTML_NAME).is_file()
    assert media_phase(logging.getLogger("test"), rows, workers=1)["media_made"] == 0
