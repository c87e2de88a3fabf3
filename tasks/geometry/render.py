"""Textured multi-view renders of an articulated object, headless on a CPU (PyBullet's
``ER_TINY_RENDERER``), root fixed at the origin in the base link frame, z up; PartNet-Mobility
objects face -x. Each view's camera is fitted to the visual vertices at the requested state.
Frames, views, drawing and timings: ``docs/design/renders.md``.

:mod:`.render_scene` makes the render-only URDF, :mod:`.render_meshes` drawable meshes,
:mod:`.render_camera` the cameras, :mod:`.render_images` the files; this module draws
(:class:`SceneRenderer`) and is the entry point (:func:`render_views`).
"""

from __future__ import annotations

import json
import math
import shutil
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterable, Mapping

import numpy as np

from asset2sim.frames import matrix_quat_wxyz, quat_wxyz_to_xyzw
from asset2sim.engines.registry import open_viewer
from asset2sim.tasks.ingest import partnet_mobility
from asset2sim.tasks.geometry.render_camera import FILL, VIEWS, Camera, ViewSpec, fit_camera, view_camera, view_spec
from asset2sim.tasks.geometry.render_images import BACKGROUND, render_contact_sheet, write_png
from asset2sim.tasks.geometry.render_meshes import DEFAULT_COLOR
from asset2sim.tasks.geometry.render_scene import prepare_scene

__all__ = [
    "ALBEDO_FLOOR", "AMBIENT", "BACKENDS", "BACKGROUND", "DEFAULT_COLOR", "DEFAULT_VIEWS", "OUTPUT_VIEW_SIZE", "DIFFUSE",
    "FILL", "SPECULAR", "VIEWS", "Camera", "RenderError", "RenderTimings", "SceneRenderer", "ViewSpec", "fit_camera",
    "read_joint_state", "render_contact_sheet", "render_views", "resolve_urdf", "write_png",
]

#: The five views of the SPEC's extraction stage.
DEFAULT_VIEWS: tuple[str, ...] = ("front", "back", "left", "right", "perspective")
#: (width, height) px of the views ``asset2sim refine`` writes (``views/``); ``asset2sim render`` keeps 256 x 256.
OUTPUT_VIEW_SIZE: tuple[int, int] = (192, 192)
BACKENDS: tuple[str, ...] = ("auto", "tiny")
#: Light coefficients (intensity = ambient + diffuse * cos + specular).
AMBIENT, DIFFUSE, SPECULAR = 0.38, 0.68, 0.1
#: Every diffuse color c is drawn as f + (1 - f) c with this f, so black materials still show shading.
ALBEDO_FLOOR = 0.22


class RenderError(RuntimeError):
    """The renderer could not load or draw the asset (message names the file)."""


def resolve_urdf(asset: Path | str) -> Path:
    """The URDF of ``asset``: the file itself, or the one of a folder
    (:func:`asset2sim.tasks.ingest.partnet_mobility.urdf_candidates`).

    Raises:
        FileNotFoundError: no such file or folder, or no URDF in the folder.
        ValueError: a folder with several URDFs and no ``mobility.urdf``.
    """
    asset = Path(asset)
    if asset.is_file():
        return asset
    if not asset.is_dir():
        raise FileNotFoundError(f"no such asset file or folder: {asset}")
    urdfs = partnet_mobility.urdf_candidates(asset)
    if len(urdfs) == 1:
        return urdfs[0]
    if not urdfs:
        raise FileNotFoundError(f"no mobility.urdf (or other .urdf) in {asset}")
    raise ValueError(f"{asset} has several URDFs and no mobility.urdf: {[u.name for u in urdfs]}")


def read_joint_state(path: Path | str) -> dict[str, float]:
    """Joint positions (rad or m) from an ``initial_state.json`` file
    ``{"initial_joint_positions": {joint: value}}``.

    Raises:
        FileNotFoundError: the file does not exist.
        ValueError: not JSON, not that shape, or a value that is not a finite number.
    """
    path = Path(path)
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except json.JSONDecodeError as exc:
        raise ValueError(f"{path}: not valid JSON ({exc})") from exc
    if not isinstance(data, dict) or not isinstance(data.get("initial_joint_positions"), dict):
        raise ValueError(f'{path}: expected {{"initial_joint_positions": {{joint: value}}}}')
    out: dict[str, float] = {}
    for name, value in data["initial_joint_positions"].items():
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise ValueError(f"{path}: joint {name!r} has position {value!r}, not a finite number")
        out[str(name)] = float(value)
    return out


@dataclass
class RenderTimings:
    """Wall times, s: ``prepare``, ``load`` (PyBullet) and ``views`` (name -> time of each render)."""

    prepare: float = 0.0
    load: float = 0.0
    views: dict[str, list[float]] = field(default_factory=dict)


class SceneRenderer:
    """One asset loaded once, rendered at any joint state from any view.

    Use as a context manager (or call :meth:`close`)::

        with SceneRenderer(urdf) as r:
            r.set_joint_positions({"joint_0": 0.5})
            img = r.render("front")          # (H, W, 3) uint8

    Args:
        urdf_path: the URDF; its meshes are resolved relative to it.
        size: (width, height) of the output images, pixels.
        backend: ``"auto"`` or ``"tiny"``: PyBullet's TinyRenderer on the CPU.
        supersample: render this many times larger and box-filter down (1 = off).
        shadows: cast shadows (slower).

    Raises:
        FileNotFoundError: URDF or a visual mesh missing.
        ValueError: bad size / backend / supersample, URDF without visual geometry.
        RenderError: PyBullet could not load the asset.
    """

    def __init__(self, urdf_path: Path | str, *, size: tuple[int, int] = (256, 256), backend: str = "auto",
                 supersample: int = 2, shadows: bool = False):
        w, h = (int(v) for v in size)
        if w < 8 or h < 8 or w > 8192 or h > 8192:
            raise ValueError(f"image size must be within 8..8192 pixels, got {size}")
        if backend not in BACKENDS:
            raise ValueError(f"unknown render backend {backend!r}; known: {BACKENDS}")
        if int(supersample) < 1 or int(supersample) > 4:
            raise ValueError(f"supersample must be 1..4, got {supersample}")
        self.size = (w, h)
        self.backend = "tiny" if backend == "auto" else backend
        self.supersample = int(supersample)
        self.shadows = bool(shadows)
        self.timings = RenderTimings()
        self.urdf_path = Path(urdf_path)
        self._viewer = None
        self._root0: tuple[np.ndarray, np.ndarray] | None = None
        self._own_colors: list | None = None
        self._work = Path(tempfile.mkdtemp(prefix="asset2sim-render-"))
        try:
            t0 = time.perf_counter()
            self._prep = prepare_scene(self.urdf_path, self._work, texture_max=max(w, h) * self.supersample)
            self.notes = list(self._prep.notes)
            t1 = time.perf_counter()
            self._load()
            self.timings.prepare = t1 - t0
            self.timings.load = time.perf_counter() - t1
        except BaseException:
            self.close()
            raise

    def _load(self) -> None:
        try:
            self._viewer = open_viewer("pybullet", self._prep.urdf)
        except RuntimeError as exc:
            raise RenderError(f"PyBullet could not load {self.urdf_path} for rendering: {exc.__cause__ or exc}") from exc
        f = ALBEDO_FLOOR  # each visual's diffuse color c drawn as f + (1 - f) c
        for link, k, rgba in self._viewer.visual_colors():
            self._viewer.set_visual_color(link, k, [f + (1 - f) * c for c in rgba[:3]] + [rgba[3]])
        self.joint_names: list[str] = list(self._viewer.joint_names)

    def set_joint_positions(self, q: Mapping[str, float] | None) -> None:
        """Set joints (rad or m) by name; others keep their position (initially zero); limits not applied.

        Raises:
            KeyError: a name that is not a movable joint of the URDF.
            ValueError: a non-finite value.
        """
        if not q:
            return
        for name, value in q.items():
            if name not in self.joint_names:
                raise KeyError(f"{self.urdf_path}: no movable joint named {name!r}; movable joints: {self.joint_names}")
            v = float(value)
            if not math.isfinite(v):
                raise ValueError(f"joint {name!r}: position {value!r} is not finite")
            self._viewer.set_joint_positions({name: v})

    def color_links(self, colors: Mapping[str, Iterable[float]] | None, others: Iterable[float] | None = None) -> None:
        """Draw each link of ``colors`` (link name -> RGBA, each in 0..1) in its colour and, with ``others``, every
        other link in that one (a pale grey makes two parts stand out); ``colors`` None: the asset's own colours
        again.

        Raises:
            KeyError: a link name the URDF has no visual of.
        """
        if self._own_colors is None:
            self._own_colors = list(self._viewer.visual_colors())
        known = {link for link, _, _ in self._own_colors}
        missing = [n for n in (colors or {}) if n not in known]
        if missing:
            raise KeyError(f"{self.urdf_path}: no visual of link(s) {missing}")
        for link, k, rgba in self._own_colors:
            c = colors.get(link) if colors is not None else None
            if c is None and colors is not None and others is not None:
                c = others
            self._viewer.set_visual_color(link, k, rgba if c is None else tuple(map(float, c)))

    def turn_root(self, rotation: np.ndarray) -> None:
        """Draw the object turned by ``rotation`` (3, 3) about the world origin from its pose as loaded (a
        tilted or toppled object as it lies; the cameras fit whatever pose)."""
        if self._root0 is None:
            self._root0 = self.root_pose()
        pos0, R0 = self._root0
        R = np.asarray(rotation, float)
        self._viewer.set_root_pose(R @ pos0, quat_wxyz_to_xyzw(matrix_quat_wxyz(R @ R0)))

    def place_root(self, position: np.ndarray, rotation: np.ndarray) -> None:
        """Put the root link's frame at ``position`` (3,) m with ``rotation`` (3, 3), in the world frame (a
        pose a simulator recorded)."""
        self._viewer.set_root_pose(np.asarray(position, float), quat_wxyz_to_xyzw(matrix_quat_wxyz(np.asarray(rotation, float))))

    def root_pose(self) -> tuple[np.ndarray, np.ndarray]:
        """(position (3,) m, rotation (3, 3)) of the root link's frame in the world now."""
        return self._viewer.link_frame(self._viewer.link_names[0])

    def world_points(self) -> np.ndarray:
        """Visual vertices (N, 3) of all links in the base frame, m, at the current state."""
        out = []
        links = set(self._viewer.link_names)
        for lname, local in self._prep.link_points.items():
            if lname not in links:
                continue
            pos, R = self._viewer.link_frame(lname)
            out.append(local @ R.T + pos)
        return np.concatenate(out)

    def camera(self, view: str | ViewSpec) -> Camera:
        """The fitted camera of ``view`` at the current joint state.

        Raises:
            KeyError: unknown view name.
        """
        return view_camera(self.world_points(), view, aspect=self.size[0] / self.size[1])

    def render(self, view: str | ViewSpec) -> np.ndarray:
        """RGB image (H, W, 3) uint8 of ``view`` at the current joint state.

        Raises:
            KeyError: unknown view name.
            RenderError: the renderer returned no image.
        """
        spec = view_spec(view)
        t0 = time.perf_counter()
        img = self._draw(self.camera(spec))
        self.timings.views.setdefault(spec.name, []).append(time.perf_counter() - t0)
        return img

    def draw(self, cam: Camera) -> np.ndarray:
        """RGB image (H, W, 3) uint8 through ``cam`` (a fixed camera, e.g. fitted once for a whole clip) at
        the current joint state. Raises RenderError: the renderer returned no image."""
        t0 = time.perf_counter()
        img = self._draw(cam)
        self.timings.views.setdefault("camera", []).append(time.perf_counter() - t0)
        return img

    def _draw(self, cam: Camera) -> np.ndarray:
        w, h = self.size
        s = self.supersample
        W, H = w * s, h * s
        # light from the camera's upper left, fixed relative to the camera
        b = cam.eye - cam.target
        b /= np.linalg.norm(b)
        r = np.cross(-b, cam.up)
        r /= np.linalg.norm(r)
        light = b * 1.0 + cam.up * 0.75 - r * 0.6
        light /= np.linalg.norm(light)
        dist = float(np.linalg.norm(cam.eye - cam.target))
        try:
            rgba, seg = self._viewer.draw(
                W, H, {"eye": cam.eye, "target": cam.target, "up": cam.up, "fov_deg": cam.fov_deg, "near": cam.near, "far": cam.far},
                {"direction": light, "color": (1.0, 1.0, 1.0), "distance": dist * 4, "shadow": self.shadows,
                 "ambient": AMBIENT, "diffuse": DIFFUSE, "specular": SPECULAR})
        except RuntimeError as exc:
            raise RenderError(f"{self.urdf_path}: {exc}") from exc
        alpha = (seg >= 0).astype(np.float32)
        rgb = rgba[:, :, :3].astype(np.float32)
        bg = np.asarray(BACKGROUND, np.float32)
        comp = rgb * alpha[..., None] + bg * (1.0 - alpha[..., None])
        if s > 1:
            comp = comp.reshape(h, s, w, s, 3).mean(axis=(1, 3))
        return np.clip(np.rint(comp), 0, 255).astype(np.uint8)

    def close(self) -> None:
        """Disconnect from PyBullet and delete the temporary files."""
        if self._viewer is not None:
            self._viewer.close()
            self._viewer = None
        if self._work is not None:
            shutil.rmtree(self._work, ignore_errors=True)
            self._work = None

    def __enter__(self) -> "SceneRenderer":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def __del__(self):  # pragma: no cover - best effort
        try:
            self.close()
        except Exception:
            pass


def render_views(urdf_path: Path | str, joint_positions: Mapping[str, float] | None = None,
                 out_dir: Path | str | None = None, *, views: Iterable[str] = DEFAULT_VIEWS,
                 size: tuple[int, int] = (256, 256), backend: str = "auto") -> dict[str, np.ndarray]:
    """Render ``views`` of the object at ``joint_positions``.

    Args:
        urdf_path: the URDF (meshes resolved relative to it).
        joint_positions: joint name -> position, rad or m; joints not named stay at zero.
        out_dir: when given, each view is also written (atomically) to ``out_dir/<view>.png``.
        views: names from :data:`VIEWS` (default the five of the SPEC).
        size: (width, height) in pixels.
        backend: see :class:`SceneRenderer` (at its defaults: supersampled, no shadows).

    Returns:
        view name -> RGB image (height, width, 3) uint8, in the order of ``views``.

    Raises:
        FileNotFoundError: the URDF or one of its visual meshes is missing.
        KeyError: an unknown view or joint name.
        ValueError: a bad size, backend, joint value or a URDF without visuals.
        RenderError: PyBullet failed to load or draw the asset.
        OSError: ``out_dir`` cannot be written.
    """
    views = list(views)
    for v in views:
        view_spec(v)
    with SceneRenderer(urdf_path, size=size, backend=backend) as r:
        r.set_joint_positions(joint_positions)
        images = {v: r.render(v) for v in views}
    if out_dir is not None:
        for v, img in images.items():
            write_png(Path(out_dir) / f"{v}.png", img)
    return images
