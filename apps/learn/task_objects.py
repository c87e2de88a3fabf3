"""The objects of the ManiSkill 3 environments (:mod:`asset2sim.apps.learn.maniskill`) without ManiSkill: each
output or input folder read as a :class:`TaskObject` (its task joint, closed end, start and target, grasp point and
resting height), the folders of an ``assets`` argument, a manifest's tasks and GenSim2's references."""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np

from asset2sim.apps.learn.task import prepare_task, targets_for
from asset2sim.engines.base import Spring
from asset2sim.engines.loading import BOX_CORNERS, CollisionPiece
from asset2sim.output_folder import REPORT_NAME, URDF_NAME
from asset2sim.refined_asset import RefinedAsset
from asset2sim.tasks.check.contact_points import contact_point_rule
from asset2sim.tasks.ingest.manifest import read_manifest_rows
from asset2sim.tasks.ingest.partnet_mobility import read_category, write_reference
from asset2sim.tasks.interpret.task_words import VERBS
from asset2sim.urdf import UrdfModel

#: The actions of the environments (``task``: each object's own task, its verb's direction).
ACTIONS = ("open", "close", "task")


class ManiSkillAssetError(ValueError):
    """An asset cannot become a ManiSkill task object. ``code``: ``MS_NO_ASSETS`` (nothing to load),
    ``MS_NOT_AN_ASSET`` (a folder without ``mobility.urdf``), ``MS_NO_TASK_JOINT`` (no joint the task can
    move), ``MS_NO_TASK`` (``Asset2Sim-ManifestTask-v1``: no task recorded for the object), ``MS_NO_REFERENCE``
    (``reference=True``: the folder has no usable ``reference_gensim2.urdf``), ``MS_BAD_MANIFEST`` (the manifest
    cannot be read), ``MS_BUILD`` (SAPIEN cannot build it); the message names the folder or file. ``skipped``:
    with ``MS_NO_ASSETS`` from :func:`load_task_objects`, each folder and the error that skipped it."""

    def __init__(self, code: str, message: str, skipped: Sequence[tuple[Path, str]] = ()):
        super().__init__(f"{code}: {message}")
        self.code = code
        self.skipped = list(skipped)


@dataclass
class TaskObject:
    """One object of an environment and its task, SI units (rad or m; fractions 0 closed, 1 fully open).

    ``kind``: ``refined`` (an asset2sim output folder), ``raw`` (an input folder) or ``gensim2`` (GenSim2's
    reference of a PartNet-Mobility folder, ``source``, written to ``folder`` as the benchmark's ``human`` method
    writes it). ``action``: ``open`` or ``close``. ``joint`` the task
    joint, ``q_closed`` / ``direction`` / ``open_range`` its closed end (the opening fraction is
    ``direction * (q - q_closed) / open_range``), ``start_fraction`` where an episode starts it,
    ``reach_fraction`` the success threshold (>= for open, <= for close); ``initial_state`` the other joints'
    positions, ``springs`` (``overlay.json``), ``fixed_root``; ``grasp_link`` / ``grasp_point`` (3,) m in that
    link's frame (:func:`~asset2sim.tasks.check.contact_points.contact_point_rule`); ``base_z`` the root's
    height that puts the lowest collision point on z = 0 at the episode's start (a fixed root is welded there)."""

    folder: Path
    kind: str
    action: str
    urdf: Path
    model: UrdfModel
    pieces: dict[str, list[CollisionPiece]]
    joint: str
    joint_type: str
    q_closed: float
    direction: float
    open_range: float
    start_fraction: float
    target_fraction: float
    reach_fraction: float
    initial_state: dict[str, float]
    springs: dict[str, Spring]
    fixed_root: bool
    grasp_link: str
    grasp_point: np.ndarray
    base_z: float
    task: str
    notes: list[str] = field(default_factory=list)
    source: Path | None = None

    def q_at(self, fraction: float) -> float:
        """The task joint's position (rad or m) at opening ``fraction``."""
        return self.q_closed + self.direction * fraction * self.open_range

    def start_qpos(self, names: Sequence[str]) -> np.ndarray:
        """Joint positions (n,) for the joints ``names`` at an episode's start: the initial state, the task joint
        at ``start_fraction``."""
        q = {**self.initial_state, self.joint: self.q_at(self.start_fraction)}
        return np.array([q.get(n, 0.0) for n in names], float)


class _Kinematics:
    """The URDF's link frames at joint positions ``q`` with the root at the identity (the part of a session
    :func:`~asset2sim.tasks.check.contact_points.contact_point_rule` reads)."""

    def __init__(self, model: UrdfModel, q: dict[str, float]):
        self.model = model
        self.poses = model.link_poses(q)
        self.link_names = list(model.links)
        self.joint_child = {j.name: j.child for j in model.movable_joints}
        self.joint_types = {j.name: j.type for j in model.movable_joints}

    def link_frame(self, link: str) -> tuple[np.ndarray, np.ndarray]:
        t = self.poses[link]
        return t[:3, 3].copy(), t[:3, :3].copy()

    def joint_axis(self, joint: str) -> np.ndarray:
        return np.asarray(self.model.joint(joint).axis, float)


def _piece_points(p: CollisionPiece) -> np.ndarray:
    """Points (k, 3) in the link frame bounding a collision piece."""
    if p.kind == "hull":
        local = np.asarray(p.points, float)
    elif p.kind == "box":
        local = BOX_CORNERS * (np.asarray(p.size, float) / 2)
    else:
        r = float(p.radius or 0.0)
        local = BOX_CORNERS * [r, r, float(p.length or 2 * r) / 2 if p.kind == "cylinder" else r]
    return local @ p.origin[:3, :3].T + p.origin[:3, 3]


def _world_points(model: UrdfModel, pieces: dict[str, list[CollisionPiece]], q: dict[str, float]) -> np.ndarray:
    poses = model.link_poses(q)
    pts = [_piece_points(p) @ poses[link][:3, :3].T + poses[link][:3, 3] for link, ps in pieces.items() for p in ps]
    return np.vstack(pts) if pts else np.zeros((0, 3))


def _task_text(report_task: str | None, action: str, category: str | None) -> str:
    """The report's task turned to ``action`` ("close the laptop" -> "open the laptop"); without one, the action
    on the category's task part."""
    if report_task:
        low = " ".join(report_task.lower().split())
        for verb in sorted(VERBS, key=len, reverse=True):
            m = re.match(rf"{re.escape(verb)}\b(.*)$", low)
            if m:
                return f"{action}{m.group(1)}"
        return f"{action} {low}"
    return f"{action} the {category.lower()}" if category else action


def task_object(folder: str | Path, action: str, task: str | None = None, *, default_task: str | None = None,
                category: str | None = None, kind: str | None = None) -> TaskObject:
    """The :class:`TaskObject` of an output or input ``folder`` for ``action``: ``open`` / ``close`` (the part
    ``task`` names, "close the laptop", turned to ``action``) or ``task`` (the task itself, its verb's direction:
    "press the stapler" closes the lid). The task text: ``task``, else the output's ``report.json`` task (what
    ``asset2sim refine --task`` recorded), else ``default_task`` (a manifest row's ``task``), else, for ``open`` /
    ``close``, the category's part. ``category`` overrides the folder's (``meta.json``, ``report.json``); ``kind``
    overrides ``refined`` / ``raw``.

    Raises:
        ManiSkillAssetError: ``MS_NOT_AN_ASSET`` (no ``mobility.urdf``, or an unreadable ``report.json``),
            ``MS_NO_TASK`` (``action="task"`` and no task text anywhere), ``MS_NO_TASK_JOINT`` (the task moves no joint).
    """
    if action not in ACTIONS:
        raise ValueError(f"action must be one of {sorted(ACTIONS)}, got {action!r}")
    asset = RefinedAsset(Path(folder))
    folder, urdf = asset.folder, asset.urdf_path
    if not urdf.is_file():
        raise ManiSkillAssetError("MS_NOT_AN_ASSET", f"{folder}: has no {URDF_NAME}")
    report = None
    if (folder / REPORT_NAME).is_file():
        try:
            report = asset.report
        except (OSError, ValueError) as exc:
            raise ManiSkillAssetError("MS_NOT_AN_ASSET", f"{folder / REPORT_NAME}: unreadable ({exc})") from exc
    recorded = task or (report.task if report else None) or default_task
    if action == "task":
        if not (recorded and recorded.strip()):
            raise ManiSkillAssetError("MS_NO_TASK", f"{folder}: no task: neither report.json (asset2sim refine --task) "
                                                    "nor a manifest row's task column records one")
        text = " ".join(recorded.split())
    else:
        text = _task_text(recorded, action, category or (report.category if report else None))
    try:
        lt = prepare_task(folder, text, start="task", category=category)
    except ValueError as exc:  # LearnTaskError, EvaluationError, UrdfError
        raise ManiSkillAssetError("MS_NO_TASK_JOINT", f"{folder}: task {text!r}: {exc}") from exc
    if action != "task" and lt.action != action:
        raise ManiSkillAssetError("MS_NO_TASK_JOINT", f"{folder}: task {text!r} does not {action} a joint ({lt.rule})")
    action = lt.action
    model, (pieces, notes) = asset.model, asset.collision
    q_closed, direction, open_range = lt.closed.q_closed, lt.closed.direction, lt.closed.open_range
    if report is not None and lt.joint in report.closed_positions:  # the closed end refine measured and wrote
        j = model.joint(lt.joint)
        q_closed = float(report.closed_positions[lt.joint])
        if j.type != "continuous":
            open_range = max((j.upper - q_closed) if direction > 0 else (q_closed - j.lower), 0.0)
    if not open_range > 0:
        raise ManiSkillAssetError("MS_NO_TASK_JOINT", f"{folder}: joint {lt.joint!r} cannot open (range 0)")
    target, reach = targets_for(action, lt.start_fraction)
    obj = TaskObject(folder=folder, kind=kind or ("refined" if report is not None else "raw"), action=action, urdf=urdf, model=model,
                     pieces=pieces, joint=lt.joint, joint_type=lt.joint_type, q_closed=q_closed, direction=direction,
                     open_range=open_range, start_fraction=lt.start_fraction, target_fraction=target, reach_fraction=reach,
                     initial_state=dict(lt.initial_state), springs=dict(lt.springs), fixed_root=bool(lt.root_fixed),
                     grasp_link="", grasp_point=np.zeros(3), base_z=0.0, task=text, notes=list(lt.notes) + notes)
    names = [j.name for j in model.movable_joints]
    q0 = dict(zip(names, obj.start_qpos(names)))
    link, point, rule = contact_point_rule(_Kinematics(model, q0), lt.joint, model, opening_direction=direction)
    # the grasp on the link that carries ``link`` (itself, or its nearest ancestor whose joint to its parent is not fixed):
    # a link welded on by a fixed joint (a handle on its door) has no joint in a SAPIEN articulation (Link.merge needs one)
    carrier, point, joint = link, np.asarray(point, float), model.parent_joint(link)
    while joint is not None and joint.type == "fixed":
        point = (joint.origin @ np.append(point, 1.0))[:3]
        carrier, joint = joint.parent, model.parent_joint(joint.parent)
    obj.grasp_link, obj.grasp_point = carrier, point
    obj.notes.append(f"grasp point: {rule} of {link}" + (f" (on {obj.grasp_link}, which carries it)" if obj.grasp_link != link else ""))
    pts = _world_points(model, pieces, q0)  # free objects rest on the floor; mounted ones are welded standing on it
    obj.base_z = float(-pts[:, 2].min()) if len(pts) else 0.0
    return obj


def find_assets(assets: str | Path | Sequence[str | Path]) -> list[Path]:
    """The object folders of ``assets``: each path that holds ``mobility.urdf`` itself, else its sub-folders that
    do (sorted by name). Raises ManiSkillAssetError ``MS_NO_ASSETS``: none found."""
    paths = [assets] if isinstance(assets, (str, Path)) else list(assets)
    out: list[Path] = []
    for p in map(Path, paths):
        if (p / URDF_NAME).is_file():
            out.append(p)
        elif p.is_dir():
            out.extend(sorted(d for d in p.iterdir() if d.is_dir() and (d / URDF_NAME).is_file()))
        else:
            raise ManiSkillAssetError("MS_NO_ASSETS", f"{p}: not a folder")
    if not out:
        raise ManiSkillAssetError("MS_NO_ASSETS", f"no folder with {URDF_NAME} in {[str(p) for p in paths]}")
    return out


def read_manifest_tasks(manifest: str | Path) -> dict[str, Any]:
    """The usable rows of a ``manifest.csv`` by ``id`` (:func:`asset2sim.tasks.ingest.manifest.read_manifest_rows`;
    refused rows are left out). Raises ManiSkillAssetError ``MS_BAD_MANIFEST``: the file cannot be read or used."""
    try:
        reading = read_manifest_rows(manifest)
    except (OSError, ValueError) as exc:  # ManifestError is a ValueError
        raise ManiSkillAssetError("MS_BAD_MANIFEST", f"{manifest}: {exc}") from exc
    return {row.id: row for row in reading.rows}


def gensim2_reference(folder: str | Path, out_dir: str | Path, row: Any = None) -> Path:
    """GenSim2's reference of the PartNet-Mobility ``folder`` (``reference_gensim2.urdf`` at
    ``reference_gensim2.json``'s scale, the task joint's limits its ``joint_position_range``, starting at the range's
    lower end) written to ``out_dir`` as an asset folder, as the learnability benchmark's ``human`` method writes it
    (:func:`asset2sim.tasks.ingest.partnet_mobility.write_reference`); ``row``: the folder's manifest row, if any (its
    ``id`` names the reference). Returns ``out_dir``. Raises ManiSkillAssetError ``MS_NO_REFERENCE``: no usable
    reference in ``folder``."""
    folder = Path(folder)
    try:
        write_reference(folder, out_dir, f"asset2sim baseline 'human' (GenSim2 reference) of {row.id if row else folder.name}")
    except (OSError, ValueError) as exc:  # AssetError and UrdfError are ValueErrors
        raise ManiSkillAssetError("MS_NO_REFERENCE", f"{folder}: GenSim2's reference cannot be used ({exc})") from exc
    return Path(out_dir)


def load_task_objects(assets: str | Path | Sequence[str | Path], action: str,
                      task: str | Mapping[str, str] | None = None, *, manifest: str | Path | None = None,
                      reference: bool = False, reference_dir: str | Path | None = None,
                      ) -> tuple[list[TaskObject], list[tuple[Path, str]]]:
    """Every object of ``assets`` (:func:`find_assets`) as a :class:`TaskObject`, and the folders that could not
    become one with the error (a failed asset does not stop the others); ``task`` as :func:`task_object`'s, or
    per folder (``str(folder)`` -> task text). ``manifest``: a ``manifest.csv`` whose row with the folder's name as
    ``id`` gives the task (its ``task`` column) and category where the output records none. ``reference``: each
    folder is a PartNet-Mobility input and its GenSim2 reference is the object (:func:`gensim2_reference`, written
    under ``reference_dir``, required then). Raises ManiSkillAssetError ``MS_NO_ASSETS``: none could;
    ``MS_BAD_MANIFEST``: the manifest cannot be read."""
    rows = read_manifest_tasks(manifest) if manifest is not None else {}
    if reference and reference_dir is None:
        raise ValueError("reference=True needs reference_dir (where GenSim2's references are written)")
    objects, skipped = [], []
    for i, folder in enumerate(find_assets(assets)):
        row = rows.get(folder.name)
        text = task.get(str(folder)) if isinstance(task, Mapping) else task
        try:
            if reference:
                ref = gensim2_reference(folder, Path(reference_dir) / f"{i:04d}", row)
                category = (row.category if row else "") or read_category(folder)
                obj = task_object(ref, action, text, default_task=row.task if row else None, category=category or None,
                                  kind="gensim2")
                obj.source = folder
            else:
                obj = task_object(folder, action, text, default_task=(row.task or None) if row else None,
                                  category=(row.category or None) if row else None)
            objects.append(obj)
        except ManiSkillAssetError as exc:
            skipped.append((folder, str(exc)))
    if not objects:
        raise ManiSkillAssetError("MS_NO_ASSETS", "no asset can be a task object: " + "; ".join(f"{f}: {e}" for f, e in skipped),
                                  skipped)
    return objects, skipped
