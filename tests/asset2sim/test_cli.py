"""The console script: refine and demo end to end, as a user runs them, and
the exit statuses of the top-level handler (one line, code and path; a
traceback only with --debug)."""

from __future__ import annotations

import errno
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from asset2sim import atomic, demo_assets
from asset2sim.cli import main
from asset2sim.tasks import refine as refine_mod
from asset2sim.tasks.interpret.request import MAX_REQUEST_CHARS
from tests.conftest import SHARED, needs_shared


def run(*args, timeout=600):
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    return subprocess.run([sys.executable, "-m", "asset2sim", *args], capture_output=True, text=True, timeout=timeout, env=env)


def test_demo_runs_without_data(tmp_path):
    out = tmp_path / "demo"
    p = run("demo", "--out", str(out), "--no-extras")
    assert p.returncode == 0, p.stderr
    assert "interaction-ready" in p.stdout
    for stage in ("extract", "analyze", "refine_state", "post_check"):
        assert stage in p.stdout
    assert json.loads((out / "report.json").read_text())["failure_mode"] == "none"


@needs_shared
def test_refine_command_prints_summary_and_writes_contract(tmp_path):
    out = tmp_path / "stapler"
    p = run("refine", str(SHARED / "103275"), "--prompt", "I want a slightly open stapler.", "--out", str(out))
    assert p.returncode == 0, p.stderr
    for word in ("scale", "total mass", "initial state", "penetration", "stability"):
        assert word in p.stdout
    for name in ("mobility.urdf", "initial_state.json", "overlay.json", "report.json"):
        assert (out / name).is_file()


def test_refine_bad_input_exits_nonzero_with_named_error(tmp_path):
    bad = tmp_path / "bad"
    bad.mkdir()
    (bad / "mobility.urdf").write_text("<robot name='x'><link name='a'/><joint name='j' type='revolute'><parent link='a'/><child link='missing'/></joint></robot>")
    p = run("refine", str(bad), "--out", str(tmp_path / "o"))
    assert p.returncode != 0
    assert "invalid_input" in p.stderr and "mobility.urdf" in p.stderr


# ------------------------------------------------------------------ exit statuses (in process)

PROMPT = "A small box with its lid slightly open."


@pytest.fixture()
def box(tmp_path):
    return demo_assets.build_box_with_lid(tmp_path / "in" / "box_lid")


def _one_line(err: str) -> str:
    lines = [ln for ln in err.splitlines() if ln.startswith("asset2sim ")]
    assert len(lines) == 1, err
    assert "Traceback" not in err
    return lines[0]


@pytest.mark.parametrize(
    "where, code",
    [("input", "OUTPUT_IS_INPUT"), ("inside", "OUTPUT_INSIDE_INPUT"), ("parent", "OUTPUT_CONTAINS_INPUT"), ("file", "OUTPUT_NOT_A_FOLDER"), ("devnull", "OUTPUT_NOT_A_FOLDER")],
)
def test_output_location_problems_exit_4_with_code_and_path(box, tmp_path, capsys, where, code):
    (tmp_path / "f").write_text("x")
    out = {"input": box, "inside": box / "o", "parent": box.parent, "file": tmp_path / "f", "devnull": Path("/dev/null")}[where]
    before = atomic.tree_hashes(tmp_path)
    assert main(["refine", str(box), "--out", str(out), "--no-extras", "-q"]) == 4
    line = _one_line(capsys.readouterr().err)
    assert code in line and str(out) in line
    assert atomic.tree_hashes(tmp_path) == before


def test_foreign_files_need_overwrite(box, tmp_path, capsys):
    out = tmp_path / "out"
    out.mkdir()
    (out / "keep.txt").write_text("mine")
    assert main(["refine", str(box), "--prompt", PROMPT, "--out", str(out), "--no-extras", "-q"]) == 4
    line = _one_line(capsys.readouterr().err)
    assert "OUTPUT_NOT_EMPTY" in line and "keep.txt" in line and "--overwrite" in line
    assert main(["refine", str(box), "--prompt", PROMPT, "--out", str(out), "--no-extras", "-q", "--overwrite"]) == 0
    assert (out / "keep.txt").read_text() == "mine" and (out / "mobility.urdf").is_file()


def test_invalid_input_exits_1_and_long_request_2(box, tmp_path, capsys):
    bad = tmp_path / "bad"
    bad.mkdir()
    (bad / "mobility.urdf").write_text("<robot name='x'><link name='a'/><link name='b'/></robot>")
    assert main(["refine", str(bad), "--out", str(tmp_path / "o1"), "--no-extras"]) == 1
    line = _one_line(capsys.readouterr().err)
    assert "invalid_input" in line and str(bad) in line
    assert main(["refine", str(box), "--prompt", "x" * (MAX_REQUEST_CHARS + 1), "--out", str(tmp_path / "o2"), "--no-extras"]) == 2
    assert "REQUEST_TOO_LONG" in _one_line(capsys.readouterr().err)
    assert not (tmp_path / "o2").exists()  # refused before any work


def test_written_but_not_interaction_ready_exits_3(box, tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(refine_mod, "post_check_failure_mode", lambda check: "unstable")
    assert main(["refine", str(box), "--prompt", PROMPT, "--out", str(tmp_path / "o"), "--no-extras", "-q"]) == 3
    assert "FAILED: unstable" in capsys.readouterr().out
    assert (tmp_path / "o" / "mobility.urdf").is_file()


def test_unwritable_output_exits_4(box, tmp_path, capsys, monkeypatch):
    def read_only(path):
        raise OSError(errno.EROFS, "Read-only file system", str(path))

    monkeypatch.setattr(atomic, "_create_temp", read_only)
    assert main(["refine", str(box), "--prompt", PROMPT, "--out", str(tmp_path / "o"), "--no-extras", "-q"]) == 4
    line = _one_line(capsys.readouterr().err)
    assert "OUTPUT_WRITE_FAILED [EROFS]" in line and str(tmp_path / "o") in line


def test_internal_error_exits_70_with_a_log_and_traceback_only_with_debug(box, tmp_path, capsys, monkeypatch):
    monkeypatch.setenv("ASSET2SIM_LOG_DIR", str(tmp_path / "logs"))

    def boom(*a, **k):
        raise ZeroDivisionError("a bug")

    monkeypatch.setattr(refine_mod, "refine_asset", boom)
    assert main(["refine", str(box), "--out", str(tmp_path / "o")]) == 70
    line = _one_line(capsys.readouterr().err)
    assert "INTERNAL_ERROR" in line and "ZeroDivisionError" in line
    (log,) = (tmp_path / "logs").iterdir()
    assert str(log) in line and "Traceback" in log.read_text() and "a bug" in log.read_text()
    assert main(["refine", str(box), "--out", str(tmp_path / "o"), "--debug"]) == 70
    assert "Traceback" in capsys.readouterr().err
    assert main(["--debug", "refine", str(box), "--out", str(tmp_path / "o")]) == 70
    assert "Traceback" in capsys.readouterr().err
