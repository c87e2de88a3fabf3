"""The audit's patch of an OpenUSD asset: the stage flattened into one ``.usda`` layer (references and sublayers
resolved; the input's layers are only read) with the UsdPhysics attributes of the changed links and joints set
in the stage's own units, the inverse of :mod:`asset2sim.tasks.ingest.usd_reader`'s conversions:

- a body's ``physics:mass`` (kg / ``kilogramsPerUnit``), ``physics:centerOfMass`` (body-local stage units),
  ``physics:diagonalInertia`` and ``physics:principalAxes`` (the tensor in the body's axes, kg*m^2 /
  (``kilogramsPerUnit`` * ``metersPerUnit``^2), diagonalised);
- a joint's ``PhysicsDriveAPI:angular`` / ``:linear`` damping (per degree for revolute joints, as UsdPhysics
  writes angular gains; a drive is added with stiffness 0 where the joint had none) and ``asset2sim:friction``
  (N*m or N in stage units), which the reader takes before ``newton:friction`` (set too where authored).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from asset2sim import atomic, file_names
from asset2sim.openusd import pxr_modules
from asset2sim.schemas.overlay import JointDynamics, LinkPhysics
from asset2sim.tasks.ingest.declared import DeclaredPhysics
from asset2sim.tasks.ingest.usd_stage import open_stage
from asset2sim.tasks.publish.host_usd import UsdEdit, set_body_mass, set_joint_dynamics

__all__ = ["write_usd"]


def write_usd(dp: DeclaredPhysics, links: dict[str, LinkPhysics], joints: dict[str, JointDynamics], folder: Path) -> Path:
    """Write ``folder/<stem>.usda``: the flattened stage of ``dp.source`` with ``links``' mass, center of mass and
    inertia tensor and ``joints``' damping and friction (SI, the asset model's link frames) in stage units
    (:func:`asset2sim.tasks.publish.host_usd.set_body_mass`, :func:`~asset2sim.tasks.publish.host_usd.set_joint_dynamics`).

    Raises:
        ImportError: usd-core is not installed.
        StagingError: the stage cannot be opened.
        KeyError: a link or joint the reader did not record a prim for.
    """
    _, _, _, Usd, UsdGeom, _ = pxr_modules()
    assert dp.read is not None
    ctx = open_stage(Path(dp.source))
    layer = ctx.stage.Flatten()
    stage = Usd.Stage.Open(layer)
    cache = UsdGeom.XformCache(Usd.TimeCode.Default())
    edit = UsdEdit()
    for name, lp in links.items():
        body = stage.GetPrimAtPath(dp.read.prims[name])
        world = ctx.L @ np.array(cache.GetLocalToWorldTransform(body), float).T
        set_body_mass(edit, ctx, body, dp.read.frames[name], world, lp.mass, np.asarray(lp.com, float), lp.inertia.matrix())
    for name, jd in joints.items():
        set_joint_dynamics(edit, ctx, stage.GetPrimAtPath(dp.read.prims[name]), jd.damping, jd.friction)
    out = folder / f"{file_names.file_stem(Path(dp.source).stem)}.usda"
    atomic.write_text(out, layer.ExportToString())
    return out
