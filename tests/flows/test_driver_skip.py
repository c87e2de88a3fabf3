"""Skip decisions in the driver (asset2sim.flows.driver_skip): a rerun of
finished assets starts no Dask cluster, no Prefect task and (without a
configured Prefect server) no Prefect server; only the assets whose input
folder changed go to the workers, which apply the skip rule as before."""

from __future__ import annotations

import os

import pandas as pd
import pytest

from asset2sim.flows.catalog import ResultCatalog
from asset2sim.flows.catalog_config import load_catalog
from asset2sim.flows import driver_skip

pytestmark = pytest.mark.slow  # end to end: the flows (Prefect, Dask, stage processes)

try:
    from . import flowfakes  # type: ignore[no-redef]
    from .flowproject import CALLS_PATH, make_project
except ImportError:
    import flowfakes  # type: ignore[no-redef]
    from flowproject import CALLS_PATH, make_project

ASSETS = {"box_lid": "box_lid", "laptop": "laptop", "cabinet_2drawer": "cabinet_2drawer"}


def _rows(catalog, run):
    cat = load_catalog(catalog)
    return {r["asset_id"]: r for r in ResultCatalog(cat.catalog_root).read("gen", run).to_dict("records")}


def _touch(path):
    st = os.stat(path)
    os.utime(path, ns=(st.st_atime_ns, st.st_mtime_ns + 5_000_000))


def test_fingerprint_follows_every_file_of_the_folder(tmp_path):
    from asset2sim import demo_assets

    folder = tmp_path / "a"
    demo_assets._write_folder(folder, demo_assets.demo_files("box_lid"))
    fp = driver_skip.input_fingerprint(folder)
    assert fp is not None and fp == driver_skip.input_fingerprint(folder)
    obj = sorted((folder / "textured_objs").glob("*.obj"))[0]
    _touch(obj)
    fp2 = driver_skip.input_fingerprint(folder)
    assert fp2 != fp
    (folder / "textured_objs" / "new.obj").write_text("v 0 0 0\n")
    assert driver_skip.input_fingerprint(folder) not in (fp, fp2)
    assert driver_skip.input_fingerprint(tmp_path / "missing") is None


def test_rerun_of_finished_assets_starts_nothing(tmp_path, prefect_server, dask_address):
    """The runs that refine or skip in the workers use the session's Dask scheduler (``dask_address``, as the
    nightly deployment does); the run with nothing to do is given none, and starts none."""
    from prefect.settings import PREFECT_API_URL, temporary_settings

    from asset2sim.flows.refine_flow import run_refine_flow

    root = tmp_path / "proj"
    catalog = make_project(root, ASSETS, catalog_extra={"run": {"workers": 1}, "tracking": {"enabled": False}})
    CALLS_PATH.write_text("")
    s1 = run_refine_flow(catalog, dask_address=dask_address)
    assert s1["done"] == 3 and s1["driver_skipped"] == 0
    assert sorted(c["asset_id"] for c in flowfakes.calls(CALLS_PATH)) == sorted(ASSETS)
    cat = load_catalog(catalog)
    index = driver_skip.read_index(ResultCatalog(cat.catalog_root), "gen")
    rows1 = _rows(catalog, s1["run"])
    assert {a: e.input_hash for a, e in index.items()} == {a: rows1[a]["input_hash"] for a in ASSETS}

    # no Prefect server configured: nothing left to do, so no server, no flow run, no Dask; the progress says nothing
    # starts, the run is recorded as one with nothing to do, and `failures` passes over it to the run that refined
    from asset2sim.commands import _progress, failures
    from asset2sim.flow_progress import listening

    CALLS_PATH.write_text("")
    said = []
    with temporary_settings(restore_defaults={PREFECT_API_URL}), listening(said.append):
        assert not PREFECT_API_URL.value()
        s2 = run_refine_flow(catalog, workers=1)
    assert s2["skipped"] == 3 and s2["driver_skipped"] == 3 and s2["done"] == 0
    started = next(e for e in said if e.kind == "run_started")
    assert started.pending == 0 and _progress.starting(started) == _progress.NOTHING_TO_START
    store = ResultCatalog(cat.catalog_root)
    assert store.run_info("gen", s2["run"])["outcome"] == "nothing_to_do"
    assert store.run_info("gen", s1["run"])["outcome"] == "worked"
    assert failures.latest_worked(store, "gen") == (("gen", s1["run"]), [s2["run"]])
    assert s2["dask_startup_seconds"] == 0.0 and s2["assets_seconds"] == 0.0
    assert flowfakes.calls(CALLS_PATH) == []
    rows2 = _rows(catalog, s2["run"])
    for aid in ASSETS:
        r1, r2 = rows1[aid], rows2[aid]
        assert r2["status"] == "skipped" and r2["source_run"] == s1["run"] and pd.isna(r2["flow_run_id"])
        assert (r2["out_dir"], r2["input_hash"], r2["config_hash"], r2["refine_config_hash"], r2["failure_mode"]) == (
            r1["out_dir"], r1["input_hash"], r1["config_hash"], r1["refine_config_hash"], r1["failure_mode"])

    # a file touched (same content): the driver no longer knows, the worker reads it and skips it
    obj = sorted((cat.dataset_root("gen") / "laptop" / "textured_objs").glob("*.obj"))[0]
    _touch(obj)
    CALLS_PATH.write_text("")
    s3 = run_refine_flow(catalog, dask_address=dask_address)
    assert s3["driver_skipped"] == 2 and s3["skipped"] == 3
    assert flowfakes.calls(CALLS_PATH) == []
    # its index entry now has the new fingerprint: the next run skips it in the driver again
    s4 = run_refine_flow(catalog, dask_address=dask_address)
    assert s4["driver_skipped"] == 3

    # a changed file: redone, the others skipped by the driver
    obj.write_text(obj.read_text() + "\n# edited\n")
    _touch(obj)
    CALLS_PATH.write_text("")
    s5 = run_refine_flow(catalog, dask_address=dask_address)
    assert s5["driver_skipped"] == 2 and s5["done"] == 1
    assert [c["asset_id"] for c in flowfakes.calls(CALLS_PATH)] == ["laptop"]
    assert _rows(catalog, s5["run"])["laptop"]["input_hash"] != rows1["laptop"]["input_hash"]

    # an output folder no longer complete: the driver sends it to a worker, which redoes it
    os.remove(os.path.join(rows1["box_lid"]["out_dir"], "mobility.urdf"))
    CALLS_PATH.write_text("")
    s6 = run_refine_flow(catalog, dask_address=dask_address)
    assert s6["driver_skipped"] == 2 and s6["done"] == 1
    assert [c["asset_id"] for c in flowfakes.calls(CALLS_PATH)] == ["box_lid"]

    # --force: nothing skipped, in the driver or elsewhere
    CALLS_PATH.write_text("")
    s7 = run_refine_flow(catalog, dask_address=dask_address, force=True)
    assert s7["driver_skipped"] == 0 and s7["done"] == 3
    assert sorted(c["asset_id"] for c in flowfakes.calls(CALLS_PATH)) == sorted(ASSETS)
