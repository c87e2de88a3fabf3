"""URDF -> MJCF conversion under the SPEC's conventions, used by the MuJoCo
engine (:mod:`asset2sim.engines.mujoco_engine`) and by ``asset2sim export
--format mjcf`` (:mod:`asset2sim.tasks.assemble.export_mjcf`).

The conversion (:func:`urdf_to_mjcf`) starts from MuJoCo's own URDF import
(``MjSpec.from_string`` on a URDF carrying a ``<mujoco><compiler .../>``
extension, then ``to_xml``) and fixes what that import drops or changes; each
fix is listed in ``docs/design/simulators.md``:

- numbers: MuJoCo writes 6 significant digits; every pose, axis, range,
  inertial and dynamics value is rewritten at full precision from the URDF
  (after checking MuJoCo read the same value);
- inertials: written as ``fullinertia`` in the body frame, with
  ``inertiafromgeom="false"``, ``balanceinertia="false"`` and no mass/inertia
  bounds, so the compiled masses, COMs and tensors are the file's;
- collision shapes: one convex hull per OBJ group, as PyBullet builds them
  (MuJoCo would make one hull of the whole file); coplanar groups become
  2 mm slabs (MuJoCo refuses flat hulls);
- fixed joints: ``fusestatic="false"`` keeps every URDF link a body;
- self-collision: MuJoCo's filter works on groups of bodies welded by fixed
  joints (and on nothing welded to the world); explicit ``<pair>`` and
  ``<exclude>`` elements make the colliding pairs exactly PyBullet's
  (:func:`contact_policy`);
- friction: MuJoCo's soft friction would let held joints creep; the no-slip
  pass (with elliptic cones, so resting bodies do not walk) makes it hold;
- a free joint on the root, a ground plane, joint springs (``stiffness`` /
  ``springref``) from the overlay, contact friction as PyBullet combines it,
  the SPEC's timestep and gravity, and a keyframe ``initial`` with the
  initial state placed on the ground.

The steps of :func:`urdf_to_mjcf` (:mod:`.convert`), in order:
:func:`.meshes.mesh_assets` (one mesh per convex piece),
:func:`.importer.urdf_for_import` + :func:`.importer.import_skeleton`
(MuJoCo's import), then the rewrites of :mod:`.rewrite`:
:func:`~.rewrite.set_options`, :func:`~.rewrite.rename_meshes`,
:func:`~.rewrite.place_bodies`, per body :func:`~.rewrite.set_inertial`,
:func:`~.rewrite.set_joints`, :func:`~.rewrite.set_geoms`; then
:func:`.contacts.set_contacts`, :func:`~.rewrite.add_root_and_ground`,
:func:`.compiler.place_on_ground` and, with ``visuals``,
:func:`.visuals.add_visuals`. Shared names and number text live in
:mod:`.base`. mujoco is imported only inside the functions that need it
(:func:`.compiler.load_mujoco`).
"""

from __future__ import annotations

from asset2sim.engines.mjcf.base import (
    DERIVED_MESH_DIR,
    FREE_JOINT,
    GROUND,
    IMPRATIO,
    KEYFRAME,
    NOSLIP_ITERATIONS,
    MjcfError,
)
from asset2sim.engines.mjcf.compiler import lowest_point, mujoco_messages
from asset2sim.engines.mjcf.contacts import contact_policy
from asset2sim.engines.mjcf.convert import MjcfBuild, urdf_to_mjcf

__all__ = [
    "DERIVED_MESH_DIR",
    "FREE_JOINT",
    "GROUND",
    "IMPRATIO",
    "KEYFRAME",
    "NOSLIP_ITERATIONS",
    "MjcfBuild",
    "MjcfError",
    "contact_policy",
    "lowest_point",
    "mujoco_messages",
    "urdf_to_mjcf",
]
