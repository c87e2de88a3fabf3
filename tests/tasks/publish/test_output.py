"""The output folder written once: candidates in memory, engines loading them
from the workspace, publish writing the final one."""

from __future__ import annotations

import builtins
import dataclasses
import io
import os
import traceback
from pathlib import Path

import pytest

from asset2sim import demo_assets, mesh_io, urdf
from asset2sim.output_paths import OutputError
from asset2sim.tasks.assemble import write
from asset2sim.tasks.assemble.candidate import Candidate, Workspace
from asset2sim.tasks.ingest import extract
from asset2sim.tasks.publish import output
from asset2sim.tasks.refine import refine_asset
from asset2sim.tasks.state.collision import CollisionPiece

CUBE_OBJ = "".join(f"v {x} {y} {z}\n" for x in (0, 0.01) for y in (0, 0.01) for z in (0, 0.01)) + \
    "f 1 3 2\nf 2 3 4\nf 5 6 7\nf 6 8 7\nf 1 2 5\nf 2 6 5\nf 3 7 4\nf 4 7 8\nf 1 5 3\nf 3 5 7\nf 2 4 6\nf 4 8 6\n"


@pytest.fixture(scope="module")
def refined(demo_root, tmp_path_factory):
    """box_lid refined (its damping escalates once: several candidates) with every
    call of the writer, the output folder's content when publish began and the
    code that read a file of the workspace, URDF or mesh, through Python's
    ``open`` or ``os.open`` (the memos of read URDFs and extracted assets off,
    so that every read reaches the file) recorded."""
    entry = next(e for e in demo_assets.DEMO_OBJECTS if e.asset_id == "box_lid")
    out = tmp_path_factory.mktemp("published") / "out"
    calls: list[Path] = []
    at_publish: list[list[str]] = []
    scratch_readers: list[Path] = []
    real_write, real_publish = write.write_output, output.publish
    real_open, real_os_open = io.open, os.open

    def counting_write(asset, overlay, out_dir, *a, **k):
        calls.append(Path(out_dir).resolve())
        return real_write(asset, overlay, out_dir, *a, **k)

    def watching_publish(candidate, workspace, out_dir):
        at_publish.append(sorted(p.name for p in Path(out_dir).iterdir()))
        return real_publish(candidate, workspace, out_dir)

    def record(path) -> None:
        if isinstance(path, (str, os.PathLike)) and "asset2sim-candidates-" in str(path) and not os.path.isdir(path):
            # the reader: the innermost frame of the project outside the modules that read files on a caller's behalf
            frames = [Path(f.filename) for f in traceback.extract_stack()[:-2]]
            scratch_readers.append(next(f for f in reversed(frames) if PROJECT in f.parents and f.name not in READERS
                                        and "/".join(f.parts[-2:]) not in READERS))

    def watching_open(file, mode="r", *a, **k):
        if not set(mode) & set("wax+"):
            record(file)
        return real_open(file, mode, *a, **k)

    def watching_os_open(path, flags, *a, **k):
        if not flags & (os.O_WRONLY | os.O_RDWR | os.O_CREAT):
            record(path)
        return real_os_open(path, flags, *a, **k)

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(write, "write_output", counting_write)
        mp.setattr(output, "publish", watching_publish)
        mp.setattr(io, "open", watching_open)
        mp.setattr(builtins, "open", watching_open)
        mp.setattr(os, "open", watching_os_open)
        mp.setattr(urdf.reader._READ_MEMO, "get", lambda key: None)
        mp.setattr(extract._EXTRACT_MEMO, "get", lambda key: None)
        res = refine_asset(demo_root / entry.asset_id, entry.prompt, out)
    return res, out.resolve(), calls, at_publish, scratch_readers


#: Modules that read files on a caller's behalf (the caller is the reader that counts).
READERS = {"safexml.py", "urdf/reader.py", "loading.py", "mesh_io.py", "atomic.py"}
PROJECT = Path(__file__).resolve().parents[3]


def test_the_output_folder_is_written_once_by_publish(refined):
    res, out, calls, at_publish, _ = refined
    into_output = [c for c in calls if c == out or out in c.parents]
    elsewhere = {c for c in calls if c not in into_output}
    assert len(into_output) == 1
    assert len(calls) - 1 >= 3, "box_lid tries several candidates"
    # every candidate went to one scratch folder outside the output, gone once the refine ended
    assert len(elsewhere) == 1
    scratch = elsewhere.pop()
    assert out not in scratch.parents and not scratch.exists()
    # the mesh bytes kept for the stages are dropped with the workspace and after publish (a flow worker goes on)
    assert not [k for k in mesh_io._WRITTEN if Path(k).is_relative_to(scratch) or Path(k).is_relative_to(out)]
    # when publish began, the output folder held nothing but the ownership record
    assert at_publish == [[".asset2sim-owned.json"]]
    assert res.report.failure_mode == "none" and (out / "mobility.urdf").is_file()


def test_only_engines_read_the_workspace_the_stages_take_the_candidates_model(refined):
    *_, readers = refined
    assert readers, "the engines load every candidate from the workspace"
    not_engines = sorted({str(r) for r in readers if "engines" not in r.parts})
    assert not not_engines, f"stages read a file the refine wrote: {not_engines}"


def test_publish_copies_the_repaired_pieces_and_refuses_names_that_leave(refined, demo_root, tmp_path):
    res, out, _, _, _ = refined
    asset, _ = extract.extract_asset_checked(demo_root / "box_lid")
    state = {k: float(v) for k, v in res.report.initial_joint_positions.items()}
    link = next(ln for ln in asset.links if any(g.kind == "mesh" for g in ln.collisions))
    source = next(g for g in link.collisions if g.kind == "mesh")
    piece = CollisionPiece(filename="collision/repaired_0_0.obj", source=source)
    cand = Candidate(asset, res.overlay, state, {link.name: [piece]})
    with Workspace(asset) as ws:
        (ws.root / "collision").mkdir()
        (ws.root / "collision" / "repaired_0_0.obj").write_text(CUBE_OBJ)
        ws.load(cand)
        target = tmp_path / "pub"
        paths = output.publish(cand, ws, target)
        assert (target / "collision" / "repaired_0_0.obj").read_text() == CUBE_OBJ
        assert paths.urdf.read_bytes() == ws.load(cand).read_bytes()
        leaving = dataclasses.replace(cand, collision_overrides={link.name: [dataclasses.replace(piece, filename="../escaped.obj")]})
        with pytest.raises(OutputError):
            output.publish(leaving, ws, tmp_path / "pub2")
        assert not (tmp_path / "escaped.obj").exists()
    assert not ws.root.exists()


def test_a_candidate_is_frozen_and_the_workspace_model_is_the_file_as_read(refined, demo_root):
    res, out, _, _, _ = refined
    asset, _ = extract.extract_asset_checked(demo_root / "box_lid")
    state = dict(res.report.initial_joint_positions)
    cand = Candidate(asset, res.overlay, state)
    with pytest.raises(dataclasses.FrozenInstanceError):
        cand.overlay = res.overlay
    with pytest.raises(TypeError):
        cand.state["x"] = 1.0
    state.clear()  # the candidate took its own copy
    assert dict(cand.state) == dict(res.report.initial_joint_positions)
    moved = dataclasses.replace(cand, state={k: 0.0 for k in cand.state})
    assert set(moved.state.values()) == {0.0} and cand.state != moved.state
    with Workspace(asset) as ws:
        model = ws.model(cand)
        read = urdf.read_urdf(ws.load(cand))
        assert urdf.write_urdf(model) == urdf.write_urdf(read)
        assert [(n, str(g.path)) for n, ln in model.links.items() for g in ln.collisions] == \
            [(n, str(g.path)) for n, ln in read.links.items() for g in ln.collisions]
        model.joints[0].name = "changed"  # a copy: the next caller gets the model as loaded
        assert ws.model(cand).joints[0].name != "changed"
        assert os.path.commonpath([ws.root, ws.load(cand)]) == str(ws.root)


def test_a_workspace_removes_what_killed_runs_left_and_nothing_else(refined, demo_root, tmp_path, monkeypatch):
    import subprocess
    import sys
    import tempfile

    from asset2sim.tasks.assemble.candidate import SCRATCH_PREFIX

    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    gone = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True, check=True)
    dead = tmp_path / f"{SCRATCH_PREFIX}{gone.stdout.strip()}-abc"
    alive = tmp_path / f"{SCRATCH_PREFIX}{os.getpid()}-def"
    kept_elsewhere = tmp_path / "elsewhere"
    for d in (dead, alive, kept_elsewhere):
        (d / "collision").mkdir(parents=True)
        (d / "collision" / "x.obj").write_text(CUBE_OBJ)
    link = tmp_path / f"{SCRATCH_PREFIX}1-link"  # a symlink named like an orphan is never followed
    link.symlink_to(kept_elsewhere)
    asset, _ = extract.extract_asset_checked(demo_root / "box_lid")
    with Workspace(asset) as ws:
        assert ws.root.parent == tmp_path.resolve() and ws.root.name.startswith(f"{SCRATCH_PREFIX}{os.getpid()}-")
        assert not dead.exists()
        assert (alive / "collision" / "x.obj").is_file() and (kept_elsewhere / "collision" / "x.obj").is_file()
        assert link.is_symlink()
    assert not ws.root.exists()
