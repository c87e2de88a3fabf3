"""Names, numbers and paths as the MJCF converter writes them, and its error.

Numbers are written at full precision (shortest round-trip text), where
MuJoCo's own ``to_xml`` writes 6 significant digits.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from asset2sim.frames import matrix_quat_wxyz

#: Folder (relative to the MJCF file's meshdir, the asset folder) of the convex
#: pieces the exporter writes.
DERIVED_MESH_DIR = "mjcf/meshes"
#: Name of the keyframe that holds the initial state.
KEYFRAME = "initial"
#: Name of the root's free joint.
FREE_JOINT = "root_free"
#: Name of the ground plane geom.
GROUND = "ground"
#: MuJoCo's friction (contact friction and joint ``frictionloss``) is a soft
#: constraint that lets a loaded joint creep; the no-slip post-processing
#: removes that, so friction holds as Coulomb friction does in Bullet and
#: PhysX (a lid held by 0.5 N*m against 0.16 N*m of gravity creeps 0.2 rad in
#: 3 s without it, 0 with it).
NOSLIP_ITERATIONS = 10
#: Friction cones: elliptic with impratio 10 (MuJoCo's advice for resting and
#: manipulated objects). With the default pyramidal cones, the no-slip pass
#: made the refined laptop 9748 walk 1 mm and the faucet 148 rock 2.3 mm
#: during the rest test (both still in PyBullet and PhysX); elliptic cones
#: keep them still (3e-9 m, 2e-6 m).
IMPRATIO = 10.0


class MjcfError(RuntimeError):
    """MuJoCo cannot import the URDF or compile the MJCF (names the file)."""


def num_text(x: float) -> str:
    """Shortest round-trip text of a float."""
    x = float(x)
    if x == 0.0:
        return "0"
    return repr(x)


def vec_text(v) -> str:
    """Numbers of ``v`` (any shape, flattened) as :func:`num_text`, space separated."""
    return " ".join(num_text(x) for x in np.asarray(v, float).ravel())


def safe_name(name: str) -> str:
    """``name`` with every character other than letters, digits, ``-_.`` as ``_``
    (for MJCF element names and file names)."""
    return "".join(ch if ch.isalnum() or ch in "-_." else "_" for ch in name)


def relative_to(path: Path, root: Path) -> str | None:
    """POSIX path of ``path`` relative to ``root`` (both resolved), or None when
    it is outside ``root``."""
    try:
        return path.resolve().relative_to(root.resolve()).as_posix()
    except ValueError:
        return None


def quat_text(r: np.ndarray) -> str:
    """The rotation matrix ``r`` (3, 3) as MJCF ``quat`` text (w x y z)."""
    return vec_text(matrix_quat_wxyz(r))


def close(a, b, tol: float) -> bool:
    """Whether arrays ``a`` and ``b`` agree to ``tol``, absolute and relative."""
    return bool(np.allclose(np.asarray(a, float), np.asarray(b, float), atol=tol, rtol=tol))
