"""The simulators' start-up messages (PyBullet's build-time line on stderr,
SAPIEN's libvulkan warning) are hidden in normal output and shown with
``asset2sim --verbose``."""

from __future__ import annotations

import importlib.util
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from asset2sim.engines.quiet import STARTUP_MESSAGES

BIN = Path(sys.executable).parent


def _env(**extra) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if k != STARTUP_MESSAGES}
    env.update(extra)
    return env


def test_engine_imports_are_quiet_unless_asked():
    code = "from asset2sim.engines.registry import available_engines; print(available_engines())"
    quiet = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=_env(), check=True)
    assert "pybullet" in quiet.stdout
    assert "build time" not in quiet.stdout + quiet.stderr and "libvulkan" not in quiet.stderr
    loud = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=_env(**{STARTUP_MESSAGES: "1"}), check=True)
    assert "pybullet build time" in loud.stdout + loud.stderr
    if importlib.util.find_spec("sapien") is not None:
        assert "libvulkan" in loud.stderr


@pytest.mark.parametrize("verbose", [False, True])
def test_the_command_line_hides_them_unless_verbose(demo_root, tmp_path, verbose):
    asset = demo_root / "box_lid"
    args = [str(BIN / "asset2sim"), *(["--verbose"] if verbose else []), "render", str(asset), "--out", str(tmp_path / "v"),
            "--views", "front", "--size", "32", "32", "--no-sheet"]
    done = subprocess.run(args, capture_output=True, text=True, env=_env())
    assert done.returncode == 0, done.stderr
    assert (tmp_path / "v" / "front.png").is_file()
    assert ("pybullet build time" in done.stdout + done.stderr) is verbose


#: What refine itself prints on stdout: progress lines (``[  0.29s] extract ...``) and the summary's labels.
REFINE_LINE = re.compile(r"^(\[\s*\d+\.\d+s\] |(asset|output|scale|total mass|initial state|task|penetration|stability|oscillation|"
                         r"manipulation|operability|verdict|why it failed|NOT AS ASKED|engine|request|host|media|wall time|skipped|report) )")


@pytest.mark.slow  # end to end: the command line
def test_a_refine_prints_only_its_own_lines(tmp_path):
    """A hand-written MJCF cabinet (primitive geoms: Bullet printed a ``?`` line on stdout for each box or capsule
    whose mesh data was asked) refined from the command line: stdout holds progress and summary lines only, stderr
    nothing (no build line, no libvulkan warning, no library log)."""
    pytest.importorskip("mujoco")
    from tests.formats.test_mjcf_reader import _cabinet_xml

    xml = _cabinet_xml(tmp_path / "in")
    env = _env()
    for name in ("PREFECT_LOGGING_HANDLERS_CONSOLE_LEVEL", "DASK_LOGGING__DISTRIBUTED", "MLFLOW_LOGGING_LEVEL"):
        env.pop(name, None)
    done = subprocess.run([str(BIN / "asset2sim"), "refine", str(xml), "--prompt", "A cabinet, door halfway open.",
                           "--out", str(tmp_path / "out"), "--no-clips"], capture_output=True, text=True, env=env)
    assert done.returncode == 0, done.stderr
    lines = done.stdout.splitlines()
    assert lines and "?" not in lines, done.stdout
    assert [ln for ln in lines if not REFINE_LINE.match(ln)] == [], done.stdout
    assert done.stderr == "", done.stderr
