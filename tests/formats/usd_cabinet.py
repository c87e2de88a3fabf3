"""A cabinet with a hinged door as an OpenUSD stage, in centimetres and Y up (stage units a host would author):
the carcass (five 2 cm panels, open at the front) and the 50 x 80 x 2 cm door hinged on its right edge about +Y,
0..90 degrees, with a drive and a friction; masses authored. Used by the host write-back tests."""

from __future__ import annotations

from pathlib import Path

from pxr import Gf, Sdf, Usd, UsdGeom, UsdPhysics

#: Prim paths of the stage.
ROOT, CARCASS, DOOR, HINGE = "/cabinet", "/cabinet/carcass", "/cabinet/door", "/cabinet/hinge"


def _box(stage, path: str, center, size) -> None:
    cube = UsdGeom.Cube.Define(stage, path)
    cube.CreateSizeAttr(1.0)
    cube.AddTranslateOp().Set(Gf.Vec3d(*center))
    cube.AddScaleOp().Set(Gf.Vec3f(*size))
    UsdPhysics.CollisionAPI.Apply(cube.GetPrim())
    cube.CreateDisplayColorAttr([Gf.Vec3f(0.6, 0.45, 0.3)])


def _body(stage, path: str, pos, mass: float, com, diag):
    xf = UsdGeom.Xform.Define(stage, path)
    xf.AddTranslateOp(UsdGeom.XformOp.PrecisionDouble).Set(Gf.Vec3d(*pos))
    prim = xf.GetPrim()
    UsdPhysics.RigidBodyAPI.Apply(prim)
    m = UsdPhysics.MassAPI.Apply(prim)
    m.CreateMassAttr(mass)
    m.CreateCenterOfMassAttr(Gf.Vec3f(*com))
    m.CreateDiagonalInertiaAttr(Gf.Vec3f(*diag))
    m.CreatePrincipalAxesAttr(Gf.Quatf(1.0))
    return prim


def cabinet_usd(path: Path) -> Path:
    """Write the cabinet at ``path`` (``.usda``); returns ``path``."""
    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y)
    UsdGeom.SetStageMetersPerUnit(stage, 0.01)
    root = UsdGeom.Xform.Define(stage, ROOT).GetPrim()
    stage.SetDefaultPrim(root)
    UsdPhysics.ArticulationRootAPI.Apply(root)
    carcass = _body(stage, CARCASS, (0, 40, 0), 18.0, (0, 0, -2), (12000, 8000, 14000))  # kg*cm^2
    for name, center, size in (("back", (0, 0, -19), (50, 80, 2)), ("left", (-24, 0, 0), (2, 80, 40)),
                               ("right", (24, 0, 0), (2, 80, 40)), ("top", (0, 39, 0), (46, 2, 36)),
                               ("bottom", (0, -39, 0), (46, 2, 36))):
        _box(stage, f"{CARCASS}/{name}", center, size)
    door = _body(stage, DOOR, (0, 40, 21), 4.0, (0, 0, 0), (2100, 850, 3000))
    _box(stage, f"{DOOR}/panel", (0, 0, 0), (50, 80, 2))
    handle = UsdGeom.Cube.Define(stage, f"{DOOR}/handle")
    handle.CreateSizeAttr(1.0)
    handle.AddTranslateOp().Set(Gf.Vec3d(-20, 0, 2))
    handle.AddScaleOp().Set(Gf.Vec3f(2, 12, 2))
    hinge = UsdPhysics.RevoluteJoint.Define(stage, HINGE)
    hinge.CreateBody0Rel().SetTargets([carcass.GetPath()])
    hinge.CreateBody1Rel().SetTargets([door.GetPath()])
    hinge.CreateLocalPos0Attr(Gf.Vec3f(25, 0, 21))
    hinge.CreateLocalPos1Attr(Gf.Vec3f(25, 0, 0))
    hinge.CreateLocalRot0Attr(Gf.Quatf(1.0))
    hinge.CreateLocalRot1Attr(Gf.Quatf(1.0))
    hinge.CreateAxisAttr(UsdPhysics.Tokens.y)
    hinge.CreateLowerLimitAttr(0.0)
    hinge.CreateUpperLimitAttr(90.0)
    drive = UsdPhysics.DriveAPI.Apply(hinge.GetPrim(), "angular")
    drive.CreateDampingAttr(1.0)  # kg*cm^2/s per degree
    drive.CreateStiffnessAttr(0.0)
    hinge.GetPrim().CreateAttribute("newton:friction", Sdf.ValueTypeNames.Float).Set(100.0)  # kg*cm^2/s^2
    stage.Save()
    return path
