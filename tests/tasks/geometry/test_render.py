"""Renders: real image content on generated assets and on real objects.

The generated asset is a box (one OBJ with four materials: a checker-textured
front face at -x, a blue top, a brown right side at +y, grey elsewhere) with a
lid hinged on its back top edge (an OBJ without a material, coloured green by
the URDF's <material>). Real objects come from ../shared (skipped if absent).
"""

from __future__ import annotations

import cachetools
import json
import math
from pathlib import Path

import numpy as np
import pytest

from asset2sim import mesh_io
from tests.helpers import tree_hashes
from asset2sim.tasks.geometry import render as R
from asset2sim.tasks.geometry import render_camera, render_images, render_meshes
from asset2sim.tasks.geometry.render_camera import VIEWS, ViewSpec, view_spec
from asset2sim.tasks.geometry.render_meshes import TextureLinks, split_obj
from asset2sim.tasks.geometry.render_scene import prepare_scene
from asset2sim.urdf import read_urdf

SMALL = (96, 96)

# ------------------------------------------------------------------ the asset
_FACES = {  # normal -> (u, v) with u x v = normal, so quads are counter-clockwise seen from outside
    (1, 0, 0): ((0, 1, 0), (0, 0, 1)),
    (-1, 0, 0): ((0, -1, 0), (0, 0, 1)),
    (0, 1, 0): ((0, 0, 1), (1, 0, 0)),
    (0, -1, 0): ((1, 0, 0), (0, 0, 1)),
    (0, 0, 1): ((1, 0, 0), (0, 1, 0)),
    (0, 0, -1): ((0, 1, 0), (1, 0, 0)),
}


def _cube_obj(face_material: dict[tuple, str | None], mtllib: str | None) -> str:
    """A unit cube centred at 0, one quad (two triangles) per face, UVs and normals."""
    lines = [f"mtllib {mtllib}"] if mtllib else []
    faces: list[tuple[str | None, list[int]]] = []
    vi = 0
    for n, (u, v) in _FACES.items():
        n_, u_, v_ = (np.array(a, float) for a in (n, u, v))
        for su, sv in ((-1, -1), (1, -1), (1, 1), (-1, 1)):
            p = 0.5 * n_ + 0.5 * su * u_ + 0.5 * sv * v_
            lines.append(f"v {p[0]:.4f} {p[1]:.4f} {p[2]:.4f}")
        for su, sv in ((0, 0), (1, 0), (1, 1), (0, 1)):
            lines.append(f"vt {su} {sv}")
        lines.append(f"vn {n[0]} {n[1]} {n[2]}")
        faces.append((face_material.get(n), [vi + 1, vi + 2, vi + 3, vi + 4]))
        vi += 4
    current = "<none>"
    for k, (mat, idx) in enumerate(faces):
        if mat != current and mat is not None:
            lines.append(f"usemtl {mat}")
            current = mat
        a, b, c, d = idx
        nn = k + 1
        lines.append(f"f {a}/{a}/{nn} {b}/{b}/{nn} {c}/{c}/{nn}")
        lines.append(f"f {a}/{a}/{nn} {c}/{c}/{nn} {d}/{d}/{nn}")
    return "\n".join(lines) + "\n"


def make_box_with_lid(root: Path, size: float = 0.4) -> Path:
    """Write the test asset (``size`` = body width, m) and return its URDF path."""
    from PIL import Image

    (root / "meshes").mkdir(parents=True, exist_ok=True)
    (root / "textures").mkdir(exist_ok=True)
    checker = np.zeros((16, 16, 3), np.uint8)
    yy, xx = np.mgrid[0:16, 0:16]
    red = ((yy // 4 + xx // 4) % 2) == 0
    checker[red] = (230, 30, 30)
    checker[~red] = (240, 220, 40)
    Image.fromarray(checker).save(root / "textures" / "checker.png")
    (root / "meshes" / "body.mtl").write_text(
        "newmtl front_tex\nKd 1 1 1\nmap_Kd ../textures/checker.png\n\n"
        "newmtl top_blue\nKd 0.1 0.2 0.9\n\n"
        "newmtl side_grey\nKd 0.6 0.6 0.6\n\n"
        "newmtl right_brown\nKd 0.45 0.3 0.2\n"
    )
    body = {n: "side_grey" for n in _FACES}
    body[(-1, 0, 0)] = "front_tex"
    body[(0, 0, 1)] = "top_blue"
    body[(0, 1, 0)] = "right_brown"
    (root / "meshes" / "body.obj").write_text(_cube_obj(body, "body.mtl"))
    (root / "meshes" / "lid.obj").write_text(_cube_obj({}, None))
    s = size  # width along y
    d = 0.7 * s  # depth along x
    h = 0.6 * s
    t = 0.05 * s
    urdf = f"""<?xml version="1.0"?>
<robot name="box_with_lid">
  <link name="base"/>
  <joint name="root" type="fixed"><parent link="base"/><child link="body"/></joint>
  <link name="body">
    <inertial><origin xyz="0 0 {h / 2}"/><mass value="1"/><inertia ixx="0.01" iyy="0.01" izz="0.01" ixy="0" ixz="0" iyz="0"/></inertial>
    <visual><origin xyz="0 0 {h / 2}"/><geometry><mesh filename="meshes/body.obj" scale="{d} {s} {h}"/></geometry></visual>
    <collision><origin xyz="0 0 {h / 2}"/><geometry><box size="{d} {s} {h}"/></geometry></collision>
  </link>
  <joint name="lid_hinge" type="revolute">
    <parent link="body"/><child link="lid"/>
    <origin xyz="{d / 2} 0 {h + t / 2}"/><axis xyz="0 1 0"/>
    <limit lower="0" upper="2.0" effort="1" velocity="1"/>
  </joint>
  <link name="lid">
    <visual><origin xyz="{-d / 2} 0 {t / 2}"/><geometry><mesh filename="meshes/lid.obj" scale="{d} {s} {t}"/></geometry>
      <material name="lid_green"><color rgba="0.1 0.8 0.2 1"/></material></visual>
    <collision><origin xyz="{-d / 2} 0 {t / 2}"/><geometry><box size="{d} {s} {t}"/></geometry></collision>
  </link>
</robot>
"""
    path = root / "mobility.urdf"
    path.write_text(urdf)
    return path


@pytest.fixture(scope="module")
def box(tmp_path_factory) -> Path:
    return make_box_with_lid(tmp_path_factory.mktemp("box"))


# ------------------------------------------------------------------ helpers
def object_mask(img: np.ndarray) -> np.ndarray:
    """(H, W) bool: pixels that are not the background."""
    return np.abs(img.astype(int) - np.array(R.BACKGROUND)).max(axis=2) > 6


def bbox(mask: np.ndarray) -> tuple[int, int, int, int]:
    ys, xs = np.nonzero(mask)
    return int(ys.min()), int(ys.max()), int(xs.min()), int(xs.max())


def count(img: np.ndarray, kind: str) -> int:
    r, g, b = (img[..., i].astype(float) for i in range(3))
    if kind == "red":
        sel = (r > 100) & (r > 2.5 * g) & (r > 2.5 * b)
    elif kind == "yellow":
        sel = (r > 110) & (g > 100) & (b < 0.5 * g)
    elif kind == "blue":
        sel = (b > 80) & (b > 1.6 * r) & (b > 1.6 * g)
    elif kind == "green":
        sel = (g > 80) & (g > 1.6 * r) & (g > 1.6 * b)
    else:
        raise ValueError(kind)
    return int(sel.sum())


# ------------------------------------------------------------------ tests
def test_views_show_the_object_and_differ(box):
    views = ("front", "back", "left", "right", "perspective", "top")
    images = R.render_views(box, views=views, size=SMALL)
    assert list(images) == list(views)
    for name, img in images.items():
        assert img.shape == (SMALL[1], SMALL[0], 3) and img.dtype == np.uint8
        m = object_mask(img)
        assert 0.15 < m.mean() < 0.9, (name, m.mean())
        # the background is the documented color, the object touches no border
        assert tuple(img[0, 0]) == R.BACKGROUND
        assert not (m[0].any() or m[-1].any() or m[:, 0].any() or m[:, -1].any()), name
        # the fitted camera fills the frame: the object spans most of one axis
        y0, y1, x0, x1 = bbox(m)
        assert max(y1 - y0, x1 - x0) > 0.7 * SMALL[0], name
        # shading: the object is not one flat color
        assert img[m].std(axis=0).max() > 10, name
    for a in views:
        for b in views:
            if a < b:
                diff = np.abs(images[a].astype(int) - images[b].astype(int)).mean()
                assert diff > 3, (a, b, diff)


def test_front_is_minus_x_with_texture_and_materials(box):
    """Front (camera at -x) sees the checker texture; back does not; the top face
    of the multi-material OBJ is blue (PyBullet alone would draw one material)."""
    img = R.render_views(box, {"lid_hinge": 1.9}, views=("front", "back", "top"), size=SMALL)
    assert count(img["front"], "red") > 100 and count(img["front"], "yellow") > 100
    assert count(img["back"], "red") == 0 and count(img["back"], "yellow") == 0
    assert count(img["top"], "blue") > 300  # the lid is open: the body's top is visible
    assert count(img["back"], "green") > 200  # the open lid leans back over +x


def test_opening_the_lid_changes_the_image(box):
    closed = R.render_views(box, {"lid_hinge": 0.0}, views=("left", "top"), size=SMALL)
    opened = R.render_views(box, {"lid_hinge": 1.2}, views=("left", "top"), size=SMALL)
    assert np.abs(closed["left"].astype(int) - opened["left"].astype(int)).mean() > 10
    # closed: the top view is the green lid, no blue; open: the blue top appears
    assert count(closed["top"], "green") > 0.3 * SMALL[0] * SMALL[1]
    assert count(closed["top"], "blue") == 0
    assert count(opened["top"], "blue") > 300
    # side view: the raised lid makes the silhouette taller for its width
    yc0, yc1, xc0, xc1 = bbox(object_mask(closed["left"]))
    yo0, yo1, xo0, xo1 = bbox(object_mask(opened["left"]))
    assert (yo1 - yo0) / (xo1 - xo0) > 1.3 * (yc1 - yc0) / (xc1 - xc0)


def test_default_state_is_zero(box):
    a = R.render_views(box, None, views=("left",), size=SMALL)["left"]
    b = R.render_views(box, {"lid_hinge": 0.0}, views=("left",), size=SMALL)["left"]
    assert np.array_equal(a, b)


@pytest.mark.parametrize("size", [0.05, 2.0])
def test_framing_adapts_to_the_object_size(tmp_path, box, size):
    """A 0.05 m and a 2 m copy of the asset give the same images as the 0.4 m one."""
    urdf = make_box_with_lid(tmp_path / "scaled", size=size)
    ref = R.render_views(box, {"lid_hinge": 0.8}, views=("perspective", "front"), size=SMALL)
    got = R.render_views(urdf, {"lid_hinge": 0.8}, views=("perspective", "front"), size=SMALL)
    for v in ref:
        assert np.abs(ref[v].astype(int) - got[v].astype(int)).mean() < 2.0, v
        assert abs(object_mask(ref[v]).mean() - object_mask(got[v]).mean()) < 0.02


def test_writes_pngs_atomically_and_leaves_inputs_alone(box, tmp_path):
    from PIL import Image

    before = tree_hashes(box.parent)
    out = tmp_path / "views"
    images = R.render_views(box, {"lid_hinge": 0.5}, out, size=(80, 64))
    assert sorted(p.name for p in out.iterdir()) == sorted(f"{v}.png" for v in R.DEFAULT_VIEWS)
    for v, img in images.items():
        assert img.shape == (64, 80, 3)
        assert np.array_equal(np.asarray(Image.open(out / f"{v}.png").convert("RGB")), img)
    assert tree_hashes(box.parent) == before


def test_contact_sheet_contains_every_view(box):
    images = R.render_views(box, {"lid_hinge": 0.5}, size=SMALL)
    sheet = R.render_contact_sheet(images)
    assert sheet.dtype == np.uint8 and sheet.ndim == 3 and sheet.shape[2] == 3
    H, W, _ = sheet.shape
    assert W >= 3 * SMALL[0] and H >= 2 * SMALL[1]  # 5 views -> 3 + 2
    h, w = SMALL[1], SMALL[0]
    for name, img in images.items():  # each tile is pasted unchanged somewhere
        tl = (sheet[: H - h + 1, : W - w + 1] == img[0, 0]).all(axis=2)
        br = (sheet[h - 1 :, w - 1 :] == img[-1, -1]).all(axis=2)
        ys, xs = np.nonzero(tl & br)
        assert any(np.array_equal(sheet[y : y + h, x : x + w], img) for y, x in zip(ys, xs)), name
    # labels: the strip above the tiles has dark text pixels
    assert (sheet[:20].min(axis=2) < 100).sum() > 20
    with pytest.raises(ValueError):
        R.render_contact_sheet({})
    with pytest.raises(ValueError, match="uint8"):
        R.render_contact_sheet({"front": np.zeros((4, 4, 3), float)})


def test_scene_renderer_reuses_one_load(box):
    with R.SceneRenderer(box, size=SMALL) as r:
        assert r.joint_names == ["lid_hinge"]
        a = r.render("front")
        r.set_joint_positions({"lid_hinge": 1.5})
        b = r.render("front")
        r.set_joint_positions({"lid_hinge": 0.0})
        c = r.render("front")
        assert r.timings.load > 0 and len(r.timings.views["front"]) == 3
    assert np.abs(a.astype(int) - b.astype(int)).mean() > 5
    assert np.array_equal(a, c)


def test_renders_in_threads_match_sequential(box):
    from concurrent.futures import ThreadPoolExecutor

    states = [{"lid_hinge": q} for q in (0.0, 0.7, 1.4)]
    seq = [R.render_views(box, q, views=("perspective",), size=SMALL)["perspective"] for q in states]
    with ThreadPoolExecutor(3) as pool:
        par = list(pool.map(lambda q: R.render_views(box, q, views=("perspective",), size=SMALL)["perspective"], states))
    for a, b in zip(seq, par):
        assert np.array_equal(a, b)


def test_bad_inputs_raise_clear_errors(box, tmp_path):
    with pytest.raises(KeyError, match="nope"):
        R.render_views(box, {"nope": 0.1}, size=SMALL)
    with pytest.raises(KeyError, match="side"):
        R.render_views(box, views=("side",), size=SMALL)
    with pytest.raises(ValueError, match="finite"):
        R.render_views(box, {"lid_hinge": math.nan}, size=SMALL)
    with pytest.raises(ValueError, match="backend"):
        R.render_views(box, backend="vulkan", size=SMALL)
    with pytest.raises(ValueError, match="size"):
        R.render_views(box, size=(0, 10))
    with pytest.raises(FileNotFoundError):
        R.render_views(tmp_path / "missing.urdf")
    broken = tmp_path / "broken"
    broken.mkdir()
    (broken / "mobility.urdf").write_text(box.read_text())
    with pytest.raises(FileNotFoundError, match="body.obj"):
        R.render_views(broken / "mobility.urdf", size=SMALL)
    (broken / "mobility.urdf").write_text("<robot name='x'><link name='a'/></robot>")
    with pytest.raises(ValueError, match="no visual geometry"):
        R.render_views(broken / "mobility.urdf", size=SMALL)
    (broken / "mobility.urdf").write_text("<robot")
    with pytest.raises(ValueError, match="parseable"):
        R.render_views(broken / "mobility.urdf", size=SMALL)


def test_primitives_stl_negative_indices_and_big_textures(tmp_path):
    """URDF colors on primitives and on an STL, an OBJ with negative (relative)
    face indices and no material, a 2048 px texture (downscaled), and a URDF
    with collision shapes only."""
    import trimesh
    from PIL import Image

    trimesh.creation.box((1.0, 1.0, 1.0)).export(tmp_path / "cube.stl")
    cube = _cube_obj({}, None).splitlines()
    n_v = sum(ln.startswith("v ") for ln in cube)
    rel = []
    for ln in cube:  # rewrite faces with negative indices, relative to the end of the data
        if ln.startswith("f "):
            corners = ["/".join(str(int(i) - (n_v if k < 2 else 6) - 1) for k, i in enumerate(c.split("/"))) for c in ln.split()[1:]]
            ln = "f " + " ".join(corners)
        rel.append(ln)
    (tmp_path / "rel.obj").write_text("\n".join(rel) + "\n")
    big = np.zeros((64, 2048, 3), np.uint8)
    big[:, :, 2] = 220  # all blue
    Image.fromarray(big).save(tmp_path / "big.png")
    (tmp_path / "tex.mtl").write_text("newmtl t\nKd 1 1 1\nmap_Kd big.png\n")
    (tmp_path / "tex.obj").write_text(_cube_obj({n: "t" for n in _FACES}, "tex.mtl"))
    (tmp_path / "shapes.urdf").write_text("""<robot name="shapes">
  <material name="red"><color rgba="0.9 0.1 0.1 1"/></material>
  <link name="base">
    <visual><geometry><box size="0.2 0.2 0.2"/></geometry><material name="red"/></visual>
    <visual><origin xyz="0 0.3 0"/><geometry><cylinder radius="0.1" length="0.2"/></geometry>
      <material name="green"><color rgba="0.1 0.8 0.1 1"/></material></visual>
    <visual><origin xyz="0 -0.3 0"/><geometry><mesh filename="cube.stl" scale="0.2 0.2 0.2"/></geometry>
      <material name="yellow"><color rgba="0.9 0.8 0.1 1"/></material></visual>
    <visual><origin xyz="0 0 0.3"/><geometry><mesh filename="rel.obj" scale="0.2 0.2 0.2"/></geometry>
      <material name="green"/></visual>
    <visual><origin xyz="0 0 -0.3"/><geometry><mesh filename="tex.obj" scale="0.2 0.2 0.2"/></geometry></visual>
  </link>
</robot>""")
    with R.SceneRenderer(tmp_path / "shapes.urdf", size=SMALL) as r:
        img = r.render("front")
        assert any("downscaled" in n for n in r.notes)
    assert count(img, "red") > 200 and count(img, "yellow") > 200 and count(img, "blue") > 200
    assert count(img, "green") > 700  # cylinder + the material-less OBJ on top (named material)
    # the OBJ on top (negative indices) is drawn: the silhouette reaches above the box
    assert bbox(object_mask(img))[0] < 0.3 * SMALL[1]
    # a URDF with collision shapes only is drawn from them
    (tmp_path / "col.urdf").write_text(
        "<robot name='c'><link name='a'><collision><geometry><box size='0.1 0.3 0.2'/></geometry></collision></link></robot>"
    )
    with R.SceneRenderer(tmp_path / "col.urdf", size=SMALL) as r:
        assert object_mask(r.render("front")).mean() > 0.2
        assert any("collision" in n for n in r.notes)


def test_read_joint_state_and_resolve_urdf(box, tmp_path):
    f = tmp_path / "s.json"
    f.write_text(json.dumps({"initial_joint_positions": {"lid_hinge": 0.3}}))
    assert R.read_joint_state(f) == {"lid_hinge": 0.3}
    for bad in ('{"lid_hinge": 0.3}', '{"initial_joint_positions": {"a": "x"}}', "{", '{"initial_joint_positions": {"a": true}}'):
        f.write_text(bad)
        with pytest.raises(ValueError):
            R.read_joint_state(f)
    assert R.resolve_urdf(box.parent) == box
    assert R.resolve_urdf(box) == box
    with pytest.raises(FileNotFoundError):
        R.resolve_urdf(tmp_path / "nothing")


def test_fit_camera_frames_points_at_any_scale():
    rng = np.random.default_rng(0)
    pts = rng.normal(size=(500, 3)) * [0.3, 0.1, 0.5] + [1.0, -2.0, 0.5]
    for view in R.VIEWS.values():
        cams = [R.fit_camera(pts * k, view.direction()) for k in (0.01, 1.0, 100.0)]
        for k, cam in zip((0.01, 1.0, 100.0), cams):
            # project: every point inside the fill fraction of the frame
            f = cam.target - cam.eye
            dist = np.linalg.norm(f)
            f /= dist
            r = np.cross(f, cam.up)
            r /= np.linalg.norm(r)
            u = np.cross(r, f)
            rel = pts * k - cam.eye
            depth = rel @ f
            X, Y = (rel @ r) / depth, (rel @ u) / depth
            t = math.tan(math.radians(cam.fov_deg) / 2)
            assert np.abs(X).max() <= t * R.FILL * 1.001 and np.abs(Y).max() <= t * R.FILL * 1.001
            assert max(np.abs(X).max(), np.abs(Y).max()) > 0.98 * t * R.FILL  # tight
            assert cam.near < depth.min() and cam.far > depth.max()
            assert np.allclose(cam.eye / k, cams[1].eye, rtol=1e-6, atol=1e-9)


def test_cli_render(box, tmp_path):
    from asset2sim.cli import main

    state = tmp_path / "initial_state.json"
    state.write_text(json.dumps({"initial_joint_positions": {"lid_hinge": 1.0}}))
    out = tmp_path / "views"
    assert main(["render", str(box.parent), "--state", str(state), "--out", str(out), "--size", "64", "64"]) == 0
    names = sorted(p.name for p in out.iterdir())
    assert names == sorted([f"{v}.png" for v in R.DEFAULT_VIEWS] + ["contact_sheet.png"])
    state.write_text(json.dumps({"initial_joint_positions": {"hinge_x": 1.0}}))
    assert main(["render", str(box.parent), "--state", str(state), "--out", str(tmp_path / "v2")]) == 2
    assert not (tmp_path / "v2").exists()
    assert main(["render", str(box.parent), "--views", "front,side", "--out", str(tmp_path / "v3")]) == 2
    assert main(["render", str(tmp_path / "none"), "--out", str(tmp_path / "v4")]) == 2


# ------------------------------------------------------------ real objects
def _wood(img: np.ndarray) -> int:
    r, g, b = (img[..., i].astype(int) for i in range(3))
    return int(((r - b > 40) & (r > g) & (g > b)).sum())


def test_real_chest_lid_and_textures(shared_dataset):
    """PartNet-Mobility 100221 (treasure chest): wood texture is drawn (not the
    flat white PyBullet gives its multi-material OBJs), the lock faces the
    front camera, and closing the lid changes the image."""
    urdf = shared_dataset / "100221" / "mobility.urdf"
    with R.SceneRenderer(urdf, size=(128, 128)) as r:
        opened = {v: r.render(v) for v in ("front", "left", "top")}
        r.set_joint_positions({"joint_0": -1.0})
        closed = {v: r.render(v) for v in ("front", "left", "top")}
    for img in (*opened.values(), *closed.values()):
        assert 0.15 < object_mask(img).mean() < 0.9
    # the inside of the open chest is wood (split multi-material OBJs)
    assert _wood(opened["front"]) > 0.15 * 128 * 128
    for v in opened:
        assert np.abs(opened[v].astype(int) - closed[v].astype(int)).mean() > 8, v
    # closed lid: lower silhouette in the side view
    yo0, yo1, xo0, xo1 = bbox(object_mask(opened["left"]))
    yc0, yc1, xc0, xc1 = bbox(object_mask(closed["left"]))
    assert (yc1 - yc0) / (xc1 - xc0) < (yo1 - yo0) / (xo1 - xo0)


def test_real_cabinet_drawer_front_is_minus_x(shared_dataset):
    """PartNet-Mobility 19179 (two-drawer cabinet): the drawers slide out along
    -x, toward the front camera: opening one widens the left view and puts the
    drawer at the bottom of the top view."""
    urdf = shared_dataset / "19179" / "mobility.urdf"
    closed = R.render_views(urdf, {}, views=("left", "top"), size=(128, 128))
    opened = R.render_views(urdf, {"joint_0": 0.6}, views=("left", "top"), size=(128, 128))
    y0, y1, x0, x1 = bbox(object_mask(closed["left"]))
    yo0, yo1, xo0, xo1 = bbox(object_mask(opened["left"]))
    assert (xo1 - xo0) / (yo1 - yo0) > 1.15 * (x1 - x0) / (y1 - y0)
    # top view (front at the bottom of the image): the narrower drawer sticks
    # out below the body, so the silhouette's bottom rows are narrower
    for mask, narrower in ((object_mask(closed["top"]), False), (object_mask(opened["top"]), True)):
        rows = np.nonzero(mask.any(axis=1))[0]
        widths = mask[rows.min() : rows.max() + 1].sum(axis=1)
        assert bool(np.median(widths[-8:]) < 0.85 * np.median(widths[:8])) is narrower


# ------------------------------------------------ the modules render.py uses
def test_public_names_stay_importable_from_render():
    assert R.fit_camera is render_camera.fit_camera and R.VIEWS is VIEWS
    assert R.write_png is render_images.write_png and R.BACKGROUND == render_images.BACKGROUND
    assert R.DEFAULT_COLOR == render_meshes.DEFAULT_COLOR
    for name in R.__all__:
        assert hasattr(R, name), name


def test_split_obj_keeps_every_face_of_a_real_multi_material_obj(shared_dataset, tmp_path):
    """100221's original-18.obj switches material 4 times: it is split into one
    OBJ per material whose faces together are exactly the original's."""
    src = shared_dataset / "100221" / "textured_objs" / "original-18.obj"
    before = src.read_bytes()
    info = split_obj(src, tmp_path, "m0000", TextureLinks(tmp_path, 4096))
    assert src.read_bytes() == before  # inputs are never written
    scan = mesh_io.scan_obj_text(src.read_text(encoding="utf-8", errors="replace"))
    n_faces = sum(len(f) for m, f in scan.faces.items() if m is not None)
    assert len(info.parts) > 1 and all(p.parent == tmp_path for p in info.parts)
    split_faces = sum(sum(1 for ln in p.read_text().splitlines() if ln.startswith("f ")) for p in info.parts)
    assert split_faces == n_faces
    assert info.vertices.shape == (len(scan.vertex_lines), 3)
    for p in info.parts:  # each part names its own one-material MTL
        text = p.read_text()
        assert text.count("usemtl ") == 1 and (tmp_path / text.splitlines()[0].split()[1]).is_file()


def test_prepare_scene_writes_a_render_only_urdf(shared_dataset, tmp_path):
    """103275: the render-only URDF has no collisions or inertials, every mesh
    it names exists, and the visual points of each link are finite."""
    scene = prepare_scene(shared_dataset / "103275" / "mobility.urdf", tmp_path, texture_max=128)
    model = read_urdf(scene.urdf, mode="lenient")
    assert scene.urdf.parent == tmp_path
    assert all(not ln.collisions and ln.inertial is None for ln in model.links.values())
    meshes = [Path(v.filename) for ln in model.links.values() for v in ln.visuals if v.kind == "mesh"]
    assert meshes and all(p.is_absolute() and p.is_file() for p in meshes)
    assert set(scene.link_points) <= set(model.links)
    assert all(np.isfinite(p).all() and p.shape[1] == 3 for p in scene.link_points.values())
    assert any("downscaled" in n for n in scene.notes)


def test_view_spec_names_the_known_views():
    assert view_spec("top") is VIEWS["top"]
    custom = ViewSpec("low", 45.0, 5.0)
    assert view_spec(custom) is custom
    assert np.isclose(np.linalg.norm(custom.direction()), 1.0)
    with pytest.raises(KeyError, match="known views"):
        view_spec("underneath")


def test_an_obj_drawn_in_several_scenes_is_scanned_once(tmp_path, monkeypatch):
    """A refine draws the same visual files in several scenes (its input, the output's byte copies, the clips):
    the second copy of a two-material OBJ takes the first one's scan, still gets its own split files in its own
    work folder, equal to the first's, and read-only vertices; other text is scanned; the memo keeps at most
    its size in characters, the oldest dropped first."""
    scans = []
    real = mesh_io.scan_obj_text
    monkeypatch.setattr(mesh_io, "scan_obj_text", lambda text: scans.append(len(text)) or real(text))
    obj = (f"# {tmp_path.name}\nmtllib m.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\n"
           "usemtl red\nf 1 2 3\nusemtl blue\nf 1 2 4\nf 1 3 4\n")
    room = len(obj) + len(obj + "f 2 3 4\n") + 5  # the first two texts, not a third
    monkeypatch.setattr(render_meshes, "_SCANS", cachetools.FIFOCache(maxsize=room, getsizeof=render_meshes._scan_size))
    folders = []
    for name in ("input", "output"):
        d = tmp_path / name
        (d / "work").mkdir(parents=True)
        (d / "m.mtl").write_text("newmtl red\nKd 1 0 0\nnewmtl blue\nKd 0 0 1\n")
        (d / "a.obj").write_text(obj)
        folders.append(d)
    infos = [split_obj(d / "a.obj", d / "work", "m0000", TextureLinks(d / "work", 4096)) for d in folders]
    assert len(scans) == 1
    assert [p.parent for p in infos[1].parts] == [folders[1] / "work"] * 2
    assert [p.read_text() for p in infos[0].parts] == [p.read_text() for p in infos[1].parts]
    assert infos[0].vertices is infos[1].vertices and not infos[1].vertices.flags.writeable
    (folders[1] / "a.obj").write_text(obj + "f 2 3 4\n")
    split_obj(folders[1] / "a.obj", folders[1] / "work", "m0001", TextureLinks(folders[1] / "work", 4096))
    assert len(scans) == 2
    assert len(render_meshes._SCANS) == 2
    (folders[1] / "a.obj").write_text(obj + "# a third text\n")
    split_obj(folders[1] / "a.obj", folders[1] / "work", "m0002", TextureLinks(folders[1] / "work", 4096))
    assert len(scans) == 3 and len(render_meshes._SCANS) == 1  # both earlier texts dropped
    split_obj(folders[0] / "a.obj", folders[0] / "work", "m0003", TextureLinks(folders[0] / "work", 4096))
    assert len(scans) == 4
