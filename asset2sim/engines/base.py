"""Simulator protocol and registry.

An *engine* opens a :class:`SimSession` on a URDF under the SPEC's measurement
conventions ("How quality is measured"):

- timestep 1/240 s, gravity -9.81 m/s^2 along z, a ground plane at z = 0;
- self-collision on except between a link and its parent;
- inertia taken from the file;
- the root free (not fixed), placed so its lowest collision point touches the
  ground, joints at the initial state;
- passive joints: Coulomb friction as a zero-target-velocity motor whose maximum
  force is ``<dynamics friction>``, viscous damping ``<dynamics damping>``, and a
  spring torque -k (q - q_s) applied each step where the overlay has one.

Metrics (``asset2sim.tasks.check.metrics``) only use this protocol, so the same
definitions run in every engine. Engines register with :func:`register_engine`;
heavy engines are imported lazily by name.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Protocol

import numpy as np

from asset2sim.schemas.config import SimConventions


@dataclass(frozen=True)
class Spring:
    """A joint spring: torque/force -stiffness * (q - reference) each step.

    ``stiffness`` N*m/rad or N/m, ``reference`` rad or m.
    """

    stiffness: float
    reference: float


@dataclass
class ContactPair:
    """Penetration between two links of the same body.

    ``depth`` m: sum over the pair's contact points of max(0, -separation);
    ``max_depth`` m: the deepest point.
    """

    link_a: str
    link_b: str
    depth: float
    max_depth: float
    points: int


@dataclass
class SessionOptions:
    """How to open a session.

    ``initial_state``: joint name -> position (rad or m). ``springs``: joint name
    -> :class:`Spring`. ``fixed_base``: pin the root (used only by state
    refinement, never by the SPEC's metrics). ``gravity``: False disables it
    (contact queries only).
    """

    initial_state: dict[str, float] = field(default_factory=dict)
    springs: dict[str, Spring] = field(default_factory=dict)
    fixed_base: bool = False
    gravity: bool = True
    ground: bool = True
    conventions: SimConventions = field(default_factory=SimConventions)


class SimSession(Protocol):
    """One loaded asset in one engine."""

    engine: str
    joint_names: list[str]
    """Movable (revolute, continuous, prismatic) joints, in file order."""
    joint_types: dict[str, str]
    joint_limits: dict[str, tuple[float, float]]

    def set_joint_positions(self, q: dict[str, float], zero_velocity: bool = True) -> None:
        """Teleport joints (rad or m); unspecified joints keep their value."""

    def joint_positions(self) -> dict[str, float]:
        """Current joint positions (rad or m)."""

    def self_penetration(self) -> tuple[float, list[ContactPair]]:
        """Phi (m) = sum over self-contact points of max(0, -separation), and the
        pairs sorted by depth (deepest first). Contacts with the ground excluded."""

    def ground_penetration(self) -> float:
        """Deepest penetration of any link into the ground plane, m (>= 0)."""

    def root_pose(self) -> tuple[np.ndarray, np.ndarray]:
        """Root link position (3,) m and orientation quaternion (4,) x, y, z, w."""

    def step(self, n: int = 1) -> None:
        """Advance n timesteps, applying springs each step."""

    def close(self) -> None:
        """Release the engine's resources."""


EngineFactory = Callable[[Path, SessionOptions], SimSession]

_ENGINES: dict[str, EngineFactory] = {}
_LAZY: dict[str, str] = {
    "pybullet": "asset2sim.engines.pybullet_engine",
    "physx": "asset2sim.engines.physx_engine",
    "mujoco": "asset2sim.engines.mujoco_engine",
    "fake": "asset2sim.engines.fake",
}


class EngineUnavailable(RuntimeError):
    """The engine's Python package is not installed (an optional extra)."""


def register_engine(name: str, factory: EngineFactory) -> None:
    """Register ``factory(urdf_path, options) -> SimSession`` under ``name``."""
    _ENGINES[name] = factory


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
        try:
            importlib.import_module(module)
        except ImportError as exc:  # optional extra missing
            raise EngineUnavailable(f"engine {name!r} is not installed ({exc})") from exc
    return _ENGINES[name]


def open_session(engine: str, urdf_path: Path | str, options: SessionOptions | None = None) -> SimSession:
    """Open a :class:`SimSession` of ``urdf_path`` in ``engine``.

    Raises:
        KeyError: unknown engine name.
        EngineUnavailable: the engine's package is not installed.
        RuntimeError: the engine failed to load the file.
    """
    return _factory(engine)(Path(urdf_path), options or SessionOptions())


def quat_angle(q0: np.ndarray, q1: np.ndarray) -> float:
    """Rotation angle (rad, in [0, pi]) between two unit quaternions (4,) xyzw."""
    d = abs(float(np.dot(np.asarray(q0, float), np.asarray(q1, float))))
    return float(2.0 * np.arccos(min(1.0, d)))
