"""Pairs that differ only in physics: one object, one joint, the same meshes,
cameras and scripted motion (:func:`asset2sim.apps.realism.motion.push_release`),
simulated with two overlays and drawn as two clips per view. Which side a
judge sees on the left is drawn later, per judge and pair; ``pairs.json``
only says which side is which method.

A pair set is a folder: ``pairs.json`` (:class:`~asset2sim.schemas.realism.PairSet`)
and ``clips/<pair>/`` with each side's WebM, poster and stills; clip folders
are named by a counter, never by an input's name.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

import numpy as np

from asset2sim import atomic, output_folder
from asset2sim.inert import one_line
from asset2sim.output_paths import OutputError
from asset2sim.schemas.config import SimConventions
from asset2sim.schemas.realism import ClipPair, PairSet, PairSide
from asset2sim.tasks.evaluation.clips import (CLIP_FPS, CLIP_SIZE, CLIP_VIEWS, draw_frames, fit_cameras, fit_poses, pose_points,
                                              write_clip)
from asset2sim.tasks.evaluation.folder_reading import closed_ends, read_asset, sim_object, task_joints
from asset2sim.tasks.geometry.closed_state import ClosedState
from asset2sim.tasks.geometry.render import SceneRenderer
from asset2sim.tasks.geometry.render_camera import view_spec
from asset2sim.apps.realism.pair_set import write_pair_set
from asset2sim.apps.realism.motion import PhysicsSide, PushReleaseConfig, drive_limit, push_release, side_from_folder, side_of

#: The folder of a pair set's clips.
PAIR_CLIPS_DIR = "clips"


@dataclass(frozen=True)
class PairSpec:
    """What one pair shows: ``a`` and ``b`` (the sides), the ``joint`` pushed, the object's id, category,
    request and ``defect`` (the planted defect of ``b``, a calibration pair; else None)."""

    a: PhysicsSide
    b: PhysicsSide
    joint: str
    object_id: str
    category: str = ""
    request: str = ""
    defect: str | None = None
    force_limit: float | None = None
    """the drive's limit, N*m or N (None: :func:`drive_limit` of side ``a``, computed by :func:`make_pair`)"""


def pushed_joints(folder: Path | str, limit: int = 1) -> list[tuple[str, ClosedState]]:
    """The joints a pair of an asset folder pushes: its task-relevant joints (:func:`asset2sim.tasks.evaluation.folder_reading.task_joints`)
    then its other movable ones, those that can open, at most ``limit``, with their closed ends (rad or m;
    :func:`asset2sim.tasks.evaluation.folder_reading.closed_ends`). Raises EvaluationError: the folder cannot be read."""
    files, desc = read_asset(folder)
    chosen, _ = task_joints(desc, desc.category or "Generic")
    names = list(dict.fromkeys([*chosen, *(j.name for j in desc.movable_joints())]))
    closed, _ = closed_ends(files, names)
    return [(n, closed[n]) for n in names if closed[n].open_range > 0][:limit]


@dataclass(frozen=True)
class Subject:
    """asset2sim's output of one object as every pair of it shows it: its ``side``, the ``joint`` pushed with its
    ``closed`` end and the drive's ``force_limit`` (N*m or N, :func:`drive_limit`), the object's id, category and
    request (the output's ``report.json`` prompt)."""

    side: PhysicsSide
    joint: str
    closed: ClosedState
    force_limit: float
    object_id: str
    category: str = ""
    request: str = ""


def _spec(subject: Subject, b: PhysicsSide, defect: str | None = None) -> tuple[PairSpec, ClosedState]:
    return PairSpec(a=subject.side, b=b, joint=subject.joint, object_id=subject.object_id, category=subject.category,
                    request=subject.request, defect=defect, force_limit=subject.force_limit), subject.closed


def make_pair(spec: PairSpec, closed: ClosedState, pair_set: Path | str, index: int, *,
              config: PushReleaseConfig | None = None, conventions: SimConventions | None = None,
              views: Sequence[str] = CLIP_VIEWS) -> ClipPair:
    """Simulate ``spec``'s two sides with the same script and drive (force limit from side ``a``,
    :func:`drive_limit`), draw both with the same cameras (fitted to every pose of both) and write their
    clips into ``pair_set/clips/<index>/``. ``closed``: side ``a``'s closed end of ``spec.joint``. The pair id is
    a SHA-256 digest (16 hex digits) of ``index``, the object id, the defect and both sides' methods and clips:
    deterministic, and distinct within a set even when two pairs show the same clips.

    Raises:
        KeyError: the joint is missing on a side. RenderError / FileNotFoundError: a side cannot be drawn.
        ImportError: PyAV is not installed. OSError: the folder cannot be written.
    """
    base = Path(pair_set)
    folder = base / PAIR_CLIPS_DIR / f"{index:04d}"
    force = spec.force_limit if spec.force_limit is not None else drive_limit(spec.a, spec.joint, closed, conventions)
    trajs = [push_release(s, spec.joint, closed, force, config=config, conventions=conventions) for s in (spec.a, spec.b)]
    with SceneRenderer(spec.a.urdf, size=CLIP_SIZE, supersample=1) as ra, SceneRenderer(spec.b.urdf, size=CLIP_SIZE, supersample=1) as rb:
        cloud = np.concatenate([pose_points(r, fit_poses(traj)) for r, traj in ((ra, trajs[0]), (rb, trajs[1]))])
        cams = fit_cameras(cloud, views, CLIP_SIZE)  # one camera per view for both sides
        sides = []
        for s, r, traj, slot in ((spec.a, ra, trajs[0], "a"), (spec.b, rb, trajs[1], "b")):
            frames = draw_frames(r, traj, cams, CLIP_FPS)
            sides.append(PairSide(method=s.method, clips=[
                write_clip(folder, f"{slot}_{v}", frames[view_spec(v).name], joint=spec.joint, motion="push_release", view=v,
                           fps=CLIP_FPS, poster_index=len(frames[view_spec(v).name]) // 3, relative_to=base) for v in cams]))
    # the clips' content, and where the pair sits in its set: two refines of one object give the same clips of a
    # planted defect, and each pair still needs its own id
    digest = hashlib.sha256(json.dumps([index, spec.object_id, spec.defect, [[s.method, [atomic.sha256_file(base / c.video)
                                                                                       for c in s.clips]] for s in sides]]).encode())
    return ClipPair(pair_id=digest.hexdigest()[:16], object_id=spec.object_id, category=spec.category, request=spec.request,
                    joint=spec.joint, motion="push_release", a=sides[0], b=sides[1], defect=spec.defect)


def build_pair_set(specs: Sequence[tuple[PairSpec, ClosedState]], pair_set: Path | str, *, skipped: dict[str, str] | None = None,
                   config: PushReleaseConfig | None = None, conventions: SimConventions | None = None,
                   progress=None) -> PairSet:
    """Make every pair of ``specs`` (:func:`make_pair`, clip folders numbered in order) and write ``pairs.json``; a pair
    that fails is listed in ``skipped`` with its error and the others go on. ``progress``: callback(text) per pair."""
    pairs, skipped = [], dict(skipped or {})
    with output_folder.guarding(pair_set):  # no clip or frame through a symlinked subfolder
        for index, (spec, closed) in enumerate(specs):
            key = f"{spec.object_id} {spec.b.method}"
            try:
                pairs.append(make_pair(spec, closed, pair_set, index, config=config, conventions=conventions))
                if progress:
                    progress(f"{key}: pair {pairs[-1].pair_id}")
            except OutputError:  # a write the guard refused: the whole set, not one pair
                raise
            except Exception as exc:  # one pair never stops the set
                skipped[key] = f"{type(exc).__name__}: {one_line(str(exc))}"
                if progress:
                    progress(f"{key}: skipped ({skipped[key]})")
        return write_pair_set(pair_set, pairs, skipped)


#: The methods a benchmark's asset2sim output is paired with by default (``asset2sim benchmark``'s baselines).
AGAINST: tuple[str, ...] = ("human", "direct", "defaults")
#: The folder of a pair set's broken copies (planted defects).
DEFECTS_DIR = "defects"


def specs_from_folders(paths: Sequence[Path | str], pair_set: Path | str, *, against: Sequence[str] = AGAINST,
                       defects: Sequence[str] | None = (), conventions: SimConventions | None = None
                       ) -> tuple[list[tuple[PairSpec, ClosedState]], dict[str, str]]:
    """The pairs of ``paths``: a benchmark output folder (``<method>/<id>/asset/``, ``asset2sim benchmark``) gives,
    per object, asset2sim against each method of ``against`` it holds; a refine output folder (``report.json``
    beside ``mobility.urdf``) gives nothing by itself. ``defects`` (None: every one of
    :data:`~asset2sim.apps.realism.defects.DEFECTS`; empty: none) adds calibration pairs of every asset2sim output,
    their broken copies under ``pair_set/defects/<n>/``. Returns (specs, skipped: key -> why).

    Raises:
        FileNotFoundError: a path that is neither.
    """
    from asset2sim.apps.realism.defects import DEFECTS, plant_defect

    outputs: list[tuple[str, dict[str, Path]]] = []
    for path in map(Path, paths):
        if (path / "asset2sim").is_dir():
            for asset in sorted(p for p in (path / "asset2sim").iterdir() if (p / "asset").is_dir()):
                outputs.append((asset.name, {"asset2sim": asset / "asset", **{
                    m: path / m / asset.name / "asset" for m in against if (path / m / asset.name / "asset").is_dir()}}))
        elif (path / "report.json").is_file():
            outputs.append((path.name, {"asset2sim": path}))
        else:
            raise FileNotFoundError(f"{path}: neither a benchmark output (asset2sim/<id>/asset/) nor a refine output (report.json)")
    specs: list[tuple[PairSpec, ClosedState]] = []
    skipped: dict[str, str] = {}
    for n, (object_id, folders) in enumerate(outputs):
        try:
            # asset2sim's output as every pair of the object shows it
            joints = pushed_joints(folders["asset2sim"])
            if not joints:
                skipped[object_id] = "no joint that opens"
                continue
            (joint, closed), (files, desc) = joints[0], read_asset(folders["asset2sim"])
            side, report = side_of(sim_object(files)[0], "asset2sim"), files.record("report.json") or {}
            subject = Subject(side=side, joint=joint, closed=closed, force_limit=drive_limit(side, joint, closed, conventions),
                              object_id=object_id, category=report.get("category") or desc.category or "",
                              request=str(report.get("prompt") or ""))
            # against every other method's asset of the object
            for method, folder in folders.items():
                if method == "asset2sim":
                    continue
                try:
                    specs.append(_spec(subject, side_from_folder(folder, method)))
                except Exception as exc:  # one method's unreadable asset skips its pair only
                    skipped[f"{object_id} {method}"] = f"{type(exc).__name__}: {exc}"
            if defects is None or len(defects):
                # one calibration pair per planted defect, each broken copy under defects/<n>/<k>/ (no input name as a path)
                work, planted, why = Path(pair_set) / DEFECTS_DIR / f"{n:04d}", [], {}
                with output_folder.guarding(pair_set):  # the broken copies: never through a symlinked defects/
                    for k, name in enumerate(defects or list(DEFECTS)):
                        try:
                            b = plant_defect(subject.side, name, subject.joint, subject.closed, subject.force_limit,
                                             work / f"{k:02d}")
                        except OutputError:  # the output guard refused a write: not a defect that cannot be planted
                            raise
                        except (KeyError, ValueError) as exc:
                            why[f"{object_id} {name}"] = one_line(exc)
                            continue
                        planted.append(_spec(subject, b, name))
                specs += planted
                skipped.update(why)
        except OutputError:  # a write the guard refused: the whole set
            raise
        except Exception as exc:  # one object's unreadable output never stops the set
            skipped[object_id] = f"{type(exc).__name__}: {one_line(exc)}"
    return specs, skipped
