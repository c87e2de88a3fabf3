"""USD export: UsdPhysics bodies, joints, drives and states read back equal
the output folder's files (authored equals intended), in pxr and in Newton."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from tests.contract_asset import write_contract_asset
from asset2sim.engines.loading import read_urdf
from asset2sim.refined_asset import read_initial_state
from asset2sim.frames import quat_wxyz_matrix
from asset2sim.schemas.overlay import Inertia
from asset2sim.formats.mjcf.export import export_mjcf
from tests.conftest import SHARED

pxr = pytest.importorskip("pxr")

from pxr import Usd, UsdGeom, UsdPhysics  # noqa: E402

from asset2sim.formats.usd.check import UsdExportError, check_usd, read_usd  # noqa: E402
from asset2sim.formats.usd.export import DEG, export_usd, principal_axes  # noqa: E402


def _tilt_lid_inertial(urdf: Path) -> None:
    """Rotate the lid's inertial frame and add a product of inertia, so the
    principal axes are not the link axes."""
    text = urdf.read_text()
    head, sep, tail = text.partition('<link name="lid">')
    tail = tail.replace('rpy="0 0 0"/>', 'rpy="0.3 -0.2 0.5"/>', 1).replace('ixy="0.0"', 'ixy="0.0001"', 1)
    urdf.write_text(head + sep + tail)


@pytest.fixture
def contract(tmp_path) -> Path:
    out = tmp_path / "out"
    write_contract_asset(out, lid_angle=0.4, post_height=0.01, lid_stiffness=0.3, lid_spring_reference=0.2)
    _tilt_lid_inertial(out / "mobility.urdf")
    # the overlay says what the URDF now carries
    lid = read_urdf(out / "mobility.urdf").links["lid"].inertial
    overlay = json.loads((out / "overlay.json").read_text())
    overlay["links"]["lid"]["com"] = lid.com().tolist()
    overlay["links"]["lid"]["inertia"] = Inertia.from_matrix(lid.inertia_in_link_axes()).model_dump()
    (out / "overlay.json").write_text(json.dumps(overlay))
    return out


def test_check_compares_with_the_overlay(contract):
    """A URDF that does not carry the overlay's numbers is caught by name."""
    build = export_usd(contract)
    overlay = json.loads((contract / "overlay.json").read_text())
    overlay["links"]["lid"]["mass"] *= 2
    (contract / "overlay.json").write_text(json.dumps(overlay))
    with pytest.raises(UsdExportError, match="overlay link 'lid' mass"):
        check_usd(build.path, contract)


def test_principal_axes_rebuild_the_tensor():
    t = np.array([[3.0, 0.4, -0.2], [0.4, 2.0, 0.1], [-0.2, 0.1, 1.0]]) * 1e-3
    w, r = principal_axes(t)
    assert np.linalg.det(r) == pytest.approx(1.0)
    assert np.allclose(r @ np.diag(w) @ r.T, t, atol=1e-15)


def test_export_reads_back_equal_to_the_folder(contract):
    build = export_usd(contract)
    assert build.path == contract / "usd" / "mobility.usd"
    urdf = read_urdf(contract / "mobility.urdf")
    usd = read_usd(build.path)
    lid = urdf.links["lid"].inertial
    got = usd.model.links["lid"].inertial
    assert got.mass == pytest.approx(lid.mass, rel=1e-6)
    assert np.allclose(got.com(), lid.com(), rtol=1e-6, atol=1e-9)
    want = lid.inertia_in_link_axes()
    assert abs(want[0, 1]) > 1e-5  # the tilt made a full tensor
    assert np.allclose(got.inertia_in_link_axes(), want, rtol=0, atol=1e-6 * np.abs(want).max())
    hinge, spring = usd.model.joint("lid_hinge"), usd.springs["lid_hinge"]
    j = urdf.joint("lid_hinge")
    assert hinge.type == "revolute"
    assert (hinge.lower, hinge.upper) == pytest.approx((j.lower, j.upper), rel=1e-6)
    assert hinge.damping == pytest.approx(j.damping, rel=1e-6)
    assert hinge.friction == pytest.approx(j.friction, rel=1e-6)
    assert spring.stiffness == pytest.approx(0.3, rel=1e-6)
    assert spring.reference == pytest.approx(0.2, rel=1e-6)
    assert usd.initial_state["lid_hinge"] == pytest.approx(0.4, rel=1e-6)
    slide = usd.model.joint("post_slide")
    assert slide.type == "prismatic" and usd.initial_state["post_slide"] == pytest.approx(0.01, rel=1e-6)
    assert not usd.root_fixed
    assert check_usd(build.path, contract).max_rel_error < 1e-6


def test_units_are_the_ones_usd_prescribes(contract):
    """Revolute limits, drive gains and states in degrees (UsdPhysics; the
    conversion Isaac Sim's URDF importer gets wrong, IsaacSim #842);
    prismatic ones in metres."""
    build = export_usd(contract)
    stage = Usd.Stage.Open(str(build.path))
    assert UsdGeom.GetStageMetersPerUnit(stage) == 1.0 and UsdGeom.GetStageUpAxis(stage) == "Z"
    hinge = stage.GetPrimAtPath(build.joints["lid_hinge"])
    rj = UsdPhysics.RevoluteJoint(hinge)
    assert rj.GetUpperLimitAttr().Get() == pytest.approx(2.0 * DEG, rel=1e-6)
    drive = UsdPhysics.DriveAPI.Get(hinge, "angular")
    assert drive.GetStiffnessAttr().Get() == pytest.approx(0.3 / DEG, rel=1e-6)
    assert drive.GetDampingAttr().Get() == pytest.approx(0.02 / DEG, rel=1e-6)
    assert drive.GetTargetPositionAttr().Get() == pytest.approx(0.2 * DEG, rel=1e-6)
    assert hinge.GetAttribute("state:angular:physics:position").Get() == pytest.approx(0.4 * DEG, rel=1e-6)
    slide = stage.GetPrimAtPath(build.joints["post_slide"])
    assert UsdPhysics.PrismaticJoint(slide).GetUpperLimitAttr().Get() == pytest.approx(0.05, rel=1e-6)
    assert UsdPhysics.DriveAPI.Get(slide, "linear").GetDampingAttr().Get() == pytest.approx(1.0, rel=1e-6)


def test_joint_frames_put_the_child_where_the_urdf_does(contract):
    """Joint frame 0 (in the parent) and frame 1 (in the child) coincide in
    the world at the authored link poses, and their X axis is the URDF axis."""
    build = export_usd(contract)
    stage = Usd.Stage.Open(str(build.path))
    cache = UsdGeom.XformCache()
    urdf = read_urdf(contract / "mobility.urdf")
    poses = urdf.link_poses(read_initial_state(contract))
    for name, path in build.links.items():
        m = np.array(cache.GetLocalToWorldTransform(stage.GetPrimAtPath(path))).T
        assert np.allclose(m, poses[name], atol=1e-9), name
    for jname in ("lid_hinge", "post_slide"):
        j = UsdPhysics.Joint(stage.GetPrimAtPath(build.joints[jname]))
        uj = urdf.joint(jname)
        p0 = poses[uj.parent][:3, :3] @ np.array(j.GetLocalPos0Attr().Get()) + poses[uj.parent][:3, 3]
        p1 = poses[uj.child][:3, :3] @ np.array(j.GetLocalPos1Attr().Get()) + poses[uj.child][:3, 3]
        if uj.type == "revolute":
            assert np.allclose(p0, p1, atol=1e-6)
        q1 = j.GetLocalRot1Attr().Get()
        r1 = np.array(quat_wxyz_matrix([q1.GetReal(), *q1.GetImaginary()]))
        assert np.allclose(r1[:, 0], uj.axis, atol=1e-6)


def test_collisions_are_closed_outward_convex_hulls(contract):
    build = export_usd(contract)
    stage = Usd.Stage.Open(str(build.path))
    n = 0
    for prim in stage.Traverse():
        if not prim.HasAPI(UsdPhysics.CollisionAPI):
            continue
        assert UsdPhysics.MeshCollisionAPI(prim).GetApproximationAttr().Get() == "convexHull"
        mesh = UsdGeom.Mesh(prim)
        v = np.array(mesh.GetPointsAttr().Get(), float)
        f = np.array(mesh.GetFaceVertexIndicesAttr().Get()).reshape(-1, 3)
        a, b, c = v[f[:, 0]], v[f[:, 1]], v[f[:, 2]]
        vol = np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0
        assert vol > 0, prim.GetPath()  # outward winding: positive signed volume
        n += 1
    assert n >= 7  # five box walls, lid, post


def test_fixed_root_gets_a_world_joint(contract):
    state = json.loads((contract / "initial_state.json").read_text())
    state["root"] = {"fixed": True, "mounting": "wall-mounted", "source": "test"}
    (contract / "initial_state.json").write_text(json.dumps(state))
    build = export_usd(contract)
    assert build.fixed_root and read_usd(build.path).root_fixed


def test_check_catches_a_changed_value(contract):
    build = export_usd(contract)
    stage = Usd.Stage.Open(str(build.path))
    prim = stage.GetPrimAtPath(build.joints["lid_hinge"])
    UsdPhysics.DriveAPI.Get(prim, "angular").GetDampingAttr().Set(0.02)  # per rad, not per degree: the Isaac bug
    stage.GetRootLayer().Save()
    with pytest.raises(UsdExportError, match="lid_hinge.*damping"):
        check_usd(build.path, contract)


def test_missing_folder_is_a_clear_error(tmp_path):
    with pytest.raises(FileNotFoundError, match="mobility.urdf"):
        export_usd(tmp_path)


def test_cli_exports_usd(contract, capsys):
    from asset2sim.cli import main

    assert main(["export", str(contract), "--format", "usd"]) == 0
    out = capsys.readouterr().out
    assert "usd/mobility.usd" in out and "read back" in out


# ------------------------------------------------------------------- Newton
def _newton_model(path: Path):
    newton = pytest.importorskip("newton")
    pytest.importorskip("newton_usd_schemas")
    builder = newton.ModelBuilder()
    builder.add_usd(str(path))
    return newton, builder


def test_newton_holds_what_was_authored(contract):
    """Newton's USD importer (newton 1.8) reads mass, COM, limits, Coulomb
    friction, drive gains (converted back per radian) and initial positions
    as the folder holds them."""
    build = export_usd(contract)
    _, b = _newton_model(build.path)
    urdf = read_urdf(contract / "mobility.urdf")
    labels = list(getattr(b, "body_label", None) or b.body_key)
    for name, path in build.links.items():
        i = labels.index(path)
        assert b.body_mass[i] == pytest.approx(urdf.links[name].inertial.mass, rel=1e-6), name
        assert np.allclose(np.array(b.body_com[i]), urdf.links[name].inertial.com(), atol=1e-7), name
    jl = list(getattr(b, "joint_label", None) or b.joint_key)
    for jname, stiff in (("lid_hinge", 0.3), ("post_slide", 0.0)):
        ji = jl.index(build.joints[jname])
        d = b.joint_qd_start[ji]
        q = b.joint_q_start[ji]
        uj = urdf.joint(jname)
        assert b.joint_limit_lower[d] == pytest.approx(uj.lower, abs=1e-6)
        assert b.joint_limit_upper[d] == pytest.approx(uj.upper, rel=1e-6)
        assert b.joint_friction[d] == pytest.approx(uj.friction, rel=1e-6)
        assert b.joint_target_kd[d] == pytest.approx(uj.damping, rel=1e-6)
        assert b.joint_target_ke[d] == pytest.approx(stiff, rel=1e-6, abs=1e-12)
        assert b.joint_q[q] == pytest.approx(read_initial_state(contract)[jname], rel=1e-6)


# --------------------------------------------------------------- real assets
def _dev_object(asset_id: str) -> Path:
    p = SHARED / asset_id
    if not (p / "mobility.urdf").is_file():
        pytest.skip(f"dev object {asset_id} not present")
    return p


@pytest.mark.slow
@pytest.mark.parametrize("asset_id,prompt", [("103275", "I want a slightly open stapler."),  # the dev rows' own requests
                                             ("7236", "I want a microwave with its door halfway open. Low damping for hinge-like behavior.")])
def test_refined_dev_objects_export(asset_id, prompt, tmp_path, refine_once):
    """Refine a real dev object (no extras) and export it: every link's
    mass/COM/inertia and every joint's values read back equal (check_usd)."""
    out = refine_once(_dev_object(asset_id), prompt, extras=False).copy_to(tmp_path / asset_id)
    build = export_usd(out)
    check = check_usd(build.path, out)
    urdf = read_urdf(out / "mobility.urdf")
    assert check.links == len(urdf.links) and check.joints == len(urdf.movable_joints)
    assert check.max_rel_error < 1e-6
    usd = read_usd(build.path)
    assert math.isclose(sum(lk.inertial.mass for lk in usd.model.links.values() if lk.inertial), urdf.total_mass(), rel_tol=1e-6)


# ------------------------------------------------------------ docs snippets
DOC = Path(__file__).resolve().parents[2] / "docs" / "guide" / "simulators.md"


def _doc_snippets() -> list[str]:
    text = DOC.read_text().split("## Loading an output in each simulator", 1)[1]
    return [block.split("```", 1)[0] for block in text.split("```python\n")[1:]]


def test_docs_snippets_load_an_output(contract):
    """Every loading snippet of docs/guide/simulators.md whose simulator is
    installed here runs on a real output folder (USD and MJCF exported)."""
    import importlib.util

    export_usd(contract)
    if importlib.util.find_spec("mujoco"):
        export_mjcf(contract)
    snippets = _doc_snippets()
    assert len(snippets) >= 5
    ran = 0
    for code in snippets:
        module = code.split("import ", 1)[1].split()[0].split(".")[0].rstrip(",")
        if importlib.util.find_spec(module) is None:
            continue
        exec(compile(code, f"{DOC}:{module}", "exec"), {"OUT": str(contract)})
        ran += 1
    assert ran >= 2  # pxr and pybullet at least


def test_parent_child_pairs_filtered_and_friction_as_physx_reads_it(tmp_path):
    """Every joint's child body names its parent in FilteredPairsAPI (the SPEC's exclusion, explicit), and every movable
    joint carries its friction as PhysX's static and dynamic friction effort (N*m or N), the file's value."""
    a = write_contract_asset(tmp_path, lid_friction=0.5, post_friction=2.0)
    build = export_usd(tmp_path)
    stage = Usd.Stage.Open(str(build.path))
    model = read_urdf(a.urdf)
    for j in model.joints:
        child = stage.GetPrimAtPath(build.links[j.child])
        assert child.HasAPI(UsdPhysics.FilteredPairsAPI), j.child
        assert [str(t) for t in UsdPhysics.FilteredPairsAPI(child).GetFilteredPairsRel().GetTargets()] == [build.links[j.parent]]
    for j in model.movable_joints:
        prim = stage.GetPrimAtPath(build.joints[j.name])
        dof = "linear" if j.type == "prismatic" else "angular"
        assert f"PhysxJointAxisAPI:{dof}" in prim.GetMetadata("apiSchemas").GetAddedOrExplicitItems()
        for effort in ("staticFrictionEffort", "dynamicFrictionEffort"):
            assert prim.GetAttribute(f"physxJointAxis:{dof}:{effort}").Get() == pytest.approx(j.friction, rel=1e-7)


def test_the_two_exports_of_one_folder_read_each_visual_mesh_once(contract, monkeypatch):
    """The MJCF and USD exports of one held folder (as a refine writes them) parse each visual mesh file once."""
    from asset2sim import mesh_io
    from asset2sim.refined_asset import RefinedAsset

    reads = []
    real = mesh_io.read_obj
    monkeypatch.setattr(mesh_io, "read_obj", lambda data, where: reads.append(Path(where)) or real(data, where))
    held = RefinedAsset(contract)
    export_mjcf(held)
    export_usd(held)
    visuals = {v.path for link in read_urdf(contract / "mobility.urdf").links.values() for v in link.visuals if v.kind == "mesh"}
    assert visuals and sorted(reads) == sorted(visuals)
