"""Open cavities: space inside a part's convex hull reachable from outside its surface (a tray's, a bucket's
inside), found on a voxel grid; an enclosed inside or a shallow dish is none."""

from __future__ import annotations

import numpy as np
import pytest

from asset2sim import mesh_io
from asset2sim.tasks.geometry import cavities
from tests.helpers import box_mesh as _box


def _tray(width: float, height: float, wall: float, *, lid: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """A tray of ``width`` x ``width`` x ``height`` m with walls ``wall`` m thick (one mesh of boxes), closed on
    top with ``lid``."""
    w, h, t = width, height, wall
    boxes = [_box([0, 0, 0], [w, w, t]), _box([0, 0, 0], [t, w, h]), _box([w - t, 0, 0], [w, w, h]),
             _box([0, 0, 0], [w, t, h]), _box([0, w - t, 0], [w, w, h])]
    if lid:
        boxes.append(_box([0, 0, h - t], [w, w, h]))
    v = np.vstack([b[0] for b in boxes])
    f = np.vstack([b[1] + 8 * i for i, b in enumerate(boxes)])
    return v, f


def _cavity(v: np.ndarray, f: np.ndarray) -> cavities.Cavity | None:
    hv, hf = mesh_io.convex_hull_mesh(v)
    return cavities.open_cavity(v, f, hv, hf)


def test_an_open_tray_holds_a_cavity_the_size_of_its_inside():
    """A 10 cm tray 5 cm tall with 4 mm walls: the largest ball inside is bounded by the inner height (46 mm)
    and the hull's top, a radius near 23 mm; its core lies inside the walls."""
    cav = _cavity(*_tray(0.1, 0.05, 0.004))
    assert cav is not None
    assert 0.017 < cav.radius < 0.026
    assert 0.5 < cav.volume / cav.hull_volume < 0.85  # the inside is 0.092^2 x 0.046 of 0.1^2 x 0.05
    assert len(cav.core) > 0
    assert np.all((cav.core[:, :2] > 0.004) & (cav.core[:, :2] < 0.096))
    assert np.all((cav.core[:, 2] > 0.004) & (cav.core[:, 2] < 0.05))


def test_a_closed_box_and_a_shallow_dish_hold_no_cavity():
    """The same tray with a lid encloses its inside (nothing gets in); a 40 cm dish 2 cm deep holds no ball
    of :data:`cavities.MIN_CAVITY_RADIUS`."""
    assert _cavity(*_tray(0.1, 0.05, 0.004, lid=True)) is None
    assert _cavity(*_tray(0.4, 0.02, 0.003)) is None


def test_the_share_of_a_core_left_free_by_pieces():
    core = np.array([[0.0, 0.0, 0.0], [0.5, 0.5, 0.5], [2.0, 2.0, 2.0], [3.0, 0.0, 0.0]])
    unit = np.array([[1, 0, 0, -1], [-1, 0, 0, 0], [0, 1, 0, -1], [0, -1, 0, 0], [0, 0, 1, -1], [0, 0, -1, 0]], float)
    assert cavities.open_fraction(core, [unit]) == pytest.approx(0.5)
    assert cavities.open_fraction(core, []) == 1.0
    assert cavities.open_fraction(np.zeros((0, 3)), [unit]) == 1.0


def test_group_meshes_match_the_hull_point_sets(tmp_path):
    """One triangle mesh per group, in the order and with the vertices of :func:`mesh_io.obj_groups`; quads
    fan-triangulated; a group without faces is none."""
    path = tmp_path / "two.obj"
    path.write_text("o empty\nv 9 9 9\no a\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 2 3 4 5\n"
                    "g b\nv 0 0 1\nv 1 0 1\nv 0 1 1\nf 6/1 7/1 8/1\n")
    meshes = mesh_io.group_meshes(path)
    groups = mesh_io.obj_groups(path)
    assert len(meshes) == len(groups) == 2
    for (v, f), pts in zip(meshes, groups):
        assert np.array_equal(v, pts)
    assert meshes[0][1].tolist() == [[0, 1, 2], [0, 2, 3]]
    assert meshes[1][1].tolist() == [[0, 1, 2]]
    bad = tmp_path / "bad.obj"
    bad.write_text("v 0 0 0\nf 1 2 3\n")
    with pytest.raises(mesh_io.MeshReadError, match="bad.obj"):
        mesh_io.group_meshes(bad)


def test_the_mouth_points_from_the_inside_to_the_opening():
    """A tray open on top opens along +z; the same tray turned upside down (a lid over what it covers) along -z."""
    v, f = _tray(0.1, 0.05, 0.004)
    up = _cavity(v, f)
    assert up is not None and len(up.regions) == 1 and up.regions[0].mouth @ np.array([0.0, 0.0, 1.0]) > 0.9
    down = _cavity(v * np.array([1.0, 1.0, -1.0]), f[:, ::-1])
    assert down is not None and len(down.regions) == 1 and down.regions[0].mouth @ np.array([0.0, 0.0, -1.0]) > 0.9


def _bowl_on_a_skirt() -> tuple[np.ndarray, np.ndarray]:
    """A bowl on a skirt in one mesh, as a toilet body or a sink's basin on its pedestal is modelled: a 16 cm tray
    8 cm deep, open on top, its floor 10 cm up on four walls open at the bottom, so that its hull also encloses
    the space under the floor, which opens downward."""
    w, t, z = 0.16, 0.004, 0.10
    boxes = [_box([0, 0, z], [w, w, z + t]), _box([0, 0, 0], [t, w, 0.18]), _box([w - t, 0, 0], [w, w, 0.18]),
             _box([0, 0, 0], [w, t, 0.18]), _box([0, w - t, 0], [w, w, 0.18])]
    v = np.vstack([b[0] for b in boxes])
    f = np.vstack([b[1] + 8 * i for i, b in enumerate(boxes)])
    return v, f


def test_a_cavity_falls_apart_into_regions_each_with_its_mouth():
    """A bowl on a skirt (:func:`_bowl_on_a_skirt`): the space in the bowl opens upward, the space under its
    floor downward, each a region of the cavity's core holding its own ball (a radius of about half the inner height of each:
    76 mm and 100 mm)."""
    cav = _cavity(*_bowl_on_a_skirt())
    assert cav is not None and len(cav.regions) == 2
    z = np.array([0.0, 0.0, 1.0])
    bowl, under = sorted(cav.regions, key=lambda r: -float(r.mouth @ z))
    assert bowl.mouth @ z > 0.9 and under.mouth @ z < -0.9
    assert 0.025 < bowl.radius < 0.045 and 0.035 < under.radius < 0.055
    assert cav.radius == max(bowl.radius, under.radius)
    assert bowl.volume + under.volume <= cav.volume
    assert np.any(cav.core[:, 2] > 0.104) and np.any(cav.core[:, 2] < 0.1)  # the core lies in both
