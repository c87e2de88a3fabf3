"""Helpers and isolated stage processes end with the process that started
them, even when it is killed with SIGKILL (Linux parent-death signal)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import psutil
import pytest

from asset2sim.flows import lifeline

try:
    from . import flowfakes  # type: ignore[no-redef]
except ImportError:
    import flowfakes  # type: ignore[no-redef]

pytestmark = [pytest.mark.slow, pytest.mark.skipif(not sys.platform.startswith("linux"), reason="parent-death signal is Linux's")]  # end to end: the flows (Prefect, Dask, stage processes)


def _env() -> dict[str, str]:
    env = dict(os.environ)
    paths = [str(Path(flowfakes.__file__).parent), *(p for p in sys.path if p and os.path.isdir(p))]
    env["PYTHONPATH"] = os.pathsep.join(dict.fromkeys(paths))
    return env


def _parent_with_child(tmp_path: Path, body: str) -> tuple[subprocess.Popen, psutil.Process]:
    """Start a Python parent running ``body`` (which writes its child's pid
    to ``pid.txt``); return the parent and the child once it runs."""
    script = tmp_path / "parent.py"
    script.write_text(textwrap.dedent(body))
    parent = subprocess.Popen([sys.executable, str(script), str(tmp_path / "pid.txt")], env=_env(),
                              start_new_session=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.time() + 30
    while time.time() < deadline:
        text = (tmp_path / "pid.txt").read_text() if (tmp_path / "pid.txt").exists() else ""
        if text.strip():
            return parent, psutil.Process(int(text))
        time.sleep(0.05)
    parent.kill()
    pytest.fail("the parent started no child")


def _gone_after_parent_killed(parent: subprocess.Popen, child: psutil.Process) -> None:
    assert child.is_running()
    os.kill(parent.pid, signal.SIGKILL)
    parent.wait(timeout=10)
    try:
        child.wait(timeout=10)
    except psutil.TimeoutExpired:
        child.kill()
        pytest.fail(f"child {child.pid} outlived its killed parent")


def test_launched_program_dies_with_its_killed_parent(tmp_path):
    parent, child = _parent_with_child(tmp_path, """
        import subprocess, sys, time
        from asset2sim.flows import lifeline
        p = subprocess.Popen(lifeline.command([sys.executable, "-c", "import time; time.sleep(120)"]))
        time.sleep(1.0)  # the launcher has exec'd the program by now
        open(sys.argv[1], "w").write(str(p.pid))
        time.sleep(120)
    """)
    assert "time.sleep(120)" in " ".join(child.cmdline())  # the launcher became the program
    _gone_after_parent_killed(parent, child)


def test_isolated_stage_process_dies_with_its_killed_parent(tmp_path):
    parent, child = _parent_with_child(tmp_path, f"""
        import sys, threading, time, psutil
        from asset2sim.flows.isolation import run_isolated
        t = threading.Thread(target=run_isolated, args=("flowfakes:sleep_for", {{"seconds": 120}}),
                             kwargs={{"timeout": 300, "workdir": {str(tmp_path / "work")!r}}}, daemon=True)
        t.start()
        while not psutil.Process().children():
            time.sleep(0.05)
        time.sleep(1.0)  # the child has set its parent-death signal
        open(sys.argv[1], "w").write(str(psutil.Process().children()[0].pid))
        t.join()
    """)
    _gone_after_parent_killed(parent, child)


def test_a_child_whose_parent_already_died_ends_itself():
    out = subprocess.run(
        [sys.executable, "-c", "from asset2sim.flows.lifeline import set_parent_death_signal as s; "
         "import signal, time; s(signal.SIGTERM, expected_parent=1); time.sleep(30)"],
        timeout=30, env=_env(),
    )
    assert out.returncode == -signal.SIGTERM
    assert lifeline.command(["true"])[-2:] == ["--", "true"]
    with pytest.raises(ValueError):
        lifeline.command([])
