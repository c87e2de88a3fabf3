"""The PyBullet engine follows the SPEC's conventions."""

from __future__ import annotations

import math

import numpy as np
import pytest

from asset2sim.engines.base import SessionOptions, Spring
from asset2sim.engines.registry import open_session
from tests.helpers import write_hinged_plate


def _urdf_with_dynamics(folder, damping, friction, rpy="0 0 0", arm='<box size="0.02 0.02 0.4"/>'):
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "mobility.urdf").write_text(
        f"""<?xml version="1.0"?>
<robot name="pend">
  <link name="base"><inertial><mass value="5"/><inertia ixx="0.1" ixy="0" ixz="0" iyy="0.1" iyz="0" izz="0.1"/></inertial>
    <collision><origin xyz="0 0 0.05" rpy="{rpy}"/><geometry><box size="0.6 0.6 0.1"/></geometry></collision></link>
  <link name="arm"><inertial><origin xyz="0 0 0.2"/><mass value="0.2"/><inertia ixx="0.001" ixy="0" ixz="0" iyy="0.001" iyz="0" izz="0.001"/></inertial>
    <collision><origin xyz="0 0 0.2"/><geometry>{arm}</geometry></collision></link>
  <joint name="j" type="revolute"><parent link="base"/><child link="arm"/><origin xyz="0 0 0.15"/><axis xyz="1 0 0"/>
    <limit lower="-2" upper="2" effort="10" velocity="10"/><dynamics damping="{damping}" friction="{friction}"/></joint>
</robot>
"""
    )
    return folder / "mobility.urdf"


def test_placed_on_ground_even_when_rotated(tmp_path):
    # a box rotated 45 degrees about z: Bullet's AABB of the rotated hull is loose
    urdf = _urdf_with_dynamics(tmp_path / "r", 0.1, 0.1, rpy="0 0.7 0.785")
    s = open_session("pybullet", urdf, SessionOptions(initial_state={"j": 0.0}))
    try:
        p = s._p
        pts = p.getClosestPoints(s.body, s.plane, 1.0, physicsClientId=s.cid)
        assert min(pt[8] for pt in pts) == pytest.approx(0.0, abs=1e-4)
    finally:
        s.close()


def test_friction_holds_a_joint_that_gravity_cannot_move(tmp_path):
    # gravity torque at q = 0.5: 0.2 kg * 9.81 * 0.2 m * sin(0.5) = 0.188 N m
    urdf = _urdf_with_dynamics(tmp_path / "f", 0.0, 0.5)
    s = open_session("pybullet", urdf, SessionOptions(initial_state={"j": 0.5}))
    try:
        s.step(240)
        assert s.joint_positions()["j"] == pytest.approx(0.5, abs=1e-3)
    finally:
        s.close()
    urdf = _urdf_with_dynamics(tmp_path / "g", 0.0, 0.05)
    s = open_session("pybullet", urdf, SessionOptions(initial_state={"j": 0.5}))
    try:
        s.step(240)
        assert abs(s.joint_positions()["j"] - 0.5) > 0.1
    finally:
        s.close()


def test_damping_from_the_file_slows_the_joint(tmp_path):
    speeds = []
    for damping in (0.0, 0.5):
        urdf = _urdf_with_dynamics(tmp_path / f"d{damping}", damping, 0.0)
        s = open_session("pybullet", urdf, SessionOptions(initial_state={"j": 1.0}))
        try:
            s.step(24)
            speeds.append(abs(s.joint_velocities()["j"]))
        finally:
            s.close()
    assert speeds[1] < 0.5 * speeds[0]


def test_spring_holds_its_reference(tmp_path):
    urdf = _urdf_with_dynamics(tmp_path / "s", 0.05, 0.0)
    # spring about 0 strong against gravity: settles near 0 from 0.8
    s = open_session("pybullet", urdf, SessionOptions(initial_state={"j": 0.8}, springs={"j": Spring(stiffness=5.0, reference=0.0)}))
    try:
        s.step(720)
        assert abs(s.joint_positions()["j"]) < 0.05
    finally:
        s.close()


def test_parent_child_pairs_excluded_siblings_counted(tmp_path):
    from tests.helpers import write_arm_through_post

    folder = write_arm_through_post(tmp_path / "a")
    s = open_session("pybullet", folder / "mobility.urdf", SessionOptions(fixed_base=True, ground=False, gravity=False))
    try:
        phi, pairs = s.self_penetration()
        assert phi > 0 and {(c.link_a, c.link_b) for c in pairs} == {("arm", "post")}
        s.set_joint_positions({"hinge": 0.5})
        assert s.self_penetration()[0] == 0.0
    finally:
        s.close()
    folder = write_hinged_plate(tmp_path / "p")  # the plate touches its parent: excluded
    s = open_session("pybullet", folder / "mobility.urdf", SessionOptions(fixed_base=True, ground=False, gravity=False, initial_state={"hinge": -0.5}))
    try:
        assert s.self_penetration()[0] == 0.0
        assert not math.isnan(float(np.sum(s.root_pose()[0])))
    finally:
        s.close()


def test_joint_axis_is_in_the_link_frame_with_a_non_diagonal_inertia(tmp_path):
    """Bullet turns a link's inertial frame to the principal axes of a
    non-diagonal inertia tensor and reports the joint axis in that frame; the
    protocol's axis is in the child link's frame, so world axes of the
    gripper, sweep and probes stay right (faucet 148's handle turned the wrong
    way in task execution before)."""
    folder = tmp_path / "tilted"
    folder.mkdir()
    (folder / "mobility.urdf").write_text(
        """<?xml version="1.0"?>
<robot name="t">
  <link name="base"><inertial><mass value="5"/><inertia ixx="0.1" ixy="0" ixz="0" iyy="0.1" iyz="0" izz="0.1"/></inertial>
    <collision><origin xyz="0 0 0.05"/><geometry><box size="0.6 0.6 0.1"/></geometry></collision></link>
  <link name="arm"><inertial><origin xyz="0 0.07 0.03"/><mass value="0.4"/>
    <inertia ixx="0.0008" ixy="-0.00001" ixz="-0.00001" iyy="0.0007" iyz="-0.00027" izz="0.0003"/></inertial>
    <collision><origin xyz="0 0.07 0.03"/><geometry><box size="0.02 0.14 0.06"/></geometry></collision></link>
  <joint name="j" type="revolute"><parent link="base"/><child link="arm"/><origin xyz="0 0 0.2"/><axis xyz="0 -1 0"/>
    <limit lower="-2" upper="2" effort="10" velocity="10"/></joint>
</robot>
"""
    )
    s = open_session("pybullet", folder / "mobility.urdf", SessionOptions(fixed_base=True, initial_state={"j": 0.3}))
    try:
        assert s.joint_axis("j") == pytest.approx([0.0, -1.0, 0.0], abs=1e-6)
        # the world axis does not move as the joint turns about it
        R = s.link_frame("arm")[1]
        assert R @ s.joint_axis("j") == pytest.approx([0.0, -1.0, 0.0], abs=1e-6)
    finally:
        s.close()


@pytest.mark.parametrize("hold, moves", [(None, True), (1000.0, False), (10.0, True)])
def test_a_held_root_resists_a_push_up_to_its_force_bound(tmp_path, hold, moves):
    """A 5.2 kg object on the ground (Coulomb friction about 0.5 x 51 N)
    pushed sideways with 60 N for 0.5 s slides; held by ``hold_root`` with
    1000 N it stays put; held with 10 N (ground friction + 10 N < 60 N) it
    slides; released, the same push moves it again."""
    urdf = _urdf_with_dynamics(tmp_path / "h", 0.1, 0.5)
    s = open_session("pybullet", urdf, SessionOptions(initial_state={"j": 0.0}))
    try:
        s.step(60)

        def push() -> float:
            p0, _ = s.root_pose()
            for _ in range(120):
                s.apply_link_force("base", np.array([60.0, 0.0, 0.0]), p0 + np.array([0.0, 0.0, 0.05]))
                s.step(1)
            return float(np.linalg.norm((s.root_pose()[0] - p0)[:2]))

        if hold is not None:
            s.hold_root(hold)
        moved = push()
        assert (moved > 0.01) is moves, moved
        if hold is not None:
            assert moved < 1e-3 or hold < 60.0
            s.release_root()
            assert push() > 0.01
    finally:
        s.close()



def _mesh_arm_urdf(folder, extent):
    """:func:`_urdf_with_dynamics` with the arm's collision the OBJ file ``arm.obj`` (a cube of ``extent`` m),
    written again at the same path on each call."""
    import trimesh

    folder.mkdir(parents=True, exist_ok=True)
    trimesh.creation.box(extents=(extent, extent, extent)).export(folder / "arm.obj")
    return _urdf_with_dynamics(folder, 0.01, 0.001, arm='<mesh filename="arm.obj"/>')


def _arm_width(session) -> float:
    lo, hi = session._p.getAABB(session.body, session.link_index("arm"), physicsClientId=session.cid)
    return hi[0] - lo[0]


def _settled(urdf, options) -> tuple[int, np.ndarray]:
    s = open_session("pybullet", urdf, options)
    try:
        for _ in range(300):
            s.step()
        pos, quat = s.root_pose()
        return s.cid, np.concatenate([pos, quat, [s.joint_positions()["j"]]])
    finally:
        s.close()


def test_sessions_of_one_files_key_share_a_client_and_give_the_same_bits(tmp_path):
    """A session given ``files_key`` leaves its client idle at close; the next session of that key reuses it and
    simulates the same to the bit as a session in a new client; another key gets a client of its own."""
    from asset2sim.engines import pybullet_clients as pc

    urdf = _mesh_arm_urdf(tmp_path / "a", 0.04)
    opts = SessionOptions(initial_state={"j": 0.6})
    _, fresh = _settled(urdf, opts)
    keyed = SessionOptions(initial_state={"j": 0.6}, files_key="a#1")
    cid1, first = _settled(urdf, keyed)
    assert ("a#1", cid1) in pc.IDLE
    cid2, second = _settled(urdf, keyed)
    assert cid2 == cid1 and ("a#1", cid1) in pc.IDLE
    assert np.array_equal(first, fresh) and np.array_equal(second, fresh)
    other = open_session("pybullet", urdf, SessionOptions(initial_state={"j": 0.6}, files_key="a#2"))
    try:
        assert other.cid != cid1
    finally:
        other.close()
    assert len(pc.IDLE) <= pc.MAX_IDLE


def test_a_collision_file_written_again_is_read_again_under_a_new_key(tmp_path):
    """The arm's OBJ rewritten at the same path: a session of the new key (a new candidate digest) has the new
    cube's width, not the old one a kept client loaded."""
    urdf = _mesh_arm_urdf(tmp_path / "b", 0.04)
    s = open_session("pybullet", urdf, SessionOptions(files_key="b#1"))
    try:
        assert _arm_width(s) == pytest.approx(0.04, abs=0.01)
    finally:
        s.close()
    _mesh_arm_urdf(tmp_path / "b", 0.2)
    s = open_session("pybullet", urdf, SessionOptions(files_key="b#2"))
    try:
        assert _arm_width(s) == pytest.approx(0.2, abs=0.01)
    finally:
        s.close()
