"""What a finalized Newton model holds, read back as
:class:`~asset2sim.engines.base.HeldPhysics`: a session's model
(:mod:`asset2sim.engines.newton_engine`) or a USD file loaded with Newton's
own importer. newton and warp are imported only inside the functions
(:func:`import_newton`), an optional extra.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from asset2sim.engines.base import HeldJoint, HeldLink, HeldPhysics, principal_moments

#: Newton's default limit magnitude for an unlimited DOF (``ModelBuilder``'s
#: 1e6) and above: read back as unlimited.
NEWTON_UNLIMITED = 1e6


def import_newton():
    """``(warp, newton)``, warp told to be quiet.

    Raises:
        ImportError: newton or warp is missing.
    """
    import warp as wp

    wp.config.quiet = True
    import newton

    return wp, newton


def held_physics_of_model(model, joint_q: np.ndarray, bodies: dict[str, int], dofs: dict[str, tuple[int, int]],
                          source: str) -> HeldPhysics:
    """Per-body and per-joint physics of a finalized ``newton.Model``:
    ``body_mass``, ``body_com`` (body frame = URDF link frame),
    ``body_inertia`` (3, 3) -> principal moments; per DOF
    ``joint_limit_lower/upper`` (Newton's +-1e6 or larger = unlimited -> inf),
    ``joint_target_kd`` (damping), ``joint_friction``, ``joint_target_ke``
    (stiffness) and ``joint_target_q`` (reference; None when ke = 0),
    position ``joint_q``. ``bodies``: link -> body index; ``dofs``: joint ->
    (q index, dof index)."""
    mass, com, inertia = model.body_mass.numpy(), model.body_com.numpy(), model.body_inertia.numpy()
    links = {n: HeldLink(mass=float(mass[i]), com=np.array(com[i], float), principal=principal_moments(inertia[i]))
             for n, i in bodies.items()}
    lo, hi = model.joint_limit_lower.numpy(), model.joint_limit_upper.numpy()
    kd, fr, ke = model.joint_target_kd.numpy(), model.joint_friction.numpy(), model.joint_target_ke.numpy()
    tp = model.joint_target_q.numpy()  # per coordinate, like joint_q
    joints = {}
    for n, (qa, da) in dofs.items():
        lo_v = float(lo[da]) if abs(float(lo[da])) < NEWTON_UNLIMITED else -np.inf
        hi_v = float(hi[da]) if abs(float(hi[da])) < NEWTON_UNLIMITED else np.inf
        k = float(ke[da])
        joints[n] = HeldJoint(lower=lo_v, upper=hi_v, damping=float(kd[da]), friction=float(fr[da]), stiffness=k,
                              reference=float(tp[qa]) if k != 0.0 else None, position=float(joint_q[qa]))
    how = {"mass, com, inertia": "Model.body_mass, body_com, body_inertia", "limits": "joint_limit_lower/upper",
           "damping, friction, spring": "joint_target_kd, joint_friction, joint_target_ke / joint_target_q",
           "position": "joint_q"}
    return HeldPhysics(engine="newton", source=source, links=links, joints=joints, how=how)


def held_physics_of_usd(path: Path, links: list[str] | None = None, joints: list[str] | None = None) -> HeldPhysics:
    """Load a USD written by ``asset2sim export --format usd`` with Newton's
    own importer (``ModelBuilder.add_usd``, finalize on the CPU) and read back
    what the model holds (:func:`held_physics_of_model`), by the URDF names
    the export stores in ``asset2sim:name`` (read with ``pxr``). ``links`` and
    ``joints`` are not needed (the names come from the file).

    Raises:
        ImportError: newton or usd-core is missing.
        ValueError: a body or joint of the model has no ``asset2sim:name``.
    """
    from pxr import Usd

    wp, newton = import_newton()
    stage = Usd.Stage.Open(str(path))
    names = {}
    for prim in stage.Traverse():
        a = prim.GetAttribute("asset2sim:name")
        if a and a.HasAuthoredValue():
            names[str(prim.GetPath())] = str(a.Get())
    b = newton.ModelBuilder()
    b.add_usd(str(path))
    model = b.finalize(device="cpu")
    body_labels = list(b.body_label)
    joint_labels = list(b.joint_label)
    bodies = {}
    for i, lab in enumerate(body_labels):
        if lab not in names:
            raise ValueError(f"{path}: Newton body {lab!r} has no asset2sim:name")
        bodies[names[lab]] = i
    qs, ds, jt = model.joint_q_start.numpy(), model.joint_qd_start.numpy(), model.joint_type.numpy()
    movable = {int(newton.JointType.REVOLUTE), int(newton.JointType.PRISMATIC)}
    dofs = {}
    for i, lab in enumerate(joint_labels):
        if int(jt[i]) in movable:
            if lab not in names:
                raise ValueError(f"{path}: Newton joint {lab!r} has no asset2sim:name")
            dofs[names[lab]] = (int(qs[i]), int(ds[i]))
    return held_physics_of_model(model, model.joint_q.numpy(), bodies, dofs, source=f"usd ({Path(path).name}, add_usd)")
