"""Named views (PartNet-Mobility objects face -x, z up) and cameras fitted to an object's points, for
:mod:`asset2sim.tasks.geometry.render`."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np


@dataclass(frozen=True)
class ViewSpec:
    """Where a named view's camera sits, seen from the object's center: ``azimuth_deg`` in the xy plane
    from +x toward +y, ``elevation_deg`` above it (90 = top)."""

    name: str
    azimuth_deg: float
    elevation_deg: float

    def direction(self) -> np.ndarray:
        """Unit vector (3,) from the object's center toward the camera."""
        az, el = math.radians(self.azimuth_deg), math.radians(self.elevation_deg)
        return np.array([math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)])


#: Named views ("left"/"right" are the object's own sides).
VIEWS: dict[str, ViewSpec] = {v.name: v for v in (
    ViewSpec("front", 180.0, 20.0), ViewSpec("back", 0.0, 20.0), ViewSpec("left", -90.0, 20.0),
    ViewSpec("right", 90.0, 20.0), ViewSpec("perspective", -135.0, 30.0), ViewSpec("top", 180.0, 90.0))}
#: Vertical field of view of every camera, degrees.
FOV_DEG = 35.0
#: Fraction of the image's half-size that the object's farthest point reaches.
FILL = 0.88


@dataclass(frozen=True)
class Camera:
    """A pinhole camera: ``eye``/``target``/``up`` (3,) in m, vertical ``fov_deg``,
    clipping ``near``/``far`` in m."""

    eye: np.ndarray
    target: np.ndarray
    up: np.ndarray
    fov_deg: float
    near: float
    far: float


def fit_camera(points: np.ndarray, direction: np.ndarray, *, up: Sequence[float] = (0.0, 0.0, 1.0), aspect: float = 1.0) -> Camera:
    """The camera looking at ``points`` (N, 3) m from ``direction`` (3,) (object -> camera) with every
    point inside :data:`FILL` of the image's half-extent, the projected extent centered; ``aspect`` is
    width / height; the vertical field of view is :data:`FOV_DEG`.

    Raises:
        ValueError: no points or a non-finite point.
    """
    P = np.asarray(points, float).reshape(-1, 3)
    if not len(P) or not np.isfinite(P).all():
        raise ValueError("fit_camera needs at least one finite point")
    b = np.asarray(direction, float)
    b = b / np.linalg.norm(b)
    upv = np.asarray(up, float)
    if abs(float(np.dot(upv / np.linalg.norm(upv), b))) > 0.999:  # looking along the up vector
        upv = np.array([1.0, 0.0, 0.0]) if abs(b[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    f = -b
    r = np.cross(f, upv)
    r /= np.linalg.norm(r)
    u = np.cross(r, f)
    lo, hi = P.min(0), P.max(0)
    extent = max(float(np.linalg.norm(hi - lo)), 1e-6)
    target = (lo + hi) / 2
    ty = math.tan(math.radians(FOV_DEG) / 2) * FILL
    tx = ty * aspect
    d = extent
    for _ in range(4):
        rel = P - target
        x, y, z = rel @ r, rel @ u, rel @ b
        d = float(max(np.max(z + np.abs(x) / tx), np.max(z + np.abs(y) / ty), extent * 1e-3))
        depth = d - z
        X, Y = x / depth, y / depth
        cx, cy = (X.max() + X.min()) / 2, (Y.max() + Y.min()) / 2
        if abs(cx) < 1e-4 * tx and abs(cy) < 1e-4 * ty:
            break
        target = target + (r * cx + u * cy) * d
    rel = P - target
    depth = d - rel @ b
    near = max(float(depth.min()) * 0.5, extent * 1e-4)
    far = float(depth.max()) * 1.5 + extent * 0.1
    return Camera(target + b * d, target, u, FOV_DEG, near, far)


def view_spec(view: str | ViewSpec) -> ViewSpec:
    """``view`` itself, or the named view of :data:`VIEWS`.

    Raises:
        KeyError: unknown view name.
    """
    if isinstance(view, ViewSpec):
        return view
    try:
        return VIEWS[view]
    except KeyError:
        raise KeyError(f"unknown view {view!r}; known views: {list(VIEWS)}") from None


def view_camera(points: np.ndarray, view: str | ViewSpec, aspect: float = 1.0) -> Camera:
    """The camera of ``view`` (a name of :data:`VIEWS` or a :class:`ViewSpec`) fitted to ``points`` (N, 3) m for an
    image of ``aspect`` = width / height: :func:`fit_camera` with the view's direction, the world's z up (x up when
    looking straight down).

    Raises:
        KeyError: unknown view name. ValueError: no points or a non-finite point.
    """
    spec = view_spec(view)
    up = (1.0, 0.0, 0.0) if spec.elevation_deg >= 89.9 else (0.0, 0.0, 1.0)
    return fit_camera(points, spec.direction(), up=up, aspect=aspect)
