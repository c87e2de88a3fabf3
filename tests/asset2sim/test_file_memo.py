"""Results kept while their files are unchanged: the URDF reader and the
asset extraction give each caller its own copy and read a changed file again."""

from __future__ import annotations

import os
import shutil
from pathlib import Path

from asset2sim import atomic, file_memo, urdf
from asset2sim.tasks.ingest import extract


def _copy_asset(demo_root: Path, tmp_path: Path, name: str = "box_lid") -> Path:
    return Path(shutil.copytree(demo_root / name, tmp_path / name))


def test_a_memo_entry_holds_until_a_file_it_came_from_changes(tmp_path):
    f = tmp_path / "a.txt"
    f.write_text("one")
    memo: file_memo.FileMemo[list] = file_memo.FileMemo(list, max_entries=2)
    memo.put("k", file_memo.identities([f]), [1, 2])
    got = memo.get("k")
    assert got == [1, 2]
    got.append(3)  # the caller's copy; the stored result stays
    assert memo.get("k") == [1, 2]
    atomic.write_text(f, "two")  # a new inode
    assert memo.get("k") is None
    memo.put("k", file_memo.identities([f]), [4])
    st = f.stat()
    with open(f, "r+") as fh:  # an edit in place: same inode and size, a later modification time
        fh.write("TWO")
    os.utime(f, ns=(st.st_atime_ns, st.st_mtime_ns + 1_000_000))
    assert memo.get("k") is None
    memo.put("missing", file_memo.identities([tmp_path / "nowhere"]), [5])  # a file that did not exist: not kept
    assert memo.get("missing") is None
    for k in ("a", "b", "c"):  # least recently used dropped beyond max_entries
        memo.put(k, file_memo.identities([f]), [k])
    assert memo.get("a") is None and memo.get("c") == ["c"]


def test_read_urdf_gives_each_caller_its_own_model_and_reads_a_rewritten_file(demo_root, tmp_path):
    folder = _copy_asset(demo_root, tmp_path)
    path = folder / "mobility.urdf"
    fresh = urdf.parse_urdf_bytes(path.read_bytes(), source=str(path), base=path.parent, mode="lenient")
    first = urdf.read_urdf(path, mode="lenient")
    hits = urdf.reader._READ_MEMO.hits
    movable = first.movable_joints[0]
    movable.limit.upper = 99.0  # a caller changes its model (convex_collisions replaces collisions in place)
    next(iter(first.links.values())).collisions.clear()
    second = urdf.read_urdf(path, mode="lenient")
    assert urdf.reader._READ_MEMO.hits == hits + 1
    assert second == fresh and second.path == path
    assert second.joint(movable.name).upper != 99.0

    text = path.read_text().replace(f'upper="{_upper_text(path, movable.name)}"', 'upper="0.5"', 1)
    atomic.write_text(path, text)
    assert urdf.read_urdf(path, mode="lenient").joint(movable.name).upper == 0.5


def _upper_text(path: Path, joint: str) -> str:
    """The upper limit of ``joint`` as written in ``path``."""
    import re

    block = path.read_text().split(f'name="{joint}"', 1)[1]
    return re.search(r'upper="([^"]+)"', block).group(1)


def test_extract_reads_the_asset_again_when_a_referenced_mesh_changes(demo_root, tmp_path):
    folder = _copy_asset(demo_root, tmp_path)
    desc, findings = extract.extract_asset_checked(folder)
    desc.joints[0].lower = -42.0  # the caller's copy
    again, findings_again = extract.extract_asset_checked(folder)
    assert again.joints[0].lower != -42.0
    assert again.input_hash == desc.input_hash and findings_again == findings

    mesh = next(g.path for ln in again.links for g in ln.collisions if g.path is not None)
    with open(mesh, "a") as fh:  # an edit the description does not show, the input hash does
        fh.write("# edited\n")
    edited = extract.extract_asset(folder)
    assert edited.input_hash != desc.input_hash
    assert edited.input_hash == extract.extract_asset(folder).input_hash
