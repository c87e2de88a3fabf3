"""A USD of :mod:`asset2sim.formats.usd.export` read back (:func:`read_usd`, SI units) and checked against the output
folder it was written from (:func:`check_usd`): every link's inertial, every movable joint's limits, damping,
friction, spring and initial position, the articulation root and the mounting.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from asset2sim.extras import pxr_modules as _pxr
from asset2sim.formats.usd.reader import DEG
from asset2sim.formats.usd.stage import authored
from asset2sim.frames import quat_wxyz_matrix
from asset2sim.refined_asset import RefinedAsset

#: Relative tolerance of a value read back from the USD (binary32: 6e-8 relative, plus a degree conversion).
FLOAT_RTOL = 1e-6


class UsdExportError(RuntimeError):
    """The USD export failed or did not check out (names the folder, link or joint)."""


@dataclass
class UsdLink:
    """A rigid body as the USD holds it, SI units, link frame: ``mass`` kg,
    ``com`` (3,) m, ``inertia`` (3, 3) kg*m^2 about the COM (from the
    diagonal inertia and principal axes); None where not authored."""

    mass: float | None
    com: np.ndarray | None
    inertia: np.ndarray | None


@dataclass
class UsdJoint:
    """A joint as the USD holds it, converted back to SI (rad or m):
    ``type`` revolute / prismatic / fixed, ``lower`` / ``upper`` (None when
    unlimited), ``damping``, ``stiffness``, ``reference`` from the drive,
    ``friction`` from ``newton:friction``, ``position`` the joint state."""

    type: str
    lower: float | None
    upper: float | None
    damping: float
    stiffness: float
    reference: float
    friction: float
    position: float


@dataclass
class UsdAsset:
    """What a USD file holds, by URDF name (``asset2sim:name``)."""

    links: dict[str, UsdLink]
    joints: dict[str, UsdJoint]
    articulation_root: bool
    fixed_root: bool


def read_usd(path: Path) -> UsdAsset:
    """Read the physics of a USD written by :func:`export_usd` back, in SI
    units (degrees converted to radians).

    Raises:
        ImportError: ``usd-core`` is not installed.
        UsdExportError: the file cannot be opened or has no default prim.
    """
    Gf, Sdf, Tf, Usd, UsdGeom, UsdPhysics = _pxr()
    stage = Usd.Stage.Open(str(path))
    if stage is None or not stage.GetDefaultPrim():
        raise UsdExportError(f"{path}: not a USD stage with a default prim")
    links, joints, fixed_root = {}, {}, False
    art = stage.GetDefaultPrim().HasAPI(UsdPhysics.ArticulationRootAPI)
    for prim in stage.Traverse():
        name = authored(prim, "asset2sim:name")
        if prim.HasAPI(UsdPhysics.RigidBodyAPI):
            m = UsdPhysics.MassAPI(prim)
            mass_attr, com_attr = m.GetMassAttr(), m.GetCenterOfMassAttr()
            mass = float(mass_attr.Get()) if mass_attr.HasAuthoredValue() else None
            com = np.array(com_attr.Get(), float) if com_attr.HasAuthoredValue() else None
            inertia = None
            if m.GetDiagonalInertiaAttr().HasAuthoredValue():
                d = np.array(m.GetDiagonalInertiaAttr().Get(), float)
                q = m.GetPrincipalAxesAttr().Get()
                r = np.array(quat_wxyz_matrix([q.GetReal(), *q.GetImaginary()]))
                inertia = r @ np.diag(d) @ r.T
            links[name or prim.GetName()] = UsdLink(mass, com, inertia)
        elif prim.IsA(UsdPhysics.Joint):
            j = UsdPhysics.Joint(prim)
            if prim.IsA(UsdPhysics.FixedJoint) and not j.GetBody0Rel().GetTargets():
                fixed_root = True
                continue
            if prim.IsA(UsdPhysics.RevoluteJoint):
                kind, dof, unit, jj = "revolute", "angular", DEG, UsdPhysics.RevoluteJoint(prim)
            elif prim.IsA(UsdPhysics.PrismaticJoint):
                kind, dof, unit, jj = "prismatic", "linear", 1.0, UsdPhysics.PrismaticJoint(prim)
            else:
                joints[name or prim.GetName()] = UsdJoint("fixed", None, None, 0.0, 0.0, 0.0, 0.0, 0.0)
                continue
            lo = jj.GetLowerLimitAttr()
            hi = jj.GetUpperLimitAttr()
            drive = UsdPhysics.DriveAPI.Get(prim, dof) if prim.HasAPI(UsdPhysics.DriveAPI, dof) else None
            fr = prim.GetAttribute("newton:friction")
            st = prim.GetAttribute(f"state:{dof}:physics:position")
            joints[name or prim.GetName()] = UsdJoint(
                type=kind,
                lower=float(lo.Get()) / unit if lo.HasAuthoredValue() else None,
                upper=float(hi.Get()) / unit if hi.HasAuthoredValue() else None,
                damping=float(drive.GetDampingAttr().Get()) * unit if drive else 0.0,
                stiffness=float(drive.GetStiffnessAttr().Get()) * unit if drive else 0.0,
                reference=float(drive.GetTargetPositionAttr().Get()) / unit if drive else 0.0,
                friction=float(fr.Get()) if fr and fr.HasAuthoredValue() else 0.0,
                position=float(st.Get()) / unit if st and st.HasAuthoredValue() else 0.0,
            )
    return UsdAsset(links=links, joints=joints, articulation_root=bool(art), fixed_root=fixed_root)


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

    def cmp(what: str, got, want, scale: float) -> None:
        nonlocal worst
        got, want = np.atleast_1d(np.asarray(got, float)), np.atleast_1d(np.asarray(want, float))
        err = float(np.abs(got - want).max()) / max(scale, 1e-300)
        worst = max(worst, err)
        if not all(abs(float(g) - float(w)) <= FLOAT_RTOL * max(abs(float(w)), scale) + 1e-15 for g, w in zip(got.ravel(), want.ravel())):
            raise UsdExportError(f"{path}: {what} is {got.tolist()} in the USD, {want.tolist()} in {out_dir}")

    def cmp_inertial(what: str, got: UsdLink, mass: float, com: np.ndarray, inertia: np.ndarray) -> None:
        cmp(f"{what} mass (kg)", got.mass, mass, abs(mass))
        cmp(f"{what} center of mass (m)", got.com, com, max(float(np.abs(com).max()), 1e-3))
        cmp(f"{what} inertia tensor (kg*m^2)", got.inertia, inertia, float(np.abs(inertia).max()))

    if not usd.articulation_root:
        raise UsdExportError(f"{path}: the default prim has no PhysicsArticulationRootAPI")
    if usd.fixed_root != fixed:
        raise UsdExportError(f"{path}: root {'fixed' if usd.fixed_root else 'free'} in the USD, "
                             f"{'fixed' if fixed else 'free'} in {out_dir / 'initial_state.json'}")
    for name, link in model.links.items():
        got = usd.links.get(name)
        if got is None:
            raise UsdExportError(f"{path}: no rigid body for link {name!r}")
        if link.inertial is None:
            if got.mass is not None:
                raise UsdExportError(f"{path}: link {name!r} has a mass in the USD but no <inertial> in the URDF")
            continue
        if got.mass is None or got.com is None or got.inertia is None:
            raise UsdExportError(f"{path}: link {name!r} lacks mass, COM or inertia in the USD")
        cmp_inertial(f"link {name!r}", got, link.inertial.mass, link.inertial.com(), link.inertial.inertia_in_link_axes())
    overlay = asset.overlay
    if overlay is not None:  # the overlay's own numbers, not only the URDF that carries them
        for name, lp in overlay.links.items():
            got = usd.links.get(name)
            if got is None or got.mass is None or got.com is None or got.inertia is None:
                raise UsdExportError(f"{path}: overlay link {name!r} has no mass, COM or inertia in the USD")
            cmp_inertial(f"overlay link {name!r}", got, lp.mass, np.asarray(lp.com, float), lp.inertia.matrix())
        for name, jd in overlay.joints.items():
            got = usd.joints.get(name)
            if got is None:
                raise UsdExportError(f"{path}: overlay joint {name!r} is not in the USD")
            for q in ("damping", "friction", "stiffness"):
                cmp(f"overlay joint {name!r} {q}", getattr(got, q), getattr(jd, q), abs(getattr(jd, q)))
    for j in model.movable_joints:
        got = usd.joints.get(j.name)
        if got is None:
            raise UsdExportError(f"{path}: no joint {j.name!r}")
        if j.type in ("revolute", "prismatic"):
            span = max(abs(j.lower), abs(j.upper), 1e-3)
            if got.lower is None or got.upper is None:
                raise UsdExportError(f"{path}: joint {j.name!r} has no limits in the USD")
            cmp(f"joint {j.name!r} limits", [got.lower, got.upper], [j.lower, j.upper], span)
        elif got.lower is not None or got.upper is not None:
            raise UsdExportError(f"{path}: continuous joint {j.name!r} has limits in the USD")
        cmp(f"joint {j.name!r} damping", got.damping, j.damping, abs(j.damping))
        cmp(f"joint {j.name!r} friction", got.friction, j.friction, abs(j.friction))
        s = springs.get(j.name)
        cmp(f"joint {j.name!r} stiffness", got.stiffness, s.stiffness if s else 0.0, abs(s.stiffness) if s else 0.0)
        if s is not None:
            cmp(f"joint {j.name!r} spring reference", got.reference, s.reference, max(abs(s.reference), 1e-3))
        want_q = float(initial.get(j.name, 0.0))
        cmp(f"joint {j.name!r} initial position", got.position, want_q, max(abs(want_q), 1e-3))
    return UsdCheck(links=len(model.links), joints=len(model.movable_joints), max_rel_error=worst)

