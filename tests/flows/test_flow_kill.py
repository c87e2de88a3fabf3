"""A flow run killed (SIGKILL, the whole process group) after k of n assets
finished redoes exactly the n - k others on rerun (an asset whose folder was
complete counts as finished even when its catalog row was not yet written),
and leaves no torn catalog; a flow driver killed alone with SIGKILL leaves
no process behind (Prefect server, Dask workers, isolated stages)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

from pathlib import Path

import psutil
import pytest

from asset2sim.flows.catalog import ResultCatalog
from asset2sim.flows.catalog_config import load_catalog
from asset2sim.output_folder import MARKER_NAME

pytestmark = pytest.mark.slow  # end to end: the flows (Prefect, Dask, stage processes)

try:
    from . import flowfakes  # type: ignore[no-redef]
    from .flowproject import FAKE_REFINE, make_project
except ImportError:
    import flowfakes  # type: ignore[no-redef]
    from flowproject import FAKE_REFINE, make_project

ASSETS = {a: a for a in ("box_lid", "cabinet_2drawer", "laptop", "microwave", "trash_can")}


def _asset_rows(catalog_root, run=None):
    files = [p for p in catalog_root.rglob("*.parquet") if not p.name.startswith("_")]
    if run is not None:
        files = [p for p in files if f"run={run}" in str(p)]
    return files


def test_flow_killed_after_k_of_n_redoes_n_minus_k(tmp_path, prefect_server):
    root = tmp_path / "proj"
    catalog = make_project(
        root,
        ASSETS,
        catalog_extra={
            "run": {
                "refine_function": "asset2sim.tasks.refine:refine_asset",  # the real pipeline
                "workers": 1,
                "evaluate": False,
                "time_limit_seconds": 300,
            },
            # other work may edit the package source between the two runs: the rerun must not redo
            # finished assets for that (code_change: rerun would, by design)
            "results": {"code_change": "keep"},
        },
    )
    cat_root = root / "catalog"
    env = dict(os.environ)
    env.pop("PREFECT_API_URL", None)  # the CLI run starts its own Prefect state under the project
    proc = subprocess.Popen(
        [sys.executable, "-m", "asset2sim", "flow", "--catalog", str(catalog), "--workers", "1"],
        cwd=root,
        env=env,
        start_new_session=True,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    deadline = time.time() + 420
    try:
        while time.time() < deadline and proc.poll() is None and not _asset_rows(cat_root):
            time.sleep(0.1)
    finally:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait(timeout=60)
    # the stage processes (sessions of their own, forked at any moment) end with their lifeline a moment later,
    # and one may finish its asset meanwhile: what the killed run finished is read once every process working
    # in the project is gone, as the rerun finds it
    deadline = time.time() + 30
    while time.time() < deadline and _working_in(root):
        time.sleep(0.2)
    assert not _working_in(root), "the killed run's processes outlived their lifeline"
    rows = _asset_rows(cat_root)
    if not rows:
        pytest.fail("the killed run finished no asset within the time allowed")
    cat = load_catalog(catalog)
    first = ResultCatalog(cat.catalog_root).read("gen")  # every row must still be readable: no torn file
    done_first = {r["asset_id"] for r in first.to_dict("records") if r["status"] == "done"}
    (killed_run,) = {r["run"] for r in first.to_dict("records")}
    # an asset may have completed its folder (marker written) without its row: finished work too
    complete_first = {a for a in ASSETS if (cat.output_root / "gen" / killed_run / a / MARKER_NAME).is_file()}
    finished_first = done_first | complete_first
    k, n = len(finished_first), len(ASSETS)
    assert 0 < len(done_first) and k < n, f"kill came too late or too early: k={k}"

    from asset2sim.flows.refine_flow import run_refine_flow

    summary = run_refine_flow(catalog, workers=1)
    rows2 = {r["asset_id"]: r for r in ResultCatalog(cat.catalog_root).read("gen", summary["run"]).to_dict("records")}
    redone = {a for a, r in rows2.items() if r["status"] != "skipped"}
    assert redone == set(ASSETS) - finished_first
    assert summary["skipped"] == k
    # the killed run's catalog now holds a row for every asset it finished
    killed_rows = ResultCatalog(cat.catalog_root).read("gen", killed_run).to_dict("records")
    assert {r["asset_id"] for r in killed_rows if r["status"] == "done"} == finished_first


def _working_in(folder: Path) -> list[int]:
    """Processes other than this one whose working folder is ``folder`` or inside it."""
    out = []
    for p in psutil.process_iter():
        try:
            if p.pid != os.getpid() and p.status() != psutil.STATUS_ZOMBIE and Path(p.cwd()).is_relative_to(folder):
                out.append(p.pid)
        except (psutil.Error, OSError):
            pass
    return out


def _descendants(pid: int, seen: dict[int, tuple[float, str]]) -> None:
    try:
        for c in psutil.Process(pid).children(recursive=True):
            try:
                seen[c.pid] = (c.create_time(), " ".join(c.cmdline())[:200])
            except psutil.Error:
                pass
    except psutil.Error:
        pass


def _alive(seen: dict[int, tuple[float, str]]) -> dict[int, str]:
    out = {}
    for pid, (created, cmd) in seen.items():
        try:
            p = psutil.Process(pid)
            if p.create_time() == created and p.status() != psutil.STATUS_ZOMBIE:
                out[pid] = cmd
        except psutil.Error:
            pass
    return out


def test_killed_flow_driver_leaves_no_process_behind(tmp_path):
    """``asset2sim flow`` on generated assets (two of them hang in their
    isolated refine process, forked from their worker's stage server), its driver alone killed with SIGKILL mid-run:
    within 20 s no process it started, directly or not, is left."""
    root = tmp_path / "proj"
    catalog = make_project(
        root,
        {"box_lid": "box_lid", "hang_a": "box_lid", "hang_b": "box_lid"},
        catalog_extra={"run": {"refine_function": FAKE_REFINE, "workers": 2, "evaluate": False,
                               "time_limit_seconds": 600}},
    )
    env = dict(os.environ)
    env.pop("PREFECT_API_URL", None)  # the driver starts its own Prefect server
    env["PYTHONPATH"] = os.pathsep.join([str(Path(flowfakes.__file__).parent), env.get("PYTHONPATH", "")])
    proc = subprocess.Popen(
        [sys.executable, "-m", "asset2sim", "flow", "--catalog", str(catalog)],
        cwd=root, env=env, start_new_session=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
    )
    seen: dict[int, tuple[float, str]] = {}
    try:
        deadline = time.time() + 120
        while time.time() < deadline and proc.poll() is None:
            _descendants(proc.pid, seen)
            # per worker its stage server and the child forked for the hanging stage
            if sum("asset2sim.flows.forkserver" in cmd for cmd in _alive(seen).values()) >= 4:
                break
            time.sleep(0.2)
        time.sleep(0.5)
        _descendants(proc.pid, seen)
        kinds = " ".join(seen[p][1] for p in _alive(seen))
        assert proc.poll() is None and "asset2sim.flows.forkserver" in kinds, "the flow did not reach its stages in time"
        assert "uvicorn" in kinds and "multiprocessing" in kinds  # the Prefect server and the Dask workers
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(timeout=30)
        deadline = time.time() + 20
        while time.time() < deadline and _alive(seen):
            time.sleep(0.2)
        assert _alive(seen) == {}
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait(timeout=30)
        for pid in _alive(seen):  # leave nothing behind whatever the outcome
            try:
                psutil.Process(pid).kill()
            except psutil.Error:
                pass
