"""The validator's modules: encoding, special files, paths as written, OBJ
through the shared reader, the face and link caps, joint travel."""

from __future__ import annotations

import os
import math

import numpy as np
import pytest

from asset2sim import mesh_io
from asset2sim.frames import pose_matrix
from asset2sim.tasks.ingest import findings, mesh_checks, mesh_paths, tree_checks, urdf_checks
from asset2sim.tasks.ingest import validate_input as vi
from asset2sim.urdf import UrdfGeometry
from tests import corpus_builder as cb


# ----------------------------------------------------------------------------- encoding


@pytest.mark.parametrize(
    "data,ok",
    [
        (b'<robot name="r"/>', True),
        (b'\xef\xbb\xbf<robot name="r\xc3\xa9"/>', True),  # UTF-8 BOM: PyBullet reads it
        (b'<?xml version="1.0" encoding="ISO-8859-1"?><robot name="r"/>', True),  # ASCII only: all agree
        ('<robot name="r"/>'.encode("utf-16"), False),
        ('<robot name="r"/>'.encode("utf-16-le"), False),  # no BOM: NUL bytes
        (b'<robot name="r\xe9"/>', False),  # not UTF-8
        (b'<?xml version="1.0" encoding="ISO-8859-1"?><robot name="r\xc3\xa9"/>', False),
    ],
)
def test_encoding_problem(data, ok):
    assert (urdf_checks.encoding_problem(data) is None) == ok


# ----------------------------------------------------------------------------- special files and paths


def test_file_kind_names_fifos_and_devices_only(tmp_path):
    os.mkfifo(tmp_path / "pipe.png")
    os.symlink("/dev/zero", tmp_path / "zero.png")
    (tmp_path / "plain.png").write_bytes(cb.PNG_1PX)
    (tmp_path / "dir").mkdir()
    assert mesh_paths.file_kind("pipe.png", tmp_path) == "FIFO"
    assert mesh_paths.file_kind("zero.png", tmp_path) == "character device"
    assert mesh_paths.file_kind(str(tmp_path / "pipe.png"), "/elsewhere") == "FIFO"  # absolute names too
    for name in ("plain.png", "dir", "missing.png", "", "http://x/y.png"):
        assert mesh_paths.file_kind(name, tmp_path) is None


def test_reference_must_open_as_written(tmp_path):
    asset = cb.build_valid(tmp_path / "a")
    ok = vi.resolve_mesh_reference(asset, "images/../meshes/lid.obj")
    assert ok.code is None and ok.path == (asset / "meshes" / "lid.obj").resolve()
    bad = vi.resolve_mesh_reference(asset, "nodir/../meshes/lid.obj")
    assert bad.code == "MESH_NOT_FOUND" and "as written" in bad.message


# ----------------------------------------------------------------------------- OBJ through mesh_io


def test_obj_scan_uses_the_shared_reader(tmp_path):
    """Validation reads OBJ files exactly as the later stages do."""
    p = tmp_path / "m.obj"
    p.write_text(cb.CUBE_V + cb.CUBE_F)
    scan = vi.scan_mesh_file(p)
    mesh = mesh_io.read_obj(p.read_bytes())
    v, f = mesh.vertices, mesh.faces
    assert scan.n_faces == len(f) == 12 and scan.n_vertices == len(v) == 8
    assert scan.defects == {}
    assert np.allclose(scan.bounds, [[0, 0, 0], [1, 1, 1]])


def test_quad_and_two_gon_do_not_pair_up(tmp_path):
    """A quad followed by a 2-vertex face has 3 indices per face on average:
    the shared reader's vectorized path must not read them as two triangles."""
    data = b"v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 1\nf 1 2 3\nf 1 2 3 4\nf 1 2\n"
    mesh = mesh_io.read_obj(data)
    v, f, notes = mesh.vertices, mesh.faces, mesh.notes
    assert f.tolist() == [[0, 1, 2], [0, 1, 2], [0, 2, 3]] and notes
    p = tmp_path / "m.obj"
    p.write_bytes(data)
    assert "MESH_BAD_INDEX" in vi.scan_mesh_file(p).defects


def test_index_zero_is_a_bad_face_even_before_later_vertices(tmp_path):
    p = tmp_path / "m.obj"
    p.write_text("v 0 0 0\nv 1 0 0\nf 0 1 2\nv 0 1 0\nv 0 0 1\n" + "f 1 2 3\nf 1 2 4\nf 1 3 4\nf 2 3 4\n")
    scan = vi.scan_mesh_file(p)
    assert "MESH_BAD_INDEX" in scan.defects and scan.n_faces == 4


def test_bare_mtllib_line_does_not_take_the_next_line():
    assert mesh_io.mtl_libraries(b"mtllib\nv 0 0 0\nmtllib a.mtl\r\n") == ["a.mtl"]
    assert mesh_io.mtl_texture_maps(b"map_Kd\nnewmtl x\nmap_Kd -s 2 t.png\n") == ["t.png"]


def test_too_many_faces_counts_in_the_total(tmp_path):
    p = tmp_path / "m.obj"
    p.write_text(cb.CUBE_V + cb.CUBE_F * 10)
    scan = vi.scan_mesh_file(p, max_faces=50)
    assert "MESH_TOO_MANY_FACES" in scan.defects and scan.n_faces == 120


# ----------------------------------------------------------------------------- caps and travel


def test_defaults():
    pol = vi.DEFAULT_POLICY
    assert pol.max_total_faces == pol.max_mesh_faces == findings.MAX_TOTAL_FACES == 1_000_000
    assert pol.max_links == 128
    assert pol.max_revolute_limit == pytest.approx(4 * math.pi)
    assert pol.simulator_mesh_extensions == {".obj", ".stl", ".dae"}


def test_link_cap_is_exact(tmp_path):
    n_extra = 128 - 4  # the corpus asset has 4 links
    assert not vi.has_errors(vi.validate_asset(cb._model_case(cb._chain(n_extra))(tmp_path / "ok")))
    codes = {f.code for f in vi.validate_asset(cb._model_case(cb._chain(n_extra + 1))(tmp_path / "over"))}
    assert "URDF_TOO_MANY_LINKS" in codes


def test_prismatic_travel_against_object_size(tmp_path):
    """The corpus asset spans about 1.6 m at the zero configuration: 1.5 m of
    travel is accepted, 2 m is not; without mesh contents no claim is made."""
    ok = cb._model_case(cb._attr("joint", "drawer_slide", upper="1.5"))(tmp_path / "ok")
    assert not vi.has_errors(vi.validate_asset(ok))
    over = cb._model_case(cb._attr("joint", "drawer_slide", upper="2"))(tmp_path / "over")
    hits = [f for f in vi.validate_asset(over) if f.code == "JOINT_LIMIT_IMPLAUSIBLE"]
    assert hits and hits[0].joint == "drawer_slide" and 1.5 < hits[0].values["object_size"] < 2
    paths_only = vi.ValidationPolicy(check_mesh_contents=False)
    assert not vi.has_errors(vi.validate_asset(over, paths_only))


def test_geometry_corners_of_primitives():
    g = UrdfGeometry(kind="cylinder", radius=0.1, length=1.0, origin=pose_matrix((1.0, 0.0, 0.0)))
    c = mesh_checks.geometry_corners(g)
    assert c.shape == (8, 3)
    assert np.allclose(c.min(axis=0), [0.9, -0.1, -0.5]) and np.allclose(c.max(axis=0), [1.1, 0.1, 0.5])
    assert mesh_checks.geometry_corners(UrdfGeometry(kind="mesh")) is None
    bounds = np.array([[0.0, 0.0, 0.0], [1.0, 2.0, 3.0]])
    m = mesh_checks.geometry_corners(UrdfGeometry(kind="mesh", mesh_scale=np.array([2.0])), bounds)
    assert np.allclose(m.max(axis=0), [2.0, 4.0, 6.0])
    assert mesh_checks.geometry_corners(UrdfGeometry(kind="box", size=np.ones(3), complete=False)) is None


def test_public_names_unchanged():
    for name in vi.__all__:
        assert hasattr(vi, name), name
    assert vi.check_inertia is tree_checks.check_inertia
    assert vi.Finding is findings.Finding


def test_a_copied_mesh_is_scanned_once_and_each_caller_gets_its_own_scan(tmp_path, monkeypatch):
    """An output's visual meshes are byte copies of its input's and both are validated: a second file of the same
    bytes takes the first one's scan without parsing again; a caller changing its scan changes no later caller's;
    other bytes are parsed."""
    from asset2sim.tasks.ingest import mesh_scan

    parsed = []
    real = mesh_scan._scan_obj
    monkeypatch.setattr(mesh_scan, "_scan_obj", lambda data, max_faces: parsed.append(data) or real(data, max_faces))
    text = cb.CUBE_V + cb.CUBE_F + f"# {tmp_path.name}\n"  # bytes no other test scanned
    a, b = tmp_path / "a.obj", tmp_path / "copy" / "b.obj"
    b.parent.mkdir()
    a.write_text(text)
    b.write_text(text)
    first = vi.scan_mesh_file(a)
    first.defects["MESH_MALFORMED"] = "changed by its caller"
    first.bounds[1] = 99.0
    second = vi.scan_mesh_file(b)
    assert len(parsed) == 1
    assert second.defects == {} and second.n_faces == 12 and np.allclose(second.bounds, [[0, 0, 0], [1, 1, 1]])
    assert "MESH_TOO_MANY_FACES" in vi.scan_mesh_file(b, max_faces=5).defects and len(parsed) == 2  # other caps: parsed
    b.write_text(text + "f 1 2 99\n")
    assert "MESH_BAD_INDEX" in vi.scan_mesh_file(b).defects and len(parsed) == 3
