"""One output guard for every writer (``asset2sim.output_paths.write_inside``): each writer is given its output
folder through a symlink (``link -> real``; followed: the files land in ``real``) and then with a subfolder of that
folder a symlink to a folder outside (``views/``, ``collision/``, ``patch/``, ``clips/``, ``mjcf/``, an asset's
folder of a flow run, ``ratings.sqlite``). Each refuses with ``OUTPUT_SYMLINK_ESCAPES`` and the outside folder is
byte for byte as it was: refine, ``report`` (make_media), audit, judge (judgements.parquet), rate (the ratings
store), pairs, the flow's refine stage and the MJCF and USD host write-backs."""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest

from asset2sim import demo_assets
from asset2sim import output_folder as of
from asset2sim.tasks.refine import RefineError, refine_asset
from tests.helpers import tree_hashes

PROMPT = "a small box with its lid closed"


@pytest.fixture()
def area(tmp_path):
    """(box input, real output folder, link to it, outside folder holding one file)."""
    box = demo_assets.build_box_with_lid(tmp_path / "in" / "box_lid")
    real = tmp_path / "real"
    real.mkdir()
    link = tmp_path / "link"
    link.symlink_to(real)
    outside = tmp_path / "outside"
    outside.mkdir()
    (outside / "victim.txt").write_text("victim")
    return box, real, link, outside


def _codes(exc: BaseException) -> set[str]:
    seen, out = set(), set()
    while exc is not None and id(exc) not in seen:
        seen.add(id(exc))
        out.update(getattr(exc, "codes", None) or [getattr(exc, "code", None)])
        exc = exc.__cause__ or exc.__context__
    return out


def _listing(folder: Path) -> list[str]:
    return sorted(str(Path(d, n).relative_to(folder)) for d, dirs, files in os.walk(folder) for n in dirs + files)


def _refused(call, outside: Path) -> BaseException:
    before, listed = tree_hashes(outside), _listing(outside)
    with pytest.raises(Exception) as info:
        call()
    assert "OUTPUT_SYMLINK_ESCAPES" in _codes(info.value), repr(info.value)
    assert tree_hashes(outside) == before and _listing(outside) == listed
    return info.value


def test_write_inside_compares_the_path_as_given_and_as_resolved(tmp_path):
    real, outside = tmp_path / "real", tmp_path / "outside"
    (real / "sub").mkdir(parents=True)
    outside.mkdir()
    link = tmp_path / "link"
    link.symlink_to(real)
    (real / "views").symlink_to(outside)
    assert of.write_inside(link / "sub" / "a.png", link, real) == "sub/a.png"
    assert of.write_inside(real / "sub" / "a.png", link, real) == "sub/a.png"
    assert of.write_inside(tmp_path / "elsewhere.txt", link, real) is None
    for path in (link / "views" / "a.png", real / "views" / "a.png", link / "sub" / ".." / ".." / "outside" / "a.png"):
        with pytest.raises(of.OutputError) as info:
            of.write_inside(path, link, real)
        assert info.value.code in ("OUTPUT_SYMLINK_ESCAPES", "OUTPUT_PATH_ESCAPES")


def test_refine_through_a_symlinked_output_and_a_symlinked_subfolder(area):
    box, real, link, outside = area
    refine_asset(box, PROMPT, link, extras=False)
    assert (real / "mobility.urdf").is_file() and link.is_symlink()
    for p in real.iterdir():
        p.unlink() if p.is_file() or p.is_symlink() else __import__("shutil").rmtree(p)
    (real / "collision").symlink_to(outside)
    err = _refused(lambda: refine_asset(box, PROMPT, link, extras=False, overwrite=True), outside)
    assert isinstance(err, (of.OutputError, RefineError))  # the command's exit status 4


def test_report_through_a_symlinked_output_with_a_symlinked_views_folder_is_refused(area, refine_once):
    """The issue's case: ``report OUT`` given OUT through a symlink whose ``views/`` leads elsewhere wrote five
    renders there; now refused through the link and through the real path alike."""
    from asset2sim.tasks.publish.media import make_media

    box, real, link, outside = area
    real.rmdir()
    refine_once("box_lid", PROMPT, extras=True, media=False).copy_to(real)
    (real / "views").symlink_to(outside)
    _refused(lambda: make_media(link), outside)
    _refused(lambda: make_media(real), outside)


@pytest.mark.slow  # the media phase made (renders, clips, report.html)
def test_report_through_a_symlinked_output_writes_the_real_folder(area, refine_once):
    from asset2sim.tasks.publish.media import make_media

    box, real, link, outside = area
    real.rmdir()
    refine_once("box_lid", PROMPT, extras=True, media=False).copy_to(real)
    made = make_media(link)
    assert (real / "views" / "front.png").is_file() and made["html"] == str(link / "report.html")


def test_audit_through_a_symlinked_output_and_a_symlinked_patch_folder(area):
    from asset2sim.apps.audit.audit import audit_asset

    box, real, link, outside = area
    result = audit_asset(box, link, simulate=False)
    assert result.report.patch and (real / result.report.patch).is_file()
    for p in ("audit.json", "audit.md"):
        (real / p).unlink()
    __import__("shutil").rmtree(real / "patch")
    (real / "patch").symlink_to(outside)
    _refused(lambda: audit_asset(box, link, simulate=False), outside)


def test_judgements_and_ratings_never_follow_a_symlinked_file(tmp_path):
    from asset2sim.apps.realism.judge import JUDGEMENTS_FILE, write_judgements
    from asset2sim.apps.realism.ratings import DATABASE_FILE, RatingStore
    from tests.realism_fixtures import write_pair_set

    real, outside = tmp_path / "real", tmp_path / "outside"
    write_pair_set(real, 2)
    outside.mkdir()
    (outside / "victim.txt").write_text("victim")
    link = tmp_path / "link"
    link.symlink_to(real)
    (real / JUDGEMENTS_FILE).symlink_to(outside / "victim.txt")
    write_judgements(link, [])  # the symlink replaced by the file, never written through
    assert not (real / JUDGEMENTS_FILE).is_symlink() and (outside / "victim.txt").read_text() == "victim"
    for name in (DATABASE_FILE, DATABASE_FILE + "-wal"):
        (real / name).symlink_to(outside / "victim.txt")
        _refused(lambda: RatingStore(link), outside)
        (real / name).unlink()
    RatingStore(link).close()
    assert (real / DATABASE_FILE).is_file()


def test_flow_refine_stage_never_writes_through_a_symlinked_asset_folder(area):
    from asset2sim.flows.stages import stage_refine

    box, real, link, outside = area
    (outside / "empty").mkdir()
    (real / "box_lid").symlink_to(outside / "empty")
    _refused(lambda: stage_refine(str(box), PROMPT, str(link / "box_lid"), {}, None, "box_lid", extras=False), outside)
    out = stage_refine(str(box), PROMPT, str(link / "own"), {}, None, "own", extras=False)
    assert Path(out["out_dir"]) == link / "own" and (real / "own" / "mobility.urdf").is_file()


@pytest.mark.slow  # three refines (an output exported to MJCF and USD, each refined again)
def test_host_write_backs_never_write_through_a_symlinked_folder(area):
    pytest.importorskip("mujoco")
    pytest.importorskip("pxr")
    from asset2sim.formats.mjcf.physics import write_host_mjcf
    from asset2sim.formats.usd.physics import write_host_usd

    box, real, link, outside = area
    exported = refine_asset(box, PROMPT, real.parent / "exported", extras=True, media=False)
    for fmt, sub, write in (("mjcf", "mjcf/mobility.xml", write_host_mjcf), ("usd", "usd/mobility.usd", write_host_usd)):
        source = exported.out_dir / sub
        out = real.parent / f"from_{fmt}"
        refine_asset(source, "a box", out, extras=False)
        done = write(out, source)  # unchanged folders: written
        assert done.path.is_file()
        host = out / fmt / "host"
        __import__("shutil").rmtree(host)
        host.symlink_to(outside)
        _refused(lambda: write(out, source), outside)


@pytest.mark.slow  # end to end: a pair simulated and drawn (push and release, two sides, clips)
def test_pairs_never_write_through_a_symlinked_clips_or_defects_folder(area):
    from asset2sim.apps.realism.pairs import build_pair_set, specs_from_folders

    box, real, link, outside = area
    refined = refine_asset(box, PROMPT, real.parent / "refined", extras=False).out_dir
    (real / "defects").symlink_to(outside)
    _refused(lambda: specs_from_folders([refined], link, defects=("mass_x100",)), outside)
    (real / "defects").unlink()
    specs, skipped = specs_from_folders([refined], link, defects=("mass_x100",))
    assert len(specs) == 1, skipped
    (real / "clips").symlink_to(outside)
    _refused(lambda: build_pair_set(specs, link), outside)
    (real / "clips").unlink()
    made = build_pair_set(specs, link)
    assert len(made.pairs) == 1 and (real / "pairs.json").is_file()
