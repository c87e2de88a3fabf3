"""``asset2sim flow`` on a terminal prints its own lines only: one line per asset and the run's summary on
stdout; the libraries' INFO logs (Prefect's flow and task runs, Dask's ``distributed.*``, MLflow's database set-up),
PyBullet's build line and SAPIEN's libvulkan warning only with ``--verbose``."""

from __future__ import annotations

import os
import re
import subprocess
import sys

try:
    from .conftest import make_project
except ImportError:
    from conftest import make_project

from asset2sim.cli import QUIET_LIBRARY_LOGS
from asset2sim.engines.quiet import STARTUP_MESSAGES

#: Lines of the libraries (any of them fails the test).
THIRD_PARTY = re.compile(r"\| (DEBUG|INFO) +\||\bINFO (mlflow|alembic)|distributed\.|Flow run '|Task run '|pybullet build time|"
                         r"libvulkan|Warning:")
#: The flow command's own stdout: the start line, one line per asset, the summary and the regression check.
FLOW_LINE = re.compile(r"^(run \S+ of dataset |\[\d+/\d+\] |  |regression check|    )")


def test_a_flow_prints_no_third_party_lines(tmp_path):
    root = tmp_path / "proj"
    catalog = make_project(root, {"box_lid": "box_lid"}, catalog_extra={
        "run": {"refine_function": "asset2sim.tasks.refine:refine_asset", "workers": 1, "evaluate": False,
                "time_limit_seconds": 300, "dashboard": False}})
    env = {k: v for k, v in os.environ.items()
           if k not in (STARTUP_MESSAGES, "PREFECT_API_URL", "PREFECT_LOGGING_LEVEL", *QUIET_LIBRARY_LOGS)}
    done = subprocess.run([sys.executable, "-m", "asset2sim", "flow", "--catalog", str(catalog), "--workers", "1"],
                          cwd=root, env=env, capture_output=True, text=True, timeout=420)
    assert done.returncode == 0, done.stderr[-3000:]
    lines = done.stdout.splitlines()
    assert any(ln.startswith("[1/1] box_lid: done") for ln in lines), done.stdout
    assert [ln for ln in lines if not FLOW_LINE.match(ln) or THIRD_PARTY.search(ln)] == [], done.stdout
    assert done.stderr == "", done.stderr[-3000:]
