"""MuJoCo engine and URDF -> MJCF conversion specifics."""

from __future__ import annotations

import os

import numpy as np
import pytest

from asset2sim.engines.base import SessionOptions, Spring
from asset2sim.engines.registry import available_engines, open_session
from asset2sim.engines.loading import BULLET_DEFAULT_MASS, read_urdf
from tests.contract_asset import write_contract_asset
from asset2sim.frames import translation_matrix
from asset2sim.urdf import write_urdf

pytestmark = pytest.mark.mujoco
mujoco = pytest.importorskip("mujoco")

from asset2sim.engines.mjcf import (  # noqa: E402
    FREE_JOINT,
    KEYFRAME,
    contact_policy,
    urdf_to_mjcf,
)
from asset2sim.engines.loading import collision_pieces  # noqa: E402


def _compile(build):
    return mujoco.MjModel.from_xml_string(build.xml, assets=build.assets())


def test_registered():
    assert "mujoco" in available_engines()


def test_conversion_keeps_the_file_values_at_full_precision(tmp_path):
    a = write_contract_asset(tmp_path, lid_angle=0.3, post_height=0.02, base_inertial=False)
    b = urdf_to_mjcf(a.urdf, SessionOptions(initial_state=a.initial_state, springs={"lid_hinge": Spring(0.7, 0.123456789012345)}))
    from lxml import etree

    root = etree.fromstring(b.xml.encode())
    comp = root.find("compiler")
    assert comp.get("inertiafromgeom") == "false" and comp.get("balanceinertia") == "false"
    assert comp.get("fusestatic") == "false"
    hinge = root.find(".//joint[@name='lid_hinge']")
    assert hinge.get("springref") == "0.123456789012345" and hinge.get("stiffness") == "0.7"
    assert hinge.get("damping") == "0.02" and hinge.get("frictionloss") == "0.02"
    assert root.find(".//body[@name='lid']").get("pos") == "0 0.1 0.12"
    assert root.find(".//body[@name='base']/freejoint").get("name") == FREE_JOINT
    assert root.find(".//geom[@name='ground']").get("type") == "plane"
    assert root.find(".//body[@name='base']/inertial") is None  # massless, as in the file
    m = _compile(b)
    assert m.opt.timestep == pytest.approx(1 / 240) and m.opt.gravity == pytest.approx([0, 0, -9.81])
    kid = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_KEY, KEYFRAME)
    assert m.key_qpos[kid] == pytest.approx(b.initial_qpos)
    assert b.joint_names == ["lid_hinge", "post_slide"]
    # the body's bottom is at z = 0 of the root: lifted by nothing
    assert b.root_height == pytest.approx(0.0, abs=1e-12)


def test_multi_group_obj_becomes_pieces_and_single_group_stays_the_file(tmp_path):
    a = write_contract_asset(tmp_path)
    b = urdf_to_mjcf(a.urdf)
    assert sorted(b.derived_meshes) == [f"mjcf/meshes/body__c0_g{g}.obj" for g in range(5)]
    assert sorted(b.mesh_files) == ["textured_objs/lid.obj", "textured_objs/post.obj"]
    m = _compile(b)
    geoms = [mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_GEOM, g) for g in range(m.ngeom)]
    assert sum(1 for g in geoms if g and g.startswith("body__")) == 5


def test_scaled_meshes_keep_their_scale(tmp_path):
    a = write_contract_asset(tmp_path)
    model = read_urdf(a.urdf)
    for g in model.links["post"].visuals + model.links["post"].collisions:
        g.mesh_scale = np.array([0.5, 0.5, 2.0])
    a.urdf.write_bytes(write_urdf(model))
    b = urdf_to_mjcf(a.urdf)
    assert 'scale="0.5 0.5 2.0"' in b.xml
    m = _compile(b)
    d = mujoco.MjData(m)
    mujoco.mj_kinematics(m, d)
    g = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, "post__c0_g0")
    mid = m.geom_dataid[g]
    v = m.mesh_vert[m.mesh_vertadr[mid]: m.mesh_vertadr[mid] + m.mesh_vertnum[mid]]
    ext = v.max(axis=0) - v.min(axis=0)
    assert sorted(ext) == pytest.approx(sorted([0.01, 0.01, 0.2]), abs=1e-6)


def test_missing_inertial_policies(tmp_path):
    a = write_contract_asset(tmp_path, base_inertial=False)
    massless = _compile(urdf_to_mjcf(a.urdf))
    bullet = _compile(urdf_to_mjcf(a.urdf, missing_inertial="bullet"))
    bid = mujoco.mj_name2id(massless, mujoco.mjtObj.mjOBJ_BODY, "base")
    assert massless.body_mass[bid] == 0.0
    assert bullet.body_mass[bid] == BULLET_DEFAULT_MASS
    with pytest.raises(ValueError, match="missing_inertial"):
        urdf_to_mjcf(a.urdf, missing_inertial="guess")
    with pytest.raises(ValueError, match="not movable joints"):
        urdf_to_mjcf(a.urdf, SessionOptions(initial_state={"no_such_joint": 0.1}))


def test_contact_policy_matches_pybullet_pairs(tmp_path):
    a = write_contract_asset(tmp_path)
    model = read_urdf(a.urdf)
    pieces, _ = collision_pieces(model)
    # base has no shapes here: nothing to restore; body/lid and body/post are parent-child
    assert contact_policy(model, pieces, free=True) == ([], [])
    # fixed to the world, body is welded to the world and MuJoCo's parent filter
    # no longer applies to it: its children must be excluded explicitly
    assert contact_policy(model, pieces, free=False) == ([], [("body", "lid"), ("body", "post")])
    pieces["base"] = pieces["body"][:1]  # a shape on the root: base/lid and base/post are PyBullet pairs
    restore, exclude = contact_policy(model, pieces, free=True)
    assert restore == [("base", "lid"), ("base", "post")] and exclude == []


def test_session_masses_and_no_mujoco_log_file(tmp_path, monkeypatch):
    """MuJoCo's default warning handler appends to MUJOCO_LOG.TXT in the
    working directory; the engine collects the warnings instead."""
    a = write_contract_asset(tmp_path / "asset")
    obj = a.root / "textured_objs" / "lid.obj"
    text = obj.read_text().replace("f 1 2 4", "vt 0 0\nf 1/1 2 4", 1)  # a face with partial texture coordinates
    obj.write_text(text)
    work = tmp_path / "cwd"
    work.mkdir()
    monkeypatch.chdir(work)
    s = open_session("mujoco", a.urdf, SessionOptions(initial_state=a.initial_state))
    try:
        model = read_urdf(a.urdf)
        for name, link in model.links.items():
            bid = mujoco.mj_name2id(s.m, mujoco.mjtObj.mjOBJ_BODY, name)
            assert s.m.body_mass[bid] == pytest.approx(link.inertial.mass, rel=1e-12)
    finally:
        s.close()
    assert not (work / "MUJOCO_LOG.TXT").exists()
    assert os.listdir(work) == []


def _lid_after(build, seconds: float, solref=None, solimp=None, options: str = "") -> float:
    """The lid's angle (rad) after ``seconds`` of the build's model, its friction solver parameters optionally set
    back (``solref`` / ``solimp``) or its ``<option>`` replaced by ``options`` (a host scene's)."""
    xml = build.xml
    if options:
        import re

        xml = re.sub(r"<option[^>]*/>", options, xml, count=1)
    m = mujoco.MjModel.from_xml_string(xml, assets=build.assets())
    if solref is not None:
        m.dof_solref[:] = solref
        m.dof_solimp[:] = solimp
    d = mujoco.MjData(m)
    mujoco.mj_resetDataKeyframe(m, d, 0)
    for _ in range(round(seconds / m.opt.timestep)):
        mujoco.mj_step(m, d)
    jid = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, "lid_hinge")
    return float(d.qpos[m.jnt_qposadr[jid]])


def test_frictionloss_holds_without_the_noslip_pass(tmp_path):
    """MuJoCo's soft friction lets a held lid creep; the MJCF holds it with no no-slip pass (MJX has none) through the
    friction solver aid its creep criterion asks for, and with MuJoCo's defaults the same lid creeps past its rest band
    (0.1 rad: 5 % of its 2 rad range), so the aid is what holds it."""
    from asset2sim.engines.mjcf import ARMATURE, FRICTION_SOLIMP, friction_solref

    a = write_contract_asset(tmp_path, lid_angle=0.6, lid_friction=0.5, lid_damping=0.0)
    b = urdf_to_mjcf(a.urdf, SessionOptions(initial_state=a.initial_state))
    m = _compile(b)
    dof = m.jnt_dofadr[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, "lid_hinge")]
    assert m.opt.noslip_iterations == 0 and m.opt.cone == mujoco.mjtCone.mjCONE_PYRAMIDAL
    assert np.allclose(m.dof_solref[dof], friction_solref(1 / 240)) and np.allclose(m.dof_solimp[dof], FRICTION_SOLIMP)
    assert ("friction_solver", "lid_hinge") in {(x.kind, x.element) for x in b.aids}
    assert np.all(m.dof_armature == ARMATURE)
    assert _lid_after(b, 3.0) == pytest.approx(0.6, abs=1e-3)
    assert abs(_lid_after(b, 3.0, (0.02, 1.0), (0.9, 0.95, 0.001, 0.5, 2.0)) - 0.6) > 0.1
    s = open_session("mujoco", a.urdf, SessionOptions(initial_state=a.initial_state))
    try:
        assert s.m.opt.noslip_iterations == 0  # the checks run MuJoCo as the file does
        s.step(720)
        assert s.joint_positions()["lid_hinge"] == pytest.approx(0.6, abs=1e-3)
    finally:
        s.close()


def test_armature_only_on_a_light_part_held_by_the_stiff_friction_and_contacts_at_mujocos_defaults(tmp_path):
    """The box's 0.2 kg lid gets no armature; a 2 g lid on the same 1.5 kg body, held by the stiff friction aid, is
    lighter than the float32 floor and is lifted to it, named with its criterion and its effect; a frictionless 2 g lid
    gets neither. The object's own contacts keep MuJoCo's default impedance; the ground carries the ground aid."""
    from asset2sim.engines.mjcf import ARMATURE, ARMATURE_FLOOR
    from asset2sim.engines.mjcf.aids import DEFAULT_SOLIMP, GROUND_SOLIMP

    b = urdf_to_mjcf(write_contract_asset(tmp_path / "heavy").urdf)
    m = _compile(b)
    assert np.all(m.dof_armature == ARMATURE) and "armature" not in {x.kind for x in b.aids}
    colliding = (m.geom_contype > 0) | (m.geom_conaffinity > 0)
    ground = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, "ground")
    colliding[ground] = False
    assert colliding.any() and np.allclose(m.geom_solimp[colliding], DEFAULT_SOLIMP)
    assert np.allclose(m.geom_solimp[ground], GROUND_SOLIMP) and ("ground_contact_impedance", "ground") in {(x.kind, x.element) for x in b.aids}
    b = urdf_to_mjcf(write_contract_asset(tmp_path / "light", lid_mass=0.002, lid_friction=0.01).urdf)
    m = _compile(b)
    dof = m.jnt_dofadr[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, "lid_hinge")]
    assert m.dof_armature[dof] > 0
    assert 1.0 / m.dof_invweight0[dof] == pytest.approx(ARMATURE_FLOOR * m.stat.meaninertia, rel=0.05)
    arm = next(x for x in b.aids if x.kind == "armature")
    assert arm.element == "lid_hinge" and arm.measure > 1 and "natural frequency" in arm.effect
    b = urdf_to_mjcf(write_contract_asset(tmp_path / "free", lid_mass=0.002, lid_friction=0.0).urdf)
    assert not {("armature", "lid_hinge"), ("friction_solver", "lid_hinge")} & {(x.kind, x.element) for x in b.aids}


def _joint_aids(build) -> list[tuple]:
    """(kind, element, written) of every aid of ``build`` but the ground's (a session without a ground has none)."""
    return sorted((a.kind, a.element, tuple(sorted(a.written.items()))) for a in build.aids if a.kind != "ground_contact_impedance")


def test_a_session_that_holds_a_free_objects_root_carries_the_files_solver_aids(tmp_path):
    """One reading of an object: the 2 g lid of a free-standing box gets armature in the file (judged with the free
    root, the model's mean inertia the whole box's). A session that fixes the root (a hand holds the box), with gravity
    on or off, judges its aids on the object as declared and carries the same ones; judged on its own fixed-root model
    (no declared root given) the lid gets none. A mounted object opened free keeps the mounted file's aids."""
    a = write_contract_asset(tmp_path / "light", lid_mass=0.002, lid_friction=0.01)
    file_aids = _joint_aids(urdf_to_mjcf(a.urdf))
    assert ("armature", "lid_hinge") in {(k, e) for k, e, _ in file_aids}
    for gravity in (True, False):
        held = urdf_to_mjcf(a.urdf, SessionOptions(fixed_base=True, ground=False, gravity=gravity, object_root_fixed=False))
        assert _joint_aids(held) == file_aids
        m = _compile(held)
        assert m.njnt == 2 and m.dof_armature[m.jnt_dofadr[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, "lid_hinge")]] > 0
    mounted = _joint_aids(urdf_to_mjcf(a.urdf, SessionOptions(fixed_base=True, ground=False)))  # judged on its own root
    assert "armature" not in {k for k, _, _ in mounted}
    opened_free = urdf_to_mjcf(a.urdf, SessionOptions(object_root_fixed=True))
    assert _joint_aids(opened_free) == mounted and _compile(opened_free).njnt == 3


def test_the_joints_hold_in_a_host_scene_with_its_own_options_and_defaults(tmp_path):
    """A host scene that includes the object brings its own ``<option>`` (elliptic cones, a 2 ms step) and
    ``<default>`` joint (MuJoCo's own friction solver parameters, under which this lid creeps 0.2 rad in 3 s): the
    parameters written on each joint win, and the lid stays where its friction holds it."""
    a = write_contract_asset(tmp_path, lid_angle=0.6, lid_friction=0.5, lid_damping=0.0)
    b = urdf_to_mjcf(a.urdf, SessionOptions(initial_state=a.initial_state))
    b.xml = b.xml.replace('<joint armature="0"/>', '<joint solreffriction="0.02 1" solimpfriction="0.9 0.95 0.001 0.5 2"/>')
    host = '<option timestep="0.002" gravity="0 0 -9.81" cone="elliptic" impratio="10"/>'
    assert _lid_after(b, 3.0, options=host) == pytest.approx(0.6, abs=1e-3)


def test_keyframe_places_the_object_on_the_ground(tmp_path):
    """Open the lid past vertical so nothing changes at the bottom, then sink
    the body's collision 3 cm below the root frame: the root is lifted 3 cm."""
    a = write_contract_asset(tmp_path, lid_angle=1.9)
    model = read_urdf(a.urdf)
    model.links["body"].collisions[0].origin = translation_matrix([0.0, 0.0, -0.03])
    a.urdf.write_bytes(write_urdf(model))
    b = urdf_to_mjcf(a.urdf, SessionOptions(initial_state=a.initial_state))
    assert b.root_height == pytest.approx(0.03, abs=1e-9)
    assert b.initial_qpos[:3] == pytest.approx([0, 0, 0.03])
    assert b.initial_qpos[7] == pytest.approx(1.9)
    m = _compile(b)
    d = mujoco.MjData(m)
    mujoco.mj_resetDataKeyframe(m, d, 0)
    mujoco.mj_forward(m, d)
    assert all(d.contact[i].dist > -1e-9 for i in range(d.ncon))
    assert np.isfinite(d.qacc).all()


def _body_contacts(xml: str, build, lid: float, filterparent: bool) -> int:
    """Contacts between the body and the lid with the lid turned ``lid`` rad (into the body below 0)."""
    import re

    if not filterparent:
        xml = re.sub(r"<option([^>]*)/>", r'<option\1><flag filterparent="disable"/></option>', xml, count=1)
    m = mujoco.MjModel.from_xml_string(xml, assets=build.assets())
    d = mujoco.MjData(m)
    mujoco.mj_resetDataKeyframe(m, d, 0)
    jid = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, "lid_hinge")
    d.qpos[m.jnt_qposadr[jid]] = lid
    mujoco.mj_forward(m, d)
    names = {mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, n) for n in ("body", "lid")}
    return sum({int(m.geom_bodyid[c.geom1]), int(m.geom_bodyid[c.geom2])} == names for c in d.contact[:d.ncon])


def test_parent_child_exclusion_travels_with_the_file(tmp_path):
    """The lid turned 0.2 rad into its parent's walls: MuJoCo's parent filter drops the pair; a host scene that turns
    it off (``filterparent="disable"``) still collides nothing there, because the MJCF names the pair in an
    ``<exclude>``; without those, the same scene collides the lid with its parent."""
    import re

    a = write_contract_asset(tmp_path)
    b = urdf_to_mjcf(a.urdf, SessionOptions(initial_state=a.initial_state))
    assert '<exclude body1="body" body2="lid"/>' in b.xml and '<exclude body1="body" body2="post"/>' in b.xml
    assert _body_contacts(b.xml, b, -0.2, filterparent=True) == 0
    assert _body_contacts(b.xml, b, -0.2, filterparent=False) == 0
    bare = re.sub(r"<exclude [^>]*/>", "", b.xml)
    assert _body_contacts(bare, b, -0.2, filterparent=False) > 0


def _post_and_door(folder):
    """A URDF of a frame with a cylindrical post (radius 0.03 m, 0.6 m long), a box door on a hinge beside it and a box
    handle fixed to the door (the post and the handle are not parent and child: MuJoCo collides them)."""
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / "mobility.urdf"
    path.write_text("""<?xml version="1.0"?>
<robot name="post_and_door">
  <link name="frame">
    <inertial><mass value="5.0"/><inertia ixx="0.15" iyy="0.15" izz="0.01" ixy="0" ixz="0" iyz="0"/></inertial>
    <collision><origin xyz="0 0 0.3"/><geometry><cylinder radius="0.03" length="0.6"/></geometry></collision>
  </link>
  <link name="door">
    <inertial><origin xyz="0.25 0 0.3"/><mass value="2.0"/>
      <inertia ixx="0.06" iyy="0.1" izz="0.04" ixy="0" ixz="0" iyz="0"/></inertial>
    <collision><origin xyz="0.25 0 0.3"/><geometry><box size="0.4 0.02 0.5"/></geometry></collision>
  </link>
  <link name="handle">
    <inertial><origin xyz="0.35 -0.05 0.3"/><mass value="0.1"/>
      <inertia ixx="1e-4" iyy="1e-4" izz="1e-4" ixy="0" ixz="0" iyz="0"/></inertial>
    <collision><origin xyz="0.35 -0.05 0.3"/><geometry><box size="0.02 0.06 0.1"/></geometry></collision>
  </link>
  <joint name="hinge" type="revolute"><parent link="frame"/><child link="door"/><origin xyz="0.05 0 0"/>
    <axis xyz="0 0 1"/><limit lower="0" upper="1.5" effort="10" velocity="1"/><dynamics damping="0.5" friction="0.3"/></joint>
  <joint name="handle_fixed" type="fixed"><parent link="door"/><child link="handle"/></joint>
</robot>
""")
    return path


def test_a_collision_cylinder_becomes_a_prism_that_holds_it(tmp_path):
    """MJX collides a cylinder with neither a box nor a mesh: the MJCF writes the post as a 20-sided convex prism whose
    faces touch the cylinder (radius 0.03 m, half-length 0.3 m), named in the notes; it compiles and stands where the
    cylinder stood."""
    from asset2sim.engines.mjcf.rewrite import CYLINDER_SIDES

    b = urdf_to_mjcf(_post_and_door(tmp_path / "in"), SessionOptions(fixed_base=True))
    assert 'type="cylinder"' not in b.xml
    assert any("frame__c0_g0" in n and "prism" in n for n in b.notes), b.notes
    m = _compile(b)
    g = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, "frame__c0_g0")
    assert m.geom_type[g] == mujoco.mjtGeom.mjGEOM_MESH
    mesh = int(m.geom_dataid[g])
    v = m.mesh_vert[m.mesh_vertadr[mesh]:m.mesh_vertadr[mesh] + m.mesh_vertnum[mesh]]
    assert len(v) == 2 * CYLINDER_SIDES
    radial = np.linalg.norm(v[:, :2], axis=1)  # in the mesh's frame (MuJoCo centres it; the axis stays z)
    assert radial.min() == pytest.approx(0.03 / np.cos(np.pi / CYLINDER_SIDES), rel=1e-6)
    assert np.ptp(v[:, 2]) == pytest.approx(0.6, rel=1e-6)
    d = mujoco.MjData(m)
    mujoco.mj_forward(m, d)
    assert d.geom_xpos[g][2] == pytest.approx(0.3, abs=1e-6)
