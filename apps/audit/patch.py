"""The audit's patch: the input written again in its own format with the patched physics, into a folder of its
own (the input is only read). URDF: the project's writer (:mod:`asset2sim.urdf`) and the meshes copied where
the URDF looks for them; the other formats: their physics writer in the format table
(:attr:`asset2sim.formats.Format.patch`). Only links and joints whose values changed are touched."""

from __future__ import annotations

from pathlib import Path

from asset2sim import atomic, file_names
from asset2sim.schemas.asset import AssetDescription
from asset2sim.schemas.audit import ValueVerdict
from asset2sim.schemas.overlay import JointDynamics, LinkPhysics, Overlay
from asset2sim.tasks.assemble import copied_meshes
from asset2sim.formats import FORMATS
from asset2sim.formats.staging import copy_named
from asset2sim.tasks.ingest.declared import DeclaredPhysics
from asset2sim.frames import translation_matrix
from asset2sim.urdf import UrdfDynamics, UrdfInertial, UrdfModel, read_urdf, write_urdf

__all__ = ["PATCH_DIR", "apply_physics", "changed", "write_patch"]

#: The patch's folder inside an asset's audit folder.
PATCH_DIR = "patch"


def changed(values: list[ValueVerdict], patched: Overlay) -> tuple[dict[str, LinkPhysics], dict[str, JointDynamics]]:
    """(links, joints) of ``patched`` that a verdict of ``values`` patches (``patched`` not None)."""
    wheres = {v.where for v in values if v.patched is not None}
    return ({n: lp for n, lp in patched.links.items() if f"link {n}" in wheres},
            {n: jd for n, jd in patched.joints.items() if f"joint {n}" in wheres})


def write_patch(asset: AssetDescription, dp: DeclaredPhysics, values: list[ValueVerdict], patched: Overlay, folder: Path) -> Path:
    """Write the patched asset into ``folder`` (created); returns the patched file.

    Raises:
        OutputError: a URDF mesh outside the asset folder, or an input file named like another copy.
        OSError: a file cannot be read or written.
        ImportError: the format's library (MuJoCo, usd-core) is not installed.
    """
    folder.mkdir(parents=True, exist_ok=True)
    links, joints = changed(values, patched)
    fmt = FORMATS.get(dp.format)
    if fmt is not None:
        children = {name: j.child for name, j in dp.joints.items()}
        return fmt.patch(dp.source, dp.read, children, links, joints, folder, asset.urdf_path)
    model = apply_physics(read_urdf(dp.source, mode="lenient"), links, joints)
    if asset.staged_from is not None:  # meshes the simulators could not load were converted: the originals copied
        for link in model.links.values():
            for g in (*link.visuals, *link.collisions):
                if g.kind == "mesh" and g.path is not None:
                    g.filename = copy_named(g.path, dp.source.parent, folder)
    else:
        copied_meshes.copy_meshes(asset, folder)
    out = folder / file_names.file_stem(dp.source.name)
    atomic.write_bytes(out, write_urdf(model, comment=f"patched by asset2sim audit from {dp.source.name}"))
    return out


def apply_physics(model: UrdfModel, links: dict[str, LinkPhysics], joints: dict[str, JointDynamics]) -> UrdfModel:
    """``model`` with the inertials of ``links`` (mass kg, COM m, inertia kg*m^2 in the link axes) and the damping
    and friction of ``joints``, changed in place; returned."""
    for name, lp in links.items():
        model.links[name].inertial = UrdfInertial(mass=lp.mass, origin=translation_matrix(lp.com), inertia=lp.inertia.matrix())
    for j in model.joints:
        if j.name in joints:
            jd = joints[j.name]
            j.dynamics = UrdfDynamics(damping=jd.damping, friction=jd.friction)
    return model
