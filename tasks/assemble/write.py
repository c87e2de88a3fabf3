"""Writer: the files of the SPEC's output folder.

``mobility.urdf`` with the scale baked in, the overlay's inertials and joint
dynamics; ``initial_state.json``, ``overlay.json``, ``semantics.txt`` (the
input's part labels, when it had any) and the meshes (with MTL files and
textures) under their relative paths. Floats at full precision; every file
written atomically; the input folder is never written.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from asset2sim import atomic, frames, urdf
from asset2sim.schemas.asset import AssetDescription
from asset2sim.schemas.overlay import Overlay, RootMount
from asset2sim.tasks.ingest import partnet_mobility
from asset2sim.tasks.assemble import collision_geometry
from asset2sim.tasks.assemble.copied_meshes import copy_meshes, taken_paths
from asset2sim.tasks.interpret.part_priors import push_buttons
from asset2sim.tasks.synthesize.validate_overlay import max_density
from asset2sim.output_folder import OVERLAY_NAME, STATE_NAME, URDF_NAME, OutputError, check_location
from asset2sim.prior_tables import load_priors
from asset2sim.refined_asset import ROOT_KEY, read_root  # noqa: F401  read_root: the measuring stages read it from here


@dataclass
class OutputPaths:
    """Files of one output folder."""

    root: Path
    urdf: Path
    initial_state: Path
    overlay: Path
    semantics: Path | None = None  # None when the input had no part labels
    collision_notes: list[str] = field(default_factory=list)  # what the writer's convex collision pieces changed
    urdf_bytes: bytes = b""  # the bytes written to ``urdf``


def collision_folder(asset: AssetDescription) -> str:
    """Output folder name for generated collision pieces that no copied input file uses: ``collision``,
    else ``collision_1``, ``collision_2`` ..."""
    taken = taken_paths(asset)
    for i in range(10_000):
        name = "collision" if i == 0 else f"collision_{i}"
        if not any(t == name or t.startswith(name + "/") for t in taken):
            return name
    raise OutputError(f"{asset.source_dir}: no free folder name for collision pieces", "OUTPUT_NAME_CONFLICT", asset.source_dir)


def build_urdf(asset: AssetDescription, overlay: Overlay, collision_overrides: dict | None = None,
               root_rotation: np.ndarray | None = None, collision_out: tuple[Path, dict[str, float]] | None = None,
               collision_notes: list[str] | None = None, open_containers: bool = False) -> bytes:
    """The revised URDF (bytes, UTF-8) for ``overlay`` applied to ``asset``: scale baked in, the overlay's
    inertial on every link that has one, ``<dynamics>`` and a complete ``<limit>`` (effort and velocity 1000
    when absent) on every movable joint, an explicit ``<axis>`` on every joint and a comment pointing to
    ``initial_state.json`` and ``overlay.json``; the input's ``<contact>``, ``<mimic>``, ``<calibration>``,
    ``<safety_controller>`` and vendor extensions are left out.

    ``collision_overrides``: link -> list of :class:`asset2sim.tasks.state.collision.CollisionPiece`
    replacing the link's mesh collisions (paths relative to the output). ``root_rotation``: (3, 3)
    rotation baked into the root link's geometry and the joints hanging from it. ``collision_out``:
    (output folder, initial state): the mesh collisions become the convex pieces of
    :func:`asset2sim.tasks.assemble.collision_geometry.convex_collisions`, written into the folder (a
    free-standing object's footprint levelled, on its category's levelling feet where it has them; with ``open_containers`` a container decomposed so that its
    inside stays open); their notes are appended to ``collision_notes`` when given.

    Raises:
        OutputError: the overlay lacks an entry for a link with geometry or a
            movable joint (validate the overlay first).
        UrdfError: the input URDF cannot be read.
    """
    s = float(overlay.scale)
    model = urdf.read_urdf(asset.urdf_path, mode="lenient")
    model.extensions = []
    model.name = model.name or ""
    # every link's <contact> dropped, the mesh collisions of each link in the overrides its pieces, its <inertial> the
    # overlay's (OutputError when it lacks a link that has geometry)
    for link in model.links.values():
        link.contact = {}
        pieces = (collision_overrides or {}).get(link.name)
        if pieces:
            link.collisions = [c for c in link.collisions if c.kind != "mesh"] + [
                urdf.UrdfGeometry(kind="mesh", origin=frames.pose_matrix(piece.source.origin.xyz, piece.source.origin.rpy),
                                  filename=piece.filename, mesh_scale=np.asarray(piece.source.scale, float)) for piece in pieces]
        lp = overlay.links.get(link.name)
        if lp is None and (link.visuals or link.collisions):
            raise OutputError(f"overlay has no mass/inertia for link {link.name!r} (validate the overlay first)")
        link.inertial = None if lp is None else urdf.UrdfInertial(mass=float(lp.mass), origin=frames.translation_matrix(lp.com),
                                                                  inertia=lp.inertia.matrix())
    urdf.scale_model(model, s, joints=False, inertials=False)
    if root_rotation is not None and not np.allclose(root_rotation, np.eye(3)):
        # baked into the root link's geometry and inertial and the joints hanging from it
        T = frames.rigid_matrix(root_rotation)
        for joint in model.children(asset.root_link):
            joint.origin = T @ joint.origin
        root = model.links.get(asset.root_link)
        if root is not None:
            for elem in root.visuals + root.collisions:
                elem.origin = T @ elem.origin
            if root.inertial is not None:
                root.inertial.origin = T @ root.inertial.origin
    urdf.scale_model(model, s, geometry=False, inertials=False)
    # every joint without <mimic>, <calibration>, <safety_controller> and with an explicit axis; every movable one with a
    # <limit> and the overlay's <dynamics> and limits (OutputError when it lacks one); the joints the asset model holds
    # (``partnet_mobility.held_bodies``, fixed in the description) written fixed at 0
    fixed = {j.name for j in asset.joints if j.type == "fixed"}
    for joint in model.joints:
        joint.mimic = joint.calibration = joint.safety_controller = None
        if joint.axis_xyz is None:
            joint.axis_xyz = np.array([1.0, 0.0, 0.0])
        if joint.name in fixed and joint.type in urdf.MOVABLE:
            joint.type, joint.limit, joint.dynamics = "fixed", None, None
        if joint.type in urdf.MOVABLE:
            dyn = overlay.joints.get(joint.name)
            if dyn is None:
                raise OutputError(f"overlay has no dynamics for joint {joint.name!r} (validate the overlay first)")
            joint.dynamics = urdf.UrdfDynamics(damping=float(dyn.damping), friction=float(dyn.friction))
            if joint.limit is None:  # no effort or velocity invented (the input declared none)
                joint.limit = urdf.UrdfLimit()
            if dyn.lower is not None:  # clipped to what the geometry allows (tasks.geometry.limits)
                joint.limit.lower = float(dyn.lower)
            if dyn.upper is not None:
                joint.limit.upper = float(dyn.upper)
    urdf.conform_limits(model, effort=urdf.PASSIVE_EFFORT, velocity=urdf.PASSIVE_VELOCITY)  # no <limit> on fixed joints; a passive part's effort and velocity where the input declared none
    if collision_out is not None:
        free = overlay.mounting is None or not overlay.mounting.fixed  # a mounted root does not stand on its footprint
        densest = {name: max_density(lp) for name, lp in overlay.links.items()}
        prior = load_priors().categories.get(overlay.category or "")
        notes = collision_geometry.convex_collisions(model, collision_out[0], collision_folder(asset), collision_out[1], level=free,
                                                     feet=prior.levelling_feet_m if prior is not None else None,
                                                     open_containers=open_containers, max_density=densest,
                                                     pushed=push_buttons(asset, overlay.category))
        if collision_notes is not None:
            collision_notes.extend(notes)
    # the comment: the scale baked in, where the state, the springs and the notes are, how the root is held
    springs = sorted(n for n, d in overlay.joints.items() if d.stiffness > 0)
    return urdf.write_urdf(model, comment=(
        f" Written by asset2sim. Uniform scale {s!r} is baked in (mesh scale, origins, prismatic limits, inertials); "
        f"load at scale 1.0. Initial joint positions (rad / m): see {STATE_NAME} (URDF has no field for them). "
        f"Joint stiffness, spring references and the reasoning notes: see {OVERLAY_NAME}"
        + (f"; springs on {', '.join(springs)}" if springs else "")
        + f". Joint limits carry effort=\"{urdf.PASSIVE_EFFORT:g}\" velocity=\"{urdf.PASSIVE_VELOCITY:g}\" "
        "where the input declared none, "
        "as the URDF format requires: a passive part, no actuator (Drake adds none for effort 0; MuJoCo, PyBullet and "
        "SAPIEN do not drive a joint from them) and no speed clamp below the one Bullet already applies. "
        + root_sentence(overlay.mounting)))


def write_output(asset: AssetDescription, overlay: Overlay, out_dir: Path, initial_state: dict[str, float], *, copy: bool = True,
                 collision_overrides: dict | None = None, root_rotation: np.ndarray | None = None,
                 open_containers: bool = False) -> OutputPaths:
    """Write (or rewrite) the output folder: meshes, ``mobility.urdf``, ``initial_state.json``,
    ``overlay.json`` and (when the input labelled parts) ``semantics.txt``.

    Args:
        initial_state: joint -> position in output units (rad or m).
        copy: copy the meshes and write ``semantics.txt``.
        collision_overrides, root_rotation, open_containers: see :func:`build_urdf`.

    Raises:
        OutputError: output folder inside the input, or an incomplete overlay.
    """
    out = check_location(asset.source_dir, out_dir)
    out.mkdir(parents=True, exist_ok=True)
    labels = part_labels(asset)
    sem = out / partnet_mobility.SEMANTICS_NAME
    if copy:  # what comes from the input, once: later writes change only the dynamics and the state
        copy_meshes(asset, out)
        if labels:
            atomic.write_bytes(sem, partnet_mobility.format_semantics(labels).encode())
    notes: list[str] = []
    data = build_urdf(asset, overlay, collision_overrides, root_rotation, (out, initial_state), notes, open_containers)
    urdf = atomic.write_bytes(out / URDF_NAME, data)
    state = atomic.write_json(out / STATE_NAME, {
        "initial_joint_positions": {k: float(v) for k, v in initial_state.items()},
        ROOT_KEY: root_record(overlay.mounting),
    })
    ovl = atomic.write_json(out / OVERLAY_NAME, overlay.model_dump(mode="json"))
    return OutputPaths(root=out, urdf=urdf, initial_state=state, overlay=ovl, semantics=sem if labels else None,
                       collision_notes=notes, urdf_bytes=data)


def part_labels(asset: AssetDescription) -> dict[str, partnet_mobility.Semantics]:
    """link -> (joint kind, part label) of the asset's labelled links, in link order; links whose name or
    label the format cannot express (whitespace) are left out."""
    return {ln.name: partnet_mobility.Semantics(ln.semantic_joint, ln.semantic_label) for ln in asset.links
            if ln.semantic_label and ln.semantic_joint and ln.name.split() == [ln.name]
            and ln.semantic_joint.split() == [ln.semantic_joint]}


def root_record(mount: RootMount | None) -> dict:
    """The ``"root"`` entry of ``initial_state.json`` for a mounting (None: free-standing):
    ``{"fixed": bool, "mounting": kind, "pose": ..., "source": ...}``. A fixed root's ``pose`` is the root
    link frame in the world, ``{"xyz": [0, 0, 0] m, "quat_xyzw": [0, 0, 0, 1]}``; a free root's is null
    (the SPEC rests it on the ground at z = 0)."""
    mount = mount or RootMount()
    return {"fixed": bool(mount.fixed), "mounting": mount.kind,
            "pose": {"xyz": [0.0, 0.0, 0.0], "quat_xyzw": [0.0, 0.0, 0.0, 1.0]} if mount.fixed else None, "source": mount.source}


def root_sentence(mount: RootMount | None) -> str:
    """The URDF comment's sentence on how the root is held."""
    mount = mount or RootMount()
    if mount.fixed:
        return (f"Mounted ({mount.kind}): load with a FIXED root link at the file's origin "
                f"(PyBullet useFixedBase, SAPIEN fix_root_link, MJCF without a free joint); see {STATE_NAME} \"{ROOT_KEY}\". ")
    return f"Free-standing: root free, resting on the ground; see {STATE_NAME} \"{ROOT_KEY}\". "
