"""MuJoCo itself (imported only here, on first use): its messages, the compile
of the converted MJCF with the root placed on the ground, and the lowest
point of a compiled model.
"""

from __future__ import annotations

import contextlib
import math
import warnings
from pathlib import Path

import numpy as np
from lxml import etree

from asset2sim.engines.mjcf.base import MjcfError, vec_text


def load_mujoco():
    """The ``mujoco`` module (imported here so the package imports without it).

    Raises:
        ImportError: MuJoCo is not installed (``pip install 'asset2sim[mujoco]'``).
    """
    import mujoco

    return mujoco


@contextlib.contextmanager
def mujoco_messages():
    """Collect MuJoCo's warnings (list of str) instead of letting MuJoCo print
    them and append them to ``MUJOCO_LOG.TXT`` in the working directory (its
    default handler) or raise Python warnings (the MjSpec compiler)."""
    mujoco = load_mujoco()
    collected: list[str] = []
    previous = mujoco.get_mju_user_warning()
    mujoco.set_mju_user_warning(lambda msg: collected.append(str(msg)))
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            yield collected
        collected.extend(str(w.message) for w in caught)
    finally:
        mujoco.set_mju_user_warning(previous)


def compile_xml(xml: str, assets: dict[str, bytes], urdf_path: Path):
    """Compile the MJCF text ``xml`` with the mesh ``assets`` (relative path
    -> bytes); returns the ``MjModel``.

    Raises:
        MjcfError: MuJoCo refuses it (names the URDF it came from).
    """
    mujoco = load_mujoco()
    try:
        with mujoco_messages():
            return mujoco.MjModel.from_xml_string(xml, assets=assets)
    except Exception as exc:
        raise MjcfError(f"{urdf_path}: the converted MJCF does not compile: {exc}") from exc


def place_on_ground(root, root_body, assets: dict[str, bytes], initial_state: dict[str, float], fixed_base: bool,
                     urdf_path: Path, notes: list[str]):
    """Compile ``root`` and lift the root so the lowest collision point
    touches z = 0 at the initial state (:func:`lowest_point`); returns
    (compiled ``MjModel``, keyframe qpos (nq,), height m).

    Raises:
        MjcfError: the MJCF does not compile.
    """
    mujoco = load_mujoco()
    xml = etree.tostring(root, encoding="unicode")
    try:
        with mujoco_messages() as caught:
            compiled = mujoco.MjModel.from_xml_string(xml, assets=assets)
    except Exception as exc:
        raise MjcfError(f"{urdf_path}: the converted MJCF does not compile: {exc}") from exc
    notes.extend(mujoco_warnings(caught))
    qpos = compiled.qpos0.copy()
    for name, value in initial_state.items():
        jid = mujoco.mj_name2id(compiled, mujoco.mjtObj.mjOBJ_JOINT, name)
        qpos[compiled.jnt_qposadr[jid]] = float(value)
    height = 0.0
    if not fixed_base:
        data = mujoco.MjData(compiled)
        data.qpos[:] = qpos
        mujoco.mj_kinematics(compiled, data)
        low = lowest_point(compiled, data)
        height = -low if math.isfinite(low) else 0.0
        qpos[2] += height
        root_body.set("pos", vec_text([0.0, 0.0, height]))
        root_body.set("quat", "1 0 0 0")
    return compiled, qpos, height


def mujoco_warnings(caught: list[str]) -> list[str]:
    """MuJoCo's compiler warnings as notes (texture-coordinate complaints about
    OBJ files are dropped: collision meshes carry no texture)."""
    return [f"MuJoCo: {text}" for text in caught if "texture coordinate" not in text]


def lowest_point(m, d) -> float:
    """Lowest z (m) of any colliding geom of the object (the ground excluded)
    for the kinematics in ``d``: mesh vertices, box corners, sphere and
    cylinder extremes. ``+inf`` when there is none."""
    mujoco = load_mujoco()
    low = math.inf
    for g in range(m.ngeom):
        gt = m.geom_type[g]
        if gt == mujoco.mjtGeom.mjGEOM_PLANE or (m.geom_contype[g] == 0 and m.geom_conaffinity[g] == 0):
            continue
        pos, mat = d.geom_xpos[g], d.geom_xmat[g].reshape(3, 3)
        size = m.geom_size[g]
        if gt == mujoco.mjtGeom.mjGEOM_MESH:
            mid = m.geom_dataid[g]
            a, n = m.mesh_vertadr[mid], m.mesh_vertnum[mid]
            z = pos[2] + m.mesh_vert[a:a + n] @ mat[2]
            low = min(low, float(z.min()))
        elif gt == mujoco.mjtGeom.mjGEOM_BOX:
            corners = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)]) * size
            low = min(low, float((pos[2] + corners @ mat[2]).min()))
        elif gt == mujoco.mjtGeom.mjGEOM_SPHERE:
            low = min(low, float(pos[2] - size[0]))
        elif gt == mujoco.mjtGeom.mjGEOM_CYLINDER:
            axis = mat[:, 2]
            radial = size[0] * math.sqrt(max(0.0, 1 - axis[2] ** 2))
            low = min(low, float(pos[2] - abs(axis[2]) * size[1] - radial))
        else:  # capsule, ellipsoid: bounding sphere (not produced from URDF)
            low = min(low, float(pos[2] - m.geom_rbound[g]))
    return low
