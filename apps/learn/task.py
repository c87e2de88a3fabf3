"""The task instance of a learning environment: which joint a task text acts
on, from which opening fraction to which target. Needs no ``gymnasium``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

from asset2sim.engines.base import SessionOptions, Spring, session_root_options
from asset2sim.engines.quiet import quiet_stdout
from asset2sim.schemas.config import SimConventions
from asset2sim.tasks.check.gripper import GripperLimits
from asset2sim.tasks.check.probes import (
    CLOSE_REACHED,
    CLOSE_TARGET,
    OPEN_FAR_REACHED,
    OPEN_FAR_TARGET,
    OPEN_REACHED,
    OPEN_TARGET,
)
from asset2sim.tasks.check.task_spec import parse_task
from asset2sim.tasks.check.task_tier import hold_required_by_label
from asset2sim.tasks.evaluation.folder_reading import closed_ends, read_asset, sim_object, task_joints
from asset2sim.tasks.geometry.closed_state import ClosedState

#: Common start of the task joint per action, opening fraction (``start="task"``).
START_FRACTION: dict[str, float] = {"close": 0.5, "open": 0.0}

#: Largest opening of a revolute task joint at the common start of a close
#: task, rad (docs/design/metrics.md, "Learnability").
START_MAX_ANGLE = math.radians(45.0)


@dataclass
class LearnConfig:
    """Environment knobs (units on every field)."""

    engine: str = "pybullet"  # engine name (open_session)
    action_repeat: int = 12  # engine steps per action (12 x 1/240 s = 20 Hz control)
    episode_time: float = 3.0  # longest episode, s
    settle_time: float = 0.25  # shortest settling before the snapshot, s (the probes')
    settle_max_time: float = 3.0  # longest settling, s: until joints and root are at rest
    rest_joint_speed: tuple[float, float] = (0.05, 0.005)  # joint at rest below: revolute rad/s, prismatic m/s
    rest_root_speed: float = 0.005  # root at rest below, m/s
    hold_time: float = 1.0  # after success, released, the target must hold this long, s
    reset_noise: float = 0.02  # largest random offset of the task joint at reset, opening fraction
    slide_tol: float = 0.005  # footprint slide that counts as sliding, m (the probes')
    tip_tol: float = 0.05  # root rotation that counts as tipping, rad (the probes')
    progress_weight: float = 10.0  # w_p: reward for moving the whole way to the target
    stretch_weight: float = 0.05  # w_s: penalty per step for pulling at the force limit
    moved_penalty: float = 5.0  # w_m: penalty when the object slides or tips
    success_bonus: float = 10.0  # w_b: bonus on success
    limits: GripperLimits = field(default_factory=GripperLimits)  # the gripper's force and speed limits


class LearnTaskError(ValueError):
    """The task cannot be set up on this asset (names the asset, the task and why)."""


@dataclass
class LearnTask:
    """One task instance on one asset. Positions rad or m; fractions 0 closed, 1 fully open."""

    urdf: Path
    task: str
    joint: str
    joint_type: str
    action: str  # "close" or "open"
    closed: ClosedState
    target_fraction: float
    reach_fraction: float  # f <= this (close) or f >= this (open) counts as reached
    hold_required: bool  # the target must still hold after release (not for a joint sprung by design)
    initial_state: dict[str, float]
    springs: dict[str, Spring]
    root_fixed: bool
    conventions: SimConventions
    start_fraction: float  # the task joint's opening fraction at the start of an episode
    start: str = "task"  # "task" (the common start) or "asset" (the initial state)
    candidates: list[str] = field(default_factory=list)  # the task's joints (the reference's when it names any)
    rule: str = ""
    notes: list[str] = field(default_factory=list)

    def reached(self, fraction: float) -> bool:
        """Whether ``fraction`` satisfies the task's reach threshold."""
        return fraction <= self.reach_fraction if self.action == "close" else fraction >= self.reach_fraction

    def fraction(self, q: float) -> float:
        """Opening fraction of the task joint at ``q`` (rad or m)."""
        return self.closed.fraction(q)

    def start_state(self) -> dict[str, float]:
        """The joint positions an episode starts from (rad or m): the asset's, the task joint at ``start_fraction``
        when ``start`` is ``task``."""
        state = dict(self.initial_state)
        if self.start == "task":
            state[self.joint] = self.closed.q_closed + self.closed.direction * self.start_fraction * self.closed.open_range
        return state

    def session_options(self) -> SessionOptions:
        """The options of a session on the task's object: :meth:`start_state`, its springs, conventions and root."""
        return SessionOptions(initial_state=self.start_state(), springs=dict(self.springs), conventions=self.conventions,
                              **session_root_options(self.root_fixed))


def common_start(action: str, joint_type: str, open_range: float) -> float:
    """The common start of a task joint, opening fraction (:data:`START_FRACTION`; a revolute close task at most
    :data:`START_MAX_ANGLE` open, ``open_range`` rad or m). Raises ValueError: ``action`` is not ``close`` or ``open``."""
    if action not in START_FRACTION:
        raise ValueError(f"task action must be 'close' or 'open', got {action!r}")
    f = START_FRACTION[action]
    if action == "close" and joint_type != "prismatic" and open_range > 0:
        f = min(f, START_MAX_ANGLE / open_range)
    return f


def targets_for(action: str, start_fraction: float) -> tuple[float, float]:
    """(target fraction, reach threshold) of an action from a start fraction (the probes').
    Raises ValueError: ``action`` is not ``close`` or ``open``."""
    if action == "close":
        return CLOSE_TARGET, CLOSE_REACHED
    if action == "open":
        return (OPEN_TARGET, OPEN_REACHED) if start_fraction < OPEN_REACHED else (OPEN_FAR_TARGET, OPEN_FAR_REACHED)
    raise ValueError(f"task action must be 'close' or 'open', got {action!r}")


def prepare_task(asset: Path | str, task: str, *, reference: Path | str | None = None,
                 category: str | None = None, conventions: SimConventions | None = None,
                 start: str = "task") -> LearnTask:
    """The :class:`LearnTask` of ``task`` ("close the box lid") on the asset folder or URDF ``asset``: of the task's joints
    (the ``reference``'s movable ones when it names any) and actions, the pair whose target lies farthest from its start.
    ``start``: ``task`` (the common start) or ``asset`` (the initial state). Raises LearnTaskError (no movable joint with a
    range > 0 to act on) or EvaluationError (unreadable asset)."""
    if start not in ("task", "asset"):
        raise ValueError(f"start must be 'task' or 'asset', got {start!r}")
    files, desc = read_asset(asset, category)
    urdf = files.urdf_path
    obj, _ = sim_object(files, conventions)
    cat = category or desc.category or "Generic"
    chosen, tj_rule = task_joints(desc, cat, Path(reference) if reference is not None else None)
    spec = parse_task(task, desc, cat, chosen)
    if not spec.joints:
        raise LearnTaskError(f"{urdf}: task {task!r} names no movable joint ({spec.rule})")
    # Where the reference names the task's joint (GenSim2 keeps only it movable), every method acts on it.
    candidates = [j for j in spec.joints if j in chosen] or list(spec.joints)
    with quiet_stdout():
        closed, how = closed_ends(files, candidates)
    types = {j.name: j.type for j in desc.joints}
    # (gap, joint, action, start fraction) of the pair whose target is farthest from its start (first on a tie)
    best = None
    for j in candidates:
        c = closed[j]
        if not c.open_range > 0:
            continue
        for action in spec.actions:
            f0 = c.fraction(obj.state.get(j, 0.0)) if start == "asset" else common_start(action, types[j], c.open_range)
            target, _ = targets_for(action, f0)
            gap = abs(target - f0)
            if best is None or gap > best[0]:
                best = (gap, j, action, f0)
    if best is None:
        raise LearnTaskError(f"{urdf}: task {task!r}: none of {candidates} can open (range 0)")
    _, joint, action, f0 = best
    target, reach = targets_for(action, f0)
    notes = list(spec.notes) + [f"closed ends: {how}", f"task-relevant joints: {tj_rule}"]
    label = desc.link(desc.joint(joint).child).semantic_label
    hold = hold_required_by_label({joint: label}, dict(obj.springs), cat, free_moving=False, spring_requested=False)[joint]
    if not hold:
        notes.append(f"{joint} returns by its spring by design ({cat} {label}): the target need not hold after release")
    return LearnTask(
        urdf=urdf, task=task, joint=joint, joint_type=types[joint], action=action, closed=closed[joint],
        target_fraction=target, reach_fraction=reach, hold_required=hold, initial_state=dict(obj.state),
        springs=dict(obj.springs), root_fixed=obj.fixed_base, conventions=obj.conventions,
        start_fraction=f0, start=start, candidates=candidates, rule=spec.rule, notes=notes,
    )
