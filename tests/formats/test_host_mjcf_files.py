"""The object's included file written back for hosts that build their own scene around it: Meta-World's layout
(generated: ``objects/drawer.xml`` including ``objects/assets/drawer.xml``) refined; an environment file as
Meta-World writes them (``sawyer_xyz/sawyer_drawer.xml``, the drawer's file included at another place) compiled
from a copy of the tree with ``mjcf/host/files/objects/assets/drawer.xml`` in place of the package's: the same
names and geometry, the refined masses, damping and friction, and a pull opens the drawer."""

from __future__ import annotations

import math
import shutil
import textwrap
import xml.etree.ElementTree as ET

import pytest

from tests.tasks.ingest import host_layouts as hl

mujoco = pytest.importorskip("mujoco")

from asset2sim.schemas.config import RefineConfig
from asset2sim.formats.mjcf.physics import JOINT_PHYSICS
from asset2sim.urdf import read_urdf

ENVIRONMENT = textwrap.dedent("""
    <mujoco>
      <include file="../objects/assets/drawer_dependencies.xml"/>
      <include file="../scene/basic_scene.xml"/>
      <worldbody>
        <body name="drawer" pos="0 0.9 0">
          <include file="../objects/assets/drawer.xml"/>
        </body>
      </worldbody>
    </mujoco>""")


def _without_physics(path, keep: bool = False):
    """The file's element tree as nested tuples, without ``<inertial>`` elements and the joints' physics
    attributes (``keep``: with them)."""
    physics = set(JOINT_PHYSICS)  # damping, friction loss and its solver parameters, spring, range

    def walk(e):
        attrib = {k: v for k, v in e.attrib.items() if keep or e.tag != "joint" or k not in physics}
        return (e.tag, tuple(sorted(attrib.items())), tuple(walk(c) for c in e if keep or c.tag != "inertial"))

    return walk(ET.parse(path).getroot())


def _environment(tree) -> mujoco.MjModel:
    """The environment file written into ``tree`` (a ``metaworld`` folder), compiled."""
    path = tree / "assets" / "sawyer_xyz" / "sawyer_drawer.xml"
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(ENVIRONMENT)
    return mujoco.MjModel.from_xml_path(str(path))


@pytest.mark.parametrize("joint_name", ["goal_slidey", None], ids=["named", "unnamed"])
def test_a_meta_world_drawer_goes_back_into_an_environment_of_its_package(tmp_path, joint_name, refine_once):
    xml = hl.metaworld_drawer(tmp_path / "in", joint_name=joint_name)
    res = refine_once(xml, "A drawer, slightly open.", RefineConfig(engines=["pybullet"]), extras=False)
    assert res.report.failure_mode == "none", res.report.failure_mode
    fragment = res.out_dir / "mjcf" / "host" / "files" / "objects" / "assets" / "drawer.xml"
    assert fragment.is_file(), res.report.notes
    assert any("; mjcf/host/files/objects/assets/drawer.xml, the package's file" in n for n in res.report.notes)
    assert "+++ objects/assets/drawer.xml" in (res.out_dir / "mjcf" / "host" / "files.diff").read_text()
    original = tmp_path / "in" / "metaworld" / "assets" / "objects" / "assets" / "drawer.xml"
    assert _without_physics(fragment) == _without_physics(original)  # only the physics changed
    assert _without_physics(fragment, keep=True) != _without_physics(original, keep=True)
    package = tmp_path / "in" / "metaworld"
    for name in ("original", "swapped"):
        shutil.copytree(package, tmp_path / name / "metaworld")
    shutil.copyfile(fragment, tmp_path / "swapped" / "metaworld" / "assets" / "objects" / "assets" / "drawer.xml")
    before, after = _environment(tmp_path / "original" / "metaworld"), _environment(tmp_path / "swapped" / "metaworld")

    assert (after.nbody, after.njnt, after.ngeom) == (before.nbody, before.njnt, before.ngeom)
    assert [after.body(i).name for i in range(after.nbody)] == [before.body(i).name for i in range(before.nbody)]
    assert (after.geom_size == before.geom_size).all() and (after.geom_pos == before.geom_pos).all()
    model = read_urdf(res.out_dir / "mobility.urdf")
    for body in ("drawercase_link", "drawer_link"):
        assert after.body(body).mass[0] == pytest.approx(model.links[body].inertial.mass, rel=1e-5), body
    assert after.body("drawer_link").mass[0] != pytest.approx(before.body("drawer_link").mass[0], rel=1e-3)
    (slide,) = model.movable_joints
    j = after.body("drawer_link").jntadr[0]
    dof = after.jnt_dofadr[j]
    assert after.dof_damping[dof] == pytest.approx(slide.dynamics.damping, rel=1e-5)
    assert after.dof_frictionloss[dof] == pytest.approx(slide.dynamics.friction, rel=1e-5)
    assert tuple(after.jnt_range[j]) == pytest.approx((slide.limit.lower, slide.limit.upper), abs=1e-6)

    data = mujoco.MjData(after)
    data.qfrc_applied[dof] = -(slide.dynamics.friction + 5.0)  # a 5 N pull beyond the refined friction, along -y
    for _ in range(400):
        mujoco.mj_step(after, data)
    assert data.qpos[after.jnt_qposadr[j]] < -0.02  # it opens


def test_a_menagerie_model_in_degrees_goes_back_into_its_scene_in_degrees(tmp_path, refine_once):
    """A Menagerie-style ``scene.xml`` including the model file, which states no ``<compiler>`` (degrees): the
    model file written again keeps its ranges in degrees, so the scene compiles the refined quarter turn."""
    door = hl.degree_door(tmp_path / "in" / "mujoco_menagerie" / "door" / "door.xml", ref=10.0)
    scene = door.parent / "scene.xml"
    scene.write_text('<mujoco model="scene"><include file="door.xml"/><worldbody><light pos="0 0 3"/></worldbody></mujoco>')
    res = refine_once(scene, "A door, halfway open.", RefineConfig(engines=["pybullet"]), extras=False)
    assert res.report.failure_mode == "none", res.report.failure_mode
    fragment = res.out_dir / "mjcf" / "host" / "files" / "door" / "door.xml"
    copy = tmp_path / "swapped" / "mujoco_menagerie"
    shutil.copytree(tmp_path / "in" / "mujoco_menagerie", copy)
    shutil.copyfile(fragment, copy / "door" / "door.xml")
    after = mujoco.MjModel.from_xml_path(str(copy / "door" / "scene.xml"))
    model = read_urdf(res.out_dir / "mobility.urdf")
    (hinge,) = model.movable_joints
    j = after.joint("hinge").id
    assert tuple(after.jnt_range[j]) == pytest.approx((hinge.limit.lower, hinge.limit.upper), abs=1e-9)  # 0..90 degrees
    assert after.dof_damping[after.jnt_dofadr[j]] == pytest.approx(hinge.dynamics.damping, rel=1e-9)
    assert after.body("leaf").mass[0] == pytest.approx(model.links["leaf"].inertial.mass, rel=1e-5)
    assert after.qpos0[after.jnt_qposadr[j]] == pytest.approx(math.radians(10.0))  # its ref kept, in degrees


def test_a_meta_world_window_rides_on_its_sash_balance_back_in_its_package(tmp_path, refine_once):
    """Meta-World's vertical window (generated; the frame and the sash unnamed, as Meta-World writes them), asked
    slightly open: the sash gets a balance (a preloaded spring whose reference lies beyond the 0.2 m travel, carrying
    its weight within +-6 %), so the friction that holds it at any height is a few newtons and a hand inside 22.2 N
    works it; the window is interaction-ready. The package's ``objects/assets/window.xml`` is written back with the
    unnamed bodies found by their joints and children: in an environment file of the package, the sash stays where
    the keyframe puts it, and a pull 5 N beyond its friction lifts it."""
    xml = hl.metaworld_window(tmp_path / "in")
    res = refine_once(xml, "A window, slightly open.", RefineConfig(engines=["pybullet"]), extras=False)
    assert res.report.failure_mode == "none", res.report.failure_mode
    assert res.report.metric("operability").passed is True
    model = read_urdf(res.out_dir / "mobility.urdf")
    (slide,) = model.movable_joints
    sash = model.links[slide.child].inertial.mass
    dyn = res.overlay.joints[slide.name]
    lo, hi = hl.METAWORLD_WINDOW_RANGE
    assert dyn.stiffness > 0 and dyn.spring_reference > hi + 5 * (hi - lo)  # a balance, preloaded far beyond the travel
    mid = 0.5 * (lo + hi)
    assert dyn.stiffness * (dyn.spring_reference - mid) == pytest.approx(sash * 9.81, rel=0.02)  # the weight at mid-travel
    assert dyn.friction < 0.3 * sash * 9.81  # friction holds the balance's imbalance, not the sash's weight

    fragment = res.out_dir / "mjcf" / "host" / "files" / "objects" / "assets" / "window.xml"
    assert fragment.is_file(), res.report.notes
    original = tmp_path / "in" / "metaworld" / "assets" / "objects" / "assets" / "window.xml"
    assert _without_physics(fragment) == _without_physics(original)  # only the physics changed
    copy = tmp_path / "swapped" / "metaworld"
    shutil.copytree(tmp_path / "in" / "metaworld", copy)
    shutil.copyfile(fragment, copy / "assets" / "objects" / "assets" / "window.xml")
    env = copy / "assets" / "sawyer_xyz" / "sawyer_window.xml"
    env.parent.mkdir(parents=True)
    env.write_text(ENVIRONMENT.replace("drawer_dependencies", "window_dependencies").replace("assets/drawer.xml", "assets/window.xml"))
    after = mujoco.MjModel.from_xml_path(str(env))
    j = after.joint("window_slide").id
    dof, adr = after.jnt_dofadr[j], after.jnt_qposadr[j]
    assert after.body(after.jnt_bodyid[j]).mass[0] == pytest.approx(sash, rel=1e-5)
    assert after.jnt_stiffness[j] == pytest.approx(dyn.stiffness, rel=1e-6)
    assert after.qpos_spring[adr] == pytest.approx(dyn.spring_reference, rel=1e-6)
    assert after.dof_frictionloss[dof] == pytest.approx(slide.dynamics.friction, rel=1e-5)
    data = mujoco.MjData(after)
    q0 = res.report.initial_joint_positions[slide.name]
    data.qpos[adr] = q0
    for _ in range(800):  # 2 s at MuJoCo's default 2.5 ms
        mujoco.mj_step(after, data)
    assert abs(data.qpos[adr] - q0) < 0.002  # held where it was put
    data.qfrc_applied[dof] = slide.dynamics.friction + 5.0  # a lift 5 N beyond the refined friction
    for _ in range(400):
        mujoco.mj_step(after, data)
    assert data.qpos[adr] > q0 + 0.05  # it rises


def test_slides_easily_keeps_the_sash_balance_that_holds_the_window(tmp_path, refine_once):
    """Meta-World's vertical window (generated, its 0.2 m sash on a vertical slide) asked "open about halfway that
    slides easily": the word is about friction, so the sash keeps its balance (a spring preloaded beyond the travel
    carrying its weight) and the sash stays where it was put (the rest tier holds it); its friction holds the balance's
    imbalance, not the sash's weight."""
    xml = hl.metaworld_window(tmp_path / "in")
    res = refine_once(xml, "A window open about halfway that slides easily.", RefineConfig(engines=["pybullet"]), extras=False)
    model = read_urdf(res.out_dir / "mobility.urdf")
    (slide,) = model.movable_joints
    sash = model.links[slide.child].inertial.mass
    dyn = res.overlay.joints[slide.name]
    lo, hi = hl.METAWORLD_WINDOW_RANGE
    assert dyn.stiffness > 0 and dyn.spring_reference > hi + 5 * (hi - lo), dyn  # the balance kept
    assert dyn.stiffness * (dyn.spring_reference - 0.5 * (lo + hi)) == pytest.approx(sash * 9.81, rel=0.02)
    assert dyn.friction < 0.3 * sash * 9.81  # the balance's imbalance, not the sash's weight
    assert "request 'slides easily'" in dyn.source
    assert res.report.readiness["rest"] is True and res.report.failure_mode != "joint_not_held", res.report.failure_mode
