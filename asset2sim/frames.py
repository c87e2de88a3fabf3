"""Frames: rotations, rigid transforms and quaternions, in one place.

Conventions of the whole project: angles rad, lengths m (or the asset's
units); URDF ``rpy`` (3,) about fixed axes X, Y, Z, ``R = Rz(yaw) @ Ry(pitch)
@ Rx(roll)`` (as scipy's ``Rotation.from_euler("xyz", rpy)``); rotations (3, 3)
act on column vectors, ``x_parent = R @ x_child``; transforms (4, 4) hold
``R`` and ``t``; unit Hamilton quaternions in the order the function name says:
``wxyz`` (MuJoCo, SAPIEN, MJCF) or ``xyzw`` (PyBullet, scipy).
"""

from __future__ import annotations

import math
from typing import Iterable

import numpy as np

__all__ = [
    "axis_angle_matrix", "axis_rotation", "matrix_quat_wxyz", "matrix_rpy", "pose_matrix", "quat_angle",
    "quat_wxyz_matrix", "quat_wxyz_to_xyzw", "quat_xyzw_to_wxyz", "rigid_inverse", "rigid_matrix", "rigid_part",
    "rpy_matrix", "translation_matrix"
]

#: Threshold of ``cos(pitch)`` under which :func:`matrix_rpy` treats the
#: rotation as gimbal locked (``trimesh.transformations._EPS``: 4 machine eps).
_GIMBAL_EPS = float(np.finfo(float).eps) * 4.0


def rpy_matrix(rpy: Iterable[float]) -> np.ndarray:
    """Rotation matrix (3, 3) of URDF roll-pitch-yaw ``rpy`` (3,) rad, in closed
    form (ValueError: not three numbers)."""
    r, p, y = (float(v) for v in rpy)
    cr, sr, cp, sp, cy, sy = math.cos(r), math.sin(r), math.cos(p), math.sin(p), math.cos(y), math.sin(y)
    return np.array([[cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
                     [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
                     [-sp, cp * sr, cp * cr]])


def matrix_rpy(r: np.ndarray) -> np.ndarray:
    """URDF roll-pitch-yaw (3,) rad of a rotation matrix ``r`` (3, 3) (or the
    rotation block of a (4, 4) transform), inverse of :func:`rpy_matrix`: pitch in
    [-pi/2, pi/2], yaw 0 at gimbal lock. Operation for operation as trimesh's
    ``euler_from_matrix(r, "sxyz")`` (Gohlke, after Shoemake, Graphics Gems IV)."""
    m = np.asarray(r, dtype=np.float64)[:3, :3]
    cy = np.sqrt(m[0, 0] * m[0, 0] + m[1, 0] * m[1, 0])
    ay = np.arctan2(-m[2, 0], cy)
    if cy > _GIMBAL_EPS:
        ax = np.arctan2(m[2, 1], m[2, 2])
        az = np.arctan2(m[1, 0], m[0, 0])
    else:
        ax = np.arctan2(-m[1, 2], m[1, 1])
        az = 0.0
    return np.array([float(ax), float(ay), float(az)])


def translation_matrix(xyz: Iterable[float]) -> np.ndarray:
    """Homogeneous transform (4, 4): identity rotation, translation ``xyz`` (3,)."""
    return rigid_matrix(np.eye(3), xyz)


def rigid_matrix(rotation: np.ndarray, translation: Iterable[float] = (0.0, 0.0, 0.0)) -> np.ndarray:
    """Homogeneous transform (4, 4) of a rotation (3, 3) and a translation (3,)."""
    t = np.eye(4)
    t[:3, :3] = np.asarray(rotation, float)
    t[:3, 3] = np.asarray(translation, float)
    return t


def rigid_inverse(m: np.ndarray) -> np.ndarray:
    """Inverse (4, 4) of a rigid transform ``m`` (4, 4): ``R^T`` and ``-R^T t``."""
    r = np.asarray(m, float)[:3, :3]
    return rigid_matrix(r.T, -r.T @ np.asarray(m, float)[:3, 3])


def rigid_part(m: np.ndarray) -> np.ndarray:
    """The rigid part (4, 4) of a transform ``m`` (4, 4) that may scale or shear: the rotation of the polar
    decomposition of its (3, 3) block (a proper rotation, also for a mirror), the same translation."""
    u, _, vt = np.linalg.svd(np.asarray(m, float)[:3, :3])
    if np.linalg.det(u @ vt) < 0:
        u[:, 2] = -u[:, 2]
    return rigid_matrix(u @ vt, np.asarray(m, float)[:3, 3])


def pose_matrix(xyz: Iterable[float] = (0.0, 0.0, 0.0), rpy: Iterable[float] = (0.0, 0.0, 0.0)) -> np.ndarray:
    """Homogeneous transform (4, 4) of a URDF ``<origin xyz rpy>``: translation
    ``xyz`` (3,) m, rotation :func:`rpy_matrix` of ``rpy`` (3,) rad."""
    return rigid_matrix(rpy_matrix(rpy), xyz)


def axis_angle_matrix(axis: Iterable[float], angle: float) -> np.ndarray:
    """Rotation (3, 3) of ``angle`` rad about ``axis`` (3,) (normalised here; NaN
    for a zero axis): Rodrigues' ``I + sin(a) K + (1 - cos(a)) K^2``."""
    a = np.asarray(axis, float)
    a = a / np.linalg.norm(a)
    k = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    return np.eye(3) + math.sin(angle) * k + (1 - math.cos(angle)) * (k @ k)


def axis_rotation(axis: int, angle: float) -> np.ndarray:
    """Elementary rotation (3, 3) of ``angle`` rad about coordinate axis
    ``axis`` (0 = X, 1 = Y, anything else = Z), right-handed."""
    c, s = np.cos(angle), np.sin(angle)
    if axis == 0:
        return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])
    if axis == 1:
        return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def matrix_quat_wxyz(r: np.ndarray) -> np.ndarray:
    """Unit quaternion (4,) **w, x, y, z** of a rotation matrix ``r`` (3, 3),
    ``w >= 0``: Shepperd's method, as MuJoCo's ``mju_mat2Quat``."""
    r = np.asarray(r, float)
    tr = r[0, 0] + r[1, 1] + r[2, 2]
    if tr > 0:
        s = math.sqrt(tr + 1.0) * 2
        q = [0.25 * s, (r[2, 1] - r[1, 2]) / s, (r[0, 2] - r[2, 0]) / s, (r[1, 0] - r[0, 1]) / s]
    elif r[0, 0] > r[1, 1] and r[0, 0] > r[2, 2]:
        s = math.sqrt(1.0 + r[0, 0] - r[1, 1] - r[2, 2]) * 2
        q = [(r[2, 1] - r[1, 2]) / s, 0.25 * s, (r[0, 1] + r[1, 0]) / s, (r[0, 2] + r[2, 0]) / s]
    elif r[1, 1] > r[2, 2]:
        s = math.sqrt(1.0 + r[1, 1] - r[0, 0] - r[2, 2]) * 2
        q = [(r[0, 2] - r[2, 0]) / s, (r[0, 1] + r[1, 0]) / s, 0.25 * s, (r[1, 2] + r[2, 1]) / s]
    else:
        s = math.sqrt(1.0 + r[2, 2] - r[0, 0] - r[1, 1]) * 2
        q = [(r[1, 0] - r[0, 1]) / s, (r[0, 2] + r[2, 0]) / s, (r[1, 2] + r[2, 1]) / s, 0.25 * s]
    q = np.array(q)
    q /= np.linalg.norm(q)
    return -q if q[0] < 0 else q


def quat_wxyz_matrix(q: Iterable[float]) -> np.ndarray:
    """Rotation matrix (3, 3) of a unit quaternion ``q`` (4,) **w, x, y, z**
    (standard Hamilton formula; ``q`` is assumed normalised)."""
    w, x, y, z = (float(v) for v in q)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def quat_xyzw_to_wxyz(q: Iterable[float]) -> np.ndarray:
    """Reorder a quaternion (4,) from x, y, z, w (PyBullet) to w, x, y, z (MuJoCo)."""
    x, y, z, w = (float(v) for v in q)
    return np.array([w, x, y, z])


def quat_wxyz_to_xyzw(q: Iterable[float]) -> np.ndarray:
    """Reorder a quaternion (4,) from w, x, y, z (MuJoCo) to x, y, z, w (PyBullet)."""
    w, x, y, z = (float(v) for v in q)
    return np.array([x, y, z, w])


def quat_angle(q0: Iterable[float], q1: Iterable[float]) -> float:
    """Rotation angle (rad, in [0, pi]) between two unit quaternions (4,) given
    in the same order (both xyzw or both wxyz): ``2 acos(|q0 . q1|)``."""
    d = abs(float(np.dot(np.asarray(q0, float), np.asarray(q1, float))))
    return float(2.0 * np.arccos(min(1.0, d)))
