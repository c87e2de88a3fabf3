"""write.mesh_copies is kept per process and computed again when a file it
read changes (an OBJ gains an MTL library, an MTL a texture, a file is
replaced): never a stale answer."""

from __future__ import annotations

import os
import shutil

import pytest

from asset2sim import demo_assets
from asset2sim.tasks.ingest.extract import extract_asset
from asset2sim.tasks.assemble import copied_meshes
from tests.conftest import NO_SHARED, SHARED


@pytest.fixture
def cabinet(tmp_path):
    return demo_assets.build_two_drawer_cabinet(tmp_path / "cabinet")


def _bump(path):
    """Make sure a rewrite shows in the modification time even on a coarse clock."""
    st = os.stat(path)
    os.utime(path, ns=(st.st_atime_ns, st.st_mtime_ns + 1_000_000))


def test_cached_answer_equals_a_fresh_one_and_follows_edits(cabinet):
    asset = extract_asset(cabinet)
    first = copied_meshes.mesh_copies(asset)
    assert first == copied_meshes._mesh_copies(asset)
    again = copied_meshes.mesh_copies(asset)
    assert again == first and again is not first  # a copy: callers may not change the cache
    again.clear()
    assert copied_meshes.mesh_copies(asset) == first

    # an OBJ gains an MTL library with a texture: both must be copied now
    obj = sorted(p for p in first.values() if p.suffix == ".obj")[0]
    obj.write_bytes(b"mtllib added_lib.mtl\n" + obj.read_bytes())
    (obj.parent / "added_lib.mtl").write_text("newmtl m\nmap_Kd added_tex.png\n")
    (obj.parent / "added_tex.png").write_bytes(b"\x89PNG")
    _bump(obj)
    edited = copied_meshes.mesh_copies(asset)
    assert edited == copied_meshes._mesh_copies(asset)
    assert any(k.endswith("added_lib.mtl") for k in edited) and any(k.endswith("added_tex.png") for k in edited)

    # the MTL loses its texture line: the texture is no longer copied
    mtl = next(v for k, v in edited.items() if k.endswith("added_lib.mtl"))
    mtl.write_text("newmtl m\n")
    _bump(mtl)
    assert not any(k.endswith("added_tex.png") for k in copied_meshes.mesh_copies(asset))


def test_cache_on_a_real_asset_is_identical(tmp_path):
    src = SHARED / "100221"
    if not (src / "mobility.urdf").is_file():
        pytest.skip(NO_SHARED)
    shutil.copytree(src, tmp_path / "a")
    asset = extract_asset(tmp_path / "a")
    fresh = copied_meshes._mesh_copies(asset)
    assert len(fresh) > 50
    assert copied_meshes.mesh_copies(asset) == fresh
    assert copied_meshes.mesh_copies(asset) == fresh  # from the cache
    victim = sorted(p for p in fresh.values() if p.suffix == ".mtl")[0]
    victim.unlink()  # a removed MTL is no longer copied
    assert copied_meshes.mesh_copies(asset) == copied_meshes._mesh_copies(asset) != fresh


def test_only_meshes_naming_outside_files_are_edited_line_by_line(tmp_path, monkeypatch):
    """A copy edits an OBJ line by line only when one of its ``mtllib`` names a file outside the asset folder
    (or a CR may split its lines otherwise): the other OBJs are copied as they are, the edited one drops the
    statement, and a file whose bytes change is edited again."""
    src = SHARED / "100221"
    if not (src / "mobility.urdf").is_file():
        pytest.skip(NO_SHARED)
    shutil.copytree(src, tmp_path / "a")
    objs = sorted((tmp_path / "a").rglob("*.obj"))
    obj, crlf = objs[0], objs[1]
    obj.write_bytes(b"mtllib ../../../outside.mtl\n" + obj.read_bytes())  # a reference the copy drops
    crlf.write_bytes(crlf.read_bytes().replace(b"\n", b"\r\n"))  # read line by line, nothing to drop
    asset = extract_asset(tmp_path / "a")
    scans: list[str] = []
    real = copied_meshes._drop_outside_references

    def counting(data, rel, names_of):
        scans.append(rel)
        return real(data, rel, names_of)

    monkeypatch.setattr(copied_meshes, "_drop_outside_references", counting)
    copied_meshes.copy_meshes(asset, tmp_path / "one")
    rel, rel_crlf = (p.relative_to(tmp_path / "a").as_posix() for p in (obj, crlf))
    assert sorted(s for s in scans if s.endswith(".obj")) == sorted([rel, rel_crlf])  # every other OBJ copied as it is
    assert (tmp_path / "one" / rel_crlf).read_bytes() == crlf.read_bytes()
    for other in objs[2:]:
        assert (tmp_path / "one" / other.relative_to(tmp_path / "a")).read_bytes() == other.read_bytes()
    one = (tmp_path / "one" / rel).read_bytes()
    assert b"outside.mtl" not in one and b"was dropped" in one
    obj.write_bytes(obj.read_bytes().replace(b"outside.mtl", b"elsewhere.mtl"))
    _bump(obj)
    copied_meshes.copy_meshes(extract_asset(tmp_path / "a"), tmp_path / "three")
    assert scans.count(rel) == 2  # new bytes: edited again
    assert b"elsewhere.mtl" not in (tmp_path / "three" / rel).read_bytes()
