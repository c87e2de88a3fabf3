"""The scripted motion of a realism pair (``push_release``): one joint pushed
toward open by a force-limited velocity drive, then let go, with gravity on
and the root as the asset declares it (mounted, or free on the ground). It is
what shows the physics a person judges: how heavy the part feels (how fast the
drive's force moves it), how it coasts and stops once released (damping,
friction), whether a spring pulls it back and how hard, and whether the body
slides or tips.

Both sides of a pair get the same command: the same target speed and the same
force limit (side ``a``'s joint sweep limit, :func:`asset2sim.tasks.check.sweep.effort_limit`:
twice the moving part's weight at its lever plus its spring over the range, and side ``a``'s joint
friction; each side's own friction is a load within it), so only the physics differs.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from asset2sim.engines.base import SessionOptions, Spring, session_root_options
from asset2sim.engines.quiet import quiet_stdout
from asset2sim.engines.registry import open_session
from asset2sim.schemas.config import SimConventions
from asset2sim.tasks.check.stroke import run_stroke
from asset2sim.tasks.check.sweep import SweepConfig, effort_limit
from asset2sim.tasks.evaluation.clips import Trajectory
from asset2sim.engines.source import SimObject
from asset2sim.refined_asset import RefinedAsset
from asset2sim.tasks.evaluation.folder_reading import EvaluationError, sim_object
from asset2sim.tasks.geometry.closed_state import ClosedState
from asset2sim.tasks.geometry.limits import subtrees
from asset2sim.tasks.ingest import partnet_mobility
from asset2sim.tasks.ingest.errors import AssetError
from asset2sim.urdf import model_of


@dataclass(frozen=True)
class PushReleaseConfig:
    """The push-and-release script (units on every field)."""

    push_time: float = 0.5
    """time the drive pushes toward open, s (half a traverse: the part is let go mid-range, moving)"""
    release_time: float = 2.0
    """time the part is left to itself after the push, s"""
    traverse_time: float = 1.0
    """target speed = open range / traverse_time (rad/s or m/s): a full traverse in this time"""
    record_every: int = 4
    """engine steps between recorded samples (4 at 240 Hz: 60 samples per s)"""


@dataclass(frozen=True)
class PhysicsSide:
    """One side of a pair as simulated: ``method`` (``asset2sim``, ``human``, ``defect:<name>`` ...), the
    ``urdf`` (its meshes beside it), ``initial_state`` (joint -> rad or m), ``springs`` (joint ->
    :class:`Spring`), ``root_fixed`` (mounted) and the ``scale`` relative to side ``a`` (1 unless a copy was
    rescaled; prismatic ranges and speeds scale with it)."""

    method: str
    urdf: Path
    initial_state: dict[str, float] = field(default_factory=dict)
    springs: dict[str, Spring] = field(default_factory=dict)
    root_fixed: bool = False
    scale: float = 1.0


def side_of(obj: SimObject, method: str) -> PhysicsSide:
    """The :class:`PhysicsSide` of an object as the checks simulate it (:func:`asset2sim.tasks.evaluation.folder_reading.sim_object`):
    its URDF, initial state, springs and declared root."""
    return PhysicsSide(method=method, urdf=Path(obj.source.path), initial_state=dict(obj.state), springs=dict(obj.springs),
                       root_fixed=bool(obj.fixed_base))


def side_from_folder(folder: Path | str, method: str) -> PhysicsSide:
    """The :class:`PhysicsSide` of an asset folder (a refine output, a benchmark method's ``asset/``): its
    URDF, ``initial_state.json``, the springs of ``overlay.json`` and the declared root, read as the
    checks read them (:func:`asset2sim.tasks.evaluation.folder_reading.sim_object`).

    Raises:
        EvaluationError: the folder has no readable URDF or sidecar.
    """
    try:
        urdf = partnet_mobility.find_urdf(folder).resolve()
    except AssetError as exc:
        raise EvaluationError(str(exc)) from exc
    return side_of(sim_object(RefinedAsset(urdf.parent, urdf.name))[0], method)


def _session(side: PhysicsSide, joint: str, conventions: SimConventions | None):
    """A PyBullet session of ``side`` (gravity on, the root as declared); KeyError when ``joint`` is not movable."""
    with quiet_stdout():
        session = open_session("pybullet", side.urdf, SessionOptions(initial_state=dict(side.initial_state), springs=dict(side.springs),
                                                                     conventions=conventions or SimConventions(),
                                                                     **session_root_options(side.root_fixed)))
    if joint not in session.joint_types:
        session.close()
        raise KeyError(f"{side.urdf}: no movable joint named {joint!r}")
    return session


def drive_limit(side: PhysicsSide, joint: str, closed: ClosedState, conventions: SimConventions | None = None) -> float:
    """The force limit (N*m or N) of the pair's drive over ``closed``'s range: the joint sweep's rule
    (:func:`asset2sim.tasks.check.sweep.effort_limit`) on ``side``'s physics plus the joint's own friction,
    so the drive moves that side's part as the sweep does (its friction is a load within the limit).

    Raises:
        KeyError: ``joint`` is not a movable joint of the side's URDF.
    """
    session = _session(side, joint, conventions)
    try:
        links = subtrees(model_of(side.urdf)).get(joint, [session.joint_child[joint]])
        return (effort_limit(session, joint, links, closed.open_range, SweepConfig(), closed.q_closed, closed.direction)
                + float(session.held_physics().joints[joint].friction))
    finally:
        session.close()


def push_release(side: PhysicsSide, joint: str, closed: ClosedState, force_limit: float, *,
                 config: PushReleaseConfig | None = None, conventions: SimConventions | None = None) -> Trajectory:
    """Simulate the script on ``side`` in PyBullet: from the initial state, drive ``joint`` toward open
    (``closed.direction``) at ``closed.open_range * side.scale / traverse_time`` with at most ``force_limit``
    (N*m or N, the joint's own friction included: a joint whose friction exceeds it does not move) for
    ``push_time``, then release it for ``release_time``; the other joints passive. Returns
    every joint's position (rad or m) and the root link's pose (m, rotation (3, 3)) every ``record_every``
    steps; a diverged run ends at its last finite sample.

    Raises:
        KeyError: ``joint`` is not a movable joint of the side's URDF.
        ValueError: ``force_limit`` not positive or a closed end without range.
    """
    cfg = config or PushReleaseConfig()
    conv = conventions or SimConventions()
    if not force_limit > 0 or not closed.open_range > 0:
        raise ValueError(f"joint {joint!r}: force limit {force_limit} and open range {closed.open_range} must be > 0")
    session = _session(side, joint, conv)
    try:
        speed = closed.open_range / cfg.traverse_time * (side.scale if session.joint_types[joint] == "prismatic" else 1.0)
        # the drive's whole force is the limit: the joint's own friction is a load within it (a hand pushing a stiff hinge)
        drive = max(float(force_limit) - float(session.held_physics().joints[joint].friction), 0.0)
        dt = conv.timestep
        root = session.link_names[0]
        names = list(session.joint_types)
        t, qs, pos, rot = [], {n: [] for n in names}, [], []

        def record(k: int) -> bool:
            q = session.joint_positions()
            p, R = session.link_frame(root)
            if not (all(math.isfinite(q[n]) for n in names) and np.all(np.isfinite(p)) and np.all(np.isfinite(R))):
                return False
            t.append(k * dt)
            for n in names:
                qs[n].append(float(q[n]))
            pos.append(np.asarray(p, float))
            rot.append(np.asarray(R, float))
            return True

        n_push = int(round(cfg.push_time / dt))
        n_free = int(round(cfg.release_time / dt))

        def law(k, q, qd):
            if k < n_push and drive > 0:
                session.drive_joint(joint, closed.direction * speed, drive)
            elif k == n_push or (k < n_push and drive <= 0):
                session.release_joint(joint)  # let go (friction beyond the limit: never pushed)

        if record(0):  # a diverged run ends at its last finite sample
            run_stroke(session, joint, n_push + n_free, law=law,
                       record=lambda k, q, qd: k % cfg.record_every == 0 and not record(k))
    finally:
        session.close()
    return Trajectory(t=np.asarray(t), joints={n: np.asarray(v) for n, v in qs.items()}, root_pos=np.asarray(pos),
                      root_rot=np.asarray(rot))
