"""A USD of :mod:`asset2sim.formats.usd.export` read back (:func:`read_usd`, SI units) and checked against the output
folder it was written from (:func:`check_usd`): every link's inertial, every movable joint's limits, damping,
friction, spring and initial position, the articulation root and the mounting.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from asset2sim.extras import pxr_modules as _pxr
from asset2sim.formats.staging import ReadAsset, StagingError
from asset2sim.formats.usd.reader import DEG, read_usd_asset
from asset2sim.formats.usd.stage import authored
from asset2sim.refined_asset import RefinedAsset
from asset2sim.urdf import UrdfInertial

#: Relative tolerance of a value read back from the USD (binary32: 6e-8 relative, plus a degree conversion).
FLOAT_RTOL = 1e-6


class UsdExportError(RuntimeError):
    """The USD export failed or did not check out (names the folder, link or joint)."""


def read_usd(path: Path) -> ReadAsset:
    """The USD at ``path`` read back by the one USD reader (:func:`~asset2sim.formats.usd.reader.read_usd_asset`,
    SI units), with each movable joint's state (``state:<angular|linear>:physics:position``, rad or m) in
    ``initial_state``.

    Raises:
        ImportError: ``usd-core`` is not installed.
        UsdExportError: the file cannot be read or its default prim has no ``PhysicsArticulationRootAPI``.
    """
    try:
        read = read_usd_asset(path)
    except StagingError as exc:
        raise UsdExportError(str(exc)) from exc
    _, _, _, Usd, _, UsdPhysics = _pxr()
    stage = Usd.Stage.Open(str(path))
    if not stage.GetDefaultPrim() or not stage.GetDefaultPrim().HasAPI(UsdPhysics.ArticulationRootAPI):
        raise UsdExportError(f"{path}: the default prim has no PhysicsArticulationRootAPI")
    for j in read.model.movable_joints:
        angular = j.type != "prismatic"
        position = authored(stage.GetPrimAtPath(read.prims[j.name]), f"state:{'angular' if angular else 'linear'}:physics:position")
        read.initial_state[j.name] = float(position or 0.0) / (DEG if angular else 1.0)
    return read


@dataclass
class UsdCheck:
    """Largest relative differences between the USD and the source files
    (mass, COM, inertia tensor, joint values), over links / joints compared."""

    links: int
    joints: int
    max_rel_error: float


def check_usd(path: Path, out_dir: Path | RefinedAsset) -> UsdCheck:
    """Read ``path`` back (:func:`read_usd`) and compare every link's inertial and every movable joint's values with
    ``mobility.urdf``, ``overlay.json`` and ``initial_state.json`` of ``out_dir`` (a folder or its
    :class:`~asset2sim.refined_asset.RefinedAsset`), to :data:`FLOAT_RTOL` relative to the quantity's
    scale on that link or joint (COM: at least 1 mm).

    Raises:
        ValueError: ``overlay.json`` is not a valid overlay.
        UsdExportError: a value differs (names the link or joint and the
            quantity), a link or joint is missing, the articulation root or
            the mounting differs.
    """
    asset = RefinedAsset.of(out_dir)
    out_dir = asset.folder
    model, initial, springs, fixed = asset.model, asset.initial_state, asset.springs, asset.root.fixed
    usd = read_usd(path)
    worst = 0.0

    def fail(message: str) -> UsdExportError:
        return UsdExportError(f"{path}: {message}")

    def cmp(what: str, got, want, scale: float) -> None:
        nonlocal worst
        got, want = np.atleast_1d(np.asarray(got, float)), np.atleast_1d(np.asarray(want, float))
        err = float(np.abs(got - want).max()) / max(scale, 1e-300)
        worst = max(worst, err)
        if not all(abs(float(g) - float(w)) <= FLOAT_RTOL * max(abs(float(w)), scale) + 1e-15 for g, w in zip(got.ravel(), want.ravel())):
            raise fail(f"{what} is {got.tolist()} in the USD, {want.tolist()} in {out_dir}")

    def cmp_inertial(what: str, got: UrdfInertial, mass: float, com: np.ndarray, inertia: np.ndarray) -> None:
        cmp(f"{what} mass (kg)", got.mass, mass, abs(mass))
        cmp(f"{what} center of mass (m)", got.com(), com, max(float(np.abs(com).max()), 1e-3))
        cmp(f"{what} inertia tensor (kg*m^2)", got.inertia_in_link_axes(), inertia, float(np.abs(inertia).max()))

    if usd.root_fixed != fixed:
        raise fail(f"root {'fixed' if usd.root_fixed else 'free'} in the USD, "
                   f"{'fixed' if fixed else 'free'} in {out_dir / 'initial_state.json'}")
    for name, link in model.links.items():
        if name not in usd.model.links:
            raise fail(f"no rigid body for link {name!r}")
        got = usd.model.links[name].inertial
        if link.inertial is None:
            if got is not None:
                raise fail(f"link {name!r} has a mass in the USD but no <inertial> in the URDF")
            continue
        if got is None:
            raise fail(f"link {name!r} lacks mass, COM or inertia in the USD")
        cmp_inertial(f"link {name!r}", got, link.inertial.mass, link.inertial.com(), link.inertial.inertia_in_link_axes())
    joints = {j.name: j for j in usd.model.joints}
    overlay = asset.overlay
    if overlay is not None:  # the overlay's own numbers, not only the URDF that carries them
        for name, lp in overlay.links.items():
            got = usd.model.links.get(name)
            if got is None or got.inertial is None:
                raise fail(f"overlay link {name!r} has no mass, COM or inertia in the USD")
            cmp_inertial(f"overlay link {name!r}", got.inertial, lp.mass, np.asarray(lp.com, float), lp.inertia.matrix())
        for name, jd in overlay.joints.items():
            if name not in joints:
                raise fail(f"overlay joint {name!r} is not in the USD")
            spring = usd.springs.get(name)
            held = {"damping": joints[name].damping, "friction": joints[name].friction, "stiffness": spring.stiffness if spring else 0.0}
            for q, value in held.items():
                cmp(f"overlay joint {name!r} {q}", value, getattr(jd, q), abs(getattr(jd, q)))
    for j in model.movable_joints:
        got = joints.get(j.name)
        if got is None:
            raise fail(f"no joint {j.name!r}")
        if j.type in ("revolute", "prismatic"):
            if got.type != j.type:
                raise fail(f"joint {j.name!r} has no limits in the USD")
            cmp(f"joint {j.name!r} limits", [got.lower, got.upper], [j.lower, j.upper], max(abs(j.lower), abs(j.upper), 1e-3))
        elif got.type != "continuous":
            raise fail(f"continuous joint {j.name!r} has limits in the USD")
        for q in ("damping", "friction"):
            cmp(f"joint {j.name!r} {q}", getattr(got, q), getattr(j, q), abs(getattr(j, q)))
        s, held = springs.get(j.name), usd.springs.get(j.name)
        cmp(f"joint {j.name!r} stiffness", held.stiffness if held else 0.0, s.stiffness if s else 0.0, abs(s.stiffness) if s else 0.0)
        if s is not None:
            cmp(f"joint {j.name!r} spring reference", held.reference if held else 0.0, s.reference, max(abs(s.reference), 1e-3))
        want_q = float(initial.get(j.name, 0.0))
        cmp(f"joint {j.name!r} initial position", usd.initial_state[j.name], want_q, max(abs(want_q), 1e-3))
    return UsdCheck(links=len(model.links), joints=len(model.movable_joints), max_rel_error=worst)

