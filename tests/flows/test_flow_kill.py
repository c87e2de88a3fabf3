"""A flow run killed (SIGKILL, the whole process group) after k of n assets
finished redoes exactly the n - k others on rerun, and leaves no torn catalog."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

import pytest

from asset2sim.catalog import ResultCatalog, load_catalog

try:
    from .conftest import make_project
except ImportError:
    from conftest import make_project

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
            }
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
    rows = _asset_rows(cat_root)
    if not rows:
        pytest.fail("the killed run finished no asset within the time allowed")
    cat = load_catalog(catalog)
    first = ResultCatalog(cat.catalog_root).read("gen")  # every row must still be readable: no torn file
    done_first = {r["asset_id"] for r in first.to_dict("records") if r["status"] == "done"}
    k, n = len(done_first), len(ASSETS)
    assert 0 < k < n, f"kill came too late or too early: k={k}"

    from asset2sim.flows.refine_flow import run_refine_flow

    summary = run_refine_flow(catalog, workers=1)
    rows2 = {r["asset_id"]: r for r in ResultCatalog(cat.catalog_root).read("gen", summary["run"]).to_dict("records")}
    redone = {a for a, r in rows2.items() if r["status"] != "skipped"}
    assert redone == set(ASSETS) - done_first
    assert summary["skipped"] == k
