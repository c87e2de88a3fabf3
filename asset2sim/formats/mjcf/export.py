"""Export an output folder to MJCF (MuJoCo), derived from ``mobility.urdf`` (the source of truth),
``overlay.json`` (springs) and ``initial_state.json`` (the keyframe) by
:func:`asset2sim.engines.mjcf.urdf_to_mjcf`. Written as ``mjcf/<urdf stem>.xml`` (every file it names relative
to its own folder, ``../collision/...``, no ``meshdir``: hosts that resolve files against the MJCF's folder, as
robosuite's ``MujocoXML`` does, load it too) and ``mjcf/meshes/*.obj`` (convex pieces MuJoCo cannot take
from the original files), then checked by loading the written file with MuJoCo (:func:`check_mjcf`).
A re-export removes the pieces it no longer uses, only those the folder records as the product's.
"""

from __future__ import annotations

import json
import math
import os
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from asset2sim import atomic, file_names, output_folder
from asset2sim.extras import import_extra
from asset2sim.output_folder import MJCF_DIR, STATE_NAME
from asset2sim.engines.base import SessionOptions
from asset2sim.engines.loading import read_urdf
from asset2sim.refined_asset import RefinedAsset
from asset2sim.engines.mjcf import KEYFRAME, mujoco_messages, urdf_to_mjcf
from asset2sim.engines.mjcf.aids import AIDS_TEXT
from asset2sim.engines.mjcf.base import load_mujoco
from asset2sim.safexml import parse_xml_file
from asset2sim.schemas.report import SolverAid
from asset2sim.frames import quat_wxyz_matrix

#: Relative tolerance of the check that a written MJCF file carries the refined masses.
MASS_RTOL = 1e-6
_DERIVED = re.compile(r".+__c\d+_g\d+\.obj$")


class ExportError(RuntimeError):
    """The export failed or did not check out (names the folder and the check)."""


@dataclass
class MjcfCheck:
    """What the exported file compiled to: ``total_mass`` kg (MJCF) vs
    ``urdf_mass`` kg, the keyframe's joint values vs ``initial_state.json``,
    and per-body inertial differences (largest absolute, SI units)."""

    total_mass: float
    urdf_mass: float
    keyframe: dict[str, float]
    initial_state: dict[str, float]
    max_com_error: float
    max_inertia_error: float


def check_mjcf(xml_path: Path, urdf_path: Path, initial_state: dict[str, float], fixed_base: bool = False,
               shown: Path | None = None) -> MjcfCheck:
    """Load ``xml_path`` with MuJoCo and compare it with the URDF: per body mass, COM (link frame) and
    inertia tensor about the COM (link axes) against the link's ``<inertial>`` (none: massless); the
    keyframe ``initial`` against ``initial_state`` (0 for joints it does not list); with ``fixed_base``
    (a mounted asset), no free joint. ``shown``: the path the errors name (default ``xml_path``; a file
    checked before it is moved into place).

    Raises:
        ExportError: MuJoCo cannot load the file, or a check fails (total mass
            beyond 1e-6 relative, a body's inertial beyond 1e-9 absolute /
            1e-6 relative, a keyframe value beyond 1e-12).
    """
    mujoco = load_mujoco()
    try:
        with mujoco_messages():
            m = mujoco.MjModel.from_xml_path(str(xml_path))
    except Exception as exc:
        raise ExportError(f"MuJoCo cannot load the exported {shown or xml_path}: {exc}") from exc
    xml_path = shown or xml_path
    urdf = read_urdf(urdf_path)
    urdf_mass = urdf.total_mass()
    total = float(m.body_mass[1:].sum())
    if not math.isclose(total, urdf_mass, rel_tol=MASS_RTOL, abs_tol=1e-12):
        raise ExportError(f"{xml_path}: total mass {total!r} kg, the URDF's {urdf_mass!r} kg")
    com_err = inertia_err = 0.0
    for name, link in urdf.links.items():
        bid = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, name)
        if bid < 0:
            raise ExportError(f"{xml_path}: no body for URDF link {name!r}")
        mass = float(m.body_mass[bid])
        if link.inertial is None:
            if mass != 0.0:
                raise ExportError(f"{xml_path}: body {name!r} weighs {mass} kg, the URDF link has no <inertial>")
            continue
        r = quat_wxyz_matrix(m.body_iquat[bid])
        tensor = r @ np.diag(m.body_inertia[bid]) @ r.T
        want = link.inertial.inertia_in_link_axes()
        dc = float(np.abs(m.body_ipos[bid] - link.inertial.com()).max())
        di = float(np.abs(tensor - want).max())
        scale = float(np.abs(want).max())
        if not math.isclose(mass, link.inertial.mass, rel_tol=MASS_RTOL) or dc > 1e-9 + 1e-9 * float(np.abs(link.inertial.com()).max()) or di > 1e-12 + 1e-6 * scale:
            raise ExportError(
                f"{xml_path}: body {name!r} has mass {mass}, COM {m.body_ipos[bid]}, inertia {tensor.tolist()}; "
                f"the URDF {link.inertial.mass}, {link.inertial.com()}, {want.tolist()}"
            )
        com_err, inertia_err = max(com_err, dc), max(inertia_err, di)
    if fixed_base and any(int(t) == int(mujoco.mjtJoint.mjJNT_FREE) for t in m.jnt_type):
        raise ExportError(f"{xml_path}: the asset is mounted (fixed root) but the MJCF has a free joint")
    kid = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_KEY, KEYFRAME)
    if kid < 0:
        raise ExportError(f"{xml_path}: no keyframe {KEYFRAME!r}")
    qpos = m.key_qpos[kid]
    key = {}
    for j in urdf.movable_joints:
        jid = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, j.name)
        if jid < 0:
            raise ExportError(f"{xml_path}: no joint {j.name!r}")
        key[j.name] = float(qpos[m.jnt_qposadr[jid]])
        want = float(initial_state.get(j.name, 0.0))
        if abs(key[j.name] - want) > 1e-12:
            raise ExportError(f"{xml_path}: keyframe {j.name} = {key[j.name]!r}, {STATE_NAME} says {want!r}")
    return MjcfCheck(total_mass=total, urdf_mass=urdf_mass, keyframe=key, initial_state=dict(initial_state),
                     max_com_error=com_err, max_inertia_error=inertia_err)


def export_mjcf(out_dir: Path | RefinedAsset, *, visuals: bool = True, check: bool = True) -> Path:
    """Write ``out_dir/mjcf/<urdf stem>.xml`` (and its derived meshes) from
    ``out_dir/mobility.urdf``, ``overlay.json`` and ``initial_state.json``.

    Args:
        out_dir: an output folder of the SPEC's contract (or its :class:`~asset2sim.refined_asset.RefinedAsset`).
        visuals: include the visual meshes (non-colliding, group 2).
        check: load the file as written with MuJoCo and run :func:`check_mjcf` before it replaces the MJCF file
            (the one compile with the visual meshes; a file that fails is not left in ``out_dir``).

    Returns:
        The path of the MJCF file.

    Raises:
        FileNotFoundError: no ``mobility.urdf`` in ``out_dir``.
        MissingExtra (an ImportError): MuJoCo is not installed (the message names the extra, ``[mujoco]``).
        ValueError: invalid ``initial_state.json`` / ``overlay.json``.
        UrdfError, MjcfError, ExportError: the URDF cannot be read, converted,
            compiled, or the written file does not check out (an earlier MJCF file then stays as it was).
    """
    import_extra("mujoco", "the MJCF export")  # the one-line hint naming the extra when it is missing

    asset = RefinedAsset.existing(out_dir)
    out_dir, urdf, initial, springs = asset.folder, asset.urdf_path, asset.initial_state, asset.springs
    fixed = asset.root.fixed  # mounted: no free joint, the root welded where the file puts it
    build = urdf_to_mjcf(urdf, SessionOptions(initial_state=initial, springs=springs, fixed_base=fixed, ground=not fixed,
                                              press_efforts=asset.press_efforts),
                         missing_inertial="massless", mesh_root=out_dir, meshdir="..", visuals=visuals, compile_visuals=not check,
                         visual_meshes=asset.meshes)
    for rel, data in build.derived_meshes.items():
        dst = file_names.join_inside(out_dir, rel)
        if not (dst.is_file() and dst.read_bytes() == data):
            atomic.write_bytes(dst, data)
    _remove_stale_pieces(out_dir, set(build.derived_meshes))
    xml_path = out_dir / MJCF_DIR / f"{urdf.stem}.xml"
    text = (
        "Written by asset2sim from mobility.urdf (the source of truth), overlay.json (springs) and "
        "initial_state.json (keyframe 'initial'). Load with mujoco.MjModel.from_xml_path; "
        + ("mj_resetDataKeyframe(model, data, 0) puts the object at its initial state. Mounted asset: the root is "
           "fixed at the world origin (no free joint, no ground plane; initial_state.json \"root\")."
           if fixed else
           "mj_resetDataKeyframe(model, data, 0) puts the object on the ground at its initial state.")
    )
    if build.notes:
        text += " Conversion notes: " + "; ".join(build.notes)
    header = "<!-- " + text.replace("--", "- -") + " -->\n"
    # checked as written, before it replaces the file: a file MuJoCo refuses never lands
    return atomic.write_text(xml_path, header + own_folder_paths(build.xml) + "\n",
                             check=(lambda tmp: check_mjcf(tmp, urdf, initial, fixed_base=fixed, shown=xml_path)) if check else None)


def solver_aids(xml_path: Path) -> list[SolverAid]:
    """The solver aids an exported MJCF file carries in its custom text
    :data:`~asset2sim.engines.mjcf.aids.AIDS_TEXT`, read back from the file ([] without it).

    Raises:
        XMLSecurityError, ET.ParseError, ValueError: the file is not an MJCF export (its XML or the aids' JSON).
    """
    text = parse_xml_file(xml_path).find(f"custom/text[@name='{AIDS_TEXT}']")
    return [] if text is None else [SolverAid.model_validate(a) for a in json.loads(text.get("data", "[]"))]


_FILE_ATTR = re.compile(r'(<(?:mesh|texture|hfield|skin)\b[^>]*?\bfile=")(?![/\\])')


def own_folder_paths(xml: str) -> str:
    """``xml`` (an MJCF written with ``meshdir=".."``) with every asset file named relative to the MJCF's own
    folder (``../collision/x.obj``) and no ``meshdir``: the same files for MuJoCo, and for hosts that join file
    names to the MJCF's folder without reading ``meshdir``."""
    return _FILE_ATTR.sub(r"\1../", xml.replace(' meshdir=".."', "", 1))


def _remove_stale_pieces(out_dir: Path, keep: set[str]) -> None:
    """Remove the convex pieces (``mjcf/meshes/*__c<i>_g<j>.obj``) of an earlier export not in ``keep``
    (paths relative to ``out_dir``) that the output folder's records list as the product's, lying in it
    with no symlink on the way."""
    mesh_dir = out_dir / MJCF_DIR / "meshes"
    root = output_folder.product_folder(out_dir)
    if root is None or not mesh_dir.is_dir() or mesh_dir.is_symlink():
        return
    owned = output_folder.recorded_files(root)
    keep_abs = {Path(os.path.abspath(out_dir / rel)) for rel in keep}
    real_dir = mesh_dir.resolve()
    for p in sorted(mesh_dir.iterdir()):
        if not _DERIVED.match(p.name) or p.is_symlink() or not p.is_file() or Path(os.path.abspath(p)) in keep_abs:
            continue
        try:
            rel = (real_dir / p.name).relative_to(root).as_posix()
        except ValueError:  # the meshes folder lies outside the product folder
            continue
        if rel in owned:
            p.unlink(missing_ok=True)
