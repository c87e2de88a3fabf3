"""Categories the dev set lacks, on generated assets (tests/unseen_assets.py):
a safe with a dial on its door, a toaster with a lever and a dial, a capped
bottle, a desk with a drawer, a range oven with a drop-down door, a pot with
a lid, a front-loading washing machine, a kettle, folding glasses, a bucket
with a bail handle, a wardrobe with two doors over two drawers, a printer, a
desk lamp and a desk fan. Each is
refined for a short request of the hidden set's kind and must be
interaction-ready on every tier, recognised as its
category, mounted as the category's prior says, with the requested joint in
its band."""

from __future__ import annotations


import numpy as np
import pytest

from asset2sim import mesh_io
from asset2sim.schemas.config import RefineConfig
from asset2sim.schemas.request import BAND_INTERVAL
from asset2sim.tasks.interpret.mounting import category_mounting
from asset2sim.tasks.evaluation.evaluate import evaluate_asset
from asset2sim.tasks.refine import refine_asset
from asset2sim.urdf import read_urdf
from tests.helpers import assert_ready_or_honestly_not_robust
from tests.unseen_assets import (
    build_barred_safe,
    build_coffee_machine,
    build_bottle,
    build_bucket,
    build_click_pen,
    build_desk_fan,
    build_desk_lamp,
    build_dispenser,
    build_eyeglasses,
    build_kettle,
    build_keyboard,
    build_kitchen_pot,
    build_oven,
    build_pocket_lighter,
    build_printer,
    build_safe,
    build_table_with_drawer,
    build_toaster,
    build_usb_swivel,
    build_wardrobe,
    build_washing_machine,
    one_mesh_per_link,
)

CASES = [
    (build_safe, "Safe", "A safe, closed.", "joint_0", "closed"),
    (build_toaster, "Toaster", "A toaster with everything closed.", "joint_0", "closed"),
    (build_bottle, "Bottle", "A bottle, fully open.", "joint_0", "fully"),
    (build_table_with_drawer, "Table", "A table, opened halfway.", "joint_0", "halfway"),
    (build_oven, "Oven", "A small oven, closed.", "joint_0", "closed"),
    (build_kitchen_pot, "KitchenPot", "A cooking pot, closed.", "joint_0", "closed"),
    (build_washing_machine, "WashingMachine", "A washing machine with its door fully open.", "joint_0", "fully"),
    (build_kettle, "Kettle", "A kettle, halfway open.", "joint_0", "halfway"),
    (build_eyeglasses, "Eyeglasses", "Eyeglasses, fully open.", "joint_1", "fully"),
    (build_bucket, "Bucket", "A bucket with its handle closed.", "joint_0", "closed"),
    (build_printer, "Printer", "A printer with its lid halfway open.", "joint_0", "halfway"),
    (build_desk_lamp, "Lamp", "A desk lamp, closed.", "joint_2", "closed"),
    (build_desk_fan, "Fan", "A desk fan with its head closed.", "joint_0", "closed"),
    (build_keyboard, "Keyboard", "A computer keyboard.", "joint_0", "closed"),
]


@pytest.mark.slow  # end to end: a sweep of generated objects, every extra
@pytest.mark.parametrize("build, category, prompt, joint, band", CASES, ids=[c[1] for c in CASES])
def test_an_unseen_category_is_interaction_ready(tmp_path, build, category, prompt, joint, band):
    src = build(tmp_path / "src")
    res = refine_asset(src, prompt, tmp_path / "out")
    r = res.report
    assert r.category == category
    assert r.failure_mode == "none", (r.failure_mode, r.readiness)
    assert all(v in (True, None) for v in r.readiness.values()), r.readiness
    assert r.mounting.fixed == category_mounting(category).fixed
    assert r.requested_bands[joint] == band
    lo, hi = BAND_INTERVAL[band]
    assert lo - 0.02 <= r.opening_fractions[joint] <= hi + 0.02


@pytest.mark.parametrize("build, prompt", [
    (build_safe, "A safe, halfway open."),
    (build_oven, "A small oven, mostly open."),
    (build_kitchen_pot, "A cooking pot, slightly open."),
    (build_bucket, "A bucket with its handle halfway open."),
], ids=["Safe", "Oven", "KitchenPot", "Bucket"])
def test_an_opened_part_is_held_by_a_hands_friction_or_the_verdict_says_it_is_not(tmp_path, build, prompt, refine_once):
    """A safe's door halfway, an oven's drop-down door mostly open (on its counterbalance spring), a pot's lid
    slightly open: every part stays operable by a hand inside its range; where robust rest's drop and tilts
    then move the part beyond its tolerance, the verdict is not_robust_at_rest at the hand's cap, never a
    part jammed to be still."""
    res = refine_once(build(tmp_path / "src"), prompt, extras=False)
    assert_ready_or_honestly_not_robust(res.report, res.overlay)


@pytest.mark.parametrize("build, prompt, joint", [
    (build_usb_swivel, "A tiny usb.", "joint_0"),
    (build_eyeglasses, "Tiny eyeglasses.", "joint_0"),
], ids=["USB", "Eyeglasses"])
def test_a_part_of_a_few_grams_opens_while_the_other_hand_holds_the_body(tmp_path, build, prompt, joint, refine_once):
    """At a few grams (an 18 mm, 1.2 g USB stick; eyeglasses a third of their
    size) the probe's hand grips the body and takes the push's reaction.
    The same reaction also applied to the gripped root left these parts
    unmoved in PyBullet while the push rose to 2.7 N."""
    src = build(tmp_path / "src")
    res = refine_once(src, prompt, media=False)  # the first phase: the verdict and evaluation.json
    r = res.report
    assert r.total_mass < 0.05
    assert r.failure_mode == "none", (r.failure_mode, r.readiness)
    probes = evaluate_asset(res.out, probes=True).metric("probes", "pybullet")
    opened = [p for p in probes.details["probes"] if p["joint"] == joint and p["action"] == "open"]
    assert opened and all(p["success"] and p["peak_force"] < 1.0 for p in opened), opened


def test_a_door_barred_by_its_own_body_is_not_reported_ready(tmp_path, refine_once):
    """Built to fail: the safe's door is barred by a part of its body. Asked
    halfway open, the door lies through the bar, which the simulators do not
    collide with it (parent and child): the bar's collision piece is kept
    (it used to be cut away at the initial state, and the safe reported
    ready) and the penetration tier fails on the parent-child depth."""
    src = build_barred_safe(tmp_path / "src")
    res = refine_once(src, "A safe, halfway open.", media=False)
    r = res.report
    assert r.failure_mode == "unresolved_penetration", (r.failure_mode, r.readiness)
    nested = next(m for m in r.metrics if m.name == "parent_child_penetration")
    assert nested.details["beyond_modelled_mm"] > 20.0  # mm: the door's edge well inside the bar, clear when closed
    assert any("past a stop" in n for n in r.state.collision_changes + r.notes), r.state.collision_changes


def test_a_button_pressed_into_a_body_drawn_solid_behind_it_meets_no_stop(tmp_path, refine_once):
    """A coffee machine's power button presses 7 mm into the front of a body drawn solid behind it (its recess not
    modelled). The limit scan keeps its limit (it is blocked from its modelled pose on, not stopped after moving
    clear), and asked mostly open, the button lay 6.2 mm inside the body: the separation called that a stop the state
    lay past and kept the pieces (``unresolved_penetration``). A part pressed into its parent from its modelled pose
    on now has its pieces cut at the state as at a limit; a door meeting a bar of its body after moving clear (the
    barred safe above) is still a stop."""
    src = build_coffee_machine(tmp_path / "src")
    r = refine_once(src, "A coffee machine, mostly open.", media=False).report
    assert r.failure_mode == "none", (r.failure_mode, r.readiness)
    assert not any("past a stop" in n for n in r.state.collision_changes), r.state.collision_changes
    assert r.opening_fractions["joint_1"] > 0.5


@pytest.mark.parametrize("prompt", ["A tiny oven.", "A very small oven."])
def test_a_small_ovens_square_dial_turns_past_the_door_below_it(tmp_path, prompt, refine_once):
    """The oven's square dial clears the door's top edge by 3.4 mm (model
    units) at rest and by 1 mm less than its corners reach while it turns:
    at a quarter of its size that is under the engines' contact margins, and
    the dial stuck at 13 % of its probe. Its collision piece is shrunk about
    its axis (noted) and it turns."""
    res = refine_once(build_oven(tmp_path / "src"), prompt, media=False)
    r = res.report
    assert r.failure_mode == "none", (r.failure_mode, r.readiness)
    assert any("shrunk" in c and "'joint_1'" in c for c in r.state.collision_changes), r.state.collision_changes


@pytest.mark.parametrize("build, prompt, joint", [
    (build_toaster, "A toaster with its slider fully open.", "joint_0"),
    (build_bucket, "A bucket with its handle fully open.", "joint_0"),
    (build_safe, "A safe, slightly open.", "joint_0"),
], ids=["Toaster", "Bucket", "Safe"])
def test_an_unseen_category_with_one_concave_mesh_per_link_is_interaction_ready(tmp_path, build, prompt, joint, refine_once):
    """PartNet-Mobility's files hold one group each, a part concave as modelled (a bail's arms and grip, a
    toaster body with its slots), where the generator's boxes are each a group of their own and so a convex
    piece for free. With every link's meshes merged into one OBJ of one group
    (:func:`tests.unseen_assets.one_mesh_per_link`) the object still passes every tier and the probes."""
    src = one_mesh_per_link(build(tmp_path / "src"))
    model = read_urdf(src / "mobility.urdf")
    for link in model.links.values():
        meshes = [g for g in link.collisions if g.kind == "mesh"]
        assert len(meshes) <= 1
        if meshes:
            assert len(mesh_io.obj_groups(src / meshes[0].filename)) == 1
    assert len(model.links["link_0"].visuals) == 1
    res = refine_once(src, prompt, media=False)  # the first phase holds every tier
    r = res.report
    assert r.failure_mode == "none", (r.failure_mode, r.readiness)
    assert all(v in (True, None) for v in r.readiness.values()), r.readiness
    assert evaluate_asset(res.out, probes=True).metric("probes").passed is True  # reported beside the verdict
    assert r.opening_fractions[joint] > 0.1


def _settled_in(urdf_path, body: str, joint: str, joint_q: float) -> tuple[float, float, float]:
    """Drop a cube of a fifth of the body's narrower width from above the middle of ``body`` (the object fixed,
    ``joint`` at ``joint_q``) in PyBullet and let it settle 2 s: (the cube's final height, the body's top, the
    cube's half size), m."""
    import pybullet as p

    cid = p.connect(p.DIRECT)
    try:
        p.setGravity(0, 0, -9.81, physicsClientId=cid)
        obj = p.loadURDF(str(urdf_path), useFixedBase=True, physicsClientId=cid,
                         flags=p.URDF_USE_SELF_COLLISION | p.URDF_USE_SELF_COLLISION_EXCLUDE_PARENT | p.URDF_USE_INERTIA_FROM_FILE)
        index = {p.getJointInfo(obj, i, physicsClientId=cid)[12].decode(): i for i in range(p.getNumJoints(obj, physicsClientId=cid))}
        joints = {p.getJointInfo(obj, i, physicsClientId=cid)[1].decode(): i for i in range(p.getNumJoints(obj, physicsClientId=cid))}
        p.resetJointState(obj, joints[joint], joint_q, physicsClientId=cid)
        for i in joints.values():
            p.setJointMotorControl2(obj, i, p.VELOCITY_CONTROL, targetVelocity=0.0, force=50.0, physicsClientId=cid)
        lo, hi = (np.asarray(v) for v in p.getAABB(obj, index.get(body, -1), physicsClientId=cid))
        half = 0.1 * float(min(hi[:2] - lo[:2]))
        box = p.createCollisionShape(p.GEOM_BOX, halfExtents=[half] * 3, physicsClientId=cid)
        cube = p.createMultiBody(0.05, box, basePosition=[*((lo[:2] + hi[:2]) / 2), hi[2] + 2 * half], physicsClientId=cid)
        for _ in range(480):
            p.stepSimulation(physicsClientId=cid)
        z = p.getBasePositionAndOrientation(cube, physicsClientId=cid)[0][2]
        return float(z), float(hi[2]), half
    finally:
        p.disconnect(cid)


@pytest.mark.slow  # end to end: a CoACD decomposition of a whole container, then a drop into it
def test_a_bucket_of_one_mesh_is_hollow_and_holds_what_is_dropped_into_it(tmp_path, refine_once):
    """A bucket whose body is one OBJ group: its one convex hull would be a solid block and a cube dropped into
    it would rest on its rim. With ``open_containers`` the body's collision is a convex decomposition (noted in
    the report) and the cube falls to the bottom, below the rim by more than its own size; without it (the
    default) the cube rests on the solid hull."""
    pytest.importorskip("coacd")
    src = one_mesh_per_link(build_bucket(tmp_path / "src"))
    res = refine_once(src, "A bucket.", config=RefineConfig(open_containers=True), extras=False)
    r = res.report
    assert r.failure_mode == "none", (r.failure_mode, r.readiness)
    opened = [n for n in r.state.collision_changes if "holds an open cavity" in n and "'link_1'" in n]
    assert opened and "convex pieces (CoACD)" in opened[0], r.state.collision_changes
    model = read_urdf(res.out_dir / "mobility.urdf")
    assert len([c for c in model.links["link_1"].collisions if c.kind == "mesh"]) > 1
    handle = next(j for j in model.joints if j.name == "joint_0")
    z, top, half = _settled_in(res.out_dir / "mobility.urdf", "link_1", "joint_0", handle.upper)
    assert z < top - 2.0 * half, (z, top, half)
    solid = refine_once(src, "A bucket.", extras=False)
    assert not any("holds an open cavity" in n for n in solid.report.state.collision_changes)
    z, top, half = _settled_in(solid.out_dir / "mobility.urdf", "link_1", "joint_0", handle.upper)
    assert z > top, (z, top, half)


def test_a_swivel_usb_stick_half_open_rests_leaning_on_its_covers_plate(tmp_path, refine_once):
    """A swivel USB stick asked halfway open: its U-shaped cover turned 90 degrees lies across under the stick's
    rear, and the stick tips onto its plug end, a few degrees, as a real one does on a table. Laid on its side
    instead (the steadiest face), the cover's turn meets the floor at 1 % open and the request was not met. With
    no face that passes, the modelled pose is put down where it came to rest: leaning 3.5 degrees, the cover
    half open, every tier passing, the lean in the notes."""
    res = refine_once(build_usb_swivel(tmp_path / "src"), "A USB stick, halfway open.", extras=False)
    r = res.report
    assert r.failure_mode == "none", (r.failure_mode, r.readiness)
    lo, hi = BAND_INTERVAL["halfway"]
    assert lo <= r.opening_fractions["joint_0"] <= hi
    (note,) = [n for n in r.notes if "put down leaning" in n]
    assert "unstable as modelled" in note
    lean = float(note.split("leaning ")[1].split(" deg")[0])
    assert 1.0 < lean < 10.0


def test_a_wardrobes_drawers_sweep_after_its_doors_without_a_stale_contact_between_the_doors(tmp_path, refine_once):
    """A wardrobe with two doors over two drawers, closed. Each joint is swept in turn in one PyBullet session,
    restored between sweeps. Bullet kept the contact of a door closing back past the other across the restore and
    read it, refreshed at the shut pose, 11.8 mm deep: the first drawer's sweep failed on the doors' penetration and
    the wardrobe was reported ``blocked_joint``. Contacts are now found anew after a teleport: on the output, the
    doors' contact after a door's sweep reads what the closest points read, and the wardrobe is ready."""
    from asset2sim.engines.source import UrdfFile
    from asset2sim.tasks.check.blockers import fixed_root_options
    from asset2sim.tasks.check.sweep import sweep_joint

    res = refine_once(build_wardrobe(tmp_path / "src"), "A wardrobe.", extras=False)
    r = res.report
    assert r.failure_mode == "none", (r.failure_mode, r.readiness)
    state = dict(r.initial_joint_positions)
    s = UrdfFile(res.out_dir / "mobility.urdf").open("pybullet", fixed_root_options(state))
    try:
        saved = s.save_state()
        for joint in ("joint_0", "joint_1"):  # the doors
            s.restore_state(saved)
            end = r.closed_ends[joint]
            sweep_joint(s, joint, closed=end["q_closed"], direction=end["direction"], open_range=end["open_range"],
                        links=[s.joint_child[joint]], initial_state=state)
            s.restore_state(saved)
            cached, fresh = (max((c.max_depth for c in pairs), default=0.0)
                             for _, pairs in (s.self_penetration(), s.self_penetration_fresh()))
            assert cached == pytest.approx(fresh, abs=1e-4), (joint, cached, fresh)
    finally:
        s.close()


@pytest.mark.parametrize("build, prompt, travel", [(build_click_pen, "A pen.", 0.06), (build_dispenser, "A dispenser.", None)])
def test_a_push_button_rests_out_of_its_body_and_is_pressed_its_whole_travel(tmp_path, build, prompt, travel, refine_once):
    """A click pen's button (its travel 0.06 units into a barrel drawn solid) and a pump dispenser's head rest where
    their springs return them, standing out of the body: closed at the unpressed end, opened by a press. Compactness
    alone closed them pressed in; and from the unpressed end the pen's button met its solid barrel 2 mm into its
    travel (the limit was clipped from 9.3 to 0.19 mm) until the barrel's pieces were cut at the pressed end too, the
    recess a real barrel has."""
    res = refine_once(build(tmp_path / "src"), prompt, extras=False)
    r = res.report
    assert r.failure_mode == "none", (r.failure_mode, r.readiness)
    (joint, end), = r.closed_ends.items() if len(r.closed_ends) == 1 else [(j, e) for j, e in r.closed_ends.items() if j == "joint_0"]
    assert end["q_closed"] == 0.0 and end["direction"] == 1.0, end  # modelled unpressed at 0, pressed toward its upper limit
    assert r.opening_fractions[joint] == pytest.approx(0.0, abs=1e-6)
    if travel is not None:
        assert end["open_range"] == pytest.approx(travel * r.scale, rel=0.05), end  # the whole travel, not clipped


@pytest.mark.parametrize("engine", ["pybullet", "mujoco"])
def test_a_button_that_is_not_the_tasks_part_springs_back_out_when_released(tmp_path, engine, refine_once):
    """A coffee machine's power button, a push button a task does not press (its task part is the lid): pressed all
    the way in and let go, its return spring brings it back out onto its stop within 2 mm (SPEC's undisturbed band),
    in PyBullet and in MuJoCo. Its spring is a push button's: preloaded onto the stop it rests on
    (``spring_holds.closer``). Before, a push button got a return spring only as the task's part, sized to its weight
    against gravity: across a horizontal button that is no spring (6.5e-4 N/m), and the button stayed pressed."""
    from asset2sim.engines.quiet import quiet_stdout
    from asset2sim.engines.source import UrdfFile
    from asset2sim.refined_asset import RefinedAsset

    res = refine_once(build_coffee_machine(tmp_path / "src"), "A coffee machine.", extras=False)
    r = res.report
    assert r.failure_mode == "none", (r.failure_mode, r.readiness)
    end = r.closed_ends["joint_1"]  # the button, pressed toward its upper limit
    asset = RefinedAsset(res.out)
    spring = asset.overlay.joints["joint_1"]
    assert spring.holding.mechanism == "return spring", spring.holding
    assert (spring.spring_reference - end["q_closed"]) * end["direction"] < 0.0  # preloaded: its rest lies beyond the stop
    options = asset.session_options()
    options = type(options)(**{**options.__dict__, "fixed_base": True, "ground": False})
    with quiet_stdout():
        s = UrdfFile(asset.urdf_path).open(engine, options)
    try:
        pressed = end["q_closed"] + end["direction"] * end["open_range"]
        s.set_joint_positions({**asset.initial_state, "joint_1": pressed})
        s.step(int(round(1.0 / s.options.conventions.timestep)))
        assert abs(s.joint_positions()["joint_1"] - end["q_closed"]) <= 2e-3, (pressed, s.joint_positions()["joint_1"])
    finally:
        s.close()


def test_an_ovens_door_asked_open_is_lowered_onto_its_open_stop(tmp_path, refine_once):
    """"An oven with its door open": a lone "open" is ``mostly`` (0.6-0.9 of the range), where a drop-down door's
    weight turns it further open and a 5 degree tilt's landing swung it out of its band (``not_robust_at_rest``: its
    friction held at a hand's cap). A door its own weight carries open is open resting on its open stop, as an oven's
    is opened to load it: the request reads fully open there, says why, and grades that; a side-hinged door asked open
    stays ``mostly`` (``test_request_apply``)."""
    r = refine_once(build_oven(tmp_path / "src"), "An oven with its door open.", extras=False).report
    assert r.failure_mode == "none", (r.failure_mode, r.readiness)
    assert r.requested_bands["joint_0"] == "fully" and r.opening_fractions["joint_0"] > 0.85
    assert any("its weight carries it open" in n for n in r.notes), r.notes


@pytest.mark.physx
def test_a_lighters_lid_a_quarter_open_has_no_penetration_only_physx_read(refine_once):
    """A generated lighter's lid a quarter open (0.475 rad) clears its 4 mm flint wheel (PyBullet and the state search
    read 0 mm), yet PhysX, probed with SAPIEN's default contact offset of 0.01 m, larger than the wheel's collision
    pieces, reported contacts 15 mm deep between the wheel and the lid's 1 mm walls: `unresolved_penetration`. The
    probe now steps with every shape at a 1 mm contact offset (a penetration is found at any offset), restored after
    it: the lid a quarter open reads 0 mm in PhysX too and the lighter is ready."""
    pytest.importorskip("sapien")
    from asset2sim.engines.source import SimObject, UrdfFile

    res = refine_once(build_pocket_lighter, "A lighter, a quarter open.", extras=False)
    assert res.report.failure_mode == "none", res.report.readiness
    obj = SimObject(UrdfFile(res.out_dir / "mobility.urdf"), res.report.initial_joint_positions)
    with obj.open("physx") as s:
        offsets = [sh.get_contact_offset() for comp in s.links.values() for sh in comp.collision_shapes]
        assert s.self_penetration() == (0.0, [])
        assert [sh.get_contact_offset() for comp in s.links.values() for sh in comp.collision_shapes] == offsets
