"""What a check simulates: a :class:`SimSource`, one URDF model that any engine opens a session of, whether a file
(:class:`UrdfFile`: an output folder's ``mobility.urdf``, a user's asset) or a refine's candidate in its scratch
workspace (:meth:`asset2sim.tasks.assemble.candidate.Workspace.source`). A check asks its source for the model and
for sessions and never opens a path itself, so the candidate it was handed is the one on disk whenever an engine
loads it.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Protocol, runtime_checkable

from asset2sim.engines.base import SessionOptions, SimSession
from asset2sim.engines.registry import open_session
from asset2sim.urdf import Mode, UrdfModel, UrdfSource, model_of, path_of

__all__ = ["SimSource", "UrdfFile"]


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
