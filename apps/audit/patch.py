"""The audit's patch: the input written again in its own format with the patched physics, into a folder of its
own (the input is only read). URDF: the project's writer (:mod:`asset2sim.urdf`) and the meshes copied where
the URDF looks for them; MJCF: MuJoCo's own writer (``MjSpec.to_xml``) with its mesh and texture files copied
beside it; OpenUSD: the stage flattened into one ``.usda`` layer with the UsdPhysics mass and drive
attributes changed (``usd-core``). Only links and joints whose values changed are touched."""

from __future__ import annotations

import hashlib
import os
from pathlib import Path

import numpy as np

from asset2sim import atomic, file_names
from asset2sim.schemas.asset import AssetDescription
from asset2sim.schemas.audit import ValueVerdict
from asset2sim.schemas.overlay import JointDynamics, LinkPhysics, Overlay
from asset2sim.tasks.assemble import copied_meshes
from asset2sim.apps.audit import patch_usd
from asset2sim.engines.mjcf.base import load_mujoco, mujoco_messages
from asset2sim.tasks.ingest.declared import DeclaredPhysics
from asset2sim.tasks.ingest import mjcf_files
from asset2sim.tasks.ingest.mjcf_files import compile_mjcf, gather_mjcf
from asset2sim.tasks.ingest.staged import StagingError
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
        ImportError: MuJoCo (MJCF) or usd-core (USD) is not installed.
    """
    folder.mkdir(parents=True, exist_ok=True)
    links, joints = changed(values, patched)
    if dp.format == "mjcf":
        return _write_mjcf(dp, links, joints, folder, mjcf_files.staged_sources(asset.urdf_path))
    if dp.format == "usd":
        return patch_usd.write_usd(dp, links, joints, folder)
    return _write_urdf(asset, dp.source, links, joints, folder)


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


def _write_urdf(asset: AssetDescription, source: Path, links: dict[str, LinkPhysics], joints: dict[str, JointDynamics], folder: Path) -> Path:
    model = apply_physics(read_urdf(source, mode="lenient"), links, joints)
    if asset.staged_from is not None:  # meshes the simulators could not load were converted: the originals copied
        for link in model.links.values():
            for g in (*link.visuals, *link.collisions):
                if g.kind == "mesh" and g.path is not None:
                    g.filename = _copy_named(g.path, source.parent, folder)
        out = folder / file_names.file_stem(source.name)
        atomic.write_bytes(out, write_urdf(model, comment=f"patched by asset2sim audit from {source.name}"))
        return out
    copied_meshes.copy_meshes(asset, folder)
    out = folder / file_names.file_stem(source.name)
    atomic.write_bytes(out, write_urdf(model, comment=f"patched by asset2sim audit from {source.name}"))
    return out


def _copy_named(src: Path, base: Path, folder: Path, data: bytes | None = None) -> str:
    """Copy an asset file the MJCF or URDF names into ``folder``: at its path relative to ``base`` (the file's folder)
    when inside it, else under ``assets/`` by a safe name; ``data``: its bytes as already read (then ``src`` only names
    it); returns the relative POSIX path written."""
    real = Path(os.path.realpath(src)) if data is None else Path(src)
    try:
        rel = real.relative_to(Path(os.path.realpath(base))).as_posix()
    except ValueError:
        digest = hashlib.sha256(str(real).encode()).hexdigest()[:8]
        rel = f"assets/{file_names.file_stem(real.stem)}-{digest}{real.suffix.lower()}"
    target = file_names.join_inside(folder, rel)
    if data is not None:
        atomic.write_bytes(target, data)  # the bytes the reader policy read: the input is not opened again
    else:
        atomic.copy_file(real, target)  # its folders made by the atomic writer, after the output's guard
    return rel


def _write_mjcf(dp: DeclaredPhysics, links: dict[str, LinkPhysics], joints: dict[str, JointDynamics], folder: Path,
                read: tuple | None = None) -> Path:
    """The patched MJCF in ``folder``, compiled from ``read`` (the sources staged when the audit read the input,
    :func:`~asset2sim.tasks.ingest.mjcf_files.staged_sources`; None: gathered once here under the reader policy),
    its meshes and textures written from those bytes; the input's paths are not opened again."""
    mujoco = load_mujoco()
    source = dp.source
    sources = read[0] if read is not None else gather_mjcf(source)  # only checked files inside the input's tree
    spec, model, _ = compile_mjcf(sources)
    base = source.parent
    meshdir, texdir = Path(spec.meshdir or ""), Path(spec.texturedir or "")
    for items, sub in ((spec.meshes, meshdir), (spec.hfields, meshdir), (spec.skins, meshdir), (spec.textures, texdir)):
        for item in items:
            if getattr(item, "file", ""):
                named = os.path.normpath(os.path.join(os.path.abspath(base), sub, item.file))
                real = sources.real.get(named)
                if real is None:  # gather_mjcf checked every file attribute; nothing else is copied
                    raise StagingError(f"{source}: {item.file!r} was not checked by the reader policy; not copied")
                item.file = _copy_named(real, base, folder, data=sources.files[named])
    spec.meshdir = spec.texturedir = ""
    spec.modelfiledir = str(folder)  # MuJoCo resolves the copies' relative paths from the patch's folder
    if spec.compiler.inertiafromgeom == mujoco.mjtInertiaFromGeom.mjINERTIAFROMGEOM_TRUE:  # else explicit inertials would be ignored
        spec.compiler.inertiafromgeom = mujoco.mjtInertiaFromGeom.mjINERTIAFROMGEOM_AUTO
    bodies = {(model.body(b).name or f"body_{b}"): b for b in range(1, model.nbody)}
    for name, lp in links.items():
        b = bodies[name]
        body = spec.bodies[b]
        offset = _joint_offset(model, b)  # the link frame is the body frame moved to its joint's pos
        I = lp.inertia.matrix()
        body.explicitinertial = True
        body.mass = lp.mass
        body.ipos = np.asarray(lp.com, float) + offset
        body.iquat = [1.0, 0.0, 0.0, 0.0]
        body.inertia = [0.0, 0.0, 0.0]  # a diagonal inertia and a full one cannot both be given
        body.fullinertia = [I[0, 0], I[1, 1], I[2, 2], I[0, 1], I[0, 2], I[1, 2]]
    for name, jd in joints.items():
        joint = next(j for j in spec.bodies[bodies[dp.joints[name].child]].joints if j.type != mujoco.mjtJoint.mjJNT_FREE)
        damping = np.array(joint.damping, float)
        damping[0] = jd.damping
        joint.damping = damping
        joint.frictionloss = jd.friction
    with mujoco_messages():
        spec.compile()
        xml = spec.to_xml()
    out = folder / file_names.file_stem(source.name)
    atomic.write_text(out, xml)
    return out


def _joint_offset(model, b: int) -> np.ndarray:
    """(3,) m: the position of body ``b``'s hinge or slide joint in the body frame (0 without one)."""
    n, adr = int(model.body_jntnum[b]), int(model.body_jntadr[b])
    return np.asarray(model.jnt_pos[adr], float) if n == 1 and model.jnt_type[adr] in (2, 3) else np.zeros(3)
