"""The SPEC's simulation conventions hold in every engine (PyBullet, PhysX, MuJoCo).

Each test runs the same scenario on a small output-contract asset written by
the test (``write_contract_asset``: a box with a hinged lid and a sliding post,
every link with ``<inertial>``, every movable joint with ``<dynamics>``) and
checks the engine against the physics the conventions imply, so the engines
are checked against each other through one expectation.
"""

from __future__ import annotations

import math

import pytest

from asset2sim.engines.base import SessionOptions, Spring
from asset2sim.engines.registry import open_session
from tests.contract_asset import write_contract_asset
from asset2sim.frames import translation_matrix
from asset2sim.tasks.check import metrics
from asset2sim.urdf import UrdfGeometry, read_urdf, write_urdf

ENGINES = [
    pytest.param("pybullet", id="pybullet"),
    pytest.param("physx", marks=pytest.mark.physx, id="physx"),
    pytest.param("mujoco", marks=pytest.mark.mujoco, id="mujoco"),
]
G = 9.81
#: PyBullet's convex hulls carry a 1 mm collision margin: touching hulls report
#: -2 mm, and a body rests 1 mm above the plane.
BULLET_MARGIN = 0.001


def _need(engine: str) -> None:
    if engine == "physx":
        pytest.importorskip("sapien")
    elif engine == "mujoco":
        pytest.importorskip("mujoco")


def _open(engine, asset, **kw):
    _need(engine)
    return open_session(engine, asset.urdf, SessionOptions(initial_state=dict(asset.initial_state), **kw))


@pytest.mark.parametrize("engine", ENGINES)
def test_joint_table_and_initial_state(tmp_path, engine):
    a = write_contract_asset(tmp_path, lid_angle=0.4, post_height=0.02)
    s = _open(engine, a)
    try:
        assert s.joint_names == ["lid_hinge", "post_slide"]
        assert s.joint_types == {"lid_hinge": "revolute", "post_slide": "prismatic"}
        assert s.joint_limits["lid_hinge"] == pytest.approx((0.0, 2.0))
        assert s.joint_limits["post_slide"] == pytest.approx((0.0, 0.05))
        q = s.joint_positions()
        assert q["lid_hinge"] == pytest.approx(0.4, abs=1e-6)
        assert q["post_slide"] == pytest.approx(0.02, abs=1e-6)
        s.set_joint_positions({"lid_hinge": 1.1})
        assert s.joint_positions() == pytest.approx({"lid_hinge": 1.1, "post_slide": 0.02}, abs=1e-6)
    finally:
        s.close()


@pytest.mark.parametrize("engine", ENGINES)
def test_root_free_and_on_the_ground(tmp_path, engine):
    a = write_contract_asset(tmp_path, lid_angle=0.6)
    s = _open(engine, a)
    try:
        pos, quat = s.root_pose()
        margin = BULLET_MARGIN if engine == "pybullet" else 0.0
        # the body's bottom plate is at z = 0 of the root frame
        assert pos == pytest.approx([0.0, 0.0, margin], abs=2e-6)
        assert quat == pytest.approx([0, 0, 0, 1], abs=1e-9)
        assert s.ground_penetration() <= 1e-6
        s.step(240)  # free root: it stays on the ground, it does not fall through
        pos1, _ = s.root_pose()
        assert abs(pos1[2] - pos[2]) < 2e-3
    finally:
        s.close()


@pytest.mark.parametrize("engine", ENGINES)
def test_fixed_base_and_no_gravity(tmp_path, engine):
    a = write_contract_asset(tmp_path, lid_angle=0.6, lid_friction=0.0)
    s = _open(engine, a, fixed_base=True, gravity=False, ground=False)
    try:
        s.step(120)
        assert s.joint_positions()["lid_hinge"] == pytest.approx(0.6, abs=1e-4)  # no gravity: no motion
        assert s.root_pose()[0] == pytest.approx([0, 0, 0], abs=1e-9)
    finally:
        s.close()


@pytest.mark.parametrize("engine", ENGINES)
def test_self_penetration_between_siblings(tmp_path, engine):
    """The post pokes into the closed lid (both children of the body): the
    engine's own contact query sees exactly that pair at the geometric depth."""
    a = write_contract_asset(tmp_path, lid_angle=0.0, post_height=0.03)
    depth = 0.03 - a.post_overlap_at
    s = _open(engine, a)
    try:
        phi, pairs = s.self_penetration()
        assert [(p.link_a, p.link_b) for p in pairs] == [("lid", "post")]
        extra = 2 * BULLET_MARGIN if engine == "pybullet" else 0.0
        assert pairs[0].max_depth == pytest.approx(depth + extra, abs=2e-4)
        assert phi == pytest.approx(sum(p.depth for p in pairs))
        assert phi >= pairs[0].max_depth - 1e-12
        # the query leaves the state alone
        assert s.joint_positions() == pytest.approx({"lid_hinge": 0.0, "post_slide": 0.03}, abs=1e-7)
        s.set_joint_positions({"post_slide": 0.0})  # 10.5 mm clear of the lid
        assert s.self_penetration() == (0.0, [])
        s.set_joint_positions({"lid_hinge": 1.0, "post_slide": 0.05})  # lid open: clear
        assert s.self_penetration()[0] == 0.0
        assert s.ground_penetration() <= 1e-6
    finally:
        s.close()


@pytest.mark.parametrize("engine", ENGINES)
def test_penetration_query_does_not_disturb_the_run(tmp_path, engine):
    a = write_contract_asset(tmp_path, lid_angle=0.6, lid_friction=0.02)
    s1, s2 = _open(engine, a), _open(engine, a)
    try:
        for _ in range(3):
            s1.self_penetration()
        s1.step(120)
        s2.step(120)
        assert s1.joint_positions()["lid_hinge"] == pytest.approx(s2.joint_positions()["lid_hinge"], abs=2e-3)
        assert s1.root_pose()[0] == pytest.approx(s2.root_pose()[0], abs=1e-4)
    finally:
        s1.close()
        s2.close()


def _gravity_torque(a, angle: float) -> float:
    return a.lid_mass * G * a.lid_com_radius * math.cos(angle)


@pytest.mark.parametrize("engine", ENGINES)
def test_coulomb_friction_holds_a_lid(tmp_path, engine):
    """friction 0.5 N*m > gravity torque 0.16 N*m: the lid stays where it is."""
    a = write_contract_asset(tmp_path, lid_angle=0.6, lid_friction=0.5, lid_damping=0.0)
    assert _gravity_torque(a, 0.6) < 0.5
    s = _open(engine, a)
    try:
        s.step(720)
        assert s.joint_positions()["lid_hinge"] == pytest.approx(0.6, abs=5e-3)
    finally:
        s.close()


@pytest.mark.parametrize("engine", ENGINES)
def test_friction_below_the_load_lets_the_lid_fall(tmp_path, engine):
    a = write_contract_asset(tmp_path, lid_angle=0.6, lid_friction=0.1, lid_damping=0.0)
    assert _gravity_torque(a, 0.6) > 0.1
    s = _open(engine, a)
    try:
        s.step(240)
        assert s.joint_positions()["lid_hinge"] < 0.05  # closed on its limit
    finally:
        s.close()


@pytest.mark.parametrize("engine", ENGINES)
def test_viscous_damping_sets_the_closing_speed(tmp_path, engine):
    """No friction. Damping c = 0.1 N*m*s/rad: the lid (I = 2.7e-3 kg*m^2)
    closes within 0.5 s. c = 2: quasi-static closing at about tau/c = 0.08
    rad/s, i.e. 0.04 rad in 0.5 s. PhysX and MuJoCo stay close to that;
    PyBullet applies much less damping once c*dt/I > 1 (measured 0.33 rad),
    which ``docs/design/simulators.md`` records, but still far less than the free
    fall (0.6 rad)."""
    fast = write_contract_asset(tmp_path / "fast", lid_angle=0.6, lid_friction=0.0, lid_damping=0.1)
    slow = write_contract_asset(tmp_path / "slow", lid_angle=0.6, lid_friction=0.0, lid_damping=2.0)
    sf, ss = _open(engine, fast), _open(engine, slow)
    try:
        sf.step(120)
        ss.step(120)
        qf, qs = sf.joint_positions()["lid_hinge"], ss.joint_positions()["lid_hinge"]
        assert qf < 0.02
        moved = 0.6 - qs
        upper = 0.45 if engine == "pybullet" else 0.1
        assert 0.02 < moved < upper, moved
    finally:
        sf.close()
        ss.close()


@pytest.mark.parametrize("engine", ENGINES)
def test_spring_holds_the_lid_at_its_equilibrium(tmp_path, engine):
    """k (q - q_s) = -m g r cos q: with k = 2 N*m/rad about q_s = 1.2 rad and
    strong damping the lid settles where the spring balances gravity."""
    k, qs = 2.0, 1.2
    a = write_contract_asset(tmp_path, lid_angle=0.9, lid_friction=0.0, lid_damping=0.05, lid_stiffness=k, lid_spring_reference=qs)
    q_eq = qs
    for _ in range(100):  # fixed point of q = qs - m g r cos(q) / k
        q_eq = qs - _gravity_torque(a, q_eq) / k
    s = _open(engine, a, springs={"lid_hinge": Spring(k, qs)})
    try:
        s.step(960)
        assert s.joint_positions()["lid_hinge"] == pytest.approx(q_eq, abs=0.01)
    finally:
        s.close()


@pytest.mark.parametrize("engine", ENGINES)
def test_spec_metrics_pass_for_a_resting_asset(tmp_path, engine):
    a = write_contract_asset(tmp_path, lid_angle=0.6, lid_friction=0.5)
    s = _open(engine, a)
    try:
        assert metrics.penetration(s).value == 0.0
        trace = metrics.run_rest_test(s)
        rest = metrics.rest_stability(trace, engine=engine)
        osc = metrics.oscillation(trace, engine=engine)
        assert rest.passed, rest.details
        assert osc.passed, osc.details
    finally:
        s.close()


@pytest.mark.parametrize("engine", ENGINES)
def test_spec_metrics_catch_an_undamped_spring(tmp_path, engine):
    """No damping, no friction, a spring 0.4 rad away from the start: the lid
    swings back and forth, and the oscillation metric fails."""
    a = write_contract_asset(tmp_path, lid_angle=1.2, lid_friction=0.0, lid_damping=0.0, lid_stiffness=1.0, lid_spring_reference=0.8)
    s = _open(engine, a, springs={"lid_hinge": Spring(1.0, 0.8)})
    try:
        trace = metrics.run_rest_test(s)
        osc = metrics.oscillation(trace, engine=engine)
        assert not osc.passed
        assert osc.details["failing"] == ["lid_hinge"]
    finally:
        s.close()


def _add_base_block(a) -> None:
    """Give the geometry-less root ``base`` a collision block where the lid
    is when closed: base -fixed- body -revolute- lid, so base and lid are
    not parent and child and PyBullet collides them (MuJoCo's own filter,
    which welds base and body, would not)."""
    (a.root / "textured_objs" / "block.obj").write_text(
        "o block\n"
        + "".join(f"v {x} {y} {z}\n" for x in (-0.05, 0.05) for y in (-0.05, 0.05) for z in (0.115, 0.135))
        + "f 1 2 4\nf 1 4 3\nf 5 7 8\nf 5 8 6\nf 1 5 6\nf 1 6 2\nf 3 4 8\nf 3 8 7\nf 1 3 7\nf 1 7 5\nf 2 6 8\nf 2 8 4\n"
    )
    model = read_urdf(a.urdf)
    model.links["base"].collisions.append(UrdfGeometry(kind="mesh", filename="textured_objs/block.obj"))
    a.urdf.write_bytes(write_urdf(model))


@pytest.mark.parametrize("engine", ENGINES)
def test_self_collision_excludes_only_parent_and_child(tmp_path, engine):
    a = write_contract_asset(tmp_path, lid_angle=0.0, post_height=0.0)
    _add_base_block(a)  # inside the box, 15 mm into the closed lid, 5 mm above the post
    s = _open(engine, a, fixed_base=True, gravity=False)
    try:
        _, pairs = s.self_penetration()
        assert ("base", "lid") in [(p.link_a, p.link_b) for p in pairs]
        assert all({p.link_a, p.link_b} != {"base", "body"} for p in pairs)
        s.set_joint_positions({"lid_hinge": 1.5})
        assert s.self_penetration()[0] == 0.0
    finally:
        s.close()


@pytest.mark.parametrize("engine", ENGINES)
def test_parent_child_overlap_is_not_a_contact(tmp_path, engine):
    """The post's collision sunk 5 mm into the body's bottom plate (its
    parent): never reported, never pushed apart."""
    a = write_contract_asset(tmp_path, lid_angle=0.6, post_height=0.0)
    model = read_urdf(a.urdf)
    model.links["post"].collisions[0].origin = translation_matrix([0.0, 0.0, -0.005])
    a.urdf.write_bytes(write_urdf(model))
    s = _open(engine, a)
    try:
        assert s.self_penetration() == (0.0, [])
        s.step(240)
        assert s.joint_positions()["post_slide"] == pytest.approx(0.0, abs=1e-3)
    finally:
        s.close()
