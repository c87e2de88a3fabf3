"""The simulators' start-up messages (PyBullet's build-time line on stderr,
SAPIEN's libvulkan warning) are hidden in normal output and shown with
``asset2sim --verbose``."""

from __future__ import annotations

import importlib.util
import os
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
