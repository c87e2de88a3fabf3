"""Files every engine takes: a fixed joint's <limit> is dropped, a visual mesh
MuJoCo refuses is left out of the MJCF (never a file that does not compile)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from asset2sim import urdf
from asset2sim.engines.mjcf.visuals import visual_mesh_problem
from asset2sim.mesh_io import MeshCache

_URDF = """<?xml version="1.0"?>
<robot name="t">
  <link name="base"/>
  <link name="body">
    <inertial><mass value="1"/><inertia ixx="0.01" iyy="0.01" izz="0.01" ixy="0" ixz="0" iyz="0"/></inertial>
    <visual><geometry><mesh filename="tri.obj"/></geometry></visual>
    <visual><geometry><mesh filename="box.obj"/></geometry></visual>
    <collision><geometry><mesh filename="box.obj"/></geometry></collision>
  </link>
  <joint name="fix" type="fixed"><parent link="base"/><child link="body"/><limit lower="0" upper="1"/></joint>
</robot>
"""

_BOX = "\n".join(f"v {x} {y} {z}" for x in (0, 0.1) for y in (0, 0.1) for z in (0, 0.1)) + "\n" + "\n".join(
    f"f {a} {b} {c}" for a, b, c in [(1, 2, 4), (1, 4, 3), (5, 7, 8), (5, 8, 6), (1, 5, 6), (1, 6, 2),
                                     (3, 4, 8), (3, 8, 7), (1, 3, 7), (1, 7, 5), (2, 6, 8), (2, 8, 4)]) + "\n"


@pytest.fixture()
def tiny(tmp_path) -> Path:
    (tmp_path / "tri.obj").write_text("v 0 0 0\nv 0.1 0 0\nv 0 0.1 0\nf 1 2 3\n")
    (tmp_path / "box.obj").write_text(_BOX)
    p = tmp_path / "t.urdf"
    p.write_text(_URDF)
    return p


def test_conform_limits_drops_a_fixed_joints_limit_and_completes_movable_ones(tiny):
    model = urdf.read_urdf(tiny)
    assert model.joint("fix").limit is not None  # read as written
    model.joints.append(urdf.UrdfJoint(name="hinge", type="revolute", parent="body", child="lid",
                                       limit=urdf.UrdfLimit(lower=0.0, upper=1.0)))
    model.links["lid"] = urdf.UrdfLink(name="lid")
    kept = urdf.read_urdf(tiny)
    kept.joints.append(urdf.UrdfJoint(name="hinge", type="revolute", parent="body", child="lid",
                                      limit=urdf.UrdfLimit(lower=0.0, upper=1.0)))
    kept.links["lid"] = urdf.UrdfLink(name="lid")
    urdf.conform_limits(kept)  # nothing given: nothing invented
    lim = kept.joint("hinge").limit
    assert (lim.lower, lim.upper, lim.effort, lim.velocity) == (0.0, 1.0, None, None)
    assert "effort" not in urdf.write_urdf(kept).decode()
    notes = urdf.conform_limits(model, effort=7.0, velocity=3.0)
    assert model.joint("fix").limit is None and "fix" in notes[0]
    lim = model.joint("hinge").limit
    assert (lim.lower, lim.upper, lim.effort, lim.velocity) == (0.0, 1.0, 7.0, 3.0)
    text = urdf.write_urdf(model).decode()
    assert text.count("<limit") == 1


def test_single_triangle_visual_is_left_out_and_the_mjcf_compiles(tiny):
    mujoco = pytest.importorskip("mujoco")
    from asset2sim.engines.mjcf import urdf_to_mjcf

    assert "fewer than 4" in visual_mesh_problem(tiny.parent / "tri.obj", MeshCache())
    assert visual_mesh_problem(tiny.parent / "box.obj", MeshCache()) == ""
    build = urdf_to_mjcf(tiny, visuals=True)
    assert any("tri.obj" in n and "not exported" in n for n in build.notes)
    m = mujoco.MjModel.from_xml_string(build.xml, assets=build.assets())
    assert m.ngeom == 3  # ground, the box's collision, the box's visual
    assert np.isfinite(m.body_mass).all()
