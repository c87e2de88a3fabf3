"""An output folder read back: :class:`RefinedAsset`, the one reader of ``mobility.urdf``, ``overlay.json``,
``initial_state.json`` (joint values and the root's mount) and ``report.json`` that the exports, the host
write-backs, the public loaders, the evaluation and the learning environments share.

Each file is read at most once, when first asked for, so a reader raises only the errors of the files it uses, in
the order it uses them. Files are opened by name (``is_file``), as the folder's writers named them; the output's
trust checks (:func:`asset2sim.tasks.publish.contract.verify_output`) and the write guard
(:func:`asset2sim.output_folder.guarding`) stay with their callers. Units SI, radians.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any

from asset2sim.atomic import non_finite
from asset2sim.engines.base import SessionOptions, Spring, session_root_options
from asset2sim.engines.loading import CollisionPiece, collision_pieces, overlay_springs, read_urdf
from asset2sim.mesh_io import MeshCache
from asset2sim.output_folder import (OVERLAY_NAME, REPORT_NAME, STATE_NAME, TIMINGS_NAME, URDF_NAME, OutputError, read_record,
                                     record_or_none)
from asset2sim.schemas.config import SimConventions
from asset2sim.schemas.overlay import Overlay, RootMount
from asset2sim.schemas.report import RefineReport
from asset2sim.urdf import UrdfModel

#: Key of the root declaration in ``initial_state.json``.
ROOT_KEY = "root"


@dataclass(frozen=True)
class RefinedAsset:
    """The output folder ``folder`` (its URDF ``urdf_name``, default ``mobility.urdf``), each file read once, on
    first use (module docstring).

    Example: ``asset = RefinedAsset(out); open_session("pybullet", asset.urdf_path, asset.session_options())``.
    """

    folder: Path
    urdf_name: str = URDF_NAME
    _records: dict[str, Any] = field(default_factory=dict, init=False, repr=False, compare=False)
    meshes: MeshCache = field(default_factory=MeshCache, init=False, repr=False, compare=False)
    """The folder's mesh files as read (:class:`~asset2sim.mesh_io.MeshCache`): the MJCF and USD exports of one
    refine parse each visual mesh once."""

    @classmethod
    def of(cls, folder: "Path | str | RefinedAsset") -> "RefinedAsset":
        """``folder`` itself when it is a :class:`RefinedAsset` (its reads kept), else the folder read anew."""
        return folder if isinstance(folder, RefinedAsset) else cls(Path(folder))

    @classmethod
    def existing(cls, folder: "Path | str | RefinedAsset") -> "RefinedAsset":
        """:meth:`of` ``folder``, which must hold its URDF. Raises FileNotFoundError: it does not (not an output
        folder)."""
        asset = cls.of(folder)
        if not asset.urdf_path.is_file():
            raise FileNotFoundError(f"{asset.urdf_path} does not exist (not an output folder?)")
        return asset

    @classmethod
    def held(cls, folder: "Path | str", report: RefineReport) -> "RefinedAsset":
        """The folder as a refine holds it before ``report.json`` is written: :attr:`report` is ``report`` (the
        verdict record in memory), every other file read from ``folder``. The exports a refine writes read the
        hand's :attr:`press_efforts` from it, as they do from the folder later."""
        asset = cls(Path(folder))
        asset.__dict__["report"] = report  # the cached_property's value, as if read
        return asset

    @property
    def urdf_path(self) -> Path:
        """The folder's URDF file."""
        return self.folder / self.urdf_name

    def record(self, name: str) -> Any:
        """The JSON of the folder's file ``name`` (UTF-8; read once), or None when it is not a file. Raises
        ValueError (not JSON) or OSError (unreadable)."""
        if name not in self._records:
            p = self.folder / name
            self._records[name] = json.loads(p.read_text(encoding="utf-8")) if p.is_file() else None
        return self._records[name]

    @cached_property
    def model(self) -> UrdfModel:
        """The URDF read strictly, limited to the joint types the engines build
        (:func:`asset2sim.engines.loading.read_urdf`). Raises UrdfError: naming the file, line and part."""
        return read_urdf(self.urdf_path)

    @cached_property
    def collision(self) -> tuple[dict[str, list[CollisionPiece]], list[str]]:
        """Every link's convex collision pieces and the notes on them, as every engine builds them
        (:func:`asset2sim.engines.loading.collision_pieces` of :attr:`model`)."""
        return collision_pieces(self.model)

    @cached_property
    def initial_state(self) -> dict[str, float]:
        """``initial_state.json``'s joint values, joint -> rad or m ({} without the file). Raises ValueError: not
        the contract's shape."""
        data = self.record(STATE_NAME)
        if data is None:
            return {}
        q = data.get("initial_joint_positions") if isinstance(data, dict) else None
        if not isinstance(q, dict):
            raise ValueError(f"{self.folder / STATE_NAME}: expected {{'initial_joint_positions': {{joint: value}}}}")
        return {str(k): float(v) for k, v in q.items()}

    @cached_property
    def root(self) -> RootMount:
        """The root declaration of ``initial_state.json`` (:func:`asset2sim.tasks.assemble.write.root_record`);
        free-standing when the file or its ``"root"`` entry is absent.

        Raises:
            OutputError: the file is not readable JSON, or ``"root"`` is not the shape ``root_record`` writes.
        """
        p = self.folder / STATE_NAME
        try:
            data = self.record(STATE_NAME)
        except (OSError, ValueError) as exc:
            raise OutputError(f"{p}: not readable JSON: {exc}") from exc
        rec = data.get(ROOT_KEY) if isinstance(data, dict) else None
        if rec is None:
            return RootMount()
        if not isinstance(rec, dict) or not isinstance(rec.get("fixed"), bool):
            raise OutputError(f"{p}: \"{ROOT_KEY}\" must be an object with a boolean \"fixed\"")
        fixed = rec["fixed"]
        try:
            return RootMount(kind=rec.get("mounting") or ("wall-mounted" if fixed else "free-standing"), fixed=fixed,
                             source=str(rec.get("source") or f"declared in {STATE_NAME}"))
        except ValueError as exc:
            raise OutputError(f"{p}: \"{ROOT_KEY}\": {exc}") from exc

    @cached_property
    def overlay(self) -> Overlay | None:
        """``overlay.json``, or None without it. Raises ValueError: not a valid overlay (names the file)."""
        p = self.folder / OVERLAY_NAME
        if not p.is_file():
            return None
        try:
            return Overlay.model_validate(self.record(OVERLAY_NAME))
        except Exception as exc:  # pydantic.ValidationError, JSONDecodeError
            raise ValueError(f"{p}: not a valid overlay: {exc}") from exc

    def required_overlay(self) -> Overlay:
        """:attr:`overlay`, which a refined output always has. Raises FileNotFoundError: none; ValueError: invalid."""
        if self.overlay is None:
            raise FileNotFoundError(f"{self.folder / OVERLAY_NAME} does not exist")
        return self.overlay

    def springs_about(self, initial_state: dict[str, float] | None) -> dict[str, Spring]:
        """The overlay's joint springs (stiffness > 0, N*m/rad or N/m) about their ``spring_reference``, else about
        ``initial_state`` (rad or m; else 0); {} without an overlay. Raises ValueError: an invalid overlay."""
        return {} if self.overlay is None else overlay_springs(self.overlay, initial_state)

    @property
    def springs(self) -> dict[str, Spring]:
        """:meth:`springs_about` the folder's :attr:`initial_state`."""
        return self.springs_about(self.initial_state)

    def session_options(self, conventions: SimConventions | None = None,
                        initial_state: dict[str, float] | None = None) -> SessionOptions:
        """The :class:`~asset2sim.engines.base.SessionOptions` every check and the public loaders open the folder
        with: ``initial_state`` (rad or m; default :attr:`initial_state`), the overlay's springs about it, the hand's
        :attr:`press_efforts`, ``conventions`` (default :class:`SimConventions`) and the root as declared (the session's
        and the one its MJCF's solver aids are judged on).

        Raises:
            ValueError: ``initial_state.json`` or ``overlay.json`` is invalid; OutputError: the root declaration is.
        """
        state = self.initial_state if initial_state is None else dict(initial_state)
        return SessionOptions(initial_state=state, springs=self.springs_about(state), conventions=conventions or SimConventions(),
                              press_efforts=self.press_efforts, object_root_fixed=self.root.fixed,
                              **session_root_options(self.root.fixed))

    @cached_property
    def press_efforts(self) -> dict[str, float]:
        """joint -> the most effort a hand presses it with (N*m, N for a prismatic joint): the operability check's hand
        in ``report.json``, the top of the part's operating range at its grasp point; {} without either."""
        try:
            m = self.report.metric("operability")
        except (OSError, ValueError):
            return {}
        parts = m.details.get("parts", {}) if m is not None else {}
        return {j: float(p["hand_force_n"]) * float(p.get("lever_m") or 1.0) for j, p in parts.items() if p.get("hand_force_n")}

    @cached_property
    def report(self) -> RefineReport:
        """``report.json`` as a :class:`RefineReport` (read as a regular file of at most
        :data:`~asset2sim.output_folder.MAX_RECORD_BYTES`), with the wall times of ``timings.json`` when it is
        readable. Raises OSError (missing, not a regular file, too large) or ValueError (invalid; a NaN or infinity
        named by its JSON path, :func:`non_finite`)."""
        p = self.folder / REPORT_NAME
        data = read_record(p)
        if not isinstance(data, dict):
            raise ValueError(f"{p}: not a JSON object")
        if (where := non_finite(data)) is not None:
            raise ValueError(f"{p}: {where} is not a finite number (NaN or infinity), which asset2sim never writes")
        timings = record_or_none(self.folder / TIMINGS_NAME)
        if isinstance(timings, dict):
            if isinstance(timings.get("stage_seconds"), dict) and not data.get("stage_seconds"):
                data["stage_seconds"] = timings["stage_seconds"]
            state = data.get("state")
            if isinstance(state, dict) and "seconds" not in state and isinstance(timings.get("state_seconds"), (int, float)):
                state["seconds"] = timings["state_seconds"]
        return RefineReport.model_validate(data)


def read_initial_state(folder: Path | str) -> dict[str, float]:
    """:attr:`RefinedAsset.initial_state` of ``folder``."""
    return RefinedAsset(Path(folder)).initial_state


def read_root(folder: Path | str) -> RootMount:
    """:attr:`RefinedAsset.root` of ``folder``."""
    return RefinedAsset(Path(folder)).root


def springs_from_overlay(out_dir: Path | str, initial_state: dict[str, float] | None = None) -> dict[str, Spring]:
    """:meth:`RefinedAsset.springs_about` ``initial_state`` of ``out_dir`` (about 0 where None)."""
    return RefinedAsset(Path(out_dir)).springs_about(initial_state)


def output_session_options(out_dir: Path | str, initial_state: dict[str, float] | None = None,
                           conventions: SimConventions | None = None) -> SessionOptions:
    """:meth:`RefinedAsset.session_options` of ``out_dir``."""
    return RefinedAsset(Path(out_dir)).session_options(conventions, initial_state)


def read_report_json(out_dir: Path | str) -> RefineReport:
    """:attr:`RefinedAsset.report` of ``out_dir``."""
    return RefinedAsset(Path(out_dir)).report
