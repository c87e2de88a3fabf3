"""Input validation: numbers, inertia, mesh paths, policy, extraction wiring, CLI, real data."""

from __future__ import annotations

import json
import os
import re
from pathlib import Path

import numpy as np
import pytest

from asset2sim import cli
from asset2sim.tasks.ingest import validate_input as vi
from asset2sim.tasks.ingest.extract import AssetError, extract_asset, extract_asset_checked
from tests import corpus_builder as cb
from tests.conftest import ROOT, SHARED, needs_shared
from tests.helpers import tree_hashes


# ----------------------------------------------------------------------------- numbers


@pytest.mark.parametrize(
    "text,count,expected",
    [
        ("0 1 2", 3, (0.0, 1.0, 2.0)),
        ("-1.5e-3 +2. .5", 3, (-1.5e-3, 2.0, 0.5)),
        ("  7\t\n", 1, (7.0,)),
        ("1e-400", 1, (0.0,)),  # underflow to 0 is finite: accepted
        ("2", (1, 3), (2.0,)),
    ],
)
def test_numbers_accepted(text, count, expected):
    assert vi.parse_number_list(text, count) == expected


@pytest.mark.parametrize(
    "text,code",
    [
        ("nan", "NUMBER_NAN"),
        ("-NaN", "NUMBER_NAN"),
        ("inf", "NUMBER_INF"),
        ("-Infinity", "NUMBER_INF"),
        ("1e400", "NUMBER_OVERFLOW"),
        ("-1.8e308", "NUMBER_OVERFLOW"),
        ("", "NUMBER_EMPTY"),
        ("   ", "NUMBER_EMPTY"),
        (None, "NUMBER_EMPTY"),
        ("1.0.0", "NUMBER_MALFORMED"),
        ("0x10", "NUMBER_MALFORMED"),
        ("1_000", "NUMBER_MALFORMED"),  # Python's float() accepts it
        ("1,5", "NUMBER_MALFORMED"),
        ("one", "NUMBER_MALFORMED"),
        ("\u0661", "NUMBER_MALFORMED"),  # Arabic-Indic digit one: float() accepts it
        ("1 2", "NUMBER_COUNT"),
    ],
)
def test_numbers_rejected(text, code):
    with pytest.raises(vi.NumberError) as info:
        vi.parse_number_list(text, 1 if code != "NUMBER_COUNT" else 3)
    assert info.value.code == code


# ----------------------------------------------------------------------------- inertia


def test_check_inertia_reports_eigenvalues_and_never_balances():
    assert vi.check_inertia(0.1, 0, 0, 0.1, 0, 0.1)[0] is None
    assert vi.check_inertia(1, 0, 0, 1, 0, 2)[0] is None  # flat lamina: equality is allowed
    code, lam = vi.check_inertia(-0.02, 0, 0, 0.02, 0, 0.03)
    assert code == "INERTIA_NOT_POSITIVE_DEFINITE"
    assert lam == pytest.approx([-0.02, 0.02, 0.03])
    code, lam = vi.check_inertia(0.01, 0, 0, 0.01, 0, 0.03)
    assert code == "INERTIA_TRIANGLE_INEQUALITY" and lam == pytest.approx([0.01, 0.01, 0.03])
    code, lam = vi.check_inertia(0.02, 0.05, 0, 0.02, 0, 0.03)  # off-diagonal makes it indefinite
    assert code == "INERTIA_NOT_POSITIVE_DEFINITE" and lam[0] < 0
    assert vi.check_inertia(0, 0, 0, 0, 0, 0)[0] == "INERTIA_NOT_POSITIVE_DEFINITE"


# ----------------------------------------------------------------------------- mesh references


def test_resolve_mesh_reference(tmp_path):
    asset = cb.build_valid(tmp_path / "a")
    ok = vi.resolve_mesh_reference(asset, "meshes/lid.obj")
    assert ok.code is None and ok.path == (asset / "meshes" / "lid.obj").resolve() and ok.size > 0
    # '..' that stays inside is fine
    assert vi.resolve_mesh_reference(asset, "images/../meshes/lid.obj").code is None
    # symlink inside the folder is fine
    os.symlink("lid.obj", asset / "meshes" / "alias.obj")
    assert vi.resolve_mesh_reference(asset, "meshes/alias.obj").path == (asset / "meshes" / "lid.obj").resolve()
    assert vi.resolve_mesh_reference(asset, "meshes/li\x00d.obj").code == "MESH_PATH_NUL"
    assert vi.resolve_mesh_reference(asset, "data:model/obj;base64,AAAA").code == "MESH_URI_FORBIDDEN"
    assert vi.resolve_mesh_reference(asset, "\\\\server\\share\\x.obj").code == "MESH_PATH_ABSOLUTE"
    assert vi.resolve_mesh_reference(asset, "meshes/lid.obj", max_bytes=10).code == "MESH_TOO_LARGE"
    assert vi.resolve_mesh_reference(asset, "meshes/lid.OBJ").code == "MESH_NOT_FOUND"
    assert vi.resolve_mesh_reference(asset, "meshes/lid.obj/x.obj").code == "MESH_NOT_FOUND"


@pytest.mark.skipif(not Path("/dev/null").exists(), reason="no /dev/null")
def test_device_is_not_a_regular_file():
    ref = vi.resolve_mesh_reference("/dev", "null", extensions=())
    assert ref.code == "MESH_NOT_REGULAR_FILE" and "character device" in ref.message


# ----------------------------------------------------------------------------- valid asset & extraction


def test_valid_asset_is_clean_and_extracts(tmp_path):
    asset = cb.build_valid(tmp_path / "a")
    before = tree_hashes(asset)
    findings = vi.validate_asset(asset)
    assert [f.describe() for f in findings if f.severity != "info"] == []
    desc, found = extract_asset_checked(asset)
    assert found == findings
    assert {ln.name for ln in desc.links} == {"base", "lid", "drawer", "handle"}
    assert all(ln.given_inertial is not None for ln in desc.links)
    assert desc.root_link == "base" and desc.category == "StorageFurniture"
    assert desc.link("lid").semantic_label == "lid"
    assert tree_hashes(asset) == before  # validation and extraction never write


def test_invalid_inertial_is_reported_with_eigenvalues_and_replaced(tmp_path):
    m = cb.valid_model()
    m.link("lid").inertial.ixx = "-0.02"
    asset = cb.write_asset(tmp_path / "a", m)
    desc, findings = extract_asset_checked(asset)
    (f,) = [f for f in findings if f.code == "INERTIA_NOT_POSITIVE_DEFINITE"]
    assert f.link == "lid" and f.severity == "warning" and f.action == "replace_with_estimate"
    assert f.values["eigenvalues"] == pytest.approx(np.linalg.eigvalsh(np.diag([-0.02, 0.02, 0.03])).tolist())
    assert f.values["inertia"] == [-0.02, 0.0, 0.0, 0.02, 0.0, 0.03]  # as given: never balanced
    assert "eigenvalues" in f.message and "-0.02" in f.message
    assert desc.link("lid").given_inertial is None  # the estimator replaces it
    assert desc.link("drawer").given_inertial is not None
    assert f.to_issue().fixed is True


def test_missing_meshes_are_listed_at_once(tmp_path):
    asset = cb.CASES_BY_NAME["path_three_missing"].build(tmp_path / "a")
    with pytest.raises(AssetError) as info:
        extract_asset(asset)
    err = info.value
    assert err.codes.count("MESH_NOT_FOUND") == 3
    for name in ("missing_a.obj", "missing_b.obj", "missing_c.obj"):
        assert name in str(err)
    assert {(f.link, f.values["role"]) for f in err.findings} == {("base", "visual"), ("lid", "visual"), ("lid", "collision")}


def test_every_error_is_collected_not_only_the_first(tmp_path):
    m = cb.valid_model()
    m.joint("lid_hinge").lower, m.joint("lid_hinge").upper = "1", "-1"
    m.joint("drawer_slide").axis = "0 0 0"
    m.link("handle").collisions[0].size = "nan 1 1"
    m.link("base").visuals[0].filename = "/etc/passwd"
    asset = cb.write_asset(tmp_path / "a", m)
    codes = {f.code for f in vi.validate_asset(asset) if f.severity == "error"}
    assert {"JOINT_LIMIT_REVERSED", "JOINT_AXIS_ZERO", "NUMBER_NAN", "MESH_PATH_ABSOLUTE"} <= codes
    f = next(f for f in vi.validate_asset(asset) if f.code == "JOINT_LIMIT_REVERSED")
    assert f.joint == "lid_hinge" and f.file == "mobility.urdf" and f.line is not None


# ----------------------------------------------------------------------------- policy


def test_policy_decides_what_is_an_error(tmp_path):
    equal = cb.CASES_BY_NAME["numbers_limit_equal"].build(tmp_path / "eq")
    assert not vi.has_errors(vi.validate_asset(equal))
    strict = vi.ValidationPolicy(overrides={"JOINT_LIMIT_EQUAL": "error"})
    assert vi.has_errors(vi.validate_asset(equal, strict))
    assert vi.has_errors(vi.validate_asset(equal, vi.ValidationPolicy(warnings_as_errors=True)))
    visual = cb.CASES_BY_NAME["mesh_visual_only_bad_index"].build(tmp_path / "vis")
    assert not vi.has_errors(vi.validate_asset(visual))
    assert vi.has_errors(vi.validate_asset(visual, vi.ValidationPolicy(visual_mesh_defects="error")))
    bad_inertia = cb.CASES_BY_NAME["inertial_negative_eigenvalue"].build(tmp_path / "in")
    refuse = vi.ValidationPolicy(overrides={"INERTIA_NOT_POSITIVE_DEFINITE": "error"})
    with pytest.raises(KeyError):
        refuse.severity("NO_SUCH_CODE")
    (f,) = [f for f in vi.validate_asset(bad_inertia, refuse) if f.code == "INERTIA_NOT_POSITIVE_DEFINITE"]
    assert f.severity == "error"


def test_mesh_defect_severity_depends_on_use(tmp_path):
    """A broken mesh used only as a visual is a warning; the same file as the
    collision (or as the mass source of a link without collision) is an error."""
    asset = cb.CASES_BY_NAME["mesh_nan_vertex"].build(tmp_path / "a")
    sev = {f.values["role"]: f.severity for f in vi.validate_asset(asset) if f.code == "MESH_NONFINITE_VERTEX"}
    assert sev == {"visual": "warning", "collision": "error"}
    m = cb.valid_model()
    m.link("lid").collisions.clear()
    cb.write_asset(tmp_path / "b", m)
    (tmp_path / "b" / "meshes" / "lid.obj").write_text(cb.CUBE_V.replace("v 1 1 1", "v nan 1 1") + cb.CUBE_F)
    (f,) = [f for f in vi.validate_asset(tmp_path / "b") if f.code == "MESH_NONFINITE_VERTEX"]
    assert f.severity == "error" and "used for mass" in f.message


@pytest.mark.parametrize("name", ["meta.json", "semantics.txt"])
def test_oversized_side_file_has_its_own_code(name, tmp_path):
    """A 1 GiB (sparse) ``meta.json`` or ``semantics.txt`` is a
    regular file, only too large: ``ASSET_FILE_TOO_LARGE`` naming the file,
    its size and the cap (was ``ASSET_FILE_NOT_REGULAR``); a FIFO keeps
    ``ASSET_FILE_NOT_REGULAR``."""
    asset = cb.build_valid(tmp_path / "a")
    with open(asset / name, "r+b") as fh:
        fh.truncate(1 << 30)
    found = [f for f in vi.validate_asset(asset) if f.code.startswith("ASSET_FILE_")]
    assert [(f.code, f.severity, f.file) for f in found] == [("ASSET_FILE_TOO_LARGE", "error", name)]
    cap = vi.DEFAULT_POLICY.max_extra_bytes
    assert str(1 << 30) in found[0].message and str(cap) in found[0].message
    assert found[0].values == {"size": 1 << 30, "cap": cap}
    os.unlink(asset / name)
    os.mkfifo(asset / name)
    assert {f.code for f in vi.validate_asset(asset) if f.code.startswith("ASSET_FILE_")} == {"ASSET_FILE_NOT_REGULAR"}


def test_asset_without_any_geometry_is_refused_naming_the_urdf(tmp_path):
    """Links but no ``<visual>``/``<collision>`` anywhere is
    ``ASSET_NO_GEOMETRY`` on the URDF (refine blamed the request with
    ``OVL_SCALE_INVALID``); one link without geometry beside others is fine."""
    model = cb.valid_model()
    for ln in model.links:
        ln.visuals, ln.collisions = [], []
    asset = cb.write_asset(tmp_path / "none", model)
    found = [f for f in vi.validate_asset(asset) if f.severity == "error"]
    assert [(f.code, f.file) for f in found] == [("ASSET_NO_GEOMETRY", "mobility.urdf")]
    assert "'lid'" in found[0].message and "4 links" in found[0].message
    with pytest.raises(AssetError) as err:
        extract_asset_checked(asset)
    assert err.value.codes == ["ASSET_NO_GEOMETRY"]
    model = cb.valid_model()
    model.link("lid").visuals, model.link("lid").collisions = [], []
    assert not vi.has_errors(vi.validate_asset(cb.write_asset(tmp_path / "one", model)))


# ----------------------------------------------------------------------------- CLI


def test_cli_validate_exit_codes_and_output(tmp_path, capsys):
    ok = cb.build_valid(tmp_path / "ok")
    assert cli.main(["validate", str(ok)]) == 0
    assert "OK (0 errors" in capsys.readouterr().out
    bad = cb.CASES_BY_NAME["numbers_limit_reversed"].build(tmp_path / "bad")
    assert cli.main(["validate", str(bad)]) == 1
    out = capsys.readouterr().out
    line = next(ln for ln in out.splitlines() if "JOINT_LIMIT_REVERSED" in ln)
    assert line.startswith("error") and re.search(r"mobility\.urdf:\d+", line) and "joint 'lid_hinge'" in line
    assert "REFUSED" in out
    eq = cb.CASES_BY_NAME["numbers_limit_equal"].build(tmp_path / "eq")
    assert cli.main(["validate", str(eq)]) == 0
    assert cli.main(["validate", "--strict", str(eq)]) == 1
    assert cli.main(["validate", "--error", "JOINT_LIMIT_EQUAL", str(eq)]) == 1
    assert cli.main(["validate", "--error", "NOT_A_CODE", str(eq)]) == 2
    capsys.readouterr()
    assert cli.main(["validate", "--json", str(bad)]) == 1
    rows = json.loads(capsys.readouterr().out)
    assert any(r["code"] == "JOINT_LIMIT_REVERSED" and r["joint"] == "lid_hinge" for r in rows)


def test_validate_counts_what_it_prints_and_shows_infos_with_verbose(tmp_path, capsys):
    """robosuite's door (three notes on how it was read): by default no info line and the verdict says 3 info, shown
    with --verbose; with --verbose every counted line is printed; the counts always agree with the lines."""
    from tests.tasks.ingest.host_layouts import robosuite_door

    pytest.importorskip("mujoco")
    xml = robosuite_door(tmp_path / "robosuite" / "robosuite" / "models" / "assets" / "objects" / "door.xml")
    for verbose in (False, True):
        assert cli.main(["validate", *(["--verbose"] if verbose else []), str(xml)]) == 0
        lines = capsys.readouterr().out.splitlines()
        verdict = lines[-1]
        infos = [ln for ln in lines[:-1] if ln.startswith("info ")]
        m = re.search(r"OK \((\d+) errors, (\d+) warnings, (\d+) info(, shown with --verbose)?\)$", verdict)
        assert m and m.group(1) == m.group(2) == "0" and int(m.group(3)) >= 3, verdict
        assert len(infos) == (int(m.group(3)) if verbose else 0) and bool(m.group(4)) is not verbose, lines


# ----------------------------------------------------------------------------- docs in sync


def test_docs_list_every_code():
    doc = (ROOT / "docs" / "guide" / "validation.md").read_text()
    missing = [c for c in vi.CODES if f"`{c}`" not in doc]
    assert missing == []


# ----------------------------------------------------------------------------- real data and demo assets


@needs_shared
@pytest.mark.parametrize("oid", ["8877", "148", "103275"])
def test_real_objects_validate_without_errors(oid):
    findings = vi.validate_asset(SHARED / oid)
    assert [f.describe() for f in findings if f.severity == "error"] == []
    if oid == "8877":  # the single-quad door and the commented-out link of semantics.txt
        codes = {f.code: f for f in findings}
        assert codes["LINK_ZERO_VOLUME"].link == "link_1" and codes["LINK_ZERO_VOLUME"].action == "mass_from_area"
        assert codes["SEMANTICS_UNKNOWN_LINK"].severity == "info"


@needs_shared
@pytest.mark.slow
def test_all_real_objects_extract():
    ids = sorted(p.name for p in SHARED.iterdir() if (p / "mobility.urdf").is_file())
    assert len(ids) == 21
    for oid in ids:
        before = tree_hashes(SHARED / oid)
        desc, findings = extract_asset_checked(SHARED / oid)
        assert not vi.has_errors(findings), oid
        assert desc.links and tree_hashes(SHARED / oid) == before


def test_demo_assets_validate_without_errors(demo_root):
    folders = sorted(p for p in demo_root.iterdir() if (p / "mobility.urdf").is_file())
    assert folders
    for folder in folders:
        findings = vi.validate_asset(folder)
        assert [f.describe() for f in findings if f.severity != "info"] == [], folder.name


# ----------------------------------------------------------------------------- other formats, textures


def test_a_line_that_begins_no_obj_record_is_named_by_number(tmp_path):
    """The first line whose first non-blank byte begins no OBJ record is named with its number and text, the
    file's first line as any other (CR line ends and blank or comment lines are records' company, not defects)."""
    for text, want in ((cb.CUBE_V + "f 1 2 3\r\n\n# note\n \t-1 2 3\n7 8\n", "line 12: not an OBJ record: b'-1 2 3'"),
                       ("0.5 0 0\n" + cb.CUBE_V + "f 1 2 3\n", "line 1: not an OBJ record: b'0.5 0 0'")):
        (tmp_path / "m.obj").write_text(text, newline="")
        assert vi.scan_mesh_file(tmp_path / "m.obj").defects.get("MESH_MALFORMED") == want


def test_scan_other_formats(tmp_path):
    import trimesh

    box = trimesh.creation.box((1, 2, 3))
    ply = tmp_path / "box.ply"
    ply.write_bytes(trimesh.exchange.ply.export_ply(box))
    scan = vi.scan_mesh_file(ply)
    assert scan.defects == {} and scan.n_faces == 12 and scan.area == pytest.approx(22.0)
    ascii_stl = tmp_path / "box.stl"
    ascii_stl.write_text(trimesh.exchange.stl.export_stl_ascii(box))
    assert vi.scan_mesh_file(ascii_stl).defects == {}
    dae = tmp_path / "evil.dae"
    dae.write_bytes(b'<!DOCTYPE c [<!ENTITY x SYSTEM "file:///etc/passwd">]><COLLADA>&x;</COLLADA>')
    assert "XML_EXTERNAL_REFERENCE_FORBIDDEN" in vi.scan_mesh_file(dae).defects["MESH_MALFORMED"]
    obj = tmp_path / "quads.obj"  # polygons, comments, negative indices: the general reader
    obj.write_text(cb.CUBE_V + "# quads\nf 1 3 4 2\nf 5 6 8 7\nf 1 2 6 5\nf -6 -2 -1 -5\nf 1 5 7 3\nf 2 4 8 6\n")
    scan = vi.scan_mesh_file(obj)
    assert scan.defects == {} and scan.n_faces == 12 and scan.area == pytest.approx(6.0)
    big = tmp_path / "big.obj"
    big.write_text(cb.CUBE_V + cb.CUBE_F * 10)
    assert "MESH_TOO_MANY_FACES" in vi.scan_mesh_file(big, max_faces=100).defects


def test_valid_texture_is_accepted(tmp_path):
    m = cb.valid_model()
    text = cb.render_urdf(m).replace(
        "</visual>", '<material name="skin"><texture filename="images/tex.png" /></material></visual>', 1
    )
    asset = cb.write_asset(tmp_path / "a", urdf_text=text)
    assert [f.describe() for f in vi.validate_asset(asset) if f.severity != "info"] == []
