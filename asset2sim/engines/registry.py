"""Which engines exist and how one is opened: the engine modules
(``pybullet_engine``, ``physx_engine``, ``mujoco_engine``, ``newton_engine``,
``fake``) are imported on first use, each registering its factories with
:mod:`asset2sim.engines.base` (which holds the protocols and the
registries), so an engine whose package is not installed costs nothing
until asked for. Stages open sessions, shape worlds and viewers here.
"""

from __future__ import annotations

import importlib
from pathlib import Path

from asset2sim.engines.base import (
    _ENGINES,
    _FILE_READERS,
    _SHAPE_WORLDS,
    _VIEWERS,
    EngineFactory,
    EngineUnavailable,
    EngineUnsupported,
    HeldPhysics,
    SessionOptions,
    ShapeWorld,
    SimSession,
    Viewer,
)
from asset2sim.engines.quiet import startup_quiet

__all__ = ["available_engines", "known_engines", "open_session", "open_shape_world", "open_viewer", "read_held_physics"]

_LAZY: dict[str, str] = {
    "pybullet": "asset2sim.engines.pybullet_engine",
    "physx": "asset2sim.engines.physx_engine",
    "mujoco": "asset2sim.engines.mujoco_engine",
    "newton": "asset2sim.engines.newton_engine",
    "fake": "asset2sim.engines.fake",
}
#: The third-party packages each engine module needs (its optional extra):
#: when one does not import, the engine is unavailable; the project's own
#: module is then imported unguarded, so an error in it is never mistaken
#: for a missing extra.
_REQUIRES: dict[str, tuple[str, ...]] = {
    "pybullet": ("pybullet",),
    "physx": ("sapien",),
    "mujoco": ("mujoco",),
    "newton": ("newton", "warp", "scipy"),
    "fake": (),
}


def read_held_physics(engine: str, fmt: str, path: Path | str, links: list[str], joints: list[str]) -> HeldPhysics:
    """Load ``path`` (format ``fmt``) with ``engine``'s own importer and read
    back every link's and joint's physics (:class:`HeldPhysics`), by the URDF
    names ``links`` and ``joints``.

    Raises:
        KeyError: unknown engine name.
        EngineUnavailable: the engine's package is not installed.
        EngineUnsupported: the engine has no reader for ``fmt``.
        Exception: whatever the engine raises when the file does not load.
    """
    _factory(engine)
    if (engine, fmt) not in _FILE_READERS:
        raise EngineUnsupported(f"engine {engine!r} has no {fmt} reader")
    return _FILE_READERS[(engine, fmt)](Path(path), list(links), list(joints))


def known_engines() -> list[str]:
    """Names of every engine asset2sim knows (installed or not), sorted."""
    return sorted(set(_ENGINES) | set(_LAZY))


def available_engines() -> list[str]:
    """Names of engines that can be opened here (their packages import)."""
    out = []
    for name in sorted(set(_ENGINES) | set(_LAZY)):
        try:
            _factory(name)
        except EngineUnavailable:
            continue
        out.append(name)
    return out


def _factory(name: str) -> EngineFactory:
    if name not in _ENGINES:
        module = _LAZY.get(name)
        if module is None:
            raise KeyError(f"unknown engine {name!r}; known: {sorted(set(_ENGINES) | set(_LAZY))}")
        for package in _REQUIRES.get(name, ()):
            try:
                with startup_quiet():
                    importlib.import_module(package)
            except ImportError as exc:  # optional extra missing
                raise EngineUnavailable(f"engine {name!r} is not installed ({exc})") from exc
        importlib.import_module(module)
    return _ENGINES[name]


def open_session(engine: str, urdf_path: Path | str, options: SessionOptions | None = None, **attach) -> SimSession:
    """Open a :class:`SimSession` of ``urdf_path`` in ``engine``.

    ``attach``: the caller's world to load into instead of a new one the
    session owns (PyBullet: ``client`` id and ``ground``; PhysX: ``scene``).

    Raises:
        KeyError: unknown engine name.
        EngineUnavailable: the engine's package is not installed.
        RuntimeError: the engine failed to load the file.
        TypeError: the engine cannot attach to a caller's world.
    """
    return _factory(engine)(Path(urdf_path), options or SessionOptions(), **attach)


def open_shape_world(engine: str = "pybullet") -> ShapeWorld:
    """Open an empty :class:`ShapeWorld` of ``engine``.

    Raises:
        KeyError: unknown engine name.
        EngineUnavailable: the engine's package is not installed.
        EngineUnsupported: the engine has no shape world.
    """
    _factory(engine)
    if engine not in _SHAPE_WORLDS:
        raise EngineUnsupported(f"engine {engine!r} has no free-shape collision world")
    return _SHAPE_WORLDS[engine]()


def open_viewer(engine: str, urdf_path: Path | str) -> Viewer:
    """Load ``urdf_path`` into a :class:`Viewer` of ``engine``.

    Raises:
        KeyError: unknown engine name.
        EngineUnavailable: the engine's package is not installed.
        EngineUnsupported: the engine cannot draw images.
        RuntimeError: the engine could not load the file.
    """
    _factory(engine)
    if engine not in _VIEWERS:
        raise EngineUnsupported(f"engine {engine!r} cannot draw images")
    return _VIEWERS[engine](Path(urdf_path))
