"""The OpenUSD reader: refined outputs exported to USD read back equal to their URDF, stages built here with pxr
(units, up axis, frames, drives, masses, primitives) read as computed by hand, refusals name the prim or joint,
and a read asset stages as a URDF folder."""

from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np
import pytest

pxr = pytest.importorskip("pxr")

from pxr import Gf, Sdf, Usd, UsdGeom, UsdPhysics, Vt  # noqa: E402

from asset2sim.mesh_io import read_mesh  # noqa: E402
from asset2sim.formats import staging  # noqa: E402
from asset2sim.formats.staging import StagingError  # noqa: E402
from asset2sim.formats.usd.reader import read_usd_asset  # noqa: E402
from asset2sim.urdf import read_urdf  # noqa: E402

DEG = 180.0 / math.pi
RTOL = 1e-6


def _close(got, want, scale: float | None = None) -> bool:
    """Every entry within RTOL of the quantity's scale (its largest magnitude unless given)."""
    got, want = np.asarray(got, float), np.asarray(want, float)
    s = float(np.abs(want).max()) if scale is None else scale
    return got.shape == want.shape and float(np.abs(got - want).max()) <= RTOL * max(s, 1e-300) + 1e-15


# ------------------------------------------------------------ refined real objects, exported and read back
def _prompt(shared: Path, asset_id: str) -> str:
    with open(shared / "manifest.csv", newline="") as f:
        return next(r["prompt"] for r in csv.DictReader(f) if r["id"] == asset_id)


@pytest.mark.parametrize("asset_id", ["148", "103275", "8877"])
@pytest.mark.slow  # end to end: dev objects refined and exported
def test_refined_output_round_trip(asset_id, shared_dataset, tmp_path, refine_once):
    """Links, joints (type, parent, child, origin, axis, limits, damping, friction), springs, masses, COM and
    inertia tensors of the USD export equal mobility.urdf's to 1e-6 relative; geometry sits where the URDF's does."""
    from asset2sim.refined_asset import read_initial_state
    from asset2sim.refined_asset import springs_from_overlay
    from asset2sim.refined_asset import read_root
    from asset2sim.formats.usd.export import export_usd

    if not (shared_dataset / asset_id / "mobility.urdf").is_file():
        pytest.skip(f"dev object {asset_id} not present")
    out = refine_once(shared_dataset / asset_id, _prompt(shared_dataset, asset_id), extras=False).copy_to(tmp_path / "out")
    usd = export_usd(out).path
    read, src = read_usd_asset(usd), read_urdf(out / "mobility.urdf")
    model = read.model
    assert read.format == "usd" and read.files == (usd,)
    assert sorted(model.links) == sorted(src.links) and model.root == src.root
    assert len(model.joints) == len(src.joints)
    for j in src.joints:
        g = model.joint(j.name)
        assert (g.type, g.parent, g.child) == (j.type, j.parent, j.child), j.name
        assert _close(g.origin, j.origin, max(float(np.abs(j.origin).max()), 1.0)), (j.name, g.origin, j.origin)
        if j.type == "fixed":
            continue
        assert _close(g.axis, j.axis, 1.0), j.name
        if j.type != "continuous":
            assert _close([g.lower, g.upper], [j.lower, j.upper], max(abs(j.lower), abs(j.upper), 1e-3)), j.name
        assert _close(g.damping, j.damping) and _close(g.friction, j.friction), j.name
    springs = {n: s for n, s in springs_from_overlay(out, read_initial_state(out)).items() if s.stiffness > 0}  # catches: no USD attribute
    assert set(read.springs) == set(springs)
    for name, s in springs.items():
        assert _close(read.springs[name].stiffness, s.stiffness) and _close(read.springs[name].reference, s.reference, 1.0)
    assert any("root fixed to the world" in n for n in read.notes) == read_root(out).fixed
    assert set(read.inferred) == {n for n, lk in src.links.items() if lk.inertial is None}
    for name, link in src.links.items():
        got = model.links[name]
        if link.inertial is not None:
            assert _close(got.inertial.mass, link.inertial.mass), name
            assert _close(got.inertial.com(), link.inertial.com(), max(float(np.abs(link.inertial.com()).max()), 1e-3)), name
            assert _close(got.inertial.inertia_in_link_axes(), link.inertial.inertia_in_link_axes()), name
        assert bool(got.collisions) == bool(link.collisions) and (not link.visuals or got.visuals), name
        if link.visuals:  # the visual meshes' bounds in the link frame, m (binary32 points)
            want = np.concatenate([(read_mesh(v.path).vertices * v.scale) @ v.origin[:3, :3].T + v.origin[:3, 3] for v in link.visuals])
            have = np.concatenate([read.meshes[v.filename][0] for v in got.visuals])
            assert np.allclose(have.min(0), want.min(0), atol=1e-6) and np.allclose(have.max(0), want.max(0), atol=1e-6), name


# ------------------------------------------------------------------------------- stages built here
def _new_stage(path: Path, *, up: str = "Z", mpu: float = 1.0, root: str = "/obj", articulation: bool = True):
    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y if up == "Y" else UsdGeom.Tokens.z)
    UsdGeom.SetStageMetersPerUnit(stage, mpu)
    obj = UsdGeom.Xform.Define(stage, root).GetPrim()
    stage.SetDefaultPrim(obj)
    if articulation:
        UsdPhysics.ArticulationRootAPI.Apply(obj)
    return stage


def _body(stage, path: str, pos=(0.0, 0.0, 0.0), rot=None):
    """A rigid body Xform at ``pos`` (stage units), turned by ``rot`` ((axis, degrees)) when given."""
    xf = UsdGeom.Xform.Define(stage, path)
    xf.AddTranslateOp(UsdGeom.XformOp.PrecisionDouble).Set(Gf.Vec3d(*pos))
    if rot is not None:
        xf.AddOrientOp(UsdGeom.XformOp.PrecisionDouble).Set(Gf.Rotation(Gf.Vec3d(*rot[0]), rot[1]).GetQuat())
    UsdPhysics.RigidBodyAPI.Apply(xf.GetPrim())
    return xf.GetPrim()


def _quatf(axis, degrees) -> Gf.Quatf:
    return Gf.Quatf(Gf.Rotation(Gf.Vec3d(*axis), degrees).GetQuat())


def _joint(stage, path: str, schema, body0, body1, *, pos0=(0, 0, 0), pos1=(0, 0, 0), rot0=None, rot1=None):
    j = schema.Define(stage, path)
    if body0 is not None:
        j.CreateBody0Rel().SetTargets([body0.GetPath()])
    j.CreateBody1Rel().SetTargets([body1.GetPath()])
    j.CreateLocalPos0Attr(Gf.Vec3f(*pos0))
    j.CreateLocalPos1Attr(Gf.Vec3f(*pos1))
    j.CreateLocalRot0Attr(rot0 or Gf.Quatf(1.0))
    j.CreateLocalRot1Attr(rot1 or Gf.Quatf(1.0))
    return j


def _box(stage, path: str, scale, *, collision: bool = False, purpose=None):
    cube = UsdGeom.Cube.Define(stage, path)
    cube.CreateSizeAttr(1.0)
    cube.AddScaleOp().Set(Gf.Vec3f(*scale))
    if collision:
        UsdPhysics.CollisionAPI.Apply(cube.GetPrim())
    if purpose:
        cube.CreatePurposeAttr(purpose)
    return cube


def _door(path: Path):
    """A door in its frame, Y up, centimetres: the 60 x 90 x 4 cm panel hinged on its left edge (x = 0) about
    the vertical Y axis, 0..90 deg; the frame fixed to the world, without a mass."""
    stage = _new_stage(path, up="Y", mpu=0.01, root="/door_asm")
    frame = _body(stage, "/door_asm/frame")
    _box(stage, "/door_asm/frame/post", (2, 90, 4), collision=True, purpose=UsdGeom.Tokens.guide)
    door = _body(stage, "/door_asm/door", pos=(30, 45, 0))
    door.CreateAttribute("asset2sim:name", Sdf.ValueTypeNames.String, custom=True).Set("door_panel")
    _box(stage, "/door_asm/door/panel", (60, 90, 4), collision=True)
    face = UsdGeom.Mesh.Define(stage, "/door_asm/door/face")  # one quad on the panel's front, door coordinates (cm)
    face.CreatePointsAttr(Vt.Vec3fArray([(-30, -45, 2), (30, -45, 2), (30, 45, 2), (-30, 45, 2)]))
    face.CreateFaceVertexCountsAttr([4])
    face.CreateFaceVertexIndicesAttr([0, 1, 2, 3])
    face.CreateDisplayColorAttr([Gf.Vec3f(0.5, 0.25, 0.0)])
    mass = UsdPhysics.MassAPI.Apply(door)
    mass.CreateMassAttr(12.0)
    mass.CreateCenterOfMassAttr(Gf.Vec3f(1, 2, 0))  # cm, door coordinates
    mass.CreateDiagonalInertiaAttr(Gf.Vec3f(100, 200, 300))  # kg*cm^2
    mass.CreatePrincipalAxesAttr(Gf.Quatf(1.0))
    _joint(stage, "/door_asm/world_fix", UsdPhysics.FixedJoint, None, frame)
    hinge = _joint(stage, "/door_asm/hinge", UsdPhysics.RevoluteJoint, frame, door, pos0=(0, 45, 0), pos1=(-30, 0, 0))
    hinge.CreateAxisAttr(UsdPhysics.Tokens.y)
    hinge.CreateLowerLimitAttr(0.0)
    hinge.CreateUpperLimitAttr(90.0)
    drive = UsdPhysics.DriveAPI.Apply(hinge.GetPrim(), "angular")
    drive.CreateDampingAttr(2.0)  # kg*cm^2/s per degree
    drive.CreateStiffnessAttr(0.5)  # kg*cm^2/s^2 per degree
    drive.CreateTargetPositionAttr(10.0)  # degrees
    drive.CreateMaxForceAttr(50.0)  # kg*cm^2/s^2
    hinge.GetPrim().CreateAttribute("newton:friction", Sdf.ValueTypeNames.Float).Set(0.25)
    stage.Save()
    return stage


def test_door_in_centimetres_y_up(tmp_path):
    """Every number of the door worked out by hand: cm -> m, Y up -> Z up, degrees -> rad, per-degree gains."""
    _door(tmp_path / "door.usda")
    read = read_usd_asset(tmp_path / "door.usda")
    m = read.model
    assert m.name == "door_asm" and list(m.links) == ["frame", "door_panel"] and m.root == "frame"
    assert any("root fixed to the world" in n for n in read.notes) and any("Y up" in n for n in read.notes)
    (j,) = m.joints
    assert (j.name, j.type, j.parent, j.child) == ("hinge", "revolute", "frame", "door_panel")
    assert np.allclose(j.origin, [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0.45], [0, 0, 0, 1]], atol=1e-7)  # hinge at 45 cm up
    assert np.allclose(j.axis, [0, 0, 1]) and np.isclose(j.lower, 0.0) and np.isclose(j.upper, math.pi / 2)
    torque = 1e-4  # one kg*cm^2/s^2 in N*m
    assert np.isclose(j.damping, 2.0 * torque * DEG) and np.isclose(j.friction, 0.25 * torque)
    assert np.isclose(j.limit.effort, 50.0 * torque)
    spring = read.springs["hinge"]
    assert np.isclose(spring.stiffness, 0.5 * torque * DEG) and np.isclose(spring.reference, math.radians(10))
    door = m.links["door_panel"]
    assert np.isclose(door.inertial.mass, 12.0)
    assert np.allclose(door.inertial.com(), [0.31, 0.0, 0.02])  # 30 cm from the hinge, COM (1, 2, 0) cm with y up
    assert np.allclose(door.inertial.inertia_in_link_axes(), np.diag([0.01, 0.03, 0.02]))  # kg*cm^2 -> kg*m^2, y <-> z
    assert read.inferred == ("frame",)
    (panel,) = door.collisions
    assert panel.kind == "box" and np.allclose(panel.origin[:3, 3], [0.3, 0, 0])
    assert np.allclose(np.abs(panel.origin[:3, :3]) @ panel.size, [0.6, 0.04, 0.9])  # 90 cm along z
    (face,) = door.visuals  # the quad, two triangles, in the link frame (m)
    v, f = read.meshes[face.filename]
    assert face.kind == "mesh" and face.filename.startswith("meshes/") and f.shape == (2, 3)
    assert np.allclose(v.min(0), [0.0, -0.02, -0.45]) and np.allclose(v.max(0), [0.6, -0.02, 0.45])
    assert np.allclose(face.material.rgba, [0.5, 0.25, 0.0, 1.0])
    frame = m.links["frame"]
    assert frame.inertial is None and frame.collisions and frame.visuals  # the guide collider doubles as the visual
    open_pose = m.link_poses({"hinge": math.pi / 2})["door_panel"] @ panel.origin  # opened 90 deg about +z
    assert np.allclose(open_pose[:3, 3], [0.0, 0.3, 0.45])


def test_staged_door_reads_back(tmp_path):
    """stage() writes model.urdf and meshes/*.obj; the URDF reads back with the same joints and meshes."""
    _door(tmp_path / "door.usda")
    read = read_usd_asset(tmp_path / "door.usda")
    out = staging.stage(read, tmp_path / "st")
    back = read_urdf(out.urdf_path)
    assert out.urdf_path == tmp_path / "st" / "model.urdf" and sorted(back.links) == sorted(read.model.links)
    for j in read.model.joints:
        b = back.joint(j.name)
        assert (b.type, b.parent, b.child) == (j.type, j.parent, j.child)
        assert np.allclose(b.origin, j.origin) and np.allclose(b.axis, j.axis)
        assert np.isclose(b.lower, j.lower) and np.isclose(b.upper, j.upper) and np.isclose(b.damping, j.damping)
    for rel, (v, f) in read.meshes.items():
        mesh = read_mesh(tmp_path / "st" / rel)
        verts, faces = mesh.vertices, mesh.faces
        assert np.allclose(verts, v) and len(faces) == len(f)
    assert np.isclose(back.links["door_panel"].inertial.mass, 12.0)


def test_prismatic_drawer_with_turned_frames(tmp_path):
    """A drawer body turned 30 deg about z, sliding along world +y (the joint frame's x turned 90 deg): the link
    keeps the body's axes, the axis is given in them, and moving the joint moves the drawer along +y. The
    articulation root is on the cabinet body (as PhysX allows): the drawer beside it is read through the joint."""
    stage = _new_stage(tmp_path / "drawer.usda", articulation=False)
    cabinet = _body(stage, "/obj/cabinet")
    UsdPhysics.ArticulationRootAPI.Apply(cabinet)
    _body(stage, "/obj/loose")  # another body, in no joint: not part of the cabinet's articulation
    _box(stage, "/obj/cabinet/shell", (1, 1, 1))
    UsdPhysics.MassAPI.Apply(cabinet).CreateDensityAttr(500.0)
    drawer = _body(stage, "/obj/drawer", pos=(0.5, 0.2, 0.3), rot=((0, 0, 1), 30))
    UsdPhysics.MassAPI.Apply(drawer).CreateMassAttr(2.0)  # mass without inertia: left to the simulator
    slide = _joint(stage, "/obj/slide", UsdPhysics.PrismaticJoint, cabinet, drawer, pos0=(0.5, 0.2, 0.3),
                   rot0=_quatf((0, 0, 1), 90), rot1=_quatf((0, 0, 1), 60))
    slide.CreateAxisAttr(UsdPhysics.Tokens.x)
    slide.CreateLowerLimitAttr(0.0)
    slide.CreateUpperLimitAttr(0.4)
    UsdPhysics.DriveAPI.Apply(slide.GetPrim(), "linear").CreateDampingAttr(5.0)
    slide.GetPrim().CreateAttribute("physxJoint:jointFriction", Sdf.ValueTypeNames.Float).Set(0.1)
    stage.Save()
    read = read_usd_asset(tmp_path / "drawer.usda")
    assert list(read.model.links) == ["cabinet", "drawer"] and read.model.root == "cabinet"
    (j,) = read.model.joints
    assert j.type == "prismatic" and np.isclose(j.lower, 0.0) and np.isclose(j.upper, 0.4) and np.isclose(j.damping, 5.0)
    assert j.dynamics.friction is None and any("jointFriction" in n for n in read.notes)
    assert np.allclose(j.axis, [math.cos(math.radians(60)), math.sin(math.radians(60)), 0], atol=1e-6)
    c, s = math.cos(math.pi / 6), math.sin(math.pi / 6)
    rz30 = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
    assert np.allclose(j.origin[:3, :3], rz30, atol=1e-6) and np.allclose(j.origin[:3, 3], [0.5, 0.2, 0.3], atol=1e-6)
    moved = read.model.link_poses({"slide": 0.1})["drawer"]
    assert np.allclose(moved[:3, 3], [0.5, 0.3, 0.3], atol=1e-6)
    assert set(read.inferred) == {"cabinet", "drawer"}
    assert any("physics:density" in n for n in read.notes) and not read.springs


def test_primitives_along_other_axes(tmp_path):
    """A cylinder along x stays a cylinder, its origin turning z to x; a capsule becomes a mesh of its surface;
    a sphere scaled unevenly becomes a mesh."""
    stage = _new_stage(tmp_path / "prims.usda")
    _body(stage, "/obj/rod", pos=(1.0, 0.0, 0.0))
    cyl = UsdGeom.Cylinder.Define(stage, "/obj/rod/bar")
    cyl.CreateAxisAttr(UsdGeom.Tokens.x)
    cyl.CreateRadiusAttr(0.1)
    cyl.CreateHeightAttr(0.5)
    cap = UsdGeom.Capsule.Define(stage, "/obj/rod/grip")
    cap.CreateAxisAttr(UsdGeom.Tokens.y)
    cap.CreateRadiusAttr(0.05)
    cap.CreateHeightAttr(0.2)
    ball = UsdGeom.Sphere.Define(stage, "/obj/rod/egg")
    ball.CreateRadiusAttr(0.1)
    ball.AddScaleOp().Set(Gf.Vec3f(1, 1, 2))
    stage.Save()
    read = read_usd_asset(tmp_path / "prims.usda")
    bar, grip, egg = read.model.links["rod"].visuals
    assert bar.kind == "cylinder" and np.isclose(bar.radius, 0.1) and np.isclose(bar.length, 0.5)
    assert np.allclose(bar.origin[:3, :3] @ [0, 0, 1], [1, 0, 0])
    v, _ = read.meshes[grip.filename]
    assert grip.kind == "mesh" and np.allclose(v.max(0) - v.min(0), [0.1, 0.3, 0.1], atol=1e-3)  # 0.2 + two 0.05 caps
    assert any("Capsule" in n and "mesh" in n for n in read.notes)
    v, _ = read.meshes[egg.filename]
    assert egg.kind == "mesh" and np.allclose(v.max(0) - v.min(0), [0.2, 0.2, 0.4], atol=1e-2)
    assert read.model.links["rod"].collisions == [] and read.inferred == ("rod",)


def test_scaled_body_is_baked_into_geometry(tmp_path):
    """A body scaled (2, 1, 1): the link frame has no scale, the cube is a 2 x 1 x 1 box and mesh points are
    scaled; an inertia authored on that body is refused, naming it."""
    stage = _new_stage(tmp_path / "scaled.usda")
    body = _body(stage, "/obj/slab", pos=(0.0, 0.0, 1.0))
    UsdGeom.Xformable(body).AddScaleOp().Set(Gf.Vec3f(2, 1, 1))
    _box(stage, "/obj/slab/block", (1, 1, 1))
    tri = UsdGeom.Mesh.Define(stage, "/obj/slab/tri")
    tri.CreatePointsAttr(Vt.Vec3fArray([(0, 0, 0), (1, 0, 0), (0, 1, 0)]))
    tri.CreateFaceVertexCountsAttr([3])
    tri.CreateFaceVertexIndicesAttr([0, 1, 2])
    stage.Save()
    read = read_usd_asset(tmp_path / "scaled.usda")
    block, mesh = read.model.links["slab"].visuals
    assert block.kind == "box" and np.allclose(block.size, [2, 1, 1]) and np.allclose(block.origin, np.eye(4))
    assert np.allclose(read.meshes[mesh.filename][0], [[0, 0, 0], [2, 0, 0], [0, 1, 0]])
    mass = UsdPhysics.MassAPI.Apply(body)
    mass.CreateMassAttr(1.0)
    mass.CreateCenterOfMassAttr(Gf.Vec3f(0, 0, 0))
    mass.CreateDiagonalInertiaAttr(Gf.Vec3f(1, 1, 1))
    stage.Save()
    with pytest.raises(StagingError, match=r"scaled\.usda: body /obj/slab: scaled, with an authored inertia"):
        read_usd_asset(tmp_path / "scaled.usda")


def test_root_keeps_the_world_axes(tmp_path):
    """A root body turned 90 deg about x on the stage: the URDF object stands as on the stage (the root link has
    the world's axes), the child's joint origin carries the turn, the root's inertia is turned with it."""
    stage = _new_stage(tmp_path / "turned.usda")
    base = _body(stage, "/obj/base", pos=(0.0, 0.0, 0.5), rot=((1, 0, 0), 90))
    _box(stage, "/obj/base/block", (1, 2, 3))
    mass = UsdPhysics.MassAPI.Apply(base)
    mass.CreateMassAttr(3.0)
    mass.CreateCenterOfMassAttr(Gf.Vec3f(0, 0.1, 0))
    mass.CreateDiagonalInertiaAttr(Gf.Vec3f(1, 2, 3))
    lid = _body(stage, "/obj/lid", pos=(0.0, 0.0, 0.5), rot=((1, 0, 0), 90))
    _joint(stage, "/obj/weld", UsdPhysics.FixedJoint, base, lid)
    stage.Save()
    read = read_usd_asset(tmp_path / "turned.usda")
    (block,) = read.model.links["base"].visuals
    assert np.allclose(np.abs(block.origin[:3, :3]) @ block.size, [1, 3, 2])  # local y (2) is now along z
    inertial = read.model.links["base"].inertial
    assert np.allclose(inertial.com(), [0, 0, 0.1]) and np.allclose(inertial.inertia_in_link_axes(), np.diag([1, 3, 2]))
    weld = read.model.joint("weld")
    assert np.allclose(weld.origin[:3, 3], 0) and np.allclose(weld.origin[:3, :3], [[1, 0, 0], [0, 0, -1], [0, 1, 0]])


def _two_bodies(path: Path):
    stage = _new_stage(path)
    return stage, _body(stage, "/obj/a"), _body(stage, "/obj/b")


def test_refusals_name_the_joint_or_prim(tmp_path):
    stage, a, b = _two_bodies(tmp_path / "ball.usda")
    _joint(stage, "/obj/ball_joint", UsdPhysics.SphericalJoint, a, b)
    stage.Save()
    with pytest.raises(StagingError, match=r"ball\.usda.*'ball_joint'.*no URDF counterpart"):
        read_usd_asset(tmp_path / "ball.usda")

    stage, a, b = _two_bodies(tmp_path / "roots.usda")
    UsdPhysics.ArticulationRootAPI.Apply(UsdGeom.Xform.Define(stage, "/other").GetPrim())
    stage.Save()
    with pytest.raises(StagingError, match=r"2 of them \(/obj, /other\)"):
        read_usd_asset(tmp_path / "roots.usda")

    stage, a, b = _two_bodies(tmp_path / "loop.usda")
    c = _body(stage, "/obj/c")
    _joint(stage, "/obj/j1", UsdPhysics.FixedJoint, a, c)
    _joint(stage, "/obj/j2", UsdPhysics.FixedJoint, b, c)
    stage.Save()
    with pytest.raises(StagingError, match=r"body /obj/c: body1 of joints 'j1' and 'j2'"):
        read_usd_asset(tmp_path / "loop.usda")

    _two_bodies(tmp_path / "forest.usda")[0].Save()
    with pytest.raises(StagingError, match=r"2 bodies and 2 root bodies \(/obj/a, /obj/b\)"):
        read_usd_asset(tmp_path / "forest.usda")

    stage, a, b = _two_bodies(tmp_path / "free.usda")
    _joint(stage, "/obj/hang", UsdPhysics.RevoluteJoint, None, a)
    stage.Save()
    with pytest.raises(StagingError, match=r"'hang'.*revolute joint to the world"):
        read_usd_asset(tmp_path / "free.usda")

    stage, a, b = _two_bodies(tmp_path / "slider.usda")
    _joint(stage, "/obj/rail", UsdPhysics.PrismaticJoint, a, b)  # no limits
    stage.Save()
    with pytest.raises(StagingError, match=r"'rail'.*not finite on both sides"):
        read_usd_asset(tmp_path / "slider.usda")

    with pytest.raises(StagingError, match="no such file"):
        read_usd_asset(tmp_path / "missing.usd")


def test_unlimited_revolute_is_continuous_and_layers_are_listed(tmp_path):
    """A revolute joint without limits is continuous; every layer file the stage uses is in ``files``; a stage
    without an articulation root is read whole (noted)."""
    sub = Usd.Stage.CreateNew(str(tmp_path / "geo.usda"))
    UsdGeom.Sphere.Define(sub, "/obj/b/knob").CreateRadiusAttr(0.02)
    sub.Save()
    stage = Usd.Stage.CreateNew(str(tmp_path / "top.usda"))
    stage.GetRootLayer().subLayerPaths.append("geo.usda")
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.z)
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    a, b = _body(stage, "/obj/a"), _body(stage, "/obj/b")
    j = _joint(stage, "/obj/spin", UsdPhysics.RevoluteJoint, a, b)
    j.CreateAxisAttr(UsdPhysics.Tokens.z)
    stage.Save()
    read = read_usd_asset(tmp_path / "top.usda")
    assert read.model.joint("spin").type == "continuous" and read.model.joint("spin").limit is None
    assert read.files == (tmp_path / "top.usda", tmp_path / "geo.usda")
    assert read.model.links["b"].visuals[0].kind == "sphere" and np.isclose(read.model.links["b"].visuals[0].radius, 0.02)
    assert any("no articulation root" in n for n in read.notes) and read.model.name == "top"
