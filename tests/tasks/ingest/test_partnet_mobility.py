"""The PartNet-Mobility adapter on the real dev folder (21 objects + manifest)."""

from __future__ import annotations

import json
import os

import pytest

from asset2sim.tasks.ingest import partnet_mobility as pm
from asset2sim.tasks.ingest.errors import AssetError
from tests.conftest import SHARED, needs_shared

pytestmark = needs_shared


def test_manifest_rows_are_typed_and_point_at_the_folders():
    rows = pm.read_manifest(SHARED / pm.MANIFEST_NAME)
    assert len(rows) == 21 and len({r.id for r in rows}) == 21
    by_id = {r.id: r for r in rows}
    st = by_id["103275"]
    assert (st.category, st.gensim2_task, st.reference_scale, st.reference_joint_range) == ("Stapler", "stapler_press", 0.1, (-0.15, 0.3))
    assert st.prompt == "I want a slightly open stapler." and st.folder == SHARED / "103275"
    assert by_id["7236"].reference_joint_range is None  # written as """""" in the CSV
    for r in rows:
        assert r.folder.is_dir() and r.prompt and r.category
        assert r.reference_scale is None or r.reference_scale > 0


def test_manifest_errors_name_file_line_and_id(tmp_path):
    m = tmp_path / "m.csv"
    cases = {
        "id,prompt\n,x\n": "without id",
        "id,prompt\n../x,y\n": "invalid asset id",
        "id,prompt\na,x\na,y\n": "duplicate",
        "id,category\na,b\n": "prompt",
        "id,prompt,reference_scale\n7,x,abc\n": r"m.csv:2 \(id 7\): reference_scale",
        "id,prompt,reference_scale\n7,x,-1\n": "positive",
        "id,prompt,reference_joint_range\n7,x,[1]\n": "reference_joint_range",
    }
    for text, match in cases.items():
        m.write_text(text)
        with pytest.raises(pm.ManifestError, match=match):
            pm.read_manifest(m)
    m.write_text("\ufeffid,prompt,time_limit_seconds\nbox,A box.,30\n")  # a byte-order mark is fine
    (row,) = pm.read_manifest(m, root=tmp_path / "r")
    assert row.id == "box" and row.time_limit_seconds == 30.0 and row.folder == tmp_path / "r" / "box"
    with pytest.raises(FileNotFoundError):
        pm.read_manifest(tmp_path / "none.csv")


def test_every_object_has_urdf_semantics_category_and_reference():
    links_seen = 0
    for row in pm.read_manifest(SHARED / pm.MANIFEST_NAME):
        urdf = pm.find_urdf(row.folder)
        assert urdf == row.folder / "mobility.urdf"
        sem = pm.read_semantics(row.folder)
        assert sem and all(s.joint_kind in {"hinge", "slider", "free", "heavy", "static", "junk"} for s in sem.values())
        links_seen += len(sem)
        assert pm.read_category(row.folder) == json.loads((row.folder / "meta.json").read_text())["model_cat"]
        assert pm.has_reference(row.folder)
        ref = pm.read_reference(row.folder)
        assert ref.urdf == row.folder / pm.REFERENCE_URDF and ref.task_joints
        if row.reference_scale is not None:
            assert ref.scale == row.reference_scale
        if row.reference_joint_range is not None:
            assert ref.joint_position_range == row.reference_joint_range
    assert links_seen > 21


def test_semantics_tuple_shape_and_line_parsing():
    sem = pm.read_semantics(SHARED / "103275")
    assert sem["link_1"] == ("hinge", "lid")
    kind, label = sem["link_2"]
    assert (kind, label) == ("free", "stapler_base")
    lines = list(pm.iter_semantics("a hinge big lid\n\nbad line\n"))
    assert [ln.lineno for ln in lines] == [1, 3]
    assert lines[0].entry == pm.Semantics("hinge", "big lid") and lines[1].entry is None


def test_semantics_writer_round_trips_every_dev_object_and_refuses_what_the_format_cannot_say():
    for row in pm.read_manifest(SHARED / pm.MANIFEST_NAME):
        sem = pm.read_semantics(row.folder)
        again = {ln.link: ln.entry for ln in pm.iter_semantics(pm.format_semantics(sem))}
        assert again == sem and list(again) == list(sem), row.id
    assert pm.format_semantics({"a": pm.Semantics("hinge", "big  lid")}) == "a hinge big lid\n"
    for bad, word in [({"a b": pm.Semantics("hinge", "lid")}, "'a b'"), ({"a": pm.Semantics("", "lid")}, "'a'"),
                      ({"a": pm.Semantics("hinge", "lid\nx")}, "'a'"), ({"a": pm.Semantics("hinge", " ")}, "'a'")]:
        with pytest.raises(ValueError, match=word):
            pm.format_semantics(bad)


def test_find_urdf_rules(tmp_path):
    (tmp_path / "reference_gensim2.urdf").write_text("<robot/>")
    with pytest.raises(AssetError, match="no mobility.urdf"):
        pm.find_urdf(tmp_path)
    (tmp_path / "other.urdf").write_text("<robot/>")
    assert pm.find_urdf(tmp_path) == tmp_path / "other.urdf"  # reference_* never counts
    (tmp_path / "third.urdf").write_text("<robot/>")
    with pytest.raises(AssetError, match="several"):
        pm.find_urdf(tmp_path)
    os.mkfifo(tmp_path / "mobility.urdf")
    with pytest.raises(AssetError, match="not a regular file"):
        pm.find_urdf(tmp_path)  # mobility.urdf wins and is never opened
    with pytest.raises(AssetError, match="no such"):
        pm.find_urdf(tmp_path / "gone")


def test_side_files_absent_or_broken(tmp_path):
    assert pm.read_semantics(tmp_path) == {} and pm.read_category(tmp_path) is None
    assert pm.read_reference(tmp_path) == pm.GenSim2Reference() and not pm.has_reference(tmp_path)
    (tmp_path / "semantics.txt").write_text("link_0 hinge\n")
    with pytest.raises(AssetError, match="semantics.txt:1"):
        pm.read_semantics(tmp_path)
    (tmp_path / "meta.json").write_text("[1, 2]")
    assert pm.read_category(tmp_path) is None
    (tmp_path / "meta.json").write_text("{not json")
    assert pm.read_category(tmp_path) is None
    assert pm.meta_category({"model_cat": "Box"}) == "Box" and pm.meta_category({"model_cat": ""}) is None


def test_manifest_rows_bad_rows_are_typed_errors_and_the_others_are_kept(tmp_path):
    """read_manifest_rows: each bad row a typed error (line, id when known,
    code); the good rows around it are kept, in file order."""
    m = tmp_path / "m.csv"
    huge = "x" * 200_000  # beyond csv.field_size_limit() (131072)
    m.write_text(
        "id,category,prompt,reference_scale,time_limit_seconds\n"
        "a,Box,open it,0.5,\n"  # 2
        f"big,Box,{huge},,\n"  # 3: too long for the CSV reader, id still read
        f"{huge},Box,p,,\n"  # 4: too long, in the id itself
        "../x,Box,p,,\n"  # 5
        ",Box,p,,\n"  # 6
        "a,Box,again,,\n"  # 7
        "short,Box\n"  # 8
        "extra,Box,p,,,surplus\n"  # 9
        "neg,Box,p,-1,\n"  # 10
        "slow,Box,p,,inf\n"  # 11
        "\n"  # 12: blank, skipped
        'b,Box,"two\nlines",0.2,\n'  # 13-14
        "c,Box,,,\n"  # 15: an empty prompt is usable
    )
    reading = pm.read_manifest_rows(m)
    assert [(r.id, r.line) for r in reading.rows] == [("a", 2), ("b", 13), ("c", 15)]
    assert reading.rows[1].prompt == "two\nlines" and reading.rows[2].prompt == ""
    got = [(e.line, e.id, e.code) for e in reading.errors]
    assert got == [
        (3, "big", "MANIFEST_ROW_TOO_LARGE"),
        (4, None, "MANIFEST_ROW_TOO_LARGE"),
        (5, "../x", "MANIFEST_INVALID_ID"),
        (6, None, "MANIFEST_MISSING_ID"),
        (7, "a", "MANIFEST_DUPLICATE_ID"),
        (8, "short", "MANIFEST_MISSING_PROMPT"),
        (9, "extra", "MANIFEST_EXTRA_FIELDS"),
        (10, "neg", "MANIFEST_INVALID_REFERENCE_SCALE"),
        (11, "slow", "MANIFEST_INVALID_TIME_LIMIT"),
    ]
    assert all(e.code in pm.ROW_ERROR_CODES and f"m.csv:{e.line}" in e.message for e in reading.errors)
    assert all(len(e.message) < 400 for e in reading.errors)  # a huge field is never echoed
    # the strict reader refuses the file at its first bad row, with that row's code
    with pytest.raises(pm.ManifestError, match=r"m.csv:3 \(id big\).*and 8 more") as info:
        pm.read_manifest(m)
    assert info.value.code == "MANIFEST_ROW_TOO_LARGE"


def test_a_file_that_is_not_a_csv_manifest_fails_as_a_whole(tmp_path):
    m = tmp_path / "m.csv"
    m.write_bytes(b"\x89PNG\r\n\x1a\n\x00\x00\xff\xfe")
    with pytest.raises(pm.ManifestError, match="not a CSV manifest") as info:
        pm.read_manifest_rows(m)
    assert info.value.code == "MANIFEST_NOT_TEXT"
    for text in ("", "{\"id\": 1}\n", "name,request\nbox,open\n"):
        m.write_text(text)
        with pytest.raises(pm.ManifestError, match="missing column") as info:
            pm.read_manifest_rows(m)
        assert info.value.code == "MANIFEST_MISSING_COLUMNS"
    m.write_text("id," + "h" * 200_000 + "\n")
    with pytest.raises(pm.ManifestError) as info:
        pm.read_manifest_rows(m)
    assert info.value.code == "MANIFEST_BAD_HEADER"


def test_the_gensim2_reference_is_written_as_an_asset_folder_at_its_scale(tmp_path):
    """write_reference: the stapler's reference_gensim2.urdf at its JSON's scale, the task joint's limits within
    GenSim2's range, the initial state at the range's lower end; a folder without a reference is refused."""
    ref = pm.read_reference(SHARED / "103275")
    out = pm.write_reference(SHARED / "103275", tmp_path / "ref")
    assert out.urdf == tmp_path / "ref" / "mobility.urdf" and out.source == ref.urdf and out.scale == ref.scale
    assert "GenSim2 reference of 103275 at scale" in out.urdf.read_text()
    joints = pm.urdf_joints(out.urdf)
    lo, hi = ref.joint_position_range
    for j in ref.task_joints:
        assert lo - 1e-9 <= joints[j]["lower"] <= joints[j]["upper"] <= hi + 1e-9
        assert out.initial_state[j] == pytest.approx(joints[j]["lower"])
    assert json.loads((tmp_path / "ref" / "initial_state.json").read_text()) == {"initial_joint_positions": out.initial_state}
    with pytest.raises(AssetError, match="no reference_gensim2.urdf"):
        pm.write_reference(tmp_path / "ref", tmp_path / "again")
