"""Which engines exist and how one is opened: each engine module is imported
on first use and registers its factories with :mod:`asset2sim.engines.base`.
"""

from __future__ import annotations

import importlib
import sys
from pathlib import Path

from asset2sim.engines.base import (_ENGINES, _FILE_READERS, _SHAPE_WORLDS, _VIEWERS, EngineFactory, EngineUnavailable, EngineUnsupported,
                                    HeldPhysics, SessionOptions, ShapeWorld, SimSession, Viewer)
from asset2sim.engines.quiet import startup_quiet
from asset2sim.extras import install_hint
from asset2sim.urdf import UrdfSource, path_of

__all__ = ["available_engines", "known_engines", "open_session", "open_shape_world", "open_viewer", "read_held_physics"]

#: Engine -> (its module, the third-party packages it needs: its optional extra); the module itself is
#: imported unguarded, so its errors are never mistaken for a missing extra.
_LAZY: dict[str, tuple[str, tuple[str, ...]]] = {
    "pybullet": ("asset2sim.engines.pybullet_engine", ("pybullet",)),
    "physx": ("asset2sim.engines.physx_engine", ("sapien",)),
    "mujoco": ("asset2sim.engines.mujoco_engine", ("mujoco",)),
    "mjx": ("asset2sim.engines.mjx_engine", ("mujoco", "jax", "mujoco.mjx")),
    "newton": ("asset2sim.engines.newton_engine", ("newton", "warp", "scipy")),
    "ovphysx": ("asset2sim.engines.ovphysx_engine", ("ovphysx", "ovstage", "pxr")),
}


def read_held_physics(engine: str, fmt: str, path: Path | str, links: list[str], joints: list[str]) -> HeldPhysics:
    """Load ``path`` (format ``fmt``) with ``engine``'s own importer and read
    back its physics (:class:`HeldPhysics`) by the URDF names ``links`` and ``joints``.

    Raises:
        KeyError: unknown engine name.
        EngineUnavailable: the engine's package is not installed.
        EngineUnsupported: the engine has no reader for ``fmt``.
        Exception: whatever the engine raises when the file does not load.
    """
    return _lookup(engine, _FILE_READERS, (engine, fmt), f"has no {fmt} reader")(Path(path), list(links), list(joints))


def _lookup(engine: str, table: dict, key, missing: str):
    """``table[key]`` once ``engine`` is loaded (EngineUnsupported ``engine ... missing`` without it)."""
    _factory(engine)
    if key not in table:
        raise EngineUnsupported(f"engine {engine!r} {missing}")
    return table[key]


def known_engines() -> list[str]:
    """Names of every engine asset2sim knows (installed or not), sorted."""
    return sorted(set(_ENGINES) | set(_LAZY))


def available_engines() -> list[str]:
    """Names of engines that can be opened here (their packages import)."""
    out = []
    for name in known_engines():
        try:
            _factory(name)
        except EngineUnavailable:
            continue
        out.append(name)
    return out


def _factory(name: str) -> EngineFactory:
    if name not in _ENGINES and name not in _LAZY:
        raise KeyError(f"unknown engine {name!r}; known: {known_engines()}")
    if name in _LAZY:  # its packages checked on every open: one made unimportable since (sys.modules) is unavailable
        module, packages = _LAZY[name]
        for package in packages:
            try:
                if sys.modules.get(package) is not None:
                    continue
                with startup_quiet():
                    importlib.import_module(package)
            except ImportError as exc:  # optional extra missing
                raise EngineUnavailable(f"engine {name!r} unavailable: {install_hint(exc)}") from exc
        if name not in _ENGINES:
            importlib.import_module(module)
    return _ENGINES[name]


def open_session(engine: str, urdf_path: UrdfSource, options: SessionOptions | None = None, **attach) -> SimSession:
    """Open a :class:`SimSession` of ``urdf_path`` (a file, or a model loaded from its ``path``) in ``engine``; ``attach``: the
    caller's world to load into (PyBullet: ``client`` and ``ground``; PhysX: ``scene``).

    Raises:
        KeyError: unknown engine name.
        EngineUnavailable: the engine's package is not installed.
        RuntimeError: the engine failed to load the file.
        TypeError: the engine cannot attach to a caller's world.
    """
    return _factory(engine)(path_of(urdf_path), options or SessionOptions(), **attach)


def open_shape_world(engine: str = "pybullet") -> ShapeWorld:
    """Open an empty :class:`ShapeWorld` of ``engine``.

    Raises:
        KeyError: unknown engine name.
        EngineUnavailable: the engine's package is not installed.
        EngineUnsupported: the engine has no shape world.
    """
    return _lookup(engine, _SHAPE_WORLDS, engine, "has no free-shape collision world")()


def open_viewer(engine: str, urdf_path: Path | str) -> Viewer:
    """Load ``urdf_path`` into a :class:`Viewer` of ``engine``.

    Raises:
        KeyError: unknown engine name.
        EngineUnavailable: the engine's package is not installed.
        EngineUnsupported: the engine cannot draw images.
        RuntimeError: the engine could not load the file.
    """
    return _lookup(engine, _VIEWERS, engine, "cannot draw images")(Path(urdf_path))
