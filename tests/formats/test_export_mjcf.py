"""MJCF export: compiles, same masses/COMs/inertias, keyframe = initial_state.json."""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path

import numpy as np
import pytest

from asset2sim.engines.loading import read_urdf
from asset2sim.refined_asset import read_initial_state
from tests.conftest import SHARED, needs_shared
from tests.contract_asset import write_contract_asset

pytestmark = pytest.mark.mujoco
mujoco = pytest.importorskip("mujoco")

from asset2sim.formats.mjcf.export import ExportError, check_mjcf, export_mjcf, solver_aids

from asset2sim.refined_asset import springs_from_overlay

ROOT = Path(__file__).resolve().parents[2]


def _real_outputs() -> list[Path]:
    """Output folders of the pipeline present in the checkout (none on a fresh clone)."""
    found = []
    for base in (ROOT / "data" / "refined", ROOT / "out"):
        if base.is_dir():
            for urdf in sorted(base.glob("**/mobility.urdf")):
                d = urdf.parent
                if (d / "initial_state.json").is_file() and (d / "overlay.json").is_file():
                    found.append(d)
    return found


def _tilt_lid_inertial(urdf: Path) -> None:
    text = urdf.read_text()
    head, sep, tail = text.partition('<link name="lid">')
    tail = tail.replace('rpy="0 0 0"/>', 'rpy="0.3 -0.2 0.5"/>', 1).replace('ixy="0.0"', 'ixy="0.0001"', 1)
    urdf.write_text(head + sep + tail)


def _load(path: Path):
    return mujoco.MjModel.from_xml_path(str(path))


def test_export_compiles_with_the_urdf_masses_and_keyframe(tmp_path):
    from tests.helpers import tree_hashes

    a = write_contract_asset(tmp_path, lid_angle=0.35, post_height=0.015, lid_stiffness=0.8, lid_spring_reference=0.2)
    _tilt_lid_inertial(a.urdf)
    before = tree_hashes(tmp_path)
    path = export_mjcf(tmp_path)
    after = tree_hashes(tmp_path)
    assert {k: v for k, v in after.items() if not k.startswith("mjcf/")} == before  # only mjcf/ is written
    assert path == tmp_path / "mjcf" / "mobility.xml"
    m = _load(path)
    urdf = read_urdf(a.urdf)
    assert math.isclose(m.body_mass.sum(), urdf.total_mass(), rel_tol=1e-6)
    # the file's per-body inertia, read back through MuJoCo's loader (no fusing: fusestatic="false")
    for name, link in urdf.links.items():
        bid = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, name)
        assert m.body_mass[bid] == pytest.approx(link.inertial.mass, rel=1e-12)
        q = m.body_iquat[bid]
        r = np.zeros(9)
        mujoco.mju_quat2Mat(r, q)
        r = r.reshape(3, 3)
        assert r @ np.diag(m.body_inertia[bid]) @ r.T == pytest.approx(link.inertial.inertia_in_link_axes(), abs=1e-12)
        assert m.body_ipos[bid] == pytest.approx(link.inertial.com(), abs=1e-12)
    key = m.key_qpos[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_KEY, "initial")]
    state = json.loads((tmp_path / "initial_state.json").read_text())["initial_joint_positions"]
    for joint, value in state.items():
        jid = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, joint)
        assert key[m.jnt_qposadr[jid]] == value  # exact: written at full precision
    hinge = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, "lid_hinge")
    assert m.jnt_stiffness[hinge] == 0.8 and m.qpos_spring[m.jnt_qposadr[hinge]] == 0.2
    assert m.dof_damping[m.jnt_dofadr[hinge]] == 0.02 and m.dof_frictionloss[m.jnt_dofadr[hinge]] == 0.02
    assert m.jnt_range[hinge] == pytest.approx([0.0, 2.0])
    # meshes are referenced relatively: the folder can move
    text = path.read_text()
    assert str(tmp_path) not in text and "meshdir" not in text


def test_every_file_the_export_names_lies_where_its_own_folder_says(tmp_path):
    """The MJCF export names each file relative to its own folder (no meshdir to read): a host that joins file names
    to the MJCF's folder, as robosuite's MujocoXML does, finds every mesh; MuJoCo loads it from another working
    folder."""
    import os
    import re

    a = write_contract_asset(tmp_path / "asset", lid_angle=0.6)
    path = export_mjcf(a.root)
    files = re.findall(r'<(?:mesh|texture|hfield|skin)\b[^>]*?\bfile="([^"]+)"', path.read_text())
    assert files and all((path.parent / f).is_file() for f in files), files
    assert all(f.startswith("../") or f.startswith("meshes/") for f in files), files
    here = os.getcwd()
    try:
        os.chdir(tmp_path)
        assert mujoco.MjModel.from_xml_path(str(path.relative_to(tmp_path))).nmesh == len(files)
    finally:
        os.chdir(here)


def test_export_is_portable_and_the_keyframe_rests(tmp_path):
    a = write_contract_asset(tmp_path / "asset", lid_angle=0.6, lid_friction=0.5)
    export_mjcf(a.root)
    moved = tmp_path / "moved"
    a.root.rename(moved)
    m = _load(moved / "mjcf" / "mobility.xml")
    d = mujoco.MjData(m)
    mujoco.mj_resetDataKeyframe(m, d, 0)
    p0 = d.qpos[:3].copy()
    for _ in range(720):
        mujoco.mj_step(m, d)
    assert np.abs(d.qpos[:3] - p0).max() < 1e-3
    hinge = m.jnt_qposadr[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, "lid_hinge")]
    assert d.qpos[hinge] == pytest.approx(0.6, abs=1e-3)


def test_visuals_are_non_colliding_and_coloured(tmp_path):
    a = write_contract_asset(tmp_path)
    (tmp_path / "textured_objs" / "lid.mtl").write_text("newmtl red\nKd 0.8 0.1 0.1\nd 1\n")
    obj = tmp_path / "textured_objs" / "lid.obj"
    obj.write_text("mtllib lid.mtl\nusemtl red\n" + obj.read_text())
    m = _load(export_mjcf(tmp_path))
    g = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, "lid__v0")
    assert m.geom_contype[g] == 0 and m.geom_conaffinity[g] == 0 and m.geom_group[g] == 2
    assert m.geom_rgba[g] == pytest.approx([0.8, 0.1, 0.1, 1.0])
    c = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, "lid__c0_g0")
    assert m.geom_contype[c] == 1 and m.geom_group[c] == 3
    m2 = _load(export_mjcf(tmp_path, visuals=False))
    assert mujoco.mj_name2id(m2, mujoco.mjtObj.mjOBJ_GEOM, "lid__v0") == -1


def _product_folder(path: Path) -> None:
    """Make ``path`` an output folder of the product: a completion marker
    listing the files it holds now."""
    from asset2sim.tasks.publish.contract import write_completion_marker

    write_completion_marker(path, "input", "config")


def test_reexport_replaces_stale_pieces(tmp_path):
    from asset2sim.output_folder import adopting

    write_contract_asset(tmp_path)
    _product_folder(tmp_path)
    with adopting(tmp_path):  # as `asset2sim export` does: the pieces become the folder's own
        export_mjcf(tmp_path)
    assert len(list((tmp_path / "mjcf" / "meshes").glob("body__c0_g*.obj"))) == 5
    (tmp_path / "textured_objs" / "body.obj").write_text((tmp_path / "textured_objs" / "lid.obj").read_text())
    keep = tmp_path / "mjcf" / "meshes" / "notes.txt"
    keep.write_text("not ours")
    users = tmp_path / "mjcf" / "meshes" / "mine__c7_g7.obj"  # the naming pattern, but not written by the product
    users.write_text("v 0 0 0\n")
    with adopting(tmp_path):
        export_mjcf(tmp_path)
    assert not list((tmp_path / "mjcf" / "meshes").glob("body__c0_g*.obj"))
    assert keep.exists() and users.read_text() == "v 0 0 0\n"


def test_export_never_removes_pieces_it_did_not_write(tmp_path):
    """In a folder with no ownership record or completion marker, nothing
    named like a piece is the product's: a re-export removes none of them."""
    write_contract_asset(tmp_path)
    export_mjcf(tmp_path)
    pieces = sorted((tmp_path / "mjcf" / "meshes").glob("body__c0_g*.obj"))
    assert len(pieces) == 5
    before = {p.name: p.read_bytes() for p in pieces}
    (tmp_path / "textured_objs" / "body.obj").write_text((tmp_path / "textured_objs" / "lid.obj").read_text())
    export_mjcf(tmp_path)
    assert {p.name: p.read_bytes() for p in (tmp_path / "mjcf" / "meshes").glob("body__c0_g*.obj")} == before


def test_the_massless_root_stays_massless(tmp_path):
    a = write_contract_asset(tmp_path, base_inertial=False)
    m = _load(export_mjcf(tmp_path))
    assert m.body_mass[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, "base")] == 0.0
    assert math.isclose(m.body_mass.sum(), sum(a.masses.values()), rel_tol=1e-12)


def test_check_catches_a_wrong_export(tmp_path):
    a = write_contract_asset(tmp_path, lid_angle=0.3)
    path = export_mjcf(tmp_path)
    good = path.read_text()
    path.write_text(good.replace('mass="0.2"', 'mass="0.2000005"'))
    with pytest.raises(ExportError, match="total mass|body 'lid'"):
        check_mjcf(path, a.urdf, a.initial_state)
    path.write_text(good)
    with pytest.raises(ExportError, match="keyframe lid_hinge"):
        check_mjcf(path, a.urdf, {**a.initial_state, "lid_hinge": 0.31})
    check_mjcf(path, a.urdf, a.initial_state)


def test_a_file_that_fails_its_check_never_replaces_the_export(tmp_path, monkeypatch):
    """The file is checked as written, before it lands: a conversion MuJoCo reads with another mass fails
    naming ``mjcf/mobility.xml``, the earlier export stays byte for byte, and no temporary file is left."""
    from asset2sim.formats.mjcf import export as module

    write_contract_asset(tmp_path, lid_angle=0.3)
    path = export_mjcf(tmp_path)
    good = path.read_bytes()
    real = module.urdf_to_mjcf

    def heavier(*args, **kwargs):
        build = real(*args, **kwargs)
        assert kwargs.get("compile_visuals") is False  # the check is the one compile with the visual meshes
        return dataclasses.replace(build, xml=build.xml.replace('mass="0.2"', 'mass="0.25"'))

    monkeypatch.setattr(module, "urdf_to_mjcf", heavier)
    with pytest.raises(ExportError, match=r"mjcf/mobility\.xml: (total mass|body 'lid')"):
        export_mjcf(tmp_path)
    assert path.read_bytes() == good
    assert sorted(p.name for p in path.parent.iterdir() if p.is_file()) == ["mobility.xml"]


def test_springs_come_from_the_overlay(tmp_path):
    write_contract_asset(tmp_path, lid_angle=0.4, lid_stiffness=1.5, lid_spring_reference=None)
    springs = springs_from_overlay(tmp_path, read_initial_state(tmp_path))
    assert set(springs) == {"lid_hinge"}
    assert springs["lid_hinge"].stiffness == 1.5 and springs["lid_hinge"].reference == 0.4  # no reference: the initial state
    (tmp_path / "overlay.json").write_text("{}")
    with pytest.raises(ValueError, match="not a valid overlay"):
        springs_from_overlay(tmp_path)


def test_missing_folder_is_a_clear_error(tmp_path):
    with pytest.raises(FileNotFoundError, match="mobility.urdf"):
        export_mjcf(tmp_path)


def test_cli_exports_and_reports(tmp_path, capsys):
    from asset2sim.cli import main

    write_contract_asset(tmp_path, lid_angle=0.2)
    assert main(["export", str(tmp_path), "--format", "mjcf"]) == 0
    out = capsys.readouterr().out
    assert "mjcf/mobility.xml" in out and "keyframe" in out and "lid_hinge=0.2" in out
    assert main(["export", str(tmp_path / "nowhere")]) == 2


@pytest.mark.slow
@pytest.mark.parametrize("out_dir", _real_outputs(), ids=lambda p: p.name)
def test_real_outputs_export(out_dir, tmp_path):
    """Every output folder of the pipeline in the checkout exports an MJCF that
    compiles, with the URDF's total mass and the initial state as keyframe
    (``check_mjcf`` raises otherwise). Exported into a copy: the folder is
    not ours to write."""
    import shutil

    copy = tmp_path / out_dir.name
    shutil.copytree(out_dir, copy, ignore=shutil.ignore_patterns("mjcf", "*.html", "*.png"))
    path = export_mjcf(copy)
    check = check_mjcf(path, copy / "mobility.urdf", read_initial_state(copy))
    assert math.isclose(check.total_mass, check.urdf_mass, rel_tol=1e-6)
    assert check.keyframe == pytest.approx({k: check.initial_state.get(k, 0.0) for k in check.keyframe}, abs=1e-12)


@needs_shared
def test_a_held_root_session_of_a_real_object_carries_the_aids_of_its_exported_file(refine_once, tmp_path):
    """Trash can 102181 stands free; its 4e-6 kg*m^2 pedal gets armature in the exported MJCF (judged with the free
    root: the model's mean inertia is the whole can's). The press's session (root held by the other hand, no ground)
    and the breakaway's (root held, gravity off) open the folder as every check does
    (``RefinedAsset.session_options``) and carry the file's joint aids, the pedal's armature included."""
    from asset2sim.engines.registry import open_session
    from asset2sim.refined_asset import RefinedAsset

    res = refine_once(SHARED / "102181", "A very small personal trash can with its lid slightly open. The hinge has low damping "
                      "and holds its position.", extras=False)
    folder = res.copy_to(tmp_path / "can")
    listed = sorted((a.kind, a.element, a.written) for a in solver_aids(export_mjcf(folder, visuals=False))
                    if a.kind != "ground_contact_impedance")
    assert "armature" in {k for k, _, _ in listed}
    asset = RefinedAsset(folder)
    assert not asset.root.fixed
    for gravity in (True, False):
        opts = dataclasses.replace(asset.session_options(), fixed_base=True, ground=False, gravity=gravity)
        with open_session("mujoco", asset.urdf_path, opts) as s:
            assert sorted((a.kind, a.element, a.written) for a in s.build.aids) == listed


def test_report_json_lists_the_solver_aids_the_mjcf_carries_and_reading_it_back_names_them(refine_once, tmp_path):
    """A refine's MJCF export names each solver aid on its joint or geom with its criterion; ``report.json`` lists
    the same aids, read back from the file, and the MJCF reader notes each one as not carried. The refine's export
    reads the hand's press from the verdict it holds: the same file as exporting the finished folder again, the lid's
    limit aid included (a 20 N press at its far edge rests past MuJoCo's default limit)."""
    from asset2sim.formats import read_asset_file

    res = refine_once("box_lid", "a small box with its lid closed", extras=True, media=False)
    xml = res.out / "mjcf" / "mobility.xml"
    aids = solver_aids(xml)
    assert aids and res.report.solver_aids == aids
    joints = {j.name for j in read_urdf(res.out / "mobility.urdf").movable_joints}
    for a in aids:
        assert a.criterion and a.measure > 0 and a.written
        assert a.element in joints or a.kind in ("ground_contact_impedance", "collision_prism")
    notes = read_asset_file(xml, "mjcf").notes
    assert sum(n.startswith("solver aid ") for n in notes) == len(aids)
    assert any(a.kind == "limit_solver" for a in aids)
    again = export_mjcf(res.copy_to(tmp_path / "again"))
    assert again.read_bytes() == xml.read_bytes()
