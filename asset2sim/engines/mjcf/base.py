"""Names, numbers (full precision, where MuJoCo's ``to_xml`` writes 6 digits)
and paths as the MJCF converter writes them, its error, and MuJoCo itself
(imported on first use): its messages, compiling the converted MJCF with the
root on the ground, the lowest point of a model."""

from __future__ import annotations

import contextlib
import logging
import math
import warnings
from pathlib import Path

import numpy as np
from lxml import etree

from asset2sim.engines.loading import BOX_CORNERS
from asset2sim.frames import matrix_quat_wxyz

#: Folder (relative to the MJCF's meshdir, the asset folder) of the convex pieces the exporter writes.
DERIVED_MESH_DIR = "mjcf/meshes"
#: Name of the keyframe that holds the initial state.
KEYFRAME = "initial"
#: Name of the root's free joint.
FREE_JOINT = "root_free"
#: Name of the ground plane geom.
GROUND = "ground"
#: Friction cones: MuJoCo's default pyramidal cones. MJX (``mujoco-mjx`` 3.17) fails to trace a step of a model with
#: elliptic cones and no contact pair (a mounted object, no ground: "Indexer must have integer or boolean type"), and no
#: ``noslip_iterations`` is written (MJX and most host scenes run without the no-slip pass), so nothing needs elliptic
#: cones any more (``docs/design/simulators.md``, "MuJoCo's soft constraints").
CONE = "pyramidal"
#: Per-dof solver parameters of a joint's dry friction (``frictionloss``), written on a joint whose creep at MuJoCo's
#: defaults the pre-flight criterion of :mod:`asset2sim.engines.mjcf.aids` finds too fast (on the joint itself, so
#: that they travel with the body into MJX and host scenes whatever their ``<default>``): MuJoCo's friction loss is a soft constraint, and
#: a joint loaded below its friction creeps at v = tau (1 - d) / (d I) * d timeconst / 2 (impedance d, time constant
#: timeconst, joint inertia I; MuJoCo documentation, "Computation: soft constraints"). The stiffest the solver allows
#: stops that creep: impedance at MuJoCo's largest (``mjMAXIMP`` 0.9999) and the time constant at two time steps
#: (the least ``refsafe`` keeps; :func:`friction_solref`). Measured on the 21 dev outputs without the no-slip pass:
#: every part held at its initial state, against 11 of 21 objects with MuJoCo's defaults (0.02 s, 0.9/0.95).
FRICTION_SOLIMP = (0.9999, 0.9999, 0.001, 0.5, 2.0)
#: Damping ratio of the friction constraint's reference acceleration (critical).
FRICTION_DAMPRATIO = 1.0
#: Joint armature (kg*m^2 or kg) written on every joint that needs no armature aid (:mod:`.aids`): 0, a passive
#: hinge or slide has no rotor, and an explicit 0 keeps a host scene's ``<default>`` armature from adding inertia the
#: files do not hold.
ARMATURE = 0.0
#: Least effective inertia of a hinge or slide, as a share of the model's mean inertia (``MjModel.stat.meaninertia``,
#: the scale MuJoCo measures its solver against): sqrt(float32 eps), 3.45e-4. A float32 solver (MJX in JAX's default
#: precision) stops when its cost no longer falls by more than rounding (eps x the cost, which the heaviest parts set),
#: so it leaves accelerations accurate to about sqrt(eps) of the model's scale; ``implicitfast`` (and Euler's implicit
#: damping) then turn the left-over error on a dof held by a stiff constraint into an acceleration error d / (1 - d)
#: times larger (impedance d: 0.9999 for friction, :data:`FRICTION_SOLIMP`). On a dof lighter than sqrt(eps) of the
#: scale those errors ratchet a part along its load (a toilet's 7 g flush lever, 1.2e-6 kg*m^2 in a model of mean
#: inertia 0.02, crept 0.047 rad in 3 s in MJX float32 against 7e-4 rad in MuJoCo). The missing inertia is written as
#: ``armature``, MuJoCo's term for inertia added to a dof's diagonal that makes a simulation more stable (MuJoCo XML
#: reference, ``joint/armature``): on the 21 dev outputs 4 small parts (a lever, a pedal, two handles) get 6e-6 to
#: 3e-4 kg*m^2, the inertia of the linkages such parts drive or of a 100 g handle at 5 cm; 1e-4 of the scale was
#: measured too little for the lever (:mod:`.aids`; ``docs/design/simulators.md``).
ARMATURE_FLOOR = float(np.sqrt(np.finfo(np.float32).eps))
def friction_solref(timestep: float) -> tuple[float, float]:
    """``solreffriction`` (time constant s, damping ratio) for a model stepped at ``timestep`` s: the time constant at
    2 ``timestep``, the least MuJoCo's ``refsafe`` flag keeps (a smaller one is raised to it), critically damped."""
    return 2.0 * float(timestep), FRICTION_DAMPRATIO


class MjcfError(RuntimeError):
    """MuJoCo cannot import the URDF or compile the MJCF (names the file)."""


def num_text(x: float) -> str:
    """Shortest round-trip text of a float (``0`` for zero)."""
    x = float(x)
    return "0" if x == 0.0 else repr(x)


def vec_text(v) -> str:
    """Numbers of ``v`` (any shape, flattened) as :func:`num_text`, space separated."""
    return " ".join(num_text(x) for x in np.asarray(v, float).ravel())


def safe_name(name: str) -> str:
    """``name`` with every character other than letters, digits, ``-_.`` as ``_``."""
    return "".join(ch if ch.isalnum() or ch in "-_." else "_" for ch in name)


def relative_to(path: Path, root: Path) -> str | None:
    """POSIX path of ``path`` relative to ``root`` (both resolved); None outside it."""
    try:
        return path.resolve().relative_to(root.resolve()).as_posix()
    except ValueError:
        return None


def quat_text(r: np.ndarray) -> str:
    """The rotation matrix ``r`` (3, 3) as MJCF ``quat`` text (w x y z)."""
    return vec_text(matrix_quat_wxyz(r))


def child(parent, tag: str):
    """``parent``'s first ``<tag>`` child, appended when it has none."""
    el = parent.find(tag)
    return etree.SubElement(parent, tag) if el is None else el


def close(a, b, tol: float) -> bool:
    """Whether arrays ``a`` and ``b`` agree to ``tol``, absolute and relative."""
    return bool(np.allclose(np.asarray(a, float), np.asarray(b, float), atol=tol, rtol=tol))


#: Where MuJoCo's warnings go outside :func:`mujoco_messages`: this logger, never ``MUJOCO_LOG.TXT`` in the
#: working directory (MuJoCo's own handler appends every warning to that file and prints it).
MUJOCO_LOGGER = logging.getLogger("asset2sim.mujoco")


def load_mujoco():
    """The ``mujoco`` module (ImportError: not installed), its warning handler set to :data:`MUJOCO_LOGGER` when
    none is set, so that no MuJoCo warning writes ``MUJOCO_LOG.TXT`` into the current directory."""
    import mujoco

    if mujoco.get_mju_user_warning() is None:
        mujoco.set_mju_user_warning(lambda msg: MUJOCO_LOGGER.warning("MuJoCo: %s", msg))
    return mujoco


@contextlib.contextmanager
def mujoco_messages():
    """Collect MuJoCo's warnings (list of str) instead of letting MuJoCo print
    them, append them to ``MUJOCO_LOG.TXT`` or raise Python warnings."""
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


def mujoco_call(load, failure: str, notes: list[str] | None = None):
    """``load()`` (a MuJoCo import or compile) with MuJoCo's messages collected (:func:`mujoco_messages`), its
    warnings added to ``notes`` as notes (texture-coordinate complaints dropped); returns what ``load`` returns
    (MjcfError ``failure: <MuJoCo's message>`` when it raises)."""
    try:
        with mujoco_messages() as caught:
            out = load()
    except Exception as exc:  # mujoco raises ValueError with its message
        raise MjcfError(f"{failure}: {exc}") from exc
    if notes is not None:
        notes.extend(f"MuJoCo: {text}" for text in caught if "texture coordinate" not in text)
    return out


def compile_xml(xml: str, assets: dict[str, bytes], urdf_path: Path, notes: list[str] | None = None):
    """Compile the MJCF text ``xml`` with the mesh ``assets`` (relative path
    -> bytes), MuJoCo's warnings added to ``notes``; returns the ``MjModel``
    (MjcfError naming the URDF: MuJoCo refuses it)."""
    mujoco = load_mujoco()
    return mujoco_call(lambda: mujoco.MjModel.from_xml_string(xml, assets=assets),
                       f"{urdf_path}: the converted MJCF does not compile", notes)


def place_on_ground(root, root_body, assets: dict[str, bytes], initial_state: dict[str, float], fixed_base: bool,
                     urdf_path: Path, notes: list[str]):
    """Compile ``root`` and lift the root so the lowest collision point touches
    z = 0 at the initial state; returns (``MjModel``, keyframe qpos (nq,), height m)."""
    mujoco = load_mujoco()
    compiled = compile_xml(etree.tostring(root, encoding="unicode"), assets, urdf_path, notes)
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


def mesh_vertices(m, g: int):
    """The vertices (k, 3) of mesh geom ``g`` of model ``m``, in the geom frame (MuJoCo's array)."""
    mid = m.geom_dataid[g]
    return m.mesh_vert[m.mesh_vertadr[mid]:m.mesh_vertadr[mid] + m.mesh_vertnum[mid]]


def lowest_point(m, d) -> float:
    """Lowest z (m) of any colliding geom but the ground for the kinematics in
    ``d`` (``+inf`` when there is none)."""
    mujoco = load_mujoco()
    low = math.inf
    for g in range(m.ngeom):
        gt = m.geom_type[g]
        if gt == mujoco.mjtGeom.mjGEOM_PLANE or (m.geom_contype[g] == 0 and m.geom_conaffinity[g] == 0):
            continue
        pos, mat = d.geom_xpos[g], d.geom_xmat[g].reshape(3, 3)
        size = m.geom_size[g]
        if gt == mujoco.mjtGeom.mjGEOM_MESH:
            z = (pos[2] + mesh_vertices(m, g) @ mat[2]).min()
        elif gt == mujoco.mjtGeom.mjGEOM_BOX:
            z = (pos[2] + BOX_CORNERS * size @ mat[2]).min()
        elif gt == mujoco.mjtGeom.mjGEOM_SPHERE:
            z = pos[2] - size[0]
        elif gt == mujoco.mjtGeom.mjGEOM_CYLINDER:
            axis = mat[:, 2]
            z = pos[2] - abs(axis[2]) * size[1] - size[0] * math.sqrt(max(0.0, 1 - axis[2] ** 2))
        else:  # capsule, ellipsoid: bounding sphere (not produced from URDF)
            z = pos[2] - m.geom_rbound[g]
        low = min(low, float(z))
    return low
