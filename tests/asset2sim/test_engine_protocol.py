"""The widened session protocol answers the same queries alike in every engine.

Each test asks PyBullet (the reference), PhysX and MuJoCo (and the fake where it
models the query) the same question on a generated asset (``write_contract_asset``:
a box with a hinged lid and a sliding post) and on a real PartNet-Mobility asset
(the box 100221), in fixed-base sessions so the root sits at the origin in every
engine, and compares the answers. Tolerances: PhysX works in float32 (1e-5);
PhysX cooks hulls to at most 255 vertices and PyBullet pads its AABBs, so boxes
are compared loosely where noted.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from tests.conftest import NO_SHARED, SHARED
from asset2sim.engines.base import EngineUnsupported, SessionOptions
from asset2sim.engines.registry import open_session, open_shape_world, open_viewer
from tests.contract_asset import write_contract_asset

REAL = SHARED / "100221" / "mobility.urdf"
OTHERS = [
    pytest.param("physx", marks=pytest.mark.physx, id="physx"),
    pytest.param("mujoco", marks=pytest.mark.mujoco, id="mujoco"),
]


def _need(engine: str) -> None:
    if engine == "physx":
        pytest.importorskip("sapien")
    elif engine == "mujoco":
        pytest.importorskip("mujoco")


def _urdf(kind: str, tmp_path: Path) -> tuple[Path, dict[str, float]]:
    if kind == "real":
        if not REAL.is_file():
            pytest.skip(NO_SHARED)
        return REAL, {"joint_0": 0.4}
    a = write_contract_asset(tmp_path, lid_angle=0.4, post_height=0.02)
    return a.urdf, dict(a.initial_state)


def _pair(engine: str, kind: str, tmp_path: Path, **kw):
    _need(engine)
    urdf, q = _urdf(kind, tmp_path)
    opts = dict(initial_state=q, fixed_base=True, gravity=False, ground=False)
    opts.update(kw)
    ref = open_session("pybullet", urdf, SessionOptions(**opts))
    other = open_session(engine, urdf, SessionOptions(**opts))
    return ref, other


@pytest.mark.parametrize("kind", ["generated", "real"])
@pytest.mark.parametrize("engine", OTHERS)
def test_links_frames_axes_and_masses_agree(tmp_path, engine, kind):
    ref, other = _pair(engine, kind, tmp_path)
    try:
        assert set(other.link_names) == set(ref.link_names)
        assert other.link_names[0] == ref.link_names[0]  # the root first
        assert other.joint_child == ref.joint_child
        for link in ref.link_names:
            p0, r0 = ref.link_frame(link)
            p1, r1 = other.link_frame(link)
            np.testing.assert_allclose(p1, p0, atol=1e-5)
            np.testing.assert_allclose(r1, r0, atol=1e-5)
            assert other.link_has_collision(link) == ref.link_has_collision(link)
        for joint, child in ref.joint_child.items():
            r = ref.link_frame(child)[1]
            a0 = r @ ref.joint_axis(joint)
            a1 = other.link_frame(child)[1] @ other.joint_axis(joint)
            np.testing.assert_allclose(a1 / np.linalg.norm(a1), a0 / np.linalg.norm(a0), atol=1e-5)
    finally:
        ref.close()
        other.close()
    # masses with the root free (Bullet reports 0 kg for a fixed base)
    ref, other = _pair(engine, kind, tmp_path, fixed_base=False, ground=True, gravity=True)
    try:
        m0, m1 = ref.link_masses(), other.link_masses()
        assert set(m0) == set(m1)
        for link in m0:
            assert m1[link] == pytest.approx(m0[link], rel=1e-5)
    finally:
        ref.close()
        other.close()


@pytest.mark.parametrize("kind", ["generated", "real"])
@pytest.mark.parametrize("engine", OTHERS)
def test_link_boxes_agree(tmp_path, engine, kind):
    """Boxes from the collision points (PhysX, MuJoCo) agree with each other's
    size and lie inside PyBullet's padded broadphase AABB."""
    ref, other = _pair(engine, kind, tmp_path)
    try:
        for link in ref.link_names:
            if not ref.link_has_collision(link):
                continue
            lo0, hi0 = ref.link_aabb(link)
            lo1, hi1 = other.link_aabb(link)
            size = float(np.max(hi0 - lo0))
            assert np.all(lo1 >= lo0 - 1e-4 * max(size, 1.0)) and np.all(hi1 <= hi0 + 1e-4 * max(size, 1.0)), link
            v = other.link_collision_vertices(link)
            assert v.ndim == 2 and v.shape[1] == 3 and len(v) > 0
    finally:
        ref.close()
        other.close()


@pytest.mark.physx
@pytest.mark.mujoco
@pytest.mark.parametrize("kind", ["generated", "real"])
def test_point_boxes_agree_between_physx_and_mujoco(tmp_path, kind):
    """Both bound the same hull points (PhysX may cook a hull to fewer vertices)."""
    _need("physx")
    _need("mujoco")
    urdf, q = _urdf(kind, tmp_path)
    opts = SessionOptions(initial_state=q, fixed_base=True, gravity=False, ground=False)
    with open_session("physx", urdf, opts) as a, open_session("mujoco", urdf, opts) as b:
        for link in a.link_names:
            if not a.link_has_collision(link):
                continue
            lo0, hi0 = a.link_aabb(link)
            lo1, hi1 = b.link_aabb(link)
            tol = 0.01 * float(np.max(hi1 - lo1)) + 1e-5
            np.testing.assert_allclose(lo0, lo1, atol=tol, err_msg=link)
            np.testing.assert_allclose(hi0, hi1, atol=tol, err_msg=link)


@pytest.mark.parametrize("engine", ["pybullet", pytest.param("mujoco", marks=pytest.mark.mujoco)])
def test_link_distances_see_the_post_in_the_lid(tmp_path, engine):
    """The post pushed into the closed lid penetrates it by about the overlap;
    lowered, it stays clear. PyBullet's hull margins add about 2 mm."""
    _need(engine)
    a = write_contract_asset(tmp_path, lid_angle=0.0, post_height=0.0)
    with open_session(engine, a.urdf, SessionOptions(fixed_base=True, gravity=False, ground=False)) as s:
        s.set_joint_positions({"lid_hinge": 0.0, "post_slide": 0.05})
        deep = s.link_distances("post", "lid", 0.0)
        s.set_joint_positions({"post_slide": 0.0})
        clear = s.link_distances("post", "lid", 0.0)
    assert deep and min(deep) < -0.005
    assert not clear or min(clear) > -0.0025


def test_link_distances_agree_between_pybullet_and_mujoco(tmp_path):
    _need("mujoco")
    ref, other = _pair("mujoco", "generated", tmp_path)
    try:
        for h in (0.03, 0.04, 0.05):
            ref.set_joint_positions({"lid_hinge": 0.0, "post_slide": h})
            other.set_joint_positions({"lid_hinge": 0.0, "post_slide": h})
            d0, d1 = min(ref.link_distances("post", "lid", 0.0)), min(other.link_distances("post", "lid", 0.0))
            assert d1 == pytest.approx(d0, abs=0.0025)  # PyBullet: 2 x 1 mm hull margin
    finally:
        ref.close()
        other.close()


def test_physx_has_no_distance_query(tmp_path):
    _need("physx")
    a = write_contract_asset(tmp_path)
    with open_session("physx", a.urdf, SessionOptions(fixed_base=True)) as s, pytest.raises(EngineUnsupported):
        s.link_distances("post", "lid")


@pytest.mark.parametrize("engine", ["pybullet", "fake"] + OTHERS)
def test_save_and_restore_state(tmp_path, engine):
    _need(engine)
    a = write_contract_asset(tmp_path, lid_angle=1.2, post_height=0.02)
    with open_session(engine, a.urdf, SessionOptions(initial_state=dict(a.initial_state))) as s:
        s.step(20)
        h = s.save_state()
        q0, (p0, o0) = s.joint_positions(), s.root_pose()
        qd0 = s.joint_velocities()
        s.step(60)
        assert s.joint_positions()["lid_hinge"] != pytest.approx(q0["lid_hinge"], abs=1e-6) or engine == "fake"
        s.restore_state(h)
        assert s.joint_positions() == pytest.approx(q0, abs=1e-6)
        assert s.joint_velocities() == pytest.approx(qd0, abs=1e-5)
        p1, o1 = s.root_pose()
        np.testing.assert_allclose(p1, p0, atol=1e-6)
        np.testing.assert_allclose(o1, o0, atol=1e-6)
        q, qd = s.joint_state("lid_hinge")
        assert q == pytest.approx(q0["lid_hinge"], abs=1e-6) and qd == pytest.approx(qd0["lid_hinge"], abs=1e-5)
        s.discard_state(h)


@pytest.mark.parametrize("engine", ["pybullet"] + OTHERS)
def test_a_push_on_the_lid_opens_it(tmp_path, engine):
    """A force at the lid's front edge, along the opening direction, opens the
    hinge in every engine by a similar amount (no gravity, fixed base)."""
    _need(engine)
    a = write_contract_asset(tmp_path, lid_angle=0.3, lid_friction=0.0, lid_damping=0.0)
    with open_session(engine, a.urdf, SessionOptions(initial_state={"lid_hinge": 0.3}, fixed_base=True, gravity=False, ground=False)) as s:
        child = s.joint_child["lid_hinge"]
        for _ in range(60):
            o, R = s.link_frame(child)
            axis = R @ s.joint_axis("lid_hinge")
            lo, hi = s.link_aabb(child)
            c = 0.5 * (lo + hi)
            r = (c - o) - np.dot(c - o, axis) * axis
            t = np.cross(axis, r)
            s.apply_link_force(child, 0.5 * t / np.linalg.norm(t), c)
            s.step(1)
        q = s.joint_positions()["lid_hinge"]
    assert 0.35 < q < 1.5


def test_fake_answers_the_geometric_queries(tmp_path):
    a = write_contract_asset(tmp_path, lid_angle=0.4, post_height=0.02)
    opts = SessionOptions(initial_state=dict(a.initial_state), fixed_base=True, gravity=False, ground=False)
    with open_session("pybullet", a.urdf, opts) as ref, open_session("fake", a.urdf, opts) as fake:
        assert fake.link_names[0] == ref.link_names[0] and set(fake.link_names) == set(ref.link_names)
        for link in ref.link_names:
            np.testing.assert_allclose(fake.link_frame(link)[0], ref.link_frame(link)[0], atol=1e-9)
            np.testing.assert_allclose(fake.link_frame(link)[1], ref.link_frame(link)[1], atol=1e-9)
        with pytest.raises(EngineUnsupported):
            fake.apply_link_force("lid", np.zeros(3), np.zeros(3))
    free = SessionOptions(initial_state=dict(a.initial_state))
    with open_session("pybullet", a.urdf, free) as ref, open_session("fake", a.urdf, free) as fake:
        assert fake.link_masses() == pytest.approx(ref.link_masses())


def test_shape_world_distances(tmp_path):
    cube = np.array([[x, y, z] for x in (-0.5, 0.5) for y in (-0.5, 0.5) for z in (-0.5, 0.5)])
    w = open_shape_world("pybullet")
    try:
        a = w.add_convex(cube, np.ones(3) * 0.1, np.zeros(3), np.array([0, 0, 0, 1.0]))
        b = w.add_convex(cube, np.ones(3) * 0.1, np.array([0.08, 0, 0]), np.array([0, 0, 0, 1.0]))
        assert min(w.distances(a, b, 0.0)) == pytest.approx(-0.02, abs=0.0025)
        w.set_pose(b, [1.0, 0.0, 0.0], [0, 0, 0, 1])
        assert w.distances(a, b, 0.0) == []
    finally:
        w.close()


def test_viewer_only_in_pybullet(tmp_path):
    a = write_contract_asset(tmp_path)
    v = open_viewer("pybullet", a.urdf)
    try:
        assert v.joint_names == ["lid_hinge", "post_slide"]
        rgba, seg = v.draw(32, 24, {"eye": [1.0, 1.0, 1.0], "target": [0, 0, 0], "up": [0, 0, 1], "fov_deg": 40.0, "near": 0.01, "far": 10.0},
                           {"direction": [1, 1, 1], "color": (1, 1, 1), "distance": 4.0, "shadow": False, "ambient": 0.4, "diffuse": 0.6, "specular": 0.1})
        assert rgba.shape == (24, 32, 4) and seg.shape == (24, 32) and (seg >= 0).any()
    finally:
        v.close()
    with pytest.raises(EngineUnsupported):
        open_viewer("fake", a.urdf)


@pytest.mark.parametrize("engine", [pytest.param("pybullet", id="pybullet"), *OTHERS, pytest.param("fake", id="fake")])
def test_joint_drive_moves_at_target_speed_and_release_holds(tmp_path, engine):
    """drive_joint: a force-limited velocity drive (the joint's friction is a
    load it overcomes); release_joint: passive again, the joint stays."""
    _need(engine)
    a = write_contract_asset(tmp_path, lid_angle=0.4, post_height=0.02)
    s = open_session(engine, a.urdf, SessionOptions(initial_state=dict(a.initial_state), fixed_base=True, gravity=False, ground=False))
    try:
        for joint, speed in (("lid_hinge", 0.2), ("post_slide", 0.01)):
            q0 = s.joint_state(joint)[0]
            s.drive_joint(joint, speed, 50.0)
            s.step(120)  # 0.5 s
            q1, qd1 = s.joint_state(joint)
            assert q1 - q0 == pytest.approx(0.5 * speed, rel=0.05)
            assert qd1 == pytest.approx(speed, rel=0.05)
            s.release_joint(joint)
            s.step(120)
            assert abs(s.joint_state(joint)[0] - q1) < 0.05 * (q1 - q0)
        # a drive weaker than an opposing load cannot move the joint
        q0 = s.joint_state("post_slide")[0]
        if engine != "fake":  # the fake has no forces
            s.drive_joint("post_slide", 0.01, 0.5)
            for _ in range(120):
                s.apply_joint_effort("post_slide", -(0.5 + 2.0 + 3.0))  # beyond limit + friction (2 N)
                s.step(1)
            assert s.joint_state("post_slide")[0] <= q0 + 1e-4
            s.release_joint("post_slide")
    finally:
        s.close()


@pytest.mark.parametrize("engine", [pytest.param("pybullet", id="pybullet"), *OTHERS])
def test_set_root_velocity_moves_a_free_root(tmp_path, engine):
    _need(engine)
    a = write_contract_asset(tmp_path, lid_angle=0.4, post_height=0.02)
    s = open_session(engine, a.urdf, SessionOptions(initial_state=dict(a.initial_state)))
    try:
        p0 = s.root_pose()[0]
        s.set_root_velocity(np.array([0.05, 0.0, 0.0]), np.zeros(3))
        s.step(1)
        assert (s.root_pose()[0][0] - p0[0]) * 240 == pytest.approx(0.05, rel=0.25)
    finally:
        s.close()
    s = open_session(engine, a.urdf, SessionOptions(initial_state=dict(a.initial_state), fixed_base=True))
    try:
        with pytest.raises(EngineUnsupported):
            s.set_root_velocity(np.array([0.05, 0.0, 0.0]), np.zeros(3))
    finally:
        s.close()
