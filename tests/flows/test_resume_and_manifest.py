"""The completion marker is the flow's record of finished work too, and a
malformed manifest row fails that asset alone.

- Kill point "marker written, catalog row not yet" (simulated: the row file
  removed): the next run refines nothing, writes the killed run's missing
  row from the folder's report and evaluation, and records the asset as
  skipped. A folder that is not complete, or another request, is redone.
- Bad manifest rows (a field over the CSV limit, an unsafe id, a duplicate
  id, a row without its prompt column, an invalid time limit) become
  failed rows (``invalid_manifest_row``) while the other assets run; a file
  that is not a CSV manifest still fails as a whole.
"""

from __future__ import annotations

import csv
import json
import time
from pathlib import Path

import pytest

from asset2sim.flows.catalog import ResultCatalog
from asset2sim.flows.catalog_config import CatalogError, load_catalog
from asset2sim.flows.job_records import JOB_RECORD_NAME

pytestmark = pytest.mark.slow  # end to end: the flows (Prefect, Dask, stage processes)

try:
    from . import flowfakes  # type: ignore[no-redef]
    from .flowproject import CALLS_PATH, make_project, write_manifest
except ImportError:
    import flowfakes  # type: ignore[no-redef]
    from flowproject import CALLS_PATH, make_project, write_manifest


def _run(catalog: Path, **kw):
    from asset2sim.flows.refine_flow import run_refine_flow

    return run_refine_flow(catalog, **kw)


def _rows(catalog: Path, run: str | None = None) -> dict[str, dict]:
    df = ResultCatalog(load_catalog(catalog).catalog_root).read("gen", run)
    return {r["asset_id"]: r for r in df.to_dict("records")}


def _called() -> list[str]:
    return [c["asset_id"] for c in flowfakes.calls(CALLS_PATH)]


def test_a_complete_folder_without_its_row_is_recorded_not_refined(tmp_path, dask_address):
    catalog = make_project(tmp_path, {"box_lid": "box_lid", "laptop": "laptop", "trash_can": "trash_can"},
                           catalog_extra={"tracking": {"enabled": False}})
    cat = load_catalog(catalog)
    CALLS_PATH.write_text("")
    s1 = _run(catalog, dask_address=dask_address)
    rows1 = _rows(catalog, s1["run"])
    assert s1["done"] == 3 and sorted(_called()) == ["box_lid", "laptop", "trash_can"]
    run1 = cat.output_root / "gen" / s1["run"]
    for aid in rows1:
        assert (run1 / ".work" / aid / JOB_RECORD_NAME).is_file()  # the job record beside the folder

    # the kill points: box_lid's and laptop's folders complete, their rows not yet written;
    # laptop's folder then loses a file (no longer complete)
    store = ResultCatalog(cat.catalog_root)
    for aid in ("box_lid", "laptop"):
        assert store.delete_row("gen", s1["run"], aid)
    (run1 / "laptop" / "initial_state.json").unlink()
    assert set(_rows(catalog, s1["run"])) == {"trash_can"}

    CALLS_PATH.write_text("")
    s2 = _run(catalog, dask_address=dask_address)
    rows2 = _rows(catalog, s2["run"])
    assert _called() == ["laptop"]  # box_lid's complete folder is not refined again
    assert s2["skipped"] == 2 and s2["done"] == 1
    assert rows2["box_lid"]["status"] == "skipped" and rows2["box_lid"]["source_run"] == s1["run"]
    assert rows2["box_lid"]["out_dir"] == str(run1 / "box_lid")
    assert rows2["laptop"]["status"] == "done" and rows2["laptop"]["out_dir"] == str(cat.output_root / "gen" / s2["run"] / "laptop")
    # the killed run's missing row, written from the folder's report and the earlier measurement
    restored = _rows(catalog, s1["run"])
    assert set(restored) == {"box_lid", "trash_can"}
    old = restored["box_lid"]
    # the fake refine reports "none": the catalog's verdict is the refine's (the metrics stage, which evaluated the
    # unrefined copy, adds its columns and never decides it again: tasks.check.verdict.asset_failure_mode)
    assert (run1 / "_metrics" / "box_lid" / "evaluation.json").is_file()
    assert old["status"] == "done" and old["failure_mode"] == "none" and old["source_run"] == s1["run"]
    assert old["out_dir"] == str(run1 / "box_lid")
    report = json.loads((run1 / "box_lid" / "report.json").read_text())
    assert old["scale"] == report["scale"] and old["total_mass_kg"] == report["total_mass"]
    assert old["config_hash"] == rows1["box_lid"]["config_hash"] and old["input_hash"] == rows1["box_lid"]["input_hash"]
    for col in ("penetration_mm", "rest_stable", "d_pos_m", "d_ori_rad", "oscillation_pass", "prompt_alignment"):
        assert old[col] == rows1["box_lid"][col], col

    # another request for box_lid: its earlier folder is not this job's; refined again
    assert store.delete_row("gen", s1["run"], "box_lid")
    assert store.delete_row("gen", s2["run"], "box_lid")
    manifest = cat.manifest_path("gen")
    with open(manifest, newline="") as fh:
        entries = list(csv.DictReader(fh))
    for e in entries:
        if e["id"] == "box_lid":
            e["prompt"] = "I want the lid of the box wide open."
    write_manifest(manifest, entries)
    CALLS_PATH.write_text("")
    s3 = _run(catalog, ids=["box_lid"], dask_address=dask_address)
    assert _called() == ["box_lid"] and _rows(catalog, s3["run"])["box_lid"]["status"] == "done"


def _write_bad_manifest(path: Path) -> None:
    good = path.read_text()
    huge = "I want it open. " * 10_000  # 160,000 characters: beyond csv.field_size_limit()
    path.write_text(
        good
        + f'huge_row,Box,"{huge}",\n'
        + "../evil,Box,I want it open.,\n"
        + "box_lid,Box,a second box_lid,\n"
        + "no_prompt,Box\n"
        + "bad_limit,Box,I want it open.,-3\n"
    )


def test_bad_manifest_rows_fail_alone_while_the_others_run(tmp_path, dask_address):
    catalog = make_project(tmp_path, {"box_lid": "box_lid", "laptop": "laptop"},
                           catalog_extra={"tracking": {"enabled": False}, "run": {"evaluate": False}})
    cat = load_catalog(catalog)
    _write_bad_manifest(cat.manifest_path("gen"))
    CALLS_PATH.write_text("")
    t0 = time.perf_counter()
    s = _run(catalog, dask_address=dask_address)
    rows = _rows(catalog, s["run"])
    assert sorted(_called()) == ["box_lid", "laptop"]
    assert rows["box_lid"]["status"] == "done" and rows["laptop"]["status"] == "done"
    bad = {a: r for a, r in rows.items() if r["failure_mode"] == "invalid_manifest_row"}
    assert set(bad) == {"huge_row", "manifest-line-5", "manifest-line-6", "no_prompt", "bad_limit"}
    assert all(r["status"] == "failed" for r in bad.values())
    codes = {a: r["error"].split(":")[1].strip() for a, r in bad.items()}
    assert codes == {"huge_row": "MANIFEST_ROW_TOO_LARGE", "manifest-line-5": "MANIFEST_INVALID_ID",
                     "manifest-line-6": "MANIFEST_DUPLICATE_ID", "no_prompt": "MANIFEST_MISSING_PROMPT",
                     "bad_limit": "MANIFEST_INVALID_TIME_LIMIT"}
    assert "'../evil'" in bad["manifest-line-5"]["error"] and ":4" in bad["huge_row"]["error"]
    assert s["assets"] == 7 and s["failed"] == 5 and s["failure_modes"]["invalid_manifest_row"] == 5
    assert time.perf_counter() - t0 < 120

    # not a CSV manifest at all, or no id/prompt header: the whole run is refused before it starts
    m = cat.manifest_path("gen")
    m.write_bytes(b"\x89PNG\r\n\x1a\n\x00\x00\x00\rIHDR\xff\xfe")
    with pytest.raises(CatalogError, match="not a CSV manifest"):
        _run(catalog, dask_address=dask_address)
    m.write_text("name,request\nbox_lid,I want it open.\n")
    with pytest.raises(CatalogError, match=r"missing column\(s\) \['id', 'prompt'\]"):
        _run(catalog, dask_address=dask_address)


def test_planning_keeps_manifest_order_and_selects_bad_rows_by_id(tmp_path):
    from asset2sim.flows.run_plan import plan_run

    catalog = make_project(tmp_path, {"box_lid": "box_lid", "laptop": "laptop"})
    cat = load_catalog(catalog)
    _write_bad_manifest(cat.manifest_path("gen"))
    plan = plan_run(cat, "gen", "20990101T000000Z-aaaaaa")
    assert [j.asset_id for j in plan.jobs] == ["box_lid", "laptop"]
    assert [(b.asset_id, b.error.line) for b in plan.bad_rows] == [
        ("huge_row", 4), ("manifest-line-5", 5), ("manifest-line-6", 6), ("no_prompt", 7), ("bad_limit", 8)]
    only = plan_run(cat, "gen", "20990101T000000Z-aaaaaa", ids=["../evil", "laptop"])
    assert [j.asset_id for j in only.jobs] == ["laptop"] and [b.asset_id for b in only.bad_rows] == ["manifest-line-5"]
    first3 = plan_run(cat, "gen", "20990101T000000Z-aaaaaa", limit=3)  # bad rows count in manifest order
    assert [j.asset_id for j in first3.jobs] == ["box_lid", "laptop"] and [b.asset_id for b in first3.bad_rows] == ["huge_row"]
    with pytest.raises(CatalogError, match="unknown id"):
        plan_run(cat, "gen", "20990101T000000Z-aaaaaa", ids=["nope"])
