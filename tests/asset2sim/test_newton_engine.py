"""The Newton engine (CPU): it holds what the URDF and overlay say, agrees with
PyBullet on frames and masses, and runs the SPEC's rest and oscillation tests."""

from __future__ import annotations

import numpy as np
import pytest

from asset2sim.engines.base import EngineUnsupported, SessionOptions, Spring
from asset2sim.engines.registry import known_engines, open_session
from tests.contract_asset import write_contract_asset
from asset2sim.engines.loading import read_urdf
from asset2sim.tasks.check.parity import evaluate_engines, parity_table

pytest.importorskip("newton")
pytest.importorskip("warp")


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
        m = nt.model
        mass, com, inertia = m.body_mass.numpy(), m.body_com.numpy(), m.body_inertia.numpy()
        for name, link in urdf.links.items():
            i = nt._body[name]
            assert mass[i] == pytest.approx(link.inertial.mass, rel=1e-6), name
            assert np.allclose(com[i], link.inertial.com(), atol=1e-7), name
            want = link.inertial.inertia_in_link_axes()
            assert np.allclose(inertia[i], want, atol=1e-6 * np.abs(want).max()), name
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
            nt.save_state()
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
