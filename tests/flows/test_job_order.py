"""The order a flow starts its assets in (asset2sim.flows.job_order): copies of one object's folder (one per
request) run apart, first of each object first, on real PartNet-Mobility folders."""

from __future__ import annotations

import shutil
from dataclasses import dataclass
from pathlib import Path

from asset2sim.flows.job_order import files_key, spread_same_files

DEV = Path(__file__).resolve().parents[2].parent / "shared" / "datasets" / "partnet_mobility"


@dataclass
class _Job:
    asset_id: str
    asset_dir: str


def _copies(tmp_path: Path, plan: list[tuple[str, str]]) -> list[_Job]:
    jobs = []
    for aid, source in plan:
        shutil.copytree(DEV / source, tmp_path / aid)
        jobs.append(_Job(aid, str(tmp_path / aid)))
    return jobs


def test_copies_of_one_object_run_apart_in_rounds(tmp_path):
    jobs = _copies(tmp_path, [("8877_r0", "8877"), ("8877_r1", "8877"), ("8877_r2", "8877"),
                              ("102181_r0", "102181"), ("102181_r1", "102181"), ("19179_r0", "19179")])
    assert files_key(tmp_path / "8877_r0") == files_key(tmp_path / "8877_r2") != files_key(tmp_path / "102181_r0")
    order = [j.asset_id for j in spread_same_files(jobs)]
    assert order == ["8877_r0", "102181_r0", "19179_r0", "8877_r1", "102181_r1", "8877_r2"]


def test_distinct_objects_keep_the_manifest_order_and_unlisted_folders_stay(tmp_path):
    jobs = _copies(tmp_path, [("a", "19179"), ("b", "8877"), ("c", "102181")])
    jobs.insert(1, _Job("gone", str(tmp_path / "missing")))
    assert files_key(tmp_path / "missing") is None
    assert [j.asset_id for j in spread_same_files(jobs)] == ["a", "gone", "b", "c"]


def test_a_changed_file_makes_another_object(tmp_path):
    jobs = _copies(tmp_path, [("x0", "8877"), ("x1", "8877")])
    urdf = tmp_path / "x1" / "mobility.urdf"
    urdf.write_text(urdf.read_text() + "\n")
    assert files_key(tmp_path / "x0") != files_key(tmp_path / "x1")
    assert [j.asset_id for j in spread_same_files(jobs)] == ["x0", "x1"]
