"""The articulated object inside an MJCF scene: the subtree that carries the joints; static bodies around it
(a table, a wall) are noted and left out; ``--body`` picks one of several."""

from __future__ import annotations

import textwrap

import pytest

from tests.tasks.ingest import host_layouts as hl

pytest.importorskip("mujoco")

from asset2sim.tasks.ingest.errors import AssetError  # noqa: E402
from asset2sim.tasks.ingest.extract import extract_asset_checked  # noqa: E402
from asset2sim.formats.mjcf.conventions import ReadOptions  # noqa: E402
from asset2sim.formats.mjcf.reader import read_mjcf_asset  # noqa: E402
from asset2sim.formats.staging import StagingError  # noqa: E402


def test_a_meta_world_scene_reads_the_drawer_and_leaves_the_table_and_wall(tmp_path):
    xml = hl.metaworld_drawer(tmp_path)
    read = read_mjcf_asset(xml)
    assert read.model.root == "body_3"
    assert set(read.model.links) == {"body_3", "drawercase_link", "drawer_link"}
    slide = next(j for j in read.model.joints if j.name == "goal_slidey")
    assert (slide.type, slide.limit.lower, slide.limit.upper) == ("prismatic", *hl.METAWORLD_DRAWER_RANGE)
    static = next(n for n in read.notes if n.startswith("static bodies"))
    assert "'tablelink'" in static and "'RetainingWall'" in static and "mounted on" in static
    assert read.root_fixed is True
    desc, _ = extract_asset_checked(xml)
    assert {ln.name for ln in desc.links} == {"body_3", "drawercase_link", "drawer_link"}


def _two_objects(tmp_path):
    xml = tmp_path / "two.xml"
    xml.write_text(textwrap.dedent("""
        <mujoco model="two">
          <worldbody>
            <body name="table"><geom type="box" size="0.5 0.5 0.02" pos="0 0 -0.02"/></body>
            <body name="cabinet" pos="0 0 0.3">
              <geom type="box" size="0.2 0.2 0.3"/>
              <body name="cabinet_door" pos="0.2 -0.21 0">
                <joint name="door_hinge" type="hinge" axis="0 0 1" range="0 90"/>
                <geom type="box" size="0.2 0.01 0.3" pos="-0.2 0 0"/>
              </body>
            </body>
            <body name="box" pos="1 0 0.1">
              <geom type="box" size="0.1 0.1 0.1"/>
              <body name="lid" pos="0 0.1 0.1">
                <joint name="lid_hinge" type="hinge" axis="1 0 0" range="0 100"/>
                <geom type="box" size="0.1 0.1 0.005" pos="0 -0.1 0.005"/>
              </body>
            </body>
          </worldbody>
        </mujoco>""").lstrip())
    return xml


def test_several_jointed_objects_need_a_body_and_the_error_lists_them(tmp_path):
    xml = _two_objects(tmp_path)
    with pytest.raises(StagingError, match=r"2 bodies under the world body carry hinge or slide joints \['cabinet', 'box'\]") as err:
        read_mjcf_asset(xml)
    assert "--body" in str(err.value) and str(xml) in str(err.value)
    with pytest.raises(AssetError, match="--body"):
        extract_asset_checked(xml)
    box = read_mjcf_asset(xml, ReadOptions(body="box"))
    assert set(box.model.links) == {"box", "lid"}
    assert any("'table'" in n and "static" in n for n in box.notes)
    assert any("'cabinet'" in n and "left out" in n for n in box.notes)
    by_part = read_mjcf_asset(xml, ReadOptions(body="cabinet_door"))  # a body inside an object picks that object
    assert set(by_part.model.links) == {"cabinet", "cabinet_door"}
    desc, _ = extract_asset_checked(xml, reading=ReadOptions(body="cabinet"))
    assert [j.name for j in desc.joints if j.type != "fixed"] == ["door_hinge"]


def test_a_body_that_is_not_there_is_refused_with_the_candidates(tmp_path):
    xml = _two_objects(tmp_path)
    with pytest.raises(StagingError, match=r"no body named 'drawer'; the objects under the world body: \['cabinet', 'box'\]"):
        read_mjcf_asset(xml, ReadOptions(body="drawer"))


def _unnamed_sash(tmp_path):
    """Meta-World's window in small: the sash is an unnamed body whose slide is named ``window_slide``."""
    xml = tmp_path / "window.xml"
    xml.write_text(textwrap.dedent("""
        <mujoco model="window">
          <worldbody>
            <body>
              <geom type="box" size="0.2 0.03 0.01" pos="0 0 0.01"/>
              <geom type="box" size="0.015 0.03 0.2" pos="0.18 0 0.2"/>
              <geom type="box" size="0.015 0.03 0.2" pos="-0.18 0 0.2"/>
              <body pos="0 -0.05 0.05">
                <joint type="slide" axis="1 0 0" range="0 0.15" name="window_slide"/>
                <geom type="box" size="0.1 0.01 0.1" pos="0 0 0.1"/>
              </body>
            </body>
          </worldbody>
        </mujoco>""").lstrip())
    return xml


def test_a_moving_body_without_a_name_is_labelled_by_its_joints_name(tmp_path):
    from asset2sim.tasks.interpret.part_labels import labels_from_names

    desc, _ = extract_asset_checked(_unnamed_sash(tmp_path))
    labelled = labels_from_names(desc)
    assert {ln.name: ln.semantic_label for ln in labelled.links} == {"body_1": "body", "body_2": "window"}
    assert any("body_2 -> window (its joint's name)" in n for n in labelled.staging_notes)
    door, _ = extract_asset_checked(hl.degree_door(tmp_path / "door" / "door.xml"))  # 'hinge' names the mechanism
    assert "leaf" not in {ln.name for ln in labels_from_names(door).links if ln.semantic_label}


def test_an_mjcf_root_without_a_free_joint_is_refined_mounted_as_the_file_says(tmp_path, refine_once):
    """A lever's category prior is free-standing; MuJoCo welds a root without a free joint, so refine does too
    (the request's words and --mount still win)."""
    from asset2sim.schemas.config import RefineConfig

    (tmp_path / "in").mkdir()
    xml = _unnamed_sash(tmp_path / "in")
    config = RefineConfig(engines=["pybullet"])
    res = refine_once(xml, "A window, slightly open.", config, extras=False)
    assert res.overlay.mounting.fixed and res.overlay.mounting.source == "the MJCF file welds the root to the world"
    free = refine_once(xml, "A free-standing window, slightly open.", config, extras=False)
    assert not free.overlay.mounting.fixed and free.overlay.mounting.source.startswith("request")


def test_a_body_deep_in_a_kitchen_scene_is_read_as_the_object_mounted_where_it_is(tmp_path):
    """Franka Kitchen's layout in small: a robot arm and a desk under the world body, the desk holding a counter, a
    sliding cabinet and a microwave; --body microwave reads the microwave alone, mounted on the desk."""
    xml = tmp_path / "kitchen.xml"
    xml.write_text(textwrap.dedent("""
        <mujoco model="kitchen">
          <compiler angle="radian"/>
          <worldbody>
            <body name="arm" pos="0 -1 0">
              <geom type="cylinder" size="0.06 0.4" pos="0 0 0.4"/>
              <body name="link1" pos="0 0 0.8"><joint name="j1" axis="0 0 1" range="-2 2"/><geom type="box" size="0.05 0.05 0.2"/></body>
            </body>
            <body name="desk">
              <body name="counter"><geom type="box" size="1 0.4 0.45" pos="0 0 0.45"/></body>
              <body name="slidecabinet" pos="0.5 0 1.5">
                <geom type="box" size="0.3 0.2 0.2"/>
                <body name="slidedoor" pos="0 -0.22 0"><joint name="slide" type="slide" axis="1 0 0" range="0 0.4"/>
                  <geom type="box" size="0.15 0.01 0.19"/></body>
              </body>
              <body name="microwave" pos="-0.5 0 1.1" euler="0 0 0.3">
                <body name="micro_body"><geom type="box" size="0.25 0.2 0.15"/>
                  <body name="micro_door" pos="-0.25 -0.21 0">
                    <joint name="micro0joint" axis="0 0 1" range="-2.094 0"/>
                    <geom type="box" size="0.25 0.01 0.15" pos="0.25 0 0"/>
                  </body>
                </body>
              </body>
            </body>
          </worldbody>
        </mujoco>""").lstrip())
    with pytest.raises(StagingError, match=r"\['arm', 'desk'\]"):
        read_mjcf_asset(xml)
    read = read_mjcf_asset(xml, ReadOptions(body="microwave"))
    assert read.model.root == "microwave" and set(read.model.links) == {"microwave", "micro_body", "micro_door"}
    hinge = next(j for j in read.model.joints if j.name == "micro0joint")
    assert (hinge.limit.lower, hinge.limit.upper) == pytest.approx((-2.094, 0.0))
    note = next(n for n in read.notes if n.startswith("object: body 'microwave'"))
    assert "mounted on ['desk']" in note and "'slidedoor'" in note
    assert any("'arm'" in n and "left out" in n for n in read.notes)
    assert read.root_fixed is True
    door = read_mjcf_asset(xml, ReadOptions(body="micro_door"))  # a moving part: the object under the world body
    assert door.model.root == "desk"
