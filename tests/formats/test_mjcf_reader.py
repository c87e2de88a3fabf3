"""MJCF inputs: read by MuJoCo into the asset model, staged as a URDF, refined like any asset.

Round trip: a refined output's own MJCF export (and, in the slow test, its USD export) read back equals its ``mobility.urdf`` (links, joints,
limits, damping, friction, masses, centers of mass, inertia tensors) within 1e-6 relative. Files the
tests write cover MJCF's conventions (degrees, default classes, meshdir, joint pos and ref, primitives)
and what is refused.
"""

from __future__ import annotations

import csv
import math
import textwrap
from pathlib import Path

import numpy as np
import pytest

from tests.conftest import SHARED

mujoco = pytest.importorskip("mujoco")

from asset2sim.formats.mjcf.export import export_mjcf  # noqa: E402
from asset2sim.tasks.ingest.errors import AssetError  # noqa: E402
from asset2sim.tasks.ingest.extract import extract_asset_checked  # noqa: E402
from asset2sim.formats.mjcf.reader import read_mjcf_asset  # noqa: E402
from asset2sim.formats.staging import StagingError, input_format, stage  # noqa: E402
from asset2sim.tasks.refine import refine_asset  # noqa: E402
from asset2sim.urdf import UrdfModel, read_urdf  # noqa: E402

RTOL = 1e-6


def _rel(got, want, scale: float) -> float:
    return float(np.abs(np.asarray(got, float) - np.asarray(want, float)).max()) / max(scale, 1e-300)


def assert_same_model(got: UrdfModel, want: UrdfModel, where: str) -> None:
    """Links, joints (type, parent, child, origin, axis, limits, damping, friction) and inertials of ``got``
    equal ``want``'s within :data:`RTOL` of each quantity's scale (fixed joints matched by parent and child)."""
    assert set(got.links) == set(want.links), where
    for name, link in want.links.items():
        g = got.links[name]
        assert bool(g.collisions) == bool(link.collisions), f"{where}: link {name} collisions"
        assert bool(g.visuals) == bool(link.visuals), f"{where}: link {name} visuals"
        if link.inertial is None:
            assert g.inertial is None, f"{where}: link {name} gained an inertial"
            continue
        assert g.inertial is not None, f"{where}: link {name} lost its inertial"
        assert _rel(g.inertial.mass, link.inertial.mass, link.inertial.mass) <= RTOL, f"{where}: {name} mass"
        com = link.inertial.com()
        assert _rel(g.inertial.com(), com, max(float(np.abs(com).max()), 1e-3)) <= RTOL, f"{where}: {name} COM"
        tensor = link.inertial.inertia_in_link_axes()
        assert _rel(g.inertial.inertia_in_link_axes(), tensor, float(np.abs(tensor).max())) <= RTOL, f"{where}: {name} inertia"
    by_pair = {(j.parent, j.child): j for j in got.joints}
    assert len(by_pair) == len(want.joints), where
    for w in want.joints:
        j = by_pair[(w.parent, w.child)]
        assert j.type == w.type, f"{where}: joint {w.name} type {j.type} != {w.type}"
        assert _rel(j.origin, w.origin, 1.0) <= RTOL, f"{where}: joint {w.name} origin"
        if w.type == "fixed":
            continue
        assert j.name == w.name
        assert _rel(j.axis, w.axis, 1.0) <= RTOL, f"{where}: joint {w.name} axis"
        if w.type in ("revolute", "prismatic"):
            span = max(abs(w.lower), abs(w.upper), 1e-3)
            assert _rel([j.lower, j.upper], [w.lower, w.upper], span) <= RTOL, f"{where}: joint {w.name} limits"
        assert _rel(j.damping, w.damping, abs(w.damping)) <= RTOL, f"{where}: joint {w.name} damping"
        assert _rel(j.friction, w.friction, abs(w.friction)) <= RTOL, f"{where}: joint {w.name} friction"


def _manifest_rows(ids: list[str] | None = None) -> list[dict]:
    rows = list(csv.DictReader(open(SHARED / "manifest.csv")))
    return [r for r in rows if ids is None or r["id"] in ids]


@pytest.fixture(scope="module")
def refined_row(tmp_path_factory, refine_factory):
    """``refined_row(row)``: a copy, made once in this module, of the session's refine of the dev row ``row`` (its
    request, no extras: ``refine_factory``); the exports below are written into the copy again by each test."""
    root = tmp_path_factory.mktemp("mjcf_round_trip")
    done: dict[str, Path] = {}

    def get(row: dict) -> Path:
        if row["id"] not in done:
            done[row["id"]] = refine_factory(SHARED / row["id"], row["prompt"], extras=False).copy_to(root / row["id"])
        return done[row["id"]]

    return get


def _round_trip(row: dict, out: Path, usd: bool = False) -> None:
    xml = export_mjcf(out)
    read = read_mjcf_asset(xml)
    urdf = read_urdf(out / "mobility.urdf")
    assert_same_model(read.model, urdf, row["id"])
    from asset2sim.refined_asset import read_initial_state

    state = read_initial_state(out)  # the export's keyframe read back as the declared initial state
    assert set(read.initial_state) == {j.name for j in urdf.joints if j.type != "fixed"}, row["id"]
    for name, q in read.initial_state.items():
        assert abs(q - state.get(name, 0.0)) <= 1e-9, (row["id"], name, q, state.get(name))
    if usd:  # URDF -> USD -> asset model, within the same tolerances (USD stores float32)
        from asset2sim.formats.usd.reader import read_usd_asset
        from asset2sim.formats.usd.export import export_usd

        assert_same_model(read_usd_asset(export_usd(out, check=False).path).model, urdf, f"{row['id']} (USD)")


@pytest.mark.parametrize("asset_id", ["148", *(pytest.param(a, marks=pytest.mark.slow) for a in ("8877", "103275"))])  # one dev object in the fast tiers, the others end to end
def test_a_refined_outputs_mjcf_reads_back_as_its_urdf(shared_dataset, refined_row, asset_id):
    row = _manifest_rows([asset_id])[0]
    _round_trip(row, refined_row(row))


@pytest.mark.slow
def test_every_dev_outputs_mjcf_and_usd_read_back_as_its_urdf(shared_dataset, refined_row):
    pytest.importorskip("pxr")
    rows = _manifest_rows()
    assert len(rows) == 21
    for row in rows:
        _round_trip(row, refined_row(row), usd=True)


# ------------------------------------------------------------------ files the tests write
def _write(folder: Path, name: str, text: str) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    p = folder / name
    p.write_text(textwrap.dedent(text))
    return p


def _cabinet_xml(folder: Path) -> Path:
    """A cabinet in MJCF's own conventions: degrees, a default class, a meshdir with an OBJ, a door
    hinged at a joint ``pos`` (opening outward, about -z), a spring, armature, an actuator force range; the body has
    no ``<inertial>`` (MuJoCo infers it), the door declares one."""
    import trimesh

    (folder / "assets").mkdir(parents=True, exist_ok=True)
    trimesh.creation.box(extents=(0.02, 0.4, 0.6)).export(folder / "assets" / "door.obj")
    return _write(folder, "cabinet.xml", """\
        <mujoco model="cabinet">
          <compiler angle="degree" meshdir="assets"/>
          <default>
            <default class="panel"><geom type="box" rgba="0.6 0.4 0.3 1"/></default>
            <default class="visual"><geom contype="0" conaffinity="0" group="2"/></default>
          </default>
          <asset><mesh name="door_mesh" file="door.obj"/></asset>
          <worldbody>
            <geom name="floor" type="plane" size="2 2 0.1"/>
            <body name="carcass" pos="0 0 0.35">
              <freejoint name="free"/>
              <geom class="panel" name="back" pos="-0.2 0 0" size="0.01 0.2 0.3"/>
              <geom class="panel" name="left" pos="0 -0.2 0" size="0.2 0.01 0.3"/>
              <geom class="panel" name="right" pos="0 0.2 0" size="0.2 0.01 0.3"/>
              <geom class="panel" name="top" pos="0 0 0.3" size="0.2 0.2 0.01"/>
              <geom class="panel" name="bottom" pos="0 0 -0.3" size="0.2 0.2 0.01"/>
              <body name="door" pos="0.22 0 0">
                <inertial pos="0 0 0" mass="1.5" diaginertia="0.065 0.045 0.02"/>
                <joint name="hinge" type="hinge" pos="0 -0.2 0" axis="0 0 -1" range="0 120"
                       damping="0.3" frictionloss="0.05" stiffness="0.8" springref="20" armature="0.01"/>
                <geom name="door_geom" type="mesh" mesh="door_mesh"/>
                <geom name="knob" type="capsule" pos="0.02 0.15 0" size="0.01 0.02" euler="90 0 0"/>
                <geom name="door_look" class="visual" type="box" size="0.01 0.2 0.3"/>
              </body>
            </body>
          </worldbody>
          <actuator><motor joint="hinge" gear="2" forcerange="-3 3" forcelimited="true"/></actuator>
        </mujoco>
        """)


def test_mjcf_conventions_are_resolved_by_mujoco(tmp_path):
    xml = _cabinet_xml(tmp_path / "in")
    read = read_mjcf_asset(xml)
    m = read.model
    assert input_format(xml) == "mjcf"
    assert m.root == "carcass" and set(m.links) == {"carcass", "door"}
    (j,) = m.joints
    assert (j.type, j.parent, j.child, j.name) == ("revolute", "carcass", "door", "hinge")
    # degrees -> radians; values read the same as MuJoCo's joint coordinate
    assert j.lower == pytest.approx(0.0) and j.upper == pytest.approx(math.radians(120))
    assert j.damping == pytest.approx(0.3) and j.friction == pytest.approx(0.05)
    assert j.limit.effort == pytest.approx(6.0)  # forcerange 3 x gear 2
    assert read.springs["hinge"].stiffness == pytest.approx(0.8)  # N*m/rad in MJCF whatever the angle unit
    assert read.springs["hinge"].reference == pytest.approx(math.radians(20))
    # the link frame sits on the hinge line: body pos + joint pos
    assert j.origin[:3, 3] == pytest.approx([0.22, -0.2, 0.0]) and j.origin[:3, :3] == pytest.approx(np.eye(3))
    assert j.axis == pytest.approx([0.0, 0.0, -1.0])
    door, carcass = m.links["door"], m.links["carcass"]
    assert door.inertial.mass == pytest.approx(1.5)
    assert door.inertial.com() == pytest.approx([0.0, 0.2, 0.0])  # the body origin, 0.2 m from the hinge line
    assert np.diag(door.inertial.inertia_in_link_axes()) == pytest.approx([0.065, 0.045, 0.02])
    assert carcass.inertial is None and read.inferred == ("carcass",)
    assert [g.kind for g in carcass.collisions] == ["box"] * 5
    assert carcass.collisions[0].size == pytest.approx([0.02, 0.4, 0.6])
    assert len(carcass.visuals) == 5  # no visual geoms: the collisions are shown
    assert [g.kind for g in door.collisions] == ["mesh", "mesh"] and [g.kind for g in door.visuals] == ["box"]
    verts, _ = read.meshes[door.collisions[0].filename]
    assert np.ptp(verts, axis=0) == pytest.approx([0.02, 0.4, 0.6], abs=1e-6)
    notes = " | ".join(read.notes)
    assert "ground plane" in notes and "armature" in notes and "capsule" in notes
    assert xml.resolve() in read.files and (tmp_path / "in" / "assets" / "door.obj").resolve() in read.files


def test_a_joint_drawn_at_its_ref_gets_the_origin_of_its_zero(tmp_path):
    """MuJoCo draws a body at its joint's ``ref``; URDF's origin is the joint at 0."""
    xml = _write(tmp_path, "ref.xml", """\
        <mujoco model="ref"><compiler angle="degree"/><worldbody><body name="base"><geom type="box" size="0.1 0.1 0.1"/>
          <body name="lid" pos="0 0 0.2"><joint name="h" axis="0 1 0" range="-30 90" ref="10"/><geom type="box" size="0.1 0.1 0.01"/></body>
          <body name="tray" pos="0.3 0 0"><joint name="s" type="slide" axis="1 0 0" range="0 0.2" ref="0.05"/><geom type="box" size="0.05 0.05 0.05"/></body>
        </body></worldbody></mujoco>""")
    read = read_mjcf_asset(xml)
    h, s = (read.model.joint(n) for n in ("h", "s"))
    c, sn = math.cos(math.radians(-10)), math.sin(math.radians(-10))
    assert h.origin[:3, :3] == pytest.approx(np.array([[c, 0, sn], [0, 1, 0], [-sn, 0, c]]), abs=1e-12)
    assert (h.lower, h.upper) == pytest.approx((math.radians(-30), math.radians(90)))
    assert s.origin[:3, 3] == pytest.approx([0.25, 0.0, 0.0])
    assert sum("ref" in n and "undone" in n for n in read.notes) == 2


def test_staged_urdf_reads_back_and_pybullet_loads_it(tmp_path):
    pybullet = pytest.importorskip("pybullet")
    read = read_mjcf_asset(_cabinet_xml(tmp_path / "in"))
    staged = stage(read, tmp_path / "st")
    back = read_urdf(staged.urdf_path)
    assert [(j.name, j.type) for j in back.joints] == [("hinge", "revolute")]
    assert back.joints[0].origin == pytest.approx(read.model.joints[0].origin, abs=1e-12)
    cid = pybullet.connect(pybullet.DIRECT)
    try:
        body = pybullet.loadURDF(str(staged.urdf_path), physicsClientId=cid)
        assert pybullet.getNumJoints(body, physicsClientId=cid) == 1
    finally:
        pybullet.disconnect(cid)


@pytest.mark.parametrize("body, message", [
    ('<body name="a"><geom size="0.1"/><body name="b"><joint name="ball" type="ball"/><geom size="0.1"/></body></body>',
     "ball joint"),
    ('<body name="a"><geom size="0.1"/></body><body name="b"><geom size="0.1"/></body>', "carries a hinge or slide joint"),
    ('<body name="a"><geom size="0.1"/><body name="b"><joint name="s" type="slide" limited="false"/><geom size="0.1"/></body></body>',
     "slide joint 's'"),
    ('<body name="a"><geom size="0.1"/><body name="b"><joint name="h1" type="hinge"/><joint name="h2" type="hinge" axis="1 0 0"/>'
     '<geom size="0.1"/></body></body>', "has 2 joints"),
    ('<body name="a"><geom size="0.1"/><body name="b"><geom type="box"/></body></body>', "MuJoCo cannot read"),
])
def test_what_the_asset_model_cannot_take_is_refused_by_name(tmp_path, body, message):
    xml = _write(tmp_path, "bad.xml", f'<mujoco model="bad"><worldbody>{body}</worldbody></mujoco>')
    with pytest.raises(StagingError, match=message) as err:
        read_mjcf_asset(xml)
    assert str(xml) in str(err.value)
    with pytest.raises(AssetError, match="cannot read this MJCF file"):
        extract_asset_checked(xml)


def test_an_mjcf_cabinet_is_refined_from_its_file_left_unchanged(tmp_path, refine_once):
    folder = tmp_path / "in"
    xml = _cabinet_xml(folder)
    before = {p: p.read_bytes() for p in folder.rglob("*") if p.is_file()}
    with pytest.raises(Exception, match="inside the input folder"):
        refine_asset(xml, "A cabinet, door halfway open.", folder / "out", extras=False)
    res = refine_once(xml, "A cabinet, door halfway open.", extras=False)
    assert res.report.source == str(xml.resolve())
    assert res.report.asset_id == "cabinet"
    assert any(n.startswith("input: ") and "staged as a URDF" in n for n in res.report.notes)
    assert res.report.failure_mode == "none", res.report.failure_mode
    q = res.report.initial_joint_positions["hinge"]
    assert 0.3 * math.radians(120) <= q <= 0.7 * math.radians(120)
    assert {p: p.read_bytes() for p in folder.rglob("*") if p.is_file()} == before
    out_model = read_urdf(res.out / "mobility.urdf")
    assert [j.name for j in out_model.movable_joints] == ["hinge"]


def test_an_mjcf_inputs_hash_is_the_same_in_every_process(tmp_path):
    """An MJCF input is staged in a new temporary folder per process; its hash names the staged files by their place
    in that folder, so two processes give the same hash (a rerun is skipped, two outputs are the same bytes): this
    one and a new one."""
    import subprocess
    import sys

    xml = _cabinet_xml(tmp_path / "in")
    code = f"from asset2sim.tasks.ingest.extract import extract_asset_checked as e; print(e({str(xml)!r})[0].input_hash)"
    other = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, timeout=300).stdout.strip()
    hashes = {extract_asset_checked(xml)[0].input_hash, other}
    assert len(hashes) == 1 and len(other) == 64, hashes


def test_a_folder_holding_one_mjcf_file_is_an_asset_named_after_the_folder(tmp_path):
    folder = tmp_path / "cabinet_7"
    _cabinet_xml(folder)
    asset, _ = extract_asset_checked(folder)
    assert asset.asset_id == "cabinet_7" and asset.staged_from == (folder / "cabinet.xml").resolve()
    assert [j.name for j in asset.movable_joints()] == ["hinge"]
    again, _ = extract_asset_checked(folder)
    assert again.input_hash == asset.input_hash
    (folder / "assets" / "door.obj").write_text((folder / "assets" / "door.obj").read_text() + "\n# changed\n")
    assert extract_asset_checked(folder)[0].input_hash != asset.input_hash  # the mesh file is part of the input


def test_a_usd_export_is_refined_from_its_file(demo_root, tmp_path, refine_once):
    """The USD reader behind the same extraction: an output's USD export refined as an input."""
    pytest.importorskip("pxr")
    first = refine_once(demo_root / "box_lid", "A box, lid closed.", media=False)  # the exports are first-phase
    usd = first.copy_to(tmp_path / "first") / "usd" / "mobility.usd"
    res = refine_once(usd, "A box, lid halfway open.", extras=False)
    assert res.report.source == str(usd.resolve()) and res.report.asset_id == "mobility"
    assert res.report.failure_mode == "none", res.report.failure_mode
    assert set(res.report.initial_joint_positions) == set(first.report.initial_joint_positions)
