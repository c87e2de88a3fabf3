"""Interaction clips: the object moving as a simulator moved it, rendered on
the CPU from two fixed views and encoded as WebM (VP9, through PyAV), with a
poster frame and a few stills (PNG) for the report and for model judges.

A clip is drawn from a recorded trajectory (:class:`Trajectory`: joint
positions and the root's pose at fixed simulated times), never simulated
here: the joint sweep tier's trace (:func:`sweep_trajectory`) for every
output, and the scripted motions of realism pairs
(``asset2sim.apps.realism.pairs``). One camera per view is fitted to every
pose of the clip (the cameras of today's views, :mod:`render_camera`), so the
object never leaves the frame and two clips drawn with the same cameras
differ only in how the object moved.

Encoding settings are fixed (VP9, constant quality, one thread, bit-exact
muxing): the same trajectory gives the same bytes.
"""

from __future__ import annotations

import contextlib
import io
import math
from dataclasses import dataclass, field
from fractions import Fraction
from pathlib import Path
from typing import Iterable, Mapping, Sequence

import numpy as np

from asset2sim import atomic
from asset2sim.output_folder import CLIPS_DIR
from asset2sim.schemas.realism import Clip, ClipSet, Motion
from asset2sim.tasks.check.sweep import JointSweep, SweepRun
from asset2sim.tasks.geometry.render import SceneRenderer
from asset2sim.tasks.geometry.render_camera import Camera, view_camera, view_spec
from asset2sim.tasks.geometry.render_images import write_png

#: The file of ``clips/`` (:data:`asset2sim.output_folder.CLIPS_DIR`) listing the clips (:class:`ClipSet`).
CLIPS_JSON = "clips.json"
#: The two fixed views of every clip (names of ``render_camera.VIEWS``): the front, and a three-quarter view
#: from above that shows doors and lids swinging toward the camera's side.
CLIP_VIEWS: tuple[str, ...] = ("front", "perspective")
#: Frame size (width, height), pixels (even numbers: the encoder's 4:2:0 chroma needs them).
CLIP_SIZE: tuple[int, int] = (224, 168)
#: Frames per simulated second (the clips play in real time; 10 keeps a sweep smooth at a tenth of a second).
CLIP_FPS = 10.0
#: Time a task clip goes on after the gripper lets go, s (the rest of the hold test is still).
TASK_AFTER_RELEASE = 0.5
#: Stills per clip for model judges, spread evenly from the first frame to the last.
STILLS = 4
#: VP9 constant quality (0 best .. 63 worst; 32-36 is libvpx's range for web video).
VP9_CRF = 34
#: Poses of a clip its cameras are fitted to (spread over the clip, plus the largest opening).
FIT_POSES = 12
#: Joints with a clip in one output folder, at most (the task-relevant ones first).
MAX_CLIP_JOINTS = 4


class ClipError(RuntimeError):
    """A clip could not be drawn or encoded."""


@dataclass
class Trajectory:
    """What a clip shows: at each of K times ``t`` (K,) s, the joint positions ``joints`` (name -> (K,), rad
    or m) and, when the root moved, ``root_pos`` (K, 3) m and ``root_rot`` (K, 3, 3) relative to its pose as
    loaded (None: the root stays as loaded)."""

    t: np.ndarray
    joints: dict[str, np.ndarray]
    root_pos: np.ndarray | None = None
    root_rot: np.ndarray | None = None
    #: positions of the joints not in ``joints`` (held), rad or m
    others: dict[str, float] = field(default_factory=dict)
    #: (K, 3) m a point drawn on each frame (the grasp point of a task; NaN: none), or None
    marks: np.ndarray | None = None

    def __post_init__(self) -> None:
        self.t = np.asarray(self.t, float)
        k = len(self.t)
        for name, q in self.joints.items():
            if len(q) != k:
                raise ValueError(f"joint {name!r}: {len(q)} positions for {k} times")
        if (self.root_pos is None) != (self.root_rot is None):
            raise ValueError("root_pos and root_rot go together")

    def sampled(self, fps: float) -> list[int]:
        """Indices (ascending) of the samples nearest to the times 0, 1/fps, 2/fps ... up to the last time."""
        if len(self.t) == 0:
            return []
        t0, t1 = float(self.t[0]), float(self.t[-1])
        want = t0 + np.arange(int(math.floor((t1 - t0) * fps + 1e-9)) + 1) / fps
        idx = np.clip(np.searchsorted(self.t, want), 0, len(self.t) - 1)
        prev = np.clip(idx - 1, 0, len(self.t) - 1)
        idx = np.where(np.abs(self.t[prev] - want) <= np.abs(self.t[idx] - want), prev, idx)
        return sorted({int(i) for i in idx})


def sweep_trajectory(js: JointSweep, others: Mapping[str, float]) -> Trajectory:
    """The joint sweep's drive out and back (``js.trace``: opening fraction per step) as a trajectory of the
    swept joint, the other joints at ``others`` (rad or m) and the root fixed (the sweep's session).

    Raises:
        ValueError: the sweep recorded no trace.
    """
    t = np.asarray(js.trace.get("t", []), float)
    f = np.asarray(js.trace.get("fraction", []), float)
    if len(t) == 0 or len(t) != len(f):
        raise ValueError(f"joint {js.joint!r}: the sweep recorded no trace")
    ok = np.isfinite(f)
    q = js.q_closed + (js.q_far - js.q_closed) * f[ok]
    return Trajectory(t=t[ok], joints={js.joint: q}, others={k: float(v) for k, v in others.items() if k != js.joint})


#: A pose of a clip: (joint positions rad or m, root position (3,) m or None, root rotation (3, 3) or None).
Pose = tuple[dict[str, float], "np.ndarray | None", "np.ndarray | None"]


def set_pose(renderer: SceneRenderer, joints: Mapping[str, float], pos: np.ndarray | None, rot: np.ndarray | None) -> None:
    """Put ``renderer``'s object at a pose: the joints it has (finite values), and the root link at ``pos``
    (3,) m with ``rot`` (3, 3) when given."""
    renderer.set_joint_positions({k: v for k, v in joints.items() if k in renderer.joint_names and math.isfinite(v)})
    if rot is not None:
        renderer.place_root(np.asarray(pos, float), np.asarray(rot, float))


def trajectory_poses(traj: Trajectory, idx: Sequence[int]) -> list[Pose]:
    """The poses of ``traj`` at sample indices ``idx``."""
    return [({**traj.others, **{n: float(q[i]) for n, q in traj.joints.items()}},
             None if traj.root_pos is None else traj.root_pos[i], None if traj.root_rot is None else traj.root_rot[i])
            for i in idx]


def fit_poses(traj: Trajectory, fps: float = CLIP_FPS, extra: Sequence[int] = ()) -> list[Pose]:
    """:data:`FIT_POSES` poses spread over the frames of ``traj`` at ``fps``, plus the samples ``extra``:
    what a clip's cameras are fitted to."""
    idx = np.asarray(traj.sampled(fps))
    picks = idx[np.linspace(0, len(idx) - 1, min(len(idx), FIT_POSES)).round().astype(int)]
    return trajectory_poses(traj, sorted({*picks.tolist(), *extra}))


def pose_points(renderer: SceneRenderer, poses: Sequence[Pose]) -> np.ndarray:
    """The object's visual vertices (N, 3), m, at every pose of ``poses`` together (the renderer is left
    at the last pose)."""
    pts = []
    for pose in poses:
        set_pose(renderer, *pose)
        pts.append(renderer.world_points())
    return np.concatenate(pts)


def fit_cameras(points: np.ndarray, views: Iterable[str], size: tuple[int, int] = CLIP_SIZE) -> dict[str, Camera]:
    """One camera per view fitted to ``points`` (N, 3), m, by the rules of today's views
    (:func:`~asset2sim.tasks.geometry.render_camera.view_camera`) for images of ``size`` (width, height) pixels."""
    return {view_spec(v).name: view_camera(points, v, aspect=size[0] / size[1]) for v in views}


def draw_frames(renderer: SceneRenderer, traj: Trajectory, cameras: Mapping[str, Camera],
                fps: float = CLIP_FPS) -> dict[str, list[np.ndarray]]:
    """view -> the frames (each (H, W, 3) uint8) of ``traj`` sampled at ``fps`` (frames per simulated
    second), drawn with the given fixed ``cameras``.

    Raises:
        ClipError: the trajectory has no sample.
    """
    idx = traj.sampled(fps)
    if not idx:
        raise ClipError("the trajectory has no sample")
    frames: dict[str, list[np.ndarray]] = {v: [] for v in cameras}
    for pose in trajectory_poses(traj, idx):
        set_pose(renderer, *pose)
        for v, cam in cameras.items():
            frames[v].append(renderer.draw(cam))
    return frames


def encode_webm(frames: Sequence[np.ndarray], fps: float = CLIP_FPS) -> bytes:
    """WebM bytes (VP9, yuv420p, constant quality :data:`VP9_CRF`, one thread, bit-exact muxing) of
    ``frames`` (each (H, W, 3) uint8, H and W even) played at ``fps``.

    Raises:
        ImportError: PyAV is not installed.
        ValueError: no frame, frames of different sizes or odd sizes.
    """
    import av

    if not frames:
        raise ValueError("no frame to encode")
    h, w = frames[0].shape[:2]
    if h % 2 or w % 2 or any(f.shape != frames[0].shape for f in frames):
        raise ValueError(f"frames must share one even size; first is {w}x{h}")
    buf = io.BytesIO()
    with av.open(buf, "w", format="webm", container_options={"fflags": "+bitexact"}) as out:
        stream = out.add_stream("libvpx-vp9", rate=Fraction(fps).limit_denominator(1000))
        stream.width, stream.height, stream.pix_fmt = w, h, "yuv420p"
        stream.options = {"crf": str(VP9_CRF), "b:v": "0", "deadline": "realtime", "cpu-used": "8", "threads": "1"}
        for f in frames:
            for packet in stream.encode(av.VideoFrame.from_ndarray(np.ascontiguousarray(f), format="rgb24")):
                out.mux(packet)
        for packet in stream.encode():
            out.mux(packet)
    return buf.getvalue()


def write_clip(folder: Path | str, stem: str, frames: Sequence[np.ndarray], *, joint: str, motion: Motion, view: str,
               fps: float = CLIP_FPS, poster_index: int | None = None, relative_to: Path | str | None = None) -> Clip:
    """Write ``<stem>.webm``, ``<stem>_poster.png`` (frame ``poster_index``, default the middle one) and
    :data:`STILLS` stills ``<stem>_<k>.png`` into ``folder`` (atomically); returns the :class:`Clip` with
    paths relative to ``relative_to`` (default ``folder``). ``stem`` must be a safe file name (the caller
    builds it from :func:`asset2sim.file_names` rules). Raises ValueError / ImportError as
    :func:`encode_webm`, OSError: the folder cannot be written."""
    folder = Path(folder)
    base = Path(relative_to) if relative_to is not None else folder
    rel = lambda p: p.relative_to(base).as_posix()  # noqa: E731
    video = atomic.write_bytes(folder / f"{stem}.webm", encode_webm(frames, fps))
    k = len(frames)
    poster = write_png(folder / f"{stem}_poster.png", frames[k // 2 if poster_index is None else int(poster_index)])
    picks = sorted(set(np.linspace(0, k - 1, min(STILLS, k)).round().astype(int).tolist()))
    stills = [write_png(folder / f"{stem}_{i}.png", frames[j]) for i, j in enumerate(picks)]
    h, w = frames[0].shape[:2]
    return Clip(joint=joint, motion=motion, view=view, video=rel(video), poster=rel(poster), frames=[rel(p) for p in stills],
                fps=float(fps), n_frames=k, duration_s=float((k - 1) / fps), width=int(w), height=int(h))


def sweep_clips(urdf: Path | str, sweep: SweepRun, joints: Sequence[str], others: Mapping[str, float], out_dir: Path | str,
                *, task_run=None) -> ClipSet:
    """Clips of the joint sweep of each joint of ``joints`` (in order, at most :data:`MAX_CLIP_JOINTS`) from each of
    :data:`CLIP_VIEWS` (:data:`CLIP_SIZE` pixels, :data:`CLIP_FPS` frames per simulated second), written into
    ``out_dir/clips/`` with ``clips.json``. ``others``: every joint's position
    during the sweep of another (the initial state), rad or m. A joint without a recorded sweep is listed
    in ``skipped`` with the reason. ``task_run``: the task execution's run (a
    :class:`~asset2sim.tasks.check.task_execution.TaskRun`), whose recorded attempts get clips too, at most
    :data:`MAX_CLIP_JOINTS`: the object as the gripper moved it (root free or mounted as simulated), the grasp point
    drawn as a red dot while held (``clips/task_<n>_<view>.*``; an attempt without a recorded motion in ``skipped``
    as ``<joint> <action>``).

    Raises:
        ImportError: PyAV is not installed.
        RenderError / FileNotFoundError: the URDF cannot be drawn.
        OSError: the folder cannot be written.
    """
    folder = Path(out_dir) / CLIPS_DIR
    by_joint = {js.joint: js for js in sweep.joints}
    clips: list[Clip] = []
    chosen = list(dict.fromkeys(joints))
    skipped = {name: f"only {MAX_CLIP_JOINTS} joints get clips (one of each kind of part first, the task's first)"
               for name in chosen[MAX_CLIP_JOINTS:]}
    todo = []
    for name in chosen[:MAX_CLIP_JOINTS]:
        js = by_joint.get(name)
        if js is None:
            skipped[name] = sweep.skipped.get(name, "not swept")
            continue
        try:
            todo.append((js, sweep_trajectory(js, others)))
        except ValueError as exc:
            skipped[name] = str(exc)
    with contextlib.ExitStack() as stack:  # one renderer for every clip of the asset
        r = stack.enter_context(SceneRenderer(urdf, size=CLIP_SIZE, supersample=1)) if todo or task_run is not None else None
        for n, (js, traj) in enumerate(todo):
            far = int(np.argmax(np.abs(traj.joints[js.joint] - js.q_closed)))
            frames = draw_frames(r, traj, fit_cameras(pose_points(r, fit_poses(traj, extra=[far])), CLIP_VIEWS))
            poster = int(np.argmin(np.abs(np.asarray(traj.sampled(CLIP_FPS)) - far)))
            for v in CLIP_VIEWS:
                clips.append(write_clip(folder, f"sweep_{n:02d}_{v}", frames[view_spec(v).name], joint=js.joint, motion="sweep",
                                        view=v, poster_index=poster))
        tasks = []
        for att in list(getattr(task_run, "attempts", []))[:MAX_CLIP_JOINTS]:
            try:
                tasks.append((att, task_trajectory(att)))
            except ValueError as exc:
                skipped[f"{att.joint} {att.action}"] = str(exc)
        for n, (att, traj) in enumerate(tasks):
            cams = fit_cameras(pose_points(r, fit_poses(traj)), CLIP_VIEWS)
            frames = draw_frames(r, traj, cams)
            for v in CLIP_VIEWS:
                name = view_spec(v).name
                marked = [draw_mark(img, project(cams[name], traj.marks[i][None], CLIP_SIZE)[0])
                          for img, i in zip(frames[name], traj.sampled(CLIP_FPS))]
                clips.append(write_clip(folder, f"task_{n:02d}_{v}", marked, joint=att.joint, motion="task", view=v))
    clip_set = ClipSet(clips=clips, skipped=skipped)
    atomic.write_json(folder / CLIPS_JSON, clip_set.model_dump(mode="json"))
    return clip_set


def task_trajectory(attempt) -> Trajectory:
    """A task attempt's recorded motion (``attempt.trace``,
    :attr:`asset2sim.tasks.check.task_execution.TaskAttempt.trace`) as a trajectory: every joint, the root's
    pose, and the grasp point in ``marks`` (K, 3) m (NaN after the release), up to :data:`TASK_AFTER_RELEASE` after
    the release.

    Raises:
        ValueError: the attempt recorded no motion (it was already at its target).
    """
    tr = attempt.trace
    if not tr or not tr.get("t"):
        raise ValueError(f"joint {attempt.joint!r}: the task attempt ({attempt.action}) recorded no motion")
    t, grip = np.asarray(tr["t"], float), np.asarray(tr["grip"], float)
    held = np.flatnonzero(np.all(np.isfinite(grip), axis=1))
    end = len(t) if not len(held) else int(np.searchsorted(t, t[held[-1]] + TASK_AFTER_RELEASE, side="right"))
    return Trajectory(t=t[:end], joints={n: np.asarray(v, float)[:end] for n, v in tr["joints"].items()},
                      root_pos=np.asarray(tr["root_pos"], float)[:end], root_rot=np.asarray(tr["root_rot"], float)[:end],
                      marks=grip[:end])


def project(cam: Camera, points: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """Pixel coordinates (N, 2) (x right, y down; NaN behind the camera) of world ``points`` (N, 3) m through the
    pinhole ``cam`` (vertical field of view ``cam.fov_deg``) in an image of ``size`` (width, height)."""
    w, h = size
    f = cam.target - cam.eye
    f = f / np.linalg.norm(f)
    r = np.cross(f, cam.up)
    r = r / np.linalg.norm(r)
    u = np.cross(r, f)
    rel = np.asarray(points, float).reshape(-1, 3) - cam.eye
    z = rel @ f
    focal = (h / 2) / math.tan(math.radians(cam.fov_deg) / 2)
    with np.errstate(divide="ignore", invalid="ignore"):
        px = np.stack([w / 2 + focal * (rel @ r) / z, h / 2 - focal * (rel @ u) / z], axis=1)
    px[z <= 0] = np.nan
    return px


def draw_mark(image: np.ndarray, xy: np.ndarray) -> np.ndarray:
    """``image`` (H, W, 3) uint8 with a red dot in a white ring at pixel ``xy`` (2,) (nothing when NaN or
    outside): where the gripper holds the part."""
    if not np.all(np.isfinite(xy)):
        return image
    h, w = image.shape[:2]
    yy, xx = np.ogrid[:h, :w]
    d2 = (xx - xy[0]) ** 2 + (yy - xy[1]) ** 2
    out = image.copy()
    out[d2 <= 5.5 ** 2] = (255, 255, 255)  # a ring 1.5 px wide around a dot of 4 px radius
    out[d2 <= 4 ** 2] = (220, 30, 30)
    return out


def read_clip_set(folder: Path | str) -> ClipSet | None:
    """The :class:`ClipSet` of an output folder (``folder/clips/clips.json``), None when it has none.
    Raises ValueError: the file is not a valid clip list."""
    path = Path(folder) / CLIPS_DIR / CLIPS_JSON
    if not path.is_file():
        return None
    try:
        return ClipSet.model_validate_json(atomic.read_regular(path, 16 * 1024 * 1024))
    except ValueError as exc:
        raise ValueError(f"{path}: not a valid clip list: {exc}") from exc


def clip_videos(out_dir: Path | str) -> list[str]:
    """The videos ``out_dir/clips/clips.json`` lists, as paths relative to ``out_dir`` (``clips/<file>.webm``);
    empty when the folder has no readable clip list (the catalog's ``clips`` column)."""
    try:
        clip_set = read_clip_set(out_dir)
    except (OSError, ValueError):
        return []
    return [] if clip_set is None else [f"{CLIPS_DIR}/{c.video}" for c in clip_set.clips]
