"""URDF -> MJCF conversion under the SPEC's conventions (:func:`urdf_to_mjcf`),
for the MuJoCo engine and ``asset2sim export --format mjcf``: MuJoCo's own URDF
import, rewritten where it drops or changes something (each fix:
``docs/design/simulators.md``). mujoco is imported only where needed.
"""

from __future__ import annotations

from asset2sim.engines.mjcf.base import (ARMATURE, ARMATURE_FLOOR, CONE, DERIVED_MESH_DIR, FREE_JOINT, FRICTION_SOLIMP,
                                         GROUND, KEYFRAME, MjcfError, friction_solref, lowest_point, mujoco_messages)
from asset2sim.engines.mjcf.rewrite import contact_policy
from asset2sim.engines.mjcf.convert import MjcfBuild, urdf_to_mjcf

__all__ = ["ARMATURE", "ARMATURE_FLOOR", "CONE", "DERIVED_MESH_DIR", "FREE_JOINT", "FRICTION_SOLIMP", "GROUND", "KEYFRAME",
           "MjcfBuild", "MjcfError", "contact_policy", "friction_solref", "lowest_point", "mujoco_messages", "urdf_to_mjcf"]
