"""An MJCF file is read with the angle unit of the package that compiles it (``host_conventions``): the override,
the file's own ``<compiler angle>`` (includes too), a known host layout, a world file above it, MuJoCo's default.
A range that only makes sense in the other unit is a validation warning."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from tests.tasks.ingest import host_layouts as hl

pytest.importorskip("mujoco")

from asset2sim.formats.mjcf import conventions as host_conventions  # noqa: E402
from asset2sim.tasks.ingest.extract import validate_any  # noqa: E402
from asset2sim.formats.mjcf.conventions import HOST_LAYOUTS, ReadOptions, mjcf_angle  # noqa: E402
from asset2sim.formats.mjcf.reader import read_mjcf_asset  # noqa: E402


def _range(read, joint: str) -> tuple[float, float]:
    j = next(j for j in read.model.joints if j.name == joint)
    return j.limit.lower, j.limit.upper


def test_a_robosuite_fragment_reads_its_hinge_range_in_radians(tmp_path):
    xml = hl.robosuite_door(tmp_path / "site-packages" / "robosuite" / "models" / "assets" / "objects" / "door.xml")
    read = read_mjcf_asset(xml)
    assert _range(read, "door_hinge") == pytest.approx(hl.ROBOSUITE_DOOR_RANGE)
    note = next(n for n in read.notes if n.startswith("angles read in"))
    assert "radians" in note and "robosuite" in note and 'base.xml, whose <compiler angle="radian">' in note
    conv = mjcf_angle(xml)
    assert (conv.unit, conv.source, conv.host) == ("radian", "host", "robosuite")


def test_the_same_fragment_alone_is_read_as_mujoco_reads_it_and_the_override_wins(tmp_path):
    xml = hl.robosuite_door(tmp_path / "loose" / "door.xml")
    alone = read_mjcf_asset(xml)
    assert _range(alone, "door_hinge") == pytest.approx((0.0, math.radians(0.4)))
    assert any("MuJoCo's default, degrees" in n for n in alone.notes)
    asked = read_mjcf_asset(xml, ReadOptions(mjcf_angle="radian"))
    assert _range(asked, "door_hinge") == pytest.approx(hl.ROBOSUITE_DOOR_RANGE)
    assert any("asked (--mjcf-angle radian" in n for n in asked.notes)
    inside = hl.robosuite_door(tmp_path / "robosuite" / "models" / "assets" / "objects" / "door.xml")
    forced = read_mjcf_asset(inside, ReadOptions(mjcf_angle="degree"))
    assert _range(forced, "door_hinge") == pytest.approx((0.0, math.radians(0.4)))


def test_a_world_file_above_the_fragment_sets_its_unit(tmp_path):
    """robosuite's layout copied out of its package: ``assets/base.xml`` states radians for ``assets/objects/*``."""
    assets = tmp_path / "my_copy" / "assets"
    assets.mkdir(parents=True)
    (assets / "base.xml").write_text('<mujoco model="base"><compiler angle="radian" meshdir="meshes/"/><worldbody/></mujoco>')
    xml = hl.robosuite_door(assets / "objects" / "door.xml")
    read = read_mjcf_asset(xml)
    assert _range(read, "door_hinge") == pytest.approx(hl.ROBOSUITE_DOOR_RANGE)
    assert mjcf_angle(xml).source == "world_file"
    assert any("assets/base.xml" in n for n in read.notes)


def test_the_files_own_compiler_wins_over_its_host(tmp_path):
    xml = hl.robosuite_door(tmp_path / "robosuite" / "models" / "assets" / "objects" / "door.xml",
                            compiler='<compiler angle="degree"/>')
    read = read_mjcf_asset(xml)
    assert _range(read, "door_hinge") == pytest.approx((0.0, math.radians(0.4)))
    assert mjcf_angle(xml).source == "file"


@pytest.mark.parametrize("layout", HOST_LAYOUTS, ids=lambda h: "/".join(h.folders))
def test_every_known_host_layout_is_recognised(tmp_path, layout):
    xml = hl.robosuite_door(tmp_path.joinpath(*layout.folders, "objects", "door.xml"))
    conv = mjcf_angle(xml)
    assert conv.host == layout.name
    want = layout.angle or host_conventions.MUJOCO_DEFAULT_ANGLE
    assert conv.unit == want
    lower, upper = _range(read_mjcf_asset(xml), "door_hinge")
    assert upper == pytest.approx(0.4 if want == "radian" else math.radians(0.4))


def test_a_degree_range_door_without_compiler_in_dm_control_keeps_its_degrees(tmp_path):
    xml = hl.degree_door(tmp_path / "dm_control" / "suite" / "door.xml")
    assert _range(read_mjcf_asset(xml), "hinge") == pytest.approx((0.0, math.pi / 2))


def test_an_include_across_folders_states_the_unit(tmp_path):
    """Meta-World's scene file states nothing itself; its ``assets/*_dependencies.xml`` include does."""
    xml = hl.metaworld_drawer(tmp_path / "copy")
    conv = mjcf_angle(xml)
    assert (conv.unit, conv.source) == ("radian", "file")
    assert "drawer_dependencies.xml" in conv.reason


def test_a_range_in_the_wrong_unit_is_a_validation_warning(tmp_path):
    xml = hl.robosuite_door(tmp_path / "robosuite" / "models" / "assets" / "objects" / "door.xml")
    findings, notes = validate_any(xml)
    assert not [f for f in findings if f.code == "JOINT_RANGE_WRONG_UNIT"]
    assert any("robosuite" in n for n in notes)
    findings, _ = validate_any(xml, reading=ReadOptions(mjcf_angle="degree"))
    wrong = [f for f in findings if f.code == "JOINT_RANGE_WRONG_UNIT"]
    assert len(wrong) == 1 and wrong[0].severity == "warning"
    assert "door_hinge" in wrong[0].describe() and "0.4 degrees" in wrong[0].message and "22.9 degrees" in wrong[0].message


def test_an_unknown_angle_unit_is_refused():
    with pytest.raises(ValueError, match="expected one of"):
        ReadOptions(mjcf_angle="grad")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="expected one of"):
        mjcf_angle(Path("x.xml"), "grad")  # type: ignore[arg-type]


def test_an_install_without_mujoco_names_the_extra(tmp_path, monkeypatch):
    xml = hl.degree_door(tmp_path / "door.xml")
    monkeypatch.setitem(__import__("sys").modules, "mujoco", None)  # as on a core-only install
    with pytest.raises(ImportError, match=r"pip install 'asset2sim\[mujoco\]'"):
        read_mjcf_asset(xml)


def test_a_keyframe_of_a_joint_drawn_at_its_ref_reads_as_mujoco_values_it(tmp_path):
    """MuJoCo's joint values are the URDF joint's (``ref`` moves the URDF origin): a keyframe at 30 degrees of a hinge
    drawn at 10 degrees starts the joint at 30 degrees, within its 0 to 90 degree range."""
    xml = hl.degree_door(tmp_path / "door.xml", ref=10.0)
    text = xml.read_text().replace("</worldbody>", '</worldbody><keyframe><key name="initial" qpos="0.5235987755982988"/></keyframe>')
    xml.write_text(text)
    read = read_mjcf_asset(xml)
    assert read.initial_state["hinge"] == pytest.approx(math.radians(30))
    assert _range(read, "hinge") == pytest.approx((0.0, math.pi / 2))
