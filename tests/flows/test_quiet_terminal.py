"""``asset2sim flow`` on a terminal prints its own lines only: one line per asset and the run's summary on
stdout; the libraries' INFO logs (Prefect's flow and task runs, Dask's ``distributed.*``, MLflow's database set-up),
PyBullet's build line and SAPIEN's libvulkan warning only with ``--verbose``."""

from __future__ import annotations

import os
import re
import subprocess
import sys

import pytest

try:  # package layout or rootdir-on-sys.path layout
    from .flowproject import make_project  # type: ignore[no-redef]
except ImportError:
    from flowproject import make_project  # type: ignore[no-redef]
from asset2sim.cli import QUIET_LIBRARY_LOGS
from asset2sim.engines.quiet import STARTUP_MESSAGES

pytestmark = pytest.mark.slow  # end to end: the flows (Prefect, Dask, stage processes)

#: Lines of the libraries (any of them fails the test).
THIRD_PARTY = re.compile(r"\| (DEBUG|INFO) +\||\bINFO (mlflow|alembic)|distributed\.|Flow run '|Task run '|pybullet build time|"
                         r"libvulkan|Warning:")
#: The flow command's own stdout: the start line, one line per asset, the summary and the regression check.
FLOW_LINE = re.compile(r"^(run \S+ of dataset |\[\d+/\d+\] |  |regression check|    )")


def test_a_flow_prints_no_third_party_lines(tmp_path):
    """... and leaves nothing in a fresh TMPDIR (Dask's lock files were left there)."""
    root, tmpdir = tmp_path / "proj", tmp_path / "tmp"
    tmpdir.mkdir()
    catalog = make_project(root, {"box_lid": "box_lid"}, catalog_extra={
        "run": {"refine_function": "asset2sim.tasks.refine:refine_asset", "workers": 1, "evaluate": False,
                "time_limit_seconds": 300, "dashboard": False}})
    env = {k: v for k, v in os.environ.items()
           if k not in (STARTUP_MESSAGES, "PREFECT_API_URL", "PREFECT_LOGGING_LEVEL", *QUIET_LIBRARY_LOGS)}
    done = subprocess.run([sys.executable, "-m", "asset2sim", "flow", "--catalog", str(catalog), "--workers", "1"],
                          cwd=root, env={**env, "TMPDIR": str(tmpdir)}, capture_output=True, text=True, timeout=420)
    assert list(tmpdir.iterdir()) == []
    assert done.returncode == 0, done.stderr[-3000:]
    lines = done.stdout.splitlines()
    assert any(ln.startswith("[1/1] box_lid: done") for ln in lines), done.stdout
    assert [ln for ln in lines if not FLOW_LINE.match(ln) or THIRD_PARTY.search(ln)] == [], done.stdout
    assert done.stderr == "", done.stderr[-3000:]


def test_a_flow_on_a_full_disk_says_so_in_one_line(tmp_path):
    """The result catalog cannot be written (ENOSPC raised where the run records itself): ``asset2sim flow`` exits 4
    with one ``OUTPUT_WRITE_FAILED [ENOSPC]`` line naming the file, and no traceback of Prefect's or ours."""
    root = tmp_path / "proj"
    catalog = make_project(root, {"box_lid": "box_lid"}, catalog_extra={
        "run": {"refine_function": "asset2sim.tasks.refine:refine_asset", "workers": 1, "evaluate": False,
                "time_limit_seconds": 300, "dashboard": False}})
    code = f"""
import errno, sys
from asset2sim.flows import catalog as c
def full(self, *a, **k):
    raise OSError(errno.ENOSPC, "No space left on device", {str(root / "catalog" / "_run.json")!r})
c.ResultCatalog.write_run_info = full
from asset2sim.cli import main
sys.exit(main(["flow", "--catalog", {str(catalog)!r}, "--workers", "1", "--no-progress"]))
"""
    env = {k: v for k, v in os.environ.items()
           if k not in (STARTUP_MESSAGES, "PREFECT_API_URL", "PREFECT_LOGGING_LEVEL", *QUIET_LIBRARY_LOGS)}
    done = subprocess.run([sys.executable, "-c", code], cwd=root, env=env, capture_output=True, text=True, timeout=420)
    assert done.returncode == 4, (done.stdout[-2000:], done.stderr[-3000:])
    err = [ln for ln in done.stderr.splitlines() if ln.strip()]
    assert len(err) == 1 and err[0].startswith("asset2sim flow: OUTPUT_WRITE_FAILED [ENOSPC]: "), done.stderr[-3000:]
    assert "_run.json" in err[0] and "Traceback" not in done.stderr + done.stdout
