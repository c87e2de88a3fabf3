"""The physics an input declares, as a simulator loading it would use it: per link mass, center of mass,
inertia tensor (or that the simulator infers them from the geometry, and from which density), per joint
limits, damping, friction and spring. Read from a URDF (:mod:`asset2sim.urdf`), an MJCF file
(:mod:`asset2sim.formats.mjcf.reader`, MuJoCo's compiled values) or an OpenUSD stage (:mod:`asset2sim.formats.usd.reader`), in the frames of
the asset model those readers make (the staged URDF's), SI units and radians. The audit
(:mod:`asset2sim.apps.audit`) judges these values."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

import numpy as np

from asset2sim.urdf import UrdfInertial, UrdfModel, read_urdf
from asset2sim.schemas.asset import AssetDescription
from asset2sim.tasks.ingest import partnet_mobility, urdf_meshes
from asset2sim.formats import FORMATS, ReadOptions, read_asset_file, staging

__all__ = ["DeclaredJoint", "DeclaredLink", "DeclaredPhysics", "read_declared", "real_units"]

How = Literal["declared", "inferred", "absent"]


@dataclass(frozen=True)
class DeclaredLink:
    """One link's inertial as loaded: ``mass`` kg, ``com`` (3,) m in the link frame, ``inertia`` (3, 3) kg*m^2
    about the COM in the link axes; ``how`` ``declared`` (the file gives them), ``inferred`` (the simulator
    computes them from the geometry, values as MuJoCo compiles them when known) or ``absent`` (no values);
    ``density`` kg/m^3 the file declares for that inference (None when not one value); ``written_moments`` (3,)
    kg*m^2 the principal moments as written where the simulator changed them on loading (else None)."""

    name: str
    how: How
    mass: float | None = None
    com: np.ndarray | None = None
    inertia: np.ndarray | None = None
    density: float | None = None
    written_moments: np.ndarray | None = None


@dataclass(frozen=True)
class DeclaredJoint:
    """One movable joint as declared: ``type`` revolute / continuous / prismatic; ``lower`` / ``upper`` rad or m
    (None when absent); ``damping`` N*m*s/rad or N*s/m, ``friction`` N*m or N (None when absent); ``stiffness``
    N*m/rad or N/m about ``reference`` rad or m (None without a spring); ``effort`` N*m or N."""

    name: str
    type: str
    child: str
    lower: float | None = None
    upper: float | None = None
    damping: float | None = None
    friction: float | None = None
    stiffness: float | None = None
    reference: float | None = None
    effort: float | None = None


@dataclass(frozen=True)
class DeclaredPhysics:
    """What one input file declares: ``format`` ``urdf`` / ``mjcf`` / ``usd``; ``root_fixed`` the file welds the
    root to the world (True), leaves it free (False) or does not say (None, URDF); ``read`` what the MJCF or USD
    reader made of the file (None for a URDF), for writers that edit the file in its own format;
    ``initial_state`` joint -> the position (rad or m) the file starts it at (an MJCF keyframe), empty if none."""

    source: Path
    format: str
    links: dict[str, DeclaredLink] = field(default_factory=dict)
    joints: dict[str, DeclaredJoint] = field(default_factory=dict)
    root_fixed: bool | None = None
    read: staging.ReadAsset | None = None
    initial_state: dict[str, float] = field(default_factory=dict)


def _link(name: str, inertial: UrdfInertial | None, how: How, density: float | None = None,
          written: tuple[float, float, float] | None = None) -> DeclaredLink:
    if inertial is None or inertial.mass is None:
        return DeclaredLink(name=name, how="absent" if how == "declared" else how, density=density)
    origin = np.asarray(inertial.origin, float)
    rot = origin[:3, :3]
    tensor = np.asarray(inertial.inertia if inertial.inertia is not None else np.zeros((3, 3)), float)
    return DeclaredLink(name=name, how=how, mass=float(inertial.mass), com=origin[:3, 3].copy(), inertia=rot @ tensor @ rot.T,
                        density=density, written_moments=None if written is None else np.asarray(written, float))


def declared_from_model(source: Path, fmt: str, model: UrdfModel, read: staging.ReadAsset | None = None) -> DeclaredPhysics:
    """The declared physics of an asset model (a URDF's, or a reader's ``read.model`` with its springs,
    inferred inertials and densities)."""
    links = {name: _link(name, read.simulated.get(name), "inferred", read.densities.get(name))
             if read is not None and name in read.inferred else
             _link(name, ln.inertial, "declared", written=None if read is None else read.written_moments.get(name))
             for name, ln in model.links.items()}
    joints = {}
    for j in model.joints:
        if j.type not in ("revolute", "continuous", "prismatic"):
            continue
        spring = read.springs.get(j.name) if read is not None else None
        lim, dyn = j.limit, j.dynamics
        stops = None if j.type == "continuous" else lim
        joints[j.name] = DeclaredJoint(
            name=j.name, type=j.type, child=j.child,
            lower=getattr(stops, "lower", None), upper=getattr(stops, "upper", None), damping=getattr(dyn, "damping", None),
            friction=getattr(dyn, "friction", None), stiffness=getattr(spring, "stiffness", None),
            reference=getattr(spring, "reference", None), effort=getattr(lim, "effort", None))
    return DeclaredPhysics(source=source, format=fmt, links=links, joints=joints, root_fixed=getattr(read, "root_fixed", None),
                           read=read, initial_state={} if read is None else dict(read.initial_state))


def read_declared(path: Path | str, urdf_path: Path | str | None = None, reading: ReadOptions | None = None) -> DeclaredPhysics:
    """The physics the input at ``path`` declares.

    Args:
        path: an MJCF or USD file (or a folder holding one, :func:`staging.other_format_file`), or a URDF asset.
        urdf_path: the URDF file extraction found or staged; needed when ``path`` is a URDF folder. A URDF this
            process staged (:func:`staging.read_of`) gives what its reader read, without reading the file again.
        reading: how an MJCF file is read (the object's body in a scene, the angle unit;
            :class:`~asset2sim.formats.mjcf.conventions.ReadOptions`).

    Raises:
        StagingError: the MJCF or USD file cannot be read into the asset model.
        UrdfError: the URDF cannot be read (lenient mode).
        ValueError: a URDF asset given as a folder without ``urdf_path``.
    """
    read = staging.read_of(urdf_path) if urdf_path is not None else None
    if read is not None:  # staged by extraction in this process: the file is not read again
        return declared_from_model(read.source, read.format, read.model, read)
    other = staging.other_format_file(path)
    if other is not None:
        source, fmt = other
        read = read_asset_file(source, fmt, reading)
        return declared_from_model(Path(source), fmt, read.model, read)
    original = urdf_meshes.urdf_needing_conversion(path)  # its meshes converted for the simulators: its own values
    urdf = original or (Path(urdf_path) if urdf_path is not None else Path(path))
    if urdf.is_dir():
        raise ValueError(f"{path}: a URDF asset folder needs its URDF file")
    return declared_from_model(urdf, "urdf", read_urdf(urdf, mode="lenient"))


def real_units(asset: AssetDescription) -> str | None:
    """Why ``asset``'s lengths are real sizes in metres, or None when they say nothing about its size: an MJCF file
    or a USD stage (:attr:`asset2sim.formats.Format.real_units`: MuJoCo's lengths are metres, a stage is read through its
    ``metersPerUnit``), a URDF declaring inertials (SI units, mass and lengths together); never PartNet-Mobility's
    ``mobility.urdf``, normalized to about unit size (:func:`asset2sim.tasks.ingest.partnet_mobility.size_normalized`)."""
    source = asset.staged_from or asset.urdf_path
    if partnet_mobility.size_normalized(source):
        return None
    suffix = Path(source).suffix.lower()
    for fmt in FORMATS.values() if asset.staged_from is not None else ():
        if suffix in fmt.suffixes:
            return fmt.real_units.format(name=Path(source).name)
    if any(ln.given_inertial is not None for ln in asset.links):
        return f"a URDF declaring inertials ({Path(source).name}: SI units, masses and lengths together)"
    return None
