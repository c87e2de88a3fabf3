"""The order a flow starts its assets in (asset2sim.flows.job_order): copies of one object's folder (one per
request) run apart, first of each object first, the objects with the most geometry first, on real
PartNet-Mobility folders."""

from __future__ import annotations

import shutil
from dataclasses import dataclass
from pathlib import Path

from asset2sim.flows.job_order import folder_listing, start_order
from tests.conftest import SHARED, needs_shared

pytestmark = needs_shared


def files_key(folder):
    """The key :func:`folder_listing` gives ``folder``."""
    return folder_listing(folder)[0]

DEV = SHARED


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


def test_copies_of_one_object_run_apart_in_rounds_largest_first(tmp_path):
    jobs = _copies(tmp_path, [("8877_r0", "8877"), ("8877_r1", "8877"), ("8877_r2", "8877"),
                              ("102181_r0", "102181"), ("102181_r1", "102181"), ("19179_r0", "19179")])
    assert files_key(tmp_path / "8877_r0") == files_key(tmp_path / "8877_r2") != files_key(tmp_path / "102181_r0")
    sizes = {a: folder_listing(tmp_path / a)[1] for a in ("8877_r0", "102181_r0", "19179_r0")}
    assert sizes["19179_r0"] > sizes["102181_r0"] > sizes["8877_r0"] > 0
    order = [j.asset_id for j in start_order(jobs)]
    assert order == ["19179_r0", "102181_r0", "8877_r0", "102181_r1", "8877_r1", "8877_r2"]


def test_textures_do_not_count_and_unlisted_folders_go_last(tmp_path):
    jobs = _copies(tmp_path, [("a", "8877"), ("b", "102181"), ("c", "9912")])
    jobs.insert(1, _Job("gone", str(tmp_path / "missing")))
    assert folder_listing(tmp_path / "missing") == (None, 0)
    # 9912's folder holds 2.6 MB of texture images: only its meshes, URDF, MTL and JSON count
    files = [p for p in (tmp_path / "c").rglob("*") if p.is_file()]
    images = sum(p.stat().st_size for p in files if p.suffix.lower() in (".png", ".jpg", ".jpeg"))
    assert images > 2_000_000 and folder_listing(tmp_path / "c")[1] == sum(p.stat().st_size for p in files) - images
    assert [j.asset_id for j in start_order(jobs)] == ["c", "b", "a", "gone"]


def test_equal_sizes_keep_the_manifest_order(tmp_path):
    jobs = _copies(tmp_path, [("x0", "8877"), ("x1", "8877")])
    urdf = tmp_path / "x1" / "mobility.urdf"
    text = urdf.read_text()
    assert 'name="base"' in text
    urdf.write_text(text.replace('name="base"', 'name="bas0"', 1))  # other bytes, the same size
    assert files_key(tmp_path / "x0") == files_key(tmp_path / "x1")  # the key reads sizes, not contents
    assert [j.asset_id for j in start_order(jobs)] == ["x0", "x1"]
    jobs.append(_Job("y", str(tmp_path / "y")))
    shutil.copytree(DEV / "8877", tmp_path / "y")
    (tmp_path / "y" / "mobility.urdf").write_text(text + "\n")  # one byte more: another object, started first
    assert files_key(tmp_path / "y") != files_key(tmp_path / "x0")
    assert [j.asset_id for j in start_order(jobs)] == ["y", "x0", "x1"]


def test_an_asset_given_as_one_file_has_its_size_and_no_key(tmp_path):
    jobs = _copies(tmp_path, [("folder", "8877")])
    urdf = tmp_path / "folder" / "mobility.urdf"
    big = tmp_path / "big.urdf"
    big.write_bytes(urdf.read_bytes() * 40)  # one file larger than 8877's whole folder
    assert folder_listing(big) == (None, big.stat().st_size)
    assert folder_listing(urdf)[1] == urdf.stat().st_size < folder_listing(tmp_path / "folder")[1] < big.stat().st_size
    jobs += [_Job("file", str(urdf)), _Job("big", str(big))]
    assert [j.asset_id for j in start_order(jobs)] == ["big", "folder", "file"]
