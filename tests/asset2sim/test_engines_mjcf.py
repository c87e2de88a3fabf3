"""The URDF -> MJCF converter's MuJoCo-free parts (asset2sim.engines.mjcf.*) on
real PartNet-Mobility objects: mesh assets, hulls, colours, number text,
contact policy. The MuJoCo-compiled conversion is in test_engines_mujoco.py."""

from __future__ import annotations

import numpy as np
import pytest

from asset2sim.engines import mjcf
from asset2sim.engines.loading import BULLET_DEFAULT_FRICTION, BULLET_PLANE_FRICTION, collision_pieces, read_urdf
from asset2sim.engines.mjcf.base import DERIVED_MESH_DIR, num_text, relative_to, safe_name, vec_text
from asset2sim.engines.mjcf.convert import hull_obj, mesh_assets
from asset2sim.engines.mjcf.rewrite import contact_policy, link_friction
from asset2sim.engines.mjcf.visuals import mtl_colour


def _obj(data: bytes) -> tuple[np.ndarray, np.ndarray]:
    lines = data.decode().splitlines()
    v = np.array([[float(c) for c in ln.split()[1:]] for ln in lines if ln.startswith("v ")])
    f = np.array([[int(c) - 1 for c in ln.split()[1:]] for ln in lines if ln.startswith("f ")])
    return v, f


def test_package_keeps_the_public_names():
    for name in mjcf.__all__:
        assert hasattr(mjcf, name), name
    assert mjcf.KEYFRAME == "initial" and mjcf.FREE_JOINT == "root_free" and mjcf.GROUND == "ground"


def test_numbers_round_trip_and_names_are_safe(tmp_path):
    for x in (0.1, 1 / 3, 1e-17, -2.5e8, 0.0, -0.0):
        assert float(num_text(x)) == x
    assert num_text(-0.0) == "0" and vec_text(np.eye(2)) == "1.0 0 0 1.0"
    assert safe_name("link 0/a:b") == "link_0_a_b"
    assert relative_to(tmp_path / "a" / "b.obj", tmp_path) == "a/b.obj"
    assert relative_to(tmp_path, tmp_path / "a") is None


def test_mesh_assets_of_a_real_object(shared_dataset):
    """103275: every convex piece gets one mesh; whole single-group files are
    referenced inside the asset folder, other hulls are written as closed,
    outward-wound OBJs under DERIVED_MESH_DIR."""
    root = shared_dataset / "103275"
    pieces, _notes = collision_pieces(read_urdf(root / "mobility.urdf"))
    hulls = [(name, p) for name, plist in pieces.items() for p in plist if p.kind == "hull"]
    m = mesh_assets(pieces, root)
    assert hulls and len(m.names) == len(hulls) == len(m.virtual) == len(m.import_assets)
    for rel, src in m.files.items():
        assert (root / rel).resolve() == src.resolve()
    assert all(rel.startswith(DERIVED_MESH_DIR + "/") for rel in m.derived)
    for data in m.derived.values():
        v, f = _obj(data)
        a, b, c = v[f[:, 0]], v[f[:, 1]], v[f[:, 2]]
        assert float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum()) > 0  # outward: positive volume
        assert np.isin(np.arange(len(v)), f).all()  # only hull vertices are written


def test_hull_obj_of_points_inside_a_cube():
    rng = np.random.default_rng(0)
    pts = np.concatenate([rng.uniform(-0.5, 0.5, (200, 3)), np.array(np.meshgrid(*[[-1, 1]] * 3)).reshape(3, -1).T])
    v, f = _obj(hull_obj(pts))
    assert len(v) == 8 and len(f) == 12
    a, b, c = v[f[:, 0]], v[f[:, 1]], v[f[:, 2]]
    assert float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum()) / 6 == pytest.approx(8.0)


def test_mtl_colour_of_a_real_obj(shared_dataset, tmp_path):
    obj = next(iter(sorted((shared_dataset / "103275" / "textured_objs").glob("*.obj"))))
    rgba = [float(x) for x in mtl_colour(obj).split()]
    assert len(rgba) == 4 and all(0.0 <= x <= 1.0 for x in rgba)
    assert mtl_colour(tmp_path / "missing.obj") == "0.7 0.7 0.7 1"
    (tmp_path / "c.mtl").write_text("newmtl a\nKd 2 0.5 -1\nd 0.25\n")
    (tmp_path / "c.obj").write_text("mtllib c.mtl\nusemtl a\nv 0 0 0\n")
    assert mtl_colour(tmp_path / "c.obj") == "1.0 0.5 0 0.25"


def test_contact_policy_and_friction_of_a_real_object(shared_dataset):
    """100221 (chest): pairs restored or excluded are never a link and its
    parent kept apart by PyBullet, and the default friction is Bullet's product."""
    model = read_urdf(shared_dataset / "100221" / "mobility.urdf")
    pieces, _ = collision_pieces(model)
    adjacent = model.adjacent_pairs()
    for free in (True, False):
        restore, exclude = contact_policy(model, pieces, free=free)
        assert all(frozenset(p) not in adjacent for p in restore)
        assert all(frozenset(p) in adjacent for p in exclude)
    for name in model.links:
        if model.links[name].lateral_friction is None:
            assert link_friction(model, name) == BULLET_DEFAULT_FRICTION * BULLET_PLANE_FRICTION
