"""Mesh analysis (``asset2sim.tasks.geometry.analyze``) against shapes with known
volume, center of mass and inertia, built here, and sanity checks on real
PartNet-Mobility objects.

Analytic references (per kg, about the center of mass):
- solid box a x b x c: I_xx = (b^2 + c^2) / 12;
- closed cube surface of side a: I = a^2 * 5/18 (each face: plate + parallel axis);
- thin rectangular plate a x b in the xy plane: I = diag(b^2, a^2, a^2 + b^2) / 12;
- tube with radii r < R, length L (axis z): I_zz = (R^2 + r^2) / 2,
  I_xx = (3 (R^2 + r^2) + L^2) / 12; open cylindrical surface: I_zz = r^2,
  I_xx = r^2 / 2 + L^2 / 12;
- union of disjoint boxes: volumes, centroids and box inertias added with the
  parallel-axis theorem (independent of any mesh).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from asset2sim import frames, mesh_io
from tests.helpers import tree_hashes
from asset2sim.schemas.asset import AssetDescription, GeometryRef, LinkDesc, Origin
from asset2sim.tasks.geometry import analyze as an
from asset2sim.tasks.geometry.analyze import MeshAnalysisError, analyze_asset, analyze_link
from tests.conftest import SHARED, needs_shared

# ---------------------------------------------------------------- helpers


def write_obj(path: Path, vertices, faces, *, style: str = "plain") -> Path:
    """Write an OBJ. style: plain ("f 1 2 3"), vn ("f 1//1 ..."), vtvn
    ("f 1/1/1 ..."), crlf (Windows line ends), negative (relative indices)."""
    v = np.asarray(vertices, float)
    f = np.asarray(faces, int)
    lines = ["# test mesh", "mtllib missing.mtl", "o part"]
    lines += [f"v {x:.17g} {y:.17g} {z:.17g}" for x, y, z in v]
    if style in ("vn", "vtvn"):
        lines += ["vn 0 0 1"] * len(v)
    if style == "vtvn":
        lines += ["vt 0 0"] * len(v)
    lines.append("usemtl none")
    for tri in f:
        if style == "vn":
            lines.append("f " + " ".join(f"{i + 1}//{i + 1}" for i in tri))
        elif style == "vtvn":
            lines.append("f " + " ".join(f"{i + 1}/{i + 1}/{i + 1}" for i in tri))
        elif style == "negative":
            lines.append("f " + " ".join(str(i - len(v)) for i in tri))
        else:
            lines.append("f " + " ".join(str(i + 1) for i in tri))
    sep = "\r\n" if style == "crlf" else "\n"
    path.write_text(sep.join(lines) + sep)
    return path


def mesh_ref(path: Path, *, role="collision", xyz=(0, 0, 0), rpy=(0, 0, 0), scale=(1, 1, 1)) -> GeometryRef:
    return GeometryRef(
        role=role,
        kind="mesh",
        filename=path.name,
        path=path,
        origin=Origin(xyz=tuple(map(float, xyz)), rpy=tuple(map(float, rpy))),
        scale=tuple(map(float, scale)),
    )


def link_of(refs, name="part", role="collision") -> LinkDesc:
    refs = list(refs)
    return LinkDesc(name=name, collisions=refs) if role == "collision" else LinkDesc(name=name, visuals=refs)


def grid_solid(xs, ys, zs, occupied):
    """Watertight, outward-oriented surface of a union of cells of the
    rectilinear grid xs x ys x zs (breaks, m); occupied (nx, ny, nz) bool.
    Cells share grid nodes, so there are no T-junctions."""
    xs, ys, zs = (np.asarray(a, float) for a in (xs, ys, zs))
    occ = np.asarray(occupied, bool)
    n = [len(xs), len(ys), len(zs)]
    node = lambda i, j, k: (i * n[1] + j) * n[2] + k  # noqa: E731
    verts = np.array([[x, y, z] for x in xs for y in ys for z in zs])
    faces = []
    shape = occ.shape
    for idx in np.argwhere(occ):
        for a in range(3):
            b, c = (a + 1) % 3, (a + 2) % 3
            for side in (0, 1):
                nb = idx.copy()
                nb[a] += 1 if side else -1
                if 0 <= nb[a] < shape[a] and occ[tuple(nb)]:
                    continue
                corners = []
                for db, dc in ((0, 0), (1, 0), (1, 1), (0, 1)):
                    p = idx.copy()
                    p[a] += side
                    p[b] += db
                    p[c] += dc
                    corners.append(node(*p))
                if not side:
                    corners = corners[::-1]
                faces += [[corners[0], corners[1], corners[2]], [corners[0], corners[2], corners[3]]]
    return verts, np.array(faces)


def boxes_moments(boxes):
    """Exact volume, com and per-kg inertia about com of disjoint boxes,
    each (lo (3,), hi (3,))."""
    vol, first, second = 0.0, np.zeros(3), np.zeros((3, 3))
    for lo, hi in boxes:
        lo, hi = np.asarray(lo, float), np.asarray(hi, float)
        d = hi - lo
        v = float(np.prod(d))
        c = 0.5 * (lo + hi)
        vol += v
        first += v * c
        second += v * (np.diag(d * d / 12.0) + np.outer(c, c))
    com = first / vol
    cov = second / vol - np.outer(com, com)
    return vol, com, np.trace(cov) * np.eye(3) - cov


def cell_boxes(xs, ys, zs, occupied):
    return [
        ((xs[i], ys[j], zs[k]), (xs[i + 1], ys[j + 1], zs[k + 1]))
        for i, j, k in np.argwhere(np.asarray(occupied, bool))
    ]


def box_mesh(a, b, c):
    return grid_solid([-a / 2, a / 2], [-b / 2, b / 2], [-c / 2, c / 2], np.ones((1, 1, 1)))


def tube_mesh(r_in, r_out, length, n=256, caps=True, inner=True, outer=True):
    """Watertight tube (axis z, centred) or, with caps=False/inner=False, an
    open cylindrical surface of radius r_out."""
    t = 2 * np.pi * np.arange(n) / n
    ring = lambda r, z: np.stack([r * np.cos(t), r * np.sin(t), np.full(n, z)], 1)  # noqa: E731
    verts = np.concatenate([ring(r_out, -length / 2), ring(r_out, length / 2), ring(r_in, -length / 2), ring(r_in, length / 2)])
    ob, ot, ib, it = 0, n, 2 * n, 3 * n
    faces = []
    for i in range(n):
        j = (i + 1) % n
        if outer:
            faces += [[ob + i, ob + j, ot + j], [ob + i, ot + j, ot + i]]
        if inner:
            faces += [[ib + i, it + j, ib + j], [ib + i, it + i, it + j]]
        if caps:
            faces += [[ot + i, ot + j, it + j], [ot + i, it + j, it + i]]
            faces += [[ob + i, ib + j, ob + j], [ob + i, ib + i, ib + j]]
    faces = np.array(faces)
    used = np.unique(faces)
    remap = np.zeros(len(verts), int)
    remap[used] = np.arange(len(used))
    return verts[used], remap[faces]


def rot(rpy):
    return frames.rpy_matrix(rpy)


def assert_valid_inertia(i):
    i = np.asarray(i, float)
    assert np.allclose(i, i.T, atol=1e-15)
    ev = np.linalg.eigvalsh(i)
    assert ev[0] > 0
    assert ev[0] + ev[1] > ev[2]


def rel(a, b):
    return float(np.max(np.abs(np.asarray(a, float) - np.asarray(b, float))) / np.max(np.abs(np.asarray(b, float))))


# ----------------------------------------------------------- watertight


def test_watertight_box_exact_with_origin_rotation_and_scale(tmp_path):
    a, b, c = 0.3, 0.2, 0.1
    v, f = box_mesh(1.0, 1.0, 1.0)
    path = write_obj(tmp_path / "box.obj", v, f)
    xyz, rpy = (0.5, -0.2, 1.0), (0.3, -0.7, 1.2)
    g = analyze_link(link_of([mesh_ref(path, xyz=xyz, rpy=rpy, scale=(a, b, c))]))
    assert g.watertight and g.volume_method == "watertight_exact"
    assert g.volume == pytest.approx(a * b * c, rel=1e-12)
    assert g.area == pytest.approx(2 * (a * b + b * c + c * a), rel=1e-12)
    assert np.allclose(g.com, xyz, atol=1e-12)
    r = rot(rpy)
    want_solid = r @ np.diag([b * b + c * c, a * a + c * c, a * a + b * b]) / 12.0 @ r.T
    assert np.allclose(g.inertia_solid, want_solid, rtol=0, atol=1e-12)
    assert g.n_meshes == 1 and g.n_faces == 12
    # the bounding box of the rotated box: corners rotated
    corners = np.array([[sx * a, sy * b, sz * c] for sx in (-0.5, 0.5) for sy in (-0.5, 0.5) for sz in (-0.5, 0.5)])
    world = corners @ r.T + xyz
    assert np.allclose(g.bbox_min, world.min(0)) and np.allclose(g.bbox_max, world.max(0))


def test_closed_cube_surface_shell_inertia(tmp_path):
    a = 0.4
    path = write_obj(tmp_path / "cube.obj", *box_mesh(a, a, a))
    g = analyze_link(link_of([mesh_ref(path)]))
    assert np.allclose(g.inertia_shell, np.eye(3) * a * a * 5.0 / 18.0, rtol=0, atol=1e-13)
    assert np.allclose(g.inertia_solid, np.eye(3) * a * a / 6.0, rtol=0, atol=1e-13)


def test_open_box_five_walls_solid(tmp_path):
    # 0.4 x 0.3 x 0.2 outside, walls t = 0.01, open at the top
    A, B, C, t = 0.4, 0.3, 0.2, 0.01
    xs, ys, zs = [0, t, A - t, A], [0, t, B - t, B], [0, t, C]
    occ = np.ones((3, 3, 2), bool)
    occ[1, 1, 1] = False  # the cavity
    v, f = grid_solid(xs, ys, zs, occ)
    path = write_obj(tmp_path / "tray.obj", v, f, style="vn")
    g = analyze_link(link_of([mesh_ref(path)]))
    vol, com, inertia = boxes_moments(cell_boxes(xs, ys, zs, occ))
    assert vol == pytest.approx(A * B * C - (A - 2 * t) * (B - 2 * t) * (C - t), rel=1e-12)
    assert g.volume_method == "watertight_exact"
    assert g.volume == pytest.approx(vol, rel=1e-10)
    assert np.allclose(g.com, com, atol=1e-12)
    assert rel(g.inertia_solid, inertia) < 1e-9
    # the voxel estimate of the same solid (thin walls: 2.5 voxels) is close
    sm = an.voxel_properties(v, f)
    assert sm.volume == pytest.approx(vol, rel=0.05)
    assert np.linalg.norm(sm.com - com) < 0.01 * A
    assert rel(np.trace(sm.second) * np.eye(3) - sm.second, inertia) < 0.05


def test_voxel_estimate_of_walls_thinner_than_a_voxel():
    # open box with 2 mm walls: 0.7 voxel at the default resolution; the two
    # faces of a wall often fall in the same cell (their separation is kept)
    A, B, C, t = 0.4, 0.3, 0.2, 0.002
    xs, ys, zs = [0, t, A - t, A], [0, t, B - t, B], [0, t, C]
    occ = np.ones((3, 3, 2), bool)
    occ[1, 1, 1] = False
    v, f = grid_solid(xs, ys, zs, occ)
    vol, com, _ = boxes_moments(cell_boxes(xs, ys, zs, occ))
    vols = [an.voxel_properties(v, f, grid_shift=s).volume for s in [(0, 0, 0), (0.3, 0.6, 0.9), (0.5, 0.5, 0.5)]]
    assert np.mean(vols) == pytest.approx(vol, rel=0.08)
    assert all(x == pytest.approx(vol, rel=0.15) for x in vols)


def test_tilted_zero_thickness_sheet_encloses_nothing(tmp_path):
    a = 0.5
    quad = np.array([[0, 0, 0], [a, 0, 0], [a, a, 0], [0, a, 0]], float)
    path = write_obj(tmp_path / "sheet.obj", quad, [[0, 1, 2], [0, 2, 3]])
    g = analyze_link(link_of([mesh_ref(path, rpy=(0.3, 0.5, 0.2))]))
    assert g.volume_method == "voxel_fill+open_shell"
    assert g.volume < 0.02 * a * a * a / 96
    assert g.area == pytest.approx(a * a, rel=1e-12)


def test_a_sheet_drawn_twice_counts_its_area_once(tmp_path):
    """PartNet-Mobility draws an open surface twice, once facing each way (every open-shell link of the
    dev set); the area a shell's mass takes counts the sheet once: the mass of a 0.5 x 0.5 sheet of
    2.5 mm ABS, not of two. The same triangles on separate vertices and in another winding are found."""
    a = 0.5
    quad = np.array([[0, 0, 0], [a, 0, 0], [a, a, 0], [0, a, 0]], float)
    twice = np.vstack([quad, quad])
    path = write_obj(tmp_path / "sheet.obj", twice, [[0, 1, 2], [0, 2, 3], [6, 5, 4], [7, 6, 4]])
    g = analyze_link(link_of([mesh_ref(path)]))
    assert g.volume_method.endswith("open_shell") and g.area == pytest.approx(a * a, rel=1e-12)
    one = analyze_link(link_of([mesh_ref(write_obj(tmp_path / "once.obj", quad, [[0, 1, 2], [0, 2, 3]]))]))
    assert np.allclose(g.inertia_shell, one.inertia_shell) and np.allclose(g.com, one.com)


@needs_shared
def test_the_door_leaf_of_8877_is_one_sheet():
    """Door 8877's leaf: 4 triangles, two drawn over the other two; its area is the leaf's one side."""
    from asset2sim.tasks.ingest.extract import extract_asset

    asset = extract_asset(SHARED / "8877")
    g = analyze_link(asset.link("link_1"))
    w, h = sorted(g.extents)[1:]
    assert g.area == pytest.approx(w * h, rel=1e-3)


@needs_shared
def test_row_ranks_are_numpys_row_unique_on_a_dev_mesh():
    """single_sided and the vertex merge rank rows by a lexicographic sort: the inverse numpy's row-unique
    (np.unique axis=0) gives, on every mesh of door 8877 (the sheet drawn twice included), and the faces kept the same."""
    from asset2sim.tasks.geometry import moments

    for path in sorted((SHARED / "8877" / "textured_objs").glob("*.obj")):
        m = mesh_io.read_mesh(path)
        key = np.round(m.vertices * 1e9).astype(np.int64)
        inverse = np.unique(key, axis=0, return_inverse=True)[1].ravel()
        assert np.array_equal(moments._row_labels(key), inverse), path.name
        _, first = np.unique(np.sort(inverse[m.faces], axis=1), axis=0, return_index=True)
        assert np.array_equal(moments.single_sided(m.vertices, m.faces), m.faces[np.sort(first)]), path.name


def test_thin_watertight_slab_solid_values(tmp_path):
    a, b, t = 0.5, 0.3, 0.004
    path = write_obj(tmp_path / "slab.obj", *box_mesh(a, b, t))
    g = analyze_link(link_of([mesh_ref(path, xyz=(0, 0, 0.1))]))
    assert g.volume_method == "watertight_exact"
    assert g.volume == pytest.approx(a * b * t, rel=1e-12)
    assert np.allclose(g.com, (0, 0, 0.1), atol=1e-12)
    assert np.allclose(np.diag(g.inertia_solid), np.array([b * b + t * t, a * a + t * t, a * a + b * b]) / 12, rtol=1e-10)
    assert_valid_inertia(g.inertia_solid)


def test_hollow_cylinder_watertight_tube(tmp_path):
    r, R, L = 0.04, 0.05, 0.3
    v, f = tube_mesh(r, R, L, n=512)
    path = write_obj(tmp_path / "tube.obj", v, f)
    g = analyze_link(link_of([mesh_ref(path)]))
    assert g.watertight and g.volume_method == "watertight_exact"
    assert g.volume == pytest.approx(math.pi * (R * R - r * r) * L, rel=1e-4)
    i = np.asarray(g.inertia_solid)
    assert i[2, 2] == pytest.approx((R * R + r * r) / 2, rel=1e-4)
    assert i[0, 0] == pytest.approx((3 * (R * R + r * r) + L * L) / 12, rel=1e-4)
    assert np.allclose(g.com, 0, atol=1e-12)


def test_open_tube_surface_shell(tmp_path):
    r, L = 0.05, 0.3
    v, f = tube_mesh(r * 0.5, r, L, n=512, caps=False, inner=False)
    path = write_obj(tmp_path / "sleeve.obj", v, f)
    g = analyze_link(link_of([mesh_ref(path)]))
    assert not g.watertight
    assert g.volume_method.endswith("open_shell")
    assert g.volume < 0.02 * math.pi * r * r * L
    assert g.area == pytest.approx(2 * math.pi * r * L, rel=1e-4)
    i = np.asarray(g.inertia_shell)
    assert i[2, 2] == pytest.approx(r * r, rel=1e-4)
    assert i[0, 0] == pytest.approx(r * r / 2 + L * L / 12, rel=1e-4)
    assert np.allclose(g.com, 0, atol=1e-9)
    assert np.allclose(g.inertia_solid, g.inertia_shell)


def test_zero_thickness_plate_shell_values_regularised(tmp_path):
    a, b = 0.6, 0.4
    quad = np.array([[-a / 2, -b / 2, 0], [a / 2, -b / 2, 0], [a / 2, b / 2, 0], [-a / 2, b / 2, 0]])
    path = write_obj(tmp_path / "plate.obj", quad, [[0, 1, 2], [0, 2, 3]])
    g = analyze_link(link_of([mesh_ref(path, xyz=(0.1, 0.2, 0.3))]))
    assert g.volume_method.endswith("open_shell")
    assert g.volume == pytest.approx(0.0, abs=1e-12)
    assert g.area == pytest.approx(a * b, rel=1e-12)
    assert np.allclose(g.com, (0.1, 0.2, 0.3), atol=1e-12)
    want = np.diag([b * b, a * a, a * a + b * b]) / 12
    assert np.allclose(g.inertia_shell, want, rtol=1e-5, atol=1e-9)
    assert_valid_inertia(g.inertia_shell)
    assert_valid_inertia(g.inertia_solid)
    assert any("regularisation" in n for n in g.notes)


# --------------------------------------------------------------- soup


def cube_soup_pieces(a, gap):
    """Six separate quads (own vertices, duplicated along the edges), each
    shrunk by ``gap`` x a/2 so neighbouring faces do not touch."""
    out = []
    h, s = a / 2, a / 2 * (1 - gap)
    for ax in range(3):
        u, w = [k for k in range(3) if k != ax]
        for sgn in (-1, 1):
            q = np.zeros((4, 3))
            q[:, ax] = sgn * h
            q[:, u] = [-s, s, s, -s]
            q[:, w] = [-s, -s, s, s]
            tris = [[0, 1, 2], [0, 2, 3]] if sgn > 0 else [[0, 2, 1], [0, 3, 2]]
            out.append((q, np.array(tris)))
    return out


@pytest.mark.parametrize("gap,rpy", [(0.0, (0, 0, 0)), (0.01, (0.4, 1.1, -0.3)), (0.02, (2.0, -0.5, 0.9))])
def test_non_watertight_cube_soup(tmp_path, gap, rpy):
    a = 0.25
    xyz = (0.3, -0.1, 0.05)
    refs = []
    for i, (q, tris) in enumerate(cube_soup_pieces(a, gap)):
        # duplicated vertices inside a piece too: every triangle gets its own
        v = q[tris].reshape(-1, 3)
        path = write_obj(tmp_path / f"face{i}.obj", v, np.arange(6).reshape(2, 3), style="vtvn" if i % 2 else "plain")
        refs.append(mesh_ref(path, xyz=xyz, rpy=rpy))
    g = analyze_link(link_of(refs, role="visual"), )
    assert not g.watertight and g.volume_method == "voxel_fill"
    assert g.n_meshes == 6
    assert g.volume == pytest.approx(a**3, rel=0.03)
    assert np.linalg.norm(np.subtract(g.com, xyz)) < 0.01 * a
    r = rot(rpy)
    assert rel(g.inertia_solid, r @ np.eye(3) * a * a / 6 @ r.T) < 0.03
    shell = (1 - gap) ** 2 * 5 / 18 * a * a  # shrunk faces: plate part smaller
    assert np.allclose(np.linalg.eigvalsh(g.inertia_shell), shell, rtol=0.03)
    assert g.volume <= np.prod(g.extents) * 1.0001


def test_voxel_estimate_independent_of_grid_offset_and_accurate_for_sphere():
    import trimesh

    sph = trimesh.creation.icosphere(subdivisions=4, radius=0.2)
    v, f = np.asarray(sph.vertices), np.asarray(sph.faces)
    vols = []
    for shift in [(0, 0, 0), (0.5, 0.5, 0.5), (0.25, 0.7, 0.1)]:
        sm = an.voxel_properties(v, f, grid_shift=shift)
        vols.append(sm.volume)
        assert np.linalg.norm(sm.com) < 1e-3
        inertia = np.trace(sm.second) * np.eye(3) - sm.second
        assert rel(inertia, np.eye(3) * 0.4 * 0.04 * (sph.volume / (4 / 3 * math.pi * 0.008)) ** (2 / 3)) < 0.02
    assert np.allclose(vols, sph.volume, rtol=0.01)
    half = an.voxel_properties(v, f, subvoxel=False, grid_shift=(0.2, 0.4, 0.6))  # the half-cell rule
    assert half.volume == pytest.approx(sph.volume, rel=0.01)


def test_overlapping_closed_parts_use_voxel_union(tmp_path):
    # two closed cubes overlapping by half: union 1.5 a^3, not 2 a^3
    a = 0.2
    v, f = box_mesh(a, a, a)
    p = write_obj(tmp_path / "c.obj", v, f)
    g = analyze_link(link_of([mesh_ref(p), mesh_ref(p, xyz=(a / 2, 0, 0))]))
    assert g.volume_method == "voxel_union"
    assert g.volume == pytest.approx(1.5 * a**3, rel=0.03)
    assert g.com[0] == pytest.approx(a / 4, abs=0.01 * a)
    # disjoint closed parts stay exact
    g2 = analyze_link(link_of([mesh_ref(p), mesh_ref(p, xyz=(2 * a, 0, 0))]))
    assert g2.volume_method == "watertight_exact"
    assert g2.volume == pytest.approx(2 * a**3, rel=1e-12)
    assert g2.com[0] == pytest.approx(a, rel=1e-12)


def test_inside_out_and_mirrored_meshes_give_positive_volume(tmp_path):
    v, f = box_mesh(0.1, 0.2, 0.3)
    flipped = write_obj(tmp_path / "inv.obj", v, f[:, ::-1])
    g = analyze_link(link_of([mesh_ref(flipped)]))
    assert g.volume == pytest.approx(0.006, rel=1e-12)
    assert any("inside-out" in n for n in g.notes)
    normal = write_obj(tmp_path / "ok.obj", v, f)
    g2 = analyze_link(link_of([mesh_ref(normal, scale=(-1, 1, 1))]))
    assert g2.volume == pytest.approx(0.006, rel=1e-12)
    assert not any("inside-out" in n for n in g2.notes)


# ----------------------------------------------------------- primitives


def test_primitives_analytic_and_rotated():
    r, L = 0.05, 0.4
    cyl = GeometryRef(role="collision", kind="cylinder", radius=r, length=L, origin=Origin(xyz=(0, 0, 1), rpy=(math.pi / 2, 0, 0)))
    g = analyze_link(LinkDesc(name="rod", collisions=[cyl]))
    assert g.volume_method == "analytic_primitive" and g.watertight
    assert g.volume == pytest.approx(math.pi * r * r * L, rel=1e-12)
    assert g.area == pytest.approx(2 * math.pi * r * (r + L), rel=1e-12)
    i = np.asarray(g.inertia_solid)  # axis now along y
    assert i[1, 1] == pytest.approx(r * r / 2, rel=1e-9)
    assert i[0, 0] == pytest.approx((3 * r * r + L * L) / 12, rel=1e-9)
    assert np.allclose(g.com, (0, 0, 1))
    assert g.bbox_max[1] == pytest.approx(L / 2, rel=1e-6)

    sph = GeometryRef(role="visual", kind="sphere", radius=0.1)
    gs = analyze_link(LinkDesc(name="ball", visuals=[sph]))
    assert gs.volume == pytest.approx(4 / 3 * math.pi * 1e-3, rel=1e-12)
    assert np.allclose(gs.inertia_solid, np.eye(3) * 0.4 * 0.01)
    assert np.allclose(gs.inertia_shell, np.eye(3) * 2 / 3 * 0.01)

    box = GeometryRef(role="collision", kind="box", size=(0.3, 0.2, 0.1))
    gb = analyze_link(LinkDesc(name="b", collisions=[box]))
    mesh_equiv = an.surface_properties(*box_mesh(0.3, 0.2, 0.1))
    assert gb.area == pytest.approx(mesh_equiv[0], rel=1e-12)
    cov = mesh_equiv[2]
    assert np.allclose(gb.inertia_shell, np.trace(cov) * np.eye(3) - cov, atol=1e-14)

    # two primitives: tessellated, disjoint closed parts, exact up to tessellation
    g2 = analyze_link(LinkDesc(name="two", collisions=[box, GeometryRef(role="collision", kind="sphere", radius=0.05, origin=Origin(xyz=(1, 0, 0)))]))
    assert g2.volume_method == "watertight_exact"
    assert g2.volume == pytest.approx(0.006 + 4 / 3 * math.pi * 0.05**3, rel=1e-3)


# ------------------------------------------------------------ IO, errors


@pytest.mark.parametrize("style", ["plain", "vn", "vtvn", "crlf", "negative"])
def test_obj_reader_styles(tmp_path, style):
    v, f = box_mesh(0.1, 0.2, 0.3)
    path = write_obj(tmp_path / f"b_{style}.obj", v, f, style=style)
    mesh = mesh_io.read_mesh(path)
    rv, rf = mesh.vertices, mesh.faces
    assert np.allclose(rv, v) and np.array_equal(rf, f)


def test_obj_reader_polygons_comments_and_colours(tmp_path):
    path = tmp_path / "poly.obj"
    path.write_text(
        "v 0 0 0 1 0 0\nv 1 0 0 1 0 0\nv 1 1 0 1 0 0\nv 0 1 0 1 0 0  # coloured\n"
        "f 1 2 3 4\n# comment\nf 1/1 2/2 3/3\nl 1 2\n"
    )
    mesh = mesh_io.read_mesh(path)
    v, f = mesh.vertices, mesh.faces
    assert v.shape == (4, 3)
    assert f.tolist() == [[0, 1, 2], [0, 2, 3], [0, 1, 2]]


def test_bad_faces_and_nan_vertices_dropped_with_note(tmp_path):
    v, f = box_mesh(0.2, 0.2, 0.2)
    v = np.vstack([v, [np.nan, 0, 0]])
    f = np.vstack([f, [[0, 1, len(v) - 1], [0, 0, 1], [0, 1, 999]]])
    path = write_obj(tmp_path / "dirty.obj", v, f)
    before = tree_hashes(tmp_path)
    g = analyze_link(link_of([mesh_ref(path)]))
    assert g.volume == pytest.approx(0.008, rel=1e-12)  # still watertight after cleaning
    text = " ".join(g.notes)
    assert "non-finite" in text and "repeated vertex" in text and "out-of-range" in text
    assert "dirty.obj" in text
    assert tree_hashes(tmp_path) == before  # inputs never modified


def test_unreadable_piece_is_noted_when_others_are_usable(tmp_path):
    good = write_obj(tmp_path / "good.obj", *box_mesh(0.1, 0.1, 0.1))
    missing = tmp_path / "missing.obj"
    g = analyze_link(link_of([mesh_ref(good), mesh_ref(missing)], name="lid"))
    assert g.n_meshes == 1
    assert any("missing.obj" in n for n in g.notes)


def test_no_usable_geometry_raises_naming_link_and_file(tmp_path):
    bad = tmp_path / "garbage.obj"
    bad.write_text("v a b c\nf 1 2 3\n")
    with pytest.raises(MeshAnalysisError) as err:
        analyze_link(link_of([mesh_ref(bad), mesh_ref(tmp_path / "gone.obj")], name="door"))
    msg = str(err.value)
    assert "'door'" in msg and "garbage.obj" in msg and "gone.obj" in msg
    assert isinstance(err.value, ValueError)

    empty = tmp_path / "empty.obj"
    empty.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\n")
    with pytest.raises(MeshAnalysisError, match="empty.obj.*no faces"):
        analyze_link(link_of([mesh_ref(empty)], name="lid"))

    line = write_obj(tmp_path / "line.obj", [[0, 0, 0], [1, 0, 0], [2, 0, 0]], [[0, 1, 2]])
    with pytest.raises(MeshAnalysisError, match="'rod'.*degenerate"):
        analyze_link(link_of([mesh_ref(line)], name="rod"))


def test_link_without_geometry_and_collision_preferred(tmp_path):
    assert analyze_link(LinkDesc(name="base")) is None
    big = write_obj(tmp_path / "big.obj", *box_mesh(1, 1, 1))
    small = write_obj(tmp_path / "small.obj", *box_mesh(0.1, 0.1, 0.1))
    link = LinkDesc(name="l", visuals=[mesh_ref(big, role="visual")], collisions=[mesh_ref(small)])
    assert analyze_link(link).volume == pytest.approx(1e-3)
    assert analyze_link(link, prefer="visual").volume == pytest.approx(1.0)
    assert any("collision" in n for n in analyze_link(link).notes)


def test_analyze_asset_shares_cache_and_skips_empty_links(tmp_path, monkeypatch):
    monkeypatch.setenv("ASSET2SIM_CACHE", "off")  # the meshes are read (once): no analysis read back from disk
    p = write_obj(tmp_path / "shared.obj", *box_mesh(0.1, 0.1, 0.1))
    links = [LinkDesc(name="base"), link_of([mesh_ref(p)], name="a"), link_of([mesh_ref(p, xyz=(1, 0, 0))], name="b")]
    asset = AssetDescription(asset_id="t", source_dir=tmp_path, urdf_path=tmp_path / "x.urdf", robot_name="t", links=links, joints=[], root_link="base")
    cache = an.MeshCache()
    out = analyze_asset(asset, cache=cache)
    assert list(out) == ["a", "b"]
    assert len(cache) == 1
    assert out["b"].com[0] == pytest.approx(1.0)


@settings(max_examples=20, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(
    dims=st.tuples(*[st.floats(0.01, 1.0)] * 3),
    rpy=st.tuples(*[st.floats(-math.pi, math.pi)] * 3),
    xyz=st.tuples(*[st.floats(-1, 1)] * 3),
)
def test_property_box_anywhere_exact(tmp_path, dims, rpy, xyz):
    a, b, c = dims
    path = tmp_path / "unit.obj"
    if not path.exists():
        write_obj(path, *box_mesh(1, 1, 1))
    g = analyze_link(link_of([mesh_ref(path, xyz=xyz, rpy=rpy, scale=dims)]))
    assert g.volume == pytest.approx(a * b * c, rel=1e-9)
    r = rot(rpy)
    want = r @ np.diag([b * b + c * c, a * a + c * c, a * a + b * b]) / 12.0 @ r.T
    assert rel(g.inertia_solid, want) < 1e-9
    assert_valid_inertia(g.inertia_solid)
    assert_valid_inertia(g.inertia_shell)


def test_rpy_matrix_matches_urdf_convention():
    # URDF: fixed-axis roll (x), then pitch (y), then yaw (z): R = Rz Ry Rx
    r = frames.rpy_matrix((math.pi / 2, 0, 0))
    assert np.allclose(r @ [0, 1, 0], [0, 0, 1])
    r = frames.rpy_matrix((0, 0, math.pi / 2))
    assert np.allclose(r @ [1, 0, 0], [0, 1, 0])
    r = frames.rpy_matrix((math.pi / 2, 0, math.pi / 2))
    assert np.allclose(r @ [0, 1, 0], [0, 0, 1])  # roll first, then yaw leaves z alone
    assert np.allclose(r @ [1, 0, 0], [0, 1, 0])


# ------------------------------------------------------------ real objects


@needs_shared
@pytest.mark.parametrize("oid", ["103275", "7236", "100221"])
def test_real_objects_sane_and_deterministic(oid):
    from asset2sim.tasks.ingest.extract import extract_asset

    folder = SHARED / oid
    asset = extract_asset(folder)
    geo = analyze_asset(asset)
    assert geo, "no link with geometry"
    assert set(geo) == {l.name for l in asset.links if l.has_geometry}
    for name, g in geo.items():
        ext = np.asarray(g.extents)
        assert np.all(ext >= 0) and g.area > 0
        assert 0 <= g.volume <= np.prod(ext) * 1.0001, name
        if not g.volume_method.endswith("open_shell"):
            assert g.volume > 0, name
            # not the bounding box: the estimate sees the shape
            assert g.volume < 0.9 * np.prod(ext), name
        tol = 1e-9 * max(ext)
        assert np.all(np.asarray(g.com) >= np.asarray(g.bbox_min) - tol), name
        assert np.all(np.asarray(g.com) <= np.asarray(g.bbox_max) + tol), name
        assert_valid_inertia(g.inertia_solid)
        assert_valid_inertia(g.inertia_shell)
        # per-kg inertia cannot exceed (half the bbox diagonal)^2
        assert np.max(np.linalg.eigvalsh(g.inertia_shell)) <= float(ext @ ext), name
    name = max(geo, key=lambda k: geo[k].n_faces)
    again = analyze_link(asset.link(name))
    assert again == geo[name]


@needs_shared
def test_real_object_voxel_estimate_matches_exact_on_closed_collision_pieces():
    """100221's collision geometry is convex pieces (watertight): the voxel
    estimate of the same union is within 3% of the exact volume."""
    from asset2sim.tasks.ingest.extract import extract_asset

    asset = extract_asset(SHARED / "100221")
    for link in asset.links:
        surf = an.link_surface(link)
        if surf is None:
            continue
        exact = an.watertight_properties(surf.vertices, surf.faces)
        assert exact is not None
        vox = an.voxel_properties(surf.vertices, surf.faces)
        assert vox.volume == pytest.approx(exact.volume, rel=0.03)
        size = float(np.max(surf.vertices.max(0) - surf.vertices.min(0)))
        assert np.linalg.norm(vox.com - exact.com) < 0.01 * size


@needs_shared
def test_real_objects_inputs_untouched():
    from asset2sim.tasks.ingest.extract import extract_asset

    folder = SHARED / "103275"
    before = tree_hashes(folder)
    analyze_asset(extract_asset(folder))
    assert tree_hashes(folder) == before


def test_analysis_is_kept_on_disk_by_content(tmp_path, monkeypatch):
    """A link analysed twice with one cache folder: the second result is read
    back equal; a mesh file whose bytes change (same name) is analysed again;
    with the cache off nothing is written."""
    monkeypatch.setenv("ASSET2SIM_CACHE", str(tmp_path / "cache"))
    v, f = box_mesh(1.0, 1.0, 1.0)
    path = write_obj(tmp_path / "box.obj", v, f)
    link = link_of([mesh_ref(path, scale=(0.3, 0.2, 0.1))])
    first = analyze_link(link)
    stored = list((tmp_path / "cache" / an.DISK_KIND).glob("*.npz"))
    assert len(stored) == 1
    calls = []
    real = an._analyze_surface
    monkeypatch.setattr(an, "_analyze_surface", lambda *a: calls.append(1) or real(*a))
    again = analyze_link(link)
    assert again == first and not calls  # read back, not computed
    write_obj(path, v * 2.0, f)  # the same file, other bytes
    bigger = analyze_link(link)
    assert calls == [1] and bigger.volume == pytest.approx(8 * first.volume, rel=1e-12)
    assert len(list((tmp_path / "cache" / an.DISK_KIND).glob("*.npz"))) == 2
    monkeypatch.setenv("ASSET2SIM_CACHE", "off")
    other = write_obj(tmp_path / "other.obj", v * 3.0, f)
    analyze_link(link_of([mesh_ref(other)]))
    assert len(list((tmp_path / "cache" / an.DISK_KIND).glob("*.npz"))) == 2


# ------------------------------------------------------------------ a proven cache entry with NaN inside its JSON
def test_a_cached_analysis_whose_json_holds_nan_is_computed_again(tmp_path, monkeypatch):
    """An entry whose proof holds (its digest recomputed over the altered JSON) but whose JSON says ``NaN`` is
    a miss: the link is analysed again and the entry stored over, instead of a NaN volume on every rerun."""
    from asset2sim import array_cache

    monkeypatch.setenv("ASSET2SIM_CACHE", str(tmp_path / "cache"))
    v, f = box_mesh(1.0, 1.0, 1.0)
    link = link_of([mesh_ref(write_obj(tmp_path / "box.obj", v, f), scale=(0.3, 0.2, 0.1))])
    first = analyze_link(link)
    (entry,) = (tmp_path / "cache" / an.DISK_KIND).glob("*.npz")
    key = entry.stem
    text = first.model_dump_json().replace(f'"volume":{first.volume!r}', '"volume":NaN')
    assert "NaN" in text
    array_cache.store(an.DISK_KIND, key, {"json": array_cache.text_array(text)})  # a valid proof over the NaN
    assert array_cache.load(an.DISK_KIND, key) is not None
    again = analyze_link(link)
    assert np.isfinite(again.volume) and again == first
    assert "NaN" not in array_cache.array_text(array_cache.load(an.DISK_KIND, key)["json"])  # stored over it
    with pytest.raises(ValueError):
        array_cache.array_json(array_cache.text_array('{"a": Infinity}'))
