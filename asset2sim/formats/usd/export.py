"""Export an output folder to OpenUSD with UsdPhysics (Isaac Sim / Isaac Lab,
Newton): ``usd/mobility.usd``, one self-contained binary layer derived from
``mobility.urdf``, ``overlay.json`` (springs) and ``initial_state.json``.
Prim layout and unit conversions: docs/design/simulators.md, "USD export".
"""

from __future__ import annotations

import os
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from asset2sim import atomic
from asset2sim.extras import pxr_modules as _pxr
from asset2sim.engines.loading import principal_axes, transform_points
from asset2sim.refined_asset import RefinedAsset
from asset2sim.formats.staging import numbered
from asset2sim.formats.usd.check import check_usd
from asset2sim.formats.usd.reader import DEG
from asset2sim.frames import matrix_quat_wxyz
from asset2sim.mesh_io import MeshCache, MeshReadError, convex_hull_mesh
from asset2sim.urdf import MOVABLE, UrdfJoint, UrdfModel
from asset2sim.output_folder import USD_DIR

# --------------------------------------------------------------------- helpers
def _axis_frame(axis: np.ndarray) -> np.ndarray:
    """A rotation (3, 3) whose first column is the unit ``axis`` (3,)."""
    x = np.asarray(axis, float) / np.linalg.norm(axis)
    helper = np.array([0.0, 0.0, 1.0]) if abs(x[2]) < 0.9 else np.array([0.0, 1.0, 0.0])
    y = np.cross(helper, x)
    y /= np.linalg.norm(y)
    z = np.cross(x, y)
    return np.column_stack([x, y, z])


def _placed(xformable, pose: np.ndarray):
    """``xformable`` (a UsdGeom.Xformable) given a translate and an orient op (double precision) of ``pose`` (4, 4)."""
    Gf, _, _, _, UsdGeom, _ = _pxr()
    xformable.AddTranslateOp(UsdGeom.XformOp.PrecisionDouble).Set(Gf.Vec3d(*map(float, pose[:3, 3])))
    xformable.AddOrientOp(UsdGeom.XformOp.PrecisionDouble).Set(Gf.Quatd(*matrix_quat_wxyz(pose[:3, :3]).tolist()))
    return xformable


def _names(names: list[str]) -> dict[str, str]:
    """URDF name -> a unique valid USD prim name."""
    used: set[str] = set()
    return {n: numbered(_pxr()[2].MakeValidIdentifier(n) or "_", used) for n in names}


# ---------------------------------------------------------------------- writing
@dataclass
class UsdBuild:
    """What :func:`export_usd` wrote: ``path``, the prim path of every link and
    joint (URDF name -> prim path), and conversion ``notes``."""

    path: Path
    links: dict[str, str]
    joints: dict[str, str]
    fixed_root: bool
    notes: list[str] = field(default_factory=list)


def export_usd(out_dir: Path | RefinedAsset, *, visuals: bool = True, check: bool = True) -> UsdBuild:
    """Write ``out_dir/usd/<urdf stem>.usd`` from ``mobility.urdf``,
    ``overlay.json`` and ``initial_state.json`` (module docstring).

    Args:
        out_dir: an output folder of the SPEC's contract (or its :class:`~asset2sim.refined_asset.RefinedAsset`).
        visuals: include the visual meshes.
        check: read the written file back and run :func:`check_usd`.

    Raises:
        FileNotFoundError: no ``mobility.urdf`` in ``out_dir``.
        ImportError: ``usd-core`` is not installed.
        ValueError: invalid ``initial_state.json`` / ``overlay.json``.
        UrdfError: the URDF or a collision mesh cannot be read.
        UsdExportError: the written file does not check out.
    """
    Gf, Sdf, _, _, UsdGeom, UsdPhysics = _pxr()  # ImportError first, without usd-core
    asset = RefinedAsset.existing(out_dir)
    model, state = asset.model, asset.initial_state
    springs, fixed = asset.springs, asset.root.fixed  # the overlay's and state's errors before any mesh is read
    notes = list(asset.collision[1])  # the cached notes stay as read
    stage, root_path = _new_stage(model)
    # every link a rigid body under /<robot>, posed at the folder's initial state, with its visuals (``visuals``, their
    # files read through asset.meshes) and collision pieces: URDF link name -> prim path
    poses, links = model.link_poses(state), {}
    for name, prim_name in _names(model.tree_order()).items():
        path, link = root_path.AppendChild(prim_name), model.links[name]
        links[name] = str(path)
        # an Xform with RigidBodyAPI, MassAPI (mass kg, COM m, principal moments kg*m^2 and axes) and a physics
        # material when the URDF gives a lateral friction
        prim = _placed(UsdGeom.Xform.Define(stage, path), poses[name]).GetPrim()
        prim.CreateAttribute("asset2sim:name", Sdf.ValueTypeNames.String, custom=True).Set(name)
        UsdPhysics.RigidBodyAPI.Apply(prim)
        mass_api = UsdPhysics.MassAPI.Apply(prim)
        if link.inertial is not None and link.inertial.mass is not None:
            mass_api.CreateMassAttr(float(link.inertial.mass))
            mass_api.CreateCenterOfMassAttr(Gf.Vec3f(*map(float, link.inertial.com())))
            moments, axes = principal_axes(link.inertial.inertia_in_link_axes())
            mass_api.CreateDiagonalInertiaAttr(Gf.Vec3f(*map(float, moments)))
            mass_api.CreatePrincipalAxesAttr(Gf.Quatf(*matrix_quat_wxyz(axes).tolist()))
        else:
            notes.append(f"link {name!r} has no <inertial>: physics:mass not authored (computed from colliders)")
        if link.lateral_friction is not None:
            mat = UsdPhysics.MaterialAPI.Apply(UsdGeom.Scope.Define(stage, path.AppendChild("physics_material")).GetPrim())
            mat.CreateStaticFrictionAttr(float(link.lateral_friction))
            mat.CreateDynamicFrictionAttr(float(link.lateral_friction))
            mat.CreateRestitutionAttr(float(link.restitution or 0.0))
        if visuals:
            _write_visuals(stage, path, model, name, notes, asset.meshes)
        scope = path.AppendChild("collisions")  # the collision pieces, guides; a hull a convex-hull mesh collider
        UsdGeom.Scope.Define(stage, scope)
        for k, piece in enumerate(asset.collision[0].get(name, [])):
            p, hull = scope.AppendChild(f"piece_{k}"), piece.kind == "hull"
            g = (_mesh(stage, p, *convex_hull_mesh(transform_points(piece.origin, piece.points))) if hull
                 else _primitive(stage, p, piece.kind, piece.size, piece.radius, piece.length, piece.origin))
            if g is None:
                continue
            UsdPhysics.CollisionAPI.Apply(g.GetPrim())
            if hull:
                UsdPhysics.MeshCollisionAPI.Apply(g.GetPrim()).CreateApproximationAttr(UsdPhysics.Tokens.convexHull)
            g.CreatePurposeAttr(UsdGeom.Tokens.guide)
    # every URDF joint under /<robot>/joints at the initial state, with its spring, and for a fixed root a FixedJoint
    # from the world to the root link: URDF joint name -> prim path
    joint_names, scope, joints = _names([j.name for j in model.joints]), root_path.AppendChild("joints"), {}
    UsdGeom.Scope.Define(stage, scope)
    for j in model.joints:
        jp = scope.AppendChild(joint_names[j.name])
        joints[j.name] = str(jp)
        _write_joint(stage, jp, j, links, state, springs.get(j.name))
        # UsdPhysics.FilteredPairsAPI on the child body naming its parent: the SPEC's exclusion of a link and its
        # parent, explicit for a runtime or importer that collides jointed bodies (UsdPhysics joints disable their two
        # bodies' collision only through physics:collisionEnabled, which a fixed joint merged by an importer loses)
        api = UsdPhysics.FilteredPairsAPI.Apply(stage.GetPrimAtPath(links[j.child]))
        api.CreateFilteredPairsRel().AddTarget(Sdf.Path(links[j.parent]))
    if fixed:
        fj = UsdPhysics.FixedJoint.Define(stage, scope.AppendChild(
            "root_joint" if "root_joint" not in joint_names.values() else "asset2sim_root_joint"))
        fj.CreateBody1Rel().SetTargets([Sdf.Path(links[model.root])])
        fj.CreateLocalPos0Attr(Gf.Vec3f(0, 0, 0))
        fj.CreateLocalRot0Attr(Gf.Quatf(1, 0, 0, 0))
        fj.CreateLocalPos1Attr(Gf.Vec3f(0, 0, 0))
        fj.CreateLocalRot1Attr(Gf.Quatf(1, 0, 0, 0))
    target = _save(stage, asset.folder / USD_DIR / f"{asset.urdf_path.stem}.usd")
    if check:
        check_usd(target, asset)
    return UsdBuild(path=target, links=links, joints=joints, fixed_root=fixed, notes=notes)


def _new_stage(model: UrdfModel):
    """An in-memory stage (z up, m, kg) and the path of its default prim
    ``/<robot>``, an Xform with the ArticulationRootAPI."""
    _, Sdf, Tf, Usd, UsdGeom, UsdPhysics = _pxr()
    stage = Usd.Stage.CreateInMemory()
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.z)
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    UsdPhysics.SetStageKilogramsPerUnit(stage, 1.0)
    robot_name = Tf.MakeValidIdentifier(model.name or "asset") or "asset"
    root_path = Sdf.Path(f"/{robot_name}")
    robot = UsdGeom.Xform.Define(stage, root_path)
    stage.SetDefaultPrim(robot.GetPrim())
    UsdPhysics.ArticulationRootAPI.Apply(robot.GetPrim())
    robot.GetPrim().SetDocumentation(
        "Written by asset2sim from mobility.urdf (source of truth), overlay.json (springs) and initial_state.json "
        "(joint positions, mounting). SI units; revolute limits, drive gains and joint states in degrees as "
        "UsdPhysics prescribes; Coulomb joint friction in newton:friction / asset2sim:friction (N*m or N)."
    )
    return stage, root_path


def _save(stage, target: Path) -> Path:
    """Write the stage as one binary layer to ``target`` atomically (exported
    to a temporary file beside it first); returns ``target``."""
    atomic.announce([target])  # the output's guard first: nothing is made through a symlinked usd/ folder
    target.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(suffix=".usd", dir=target.parent)
    os.close(fd)
    try:
        stage.GetRootLayer().Export(tmp)
        atomic.write_bytes(target, Path(tmp).read_bytes())
    finally:
        Path(tmp).unlink(missing_ok=True)
    return target


def _write_visuals(stage, link_path, model: UrdfModel, link: str, notes: list[str], meshes: MeshCache) -> None:
    Gf, _, _, _, UsdGeom, _ = _pxr()
    scope = link_path.AppendChild("visuals")
    UsdGeom.Scope.Define(stage, scope)
    for k, v in enumerate(model.links[link].visuals):
        p = scope.AppendChild(f"visual_{k}")
        if v.kind == "mesh":
            try:
                read = meshes.get(v.path)
                verts, faces = read.vertices, read.faces
            except MeshReadError as exc:
                notes.append(f"link {link!r} visual {k}: {exc}; left out")
                continue
            faces = faces[(faces >= 0).all(axis=1) & (faces < len(verts)).all(axis=1)]
            if len(faces) == 0:
                notes.append(f"link {link!r} visual {k} ({v.filename}) has no faces; left out")
                continue
            mesh = _mesh(stage, p, transform_points(v.origin, verts * v.scale), faces)
            mesh.CreateDoubleSidedAttr(True)
        else:
            mesh = _primitive(stage, p, v.kind, v.size, v.radius, v.length, v.origin)
            if mesh is None:
                continue
        if v.material is not None and v.material.rgba is not None:
            mesh.CreateDisplayColorAttr([Gf.Vec3f(*map(float, v.material.rgba[:3]))])


def _mesh(stage, path, points: np.ndarray, triangles: np.ndarray):
    """A UsdGeom.Mesh at ``path`` of points (k, 3) m (binary32) and triangles (m, 3), not subdivided."""
    from pxr import UsdGeom, Vt

    mesh = UsdGeom.Mesh.Define(stage, path)
    mesh.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(points, np.float32)))
    mesh.CreateFaceVertexCountsAttr(Vt.IntArray.FromNumpy(np.full(len(triangles), 3, np.int32)))
    mesh.CreateFaceVertexIndicesAttr(Vt.IntArray.FromNumpy(np.ascontiguousarray(triangles, np.int32).ravel()))
    mesh.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
    return mesh


def _primitive(stage, path, kind: str, size, radius, length, origin: np.ndarray):
    """A box / sphere / cylinder prim (UsdGeom Cube / Sphere / Cylinder along z) at ``origin`` (4, 4)."""
    Gf, _, _, _, UsdGeom, _ = _pxr()
    if kind == "box":
        g = UsdGeom.Cube.Define(stage, path)
        g.CreateSizeAttr(1.0)
    elif kind == "sphere":
        g = UsdGeom.Sphere.Define(stage, path)
        g.CreateRadiusAttr(float(radius))
    elif kind == "cylinder":
        g = UsdGeom.Cylinder.Define(stage, path)
        g.CreateRadiusAttr(float(radius))
        g.CreateHeightAttr(float(length))
        g.CreateAxisAttr(UsdGeom.Tokens.z)
    else:
        return None
    _placed(g, origin)
    if kind == "box":
        g.AddScaleOp(UsdGeom.XformOp.PrecisionDouble).Set(Gf.Vec3d(*map(float, size)))
    return g


def _write_joint(stage, path, j: UrdfJoint, link_paths: dict[str, str], initial: dict[str, float], spring) -> None:
    Gf, Sdf, _, _, _, UsdPhysics = _pxr()
    rot = j.type in ("revolute", "continuous")
    kind = UsdPhysics.RevoluteJoint if rot else UsdPhysics.PrismaticJoint if j.type == "prismatic" else UsdPhysics.FixedJoint
    joint = kind.Define(stage, path)
    joint.CreateBody0Rel().SetTargets([Sdf.Path(link_paths[j.parent])])
    joint.CreateBody1Rel().SetTargets([Sdf.Path(link_paths[j.child])])
    prim = joint.GetPrim()
    prim.CreateAttribute("asset2sim:name", Sdf.ValueTypeNames.String, custom=True).Set(j.name)
    a = _axis_frame(j.axis) if j.type in MOVABLE else np.eye(3)
    joint.CreateLocalPos0Attr(Gf.Vec3f(*map(float, j.origin[:3, 3])))
    joint.CreateLocalRot0Attr(Gf.Quatf(*map(float, matrix_quat_wxyz(j.origin[:3, :3] @ a))))
    joint.CreateLocalPos1Attr(Gf.Vec3f(0.0, 0.0, 0.0))
    joint.CreateLocalRot1Attr(Gf.Quatf(*map(float, matrix_quat_wxyz(a))))
    if j.type == "fixed":
        return
    joint.CreateAxisAttr(UsdPhysics.Tokens.x)
    unit = DEG if rot else 1.0
    if j.type in ("revolute", "prismatic"):
        joint.CreateLowerLimitAttr(float(j.lower * unit))
        joint.CreateUpperLimitAttr(float(j.upper * unit))
    dof = "angular" if rot else "linear"
    k, ref = (spring.stiffness, spring.reference) if spring is not None else (0.0, 0.0)
    if j.damping > 0 or k > 0:
        drive = UsdPhysics.DriveAPI.Apply(prim, dof)
        drive.CreateTypeAttr(UsdPhysics.Tokens.force)
        drive.CreateDampingAttr(float(j.damping / unit))
        drive.CreateStiffnessAttr(float(k / unit))
        drive.CreateTargetPositionAttr(float(ref * unit))
        drive.CreateTargetVelocityAttr(0.0)
    position, Float = float(initial.get(j.name, 0.0) * unit), Sdf.ValueTypeNames.Float
    prim.AddAppliedSchema(f"PhysicsJointStateAPI:{dof}")
    prim.CreateAttribute(f"state:{dof}:physics:position", Float).Set(position)
    prim.CreateAttribute(f"state:{dof}:physics:velocity", Float).Set(0.0)
    # Newton's importer reads its own namespace by default (newton:<dof>:position, degrees for angular)
    prim.CreateAttribute(f"newton:{dof}:position", Float).Set(position)
    prim.AddAppliedSchema("NewtonJointAPI")
    prim.CreateAttribute("newton:friction", Float).Set(float(j.friction))
    # PhysX (Isaac Sim 5, ovphysx) reads Coulomb joint friction as an effort (N*m or N) from PhysxJointAxisAPI:<dof>
    # (ovphysx also takes newton:friction); physxJoint:jointFriction, PhysX's unitless coefficient on the constraint
    # force, is left at its default 0
    prim.AddAppliedSchema(f"PhysxJointAxisAPI:{dof}")
    for effort in ("staticFrictionEffort", "dynamicFrictionEffort"):
        prim.CreateAttribute(f"physxJointAxis:{dof}:{effort}", Float).Set(float(j.friction))
    for attr, value in (("damping", j.damping), ("friction", j.friction), ("stiffness", k), ("springReference", ref)):
        prim.CreateAttribute(f"asset2sim:{attr}", Sdf.ValueTypeNames.Double, custom=True).Set(float(value))
