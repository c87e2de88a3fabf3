"""The shared URDF model (reader, PyBullet's collision pieces), the fake engine
and the contract-asset fixture."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from asset2sim.engines.base import SessionOptions, Spring
from asset2sim.engines.registry import available_engines, open_session
from asset2sim.engines.loading import BULLET_DEFAULT_INERTIA, BULLET_DEFAULT_MASS, FLAT_HULL_THICKNESS, collision_pieces, read_urdf
from asset2sim.refined_asset import read_initial_state
from tests.contract_asset import write_contract_asset
from tests.fake_engine import FakeBehaviour, FakeSession, fake_behaviour
from asset2sim.urdf import UrdfError
from asset2sim.frames import matrix_quat_wxyz, rpy_matrix
from asset2sim.mesh_io import obj_groups
from asset2sim.schemas.overlay import Overlay
from asset2sim.tasks.check import metrics


# ----------------------------------------------------------------- the model
def test_contract_asset_satisfies_the_output_contract(tmp_path):
    a = write_contract_asset(tmp_path, lid_angle=0.3, post_height=0.01, lid_stiffness=0.5, lid_spring_reference=0.2)
    m = read_urdf(a.urdf)
    assert m.root == "base"
    assert [j.name for j in m.movable_joints] == ["lid_hinge", "post_slide"]
    for link in m.links.values():  # every link with geometry has a valid inertial
        if link.collisions or link.visuals:
            assert link.inertial is not None and link.inertial.mass > 0
            assert np.all(np.linalg.eigvalsh(link.inertial.inertia) > 0)
    for j in m.movable_joints:
        assert j.dynamics is not None
    for link in m.links.values():
        for c in link.collisions + link.visuals:
            assert c.path.is_file() and not c.filename.startswith("/")
    assert read_initial_state(tmp_path) == {"lid_hinge": 0.3, "post_slide": 0.01}
    Overlay.model_validate(json.loads((tmp_path / "overlay.json").read_text()))
    assert m.total_mass() == pytest.approx(sum(a.masses.values()))


def test_reader_values(tmp_path):
    a = write_contract_asset(tmp_path)
    m = read_urdf(a.urdf)
    hinge = next(j for j in m.joints if j.name == "lid_hinge")
    assert hinge.parent == "body" and hinge.child == "lid"
    assert hinge.axis == pytest.approx([-1, 0, 0])
    assert hinge.origin[:3, 3] == pytest.approx([0, 0.1, 0.12])
    assert (hinge.lower, hinge.upper) == (0.0, 2.0)
    assert (hinge.damping, hinge.friction) == (0.02, 0.02)
    assert m.adjacent_pairs() == {frozenset(p) for p in [("base", "body"), ("body", "lid"), ("body", "post")]}
    poses = m.link_poses({"lid_hinge": math.pi / 2})
    # the lid's far edge (0, -0.2, 0) in its frame goes straight up when opened 90 degrees
    tip = poses["lid"] @ np.array([0, -0.2, 0, 1.0])
    assert tip[:3] == pytest.approx([0, 0.1, 0.32], abs=1e-12)


def test_rotations():
    r = rpy_matrix([0.3, -0.2, 1.1])
    assert r @ r.T == pytest.approx(np.eye(3))
    # fixed axes X, Y, Z = Rz @ Ry @ Rx
    rx = np.array([[1, 0, 0], [0, math.cos(0.3), -math.sin(0.3)], [0, math.sin(0.3), math.cos(0.3)]])
    assert rpy_matrix([0.3, 0, 0]) == pytest.approx(rx)
    q = matrix_quat_wxyz(rpy_matrix([0, 0, math.pi / 2]))
    assert q == pytest.approx([math.sqrt(0.5), 0, 0, math.sqrt(0.5)])


@pytest.mark.parametrize(
    "mutation, message",
    [
        (lambda s: s.replace('type="prismatic"', 'type="planar"'), "not supported"),
        (lambda s: s.replace('<child link="post"/>', '<child link="nowhere"/>'), "parent/child"),
        (lambda s: s.replace('<mass value="1.5"/>', '<mass value="heavy"/>'), "not a decimal number"),
        (lambda s: s.replace("<robot", "<rob").replace("</robot>", "</rob>"), "not <robot>"),
        (lambda s: s.replace("</robot>", '<link name="orphan"/></robot>'), "one root"),
    ],
)
def test_reader_names_what_is_wrong(tmp_path, mutation, message):
    a = write_contract_asset(tmp_path)
    a.urdf.write_text(mutation(a.urdf.read_text()))
    with pytest.raises(UrdfError, match=message):
        read_urdf(a.urdf)


def test_obj_groups_follow_the_file(tmp_path):
    p = tmp_path / "m.obj"
    p.write_text(
        "o a\nv 0 0 0\nv 1 0 0\nv 0 1 0\nv 9 9 9\nf 1 2 3\n"  # the unused vertex 4 is not part of the group
        "g b\nv 0 0 1\nv 1 0 1\nv 0 1 1\nv 0 0 2\nf 5 6 7\nf -4 -3 -1\n"
    )
    groups = obj_groups(p)
    assert len(groups) == 2
    assert sorted(map(tuple, groups[0])) == [(0, 0, 0), (0, 1, 0), (1, 0, 0)]
    assert len(groups[1]) == 4


def test_pybullet_makes_one_hull_per_obj_group(tmp_path):
    """The convention ``collision_pieces`` copies, checked in PyBullet itself:
    two cubes 0.5 m apart in two groups of one OBJ leave the gap empty (two
    hulls); in one group the hull fills it."""
    import pybullet as p

    def obj(groups: bool) -> str:
        lines, off = [], 1
        for k, x0 in enumerate((0.0, 0.5)):
            if groups or k == 0:
                lines.append(f"o cube{k}")
            lines += [f"v {x0 + dx} {dy} {dz}" for dx in (-0.05, 0.05) for dy in (-0.05, 0.05) for dz in (-0.05, 0.05)]
            lines += [f"f {a + off} {b + off} {c + off}" for a, b, c in [(0, 1, 3), (0, 3, 2), (4, 6, 7), (4, 7, 5), (0, 4, 5), (0, 5, 1), (2, 3, 7), (2, 7, 6), (0, 2, 6), (0, 6, 4), (1, 5, 7), (1, 7, 3)]]
            off += 8
        return "\n".join(lines) + "\n"

    for groups, gap_is_free in ((True, True), (False, False)):
        (tmp_path / "two.obj").write_text(obj(groups))
        (tmp_path / "two.urdf").write_text(
            '<robot name="t"><link name="a"><inertial><mass value="1"/><inertia ixx="1" iyy="1" izz="1" ixy="0" ixz="0" iyz="0"/>'
            '</inertial><collision><geometry><mesh filename="two.obj"/></geometry></collision></link></robot>'
        )
        cid = p.connect(p.DIRECT)
        try:
            body = p.loadURDF(str(tmp_path / "two.urdf"), physicsClientId=cid)
            probe = p.createMultiBody(0, p.createCollisionShape(p.GEOM_SPHERE, radius=0.01, physicsClientId=cid), basePosition=[0.25, 0, 0], physicsClientId=cid)
            p.performCollisionDetection(physicsClientId=cid)
            d = min(pt[8] for pt in p.getClosestPoints(body, probe, 1.0, physicsClientId=cid))
        finally:
            p.disconnect(cid)
        assert (d > 0.1) == gap_is_free
        pieces, _ = collision_pieces(read_urdf(tmp_path / "two.urdf"))
        assert len(pieces["a"]) == (2 if groups else 1)


def test_flat_groups_become_slabs_and_degenerate_ones_are_dropped(tmp_path):
    (tmp_path / "f.obj").write_text("o flat\nv 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nf 1 2 3\nf 2 4 3\no line\nv 0 0 0\nv 1 1 1\nv 2 2 2\nf 5 6 7\n")
    (tmp_path / "f.urdf").write_text(
        '<robot name="t"><link name="a"><collision><geometry><mesh filename="f.obj" scale="2 2 2"/></geometry></collision></link></robot>'
    )
    pieces, notes = collision_pieces(read_urdf(tmp_path / "f.urdf"))
    (slab,) = pieces["a"]
    assert slab.thickened and not slab.whole_file
    ext = slab.points.max(axis=0) - slab.points.min(axis=0)
    assert ext == pytest.approx([2, 2, FLAT_HULL_THICKNESS])  # scale applied, then 2 mm thick
    assert any("slab" in n for n in notes) and any("dropped" in n for n in notes)


def test_pybullet_default_for_a_link_without_inertial(tmp_path):
    """The fallback the PhysX and MuJoCo engines copy for parity."""
    import pybullet as p

    (tmp_path / "n.urdf").write_text('<robot name="t"><link name="a"/></robot>')
    cid = p.connect(p.DIRECT)
    try:
        body = p.loadURDF(str(tmp_path / "n.urdf"), flags=p.URDF_USE_INERTIA_FROM_FILE, physicsClientId=cid)
        info = p.getDynamicsInfo(body, -1, physicsClientId=cid)
    finally:
        p.disconnect(cid)
    assert info[0] == BULLET_DEFAULT_MASS
    assert info[2] == pytest.approx(BULLET_DEFAULT_INERTIA)


# ------------------------------------------------------------------ the fake
def test_fake_is_registered_and_deterministic(tmp_path):
    assert "fake" in available_engines()
    a = write_contract_asset(tmp_path, lid_angle=0.5)
    runs = []
    for _ in range(2):
        with fake_behaviour(joint_oscillation={"lid_hinge": (0.1, 2.0)}, root_velocity=(1e-3, 0, 0)):
            s = open_session("fake", a.urdf, SessionOptions(initial_state=a.initial_state))
        s.step(37)
        runs.append((s.joint_positions(), s.root_pose()[0].tolist()))
    assert runs[0] == runs[1]
    assert runs[0][0]["lid_hinge"] == pytest.approx(0.5 + 0.1 * math.sin(2 * math.pi * 2.0 * 37 / 240))


def test_fake_makes_metrics_pass_or_fail_on_purpose(tmp_path):
    a = write_contract_asset(tmp_path, lid_angle=0.5)
    opts = SessionOptions(initial_state=a.initial_state)
    still = FakeSession(a.urdf, opts)
    trace = metrics.run_rest_test(still)
    assert metrics.rest_stability(trace).passed and metrics.oscillation(trace).passed

    drifting = FakeSession(a.urdf, opts, FakeBehaviour(root_velocity=(0.001, 0, 0)))  # 2 mm in T_test
    rest = metrics.rest_stability(metrics.run_rest_test(drifting))
    assert not rest.passed and rest.value == pytest.approx(0.002, rel=1e-6)

    swinging = FakeSession(a.urdf, opts, FakeBehaviour(joint_oscillation={"lid_hinge": (0.05, 1.0)}))
    osc = metrics.oscillation(metrics.run_rest_test(swinging))
    assert not osc.passed and osc.details["failing"] == ["lid_hinge"]
    small = FakeSession(a.urdf, opts, FakeBehaviour(joint_oscillation={"*": (0.02, 1.0)}))  # 0.04 rad < 0.05
    osc = metrics.oscillation(metrics.run_rest_test(small))
    assert not osc.passed and osc.details["failing"] == ["post_slide"]  # 0.02 m (clipped at 0) > 0.005 m

    turning = FakeSession(a.urdf, opts, FakeBehaviour(root_yaw_rate=0.01))
    assert not metrics.rest_stability(metrics.run_rest_test(turning)).passed


def test_fake_penetration_may_depend_on_the_state(tmp_path):
    a = write_contract_asset(tmp_path)
    s = FakeSession(a.urdf, SessionOptions(), FakeBehaviour(penetration=lambda q: 0.01 - q["lid_hinge"] * 0.05))
    phi, pairs = s.self_penetration()
    assert phi == pytest.approx(0.01) and (pairs[0].link_a, pairs[0].link_b) == ("base", "lid")  # first non-adjacent pair
    s.set_joint_positions({"lid_hinge": 0.3})
    assert s.self_penetration() == (0.0, [])


def test_fake_springs_and_limits(tmp_path):
    a = write_contract_asset(tmp_path)
    s = FakeSession(
        a.urdf,
        SessionOptions(initial_state={"lid_hinge": 1.5}, springs={"lid_hinge": Spring(1.0, 0.5)}),
        FakeBehaviour(joint_drift={"post_slide": 1.0}),
    )
    s.step(480)  # 2 s = 10 time constants
    q = s.joint_positions()
    assert q["lid_hinge"] == pytest.approx(0.5, abs=1e-3)
    assert q["post_slide"] == 0.05  # clipped at the upper limit
