"""MJCF files laid out as host packages ship them, written by the tests (no package installed).

- :func:`robosuite_door`: a fragment without ``<compiler>`` (robosuite's ``objects/door.xml``: a frame, a door on
  a hinge ranged ``0 0.4``, meant as radians by robosuite's ``base.xml``), at any place in a folder tree.
- :func:`metaworld_drawer`: a Meta-World scene (``objects/drawer.xml``) including its dependencies
  (``<compiler angle="radian">``, default classes) and ``../scene/basic_scene.xml`` (a table, a retaining wall and a
  floor plane around the object), the drawer's body unnamed under the world body.
- :func:`metaworld_window`: Meta-World's vertical window (``objects/window.xml``) in the same layout: a frame and
  a sash on a vertical slide ``window_slide`` ranged 0 to 0.2 m, both bodies unnamed, as Meta-World writes them.
- :func:`degree_door`: a door whose range is written in degrees (``0 90``) with no ``<compiler>``.
- :func:`hand_written_cabinet`: a small free-standing cabinet written by hand (degrees, primitive boxes, masses left to
  MuJoCo), a door on a hinge ranged 0 to 120 degrees.
"""

from __future__ import annotations

import textwrap
from pathlib import Path

#: The robosuite door's hinge range as written (rad, robosuite's unit).
ROBOSUITE_DOOR_RANGE = (0.0, 0.4)
#: The Meta-World drawer's slide range as written (m).
METAWORLD_DRAWER_RANGE = (-0.16, 0.0)


def _write(path: Path, text: str) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(textwrap.dedent(text).lstrip())
    return path


def robosuite_door(path: Path, compiler: str = "") -> Path:
    """robosuite's door fragment (frame 0.6 m tall, door 0.44 x 0.58 m, hinge ``door_hinge`` ranged 0 to 0.4, a
    ``handle`` geom and a ``door_handle`` site on the latch) at ``path``; ``compiler`` an optional element put first."""
    return _write(path, f"""
        <mujoco model="door_lock">
          {compiler}
          <worldbody>
            <body name="door_body">
              <body name="collision">
                <body name="frame" quat="0.707388 0 0 -0.706825">
                  <inertial pos="0.3 0 0" quat="0.5 0.5 0.5 0.5" mass="7.85398" diaginertia="0.923301 0.764585 0.168533"/>
                  <geom size="0.03 0.3" pos="0.555 0 0" type="cylinder" name="r_frame"/>
                  <geom size="0.03 0.3" pos="0.045 0 0" type="cylinder" name="l_frame"/>
                  <body name="door" pos="0.3 0 0">
                    <inertial pos="0.0296816 -0.00152345 0" quat="0.701072 0 0 0.713091" mass="2.43455"
                              diaginertia="0.0913751 0.0521615 0.043714"/>
                    <joint name="door_hinge" pos="0.255 0 0" axis="0 0 1" range="0.0 0.4" damping="1" frictionloss="1"
                           limited="true"/>
                    <geom size="0.22 0.02 .29" type="box" friction="1 1 1" name="door_box"/>
                    <body name="latch" pos="-0.175 0 -0.025">
                      <inertial pos="0 -0.06 0" mass="0.1" diaginertia="0.0002 0.0002 0.0001"/>
                      <geom fromto="0 0 0 0 -0.125 0" size="0.025" type="cylinder" name="handle_base"/>
                      <geom size="0.075 0.015 0.02" pos="0.075 -0.10 0" type="box" name="handle"/>
                      <site name="door_handle" pos="0.125 -0.10 0" size="0.02"/>
                    </body>
                  </body>
                </body>
              </body>
              <site name="bottom_site" pos="0 0 -0.3" size="0.005"/>
            </body>
          </worldbody>
        </mujoco>""")


def _dependencies(assets: Path, name: str) -> Path:
    """Meta-World's ``objects/assets/<name>_dependencies.xml`` under ``assets``: ``<compiler angle="radian">`` and the
    default classes ``<name>_base`` (visual geoms, joints) and ``<name>_col`` (collision geoms)."""
    return _write(assets / "objects" / "assets" / f"{name}_dependencies.xml", """
        <mujocoinclude>
          <compiler angle="radian" inertiafromgeom="auto" inertiagrouprange="4 5"/>
          <default>
            <default class="NAME_base">
              <joint armature="0.001" damping="2" limited="true"/>
              <geom conaffinity="0" contype="0" group="1" type="box"/>
              <default class="NAME_col">
                <geom conaffinity="1" condim="3" contype="1" group="4"/>
              </default>
            </default>
          </default>
        </mujocoinclude>""".replace("NAME", name))


def metaworld_drawer(root: Path, joint_name: str | None = "goal_slidey") -> Path:
    """Meta-World's layout under ``root`` (``metaworld/assets/``): ``objects/drawer.xml`` including
    ``objects/assets/drawer_dependencies.xml``, ``scene/basic_scene.xml`` and ``objects/assets/drawer.xml``; returns
    the scene file. The drawer (20 x 20 x 17 cm case, a slide ``goal_slidey`` ranged -0.16 to 0 m, an ``objGeom`` handle)
    sits on a 1.4 x 0.8 m table inside a retaining wall; ``joint_name`` None leaves the slide unnamed (as Meta-World's
    doorlock leaves its lock's hinge)."""
    assets = root / "metaworld" / "assets"
    _write(assets / "scene" / "basic_scene.xml", """
        <mujocoinclude>
          <worldbody>
            <body name="tablelink" pos="0 .6 0">
              <geom type="box" size=".7 .4 .027" pos="0 0 -.027" conaffinity="0" contype="0" group="1"/>
              <geom type="box" size="0.7 0.4 0.46" pos="0.0 0.0 -0.46" conaffinity="1" contype="0" group="4"/>
            </body>
            <body name="RetainingWall" pos="0.0 0.6 0.06">
              <geom type="box" size=".7 .01 .06" pos="0. -0.39 0." conaffinity="1" contype="0"/>
              <geom type="box" size=".7 .01 .06" pos="0. 0.39 0." conaffinity="1" contype="0"/>
            </body>
            <geom name="floor" size="4 4 .1" pos="0 0 -.913" type="plane"/>
          </worldbody>
        </mujocoinclude>""")
    _dependencies(assets, "drawer")
    _write(assets / "objects" / "assets" / "drawer.xml", """
        <mujocoinclude>
          <body childclass="drawer_base">
            <body name="drawercase_link" pos="0 0 0.084">
              <geom class="drawer_col" pos="-0.11 0 0" size="0.008 0.1 0.084" mass=".05"/>
              <geom class="drawer_col" pos="0.11 0 0" size="0.008 0.1 0.084" mass=".05"/>
              <geom class="drawer_col" pos="0 0.092 -0.008" size="0.102 0.008 0.076" mass=".05"/>
              <geom class="drawer_col" pos="0 -0.008 -0.07" size="0.102 0.092 0.014" mass=".05"/>
              <geom class="drawer_col" pos="0 0 0.076" size="0.102 0.1 0.008" mass=".05"/>
              <body name="drawer_link" pos="0 -0.01 0.006">
                <joint type="slide" range="-0.16 0" axis="0 1 0" NAME pos="0 0 0" damping="2"/>
                <geom class="drawer_col" pos="0 -0.082 0.008" size="0.1 0.008 0.052" mass=".04"/>
                <geom class="drawer_col" pos="0 0.082 0.008" size="0.1 0.008 0.052" mass=".04"/>
                <geom class="drawer_col" pos="-0.092 0 0.008" size="0.008 0.074 0.052" mass=".04"/>
                <geom class="drawer_col" pos="0.092 0 0.008" size="0.008 0.074 0.052" mass=".04"/>
                <geom class="drawer_col" pos="0 0 -0.052" size="0.1 0.09 0.008" mass=".04"/>
                <geom class="drawer_col" euler="0 1.57 0" pos="0 -0.15 0" size="0.009 0.05" type="capsule" mass=".06"
                      name="objGeom"/>
                <geom class="drawer_col" euler="1.571 0 0" pos="-0.05 -0.12 0.0" size="0.009 0.03" type="capsule" mass=".06"/>
                <geom class="drawer_col" euler="1.571 0 0" pos="0.05 -0.12 0" size="0.009 0.03" type="capsule" mass=".06"/>
              </body>
            </body>
          </body>
        </mujocoinclude>""".replace("NAME", f'name="{joint_name}"' if joint_name else ""))
    return _write(assets / "objects" / "drawer.xml", """
        <mujoco model="drawer">
          <include file="assets/drawer_dependencies.xml"/>
          <include file="../scene/basic_scene.xml"/>
          <worldbody>
            <include file="assets/drawer.xml"/>
          </worldbody>
        </mujoco>""")


#: The Meta-World window's slide range as written (m).
METAWORLD_WINDOW_RANGE = (0.0, 0.2)


def metaworld_window(root: Path) -> Path:
    """Meta-World's vertical window under ``root`` (``metaworld/assets/``): ``objects/window.xml`` including
    ``objects/assets/window_dependencies.xml``, ``scene/basic_scene.xml`` and ``objects/assets/window.xml``; returns
    the scene file. A 0.39 x 0.47 m frame (posts, sill, head, a fixed upper pane) and a 0.3 x 0.2 m lower sash with its
    pane and a handle on a vertical slide ``window_slide`` ranged 0 to 0.2 m; neither body is named."""
    metaworld_drawer(root)  # the scene and the table around it
    assets = root / "metaworld" / "assets"
    _dependencies(assets, "window")
    _write(assets / "objects" / "assets" / "window.xml", """
        <mujocoinclude>
          <body childclass="window_base">
            <geom class="window_col" pos="0 0 0.035" size="0.181 0.03 0.015" type="box"/>
            <geom class="window_col" pos="0 0 0.01" size="0.195 0.06 0.01" type="box"/>
            <geom class="window_col" pos="0 0 0.467" size="0.181 0.03 0.015" type="box"/>
            <geom class="window_col" pos="0.166 0 0.251" size="0.015 0.03 0.201" type="box"/>
            <geom class="window_col" pos="-0.166 0 0.251" size="0.015 0.03 0.201" type="box"/>
            <geom class="window_col" pos="0 0.012 0.351" size="0.13 0.004 0.08" type="box"/>
            <geom class="window_col" pos="0 0.012 0.261" size="0.15 0.012 0.01" type="box"/>
            <geom class="window_col" pos="0 0.012 0.441" size="0.15 0.012 0.01" type="box"/>
            <body pos="0 0 0.051">
              <joint type="slide" range="0 .2" axis="0 0 1" name="window_slide"/>
              <geom class="window_col" pos="0 -0.013 0.014" size="0.15 0.012 0.014" type="box" mass=".001"/>
              <geom class="window_col" pos="0 -0.013 0.19" size="0.15 0.012 0.01" type="box" mass=".001"/>
              <geom class="window_col" pos="0.14 -0.013 0.104" size="0.01 0.012 0.076" type="box" mass=".001"/>
              <geom class="window_col" pos="-0.14 -0.013 0.104" size="0.01 0.012 0.076" type="box" mass=".001"/>
              <geom class="window_col" pos="0 -0.018 0.104" size="0.13 0.004 0.076" type="box" mass=".001"/>
              <geom class="window_col" euler="0 1.57 0" pos="0 -0.095 0.014" size="0.008 0.045" type="capsule" mass=".001"/>
            </body>
          </body>
        </mujocoinclude>""")
    return _write(assets / "objects" / "window.xml", """
        <mujoco model="window">
          <include file="assets/window_dependencies.xml"/>
          <include file="../scene/basic_scene.xml"/>
          <worldbody>
            <body pos="0 0.8 0">
              <include file="assets/window.xml"/>
            </body>
          </worldbody>
        </mujoco>""")


def degree_door(path: Path, ref: float = 0.0) -> Path:
    """A door (0.8 x 2.0 m, 4 cm thick, 2 cm clear of its posts) on a frame, hinge ``hinge`` ranged ``0 90`` with no ``<compiler>``: degrees,
    as dm_control and MuJoCo read it alone; ``ref`` (degrees) the hinge value the leaf is drawn at."""
    return _write(path, """
        <mujoco model="door">
          <worldbody>
            <body name="frame">
              <geom type="box" size="0.03 0.03 1.0" pos="-0.45 0 1.0"/>
              <geom type="box" size="0.03 0.03 1.0" pos="0.45 0 1.0"/>
              <geom type="box" size="0.48 0.03 0.03" pos="0 0 2.03"/>
              <body name="leaf" pos="-0.38 0 1.0">
                <joint name="hinge" type="hinge" axis="0 0 1" range="0 90" damping="0.5" ref="REF"/>
                <geom name="panel" type="box" size="0.39 0.02 0.98" pos="0.4 0 0"/>
                <geom name="knob" type="box" size="0.02 0.04 0.02" pos="0.72 -0.06 0"/>
              </body>
            </body>
          </worldbody>
        </mujoco>""".replace("REF", f"{ref:g}"))


def hand_written_cabinet(path: Path, door: str = 'damping="0.3" frictionloss="0.05"') -> Path:
    """A small cabinet as someone writes one by hand in MJCF (``<compiler angle="degree">``, primitive boxes, no
    ``<inertial>``: MuJoCo infers the masses from the geoms): a free-standing 0.4 x 0.4 x 0.6 m carcass and a door
    on a hinge ``door_hinge`` ranged 0 to 120 degrees at its left edge, with a knob; ``door``: the hinge's dynamics
    attributes as written."""
    return _write(path, f"""
        <mujoco model="cabinet">
          <compiler angle="degree"/>
          <worldbody>
            <body name="carcass" pos="0 0 0.35">
              <freejoint name="free"/>
              <geom type="box" name="back" pos="-0.2 0 0" size="0.01 0.2 0.3"/>
              <geom type="box" name="left" pos="0 -0.2 0" size="0.2 0.01 0.3"/>
              <geom type="box" name="right" pos="0 0.2 0" size="0.2 0.01 0.3"/>
              <geom type="box" name="top" pos="0 0 0.3" size="0.2 0.2 0.01"/>
              <geom type="box" name="bottom" pos="0 0 -0.3" size="0.2 0.2 0.01"/>
              <body name="door" pos="0.22 0 0">
                <joint name="door_hinge" type="hinge" pos="0 -0.2 0" axis="0 0 -1" range="0 120" {door}/>
                <geom type="box" name="panel" size="0.01 0.2 0.3"/>
                <geom type="box" name="knob" pos="0.03 0.15 0" size="0.02 0.01 0.02"/>
              </body>
            </body>
          </worldbody>
        </mujoco>""")
