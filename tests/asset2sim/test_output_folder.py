"""The output folder owns only what it wrote: location checks, ownership
record, rewrites that remove only recorded files, foreign files refused
unless overwrite, symlinks, collision pieces beside input meshes in
``collision/``, symlinked and ``dir/../`` mesh paths, the completion marker
only when every file exists, and file modes from the umask.

Data-loss tests hash every file outside the output folder (the whole test
area, input included) before and after."""

from __future__ import annotations

import errno
import hashlib
import json
import os
import signal
import stat
from pathlib import Path

import pytest

from asset2sim import atomic, demo_assets
from asset2sim.engines.base import SessionOptions
from asset2sim.engines.registry import open_session
from asset2sim.tasks.ingest.extract import extract_asset
from asset2sim.tasks.ingest.validate_input import validate_asset
from asset2sim import output_folder as of
from asset2sim.output_staging import STAGING_SUFFIX
from asset2sim.tasks.assemble import copied_meshes, write
from asset2sim.formats.mjcf import export as export_mjcf
from asset2sim.tasks.publish import refine_report
from asset2sim.tasks.refine import MARKER_NAME, RefineError, is_complete, refine_asset
from asset2sim.schemas.config import RefineConfig
from tests import corpus_builder as cb

PROMPT = "a small box with its lid slightly open"


def outside_hashes(area: Path, out: Path) -> dict[str, str]:
    """sha256 of every file under ``area`` that is not inside ``out``
    (symlinks recorded by their target, never followed)."""
    out = Path(os.path.abspath(out))
    res = {}
    for folder, dirs, files in os.walk(area):
        base = Path(folder)
        if base == out or out in base.parents:
            continue
        for name in files + [d for d in dirs if (base / d).is_symlink()]:
            p = base / name
            if p == out:
                continue
            rel = str(p.relative_to(area))
            if p.is_symlink():
                res[rel] = "link:" + os.readlink(p)
            elif p.is_file():
                res[rel] = hashlib.sha256(p.read_bytes()).hexdigest()
    return res


@pytest.fixture()
def box(tmp_path):
    return demo_assets.build_box_with_lid(tmp_path / "in" / "box_lid")


# ----------------------------------------------------------------------------- location


def test_location_refusals_name_code_and_path(tmp_path, box):
    (tmp_path / "a_file").write_text("x")
    (tmp_path / "link_into_input").symlink_to(box)
    cases = {
        box: "OUTPUT_IS_INPUT",
        box / "out": "OUTPUT_INSIDE_INPUT",
        tmp_path / "link_into_input" / "out": "OUTPUT_INSIDE_INPUT",
        tmp_path / "link_into_input": "OUTPUT_IS_INPUT",
        box.parent: "OUTPUT_CONTAINS_INPUT",
        tmp_path: "OUTPUT_CONTAINS_INPUT",
        tmp_path / "a_file": "OUTPUT_NOT_A_FOLDER",
        Path("/dev/null"): "OUTPUT_NOT_A_FOLDER",
    }
    for out, code in cases.items():
        with pytest.raises(of.OutputError) as err:
            of.check_location(box, out)
        assert err.value.code == code, (out, err.value)
        assert err.value.path is not None and str(out) in str(err.value)
    assert of.check_location(box, tmp_path / "elsewhere" / "new") == (tmp_path / "elsewhere" / "new").resolve()


def test_refine_with_out_at_input_parent_or_named_collision_loses_nothing(tmp_path):
    """The cases: --out the input's parent; an input folder named
    ``collision`` and --out its parent. Refused, nothing written or removed."""
    box = demo_assets.build_box_with_lid(tmp_path / "area" / "collision")
    (tmp_path / "area" / ".notes.tmp").write_text("a user's file that looks temporary")
    (tmp_path / "area" / "collision" / ".draft.tmp").write_text("another")
    before = outside_hashes(tmp_path, tmp_path / "no-output")
    for out in (tmp_path / "area", tmp_path):
        with pytest.raises(RefineError) as err:
            refine_asset(box, PROMPT, out, extras=False)
        assert err.value.codes == ["OUTPUT_CONTAINS_INPUT"]
        assert isinstance(err.value.__cause__, of.OutputError)
    assert outside_hashes(tmp_path, tmp_path / "no-output") == before


# ----------------------------------------------------------------------------- ownership


def _write_run(out: Path, box: Path, files: dict[str, str], *, overwrite: bool = False, finish: bool = True) -> of.OwnedFolder:
    owner = of.start(box, out, overwrite=overwrite)
    for rel, text in files.items():
        atomic.write_text(out / rel, text)
    if finish:
        owner.finish({"input_hash": "i", "config_hash": "c", "version": "v"})
    else:
        owner.close()
    return owner


def test_foreign_files_refused_then_kept_with_overwrite(tmp_path, box):
    out = tmp_path / "out"
    (out / "notes").mkdir(parents=True)
    (out / "notes" / "mine.txt").write_text("user data")
    (out / ".hidden.tmp").write_text("user data that looks temporary")
    before = outside_hashes(tmp_path, tmp_path / "nothing")
    with pytest.raises(of.OutputError) as err:
        of.start(box, out)
    assert err.value.code == "OUTPUT_NOT_EMPTY"
    assert "notes/mine.txt" in str(err.value) and ".hidden.tmp" in str(err.value)
    assert outside_hashes(tmp_path, tmp_path / "nothing") == before  # nothing touched
    _write_run(out, box, {"a.json": "1", "sub/b.txt": "2"}, overwrite=True)
    assert (out / "notes" / "mine.txt").read_text() == "user data"
    assert (out / ".hidden.tmp").read_text() == "user data that looks temporary"
    marker = json.loads((out / MARKER_NAME).read_text())
    assert set(marker["files"]) == {"a.json", "sub/b.txt"}  # the user's files are not the product's
    assert not (out / of.RECORD_NAME).exists()


def test_rewrite_removes_exactly_the_recorded_files(tmp_path, box):
    out = tmp_path / "out"
    _write_run(out, box, {"a.json": "1", "sub/b.txt": "2", "sub/deeper/c.txt": "3"})
    (out / "user.txt").write_text("mine")  # added later by the user
    with pytest.raises(of.OutputError):
        of.start(box, out)
    keep = outside_hashes(tmp_path, out)
    owner = of.start(box, out, overwrite=True)
    assert not (out / MARKER_NAME).exists()
    assert not (out / "a.json").exists() and not (out / "sub").exists()  # recorded files and their emptied folders
    assert (out / "user.txt").read_text() == "mine"
    owner.close()
    assert outside_hashes(tmp_path, out) == keep


def test_killed_run_is_recorded_and_cleaned_by_the_next(tmp_path, box):
    out = tmp_path / "out"
    owner = of.start(box, out)
    atomic.write_text(out / "x.json", "{}")
    (out / atomic.temp_name(out / "big.obj")).write_bytes(b"partial")  # a copy killed half-way ...
    owner._observe([out / "big.obj"])  # ... after its destination was recorded
    owner.close()  # killed: no marker
    record = json.loads((out / of.RECORD_NAME).read_text())
    assert set(record["files"]) == {"x.json", "big.obj"}
    assert of.foreign_files(out) == []
    owner = of.start(box, out)  # no overwrite needed: everything there is the product's
    assert sorted(p.name for p in out.iterdir()) == [of.RECORD_NAME]
    owner.close()


def test_tampered_record_cannot_delete_outside(tmp_path, box):
    out = tmp_path / "out"
    out.mkdir()
    victim = tmp_path / "victim.txt"
    victim.write_text("precious")
    entries = ["../victim.txt", str(victim), "/etc/hostname", "a/../../victim.txt", ""]
    (out / of.RECORD_NAME).write_text(json.dumps({"files": entries}))
    before = outside_hashes(tmp_path, out)
    of.start(box, out).close()
    assert outside_hashes(tmp_path, out) == before


def test_owned_path_behind_a_symlink_into_the_input_is_not_removed(tmp_path):
    """A recorded ``meshes/base.obj`` whose folder was replaced by a symlink
    to the input's meshes: the rewrite must not delete the input's file, and a
    write through it is refused."""
    src = cb.build_valid(tmp_path / "in")
    out = tmp_path / "out"
    _write_run(out, src, {"meshes/base.obj": "copy"})
    (out / "meshes" / "base.obj").unlink()
    (out / "meshes").rmdir()
    (out / "meshes").symlink_to(src / "meshes")
    before = outside_hashes(tmp_path, out)
    with pytest.raises(of.OutputError) as err:  # the symlink is not the product's
        of.start(src, out)
    assert err.value.code == "OUTPUT_NOT_EMPTY"
    owner = of.start(src, out, overwrite=True)
    with pytest.raises(of.OutputError) as err:
        atomic.write_text(out / "meshes" / "base.obj", "would overwrite the input")
    assert err.value.code == "OUTPUT_SYMLINK_ESCAPES"
    owner.close()
    with pytest.raises(of.OutputError) as err:  # refine refuses it the same way, when it copies the meshes
        refine_asset(src, "open", out, extras=False, overwrite=True)
    assert err.value.code == "OUTPUT_SYMLINK_ESCAPES"
    assert outside_hashes(tmp_path, out) == before


def test_finish_refuses_a_missing_file_and_writes_no_marker(tmp_path, box):
    out = tmp_path / "out"
    owner = of.start(box, out)
    atomic.write_text(out / "a.json", "1")
    atomic.write_text(out / "report.html", "<html></html>")
    (out / "report.html").unlink()  # as if its write had failed
    with pytest.raises(of.OutputError) as err:
        owner.finish({"input_hash": "i"})
    assert err.value.code == "OUTPUT_INCOMPLETE" and "report.html" in str(err.value)
    assert not (out / MARKER_NAME).exists() and (out / of.RECORD_NAME).exists()


# ----------------------------------------------------------------------------- refine


def test_refine_rerun_owns_its_files_and_marker_lists_them(tmp_path, box):
    """A rerun of another request over a complete output: refused beside a user's file, then (allowed) it says the
    earlier output it replaces and what of it goes, and owns only its own files."""
    out = tmp_path / "out"
    said: list[str] = []
    first = refine_asset(box, PROMPT, out, extras=False, progress=lambda stage, msg: said.append(msg))
    assert not [m for m in said if "earlier output" in m]  # a new folder replaces nothing
    marker = json.loads((out / MARKER_NAME).read_text())
    on_disk = {str(p.relative_to(out)) for p in out.rglob("*") if p.is_file() and p.name != MARKER_NAME}
    assert set(marker["files"]) | set(marker["unhashed"]) == on_disk  # the same list the whole-folder scan gave
    assert marker["unhashed"] == [of.TIMINGS_NAME]  # wall times: owned, never hashed
    assert not (out / of.RECORD_NAME).exists()
    (out / "user_notes.txt").write_text("mine")
    with pytest.raises(RefineError) as err:  # a changed request must rewrite, but the folder holds a user file
        refine_asset(box, "a small box with its lid closed", out, extras=False)
    assert err.value.codes == ["OUTPUT_NOT_EMPTY"]
    assert is_complete(out, first.report.input_hash, first.report.config_hash)  # refused before touching anything
    before = outside_hashes(tmp_path, out)
    said.clear()
    again = refine_asset(box, "a small box with its lid closed", out, extras=False, overwrite=True,
                         progress=lambda stage, msg: said.append(msg))
    assert not again.skipped and (out / "user_notes.txt").read_text() == "mine"
    (told,) = [m for m in said if "earlier output" in m]  # the replace is said, with what goes
    assert told.startswith("WARNING: ") and "report.json" in told and f"its {len(marker['files']) + 1} files" in told, told
    assert outside_hashes(tmp_path, out) == before
    assert "user_notes.txt" not in json.loads((out / MARKER_NAME).read_text())["files"]


def _collision_named_asset(folder: Path) -> Path:
    """The corpus's valid asset with its meshes in ``collision/`` (a common
    name in robot descriptions), MTL and texture included."""
    src = cb.build_valid(folder)
    (src / "meshes").rename(src / "collision")
    urdf = src / "mobility.urdf"
    urdf.write_text(urdf.read_text().replace('"meshes/', '"collision/'))
    return src


def test_meshes_in_a_folder_named_collision_are_kept(tmp_path):
    src = _collision_named_asset(tmp_path / "in" / "robot")
    asset = extract_asset(src)
    assert write.collision_folder(asset) == "collision_1"
    assert set(copied_meshes.mesh_copies(asset)) == {"collision/base.obj", "collision/base.mtl", "images/tex.png", "collision/lid.obj", "collision/drawer.stl"}
    before = outside_hashes(tmp_path, tmp_path / "out")
    res = refine_asset(src, "a cabinet with the drawer slightly open", tmp_path / "out", extras=False)
    out = res.out_dir
    for rel in ("collision/base.obj", "collision/base.mtl", "collision/lid.obj", "collision/drawer.stl", "images/tex.png"):
        assert (out / rel).read_bytes() == (src / rel).read_bytes(), rel
    assert set(json.loads((out / MARKER_NAME).read_text())["files"]) >= {"collision/base.obj", "images/tex.png"}
    with open_session("pybullet", out / "mobility.urdf", SessionOptions(initial_state=res.report.initial_joint_positions)):
        pass
    assert outside_hashes(tmp_path, tmp_path / "out") == before


def test_symlinked_and_dotdot_mesh_paths_are_copied_where_referenced(tmp_path):
    src = cb.build_valid(tmp_path / "in")
    (src / "parts").mkdir()
    (src / "meshes" / "lid.obj").rename(src / "parts" / "lid_real.obj")
    (src / "meshes" / "lid.obj").symlink_to(Path("..") / "parts" / "lid_real.obj")  # a file symlink
    (src / "alias").symlink_to("meshes")  # a folder symlink
    (src / "sub").mkdir()  # an (empty) folder a path walks through: "sub/../meshes/drawer.stl"
    urdf = src / "mobility.urdf"
    text = urdf.read_text()
    text = text.replace('"meshes/base.obj"', '"alias/base.obj"', 1)  # the visual: through the folder link
    text = text.replace('"meshes/drawer.stl"', '"sub/../meshes/drawer.stl"')
    urdf.write_text(text)
    asset = extract_asset(src)
    copies = copied_meshes.mesh_copies(asset)
    assert {"alias/base.obj", "alias/base.mtl", "meshes/lid.obj", "meshes/drawer.stl", "meshes/base.obj"} <= set(copies)
    before = outside_hashes(tmp_path, tmp_path / "out")
    res = refine_asset(src, "a cabinet with the lid closed", tmp_path / "out", extras=False)
    out = res.out_dir
    for rel in ("alias/base.obj", "alias/base.mtl", "meshes/lid.obj", "meshes/drawer.stl"):
        p = out / rel
        assert p.is_file() and not p.is_symlink() and not p.parent.is_symlink(), rel
        assert p.read_bytes() == (src / rel).read_bytes()
    assert (out / "sub").is_dir()  # "sub/../meshes/drawer.stl" opens in the output too
    assert (out / "sub" / ".." / "meshes" / "drawer.stl").is_file()
    assert not [p for p in out.rglob("*") if p.is_symlink()]
    with open_session("pybullet", out / "mobility.urdf", SessionOptions(initial_state=res.report.initial_joint_positions)):
        pass
    assert outside_hashes(tmp_path, tmp_path / "out") == before


def test_failed_write_during_extras_leaves_no_marker(tmp_path, box, monkeypatch):
    """A full disk while the HTML report is written: the run says so
    (``OUTPUT_WRITE_FAILED`` raised from the ENOSPC error, naming report.html;
    it was ``OUTPUT_INCOMPLETE``, which named the missing file but not the
    cause) and writes no completion marker, so a rerun redoes the asset."""
    from asset2sim.tasks import refine as refine_mod

    monkeypatch.setattr(refine_mod.media_phase.render, "render_views", lambda *a, **k: None)
    monkeypatch.setattr(export_mjcf, "export_mjcf", lambda *a, **k: None)
    real = atomic._create_temp

    def full_disk(path):
        if path.name == "report.html":
            raise OSError(errno.ENOSPC, "No space left on device", str(path))
        return real(path)

    monkeypatch.setattr(atomic, "_create_temp", full_disk)
    out = tmp_path / "out"
    no_clips = RefineConfig(clips=False)  # report.html without the sweep clips: the write that fails is the report's
    with pytest.raises(of.OutputError) as err:
        refine_asset(box, PROMPT, out, no_clips, extras=True)
    assert err.value.code == "OUTPUT_WRITE_FAILED" and "report.html" in str(err.value)
    assert isinstance(err.value.__cause__, OSError) and err.value.__cause__.errno == errno.ENOSPC
    assert not (out / MARKER_NAME).exists()
    monkeypatch.setattr(atomic, "_create_temp", real)
    res = refine_asset(box, PROMPT, out, no_clips, extras=True)  # the rerun redoes it (nothing foreign in the folder)
    assert not res.skipped and (out / "report.html").is_file() and (out / MARKER_NAME).is_file()


def _tree(root: Path) -> dict[str, str]:
    return {str(p.relative_to(root)): hashlib.sha256(p.read_bytes()).hexdigest() for p in sorted(root.rglob("*")) if p.is_file()}


def test_failed_force_rerun_keeps_the_earlier_complete_output(tmp_path, box, monkeypatch, refine_once):
    """--force over a complete output that then fails (here: the report step
    raises) leaves the earlier output byte for byte, marker valid, and no
    staging folder; a rerun that completes replaces it whole."""

    first = refine_once(box, PROMPT, extras=False)  # a complete output (the session's, copied)
    out = first.copy_to(tmp_path / "out")
    before = _tree(out)
    real = refine_report.build_report

    def broken(*a, **k):
        raise RuntimeError("refused mid-way")

    monkeypatch.setattr(refine_report, "build_report", broken)
    with pytest.raises(RuntimeError):
        refine_asset(box, "a small box with its lid closed", out, extras=False, skip_if_complete=False)
    assert _tree(out) == before
    assert is_complete(out, first.report.input_hash, first.report.config_hash)
    assert not of.staging_folder(out).exists()
    monkeypatch.setattr(refine_report, "build_report", real)
    again = refine_asset(box, "a small box with its lid closed", out, extras=False, skip_if_complete=False)
    assert is_complete(out, again.report.input_hash, again.report.config_hash)
    assert not is_complete(out, first.report.input_hash, first.report.config_hash)
    assert not of.staging_folder(out).exists() and of.foreign_files(out) == []
    assert set(json.loads((out / MARKER_NAME).read_text())["files"]) == set(_tree(out)) - {MARKER_NAME, of.TIMINGS_NAME}


def test_sigterm_during_a_rerun_cleans_up_as_ctrl_c_does(tmp_path, box, monkeypatch, refine_once, capsys):
    """``kill`` (SIGTERM) in the middle of a --force rerun unwinds as Ctrl-C does: the staging folder beside the output
    is removed at once (not left for the next run), the earlier output is kept byte for byte, exit status 143 with
    one line."""
    from asset2sim import cli

    first = refine_once(box, PROMPT, extras=False)
    out = first.copy_to(tmp_path / "out")
    before = _tree(out)

    def killed(*a, **k):  # the moment a scheduler sends SIGTERM: the staged rerun is half written
        assert of.staging_folder(out).is_dir()
        os.kill(os.getpid(), signal.SIGTERM)
        raise AssertionError("SIGTERM did not stop the command")

    monkeypatch.setattr(refine_report, "build_report", killed)
    previous = signal.getsignal(signal.SIGTERM)
    assert cli.main(["refine", str(box), "-p", PROMPT, "--out", str(out), "--no-extras", "--force", "-q"]) == 143
    assert signal.getsignal(signal.SIGTERM) is previous  # the command's handler is gone with it
    lines = capsys.readouterr().err.strip().splitlines()  # the --force warning naming what a finished rerun replaces
    assert lines[-1] == "asset2sim refine: TERMINATED" and all("which this run replaces" in x for x in lines[:-1]), lines
    assert not of.staging_folder(out).exists() and _tree(out) == before


def test_a_first_run_that_fails_mid_way_leaves_no_partial_output(tmp_path, box, monkeypatch):
    """An internal error after the writer ran (here: the report step raises)
    removes what the run wrote: no URDF without its report, no folder."""

    def broken(*a, **k):
        raise RuntimeError("internal error")

    monkeypatch.setattr(refine_report, "build_report", broken)
    out = tmp_path / "new" / "out"
    with pytest.raises(RuntimeError):
        refine_asset(box, PROMPT, out, extras=False)
    assert not out.exists()
    (tmp_path / "kept").mkdir()
    (tmp_path / "kept" / "user.txt").write_text("mine")
    with pytest.raises(RuntimeError):
        refine_asset(box, PROMPT, tmp_path / "kept", extras=False, overwrite=True)
    assert sorted(p.name for p in (tmp_path / "kept").iterdir()) == ["user.txt"]


def test_staged_rerun_records_the_folder_the_user_named(tmp_path, box, refine_once):
    """The evaluation of a rerun written in the staging folder names the
    output folder, not the staging folder it was written in."""
    out = refine_once(box, PROMPT, extras=True).copy_to(tmp_path / "out")  # a complete output (the session's, copied)
    res = refine_asset(box, PROMPT, out, extras=True, skip_if_complete=False)
    ev = json.loads((out / "evaluation.json").read_text())
    assert ev["urdf"] == "mobility.urdf"  # relative to the folder it lies in: neither the staging folder nor a place
    assert STAGING_SUFFIX not in (out / "report.html").read_text()
    assert all(Path(p).is_relative_to(out) for p in res.extras.values())


def test_staging_path_taken_by_a_user_file_is_refused(tmp_path, box, refine_once):
    out = refine_once(box, PROMPT, extras=False).copy_to(tmp_path / "out")  # a complete output (the session's, copied)
    of.staging_folder(out).write_text("mine")
    with pytest.raises(RefineError) as err:
        refine_asset(box, PROMPT, out, extras=False, skip_if_complete=False)
    assert err.value.codes == ["OUTPUT_NAME_CONFLICT"] and of.staging_folder(out).read_text() == "mine"


# ----------------------------------------------------------------------------- modes


@pytest.mark.parametrize("mask, mode", [(0o022, 0o644), (0o077, 0o600), (0o002, 0o664)])
def test_files_get_the_umask_mode(tmp_path, mask, mode):
    old = os.umask(mask)
    try:
        a = atomic.write_text(tmp_path / "a.txt", "x")
        (tmp_path / "src.bin").write_bytes(b"y")
        (b,) = atomic.copy_files([(tmp_path / "src.bin", tmp_path / "sub" / "b.bin")])
    finally:
        os.umask(old)
    for p in (a, b):
        assert stat.S_IMODE(p.stat().st_mode) == mode, (p, oct(p.stat().st_mode))
    assert not [p for p in tmp_path.rglob("*.tmp")]


def test_refine_output_is_readable_by_others_under_umask_022(tmp_path, box):
    old = os.umask(0o022)
    try:
        res = refine_asset(box, PROMPT, tmp_path / "out", extras=False)
    finally:
        os.umask(old)
    for p in res.out_dir.rglob("*"):
        if p.is_file():
            assert stat.S_IMODE(p.stat().st_mode) == 0o644, p


def test_files_evaluate_writes_into_a_refined_folder_are_the_products(tmp_path, box, refine_once):
    from asset2sim.cli import main

    out = refine_once(box, PROMPT, extras=False).copy_to(tmp_path / "out")  # a complete output (the session's, copied)
    assert main(["evaluate", str(out), "--out", str(out), "--no-probes", "--no-report"]) in (0, 1)  # asked to write into it
    assert (out / "evaluation.json").is_file()
    assert "evaluation.json" in of.recorded_files(out) and of.foreign_files(out) == []
    with of.adopting(tmp_path / "elsewhere") as owner:  # not an output folder: nothing recorded
        assert owner is None
    before = outside_hashes(tmp_path, out)
    res = refine_asset(box, "a small box with its lid closed", out, extras=False)  # no --overwrite needed
    assert not res.skipped and not (out / "evaluation.json").exists()  # stale after the rewrite: removed
    assert outside_hashes(tmp_path, out) == before


# ----------------------------------------------------------------------------- non-regular files in the output (no hang)


def _alarm(seconds: int):
    def on_alarm(signum, frame):
        raise TimeoutError(f"still blocked after {seconds} s")

    signal.signal(signal.SIGALRM, on_alarm)
    signal.alarm(seconds)


@pytest.mark.parametrize("name", [of.MARKER_NAME, of.RECORD_NAME])
@pytest.mark.parametrize("kind", ["fifo", "dir", "symlink"])
def test_bookkeeping_file_that_is_not_regular_is_refused_without_blocking(tmp_path, box, name, kind):
    out = tmp_path / "out"
    out.mkdir()
    p = out / name
    {"fifo": lambda: os.mkfifo(p), "dir": p.mkdir, "symlink": lambda: p.symlink_to(tmp_path / "elsewhere.json")}[kind]()
    before = outside_hashes(tmp_path, out)
    _alarm(20)
    try:
        assert of.recorded_files(out) == set()  # a FIFO is not read: no block
        assert not is_complete(out, "x", "y")
        with pytest.raises(of.OutputError) as err:
            of.check_location(box, out)
        assert err.value.code == "OUTPUT_RECORD_NOT_A_FILE" and err.value.path == p
        with pytest.raises(RefineError) as rerr:
            refine_asset(box, PROMPT, out, extras=False)
        assert "OUTPUT_RECORD_NOT_A_FILE" in rerr.value.codes
    finally:
        signal.alarm(0)
    assert outside_hashes(tmp_path, out) == before
    assert os.path.lexists(p)  # left for the user to look at


def test_read_regular_refuses_fifo_and_devices_at_once(tmp_path):
    fifo = tmp_path / "f"
    os.mkfifo(fifo)
    _alarm(10)
    try:
        for p in (fifo, Path("/dev/zero"), tmp_path):
            with pytest.raises(atomic.NotRegularFileError):
                atomic.read_regular(p)
            with pytest.raises(atomic.NotRegularFileError):
                atomic.sha256_file(p)
    finally:
        signal.alarm(0)
    (tmp_path / "r").write_bytes(b"abc")
    assert atomic.read_regular(tmp_path / "r") == b"abc"
    with pytest.raises(OSError):
        atomic.read_regular(tmp_path / "r", max_bytes=2)


def test_write_error_names_the_destination_not_the_temp_file(tmp_path):
    (tmp_path / "mobility.urdf").mkdir()
    with pytest.raises(IsADirectoryError) as err:
        atomic.write_text(tmp_path / "mobility.urdf", "x")
    assert err.value.filename == str(tmp_path / "mobility.urdf")
    assert not [p for p in tmp_path.iterdir() if p.name.endswith(".tmp")]


# ----------------------------------------------------------------------------- MTL statements naming files outside


def test_output_mtl_and_obj_never_reference_files_outside(tmp_path):
    """``map_Kd /etc/hostname``, ``map_Kd ../../x.png`` and an ``mtllib`` with an
    absolute path are dropped from the output's copies (validate warns); the
    statements that stay inside are kept, and files without such statements
    are copied byte for byte."""
    src = cb.build_valid(tmp_path / "in")
    (tmp_path / "x.png").write_bytes(cb.PNG_1PX)  # exists beside the input: must not be referenced
    (src / "meshes" / "base.mtl").write_text(
        "newmtl m0\nKd 0.8 0.6 0.4\nmap_Kd ../images/tex.png\nmap_Ks /etc/hostname\nmap_Bump -bm 1 ../../x.png\n"
        "newmtl m1\nKd 0.1 0.2 0.3\nmap_Kd file:///etc/passwd\n")
    base_obj = (src / "meshes" / "base.obj").read_text()
    (src / "meshes" / "base.obj").write_text("mtllib /etc/other.mtl\n" + base_obj)
    found = {f.code for f in validate_asset(src)}
    assert "MESH_MATERIAL_OUTSIDE" in found
    before = outside_hashes(tmp_path, tmp_path / "out")
    res = refine_asset(src, "a cabinet with the lid closed", tmp_path / "out", extras=False)
    out = res.out_dir
    mtl = (out / "meshes" / "base.mtl").read_text()
    obj = (out / "meshes" / "base.obj").read_text()
    assert "/etc/" not in mtl and "../../x.png" not in mtl and "file:" not in mtl and "/etc/" not in obj
    assert "map_Kd ../images/tex.png" in mtl and "Kd 0.1 0.2 0.3" in mtl and "mtllib base.mtl" in obj
    assert mtl.count("# asset2sim: a ") == 3 and obj.count("# asset2sim: a mtllib") == 1
    assert (out / "meshes" / "lid.obj").read_bytes() == (src / "meshes" / "lid.obj").read_bytes()
    for rel in ("meshes/base.mtl", "meshes/base.obj"):  # recorded and hashed as the output's own
        assert rel in json.loads((out / MARKER_NAME).read_text())["files"]
    assert is_complete(out, extract_asset(src).input_hash, json.loads((out / MARKER_NAME).read_text())["config_hash"])
    with open_session("pybullet", out / "mobility.urdf", SessionOptions(initial_state=res.report.initial_joint_positions)):
        pass
    assert outside_hashes(tmp_path, tmp_path / "out") == before


@pytest.mark.parametrize(
    "ref, inside",
    [("tex.png", True), ("../images/tex.png", True), ("a/../b.png", True), ("/etc/hostname", False), ("../../x", False),
     ("file:///x", False), ("package://p/x.png", False), ("C:\\x.png", False), ("../..", False)],
)
def test_reference_leaves_folder(ref, inside):
    assert copied_meshes.reference_leaves_folder(ref, "meshes/base.mtl") is (not inside)


def test_outputs_are_fsynced_scratch_files_and_the_ownership_record_are_not(tmp_path, box, monkeypatch, durable_writes):
    """Each output file is synced (the file and its folder) before it counts as written; a scratch folder's files
    (``atomic.add_scratch``) and the ownership record are written atomically without ``fsync``; a refine leaves no
    scratch folder registered."""
    synced: list[int] = []
    real = os.fsync
    monkeypatch.setattr(os, "fsync", lambda fd: (synced.append(fd), real(fd))[1])
    out = tmp_path / "out"
    owner = of.start(box, out)
    atomic.write_text(out / "a.json", "{}")  # the record is rewritten first (no fsync), then a.json (file + folder)
    assert len(synced) == 2 and json.loads((out / of.RECORD_NAME).read_text())["files"] == ["a.json"]
    owner.close()
    scratch = tmp_path / "scratch"
    atomic.add_scratch(scratch)
    try:
        atomic.write_bytes(scratch / "deep" / "b.obj", b"v 0 0 0\n")
        atomic.copy_files([(scratch / "deep" / "b.obj", scratch / "c.obj")])
        assert len(synced) == 2 and (scratch / "c.obj").read_bytes() == b"v 0 0 0\n"
        assert not list(scratch.rglob("*.tmp"))
    finally:
        atomic.remove_scratch(scratch)
    atomic.write_bytes(scratch / "d.obj", b"")  # no longer scratch: synced again
    assert len(synced) == 4
    refine_asset(box, "", tmp_path / "refined", extras=False)
    assert atomic._SCRATCH == {}


def test_remove_owned_removes_only_the_products_files(tmp_path, box, refine_once):
    """The flow's clean-up after an upload (``output_folder.remove_owned``) removes what the refine recorded and
    leaves a user's file (with its folder); a folder holding only the product's files goes whole."""
    refined = refine_once(box, PROMPT, extras=False)  # a complete output (the session's, copied twice)
    out = refined.copy_to(tmp_path / "out")
    (out / "my_notes.txt").write_text("keep me")
    (out / "collision" / "mine.obj").parent.mkdir(exist_ok=True)
    (out / "collision" / "mine.obj").write_text("v 0 0 0\n")
    before = outside_hashes(tmp_path, out)
    left = of.remove_owned(out)
    assert left == ["collision/mine.obj", "my_notes.txt"]
    assert sorted(str(p.relative_to(out)) for p in out.rglob("*") if p.is_file()) == left
    assert outside_hashes(tmp_path, out) == before
    out2 = refined.copy_to(tmp_path / "out2")
    assert of.remove_owned(out2) == [] and not out2.exists()
