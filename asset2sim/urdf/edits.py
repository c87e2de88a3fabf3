"""In-place edits of a :class:`~asset2sim.urdf.model.UrdfModel`: :func:`scale_model` bakes in a
uniform scale, :func:`conform_limits` makes every ``<limit>`` fit its joint type.
"""

from __future__ import annotations

import math

import numpy as np

from asset2sim.urdf.model import MOVABLE, UrdfLimit, UrdfModel

def _scale_translation(m: np.ndarray, s: float) -> np.ndarray:
    out = np.array(m, float)
    out[:3, 3] *= s
    return out


#: ``effort`` (N*m or N) of a passive joint's ``<limit>``, which the URDF format requires (urdfdom and urdf_parser_py refuse
#: a revolute or prismatic limit without it): nothing drives the joint. Drake adds an actuator only for a non-zero effort
#: ("joints with an effort limit of zero are not actuated", multibody/parsing); MuJoCo's URDF import bounds actuator forces
#: (``actuatorfrcrange``) only for an effort above 0 and the model has no actuator; PyBullet stores it (``getJointInfo``)
#: without using it (PyBullet Quickstart Guide); SAPIEN 3's URDF loader does not read it; Gazebo clamps only the forces a
#: controller commands to it, and a passive part has none.
PASSIVE_EFFORT = 0.0
#: ``velocity`` (rad/s or m/s) of a passive joint's ``<limit>``, also required: no clamp on a part's own motion. Gazebo's
#: DART physics enforces joint velocity limits (gz-physics issue 216), and Drake's planners read them, so 0 would lock
#: the part; 100 is the speed Bullet's multibody already caps every joint at (``btMultiBody`` maximum coordinate
#: velocity, measured in PyBullet: a free wheel under any torque stops gaining speed at 100 rad/s), far above what a
#: handled part reaches (a door slammed shut turns a few rad/s); MuJoCo's URDF import and SAPIEN 3's loader ignore it.
PASSIVE_VELOCITY = 100.0


def conform_limits(model: UrdfModel, effort: float | None = None, velocity: float | None = None) -> list[str]:
    """Make every ``<limit>`` of ``model`` (in place) fit its joint: joints of types without limits lose theirs,
    revolute and prismatic joints get one; a missing ``effort`` (N*m or N) / ``velocity`` (rad/s or m/s) gets
    the value given, and stays missing with None (the default: a limit keeps what its file declared; URDF
    readers that need both, such as ROS's urdfdom, then need them added). Returns a note per dropped limit."""
    notes: list[str] = []
    for j in model.joints:
        # a <limit> means something on these (ROS URDF specification, wiki.ros.org/urdf/XML/joint: required for
        # revolute and prismatic joints; continuous joints use its effort and velocity)
        if j.type not in MOVABLE:
            if j.limit is not None:
                notes.append(f"joint {j.name!r} ({j.type}): <limit> dropped (a {j.type} joint has none)")
                j.limit = None
            continue
        if j.limit is None:
            if j.type == "continuous":
                continue
            j.limit = UrdfLimit()
        if j.limit.effort is None and effort is not None:
            j.limit.effort = float(effort)
        if j.limit.velocity is None and velocity is not None:
            j.limit.velocity = float(velocity)
    return notes


def scale_model(model: UrdfModel, s: float, *, geometry: bool = True, joints: bool = True,
                inertials: bool = True) -> UrdfModel:
    """Bake a uniform scale ``s`` (> 0) into ``model`` in place and return it:
    ``geometry`` origins and sizes, ``joints`` origins and prismatic limits,
    ``inertials`` COM and inertia (times ``s**2``; mass kept).

    Raises:
        ValueError: ``s`` is not a finite number > 0.
    """
    s = float(s)
    if not (math.isfinite(s) and s > 0):
        raise ValueError(f"scale must be a finite number > 0, got {s}")
    for link in model.links.values():
        for g in (link.visuals + link.collisions) if geometry else ():
            g.origin = _scale_translation(g.origin, s)
            if g.kind == "mesh":
                g.mesh_scale = g.scale * s
            if g.size is not None:
                g.size = np.asarray(g.size, float) * s
            for attr in ("radius", "length"):
                if getattr(g, attr) is not None:
                    setattr(g, attr, float(getattr(g, attr)) * s)
        if inertials and link.inertial is not None:
            link.inertial.origin = _scale_translation(link.inertial.origin, s)
            if link.inertial.inertia is not None:
                link.inertial.inertia = np.asarray(link.inertial.inertia, float) * s * s
    for j in model.joints if joints else ():
        j.origin = _scale_translation(j.origin, s)
        if j.type == "prismatic" and j.limit is not None:
            for attr in ("lower", "upper"):
                if getattr(j.limit, attr) is not None:
                    setattr(j.limit, attr, float(getattr(j.limit, attr)) * s)
    return model

