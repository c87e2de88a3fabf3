"""PhysX (SAPIEN 3, CPU) engine specifics: what it builds from the URDF."""

from __future__ import annotations

import numpy as np
import pytest

from asset2sim.engines.base import SessionOptions
from asset2sim.engines.registry import available_engines, open_session
from asset2sim.engines.loading import BULLET_DEFAULT_MASS, read_urdf
from tests.contract_asset import write_contract_asset

pytestmark = pytest.mark.physx
pytest.importorskip("sapien")


def _rotate_lid_inertial(urdf) -> None:
    """A non-diagonal tensor in a rotated inertial frame for the lid."""
    text = urdf.read_text()
    head, sep, tail = text.partition('<link name="lid">')
    tail = tail.replace('rpy="0 0 0"/>', 'rpy="0.3 -0.2 0.5"/>', 1)
    tail = tail.replace('ixy="0.0"', 'ixy="0.0001"', 1).replace('iyz="0.0"', 'iyz="-0.00005"', 1)
    urdf.write_text(head + sep + tail)


def test_registered():
    assert "physx" in available_engines()


def test_links_carry_the_file_inertials(tmp_path):
    a = write_contract_asset(tmp_path)
    _rotate_lid_inertial(a.urdf)
    model = read_urdf(a.urdf)
    s = open_session("physx", a.urdf, SessionOptions(initial_state=a.initial_state))
    try:
        assert set(s.links) == set(model.links)
        for name, comp in s.links.items():
            ine = model.links[name].inertial
            assert comp.mass == pytest.approx(ine.mass, rel=1e-6)
            pose = comp.cmass_local_pose.to_transformation_matrix()
            assert pose[:3, 3] == pytest.approx(ine.com(), abs=1e-6)
            r = pose[:3, :3]
            tensor = r @ np.diag(comp.inertia) @ r.T
            assert tensor == pytest.approx(ine.inertia_in_link_axes(), abs=1e-7 * max(1.0, np.abs(ine.inertia).max()))
    finally:
        s.close()


def test_missing_inertial_gets_the_pybullet_default(tmp_path):
    a = write_contract_asset(tmp_path, base_inertial=False)
    s = open_session("physx", a.urdf, SessionOptions(initial_state=a.initial_state))
    try:
        assert s.links["base"].mass == pytest.approx(BULLET_DEFAULT_MASS)
        assert any("'base' has no <inertial>" in n for n in s.notes)
    finally:
        s.close()


def test_link_frames_follow_the_urdf(tmp_path):
    a = write_contract_asset(tmp_path)
    model = read_urdf(a.urdf)
    q = {"lid_hinge": 0.7, "post_slide": 0.03}
    s = open_session("physx", a.urdf, SessionOptions(initial_state=q, fixed_base=True, gravity=False, ground=False))
    try:
        want = model.link_poses(q)
        for name, comp in s.links.items():
            got = comp.get_pose().to_transformation_matrix()
            assert got == pytest.approx(want[name], abs=1e-6), name
    finally:
        s.close()


def test_one_shape_per_pybullet_piece_and_passive_drives(tmp_path):
    a = write_contract_asset(tmp_path, lid_friction=0.3, post_friction=1.5)
    s = open_session("physx", a.urdf, SessionOptions())
    try:
        counts = {n: len(c.get_collision_shapes()) for n, c in s.links.items()}
        assert counts == {"base": 0, "body": 5, "lid": 1, "post": 1}  # the body OBJ holds five groups
        joints = {j.name: j for j in s.art.active_joints}
        assert joints["lid_hinge"].friction == 0.0  # PhysX's coefficient is not Coulomb friction
        assert joints["lid_hinge"].force_limit == pytest.approx(0.3)
        assert joints["post_slide"].force_limit == pytest.approx(1.5)
    finally:
        s.close()


def test_placement_follows_the_joint_state(tmp_path):
    """Lowest point from the cooked hulls after a joint change (PhysX updates
    link poses on set_qpos)."""
    a = write_contract_asset(tmp_path)
    s = open_session("physx", a.urdf, SessionOptions(fixed_base=True, gravity=False, ground=False))
    try:
        assert s.lowest_point() == pytest.approx(0.0, abs=1e-6)
        s.set_root_pose([0, 0, 0.5], [0, 0, 0, 1])
        assert s.lowest_point() == pytest.approx(0.5, abs=1e-6)
    finally:
        s.close()
