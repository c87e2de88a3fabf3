"""The Newton engine (CPU): it holds what the URDF and overlay say, agrees with
PyBullet on frames and masses, runs the SPEC's rest and oscillation tests, and
pushes a joint: a joint declared with friction breaks away at it."""

from __future__ import annotations

import importlib.util

import numpy as np
import pytest

from asset2sim.engines.base import EngineUnsupported, SessionOptions, Spring
from asset2sim.engines.registry import known_engines, open_session
from tests.contract_asset import write_contract_asset
from asset2sim.engines.loading import read_urdf
from asset2sim.tasks.check import breakaway, metrics
from asset2sim.tasks.check.parity import engine_breakaway, evaluate_engines, parity_table
from asset2sim.engines.source import UrdfFile

#: newton and warp looked up, not imported (about 6 s in each process that collects the module): a session opened
#: imports them
pytestmark = pytest.mark.skipif(importlib.util.find_spec("newton") is None or importlib.util.find_spec("warp") is None,
                                reason="Newton is not installed: pip install 'asset2sim[newton]'")


def test_newton_is_a_known_engine():
    assert "newton" in known_engines()


def test_newton_holds_the_files_values_and_pybullets_frames(tmp_path):
    """Authored equals simulated: every body's mass, COM and inertia tensor
    and every joint's limits, Coulomb friction, damping and spring as Newton's
    model holds them equal the URDF and overlay (float32: 1e-6 relative); link
    frames equal PyBullet's at the initial state (fixed base, no gravity)."""
    a = write_contract_asset(tmp_path, lid_angle=0.4, post_height=0.02)
    springs = {"lid_hinge": Spring(stiffness=0.3, reference=0.2)}
    opts = dict(initial_state=dict(a.initial_state), fixed_base=True, gravity=False, ground=False, springs=springs)
    nt = open_session("newton", a.urdf, SessionOptions(**opts))
    ref = open_session("pybullet", a.urdf, SessionOptions(**opts))
    try:
        urdf = read_urdf(a.urdf)
        assert urdf.root not in nt._body and set(nt._full_body) == set(urdf.links)  # the fixed root welded to the world
        for m, bodies in ((nt.full_model, nt._full_body), (nt.model, nt._body)):  # as built; as stepped
            mass, com, inertia = m.body_mass.numpy(), m.body_com.numpy(), m.body_inertia.numpy()
            for name, i in bodies.items():
                link = urdf.links[name]
                assert mass[i] == pytest.approx(link.inertial.mass, rel=1e-6), name
                assert np.allclose(com[i], link.inertial.com(), atol=1e-7), name
                want = link.inertial.inertia_in_link_axes()
                assert np.allclose(inertia[i], want, atol=1e-6 * np.abs(want).max()), name
        m = nt.model
        lo, hi = m.joint_limit_lower.numpy(), m.joint_limit_upper.numpy()
        fr, kd, ke = m.joint_friction.numpy(), m.joint_target_kd.numpy(), m.joint_target_ke.numpy()
        tp = m.joint_target_pos.numpy() if hasattr(m, "joint_target_pos") else None
        for j in urdf.movable_joints:
            d = nt._dadr[j.name]
            assert (lo[d], hi[d]) == pytest.approx((j.lower, j.upper), rel=1e-6, abs=1e-9), j.name
            assert fr[d] == pytest.approx(j.friction, rel=1e-6), j.name
            assert kd[d] == pytest.approx(j.damping, rel=1e-6), j.name
            s = springs.get(j.name)
            assert ke[d] == pytest.approx(s.stiffness if s else 0.0, rel=1e-6), j.name
            if tp is not None and s is not None:
                assert tp[d] == pytest.approx(s.reference, rel=1e-6)
        assert nt.joint_positions() == pytest.approx(a.initial_state, abs=1e-6)
        for link in ref.link_names:
            p0, r0 = ref.link_frame(link)
            p1, r1 = nt.link_frame(link)
            np.testing.assert_allclose(p1, p0, atol=1e-5)
            np.testing.assert_allclose(r1, r0, atol=1e-5)
        with pytest.raises(EngineUnsupported):
            nt.drive_joint("lid_hinge", 0.1, 1.0)
    finally:
        nt.close()
        ref.close()


def test_newton_places_the_free_root_on_the_ground(tmp_path):
    a = write_contract_asset(tmp_path, lid_angle=0.4)
    nt = open_session("newton", a.urdf, SessionOptions(initial_state=dict(a.initial_state)))
    try:
        low = min((nt.link_collision_vertices(n) @ nt.link_frame(n)[1].T + nt.link_frame(n)[0])[:, 2].min()
                  for n in nt.link_names if nt.link_has_collision(n))
        assert low == pytest.approx(0.0, abs=1e-7)
        assert nt.ground_penetration() == pytest.approx(0.0, abs=1e-7)
    finally:
        nt.close()


@pytest.mark.slow
def test_newton_rest_and_oscillation_pass_like_pybullet(tmp_path):
    """The SPEC's rest-stability and oscillation tests in Newton (Kamino on
    the CPU, about a minute) on the contract asset: both pass, as in PyBullet."""
    write_contract_asset(tmp_path, lid_angle=0.4)
    rows = {r["engine"]: r for r in parity_table(evaluate_engines(tmp_path, ["newton", "pybullet"]))}
    assert rows["newton"]["status"] == "ok", rows["newton"]["reason"]
    assert rows["newton"]["rest_stability"] is True and rows["newton"]["oscillation"] is True
    assert rows["newton"]["penetration_mm"] == pytest.approx(0.0, abs=0.1)


def test_contact_capacity_follows_the_contacts_and_never_drops_one(tmp_path, monkeypatch):
    """The stepping pipeline and Kamino are sized from the contacts the
    object makes (Kamino's CPU cost grows with the capacity); a step that
    fills the capacity grows it. The trajectory equals one at a large fixed
    capacity (no contact dropped)."""
    from asset2sim.engines import newton_engine

    a = write_contract_asset(tmp_path, lid_angle=0.4)
    opts = SessionOptions(initial_state=dict(a.initial_state))
    runs = {}
    for label, minimum, headroom in (("large", 1024, 1), ("tight", 1, 1)):
        monkeypatch.setattr(newton_engine, "CONTACT_CAPACITY_MIN", minimum)
        monkeypatch.setattr(newton_engine, "CONTACT_CAPACITY_HEADROOM", headroom)
        s = open_session("newton", a.urdf, opts)
        try:
            start = s._capacity
            s.step(24)
            runs[label] = (start, s._capacity, s.rebuilds, s.root_pose()[0], s.joint_positions())
        finally:
            s.close()
    assert runs["large"][0] == 1024 and runs["large"][2] == 0
    start, end, rebuilds, pos, q = runs["tight"]
    assert start < 1024
    if rebuilds:  # the tight capacity filled and grew
        assert end > start
    np.testing.assert_allclose(pos, runs["large"][3], atol=1e-6)
    assert q == pytest.approx(runs["large"][4], abs=1e-6)


def _one_hinge(folder, friction: float, damping: float = 0.0):
    """A generated one-joint asset: a 0.2 x 0.2 x 0.05 m base (2 kg) and a 0.2 x 0.2 x 0.01 m lid (0.4 kg, COM 0.1 m
    from the hinge, I about the hinge 5.35e-3 kg*m^2) on a revolute hinge along y, limits 0 to 2 rad,
    ``friction`` N*m and ``damping`` N*m*s/rad; the URDF's path."""
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / "mobility.urdf"
    path.write_text(f"""<?xml version="1.0"?>
<robot name="one_hinge">
  <link name="base">
    <inertial><origin xyz="0 0 0.025"/><mass value="2.0"/>
      <inertia ixx="0.0070833" iyy="0.0070833" izz="0.0133333" ixy="0" ixz="0" iyz="0"/></inertial>
    <collision><origin xyz="0 0 0.025"/><geometry><box size="0.2 0.2 0.05"/></geometry></collision>
  </link>
  <link name="lid">
    <inertial><origin xyz="0.1 0 0.005"/><mass value="0.4"/>
      <inertia ixx="0.0013367" iyy="0.0013367" izz="0.0026667" ixy="0" ixz="0" iyz="0"/></inertial>
    <collision><origin xyz="0.1 0 0.005"/><geometry><box size="0.2 0.2 0.01"/></geometry></collision>
  </link>
  <joint name="hinge" type="revolute">
    <parent link="base"/><child link="lid"/><origin xyz="-0.1 0 0.06" rpy="0 0 0"/><axis xyz="0 -1 0"/>
    <limit lower="0" upper="2.0" effort="10" velocity="5"/>
    <dynamics damping="{damping!r}" friction="{friction!r}"/>
  </joint>
</robot>
""")
    return path


_PUSHED = SessionOptions(initial_state={"hinge": 0.5}, fixed_base=True, gravity=False, ground=False)


def test_a_joint_with_friction_breaks_away_at_its_friction(tmp_path):
    """A hinge declared with 0.3 N*m of friction (and 0.01 N*m*s/rad of damping), pushed alone by the ramp from 0.5 to
    1.5 times its friction (root fixed, gravity off): Kamino's joint-friction row holds it until the push reaches
    the friction, and it breaks away within 20 % of it; the state is restored afterwards."""
    urdf = _one_hinge(tmp_path / "a", friction=0.3, damping=0.01)
    got = engine_breakaway(UrdfFile(urdf), "newton", SessionOptions(initial_state={"hinge": 0.5}))
    assert got["measured"], got["reason"]
    r = got["joints"]["hinge"]
    assert r["direction"] == 1 and r["passed"] and 0.8 <= r["ratio"] <= 1.2, r
    with open_session("newton", urdf, _PUSHED) as s:
        r = breakaway.joint_breakaway(s, "hinge", 0.3, 0.01)
        assert r.passed, r
        assert s.joint_positions()["hinge"] == pytest.approx(0.5, abs=1e-6)  # restored
        assert s.joint_velocities()["hinge"] == pytest.approx(0.0, abs=1e-9)


def test_the_friction_is_what_holds_the_joint(tmp_path):
    """The same hinge with no friction in the file moves under the ramp's first push (0.5 x 0.3 N*m): what held it
    above was the declared friction, not the solver. And an effort acts for one step only: after one step pushed by
    0.15 N*m on I = 5.35e-3 kg*m^2 the lid turns at 0.15 / 5.35e-3 x dt = 0.12 rad/s (dt = 1/240 s), and keeps that speed
    unpushed (no friction, no damping, gravity off)."""
    urdf = _one_hinge(tmp_path / "b", friction=0.0)
    with open_session("newton", urdf, _PUSHED) as s:
        r = breakaway.joint_breakaway(s, "hinge", 0.3)
        assert r.ratio == pytest.approx(breakaway.RAMP_FROM, abs=0.02), r
        s.apply_joint_effort("hinge", 0.15)
        s.step(1)
        _, v1 = s.joint_state("hinge")
        s.step(2)
        _, v3 = s.joint_state("hinge")
    inertia = 0.0013367 + 0.4 * (0.1 ** 2 + 0.005 ** 2)  # kg*m^2 about the hinge (parallel axes)
    want = 0.15 / inertia * (1.0 / 240.0)
    assert v1 == pytest.approx(want, rel=0.1)
    assert v3 == pytest.approx(v1, rel=1e-3)


def test_a_restored_state_steps_as_the_saved_one(tmp_path):
    """save_state / restore_state: 30 steps pushed from a snapshot, restored, then 30 unpushed steps give the same
    joint position as 30 unpushed steps from the snapshot in a fresh session (the friction rows' warm start and
    Kamino's previous-coordinates arrays are part of the snapshot)."""
    urdf = _one_hinge(tmp_path / "c", friction=0.3, damping=0.01)
    with open_session("newton", urdf, _PUSHED) as fresh:
        fresh.step(30)
        want = fresh.joint_positions()["hinge"]
    with open_session("newton", urdf, _PUSHED) as s:
        h = s.save_state()
        for _ in range(30):
            s.apply_joint_effort("hinge", 1.0)
            s.step(1)
        assert s.joint_positions()["hinge"] > 0.55  # pushed well past its friction
        s.restore_state(h)
        s.discard_state(h)
        assert s.joint_positions()["hinge"] == pytest.approx(0.5, abs=1e-7)
        s.step(30)
        assert s.joint_positions()["hinge"] == pytest.approx(want, abs=1e-6)


def _mounted_slide(folder):
    """A generated mounted slide shaped like a refined under-counter dishwasher: a 25 g root link, a 12 kg tub fixed
    to it, a 12.6 kg rack on a horizontal prismatic joint (x, limits -0.3 to 0.3 m, 0.25 N of Coulomb friction, 21
    N*s/m of damping) whose centre of mass lies 0.1 m further out along the slide and 0.1 m below it; the URDF's path."""
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / "mobility.urdf"
    path.write_text("""<?xml version="1.0"?>
<robot name="mounted_slide">
  <link name="base">
    <inertial><mass value="0.025"/><inertia ixx="4.2e-7" iyy="4.2e-7" izz="4.2e-7" ixy="0" ixz="0" iyz="0"/></inertial>
  </link>
  <link name="tub">
    <inertial><origin xyz="0 -0.03 -0.19"/><mass value="12.0"/>
      <inertia ixx="0.58" iyy="0.58" izz="0.80" ixy="0" ixz="0" iyz="0"/></inertial>
    <collision><origin xyz="0 0 -0.4"/><geometry><box size="0.5 0.5 0.04"/></geometry></collision>
  </link>
  <link name="rack">
    <inertial><origin xyz="-0.1 0.07 -0.1"/><mass value="12.6"/>
      <inertia ixx="0.44" iyy="0.52" izz="0.62" ixy="0" ixz="0" iyz="0"/></inertial>
    <collision><geometry><box size="0.4 0.4 0.04"/></geometry></collision>
  </link>
  <joint name="weld" type="fixed"><parent link="base"/><child link="tub"/></joint>
  <joint name="slide" type="prismatic">
    <parent link="tub"/><child link="rack"/><origin xyz="0 0 0.3" rpy="0 0 0"/><axis xyz="1 0 0"/>
    <limit lower="-0.3" upper="0.3" effort="100" velocity="1"/>
    <dynamics damping="21.0" friction="0.25"/>
  </joint>
</robot>
""")
    return path


def test_a_fixed_root_is_welded_to_the_world_and_a_slide_on_it_holds(tmp_path):
    """A fixed root and the links fixed to it are merged into the world, as the reduced-coordinate engines hold a fixed
    base; Kamino would hold the welds world -> base -> tub as constraint rows, under which the tub tilts by degrees
    within a second and the rack slides off its friction (120 mm in 1.25 s in benchmarks/newton_fixed_root_sag.py).
    Welded, the rack (no gravity along its slide) stays within 0.1 mm over the SPEC's rest test; the welded links'
    frames, masses and Phi are still answered."""
    urdf = _mounted_slide(tmp_path)
    opts = SessionOptions(initial_state={"slide": -0.2}, fixed_base=True, gravity=True, ground=False)
    with open_session("newton", urdf, opts) as s:
        assert set(s._body) == {"rack"} and set(s._welded) == {"base", "tub"}
        assert any("welded to the world" in n for n in s.notes)
        assert s.link_masses() == pytest.approx({"base": 0.025, "tub": 12.0, "rack": 12.6}, rel=1e-6)
        assert s.self_penetration()[0] == pytest.approx(0.0, abs=1e-9)
        held = s.held_physics()
        assert set(held.welded_to_world) == {"base", "tub"} and held.joints["slide"].friction == pytest.approx(0.25, rel=1e-6)
        trace = metrics.run_rest_test(s)
        p, r = s.link_frame("tub")
        np.testing.assert_allclose(p, 0.0, atol=1e-12)
        np.testing.assert_allclose(r, np.eye(3), atol=1e-12)
    q = np.concatenate([trace.settle_joints["slide"], trace.joints["slide"]])
    assert np.abs(q + 0.2).max() < 1e-4
    assert metrics.oscillation(trace).passed
