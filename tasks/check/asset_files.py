"""The evaluated asset's files as the evaluation reads them: any URDF (read
leniently) and the PartNet-Mobility sidecars through their adapter.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from asset2sim.tasks.ingest import partnet_mobility
from asset2sim.tasks.ingest.errors import AssetError
from asset2sim.engines.source import SimSource
from asset2sim.refined_asset import RefinedAsset
from asset2sim.urdf import UrdfError

#: Joint types that move (the others are fixed).
MOVABLE = ("revolute", "continuous", "prismatic")


class EvaluationError(ValueError):
    """The asset cannot be evaluated (message names the file and why)."""


@dataclass
class JointInfo:
    """A joint as written in the URDF (limits rad/m, dynamics SI or None)."""

    name: str
    type: str
    parent: str
    child: str
    lower: float | None
    upper: float | None
    damping: float | None
    friction: float | None


@dataclass
class LinkInfo:
    """A link as written in the URDF (mass kg or None without ``<inertial>``)."""

    name: str
    mass: float | None
    has_collision: bool
    has_visual: bool


def find_urdf(path: Path | str) -> Path:
    """The URDF of ``path`` (:func:`asset2sim.tasks.ingest.partnet_mobility.find_urdf`).

    Raises:
        EvaluationError: nothing (or several candidates) found.
    """
    try:
        return partnet_mobility.find_urdf(path)
    except AssetError as exc:
        raise EvaluationError(str(exc)) from exc


def parse_urdf(source: SimSource) -> tuple[dict[str, LinkInfo], dict[str, JointInfo]]:
    """Links and joints of a URDF as written (``source.model``, a file read leniently): (link name ->
    :class:`LinkInfo`, joint name -> :class:`JointInfo`), in file order.

    Raises:
        EvaluationError: unreadable XML or a malformed number (names the file,
            line and link or joint), or a name longer than
            :data:`asset2sim.urdf.MAX_NAME_CHARS` (``code`` ``NAME_TOO_LONG``).
    """
    try:
        model = source.model(mode="lenient")
    except UrdfError as exc:
        err = EvaluationError(f"unreadable URDF: {exc}")
        if exc.code == "NAME_TOO_LONG":  # refused before any engine loads it: PyBullet ends the process on such names
            err.code = exc.code
        raise err from exc
    links = {name: LinkInfo(name, None if ln.inertial is None else ln.inertial.mass, bool(ln.collisions), bool(ln.visuals))
             for name, ln in model.links.items()}
    joints = {}
    for jt in model.joints:
        lim, dyn = jt.limit, jt.dynamics
        joints[jt.name] = JointInfo(
            name=jt.name, type=jt.type, parent=jt.parent, child=jt.child,
            lower=None if lim is None else lim.lower, upper=None if lim is None else lim.upper,
            damping=None if dyn is None else dyn.damping, friction=None if dyn is None else dyn.friction)
    return links, joints


def read_json(asset: RefinedAsset, name: str) -> dict[str, Any] | None:
    """The JSON sidecar ``name`` of the asset's folder (:meth:`~asset2sim.refined_asset.RefinedAsset.record`, read
    once): None when the file is absent or holds no object.

    Raises:
        EvaluationError: the file exists but is not readable JSON.
    """
    try:
        data = asset.record(name)
    except (ValueError, OSError) as exc:
        raise EvaluationError(f"{asset.folder / name}: unreadable JSON: {exc}") from exc
    return data if isinstance(data, dict) else None


def read_semantics(folder: Path) -> dict[str, tuple[str, str]]:
    """``semantics.txt`` as link -> (joint kind, label); empty when missing or malformed."""
    try:
        return partnet_mobility.read_semantics(folder)
    except AssetError:
        return {}


def read_category(folder: Path) -> str | None:
    """``meta.json``'s ``model_cat`` of ``folder``, or None."""
    return partnet_mobility.read_category(folder)


def clip_to_limits(q: float, lo: float | None, hi: float | None) -> float:
    """``q`` (rad or m) clipped to [lo, hi]; a missing or non-finite bound does not clip."""
    if lo is not None and math.isfinite(lo):
        q = max(q, lo)
    if hi is not None and math.isfinite(hi):
        q = min(q, hi)
    return float(q)
