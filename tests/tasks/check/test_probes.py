"""Passive probes on generated drawers and lids built to pass and to fail."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from asset2sim.engines.base import EngineUnsupported, SessionOptions
from asset2sim.engines.registry import open_session
from asset2sim.tasks.evaluation.evaluate import evaluate_asset
from asset2sim.tasks.check.probes import (
    probe_joint,
    probes_metric,
    run_probes,
)
from asset2sim.tasks.check.pusher import MAX_PUSH_TIME, TRAVEL_TIME_MARGIN, ProbeConfig, push_budget
from asset2sim.urdf import read_urdf


def _inertial(mass, xyz=(0, 0, 0), i=(0.01, 0.01, 0.01)):
    return (f'<inertial><origin xyz="{xyz[0]} {xyz[1]} {xyz[2]}"/><mass value="{mass}"/>'
            f'<inertia ixx="{i[0]}" iyy="{i[1]}" izz="{i[2]}" ixy="0" ixz="0" iyz="0"/></inertial>')


def _box(x, y, z, xyz=(0, 0, 0)):
    o = f'<origin xyz="{xyz[0]} {xyz[1]} {xyz[2]}"/>'
    g = f'<geometry><box size="{x} {y} {z}"/></geometry>'
    return f"<collision>{o}{g}</collision><visual>{o}{g}</visual>"


def _two_links(folder: Path, robot: str, parent: str, child: str, joint: str) -> Path:
    """Write ``folder``/mobility.urdf: links ``parent`` and ``child`` (their
    XML) and ``joint`` (its XML); returns ``folder``."""
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "mobility.urdf").write_text(f'<?xml version="1.0"?><robot name="{robot}">{parent}{child}{joint}</robot>')
    return folder


def drawer(folder: Path, *, base_mass=20.0, friction=1.0, damping=2.0, stiffness=None, q0=0.15) -> Path:
    """A carcass with a drawer sliding along +x beside it, limits [0, 0.3] m
    (closed at 0, where the drawer is nearest the carcass)."""
    _two_links(
        folder, "drawer",
        f'<link name="carcass">{_inertial(base_mass, i=(0.3, 0.3, 0.3))}{_box(0.4, 0.4, 0.3)}</link>',
        f'<link name="drawer">{_inertial(1.0)}{_box(0.2, 0.3, 0.1)}</link>',
        '<joint name="slide" type="prismatic"><parent link="carcass"/><child link="drawer"/>'
        '<origin xyz="0.31 0 0"/><axis xyz="1 0 0"/><limit lower="0" upper="0.3" effort="100" velocity="1"/>'
        f'<dynamics damping="{damping}" friction="{friction}"/></joint>',
    )
    (folder / "initial_state.json").write_text(json.dumps({"initial_joint_positions": {"slide": q0}}))
    if stiffness is not None:  # a spring pulling the drawer open (rest position 0.3 m)
        (folder / "overlay.json").write_text(json.dumps({
            "scale": 1.0, "estimator": {"name": "test"},
            "joints": {"slide": {"damping": damping, "friction": friction, "stiffness": stiffness, "spring_reference": 0.3}},
        }))
    return folder


def _probes(ev):
    m = ev.metric("probes")
    return m, {p["action"]: p for p in m.details["probes"]}


def test_smooth_drawer_is_closed_and_opened_by_the_pusher(tmp_path):
    ev = evaluate_asset(drawer(tmp_path / "d"), probes=True)
    assert ev.closed_positions["slide"]["q_closed"] == pytest.approx(0.0, abs=0.01)
    m, p = _probes(ev)
    assert m.passed is True and m.value == 0.0
    for action in ("close", "open"):
        assert p[action]["reached"] and p[action]["success"]
        assert not p[action]["slid"] and not p[action]["tipped"]
        assert 0.0 < p[action]["peak_force"] < 50.0  # friction 1 N, damping, 1 kg drawer
        assert p[action]["lever_arm"] is None  # prismatic: the force is the generalised force
    assert p["close"]["release_fraction"] <= 0.10
    assert not p["close"]["rebound"]


def test_drawer_that_springs_back_fails_the_close_probe(tmp_path):
    ev = evaluate_asset(drawer(tmp_path / "d", stiffness=200.0), probes=True)
    m, p = _probes(ev)
    assert m.passed is False
    assert p["close"]["reached"] and p["close"]["rebound"]
    assert p["close"]["failure"] == "springs back after release"
    # it took roughly the spring force at the closed end to hold it (200 N/m x 0.3 m)
    assert 30.0 < p["close"]["peak_force"] < 200.0


def test_drawer_too_stiff_for_a_light_carcass_is_not_moved_by_a_hand_force(tmp_path):
    """The probe holds the body (the reaction acts on the carcass): a drawer
    whose friction (100 N) is beyond the probe's force (2 x the weight) is not
    reached, and the held carcass does not slide (3 kg: with the 1 kg drawer
    out, the center of mass stays over the carcass)."""
    ev = evaluate_asset(drawer(tmp_path / "d", base_mass=3.0, friction=100.0), probes=True)
    m, p = _probes(ev)
    assert m.passed is False
    for action in ("close", "open"):
        assert not p[action]["reached"]
        assert not p[action]["slid"] and not p[action]["tipped"]
        assert p[action]["failure"] == "target not reached"
        assert p[action]["peak_force"] == pytest.approx(p[action]["max_force"])


def test_a_light_carcass_held_by_the_probe_is_operated_pushed_alone_it_slides(tmp_path):
    """A 3 kg carcass with a drawer that needs 40 N (the probe's limit is
    2 x 39 N): held (default) the drawer closes; pushed without holding the
    body (an external push), the carcass slides away instead (ground friction
    about 0.5 x 39 N < 40 N)."""
    f = drawer(tmp_path / "d", base_mass=3.0, friction=40.0)
    for hold, ok in ((True, True), (False, False)):
        s = open_session("pybullet", f / "mobility.urdf", SessionOptions(initial_state={"slide": 0.15}))
        try:
            r = probe_joint(s, "slide", (0.0, 1.0, 0.3), action="close",
                            config=ProbeConfig(hold_body=hold))
        finally:
            s.close()
        assert r.success is ok, r.failure
        if not ok:
            assert r.slid and "moved instead" in r.failure


def _swivel(folder: Path) -> Path:
    """A USB-stick-sized stick (5 g, 60 x 20 x 10 mm) with a 15 g cover
    beside it that swivels about a vertical axis at the stick's end, both
    lying on the ground: swinging the cover drags it over the ground."""
    return _two_links(
        folder, "swivel",
        f'<link name="stick">{_inertial(0.005, i=(2e-7, 2e-6, 2e-6))}{_box(0.06, 0.02, 0.01)}</link>',
        f'<link name="cover">{_inertial(0.015, (0.035, 0, 0), (5e-7, 5e-6, 5e-6))}{_box(0.06, 0.02, 0.01, (0.035, 0, 0))}</link>',
        '<joint name="swivel" type="revolute"><parent link="stick"/><child link="cover"/>'
        '<origin xyz="0.03 0 0"/><axis xyz="0 0 1"/><limit lower="0" upper="1.2" effort="1" velocity="5"/>'
        '<dynamics damping="0.0001" friction="0.0001"/></joint>',
    )


class _NoRootHold:
    """A session whose engine cannot hold the root (the probe then applies
    the push's reaction on the root only)."""

    def __init__(self, session):
        self._session = session

    def hold_root(self, max_force: float) -> None:
        raise EngineUnsupported("test: no bounded root hold")

    def __getattr__(self, name):
        return getattr(self._session, name)


@pytest.mark.parametrize("hold", ["held", "reaction only", "external push"])
def test_a_cover_that_drags_on_the_ground_is_swung_open_while_the_other_hand_holds_the_stick(tmp_path, hold):
    """The ground's friction on the 15 g cover (about 0.07 N) is a force from
    outside the object: the push's reaction on the 5 g stick alone (ground
    friction about 0.025 N) leaves it to slide or turn with the cover, as
    does an external push; the stick held by the other hand (the default,
    a bounded hold of the root) stays put and the cover swings open."""
    f = _swivel(tmp_path / "s")
    s = open_session("pybullet", f / "mobility.urdf", SessionOptions(initial_state={"swivel": 0.0}))
    try:
        session = _NoRootHold(s) if hold == "reaction only" else s
        r = probe_joint(session, "swivel", (0.0, 1.0, 1.2), action="open",
                        config=ProbeConfig(hold_body=hold != "external push"))
    finally:
        s.close()
    if hold == "held":
        assert r.success, r.failure
        assert r.root_displacement < 1e-3 and r.root_rotation < 0.01
    else:
        assert not r.success and "moved instead" in r.failure
        assert r.slid or r.tipped
    assert any("not held" in n for n in r.notes) is (hold == "reaction only")


def _lid(folder: Path, friction: float) -> Path:
    """A box with a lid hinged along y at its top back edge; closed at 0,
    opening towards +q up to 2 rad."""
    return _two_links(
        folder, "box",
        f'<link name="body">{_inertial(10.0, i=(0.1, 0.1, 0.1))}{_box(0.3, 0.3, 0.2)}</link>',
        f'<link name="lid">{_inertial(0.5, (0.15, 0, 0), (0.002, 0.004, 0.005))}{_box(0.3, 0.3, 0.01, (0.15, 0, 0.006))}</link>',
        '<joint name="hinge" type="revolute"><parent link="body"/><child link="lid"/>'
        '<origin xyz="-0.15 0 0.1"/><axis xyz="0 -1 0"/><limit lower="0" upper="2.0" effort="10" velocity="5"/>'
        f'<dynamics damping="0.05" friction="{friction}"/></joint>',
    )


@pytest.mark.parametrize("friction, holds", [(0.0, False), (2.0, True)])
def test_open_probe_detects_a_lid_that_falls_shut(tmp_path, friction, holds):
    f = _lid(tmp_path / "l", friction)
    s = open_session("pybullet", f / "mobility.urdf", SessionOptions(initial_state={"hinge": 0.0}))
    try:
        r = probe_joint(s, "hinge", (0.0, 1.0, 2.0), action="open", holds_position=True)
    finally:
        s.close()
    assert r.reached
    assert r.peak_effort == pytest.approx(r.peak_force * r.lever_arm, rel=1e-6)
    assert r.rebound is (not holds)
    assert r.success is holds
    if not holds:
        assert r.failure == "does not hold the open position after release"
        assert r.final_fraction < r.release_fraction - 0.05


def test_falling_lid_is_only_a_note_when_holding_is_not_requested(tmp_path):
    f = _lid(tmp_path / "l", 0.0)
    s = open_session("pybullet", f / "mobility.urdf", SessionOptions(initial_state={"hinge": 0.0}))
    try:
        (r,) = run_probes(s, {"hinge": (0.0, 1.0, 2.0)}, actions=("open",))
        after = s.joint_positions()["hinge"]
    finally:
        s.close()
    assert r.rebound and r.success and r.notes
    assert after == pytest.approx(0.0, abs=1e-9)  # run_probes restores the saved state


def test_probe_arguments_are_checked(tmp_path):
    f = drawer(tmp_path / "d")
    s = open_session("pybullet", f / "mobility.urdf", SessionOptions())
    try:
        with pytest.raises(ValueError, match="action"):
            probe_joint(s, "slide", (0, 1, 0.3), action="push")
        with pytest.raises(ValueError, match="open_range"):
            probe_joint(s, "slide", (0, 1, 0.0), action="open")
        with pytest.raises(KeyError):
            probe_joint(s, "nope", (0, 1, 0.3), action="open")
    finally:
        s.close()


def test_probes_metric_without_probes_has_no_verdict():
    m = probes_metric([])
    assert m.passed is None and m.value == 0.0


def test_probe_config_time_budget_limits_a_stuck_push(tmp_path):
    f = drawer(tmp_path / "d", base_mass=200.0, friction=5000.0)
    s = open_session("pybullet", f / "mobility.urdf", SessionOptions(initial_state={"slide": 0.15}))
    try:
        cfg = ProbeConfig(push_time=0.5, release_time=0.1, force_factor=0.05)  # F_max ~ 99 N: below both frictions
        r = probe_joint(s, "slide", (0.0, 1.0, 0.3), action="close", config=cfg)
    finally:
        s.close()
    assert not r.reached and r.failure == "target not reached"
    # stuck: the push lasts the travel's budget (the 1 s ramp plus 1.5 x the travel at the push speed,
    # more than push_time here), the force saturating at F_max after the ramp
    budget = max(cfg.push_time, cfg.ramp_time + TRAVEL_TIME_MARGIN * abs(r.target - r.start) / cfg.push_speed)
    assert budget > cfg.push_time
    assert r.peak_force == pytest.approx(r.max_force, rel=1e-6)
    assert len([x for x in r.trace["phase"] if x == 0.0]) == int(round(budget * 240))


def test_push_budget_is_capped_but_never_below_push_time():
    cfg = ProbeConfig()
    assert push_budget(cfg, 1.0, 0.1) == (cfg.push_time, cfg.push_time)  # a short travel: push_time
    allowed, asked = push_budget(cfg, 1.0, 2.4)  # a very large door opened 1.57 rad at 1.5 m: not cut
    assert allowed == asked == pytest.approx(1.0 + TRAVEL_TIME_MARGIN * 2.4 / cfg.push_speed) and asked < MAX_PUSH_TIME
    assert push_budget(cfg, 1.0, 30.0) == (MAX_PUSH_TIME, pytest.approx(1.0 + TRAVEL_TIME_MARGIN * 30.0 / cfg.push_speed))
    assert push_budget(cfg, 250.0, 0.0)[0] == MAX_PUSH_TIME  # a part of 0.1 g effective mass: the ramp is cut too
    assert push_budget(ProbeConfig(push_time=40.0), 1.0, 30.0)[0] == 40.0


def test_push_on_a_part_far_from_its_axis_is_bounded(tmp_path):
    """Once the HTML report took 78 s on an asset with mesh scale 1e-6,
    its joint origins left in file units. A lid whose hinge lies 100 m
    away asks 1 + 1.5 x 30 m / 0.25 m/s = 181 s of push for a 0.3 rad
    opening (43,440 engine steps when stuck). The push stops at
    ``MAX_PUSH_TIME`` (30 s) and the probe says so."""
    f = _two_links(
        tmp_path / "far", "box",
        f'<link name="body">{_inertial(10.0, i=(0.1, 0.1, 0.1))}{_box(0.3, 0.3, 0.2)}</link>',
        f'<link name="lid">{_inertial(0.5, (-100.0, 0, 0.006), (0.002, 0.004, 0.005))}{_box(0.3, 0.3, 0.01, (-100.0, 0, 0.106))}</link>',
        '<joint name="hinge" type="revolute"><parent link="body"/><child link="lid"/>'
        '<origin xyz="100 0 0"/><axis xyz="0 -1 0"/><limit lower="0" upper="0.5" effort="10" velocity="5"/>'
        '<dynamics damping="0.05" friction="100000.0"/></joint>',  # stuck: more friction than the pusher's torque
    )
    s = open_session("pybullet", f / "mobility.urdf", SessionOptions(initial_state={"hinge": 0.0}))
    try:
        r = probe_joint(s, "hinge", (0.0, 1.0, 0.5), action="open")
        dt = s.options.conventions.timestep
    finally:
        s.close()
    assert r.lever_arm == pytest.approx(100.15, abs=0.01)
    assert not r.reached and r.failure == "target not reached"
    assert len([x for x in r.trace["phase"] if x == 0.0]) == int(round(MAX_PUSH_TIME / dt))
    (note,) = [n for n in r.notes if "cap" in n]
    assert "30 s cap" in note and "asked 181 s" in note and "lever 100 m" in note


def _lever_on_heavy_body(folder: Path) -> Path:
    """A 50 kg body with a 20 g lever (6 cm) turning about a vertical axis
    (no gravity load), limits [0, 0.52] rad, closed at 0: a toilet's flush
    lever."""
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "mobility.urdf").write_text(
        '<?xml version="1.0"?><robot name="toilet">'
        f'<link name="body">{_inertial(50.0, i=(2.0, 2.0, 2.0))}{_box(0.4, 0.4, 0.4, (0, 0, 0.2))}</link>'
        f'<link name="lever">{_inertial(0.02, (0.03, 0, 0), (1e-7, 6e-6, 6e-6))}{_box(0.06, 0.01, 0.01, (0.03, 0, 0))}</link>'
        '<joint name="flush" type="revolute"><parent link="body"/><child link="lever"/>'
        '<origin xyz="0.2 0 0.35"/><axis xyz="0 0 1"/><limit lower="0" upper="0.52" effort="10" velocity="50"/>'
        '<dynamics damping="0.0001" friction="0.002"/></joint></robot>'
    )
    return folder


def test_a_light_lever_on_a_heavy_body_is_closed_without_slamming_into_its_stop(tmp_path):
    """The pusher's stiffness is bounded by the lever's effective mass (module
    docstring): the 20 g lever of a 50 kg body is closed at about the push
    speed and stays closed. With the stiffness set by the whole object's
    weight (the earlier force law) the first step's 4 N threw it at ~4 m/s
    into its stop and it bounced back open ("springs back after release")."""
    f = _lever_on_heavy_body(tmp_path / "t")
    s = open_session("pybullet", f / "mobility.urdf", SessionOptions(initial_state={"flush": 0.52}))
    try:
        r = probe_joint(s, "flush", (0.0, 1.0, 0.52), action="close")
    finally:
        s.close()
    assert r.success, r.failure
    assert r.reached and not r.rebound
    assert r.release_fraction > -0.05  # not driven into the stop
    # it moved at about the push speed (0.25 m/s at a 6 cm lever: ~4 rad/s), not tens of rad/s
    q = np.array(r.trace["q"])
    assert np.max(np.abs(np.diff(q))) * 240 < 8.0


def _stapler(folder: Path) -> Path:
    """A base with a top hinged at its back edge (no friction: it falls shut)
    and a magazine hinged to the top's front edge that opens downwards, into
    the base while the top is closed (a stapler's magazine under its top)."""
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "mobility.urdf").write_text(
        '<?xml version="1.0"?><robot name="stapler">'
        f'<link name="base">{_inertial(5.0, (0, 0, 0.05), (0.05, 0.05, 0.05))}{_box(0.3, 0.3, 0.1, (0, 0, 0.05))}</link>'
        f'<link name="top">{_inertial(0.3, (0.075, 0, 0.006), (0.002, 0.001, 0.002))}{_box(0.15, 0.3, 0.01, (0.075, 0, 0.006))}</link>'
        f'<link name="magazine">{_inertial(0.2, (0.075, 0, 0.006), (0.0015, 0.0005, 0.0015))}{_box(0.14, 0.3, 0.01, (0.075, 0, 0.006))}</link>'
        '<joint name="top_hinge" type="revolute"><parent link="base"/><child link="top"/>'
        '<origin xyz="-0.15 0 0.1"/><axis xyz="0 -1 0"/><limit lower="0" upper="1.6" effort="10" velocity="5"/>'
        '<dynamics damping="0.01" friction="0.0"/></joint>'
        '<joint name="magazine_hinge" type="revolute"><parent link="top"/><child link="magazine"/>'
        '<origin xyz="0.155 0 0"/><axis xyz="0 1 0"/><limit lower="0" upper="1.5" effort="10" velocity="5"/>'
        '<dynamics damping="0.01" friction="0.05"/></joint></robot>'
    )
    return folder


def test_a_part_shut_in_by_another_is_probed_with_that_one_held_open(tmp_path):
    """The magazine opens into the base while the top is closed: its open
    probe stalls at the closed end. Given the URDF model, the probe finds the
    base in the way, holds the top open (it falls shut by itself) and opens
    the magazine, with a note; without the model the stall is the verdict."""
    f = _stapler(tmp_path / "s")
    joints = {"magazine_hinge": (0.0, 1.0, 1.5), "top_hinge": (0.0, 1.0, 1.6)}
    out = {}
    for with_model in (False, True):
        s = open_session("pybullet", f / "mobility.urdf", SessionOptions())
        try:
            out[with_model] = run_probes(s, joints, actions=("open",),
                                         model=read_urdf(f / "mobility.urdf") if with_model else None)
        finally:
            s.close()
    plain, cleared = ({r.joint: r for r in out[k]} for k in (False, True))
    assert not plain["magazine_hinge"].success and plain["magazine_hinge"].failure == "target not reached"
    assert plain["magazine_hinge"].release_fraction < 0.05
    r = cleared["magazine_hinge"]
    assert r.success, r.failure
    assert any("base is in the way" in n and "top_hinge held" in n for n in r.notes)
    assert cleared["top_hinge"].success and plain["top_hinge"].success  # the top itself opens either way


def test_a_spring_the_part_prior_expects_may_return_the_close_probe_a_stray_one_may_not(tmp_path):
    """The rebound rule is the task check's hold rule: the same sprung drawer
    fails the close probe as a drawer (no spring expected) and passes, with a
    note, where its spring is one the joint is expected to have."""
    from asset2sim.engines.base import SessionOptions, Spring
    from asset2sim.engines.registry import open_session
    from asset2sim.tasks.check.probes import run_probes

    urdf = drawer(tmp_path / "d", stiffness=200.0) / "mobility.urdf"
    opts = SessionOptions(initial_state={"slide": 0.15}, springs={"slide": Spring(stiffness=200.0, reference=0.3)})
    with open_session("pybullet", urdf, opts) as s:
        stray, = run_probes(s, {"slide": (0.0, 1.0, 0.3)}, actions=("close",))
        designed, = run_probes(s, {"slide": (0.0, 1.0, 0.3)}, actions=("close",), returns={"slide"})
    assert stray.rebound and stray.failure == "springs back after release"
    assert designed.rebound and designed.success and any("springs back" in n for n in designed.notes)


def test_a_turn_about_the_vertical_is_not_tipping(tmp_path):
    """SupportWatch's tilt is the up direction's angle from the vertical (as
    robust rest's topple): a flat object turned on the table by 0.9 rad has
    not tipped; one tilted by 0.1 rad has, whatever it was turned by."""
    from asset2sim.engines.base import SessionOptions
    from asset2sim.engines.registry import open_session
    from asset2sim.frames import axis_angle_matrix, matrix_quat_wxyz, quat_wxyz_to_xyzw
    from asset2sim.tasks.check.support import SupportWatch

    urdf = drawer(tmp_path / "d") / "mobility.urdf"
    with open_session("pybullet", urdf, SessionOptions()) as s:
        watch = SupportWatch(s, s.link_names[0])
        p, _ = s.root_pose()
        for R, tilt in ((axis_angle_matrix(np.array([0.0, 0.0, 1.0]), 0.9), 0.0),
                        (axis_angle_matrix(np.array([1.0, 0.0, 0.0]), 0.1) @ axis_angle_matrix(np.array([0.0, 0.0, 1.0]), 0.9), 0.1)):
            s.set_root_pose(p, quat_wxyz_to_xyzw(matrix_quat_wxyz(R)))
            assert watch.current()[1] == pytest.approx(tilt, abs=1e-6)
