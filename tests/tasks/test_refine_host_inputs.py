"""Third-party MJCF objects refined as their packages mean them: a robosuite fragment (radians from robosuite's
world), a Meta-World scene (a drawer on a table inside a wall), a degree-range door: interaction-ready at their own
size, their names and ranges in the host's unit; the audit agrees with refine on the size; a range in the wrong
unit is refused."""

from __future__ import annotations

import html
import json
import math
import shutil

import pytest

from tests.tasks.ingest import host_layouts as hl

mujoco = pytest.importorskip("mujoco")

from asset2sim.schemas.config import RefineConfig  # noqa: E402
from asset2sim.schemas.request import RequestOverrides  # noqa: E402
from asset2sim.apps.audit.audit import audit_asset  # noqa: E402
from asset2sim.tasks.refine import RefineError, refine_asset  # noqa: E402
from asset2sim.urdf import read_urdf  # noqa: E402
from asset2sim.commands.refine import summary_lines  # noqa: E402
from asset2sim.tasks.evaluation.report_html import host_section  # noqa: E402

CONFIG = RefineConfig(engines=["pybullet"])


def _out(res):
    model = read_urdf(res.out_dir / "mobility.urdf")
    overlay = json.loads((res.out_dir / "overlay.json").read_text())
    return model, overlay


def _joint(model, name):
    return next(j for j in model.joints if j.name == name)


def _names(m):
    kinds = ((mujoco.mjtObj.mjOBJ_BODY, m.nbody), (mujoco.mjtObj.mjOBJ_JOINT, m.njnt), (mujoco.mjtObj.mjOBJ_GEOM, m.ngeom),
             (mujoco.mjtObj.mjOBJ_SITE, m.nsite))
    return [sorted(x for i in range(n) if (x := mujoco.mj_id2name(m, obj, i))) for obj, n in kinds]


def _swapped_in(res, xml, tmp_path):
    """The host package's tree copied, the refined host file in place of ``xml``: (original model, swapped model)."""
    root = xml.parents[len(xml.relative_to(tmp_path / "in").parts) - 1]
    copy = tmp_path / "host_copy"
    shutil.copytree(root, copy / root.name)
    target = copy / xml.relative_to(root.parent)
    host = res.out_dir / "mjcf" / "host" / f"{xml.stem}.xml"
    assert (res.out_dir / "mjcf" / "host" / f"{xml.stem}.diff").read_text().startswith("---")
    shutil.copyfile(host, target)
    return mujoco.MjModel.from_xml_path(str(xml)), mujoco.MjModel.from_xml_path(str(target))


def _check_swapped(res, before, after, joint, jid=None):
    """Same names; the refined masses, range and damping; the keyframe 'initial' at the refined state; it steps
    (``jid``: the joint's id when it has no name in the file)."""
    assert _names(after) == _names(before)
    model, _ = _out(res)
    for name, link in model.links.items():
        b = mujoco.mj_name2id(after, mujoco.mjtObj.mjOBJ_BODY, name)
        if b > 0 and link.inertial is not None and before.body_geomnum[b] > 0:
            assert after.body_mass[b] == pytest.approx(link.inertial.mass, rel=1e-5)
    j = mujoco.mj_name2id(after, mujoco.mjtObj.mjOBJ_JOINT, joint) if jid is None else jid
    urdf = _joint(model, joint)
    assert after.jnt_range[j] == pytest.approx([urdf.limit.lower, urdf.limit.upper], abs=1e-5)
    assert after.dof_damping[after.jnt_dofadr[j]] == pytest.approx(urdf.dynamics.damping, rel=1e-5)
    data = mujoco.MjData(after)
    mujoco.mj_resetDataKeyframe(after, data, mujoco.mj_name2id(after, mujoco.mjtObj.mjOBJ_KEY, "initial"))
    assert data.qpos[after.jnt_qposadr[j]] == pytest.approx(res.report.initial_joint_positions[joint], abs=1e-5)
    for _ in range(200):
        mujoco.mj_step(after, data)
    assert abs(data.qpos[after.jnt_qposadr[j]] - res.report.initial_joint_positions[joint]) < 0.02


def test_a_robosuite_door_is_refined_at_its_size_with_its_range_in_radians(tmp_path):
    xml = hl.robosuite_door(tmp_path / "in" / "robosuite" / "models" / "assets" / "objects" / "door.xml")
    before = xml.read_bytes()
    res = refine_asset(xml, "A door, slightly open.", tmp_path / "out", CONFIG, extras=False)
    assert res.report.failure_mode == "none", res.report.failure_mode
    model, overlay = _out(res)
    assert overlay["scale"] == 1.0 and "size kept" in overlay["notes"]["size"]
    hinge = _joint(model, "door_hinge")
    assert hinge.limit.upper == pytest.approx(0.4)
    assert 0.0 < res.report.initial_joint_positions["door_hinge"] < 0.4 * 0.5
    assert {"door_body", "frame", "door", "latch"} <= set(model.links)
    assert any("robosuite" in n and "radians" in n for n in res.report.notes)
    assert xml.read_bytes() == before
    before_model, after_model = _swapped_in(res, xml, tmp_path)
    _check_swapped(res, before_model, after_model, "door_hinge")
    assert after_model.jnt_range[0][1] == pytest.approx(0.4)  # radians, as robosuite compiles it
    assert any(n.startswith("host MJCF: mjcf/host/door.xml") for n in res.report.notes)
    # robosuite's Door environment sets the hinge's friction and damping when it builds the task: the notes say so,
    # with the refined values and the DoorObject call that keeps them
    friction, damping = hinge.dynamics.friction, hinge.dynamics.damping
    (override,) = [n for n in res.report.notes if "DoorObject" in n]
    assert "friction=0.0, damping=0.1" in override and f"frictionloss {friction:.6g} with 0" in override
    assert f'DoorObject(name="Door", friction={friction:.6g}, damping={damping:.6g}, lock=...)' in override
    # the package's file holds the refined friction without the no-slip pass, at robosuite's 2 ms step
    j = after_model.joint("door_hinge").id
    assert after_model.dof_solref[after_model.jnt_dofadr[j]] == pytest.approx((2 * after_model.opt.timestep, 1.0))
    assert after_model.dof_solimp[after_model.jnt_dofadr[j]][:2] == pytest.approx((0.9999, 0.9999))
    audit = audit_asset(xml, simulate=False).report
    scale = audit.values[0]
    assert scale.quantity == "scale" and scale.verdict == "plausible" and scale.declared == pytest.approx(0.6, rel=0.05)


def test_a_robosuite_door_read_in_degrees_is_refused_by_name(tmp_path):
    xml = hl.robosuite_door(tmp_path / "robosuite" / "models" / "assets" / "objects" / "door.xml")
    config = CONFIG.model_copy(update={"mjcf": CONFIG.mjcf.model_copy(update={"angle": "degree"})})
    with pytest.raises(RefineError, match="door_hinge.*0.4 degrees") as err:
        refine_asset(xml, "A door, slightly open.", tmp_path / "out", config, extras=False)
    assert err.value.failure_mode == "invalid_input" and err.value.codes == ["JOINT_RANGE_WRONG_UNIT"]
    assert not (tmp_path / "out" / "mobility.urdf").exists()
    audit = audit_asset(xml, simulate=False, config=config).report
    assert any(n.startswith("WARNING: ") and "JOINT_RANGE_WRONG_UNIT" in n for n in audit.notes)
    limits = next(v for v in audit.values if v.where == "joint door_hinge" and v.quantity == "limits")
    assert limits.verdict == "implausible" and "less than a degree" in limits.reason
    radians = audit_asset(xml, simulate=False).report  # as robosuite compiles it: 0.4 rad, plausible
    assert next(v for v in radians.values if v.where == "joint door_hinge" and v.quantity == "limits").verdict == "plausible"


def test_a_meta_world_drawer_is_refined_out_of_its_scene(tmp_path):
    xml = hl.metaworld_drawer(tmp_path / "in")
    res = refine_asset(xml, "A drawer, slightly open.", tmp_path / "out", CONFIG, extras=False)
    assert res.report.failure_mode == "none", res.report.failure_mode
    model, overlay = _out(res)
    assert overlay["scale"] == 1.0
    assert set(model.links) == {"body_3", "drawercase_link", "drawer_link"}
    slide = _joint(model, "goal_slidey")
    assert (slide.limit.lower, slide.limit.upper) == pytest.approx(hl.METAWORLD_DRAWER_RANGE)
    assert hl.METAWORLD_DRAWER_RANGE[0] < res.report.initial_joint_positions["goal_slidey"] < 0.0
    assert any("'tablelink'" in n and "not refined" in n for n in res.report.notes)
    before_model, after_model = _swapped_in(res, xml, tmp_path)  # the scene's includes inlined, the table kept
    _check_swapped(res, before_model, after_model, "goal_slidey")


def test_a_degree_range_door_keeps_its_size_and_its_quarter_turn(tmp_path):
    xml = hl.degree_door(tmp_path / "in" / "dm_control" / "suite" / "door.xml", ref=10.0)
    res = refine_asset(xml, "A door, halfway open.", tmp_path / "out", CONFIG, extras=False)
    assert res.report.failure_mode == "none", res.report.failure_mode
    model, overlay = _out(res)
    assert overlay["scale"] == 1.0
    assert _joint(model, "hinge").limit.upper == pytest.approx(math.pi / 2)
    before_model, after_model = _swapped_in(res, xml, tmp_path)  # written in radians, stated by its <compiler>
    _check_swapped(res, before_model, after_model, "hinge")  # drawn at ref 10 degrees: values read the same
    assert after_model.jnt_range[0][1] == pytest.approx(math.pi / 2, abs=1e-5)  # MuJoCo writes 6 significant digits
    scaled = refine_asset(xml, "A door, halfway open.", tmp_path / "scaled",
                          CONFIG.model_copy(update={"overrides": RequestOverrides(scale=0.5)}), extras=False)
    assert _out(scaled)[1]["scale"] == 0.5
    assert any(n.startswith("host MJCF not written: ") and "rescaled" in n for n in scaled.report.notes)
    assert not (scaled.out_dir / "mjcf" / "host").exists()


def test_a_urdf_with_inertials_keeps_its_size_and_a_partnet_mobility_model_is_sized(tmp_path):
    from asset2sim.formats.mjcf.reader import read_mjcf_asset
    from asset2sim.formats.staging import stage

    xml = hl.robosuite_door(tmp_path / "robosuite" / "models" / "assets" / "objects" / "door.xml")
    urdf = stage(read_mjcf_asset(xml), tmp_path / "door_urdf").urdf_path  # model.urdf with the door's inertials
    kept = refine_asset(urdf.parent, "A door, slightly open.", tmp_path / "kept", CONFIG, extras=False)
    size = _out(kept)[1]["notes"]["size"]
    assert _out(kept)[1]["scale"] == 1.0 and "a URDF declaring inertials" in size
    urdf.rename(urdf.parent / "mobility.urdf")  # PartNet-Mobility's name: a normalized size, sized to the category
    sized = refine_asset(urdf.parent, "A door, slightly open.", tmp_path / "sized", CONFIG, extras=False)
    assert _out(sized)[1]["scale"] > 2.0


def test_an_unnamed_joint_is_refined_and_written_back_in_its_place(tmp_path):
    """Meta-World leaves some joints unnamed (the doorlock's lock): the link's joint is ``<body>_joint`` and the host
    file changes that joint, still unnamed."""
    xml = hl.metaworld_drawer(tmp_path / "in", joint_name=None)
    res = refine_asset(xml, "A drawer, slightly open.", tmp_path / "out", CONFIG, extras=False)
    assert res.report.failure_mode == "none", res.report.failure_mode
    assert "drawer_link_joint" in res.report.initial_joint_positions
    before_model, after_model = _swapped_in(res, xml, tmp_path)
    assert after_model.njnt == 1 and not mujoco.mj_id2name(after_model, mujoco.mjtObj.mjOBJ_JOINT, 0)
    _check_swapped(res, before_model, after_model, "drawer_link_joint", jid=0)



def _door_notes(res) -> tuple[str, str]:
    """(the written-back file's note, the DoorObject call's note) of a refined robosuite door."""
    (written,) = [n for n in res.report.notes if n.startswith("host MJCF: mjcf/host/door.xml")]
    (call,) = [n for n in res.report.notes if "DoorObject" in n]
    return written, call


def test_the_way_back_into_robosuite_is_on_the_terminal(tmp_path, refine_once):
    """A robosuite door refined: the terminal's summary says which file to copy back into the package and the
    DoorObject(friction=..., damping=...) call robosuite's Door task needs to keep the refined values (report.json's
    notes, no longer only there)."""
    xml = hl.robosuite_door(tmp_path / "in" / "robosuite" / "models" / "assets" / "objects" / "door.xml")
    res = refine_once(xml, "A door, slightly open.", CONFIG, extras=False)
    written, call = _door_notes(res)
    host = [ln.removeprefix("host         ") for ln in summary_lines(res.result) if ln.startswith("host ")]
    assert written in host and call in host, host
    html = host_section(json.loads((res.out_dir / "report.json").read_text()))
    assert "Back into its package" in html and "DoorObject(name=&quot;Door&quot;, friction=" in html, html


@pytest.mark.slow  # end to end: a refine with its media (report.html)
def test_report_html_says_the_way_back_into_robosuite(tmp_path, refine_once):
    xml = hl.robosuite_door(tmp_path / "in" / "robosuite" / "models" / "assets" / "objects" / "door.xml")
    res = refine_once(xml, "A door, slightly open.", CONFIG.model_copy(update={"clips": False}), extras=True)
    _, call = _door_notes(res)
    text = (res.out_dir / "report.html").read_text()
    assert "<h2>Back into its package</h2>" in text and html.escape(call, quote=True) in text
