"""The console script: refine and demo end to end, as a user runs them."""

from __future__ import annotations

import json
import os
import subprocess
import sys

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
