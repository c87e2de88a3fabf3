"""Planted defects: deliberately broken copies of an asset's physics, the
calibration set of a realism judge. Each copy keeps
the meshes (referenced by absolute path, never copied or modified) and changes
one thing a person would notice when the part is pushed and let go:

=====================  ===========================================================
``mass_x100``          every link's mass and inertia tensor x100
``zero_damping``       the pushed joint's damping and friction 0: it coasts on
``stuck_friction``     the pushed joint's friction 20x the drive's force limit: it does not move
``penetration_10mm``   the pushed part moved 10 mm into its parent
``scale_x3``           the whole object 3x its size (masses kept)
``slamming_spring``    a spring pulling the part shut, 0.8x the drive's limit at full
                       opening, with no damping or friction: it slams closed when let go
=====================  ===========================================================
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import Callable

import numpy as np

from asset2sim.atomic import write_bytes
from asset2sim.engines.base import SessionOptions, Spring, session_root_options
from asset2sim.engines.quiet import quiet_stdout
from asset2sim.engines.registry import open_session
from asset2sim.tasks.geometry.closed_state import ClosedState
from asset2sim.apps.realism.motion import PhysicsSide
from asset2sim.urdf import UrdfDynamics, UrdfModel, read_urdf, resolve_mesh_path, scale_model, write_urdf

#: Mass and inertia factor of ``mass_x100``.
MASS_FACTOR = 100.0
#: ``stuck_friction``: joint friction in multiples of the drive's force limit (far beyond it).
STUCK_FRICTION_FACTOR = 20.0
#: ``penetration_10mm``: how far the part is moved into its parent, m.
PENETRATION_DEPTH = 0.010
#: ``scale_x3``: the object's scale factor.
SCALE_FACTOR = 3.0
#: ``slamming_spring``: the spring's pull at full opening, in multiples of the drive's force limit
#: (below 1: the drive still opens the part most of the way).
SLAM_SHARE = 0.8


def _joint(model: UrdfModel, name: str):
    for j in model.joints:
        if j.name == name:
            return j
    raise KeyError(f"{model.path}: no joint named {name!r}")


def _mass_x100(model: UrdfModel, side: PhysicsSide, joint: str, closed: ClosedState, force: float) -> PhysicsSide:
    for link in model.links.values():
        ine = link.inertial
        if ine is not None and ine.mass is not None:
            ine.mass = float(ine.mass) * MASS_FACTOR
            if ine.inertia is not None:
                ine.inertia = np.asarray(ine.inertia, float) * MASS_FACTOR
    return side


def _zero_damping(model: UrdfModel, side: PhysicsSide, joint: str, closed: ClosedState, force: float) -> PhysicsSide:
    _joint(model, joint).dynamics = UrdfDynamics(damping=0.0, friction=0.0)
    return side


def _stuck_friction(model: UrdfModel, side: PhysicsSide, joint: str, closed: ClosedState, force: float) -> PhysicsSide:
    j = _joint(model, joint)
    j.dynamics = UrdfDynamics(damping=(j.dynamics.damping if j.dynamics else None), friction=STUCK_FRICTION_FACTOR * force)
    return side


def _penetration(model: UrdfModel, side: PhysicsSide, joint: str, closed: ClosedState, force: float) -> PhysicsSide:
    """Move the joint's origin (in the parent frame) 10 mm from the child's box center toward the parent's."""
    j = _joint(model, joint)
    with quiet_stdout():
        session = open_session("pybullet", side.urdf, SessionOptions(initial_state=dict(side.initial_state), gravity=False,
                                                                     **session_root_options(True)))
    try:
        (plo, phi), (clo, chi) = session.link_aabb(j.parent), session.link_aabb(j.child)
        _, R_parent = session.link_frame(j.parent)
    finally:
        session.close()
    d = (np.asarray(plo) + np.asarray(phi)) / 2 - (np.asarray(clo) + np.asarray(chi)) / 2
    n = float(np.linalg.norm(d))
    if n < 1e-9:
        raise ValueError(f"joint {joint!r}: the part and its parent share a center; no direction to push it in")
    j.origin = np.array(j.origin, float)
    j.origin[:3, 3] += np.asarray(R_parent, float).T @ (d / n) * PENETRATION_DEPTH
    return side


def _scale_x3(model: UrdfModel, side: PhysicsSide, joint: str, closed: ClosedState, force: float) -> PhysicsSide:
    scale_model(model, SCALE_FACTOR)
    prismatic = {j.name for j in model.joints if j.type == "prismatic"}
    return replace(side, scale=side.scale * SCALE_FACTOR,
                   initial_state={k: v * SCALE_FACTOR if k in prismatic else v for k, v in side.initial_state.items()})


def _slamming_spring(model: UrdfModel, side: PhysicsSide, joint: str, closed: ClosedState, force: float) -> PhysicsSide:
    spring = Spring(stiffness=float(SLAM_SHARE * force / closed.open_range), reference=float(closed.q_closed))
    return replace(_zero_damping(model, side, joint, closed, force), springs={**side.springs, joint: spring})


#: Defect name -> what it does to the model (in place) and the side (returned).
DEFECTS: dict[str, Callable[[UrdfModel, PhysicsSide, str, ClosedState, float], PhysicsSide]] = {
    "mass_x100": _mass_x100,
    "zero_damping": _zero_damping,
    "stuck_friction": _stuck_friction,
    "penetration_10mm": _penetration,
    "scale_x3": _scale_x3,
    "slamming_spring": _slamming_spring,
}


def plant_defect(side: PhysicsSide, defect: str, joint: str, closed: ClosedState, force_limit: float, folder: Path | str) -> PhysicsSide:
    """A broken copy of ``side`` with ``defect`` (a key of :data:`DEFECTS`) on ``joint`` (``closed``: its closed end,
    rad or m; ``force_limit``: the pair's drive limit, N*m or N), its URDF written to ``folder/mobility.urdf`` with
    absolute mesh paths; ``side``'s files are not touched. The returned side's method is ``defect:<name>``.

    Raises:
        KeyError: an unknown defect or joint. ValueError: a defect that cannot be planted on this joint.
        UrdfError / OSError: the side's URDF cannot be read or the copy written.
    """
    if defect not in DEFECTS:
        raise KeyError(f"unknown defect {defect!r}; known: {sorted(DEFECTS)}")
    src = Path(side.urdf).resolve()
    model = read_urdf(src, mode="lenient")
    for link in model.links.values():  # every mesh by absolute path: the copy lives elsewhere
        for g in [*link.visuals, *link.collisions]:
            if g.kind == "mesh" and g.filename:
                g.filename = str(resolve_mesh_path(g.filename, src.parent).resolve())
    broken = DEFECTS[defect](model, side, joint, closed, float(force_limit))
    dst = Path(folder) / "mobility.urdf"
    write_bytes(dst, write_urdf(model, comment=f" asset2sim realism calibration: planted defect {defect} "))
    return replace(broken, method=f"defect:{defect}", urdf=dst)
