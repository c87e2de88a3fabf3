"""The one OpenUSD physics writer: the refined object written back into its own stage, to drop into its host in
place of the original (:func:`write_host_usd`), and the audit's patch of a USD input (:func:`write_patched_usd`),
both through :class:`UsdEdit`, :func:`set_body_mass` and :func:`set_joint_dynamics`.

A USD input is opened again (:func:`asset2sim.formats.usd.stage.open_stage`, the trust rules of the reader)
and read again (:func:`asset2sim.formats.usd.reader.read_usd_asset`: each link's rigid-body prim and frame,
each joint's prim). The refined physics of ``mobility.urdf``, ``overlay.json`` and ``initial_state.json`` is
authored on the stage's session layer, in the stage's own units (``metersPerUnit``, ``kilogramsPerUnit``, degrees
for angles and angular gains, as UsdPhysics writes them; the inverse of the reader's conversions):

- each link's body: ``physics:mass``, ``physics:centerOfMass`` (body-local), ``physics:diagonalInertia`` and
  ``physics:principalAxes`` (the refined tensor in the body's axes, diagonalised); an authored
  ``physics:density`` is set to 0 so that no density contradicts the explicit mass;
- each revolute and prismatic joint: ``physics:lowerLimit`` / ``physics:upperLimit`` where the joint had limits,
  ``PhysicsDriveAPI:angular`` / ``:linear`` damping, stiffness and ``targetPosition`` (the refined spring and its
  reference; a drive of stiffness 0 is added where the joint had none), the Coulomb friction in
  ``asset2sim:friction`` and ``newton:friction`` (torque or force in stage units), and the refined initial state
  in ``state:<angular|linear>:physics:position`` (``PhysicsJointStateAPI``, as PhysX and Isaac Sim read it) and
  ``newton:<angular|linear>:position``.

Prim paths, geometry, materials, transforms and every other attribute stay. Three files are written in
``usd/host/``:

- ``<input file name>`` (a ``.usdz`` input: ``<stem>.usd``): the stage flattened with the refined physics, one
  self-contained layer with the input's prim paths, to put in place of the input file (its relative asset paths,
  a texture, resolve from where the input was);
- ``<stem>.physics.usda``: the changes alone, ``over`` specs at the input's prim paths, a layer to put above the
  input in a layer stack (``subLayers = [@<stem>.physics.usda@, @<input>@]``) where the input file stays as it is;
- ``<stem>.diff``: one line per changed attribute, ``<prim path>.<attribute>: <old> -> <new>`` (``None``: it was not
  authored), and the API schemas applied.

A refine that rescaled the object writes no such files: the host's geometry would no longer match the physics.
"""

from __future__ import annotations

import tempfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from asset2sim import atomic, file_names, output_folder
from asset2sim.refined_asset import RefinedAsset
from asset2sim.frames import matrix_quat_wxyz, rigid_inverse
from asset2sim.extras import pxr_modules
from asset2sim.output_folder import URDF_NAME, USD_DIR
from asset2sim.schemas.overlay import JointDynamics, LinkPhysics
from asset2sim.formats.staging import HOST_DIR, ReadAsset, host_overlay
from asset2sim.formats.usd import reader
from asset2sim.formats.usd.reader import DEG, FRICTION_ATTRS
from asset2sim.formats.usd.stage import StageReading, authored, open_stage, value_or

__all__ = ["HOST_DIR", "HostUsdError", "HostUsdExport", "UsdEdit", "applied_schemas", "set_body_mass", "set_joint_dynamics", "write_host_usd"]

#: Relative tolerance of the check that the written stage holds the refined values (binary32 attributes).
VALUE_RTOL = 1e-5
#: A value within this difference (relative to its magnitude) of the one the stage holds is left as it is: a value
#: read in, converted to SI and back, agrees to a few binary32 roundings.
SAME_RTOL = 1e-6


class HostUsdError(RuntimeError):
    """The host stage cannot be written (names the input and why)."""


@dataclass(frozen=True)
class HostUsdExport:
    """What :func:`write_host_usd` wrote, inside the output folder: ``path`` the flattened stage, ``layer`` the
    changes alone, ``diff`` their listing; ``prims`` the prim paths whose physics changed; ``changes`` how many
    attributes."""

    path: Path
    layer: Path
    diff: Path
    prims: tuple[str, ...]
    changes: int


@dataclass
class UsdEdit:
    """Attributes authored on a stage, each with the value the stage held before: ``changes`` (prim path,
    attribute, old or None, new), ``schemas`` (prim path, API schema) applied where the prim lacked it."""

    changes: list[tuple[str, str, object, object]] = field(default_factory=list)
    schemas: list[tuple[str, str]] = field(default_factory=list)

    def set(self, prim, name: str, value, type_name=None) -> None:
        """Author ``name`` (of Sdf type ``type_name``, used when the attribute does not exist; None: ``Float``) on
        ``prim``."""
        attr = prim.GetAttribute(name)
        old = attr.Get() if attr and attr.HasValue() else None
        if old is not None and same(old, value):
            return  # the stage holds it already (to the attribute's binary32 precision)
        if not attr:
            sdf_type = type_name or pxr_modules()[1].ValueTypeNames.Float
            attr = prim.CreateAttribute(name, sdf_type, custom=name.startswith("asset2sim:"))
        attr.Set(value)
        self.changes.append((str(prim.GetPath()), name, old, attr.Get()))

    def apply(self, prim, schema: str) -> None:
        """Apply the API schema ``schema`` (``PhysicsMassAPI``, ``PhysicsDriveAPI:angular``) unless it is."""
        if schema not in applied_schemas(prim):
            prim.AddAppliedSchema(schema)
            self.schemas.append((str(prim.GetPath()), schema))

    def lines(self) -> list[str]:
        """The edit as text: ``<path>: apiSchemas += <schema>``, then ``<path>.<attribute>: <old> -> <new>``."""
        out = [f"{path}: apiSchemas += {schema}" for path, schema in self.schemas]
        return out + [f"{path}.{name}: {_text(old)} -> {_text(new)}" for path, name, old, new in self.changes]


def applied_schemas(prim) -> list[str]:
    """The API schemas applied to ``prim`` as its ``apiSchemas`` metadata lists them, registered or not
    (``PhysicsJointStateAPI`` is PhysX's, which usd-core does not register)."""
    op = prim.GetMetadata("apiSchemas")
    return list(op.ApplyOperations([])) if op is not None else []


def same(a, b) -> bool:
    """Whether two values (numbers, vectors, quaternions) agree to :data:`SAME_RTOL` of the larger magnitude (a
    vector's tiny components, 1e-17 beside 0.03, count as equal)."""
    x, y = _numbers(a), _numbers(b)
    if x.shape != y.shape:
        return False
    scale = max(float(np.abs(x).max(initial=0.0)), float(np.abs(y).max(initial=0.0)))
    return bool(np.allclose(x, y, rtol=0.0, atol=SAME_RTOL * scale))


def _numbers(value) -> np.ndarray:
    """A number, vector or quaternion (w, x, y, z) as an array."""
    if hasattr(value, "GetReal"):
        return np.array([value.GetReal(), *value.GetImaginary()], float)
    return np.atleast_1d(np.asarray(value, float))


def _text(value) -> str:
    """A value as the diff writes it (floats to 9 significant digits, vectors and quaternions as tuples)."""
    if value is None:
        return "None"
    if isinstance(value, float):
        return f"{value:.9g}"
    if hasattr(value, "GetReal") or hasattr(value, "__len__") and not isinstance(value, str):
        return "(" + ", ".join(f"{v:.9g}" for v in _numbers(value)) + ")"
    return str(value)


def set_body_mass(edit: UsdEdit, ctx: StageReading, body, link_frame: np.ndarray, world: np.ndarray, mass: float,
                  com: np.ndarray, inertia: np.ndarray) -> None:
    """Author a link's ``mass`` kg, ``com`` (3,) m and ``inertia`` (3, 3) kg*m^2 about the COM, both in the link
    frame ``link_frame`` (4, 4, world, m, Z up), on its rigid-body prim ``body`` whose local-to-world is ``world``
    (4, 4, body-local stage units -> m, Z up), in the stage's units (``ctx.m`` m and ``ctx.kg`` kg per unit)."""
    Gf, Sdf, _, _, _, _ = pxr_modules()
    to_link = rigid_inverse(link_frame) @ world  # body-local (stage units) -> link frame (m)
    a = to_link[:3, :3] / ctx.m  # body axes -> link axes
    tensor = a.T @ np.asarray(inertia, float) @ a / (ctx.kg * ctx.m ** 2)
    local = (np.linalg.inv(to_link) @ np.append(np.asarray(com, float), 1.0))[:3]
    edit.apply(body, "PhysicsMassAPI")
    edit.set(body, "physics:mass", float(mass / ctx.kg))
    edit.set(body, "physics:centerOfMass", Gf.Vec3f(*map(float, local)), Sdf.ValueTypeNames.Point3f)
    diag, r = authored(body, "physics:diagonalInertia"), reader.quat_matrix(value_or(body, "physics:principalAxes", None))
    held = np.full((3, 3), np.nan) if diag is None else r @ np.diag(np.asarray(diag, float)) @ r.T  # stage units
    if not same(held, tensor):  # the moments and axes together: one tensor has many of them
        # its principal moments and axes (columns of a rotation, det +1); a tensor diagonal in the body's axes keeps them
        sym = 0.5 * (tensor + tensor.T)
        if np.abs(sym - np.diag(np.diag(sym))).max() <= 1e-12 * max(np.abs(sym).max(), 1e-300):
            d, q = np.diag(sym).copy(), np.eye(3)
        else:
            d, q = np.linalg.eigh(sym)
            if np.linalg.det(q) < 0:
                q[:, 0] = -q[:, 0]
        edit.set(body, "physics:diagonalInertia", Gf.Vec3f(*map(float, d)), Sdf.ValueTypeNames.Float3)
        edit.set(body, "physics:principalAxes", Gf.Quatf(*matrix_quat_wxyz(q).tolist()), Sdf.ValueTypeNames.Quatf)
    if authored(body, "physics:density"):
        edit.set(body, "physics:density", 0.0)  # an explicit mass wins; no density contradicts it


def set_joint_dynamics(edit: UsdEdit, ctx: StageReading, prim, damping: float, friction: float,
                       stiffness: float | None = None, reference: float | None = None) -> None:
    """Author a revolute or prismatic joint's ``damping`` (N*m*s/rad or N*s/m) on its drive and its Coulomb
    ``friction`` (N*m or N) in :data:`~asset2sim.formats.usd.reader.FRICTION_ATTRS` (the first always, the
    others where authored), in stage units (angular gains per degree); with ``stiffness`` (N*m/rad or N/m) the
    drive's stiffness and its ``targetPosition`` ``reference`` (rad or m). A drive of stiffness 0 is added where
    the joint had none."""
    UsdPhysics = pxr_modules()[5]
    rot = prim.IsA(UsdPhysics.RevoluteJoint)
    dof = "angular" if rot else "linear"
    gain = ctx.kg * ctx.m ** 2 * DEG if rot else ctx.kg  # the reader's: stage gain -> SI
    force = ctx.kg * ctx.m * (ctx.m if rot else 1.0)
    had_drive = prim.HasAPI(UsdPhysics.DriveAPI, dof)
    edit.apply(prim, f"PhysicsDriveAPI:{dof}")
    drive = f"drive:{dof}:physics:"
    if not had_drive:
        edit.set(prim, drive + "stiffness", 0.0)
    edit.set(prim, drive + "damping", float(damping / gain))
    if stiffness is not None:
        edit.set(prim, drive + "stiffness", float(stiffness / gain))
        if stiffness > 0 and reference is not None:
            edit.set(prim, drive + "targetPosition", float(reference * (DEG if rot else 1.0 / ctx.m)))
    for i, name in enumerate(FRICTION_ATTRS):
        if i == 0 or prim.GetAttribute(name).HasAuthoredValue():
            edit.set(prim, name, float(friction / force))


def write_host_usd(out_dir: Path | str, source: Path | str) -> HostUsdExport:
    """Write the refined output in ``out_dir`` back into the USD stage ``source`` it was refined from.

    Args:
        out_dir: a refined output folder (``mobility.urdf``, ``overlay.json``, ``initial_state.json``).
        source: the USD file the refine read (only read; its layers opened under the reader's trust rules).

    Returns:
        :class:`HostUsdExport`: ``usd/host/<source name>``, ``<stem>.physics.usda`` and ``<stem>.diff``, inside
        ``out_dir``.

    Raises:
        ImportError: usd-core is not installed.
        StagingError: the stage cannot be opened or read again.
        HostUsdError: the output was rescaled; a refined link or joint has no prim in the stage; the written
            stage loses a prim path or does not hold a refined value.
    """
    out_dir, source = Path(out_dir), Path(source)
    with output_folder.guarding(out_dir):  # nothing through a symlinked usd/ or usd/host/
        _, _, _, Usd, _, UsdPhysics = pxr_modules()
        asset = RefinedAsset(out_dir)
        overlay = host_overlay(asset, source, "stage", HostUsdError)
        model, state = asset.model, asset.initial_state
        read = reader.read_usd_asset(source)
        ctx = open_stage(source)
        stage = ctx.stage
        before = _prim_paths(stage, Usd)
        stage.SetEditTarget(Usd.EditTarget(stage.GetSessionLayer()))
        edit = UsdEdit()
        for name, link in model.links.items():
            if link.inertial is None or not link.inertial.mass:
                continue
            if name not in read.prims:
                raise HostUsdError(f"{source}: link {name!r} of the refined {URDF_NAME} has no rigid body in the stage")
            body = stage.GetPrimAtPath(read.prims[name])
            set_body_mass(edit, ctx, body, read.frames[name], ctx.world(body), float(link.inertial.mass), link.inertial.com(),
                          link.inertial.inertia_in_link_axes())
        for j in model.movable_joints:
            if j.name not in read.prims:
                raise HostUsdError(f"{source}: joint {j.name!r} of the refined {URDF_NAME} has no joint prim in the stage")
            prim = stage.GetPrimAtPath(read.prims[j.name])
            rot = prim.IsA(UsdPhysics.RevoluteJoint)
            unit = DEG if rot else 1.0 / ctx.m  # rad -> degrees, m -> stage units
            dyn = overlay.joints.get(j.name)
            set_joint_dynamics(edit, ctx, prim, j.damping or 0.0, j.friction or 0.0,
                               None if dyn is None else float(dyn.stiffness),
                               None if dyn is None else dyn.spring_reference)
            if j.type != "continuous" and j.limit is not None and j.limit.lower is not None and j.limit.upper is not None:
                edit.set(prim, "physics:lowerLimit", float(j.limit.lower * unit))
                edit.set(prim, "physics:upperLimit", float(j.limit.upper * unit))
            dof = "angular" if rot else "linear"
            position = float(state.get(j.name, 0.0) * unit)
            edit.apply(prim, f"PhysicsJointStateAPI:{dof}")
            edit.set(prim, f"state:{dof}:physics:position", position)
            edit.set(prim, f"state:{dof}:physics:velocity", 0.0)
            edit.set(prim, f"newton:{dof}:position", position)
        folder = out_dir / USD_DIR / HOST_DIR
        stem = file_names.file_stem(source.stem)
        name = f"{stem}.usd" if source.suffix.lower() == ".usdz" else file_names.file_stem(source.name)
        path = file_names.join_inside(folder, name)
        _write_layer(stage.Flatten(), path)
        layer = file_names.join_inside(folder, f"{stem}.physics.usda")
        atomic.write_text(layer, stage.GetSessionLayer().ExportToString())
        _check(source, path, before, edit, Usd)
        diff = file_names.join_inside(folder, f"{stem}.diff")
        atomic.write_text(diff, "".join(line + "\n" for line in edit.lines()))
        prims = tuple(dict.fromkeys(p for p, *_ in edit.changes))
        return HostUsdExport(path=path, layer=layer, diff=diff, prims=prims, changes=len(edit.changes))


def _prim_paths(stage, Usd) -> list[str]:
    """Every prim path of a stage (instance proxies included), sorted."""
    return sorted(str(p.GetPath()) for p in stage.Traverse(Usd.TraverseInstanceProxies(Usd.PrimAllPrimsPredicate)))


def _write_layer(layer, path: Path) -> None:
    """``layer`` written atomically at ``path`` in the format its suffix names (``.usdc`` binary, else text)."""
    if path.suffix.lower() == ".usdc":
        with tempfile.TemporaryDirectory() as tmp:
            scratch = Path(tmp) / path.name
            if not layer.Export(str(scratch)):
                raise HostUsdError(f"{path}: the stage could not be exported")
            atomic.write_bytes(path, scratch.read_bytes())
    else:
        atomic.write_text(path, layer.ExportToString())


def _check(source: Path, path: Path, before: list[str], edit: UsdEdit, Usd) -> None:
    """The written stage has the input's prim paths and holds every authored value."""
    written = Usd.Stage.Open(str(path))
    if written is None:
        raise HostUsdError(f"{path}: the written stage does not open")
    after = _prim_paths(written, Usd)
    if after != before:
        lost, added = sorted(set(before) - set(after)), sorted(set(after) - set(before))
        raise HostUsdError(f"{source}: the host stage changes prim paths (lost {lost[:5]}, added {added[:5]})")
    for prim_path, name, _, new in edit.changes:
        got = written.GetPrimAtPath(prim_path).GetAttribute(name).Get()
        if got is None or not np.allclose(_numbers(got), _numbers(new), rtol=VALUE_RTOL, atol=0.0):
            raise HostUsdError(f"{path}: {prim_path}.{name} reads {got}, not the refined {new}")


def write_patched_usd(source: Path, read: ReadAsset | None, children: dict[str, str], links: dict[str, LinkPhysics],
                      joints: dict[str, JointDynamics], folder: Path, staged_urdf: Path | None = None) -> Path:
    """The audit's patch of the USD stage ``source``: ``folder/<stem>.usda``, the stage flattened into one layer
    (references and sublayers resolved; the input's layers are only read) with ``links``' mass, center of mass and
    inertia tensor and ``joints``' damping and friction (SI, the asset model's link frames) in stage units
    (:func:`set_body_mass`, :func:`set_joint_dynamics`) on the prims ``read`` (what the reader read) recorded for
    them. ``children`` and ``staged_urdf`` are not used (the table's writers share one signature).

    Raises:
        ImportError: usd-core is not installed.
        StagingError: the stage cannot be opened.
        KeyError: a link or joint the reader did not record a prim for.
    """
    Usd = pxr_modules()[3]
    assert read is not None
    ctx = open_stage(Path(source))
    layer = ctx.stage.Flatten()
    stage = Usd.Stage.Open(layer)
    edit = UsdEdit()
    for name, lp in links.items():
        body = stage.GetPrimAtPath(read.prims[name])
        set_body_mass(edit, ctx, body, read.frames[name], ctx.world(body), lp.mass, np.asarray(lp.com, float),
                      lp.inertia.matrix())
    for name, jd in joints.items():
        set_joint_dynamics(edit, ctx, stage.GetPrimAtPath(read.prims[name]), jd.damping, jd.friction)
    out = folder / f"{file_names.file_stem(Path(source).stem)}.usda"
    atomic.write_text(out, layer.ExportToString())
    return out
