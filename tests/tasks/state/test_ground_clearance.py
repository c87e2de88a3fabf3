"""Ground clearance: a door modelled flush with the body's bottom drags on the
floor when opened (the body slides and the door probe fails); refine raises
the door's collision pieces off the ground."""

from __future__ import annotations

import json

import pytest

from asset2sim.demo_assets import build_microwave
from asset2sim.tasks import refine
from asset2sim.tasks.evaluation.evaluate import evaluate_asset
from asset2sim.tasks.state import ground_clearance
from asset2sim.urdf import read_urdf
from asset2sim.tasks.interpret.categories import category_prior
from tests.conftest import SHARED, needs_shared


def _lowest(urdf, state) -> dict[str, float]:
    """link -> lowest collision vertex (m, z) of the written URDF at ``state``."""
    model = read_urdf(urdf)
    poses = model.link_poses(state)
    out = {}
    for ln in model.links:
        ps = ground_clearance.link_pieces(model, urdf.parent, ln)
        if ps:
            T = poses[ln]
            out[ln] = min(float((P @ T[:3, :3].T + T[:3, 3])[:, 2].min()) for P in ps)
    return out


def _open_probe(out):
    ev = evaluate_asset(out, probes=True)
    return next(p for p in ev.metric("probes").details["probes"] if p["action"] == "open")


def test_door_flush_with_the_floor_is_raised_and_opens_without_the_body_sliding(tmp_path, refine_once):
    src = build_microwave(tmp_path / "src")
    res = refine_once(src, "A microwave.", extras=False)
    out = res.copy_to(tmp_path / "out")  # the evaluation below writes into it
    urdf = out / "mobility.urdf"
    state = res.report.initial_joint_positions
    low = _lowest(urdf, state)
    assert any("link_0: collision piece" in c and "above the ground" in c for c in res.report.state.collision_changes)
    body = min(low[ln] for ln in low if ln != "link_0")
    assert low["link_0"] - body >= ground_clearance.GROUND_CLEARANCE - 1e-6
    p = _open_probe(out)
    assert p["success"], p["failure"]
    assert p["root_displacement"] < 0.002


def test_a_door_flush_with_the_floor_is_not_pressed_into_it_by_a_contact_cached_before_placement(tmp_path, monkeypatch):
    """The same refine with the repair off leaves the door's piece flush with the floor. Put on the ground, the
    object is first lifted by its bounding boxes, then lowered by the closest points' distance: Bullet kept the
    contacts of the first pose and read them, shifted by the second, as a penetration of the door into the floor,
    and opening the door pulled the body 5 mm along (the probe failed). Contacts are found anew after a teleport:
    the flush door opens and the body stays; the repair still lifts the door as real appliance doors clear the
    floor (the test above)."""
    monkeypatch.setattr(ground_clearance, "apply_ground_clearance",
                        lambda candidate, ws, closed: ground_clearance.GroundLifted(dict(candidate.state), candidate.collision_overrides, [], []))
    src = build_microwave(tmp_path / "src")
    res = refine.refine_asset(src, "A microwave.", tmp_path / "out", extras=False)
    low = _lowest(tmp_path / "out" / "mobility.urdf", res.report.initial_joint_positions)
    assert abs(low["link_0"] - min(low.values())) < 1e-3  # flush with the body's bottom
    p = _open_probe(tmp_path / "out")
    assert p["success"] and not p["slid"], p["failure"]
    assert p["root_displacement"] < 0.002


def _box_obj(path, lo, hi):
    v = [(x, y, z) for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])]
    f = [(1, 2, 4), (1, 4, 3), (5, 7, 8), (5, 8, 6), (1, 5, 6), (1, 6, 2), (3, 4, 8), (3, 8, 7), (1, 3, 7), (1, 7, 5), (2, 6, 8), (2, 8, 4)]
    path.write_text("".join(f"v {a} {b} {c}\n" for a, b, c in v) + "".join(f"f {a} {b} {c}\n" for a, b, c in f))


def _two_part(folder, *, part_lo, part_hi, body_lo, body_hi, axis, jtype="revolute", origin="0 0 0"):
    """A body box and a part box joined at ``origin`` by ``jtype`` about ``axis``."""
    folder.mkdir(parents=True, exist_ok=True)
    _box_obj(folder / "body.obj", body_lo, body_hi)
    _box_obj(folder / "part.obj", part_lo, part_hi)
    inert = '<inertial><mass value="1"/><inertia ixx="0.01" iyy="0.01" izz="0.01" ixy="0" ixz="0" iyz="0"/></inertial>'
    (folder / "mobility.urdf").write_text(
        '<?xml version="1.0"?><robot name="t">'
        f'<link name="body">{inert}<collision><geometry><mesh filename="body.obj"/></geometry></collision></link>'
        f'<link name="part">{inert}<collision><geometry><mesh filename="part.obj"/></geometry></collision></link>'
        f'<joint name="j" type="{jtype}"><parent link="body"/><child link="part"/><origin xyz="{origin}"/><axis xyz="{axis}"/>'
        '<limit lower="0" upper="1.5" effort="10" velocity="1"/></joint></robot>')
    return folder / "mobility.urdf"


def test_flush_side_hinged_door_is_raised_by_the_clearance(tmp_path):
    urdf = _two_part(tmp_path / "a", body_lo=(0, 0, 0), body_hi=(0.4, 0.4, 0.3), part_lo=(-0.02, 0, 0), part_hi=(0, 0.4, 0.3),
                     axis="0 0 1")
    rep = ground_clearance.ground_clearance(read_urdf(urdf), urdf, {"j": 0.0})
    assert list(rep.pieces) == ["part"]
    assert float(rep.pieces["part"][0][:, 2].min()) == pytest.approx(ground_clearance.GROUND_CLEARANCE)
    assert float(rep.pieces["part"][0][:, 2].max()) == pytest.approx(0.3)  # the top face stays


def test_horizontal_hinge_wheel_and_parts_that_carry_the_body_are_left_alone(tmp_path):
    # a flap on a horizontal hinge at the floor: it lifts off, it does not drag
    flap = _two_part(tmp_path / "f", body_lo=(0, 0, 0), body_hi=(0.4, 0.4, 0.3), part_lo=(-0.02, 0, 0), part_hi=(0, 0.4, 0.3),
                     axis="0 1 0")
    assert not ground_clearance.ground_clearance(read_urdf(flap), flap, {"j": 0.0}).pieces
    # a wheel (continuous joint)
    wheel = _two_part(tmp_path / "w", body_lo=(0, 0, 0), body_hi=(0.4, 0.4, 0.3), part_lo=(-0.02, 0, 0), part_hi=(0, 0.4, 0.3),
                      axis="0 0 1", jtype="continuous")
    assert not ground_clearance.ground_clearance(read_urdf(wheel), wheel, {"j": 0.0}).pieces
    # a swivel stand under a body that does not reach the ground: the stand is the support
    stand = _two_part(tmp_path / "s", body_lo=(-0.2, -0.2, 0.05), body_hi=(0.2, 0.2, 0.3), part_lo=(-0.1, -0.1, 0),
                      part_hi=(0.1, 0.1, 0.05), axis="0 0 1")
    assert not ground_clearance.ground_clearance(read_urdf(stand), stand, {"j": 0.0}).pieces


def test_pedal_pressed_below_the_floor_is_stopped_at_the_floor(tmp_path):
    """A pedal on a horizontal hinge 2 cm above the floor, 15 cm long: pressed
    to 0.4 rad its tip would be 4 cm below the floor the body stands on (trash
    can 102181: the object then stood on the pedal and its weight pushed it
    back); the opening is limited to where the pedal keeps FLOOR_GAP."""
    urdf = _two_part(tmp_path / "p", body_lo=(0, -0.2, 0), body_hi=(0.4, 0.2, 0.3), part_lo=(-0.15, -0.05, -0.005),
                     part_hi=(0, 0.05, 0.005), axis="0 -1 0", origin="0 0 0.02")
    model = read_urdf(urdf)
    state, notes = ground_clearance.floor_limited_state(model, urdf, {"j": 0.4}, {"j": (0.0, 1.0, 1.5)})
    assert notes and "limited by the floor" in notes[0]
    assert 0.0 < state["j"] < 0.4
    low = _lowest(urdf, state)
    assert low["part"] == pytest.approx(ground_clearance.FLOOR_GAP, abs=1e-5)
    # already above the floor: unchanged (the same dict, no notes)
    same = {"j": 0.05}
    assert ground_clearance.floor_limited_state(model, urdf, same, {"j": (0.0, 1.0, 1.5)}) == (same, [])


def test_an_object_lying_flat_as_a_whole_keeps_its_moving_half_on_the_floor(tmp_path, refine_once):
    """15 mm tall (lower than 2 clearances), a side-hinged half with as much
    floor contact as the body is half of what the object lies on: not
    raised; a narrow flap on the same body (a lighter's lid) is raised as a
    door is. A pair of pliers lying flat refines interaction-ready: raised,
    its moving half left it lying on the other and it tipped 0.052 rad when
    opened."""
    from tests.unseen_assets import build_pliers

    half = _two_part(tmp_path / "t", body_lo=(0, 0, 0), body_hi=(0.4, 0.4, 0.015), part_lo=(-0.4, 0, 0),
                     part_hi=(0, 0.4, 0.015), axis="0 0 1")
    assert not ground_clearance.ground_clearance(read_urdf(half), half, {"j": 0.0}).pieces
    flap = _two_part(tmp_path / "f", body_lo=(0, 0, 0), body_hi=(0.4, 0.4, 0.015), part_lo=(-0.02, 0, 0),
                     part_hi=(0, 0.4, 0.015), axis="0 0 1")
    assert list(ground_clearance.ground_clearance(read_urdf(flap), flap, {"j": 0.0}).pieces) == ["part"]
    res = refine_once(build_pliers, "Pliers, fully open.", media=False)
    assert res.report.failure_mode == "none", res.report.readiness
    assert not any("raised" in n for n in res.report.state.collision_changes)


#: The drop-down door of :func:`_drop_door`: hinge height above the floor,
#: door length and thickness, m.
HINGE_Z, DOOR, DOOR_T = 0.05, 0.2, 0.01


def _drop_door(folder, q0: float):
    """A 3 kg box (0.3 m cube) standing on the floor with a 0.5 kg door
    hinged 5 cm above the floor on its front face, opening outwards and down
    (closed at 0, limit 2.5 rad): past 90 deg the door's top edge swings
    down to the floor."""
    folder.mkdir(parents=True, exist_ok=True)
    _box_obj(folder / "body.obj", (-0.15, -0.15, 0.0), (0.15, 0.15, 0.3))
    _box_obj(folder / "door.obj", (0.0, -0.14, 0.0), (DOOR_T, 0.14, DOOR))

    def link(name, mass, com, inertia):
        return (f'<link name="{name}"><inertial><origin xyz="{com}"/><mass value="{mass}"/>'
                f'<inertia ixx="{inertia}" iyy="{inertia}" izz="{inertia}" ixy="0" ixz="0" iyz="0"/></inertial>'
                f'<collision><geometry><mesh filename="{name}.obj"/></geometry></collision></link>')

    (folder / "mobility.urdf").write_text(
        '<?xml version="1.0"?><robot name="dropdoor">'
        + link("body", 3.0, "0 0 0.15", 0.05) + link("door", 0.5, f"{DOOR_T / 2} 0 {DOOR / 2}", 0.002)
        + '<joint name="flap" type="revolute"><parent link="body"/><child link="door"/>'
        f'<origin xyz="0.15 0 {HINGE_Z}"/><axis xyz="0 1 0"/><limit lower="0" upper="2.5" effort="10" velocity="5"/>'
        '<dynamics damping="0.05" friction="1.0"/></joint></robot>')
    (folder / "initial_state.json").write_text(f'{{"initial_joint_positions": {{"flap": {q0}}}}}')
    return folder


def _door_stop() -> float:
    """The opening (rad) at which the door's lowest corner comes FLOOR_GAP
    above the floor: corners (0, DOOR) and (DOOR_T, DOOR) of the door rotated
    by q about the hinge, by bisection on the closed form."""
    import math

    def lowest(q):
        return HINGE_Z + min(DOOR * math.cos(q) - DOOR_T * math.sin(q), DOOR * math.cos(q), -DOOR_T * math.sin(q))

    lo, hi = 1.0, 2.5
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if lowest(mid) >= ground_clearance.FLOOR_GAP else (lo, mid)
    return lo


def test_floor_stops_finds_where_a_drop_down_door_meets_the_floor(tmp_path):
    f = _drop_door(tmp_path / "d", 0.0)
    stops = ground_clearance.floor_stops(read_urdf(f / "mobility.urdf"), f / "mobility.urdf", {"flap": 0.0},
                                         {"flap": (0.0, 1.0, 2.5)})
    assert stops["flap"] == pytest.approx(_door_stop(), abs=1e-6)  # 1.763 rad
    # a range that ends before the floor: no stop
    assert ground_clearance.floor_stops(read_urdf(f / "mobility.urdf"), f / "mobility.urdf", {"flap": 0.0},
                                        {"flap": (0.0, 1.0, 1.5)}) == {}


@pytest.mark.parametrize("with_stop", [True, False])
def test_the_open_probe_stops_where_the_floor_stops_the_door(tmp_path, monkeypatch, with_stop):
    """Held at 1.45 rad (58 % of its range), the door's open probe aims at
    90 % (2.25 rad), beyond the floor (1.76 rad): pushed into the floor it
    levers the box up (the object moved instead). Capped at the floor stop
    (the evaluation's floor stops) the door opens to it and the probe passes,
    with notes."""
    from asset2sim.tasks.check import probes

    if not with_stop:
        monkeypatch.setattr(probes, "floor_stops", lambda *a, **k: {})
    ev = evaluate_asset(_drop_door(tmp_path / "d", 1.45), probes=True)
    m = ev.metric("probes")
    opened = next(p for p in m.details["probes"] if p["action"] == "open")
    if with_stop:
        assert m.passed is True, m.details["failures"]
        assert opened["target_fraction"] == pytest.approx(_door_stop() / 2.5, abs=1e-4)
        assert any("floor stops it" in n for n in opened["notes"])
        assert any("probes: the floor stops flap" in n for n in ev.notes)
    else:
        assert m.passed is False and not opened["success"]
        assert opened["target_fraction"] == pytest.approx(0.9)


def test_a_collision_file_the_floor_stops_cannot_read_leaves_the_probes_running(tmp_path):
    """A door mesh with a two-coordinate vertex: PyBullet loads what it can,
    the floor stops are not measured (a note says why) and the probes still
    run and report; the evaluation, which reads the asset as refine does, refuses it naming the file."""
    from asset2sim.engines.source import SimObject, UrdfFile
    from asset2sim.tasks.check.probes import probe_object
    from asset2sim.tasks.evaluation.evaluate import EvaluationError

    f = _drop_door(tmp_path / "d", 1.45)
    (f / "door.obj").write_text("v 0 0 0\nv 1 0\nf 1 2 3\n")
    state = json.loads((f / "initial_state.json").read_text())["initial_joint_positions"]
    found, notes = probe_object(SimObject(UrdfFile(f / "mobility.urdf"), state), {"flap": (0.0, 1.0, 2.5)})
    assert found and any("where the floor stops the parts was not measured" in n and "door.obj" in n for n in notes)
    with pytest.raises(EvaluationError, match="door.obj"):
        evaluate_asset(f)


def _box_mesh(lo, hi) -> str:
    """OBJ text of one axis-aligned box (lo, hi) (m)."""
    vs = [[(hi if i & m else lo)[k] for k, m in enumerate((1, 2, 4))] for i in range(8)]
    fs = [t for a, b, c, d in ((0, 2, 3, 1), (4, 5, 7, 6), (0, 1, 5, 4), (2, 6, 7, 3), (0, 4, 6, 2), (1, 3, 7, 5))
          for t in ((a, b, c), (a, c, d))]
    return "".join(f"v {x} {y} {z}\n" for x, y, z in vs) + "".join(f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in fs)


def _flat_laptop(folder):
    """A laptop whose screen hinge at the base's back top edge turns 4.2 rad (240 deg): past 180 deg the screen swings
    below the base, into the floor the laptop stands on."""
    folder.mkdir(parents=True)
    (folder / "body.obj").write_text(_box_mesh((-0.16, -0.11, 0.0), (0.16, 0.11, 0.02)))
    (folder / "screen.obj").write_text(_box_mesh((-0.16, 0.0, 0.0), (0.16, 0.22, 0.008)))
    mesh = "<visual><geometry><mesh filename='{0}'/></geometry></visual><collision><geometry><mesh filename='{0}'/></geometry></collision>"
    (folder / "mobility.urdf").write_text(
        "<?xml version='1.0'?><robot name='flat_laptop'><link name='base_link'/>"
        f"<link name='body'>{mesh.format('body.obj')}</link><link name='screen'>{mesh.format('screen.obj')}</link>"
        "<joint name='fix' type='fixed'><parent link='base_link'/><child link='body'/></joint>"
        "<joint name='hinge' type='revolute'><parent link='body'/><child link='screen'/><origin xyz='0 -0.11 0.0205'/>"
        "<axis xyz='1 0 0'/><limit lower='0' upper='4.2'/></joint></robot>")
    (folder / "semantics.txt").write_text("body free laptop_base\nscreen hinge screen\n")
    (folder / "meta.json").write_text('{"model_cat": "Laptop"}')
    return folder


def test_fully_open_is_as_far_as_the_part_goes_where_the_object_stands(tmp_path, refine_once):
    """"fully open" on a laptop whose screen meets the floor before its limit: the screen opens to the floor, that is
    its open end (recorded in report.json's closed ends, said with the stop), the request is met and the output read
    back gives the same verdict; before, "fully" was graded against the range the floor cuts off (76 %: not met)."""
    from asset2sim.tasks.evaluation.evaluate import evaluate_asset

    res = refine_once(_flat_laptop(tmp_path / "laptop"), "A laptop with its screen fully open.", extras=False)
    r = res.report
    end = r.closed_ends["hinge"]
    assert end["open_range"] < 0.9 * 4.2 and r.initial_joint_positions["hinge"] == pytest.approx(end["q_closed"] + end["open_range"])
    assert r.opening_fractions["hinge"] == pytest.approx(1.0) and r.metric("request_met").passed is True
    assert any("asked fully open" in n and "floor stops it" in n for n in r.design_changes)
    assert r.failure_mode == "none", r.readiness
    assert evaluate_asset(res.out_dir).failure_mode == "none"


@needs_shared
def test_a_suitcase_asked_half_open_is_opened_lying_on_its_back(refine_once):
    """Suitcase 101668 stands upright as modelled, and there the floor stops its lid at 3 % of its range: "A suitcase
    with its lid half open." ended request_not_met. A suitcase is opened lying on its back (categories.yaml
    `opened_lying`, sourced); laid down, the lid opens half way and every check passes, the pose said in the notes. The
    pose is the category's knowledge, not the floor's alone: a refrigerator is never laid down."""
    res = refine_once(SHARED / "101668", "A suitcase with its lid half open.", extras=False)
    r = res.report
    assert r.failure_mode == "none", r.readiness
    assert 0.35 <= r.opening_fractions["joint_2"] <= 0.65
    assert any(n.startswith("resting pose (as it is put down): opened lying on its back") for n in r.notes), r.notes
    assert category_prior("Suitcase").opened_lying and not category_prior("Refrigerator").opened_lying


@needs_shared
@pytest.mark.parametrize("prompt, band", [("A suitcase, open.", (0.6, 0.9)), ("A suitcase, slightly open.", (0.05, 0.35))])
def test_a_suitcase_laid_down_to_open_rests_where_its_lids_weight_turns_it_least(refine_once, prompt, band):
    """Laid on its back, suitcase 101668's lid asked open (a lone "open": mostly, 0.6-0.9 of its range) stood at 0.85,
    leaning back 45 degrees, and a tilt's landing swung it 0.26 rad against a 0.14 rad band (its hinge's friction at a
    hand's cap); asked slightly open, at 0.14 the landing swung it 0.13 rad against 0.12. The laid attempt failed and
    the suitcase was kept upright, the floor stopping its lid at 2-4 % of its range: `request_not_met`. Now the lid
    stands where, within its band, its weight turns it least (nearest upright: 0.60 and 0.35), said in the design
    notes, and every check passes there."""
    r = refine_once(SHARED / "101668", prompt, extras=False).report
    assert r.failure_mode == "none", r.readiness
    assert any(n.startswith("resting pose (as it is put down): opened lying on its back") for n in r.notes), r.notes
    assert any("joint_2" in d and "where it turns it least within its band" in d for d in r.design_changes), r.design_changes
    lo, hi = band
    assert lo - 1e-6 <= r.opening_fractions["joint_2"] <= hi + 1e-6
    assert r.metric("request_met").passed is True


@needs_shared
def test_a_large_suitcase_too_heavy_to_open_standing_is_opened_lying_on_its_back(refine_once):
    """Suitcase 103755 asked "A large suitcase, halfway open." stands as modelled on its narrow edge, its 3.3 kg lid
    swinging out sideways; held half open by friction (11.1 N m against a 9.4 N m weight moment), a 22.2 N hand at the
    lid's far edge could not close it from 88 % open (35.4 N): `not_operable`. Only a band the floor cut short laid a
    suitcase down. Now any opening that does not settle as modelled is tried lying on its back, as a suitcase is
    opened, and there every check passes, the pose and the reason in the notes."""
    r = refine_once(SHARED / "103755", "A large suitcase, halfway open.", extras=False).report
    assert r.failure_mode == "none", r.readiness
    assert any(n.startswith("resting pose (as it is put down): opened lying on its back, as a suitcase is (operability failed")
               for n in r.notes), r.notes
    assert 0.35 <= r.opening_fractions["joint_1"] <= 0.65
