"""The working asset: a refine's candidate outputs held in memory (frozen :class:`Candidate`s; the stages
hand candidates over, never the output folder) and :class:`Workspace`, the scratch folder (outside the
output folder, removed when the refine ends) the engines load them from. The output folder is written
once, from the final candidate (:func:`asset2sim.tasks.publish.output.publish`).
"""

from __future__ import annotations

import os
import shutil
import stat
import tempfile
from dataclasses import dataclass, field, replace
from pathlib import Path
from types import MappingProxyType
from typing import Mapping

import numpy as np

from asset2sim import array_cache, atomic, file_names, mesh_io, urdf
from asset2sim.engines.base import SessionOptions, SimSession
from asset2sim.engines.registry import open_session
from asset2sim.schemas.asset import AssetDescription
from asset2sim.schemas.overlay import Overlay
from asset2sim.tasks.assemble import write
from asset2sim.tasks.geometry import analyze


@dataclass(frozen=True)
class Candidate:
    """One candidate output: the asset with ``overlay`` applied, its joints at
    ``state`` (joint -> rad or m, output units), the mesh collisions of the
    links in ``collision_overrides`` replaced by their convex pieces (link ->
    :class:`asset2sim.tasks.state.collision.CollisionPiece` tuple, paths
    relative to the folder the candidate is written into) and the (3, 3)
    ``root_rotation`` of a requested resting pose (None: as modelled)."""

    asset: AssetDescription
    overlay: Overlay
    state: Mapping[str, float]
    collision_overrides: Mapping[str, tuple] = field(default_factory=dict)
    root_rotation: np.ndarray | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "state", MappingProxyType({k: float(v) for k, v in self.state.items()}))
        if not isinstance(self.collision_overrides, MappingProxyType):  # frozen already: kept, so that
            # dataclasses.replace hands the same overrides on (a stage tells "unchanged" by identity)
            object.__setattr__(self, "collision_overrides",
                               MappingProxyType({k: tuple(v) for k, v in (self.collision_overrides or {}).items()}))

    def write_into(self, folder: Path, *, copy: bool, open_containers: bool = False) -> write.OutputPaths:
        """Write this candidate's files into ``folder``
        (:func:`asset2sim.tasks.assemble.write.write_output`; meshes copied
        when ``copy``; containers decomposed with ``open_containers``).

        Raises:
            OutputError: ``folder`` inside the input, or an incomplete overlay.
        """
        return write.write_output(self.asset, self.overlay, folder, dict(self.state), copy=copy,
                                  collision_overrides={k: list(v) for k, v in self.collision_overrides.items()},
                                  root_rotation=self.root_rotation, open_containers=open_containers)


def candidate_digest(candidate: Candidate, folder: Path) -> str:
    """Digest of what :meth:`Candidate.write_into` reads: the overlay, the state, the root rotation, the
    collision overrides with the bytes of their files (relative to ``folder``, where the stages wrote them)
    and the asset's URDF file."""
    parts: list[bytes | str] = [str(candidate.asset.urdf_path), candidate.overlay.model_dump_json(),
                                repr(sorted(candidate.state.items())),
                                b"" if candidate.root_rotation is None else np.asarray(candidate.root_rotation, float).tobytes()]
    for link in sorted(candidate.collision_overrides):
        for piece in candidate.collision_overrides[link]:
            parts.append(f"{link}\0{piece!r}")
            try:
                parts.append(mesh_io.file_bytes(file_names.join_inside(folder, piece.filename)))
            except (OSError, file_names.UnsafePath):  # written as named, it fails there with the file's name
                parts.append(b"\0unreadable")
    return array_cache.digest(*parts)


#: Name prefix of a workspace folder, followed by the process id of the refine that owns it.
SCRATCH_PREFIX = "asset2sim-candidates-"


def _remove_orphans(parent: Path) -> None:
    """Remove the workspace folders in ``parent`` that this user's processes left when killed (their
    owner's process id names no running process); never a symlink or another user's folder."""
    for entry in parent.glob(f"{SCRATCH_PREFIX}*-*"):
        pid = entry.name.removeprefix(SCRATCH_PREFIX).split("-", 1)[0]
        try:
            st = entry.lstat()
            if not (pid.isdigit() and stat.S_ISDIR(st.st_mode) and st.st_uid == os.getuid()):
                continue
            os.kill(int(pid), 0)
        except ProcessLookupError:
            shutil.rmtree(entry, ignore_errors=True)
        except OSError:  # gone meanwhile, or a process of another user holds that id
            continue


class Workspace:
    """The scratch folder a refine's engine sessions load candidates from:
    a fresh temporary folder (meshes copied into it once), removed by
    :meth:`close`. Only engines read what is written here. ``open_containers``:
    a container's collision is a decomposition that leaves its inside open
    (:func:`asset2sim.tasks.assemble.collision_geometry.link_pieces`); ``mesh_cache``: the refine's mesh analysis
    cache (:class:`asset2sim.tasks.geometry.analyze.MeshCache`), which the collision improvements made on its
    candidates share (a fresh one when None).

    A stage asks for the candidate it works on (:meth:`load`, :meth:`model`,
    :meth:`session`); the folder is written only when that candidate is not
    the one on disk (:func:`candidate_digest`), so asking again costs nothing.
    :attr:`writes` counts the writes."""

    def __init__(self, asset: AssetDescription, *, open_containers: bool = False,
                 mesh_cache: analyze.MeshCache | None = None):
        self.asset = asset
        self.open_containers = open_containers
        self.mesh_cache = mesh_cache if mesh_cache is not None else analyze.MeshCache()
        _remove_orphans(Path(tempfile.gettempdir()))
        self.root = Path(tempfile.mkdtemp(prefix=f"{SCRATCH_PREFIX}{os.getpid()}-")).resolve()
        atomic.add_scratch(self.root)  # engines read it and close() removes it: no fsync
        self._copied = False
        self.collision_notes: list[str] = []
        self._written: tuple[bytes, Path] | None = None  # the loaded URDF's bytes and path, parsed on demand
        self._model: urdf.UrdfModel | None = None
        self._digest: str | None = None  # candidate_digest of the candidate on disk
        self.writes = 0

    def load(self, candidate: Candidate) -> Path:
        """The scratch URDF of ``candidate`` for the engines to load: written
        into the scratch folder unless it is the candidate on disk already.
        :attr:`collision_notes` holds what the writer's convex pieces changed.

        Raises:
            OutputError: an incomplete overlay (see :meth:`Candidate.write_into`).
            OSError: a file cannot be read or written.
        """
        key = candidate_digest(candidate, self.root)
        if key == self._digest and self._written is not None:
            return self._written[1]
        self._digest = None  # a write that fails leaves no candidate on disk
        paths = candidate.write_into(self.root, copy=not self._copied, open_containers=self.open_containers)
        self._copied = True
        self.writes += 1
        self.collision_notes = list(paths.collision_notes)
        self._written, self._model, self._digest = (paths.urdf_bytes, paths.urdf), None, key
        return paths.urdf

    def collision_notes_of(self, candidate: Candidate) -> list[str]:
        """What the writer's convex pieces changed in ``candidate`` (loaded first)."""
        self.load(candidate)
        return list(self.collision_notes)

    def model(self, candidate: Candidate) -> urdf.UrdfModel:
        """The URDF model of ``candidate`` (loaded first) as the engines read it (parsed once from the bytes
        written, mesh paths in the scratch folder); a copy the caller may change.

        Raises:
            OutputError, OSError: as :meth:`load`.
        """
        self.load(candidate)
        if self._model is None:
            data, path = self._written
            self._model = urdf.parse_urdf_bytes(data, source=str(path), base=self.root)
            self._model.path = path
        return urdf.clone_model(self._model)

    def source(self, candidate: Candidate) -> "CandidateSource":
        """``candidate`` as the :class:`~asset2sim.engines.source.SimSource` the checks simulate: loaded into this
        workspace whenever its model, its file or a session of it is asked for."""
        return CandidateSource(self, candidate)

    def session(self, candidate: Candidate, engine: str = "pybullet", options: SessionOptions | None = None) -> SimSession:
        """A session of ``candidate`` (loaded first) in ``engine``
        (:func:`asset2sim.engines.registry.open_session`), its ``files_key`` the scratch folder and the candidate's
        digest (sessions of the candidate on disk may share what an engine kept of its files); the caller closes it.

        Raises:
            EngineUnavailable, RuntimeError: see :func:`asset2sim.engines.registry.open_session`.
        """
        path = self.load(candidate)
        return open_session(engine, path, replace(options or SessionOptions(), files_key=f"{self.root}#{self._digest}"))

    def close(self) -> None:
        """Remove the scratch folder (and what :mod:`asset2sim.mesh_io` kept of its meshes)."""
        mesh_io.forget_under(self.root)
        shutil.rmtree(self.root, ignore_errors=True)
        atomic.remove_scratch(self.root)

    def __enter__(self) -> "Workspace":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


@dataclass(frozen=True)
class CandidateSource:
    """A candidate of a workspace as a :class:`~asset2sim.engines.source.SimSource` (:meth:`Workspace.source`)."""

    workspace: Workspace
    candidate: Candidate

    @property
    def path(self) -> Path:
        """The scratch URDF, the candidate loaded first."""
        return self.workspace.load(self.candidate)

    def model(self, mode: str = "strict") -> urdf.UrdfModel:
        """:meth:`Workspace.model` of the candidate (written by this project: ``mode`` changes nothing)."""
        return self.workspace.model(self.candidate)

    def open(self, engine: str, options: SessionOptions | None = None) -> SimSession:
        """:meth:`Workspace.session` of the candidate."""
        return self.workspace.session(self.candidate, engine, options)
