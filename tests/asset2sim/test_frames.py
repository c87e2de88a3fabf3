"""``asset2sim.frames`` against scipy's Rotation and trimesh.transformations."""

from __future__ import annotations

import math

import numpy as np
import pytest
import trimesh.transformations as tf
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from asset2sim import frames

angles = st.floats(-2 * math.pi, 2 * math.pi, allow_nan=False)
rpys = st.tuples(angles, angles, angles)


@settings(max_examples=200, deadline=None)
@given(rpy=rpys)
def test_rpy_matrix_is_urdf_fixed_axes_xyz(rpy):
    r = frames.rpy_matrix(rpy)
    assert np.allclose(r, Rotation.from_euler("xyz", rpy).as_matrix(), atol=1e-12)
    assert np.allclose(r, tf.euler_matrix(*rpy, axes="sxyz")[:3, :3], atol=1e-12)
    assert np.allclose(r @ r.T, np.eye(3), atol=1e-12) and np.linalg.det(r) == pytest.approx(1.0)


def test_rpy_matrix_order_is_yaw_pitch_roll_product():
    roll, pitch, yaw = 0.3, -0.7, 1.9
    expect = frames.axis_rotation(2, yaw) @ frames.axis_rotation(1, pitch) @ frames.axis_rotation(0, roll)
    assert np.allclose(frames.rpy_matrix((roll, pitch, yaw)), expect, atol=1e-15)


@settings(max_examples=200, deadline=None)
@given(rpy=rpys)
def test_matrix_rpy_inverts_and_matches_trimesh_bit_for_bit(rpy):
    r = frames.rpy_matrix(rpy)
    back = frames.matrix_rpy(r)
    assert np.allclose(frames.rpy_matrix(back), r, atol=1e-12)
    assert -math.pi / 2 <= back[1] <= math.pi / 2
    assert np.array_equal(back, np.array(tf.euler_from_matrix(r, "sxyz")))
    t = frames.pose_matrix((1.0, 2.0, 3.0), rpy)
    assert np.array_equal(frames.matrix_rpy(t), back)  # a (4, 4) transform reads its rotation block


def test_matrix_rpy_gimbal_lock_puts_the_turn_into_roll():
    r = frames.rpy_matrix((0.4, math.pi / 2, 0.0))
    back = frames.matrix_rpy(r)
    assert back[2] == 0.0 and back[1] == pytest.approx(math.pi / 2)
    assert np.allclose(frames.rpy_matrix(back), r, atol=1e-12)


def test_pose_and_translation_matrix():
    t = frames.pose_matrix((0.1, -0.2, 0.3), (0.0, 0.0, math.pi / 2))
    assert np.allclose(t @ [1.0, 0.0, 0.0, 1.0], [0.1, 0.8, 0.3, 1.0])
    assert np.array_equal(frames.pose_matrix(), np.eye(4))
    assert np.array_equal(frames.translation_matrix((1, 2, 3))[:3, 3], [1.0, 2.0, 3.0])


@settings(max_examples=100, deadline=None)
@given(axis=st.tuples(*[st.floats(-1, 1)] * 3).filter(lambda a: np.linalg.norm(a) > 1e-3), angle=angles)
def test_axis_angle_matrix_matches_rotvec(axis, angle):
    a = np.asarray(axis) / np.linalg.norm(axis)
    expect = Rotation.from_rotvec(a * angle).as_matrix()
    assert np.allclose(frames.axis_angle_matrix(axis, angle), expect, atol=1e-12)
    assert np.allclose(frames.axis_angle_matrix(np.asarray(axis) * 7.0, angle), expect, atol=1e-12)  # not unit: normalised


@pytest.mark.parametrize("k", [0, 1, 2])
def test_axis_rotation_is_the_elementary_rotation(k):
    e = np.eye(3)[k]
    assert np.allclose(frames.axis_rotation(k, 0.8), Rotation.from_rotvec(e * 0.8).as_matrix(), atol=1e-15)


@settings(max_examples=200, deadline=None)
@given(rpy=rpys)
def test_quaternions_wxyz_against_scipy_xyzw(rpy):
    r = frames.rpy_matrix(rpy)
    q = frames.matrix_quat_wxyz(r)
    assert q[0] >= 0 and np.linalg.norm(q) == pytest.approx(1.0)
    sx = Rotation.from_matrix(r).as_quat()  # scipy: x, y, z, w
    assert np.allclose(frames.quat_xyzw_to_wxyz(sx) * np.sign(sx[3] or 1.0), q, atol=1e-9)
    assert np.allclose(frames.quat_wxyz_matrix(q), r, atol=1e-12)
    assert np.array_equal(frames.quat_xyzw_to_wxyz(frames.quat_wxyz_to_xyzw(q)), q)


def test_matrix_quat_covers_every_pivot_branch():
    for rpy in [(0, 0, 0), (math.pi, 0, 0), (0, math.pi, 0), (0, 0, math.pi), (math.pi - 1e-3, 0.2, 0.1)]:
        r = frames.rpy_matrix(rpy)
        assert np.allclose(frames.quat_wxyz_matrix(frames.matrix_quat_wxyz(r)), r, atol=1e-12)


def test_quat_angle():
    q0 = Rotation.identity().as_quat()
    q1 = Rotation.from_rotvec([0, 0, 0.5]).as_quat()
    assert frames.quat_angle(q0, q1) == pytest.approx(0.5)
    assert frames.quat_angle(q1, -q1) == pytest.approx(0.0, abs=1e-7)  # q and -q are the same rotation
    assert frames.quat_angle(frames.quat_xyzw_to_wxyz(q0), frames.quat_xyzw_to_wxyz(q1)) == pytest.approx(0.5)
