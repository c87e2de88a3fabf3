"""The passive joint forces of a SAPIEN (PhysX) articulation as asset2sim verifies them, without importing SAPIEN:
:class:`PassiveJoints` (friction, damping and springs of the movable joints) and :class:`DeclaredPhysics` (a user's
own articulation given them). Used by :mod:`asset2sim.engines.physx_engine`, :mod:`asset2sim.apps.learn.maniskill` and
:func:`asset2sim.api.declare_physics`."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from asset2sim.engines.base import Spring

#: Damping (N*m*s/rad or N*s/m) of the zero-velocity drive carrying the passive
#: joint forces: a velocity constraint clamped at friction + damping * |qdot|.
FRICTION_DRIVE_DAMPING = 1.0e6


@dataclass
class PassiveJoints:
    """The passive forces of an articulation's movable joints, in the order of its ``active_joints``: Coulomb
    ``friction`` (N*m or N) and viscous ``damping`` (N*m*s/rad or N*s/m) act through a zero-velocity drive whose
    force limit is ``friction + damping * |qdot|`` (:meth:`force_limits`, set each step); springs
    (``stiffness`` N*m/rad or N/m about ``reference``) as joint forces (:meth:`joint_forces`).
    The one implementation of SAPIEN's passive joints: :class:`PhysXSession` and :mod:`asset2sim.apps.learn.maniskill` use it."""

    names: list[str]
    friction: np.ndarray
    damping: np.ndarray
    stiffness: np.ndarray
    reference: np.ndarray

    @classmethod
    def from_urdf(cls, urdf, springs: dict[str, Spring], names: list[str]) -> PassiveJoints:
        """From the ``<dynamics>`` of ``urdf``'s movable joints and ``springs`` (joint -> :class:`Spring`, the
        output's ``overlay.json``), for the joints ``names`` in the articulation's order (a name the URDF does
        not have as a movable joint keeps zeros)."""
        index = {n: i for i, n in enumerate(names)}
        out = cls(list(names), *(np.zeros(len(names)) for _ in range(4)))
        for pj in urdf.movable_joints:
            i = index.get(pj.name)
            if i is None:
                continue
            out.damping[i] = pj.damping
            out.friction[i] = pj.friction
            sp = springs.get(pj.name)
            if sp is not None:
                out.stiffness[i] = sp.stiffness
                out.reference[i] = sp.reference
        return out

    @property
    def sprung(self) -> bool:
        """Whether any joint has a spring (joint forces to apply each step)."""
        return bool(np.any(self.stiffness))

    @property
    def damped(self) -> bool:
        """Whether any joint has damping (force limits to update each step)."""
        return bool(np.any(self.damping))

    def configure(self, joints) -> None:
        """Give each of ``joints`` (``PhysxArticulationJoint``, this order) its passive drive: no PhysX joint
        friction, zero target velocity, damping :data:`FRICTION_DRIVE_DAMPING`, force limit the friction."""
        for i, joint in enumerate(joints):
            joint.set_friction(0.0)
            joint.set_drive_properties(0.0, FRICTION_DRIVE_DAMPING, float(self.friction[i]), "force")
            joint.set_drive_target(0.0)
            joint.set_drive_velocity_target(0.0)

    def force_limits(self, qvel: np.ndarray) -> np.ndarray:
        """The drives' force limits (n,) N*m or N at joint velocities ``qvel`` (n,) or (b, n): friction + damping * |qdot|."""
        return self.friction + self.damping * np.abs(np.asarray(qvel, float))

    def joint_forces(self, qpos: np.ndarray) -> np.ndarray:
        """The springs' joint forces (n,) or (b, n) N*m or N at joint positions ``qpos``: -k (q - q_ref)."""
        return -self.stiffness * (np.asarray(qpos, float) - self.reference)


class DeclaredPhysics:
    """A SAPIEN articulation the user built (SAPIEN's or ManiSkill's own URDF loader, which take ``<dynamics
    friction>`` as PhysX's unitless coefficient and damping as a drive) given the joints' declared physics: PhysX's
    joint friction set to 0 and each movable joint's :class:`PassiveJoints` drive configured (force limit = friction
    + damping * |qdot|, N*m or N), springs as joint forces. Call :meth:`before_step` before every ``scene.step()``
    (it re-sets the force limits at the joints' speeds and the springs' forces).

    Raises:
        ValueError: an active joint of ``art`` is not a movable joint of ``urdf`` (the articulation is not this
            file's), or the articulation has none.
    """

    def __init__(self, art, urdf, springs: dict[str, Spring]):
        joints = list(art.get_active_joints())
        names = [j.get_name() for j in joints]
        movable = {j.name for j in urdf.movable_joints}
        unknown = [n for n in names if n not in movable]
        if not names or unknown:
            raise ValueError(f"{urdf.path}: the articulation's joints {unknown or names} are not the file's movable joints")
        self.art = art
        self.joints = joints
        self.passive = PassiveJoints.from_urdf(urdf, springs, names)
        self.passive.configure(joints)

    def before_step(self) -> None:
        """For the next ``scene.step()``: each drive's force limit at the joint's speed and the springs' forces."""
        if self.passive.damped:
            limits = self.passive.force_limits(np.asarray(self.art.get_qvel(), float))
            for joint, limit in zip(self.joints, limits):
                joint.set_drive_properties(0.0, FRICTION_DRIVE_DAMPING, float(limit), "force")
        if self.passive.sprung:
            self.art.set_qf(self.passive.joint_forces(np.asarray(self.art.get_qpos(), float)).astype(np.float32))
