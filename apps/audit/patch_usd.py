"""The audit's patch of an OpenUSD asset: the stage flattened into one ``.usda`` layer (references and sublayers
resolved; the input's layers are only read) with the UsdPhysics attributes of the changed links and joints set
in the stage's own units, the inverse of :mod:`asset2sim.tasks.ingest.usd_reader`'s conversions:

- a body's ``physics:mass`` (kg / ``kilogramsPerUnit``), ``physics:centerOfMass`` (body-local stage units),
  ``physics:diagonalInertia`` and ``physics:principalAxes`` (the tensor in the body's axes, kg*m^2 /
  (``kilogramsPerUnit`` * ``metersPerUnit``^2), diagonalised);
- a joint's ``PhysicsDriveAPI:angular`` / ``:linear`` damping (per degree for revolute joints, as UsdPhysics
  writes angular gains; a drive is added with stiffness 0 where the joint had none) and ``asset2sim:friction``
  (N*m or N in stage units), which the reader takes before ``newton:friction``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from asset2sim import atomic, file_names
from asset2sim.frames import matrix_quat_wxyz, rigid_inverse
from asset2sim.openusd import pxr_modules
from asset2sim.schemas.overlay import JointDynamics, LinkPhysics
from asset2sim.tasks.ingest.declared import DeclaredPhysics
from asset2sim.tasks.ingest.usd_reader import DEG, FRICTION_ATTRS
from asset2sim.tasks.ingest.usd_stage import open_stage

__all__ = ["write_usd"]


def _principal(tensor: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(principal moments (3,), rotation (3, 3) with det +1 whose columns are the principal axes) of a tensor."""
    d, q = np.linalg.eigh(0.5 * (tensor + tensor.T))
    if np.linalg.det(q) < 0:
        q[:, 0] = -q[:, 0]
    return d, q


def write_usd(dp: DeclaredPhysics, links: dict[str, LinkPhysics], joints: dict[str, JointDynamics], folder: Path) -> Path:
    """Write ``folder/<stem>.usda``: the flattened stage of ``dp.source`` with ``links``' mass, center of mass and
    inertia tensor and ``joints``' damping and friction (SI, the asset model's link frames) in stage units.

    Raises:
        ImportError: usd-core is not installed.
        StagingError: the stage cannot be opened.
        KeyError: a link or joint the reader did not record a prim for.
    """
    Gf, Sdf, _, Usd, UsdGeom, UsdPhysics = pxr_modules()
    assert dp.read is not None
    ctx = open_stage(Path(dp.source))
    layer = ctx.stage.Flatten()
    stage = Usd.Stage.Open(layer)
    cache = UsdGeom.XformCache(Usd.TimeCode.Default())
    for name, lp in links.items():
        body = stage.GetPrimAtPath(dp.read.prims[name])
        world = ctx.L @ np.array(cache.GetLocalToWorldTransform(body), float).T
        to_link = rigid_inverse(dp.read.frames[name]) @ world  # body-local (stage units) -> link frame (m)
        a = to_link[:3, :3] / ctx.m  # body axes -> link axes
        tensor = a.T @ lp.inertia.matrix() @ a / (ctx.kg * ctx.m ** 2)
        d, q = _principal(tensor)
        com = (np.linalg.inv(to_link) @ np.append(np.asarray(lp.com, float), 1.0))[:3]
        mass_api = UsdPhysics.MassAPI.Apply(body)
        mass_api.CreateMassAttr().Set(float(lp.mass / ctx.kg))
        mass_api.CreateCenterOfMassAttr().Set(Gf.Vec3f(*(float(v) for v in com)))
        mass_api.CreateDiagonalInertiaAttr().Set(Gf.Vec3f(*(float(v) for v in d)))
        w, x, y, z = (float(v) for v in matrix_quat_wxyz(q))
        mass_api.CreatePrincipalAxesAttr().Set(Gf.Quatf(w, x, y, z))
        if body.HasAttribute("physics:density"):
            body.GetAttribute("physics:density").Set(0.0)  # an explicit mass wins; no density left to contradict it
    for name, jd in joints.items():
        prim = stage.GetPrimAtPath(dp.read.prims[name])
        rot = prim.IsA(UsdPhysics.RevoluteJoint)
        dof = "angular" if rot else "linear"
        gain = ctx.kg * ctx.m ** 2 * DEG if rot else ctx.kg  # the reader's: stage gain -> SI
        force = ctx.kg * ctx.m * (ctx.m if rot else 1.0)
        drive = UsdPhysics.DriveAPI.Apply(prim, dof)
        if not drive.GetStiffnessAttr().HasAuthoredValue():
            drive.CreateStiffnessAttr().Set(0.0)
        drive.CreateDampingAttr().Set(float(jd.damping / gain))
        prim.CreateAttribute(FRICTION_ATTRS[0], Sdf.ValueTypeNames.Float).Set(float(jd.friction / force))
    out = folder / f"{file_names.file_stem(Path(dp.source).stem)}.usda"
    atomic.write_text(out, layer.ExportToString())
    return out
