"""What a check simulates: a :class:`SimSource`, one URDF model that any engine opens a session of, whether a file
(:class:`UrdfFile`: an output folder's ``mobility.urdf``, a user's asset) or a refine's candidate in its scratch
workspace (:meth:`asset2sim.tasks.assemble.candidate.Workspace.source`). A check asks its source for the model and
for sessions and never opens a path itself, so the candidate it was handed is the one on disk whenever an engine
loads it.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType
from typing import Protocol, runtime_checkable

from asset2sim.engines.base import SessionOptions, SimSession, Spring, session_root_options
from asset2sim.engines.registry import open_session
from asset2sim.schemas.config import SimConventions
from asset2sim.urdf import Mode, UrdfModel, UrdfSource, model_of, path_of

__all__ = ["SimObject", "SimSource", "UrdfFile"]


@runtime_checkable
class SimSource(Protocol):
    """One URDF model the engines load (SI units, as written: scale baked in)."""

    @property
    def path(self) -> Path:
        """The URDF file an engine loads (written first where the source is a candidate not on disk)."""
        ...

    def model(self, mode: Mode = "strict") -> UrdfModel:
        """The model (a copy the caller may change), ``path`` set; ``mode`` as :func:`asset2sim.urdf.read_urdf`
        where the source reads a file. Raises UrdfError: the file cannot be read."""
        ...

    def open(self, engine: str, options: SessionOptions | None = None) -> SimSession:
        """A session of the model in ``engine`` (the caller closes it). Raises EngineUnavailable, RuntimeError:
        as :func:`asset2sim.engines.registry.open_session`."""
        ...


@dataclass(frozen=True)
class UrdfFile:
    """A URDF file, or a model read from or written to its file, as a :class:`SimSource`.

    Example: ``run_robust_rest("pybullet", UrdfFile(out / "mobility.urdf"), state)``.
    """

    source: UrdfSource

    @property
    def path(self) -> Path:
        """The file (:func:`asset2sim.urdf.path_of`). Raises UrdfError: a model without a file."""
        return path_of(self.source)

    def model(self, mode: Mode = "strict") -> UrdfModel:
        """:func:`asset2sim.urdf.model_of` of the file or model. Raises UrdfError: the file cannot be read."""
        return model_of(self.source, mode=mode)

    def open(self, engine: str, options: SessionOptions | None = None, **attach) -> SimSession:
        """:func:`asset2sim.engines.registry.open_session` of the file; ``attach`` as there."""
        return open_session(engine, self.source, options, **attach)


@dataclass(frozen=True)
class SimObject:
    """An object as the checks simulate it: its :class:`SimSource`, the initial joint positions ``state`` (joint ->
    rad or m), the joints' passive ``springs`` (joint -> :class:`asset2sim.engines.base.Spring`), the measurement
    ``conventions`` and whether its root is fixed as mounted (``fixed_base``; else it rests free on the ground).

    The mappings are frozen copies. Example:
    ``run_robust_rest("pybullet", SimObject(UrdfFile(out / "mobility.urdf"), state))``.
    """

    source: SimSource
    state: Mapping[str, float] = field(default_factory=dict)
    springs: Mapping[str, Spring] = field(default_factory=dict)
    conventions: SimConventions = field(default_factory=SimConventions)
    fixed_base: bool = False

    def __post_init__(self) -> None:
        object.__setattr__(self, "state", MappingProxyType({str(k): float(v) for k, v in self.state.items()}))
        object.__setattr__(self, "springs", MappingProxyType(dict(self.springs or {})))

    def options(self, **changes) -> SessionOptions:
        """The :class:`asset2sim.engines.base.SessionOptions` of the object as it is (state, springs, conventions; a
        mounted root fixed with no ground), with ``changes`` (SessionOptions fields) applied over them."""
        return SessionOptions(**{"initial_state": dict(self.state), "springs": dict(self.springs), "conventions": self.conventions,
                                 "object_root_fixed": self.fixed_base, **session_root_options(self.fixed_base), **changes})

    def open(self, engine: str, **changes) -> SimSession:
        """A session of the source in ``engine`` under :meth:`options` (``changes`` as there; the caller closes it).
        Raises EngineUnavailable, RuntimeError: as :meth:`SimSource.open`."""
        return self.source.open(engine, self.options(**changes))
