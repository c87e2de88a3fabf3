"""The URDF -> MJCF conversion (:func:`urdf_to_mjcf`) as named steps over
MuJoCo's own import; see :mod:`asset2sim.engines.mjcf` for what each step
fixes."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from lxml import etree

from asset2sim.engines.base import Spring
from asset2sim.engines.loading import CollisionPiece, collision_pieces, read_urdf
from asset2sim.engines.mjcf.base import KEYFRAME, MjcfError, vec_text
from asset2sim.engines.mjcf.compiler import compile_xml, load_mujoco, place_on_ground
from asset2sim.engines.mjcf.contacts import set_contacts
from asset2sim.engines.mjcf.importer import import_skeleton, urdf_for_import
from asset2sim.engines.mjcf.meshes import MeshAssets, mesh_assets
from asset2sim.engines.mjcf.rewrite import (
    add_root_and_ground,
    place_bodies,
    rename_meshes,
    set_geoms,
    set_inertial,
    set_joints,
    set_options,
)
from asset2sim.engines.mjcf.visuals import add_visuals
from asset2sim.schemas.config import SimConventions
from asset2sim.urdf import UrdfModel


@dataclass
class MjcfBuild:
    """An MJCF document and what it needs.

    ``xml`` the MJCF text; ``derived_meshes`` relative path (from ``meshdir``)
    -> OBJ bytes of convex pieces the exporter must write; ``mesh_files``
    relative path -> absolute source file of meshes referenced as they are;
    ``initial_qpos`` (nq,) of the keyframe; ``joint_names`` movable joints in
    qpos order; ``notes`` what the conversion changed for this asset;
    ``root_height`` m the root was lifted to touch the ground.
    """

    xml: str
    derived_meshes: dict[str, bytes]
    mesh_files: dict[str, Path]
    initial_qpos: np.ndarray
    joint_names: list[str]
    notes: list[str] = field(default_factory=list)
    root_height: float = 0.0

    def assets(self) -> dict[str, bytes]:
        """Every mesh as bytes, keyed as the MJCF names them (for in-memory compiles)."""
        out = {k: p.read_bytes() for k, p in self.mesh_files.items()}
        out.update(self.derived_meshes)
        return out


def urdf_to_mjcf(
    urdf_path: Path | str,
    *,
    initial_state: dict[str, float] | None = None,
    springs: dict[str, Spring] | None = None,
    missing_inertial: str = "massless",
    fixed_base: bool = False,
    ground: bool = True,
    gravity: bool = True,
    conventions: SimConventions | None = None,
    mesh_root: Path | None = None,
    meshdir: str = ".",
    visuals: bool = False,
) -> MjcfBuild:
    """Convert a URDF into MJCF under the SPEC's conventions.

    Args:
        initial_state: joint -> rad or m, stored in the keyframe ``initial``
            (other joints at 0).
        springs: joint -> :class:`Spring` (stiffness N*m/rad or N/m, reference
            rad or m), written as joint ``stiffness`` and ``springref``.
        missing_inertial: what a link without ``<inertial>`` weighs:
            ``"massless"`` (the file's truth; MuJoCo accepts it only for links
            welded to a massive one) or ``"bullet"`` (PyBullet's 1 kg and unit
            inertia, for parity with the reference engine).
        fixed_base: no free joint; the root stays at the world origin.
        ground / gravity: add the ground plane / gravity -9.81 m/s^2 along z.
        mesh_root: folder the MJCF's ``meshdir`` points at; meshes of the URDF
            inside it are referenced relative to it (default: the URDF's folder).
        meshdir: the ``meshdir`` written in the MJCF (relative to the MJCF file).
        visuals: also write the URDF's visual meshes as non-colliding geoms
            (group 2, colour from the MTL ``Kd``; collision geoms go to group 3).

    Returns:
        :class:`MjcfBuild`.

    Raises:
        UrdfError: the URDF cannot be read.
        MjcfError: MuJoCo cannot import or compile the result, or read a value
            differently from the URDF.
        ValueError: ``missing_inertial`` is not one of the two policies, or an
            initial state names an unknown joint.
    """
    mujoco = load_mujoco()
    if missing_inertial not in ("massless", "bullet"):
        raise ValueError(f"missing_inertial must be 'massless' or 'bullet', not {missing_inertial!r}")
    conv = conventions or SimConventions()
    urdf_path = Path(urdf_path)
    model = read_urdf(urdf_path)
    initial_state = dict(initial_state or {})
    springs = dict(springs or {})
    movable = _movable_joints(model, initial_state, urdf_path)
    mesh_root = Path(mesh_root) if mesh_root is not None else urdf_path.parent
    pieces, notes = collision_pieces(model)
    meshes = mesh_assets(pieces, mesh_root)
    final_assets = {rel: meshes.import_assets[v] for v, (rel, _) in meshes.virtual.items()}

    urdf_text = urdf_for_import(model, pieces, meshes.names, meshes.scales, missing_inertial)
    spec, root = import_skeleton(urdf_text, meshes.import_assets, urdf_path, notes)
    set_options(root, conv, gravity, meshdir)
    file_to_mesh, used = rename_meshes(root, meshes.virtual, urdf_path)
    asset_el = root.find("asset")
    if asset_el is None:
        asset_el = etree.SubElement(root, "asset")
    worldbody = root.find("worldbody")
    bodies = _rewrite_bodies(
        worldbody, model, spec, pieces, meshes, file_to_mesh, springs, missing_inertial, visuals, movable, urdf_path, notes
    )
    set_contacts(root, model, pieces, fixed_base, notes)
    root_body = bodies[model.root]
    add_root_and_ground(root_body, worldbody, fixed_base, ground)

    compiled, qpos, height = place_on_ground(root, root_body, final_assets, initial_state, fixed_base, urdf_path, notes)
    if visuals:  # after placement: visual meshes never collide, and cost compile time
        for b in worldbody.iter("body"):
            add_visuals(b, model.links[b.get("name")], mesh_root, asset_el, meshes.files, final_assets, used, notes)
    xml = _with_keyframe(root, qpos)
    if visuals:  # the visual meshes were not in ``compiled``: the file as written must compile too
        compile_xml(xml, final_assets, urdf_path)
    # Only the root's pose and the keyframe changed since ``compiled``.
    order = [mujoco.mj_id2name(compiled, mujoco.mjtObj.mjOBJ_JOINT, j) for j in range(compiled.njnt)]
    joint_names = [n for n in order if n in movable]
    return MjcfBuild(
        xml=xml,
        derived_meshes=meshes.derived,
        mesh_files=meshes.files,
        initial_qpos=qpos,
        joint_names=joint_names,
        notes=notes,
        root_height=height,
    )


def _movable_joints(model: UrdfModel, initial_state: dict[str, float], urdf_path: Path) -> dict:
    """Movable joints of ``model`` by name.

    Raises:
        ValueError: ``initial_state`` names a joint that is not one of them.
    """
    movable = {j.name: j for j in model.movable_joints}
    unknown = sorted(set(initial_state) - set(movable))
    if unknown:
        raise ValueError(f"{urdf_path}: initial state names joints that are not movable joints of the file: {unknown}")
    return movable


def _rewrite_bodies(
    worldbody,
    model: UrdfModel,
    spec,
    pieces: dict[str, list[CollisionPiece]],
    meshes: MeshAssets,
    file_to_mesh: dict[str, str],
    springs: dict[str, Spring],
    missing_inertial: str,
    visuals: bool,
    movable: dict,
    urdf_path: Path,
    notes: list[str],
) -> dict:
    """Rewrite every body of the import (pose, inertial, joint, collision
    geoms) from the URDF; returns body name -> element.

    Raises:
        MjcfError: the import's bodies or movable joints are not the URDF's,
            or one of the per-body checks fails.
    """
    bodies = {b.get("name"): b for b in worldbody.iter("body")}
    if set(bodies) != set(model.links):
        raise MjcfError(f"{urdf_path}: MuJoCo's import has bodies {sorted(bodies)}, the URDF links {sorted(model.links)}")
    place_bodies(model, spec, bodies, urdf_path)
    names_in_qpos: list[str] = []
    for b in worldbody.iter("body"):
        link = model.links[b.get("name")]
        set_inertial(b, link, missing_inertial, notes)
        names_in_qpos += set_joints(b, link, model, spec, springs, urdf_path)
        geom_mesh = {key: file_to_mesh[v] for key, v in meshes.names.items() if key[0] == link.name}
        set_geoms(b, link, model, pieces[link.name], geom_mesh, visuals, urdf_path)
    if set(names_in_qpos) != set(movable):
        raise MjcfError(f"{urdf_path}: MuJoCo's import has joints {names_in_qpos}, the URDF {sorted(movable)}")
    return bodies


def _with_keyframe(root, qpos: np.ndarray) -> str:
    """The MJCF text of ``root`` with the keyframe :data:`KEYFRAME` holding
    ``qpos`` (nq,), indented by two spaces."""
    key = etree.SubElement(etree.SubElement(root, "keyframe"), "key", name=KEYFRAME)
    key.set("qpos", vec_text(qpos))
    etree.indent(root, space="  ")
    return etree.tostring(root, encoding="unicode")
