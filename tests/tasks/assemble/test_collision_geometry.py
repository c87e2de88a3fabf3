"""Output collision geometry: closed, outward, never flat, a bounded number of
convex pieces per link, parents cut around their children; every output URDF
loads in MuJoCo's URDF importer."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest

from asset2sim.engines.source import UrdfFile
from asset2sim.prior_tables import load_priors
from asset2sim import mesh_io, urdf
from asset2sim.mesh_io import read_mesh
from asset2sim.schemas.overlay import EstimatorInfo, JointDynamics, Overlay
from asset2sim.tasks.geometry.analyze import analyze_asset
from asset2sim.tasks.ingest.extract import extract_asset
from asset2sim.tasks.assemble import collision_geometry as cg, containment_cuts as cc, convex_pieces as cp, footprint as fp
from asset2sim.tasks.assemble import joint_sweep as js, parent_child_separation as pcs, piece_penetration as pp, sliding_clearance as sc
from asset2sim.tasks.assemble import container_pieces as cp_
from asset2sim.tasks.assemble.write import write_output
from asset2sim.tasks.geometry import cavities
from asset2sim.tasks.synthesize.validate_overlay import validate_overlay
from tests.conftest import SHARED, needs_shared
from tests.helpers import box_mesh as _box


def _obj(parts: list[tuple[np.ndarray, np.ndarray]], groups: bool = True) -> str:
    lines, off = [], 0
    for i, (v, f) in enumerate(parts):
        if groups:
            lines.append(f"o part{i}")
        lines += [f"v {float(x)!r} {float(y)!r} {float(z)!r}" for x, y, z in v]
        lines += [f"f {a + off + 1} {b + off + 1} {c + off + 1}" for a, b, c in f]
        off += len(v)
    return "\n".join(lines) + "\n"


def _asset(tmp_path: Path, base_parts: list, lid_parts: list, *, fixed_limit: bool = True) -> Path:
    """A two-link object: ``base`` (root) -fixed-> ``body`` -revolute-> ``lid``;
    the body's parts in one OBJ (one group each), the lid's in another."""
    d = tmp_path / "asset"
    (d / "textured_objs").mkdir(parents=True)
    (d / "textured_objs" / "body.obj").write_text(_obj(base_parts))
    (d / "textured_objs" / "lid.obj").write_text(_obj(lid_parts))
    lim = '<limit lower="0" upper="0.5"/>' if fixed_limit else ""
    (d / "mobility.urdf").write_text(f"""<?xml version="1.0"?>
<robot name="t">
  <link name="base"/>
  <link name="body">
    <visual><geometry><mesh filename="textured_objs/body.obj"/></geometry></visual>
    <collision><geometry><mesh filename="textured_objs/body.obj"/></geometry></collision>
  </link>
  <link name="lid">
    <visual><geometry><mesh filename="textured_objs/lid.obj"/></geometry></visual>
    <collision><geometry><mesh filename="textured_objs/lid.obj"/></geometry></collision>
  </link>
  <joint name="fix" type="fixed"><parent link="base"/><child link="body"/>{lim}</joint>
  <joint name="hinge" type="revolute"><parent link="body"/><child link="lid"/><axis xyz="1 0 0"/>
    <limit lower="0" upper="1.5"/></joint>
</robot>
""")
    (d / "meta.json").write_text(json.dumps({"model_cat": "Box"}))
    return d


def _write(folder: Path, out: Path, state: dict[str, float] | None = None, upper: dict[str, float] | None = None):
    """The asset at ``folder`` written into ``out``; ``upper``: joint -> the overlay's upper limit clipped to it."""
    asset = extract_asset(folder)
    ov = Overlay(estimator=EstimatorInfo(name="test"), scale=1.0,
                 joints={j.name: JointDynamics(damping=0.1, friction=0.01, upper=(upper or {}).get(j.name))
                         for j in asset.movable_joints()})
    ov, _ = validate_overlay(ov, asset, analyze_asset(asset))
    return write_output(asset, ov, out, state or {"hinge": 0.0})


def _collision_files(urdf_path: Path) -> dict[str, list[Path]]:
    model = urdf.read_urdf(urdf_path)
    return {n: [c.path for c in ln.collisions if c.kind == "mesh"] for n, ln in model.links.items()}


def _signed_volume(path: Path) -> float:
    mesh = read_mesh(path)
    v, f = mesh.vertices, mesh.faces
    t = v[f]
    return float(np.einsum("ij,ij->i", t[:, 0], np.cross(t[:, 1], t[:, 2])).sum() / 6)


def test_solid_points_grows_flat_sets_and_drops_lines():
    square = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]], float)
    grown = cp.solid_points(square)
    assert np.ptp(grown[:, 2]) == pytest.approx(cp.MIN_THICKNESS)
    assert cp.solid_points(np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0]], float)) is None
    thin = np.vstack([square, [[0.5, 0.5, 0.0005]]])  # 0.5 mm: thin, not flat: unchanged
    assert np.array_equal(cp.solid_points(thin), thin)



@needs_shared
def test_the_quick_solid_test_decides_as_the_principal_axes_do_on_real_and_thin_sets():
    """``solid_points`` skips the SVD only where the covariance shows the set is surely thick enough: on the
    vertices of a real object's meshes, on turned slabs from far thinner to thicker than FLAT_WIDTH, on sets
    with a non-finite row and on lines, it returns what the principal axes give."""
    flat = min(cp.FLAT_WIDTH, cp.MIN_THICKNESS)

    def by_axes(p):
        axis = cp.thinnest_axis(p)
        if axis is None:
            return None
        q, _, n, width = axis
        return q if width >= flat else np.vstack([q + 0.5 * (cp.MIN_THICKNESS - width) * n,
                                                  q - 0.5 * (cp.MIN_THICKNESS - width) * n])

    sets = [read_mesh(f).vertices for f in sorted((SHARED / "datasets" / "partnet_mobility" / "9912" / "textured_objs").glob("*.obj"))[:12]]
    rng = np.random.default_rng(5)
    for s in (1e-6, 3e-5, 1e-4, 2e-4, 1e-3, 0.05):
        turn = np.linalg.qr(rng.normal(size=(3, 3)))[0]
        sets.append((rng.normal(size=(200, 3)) * [0.1, 0.05, s]) @ turn.T)
    sets += [np.vstack([sets[-1], [[np.nan, 0, 0]]]), np.outer(np.arange(5.0), [1, 2, 3])]
    quick = 0
    for p in sets:
        got, want = cp.solid_points(p), by_axes(p)
        assert (got is None and want is None) or np.array_equal(got, want)
        quick += cp._surely_solid(p, flat)
    assert 0 < quick < len(sets)  # both paths taken

def test_piece_files_are_closed_and_wound_outward(tmp_path):
    rng = np.random.default_rng(3)
    piece = cp.Piece.of(rng.normal(size=(60, 3)))
    p = tmp_path / "p.obj"
    p.write_bytes(cp.piece_obj(piece))
    mesh = read_mesh(p)
    v, f = mesh.vertices, mesh.faces
    assert _signed_volume(p) == pytest.approx(piece.volume, rel=1e-9)
    edges = np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1)
    _, counts = np.unique(edges, axis=0, return_counts=True)
    assert np.all(counts == 2)  # every edge shared by two faces: closed


def test_merge_keeps_every_point_and_respects_the_limit():
    cubes = [cp.Piece.of(_box([i * 0.011, j * 0.011, 0], [i * 0.011 + 0.01, j * 0.011 + 0.01, 0.01])[0])
             for i in range(6) for j in range(5)]
    merged = cp.merge_pieces(cubes, 4)
    assert len(merged) == 4
    every = np.vstack([c.points for c in cubes])
    inside = np.zeros(len(every), bool)
    for m in merged:
        inside |= np.max(every @ m.equations[:, :3].T + m.equations[:, 3], axis=1) <= 1e-9
    assert inside.all()


def test_merge_does_not_swallow_another_link():
    """Two rows of cubes with another link's point between them: the rows
    merge among themselves, never across the point."""
    row_a = [cp.Piece.of(_box([i * 0.02, 0, 0], [i * 0.02 + 0.015, 0.01, 0.01])[0]) for i in range(5)]
    row_b = [cp.Piece.of(_box([i * 0.02, 0.03, 0], [i * 0.02 + 0.015, 0.04, 0.01])[0]) for i in range(5)]
    other = np.array([[0.05, 0.02, 0.005]])
    merged = cp.merge_pieces(row_a + row_b, 2, others=other)
    assert len(merged) == 2
    assert all(cp.depth_inside(other, m) == 0.0 for m in merged)
    unguarded = cp.merge_pieces(row_a + row_b, 1)
    assert cp.depth_inside(other, unguarded[0]) > 0.004  # the test can fail: one hull holds the point


def _merge_measuring_every_pair(pieces, limit, others, free_only, neighbours=8):
    """merge_pieces as it was, each pair's hold on ``others`` measured as it enters the queue: the reference
    the lazy measurement must reproduce merge for merge."""
    import heapq

    from scipy.spatial import QhullError
    pieces = list(pieces)
    if len(pieces) <= limit:
        return pieces
    others = others[np.argsort(others[:, 0], kind="stable")]
    xs = others[:, 0]
    alive = dict(enumerate(pieces))
    nxt, penalty = len(pieces), 1.0 + sum(p.volume for p in pieces) * 1e6

    def cost(a, b):
        try:
            m = cp.Piece.of(np.vstack([a.support, b.support]))
        except (QhullError, ValueError):
            return float("inf"), None
        c = m.volume - a.volume - b.volume
        lo, hi = m.points.min(axis=0), m.points.max(axis=0)
        band = others[np.searchsorted(xs, lo[0], "left"):np.searchsorted(xs, hi[0], "right")]
        near = band[np.all((band[:, 1:] >= lo[1:]) & (band[:, 1:] <= hi[1:]), axis=1)]
        size = float(np.ptp(m.points, axis=0).max())
        if len(near):
            inside = np.max(near @ m.equations[:, :3].T + m.equations[:, 3], axis=1) < -cp._INSIDE_EPS * size
            held = np.zeros(len(near), bool)
            for q in (a, b):
                held |= np.max(near @ q.equations[:, :3].T + q.equations[:, 3], axis=1) < -cp._INSIDE_EPS * size
            if (inside & ~held).any():
                c += penalty
        return c, m

    heap, merged = [], {}

    def push_for(i):
        ids = [j for j in alive if j != i]
        if not ids:
            return
        cs = np.array([alive[j].points.mean(axis=0) for j in ids])
        for o in np.argsort(np.linalg.norm(cs - alive[i].points.mean(axis=0), axis=1))[:neighbours]:
            j = ids[int(o)]
            key = (min(i, j), max(i, j))
            if key not in merged:
                c, m = cost(alive[key[0]], alive[key[1]])
                if m is not None:
                    merged[key] = m
                    heapq.heappush(heap, (c, *key))

    for i in list(alive):
        push_for(i)
    while len(alive) > limit and heap:
        c, i, j = heapq.heappop(heap)
        if i not in alive or j not in alive:
            continue
        if free_only and c >= penalty:
            break
        merged.pop((i, j))
        a, b = alive.pop(i), alive.pop(j)
        alive[nxt] = cp.Piece.of(np.vstack([a.points, b.points]), a.sources + tuple(s for s in b.sources if s not in a.sources))
        push_for(nxt)
        nxt += 1
    return list(alive.values())


def _round_pieces(rng, n: int, faces_at_least: int) -> list:
    """``n`` hulls of 80 points each on small spheres scattered over a 0.1 m cube, every one with more than
    ``faces_at_least`` faces (the hulls of curved surface samples whose many planes the bounds skip)."""
    out = []
    for c in rng.uniform(0.0, 0.1, (n, 3)):
        d = rng.normal(size=(80, 3))
        out.append(cp.Piece.of(c + rng.uniform(0.006, 0.015) * d / np.linalg.norm(d, axis=1)[:, None]))
    assert min(len(q.equations) for q in out) > faces_at_least
    return out


@pytest.mark.parametrize("kind, seed", [("blocks", s) for s in range(6)] + [("round", s) for s in range(4)])
def test_merge_measures_lazily_and_by_bounds_the_same_merges(kind, seed):
    """Pieces scattered with another link's points among them: merge_pieces, measuring a pair's hold on those
    points only when the pair comes first, and on a piece of many faces (``round``: more than a few planes bound,
    ``convex_pieces._BOUND_PLANES``) testing a point against its box and a few of its planes before all of them,
    makes the same pieces, bit for bit, as measuring every pair on entry against every plane."""
    if kind == "blocks":
        rng = np.random.default_rng(seed)
        pieces = [cp.Piece.of(_box(a, a + rng.uniform(0.005, 0.02, 3))[0]) for a in rng.uniform(0.0, 0.1, (24, 3))]
        others = rng.uniform(0.0, 0.12, (40, 3))
    else:
        rng = np.random.default_rng(100 + seed)
        pieces = _round_pieces(rng, 20, 2 * cp._BOUND_PLANES)
        others = rng.uniform(0.0, 0.11, (400, 3))
    for free_only, limit in ((True, 1), (True, 5), (False, 3)):
        got = cp.merge_pieces(pieces, limit, others, free_only=free_only)
        want = _merge_measuring_every_pair(pieces, limit, others, free_only)
        assert len(got) == len(want) and len(got) >= limit
        assert all(np.array_equal(g.points, w.points) for g, w in zip(got, want))
    assert len(cp.merge_pieces(pieces, 1, others, free_only=True)) > 1  # the guard acts: the test can fail


@pytest.mark.parametrize("seed", range(4))
def test_the_depth_found_by_bounds_is_the_depth_over_every_plane(seed):
    """depth_inside on a hull of many faces (bounded by a few planes, the points measured deepest bound first)
    equals the largest depth over every point and plane, bit for bit; points all outside read 0."""
    rng = np.random.default_rng(200 + seed)
    d = rng.normal(size=(600, 3))
    hull = cp.Piece.of(0.05 * d / np.linalg.norm(d, axis=1)[:, None] * rng.uniform(0.9, 1.0, (600, 1)))
    assert len(hull.equations) > 4 * cp._BOUND_PLANES
    shell = rng.normal(size=(3000, 3))
    shell *= rng.uniform(0.042, 0.05, (3000, 1)) / np.linalg.norm(shell, axis=1)[:, None]  # bounds far above depths
    for pts in (rng.uniform(-0.06, 0.06, (3000, 3)), rng.uniform(-0.02, 0.02, (500, 3)) + [0.04, 0.0, 0.0], shell):
        full = np.max(pts @ hull.equations[:, :3].T + hull.equations[:, 3], axis=1)
        assert cp.depth_inside(pts, hull) == max(0.0, float(-full.min())) > 0.0
    outside = rng.uniform(0.051, 0.06, (300, 3)) * rng.choice([-1.0, 1.0], (300, 3))
    assert cp.depth_inside(outside, hull) == 0.0


def test_written_collisions_are_few_closed_convex_pieces_mujoco_loads(tmp_path):
    """A body of 40 small blocks plus a flat plate, a lid of one block: the
    output has at most MAX_PIECES_PER_LINK closed, outward, non-flat pieces
    per link, no <limit> on the fixed joint, and MuJoCo imports the URDF."""
    blocks = [_box([i * 0.012, j * 0.012, 0], [i * 0.012 + 0.01, j * 0.012 + 0.01, 0.01]) for i in range(8) for j in range(5)]
    plate = (np.array([[0, 0, 0.02], [0.1, 0, 0.02], [0, 0.06, 0.02], [0.1, 0.06, 0.02]]), np.array([[0, 1, 3], [0, 3, 2]]))
    lid = [_box([0, 0, 0.03], [0.1, 0.06, 0.04])]
    out = _write(_asset(tmp_path, blocks + [plate], lid), tmp_path / "out")
    files = _collision_files(out.urdf)
    assert 1 <= len(files["body"]) <= cp.MAX_PIECES_PER_LINK and len(files["lid"]) == 1
    for paths in files.values():
        for p in paths:
            assert p.parent.name.startswith("collision")
            mesh = read_mesh(p)
            v, f = mesh.vertices, mesh.faces
            assert _signed_volume(p) > 0
            sv = np.linalg.svd(v - v.mean(axis=0), compute_uv=False)
            assert np.ptp((v - v.mean(axis=0)) @ np.linalg.svd(v - v.mean(axis=0))[2][2]) >= cp.FLAT_WIDTH
            assert sv[2] > 0
    model = urdf.read_urdf(out.urdf)
    assert model.joint("fix").limit is None
    lim = model.joint("hinge").limit  # none declared: a passive part's, which the URDF format requires
    assert (lim.effort, lim.velocity) == (urdf.PASSIVE_EFFORT, urdf.PASSIVE_VELOCITY)
    mujoco = pytest.importorskip("mujoco")
    m = mujoco.MjModel.from_xml_path(str(out.urdf))
    assert m.ngeom == len(files["body"]) + len(files["lid"])
    assert {str(c.filename) for ln in model.links.values() for c in ln.collisions if c.kind == "mesh"} == {str(Path(p).relative_to(out.root).as_posix()) for ps in files.values() for p in ps}


def _tray_with_block(tmp_path):
    """An open tray (one concave mesh, one hull) holding a block on a hinge: (folder, its URDF model)."""
    t = 0.004
    walls = [_box([0, 0, 0], [0.1, 0.1, t]), _box([0, 0, 0], [t, 0.1, 0.05]), _box([0.1 - t, 0, 0], [0.1, 0.1, 0.05]),
             _box([0, 0, 0], [0.1, t, 0.05]), _box([0, 0.1 - t, 0], [0.1, 0.1, 0.05])]
    v = np.vstack([w[0] for w in walls])
    f = np.vstack([w[1] + 8 * i for i, w in enumerate(walls)])
    block = [_box([0.03, 0.03, 0.01], [0.07, 0.07, 0.03])]
    folder = _asset(tmp_path, [(v, f)], block)
    (folder / "textured_objs" / "body.obj").write_text(_obj([(v, f)], groups=False))  # one group: one hull
    model = urdf.read_urdf(folder / "mobility.urdf")
    return folder, model


def test_parent_is_cut_around_a_child_inside_its_hull(tmp_path):
    """An open tray (one concave mesh) holding a block: the tray's hull holds
    the block 20 mm deep; the written pieces of the tray hold it no deeper
    than the tolerance."""
    folder, model = _tray_with_block(tmp_path)
    before, _ = cg.link_pieces(model, lambda g: g.path, {}, decompose=False)
    assert pp.containment_depths(model, before, {})[("body", "lid")] > 0.015
    out = _write(folder, tmp_path / "out")
    written = urdf.read_urdf(out.urdf)
    after, _ = cg.link_pieces(written, lambda g: g.path, {"hinge": 0.0}, decompose=False)
    assert pp.containment_depths(written, after, {"hinge": 0.0})[("body", "lid")] <= cp.CONTAINMENT_TOLERANCE


def test_a_part_holding_an_open_cavity_keeps_it_open(tmp_path):
    """An open tray that is one OBJ group, alone on its link: its one hull would be a solid block. Its pieces are
    a convex decomposition (noted) that leaves the inside free and still holds the bottom and the walls; without
    ``decompose`` or ``open_containers`` it stays one hull."""
    pytest.importorskip("coacd")
    folder, _ = _tray_with_block(tmp_path)
    (folder / "textured_objs" / "lid.obj").write_text(_obj([_box([0.0, 0.2, 0.0], [0.1, 0.22, 0.01])]))  # lid beside it
    model = urdf.read_urdf(folder / "mobility.urdf")
    solid, _ = cg.link_pieces(model, lambda g: g.path, {}, decompose=False)
    assert len(solid["body"]) == 1
    assert len(cg.link_pieces(model, lambda g: g.path, {})[0]["body"]) == 1  # the default: containers stay hulls
    pieces, notes = cg.link_pieces(model, lambda g: g.path, {}, open_containers=True)
    assert len(pieces["body"]) > 1
    assert any(cp_.CAVITY_NOTE in n and "'body'" in n for n in notes), notes

    def held(p: np.ndarray) -> bool:
        return any(np.max(p @ q.equations[:, :3].T + q.equations[:, 3]) <= 0 for q in pieces["body"])

    assert not held(np.array([0.05, 0.05, 0.03]))  # the middle of the inside
    assert not held(np.array([0.03, 0.07, 0.02]))
    for wall in ([0.05, 0.05, 0.002], [0.002, 0.05, 0.025], [0.098, 0.05, 0.025], [0.05, 0.002, 0.025], [0.05, 0.098, 0.025]):
        assert held(np.array(wall)), wall


def test_a_link_whose_hull_a_child_moves_in_is_found(tmp_path):
    """The open tray holding a block on a hinge (:func:`_tray_with_block`): the tray's hull holds the block over
    its range, so a cavity of the tray is decomposed even where it opens downward (a desk's body around its
    drawer); the block holds no child."""
    _, model = _tray_with_block(tmp_path)
    hulls = {name: cg._group_hulls(link, lambda g: g.path, []) for name, link in model.links.items()}
    assert cp_.holding_children(model, hulls) == {"body"}
    far = {name: [(k, g, cg.Piece.of(p.points + (0.0, 0.0, 1.0) if name == "lid" else p.points, p.sources))
                  for k, g, p in found] for name, found in hulls.items()}  # the block lifted 1 m clear of the tray
    assert cp_.holding_children(model, far) == set()


@needs_shared
def test_a_trash_can_body_is_hollow_and_a_drawer_that_slides_along_another_keeps_its_hull():
    """Dev assets whose container is one OBJ group: trash can 102155's body (link_3) is decomposed and its inside
    left free; cabinet 19179's upper drawer box (link_0) slides along the drawer below it, so it keeps its one
    hull (a sliding part catches on the seams between pieces in PyBullet), and the note says why; toilet 102703's
    lid (link_2), whose hollow underside faces down when shut, keeps its hull too, while its body (link_4) is
    decomposed: its bowl opens upward, though the space under the bowl's rim opens downward."""
    pytest.importorskip("coacd")
    can = urdf.read_urdf(SHARED / "102155" / "mobility.urdf")
    pieces, notes = cg.link_pieces(can, lambda g: g.path, {}, open_containers=True)
    opened = [n for n in notes if cp_.CAVITY_NOTE in n and "'link_3'" in n]
    assert opened and "convex pieces (CoACD)" in opened[0], notes
    body = can.links["link_3"]
    surfaces = cp_.link_surfaces(body, lambda g: g.path)
    group = next(m for (k, _), m in surfaces[1].items() if "original-6" in body.collisions[k].filename)
    hv, hf = mesh_io.convex_hull_mesh(group[0])
    cav = cavities.open_cavity(*surfaces[0], hv, hf)
    assert cav is not None and cavities.open_fraction(cav.core, [p.equations for p in pieces["link_3"]]) > 0.9
    cabinet = urdf.read_urdf(SHARED / "19179" / "mobility.urdf")
    pieces, notes = cg.link_pieces(cabinet, lambda g: g.path, {}, open_containers=True)
    kept = [n for n in notes if cp_.CAVITY_NOTE in n and "'link_0'" in n]
    assert kept and "kept as one convex hull" in kept[0] and "slides along 'link_1'" in kept[0], notes
    assert len(pieces["link_0"]) <= 2  # the box's hull and the handle's
    toilet = urdf.read_urdf(SHARED / "102703" / "mobility.urdf")  # its lid's underside opens downward when shut
    pieces, notes = cg.link_pieces(toilet, lambda g: g.path, {}, open_containers=True)
    lid = [n for n in notes if cp_.CAVITY_NOTE in n and "'link_2'" in n]
    assert lid and "opening faces down" in lid[0] and len(pieces["link_2"]) == 1, notes
    body = [n for n in notes if cp_.CAVITY_NOTE in n and "'link_4'" in n]
    assert body and "convex pieces (CoACD)" in body[0], notes
    assert len(pieces["link_4"]) > 1


@needs_shared
def test_laptop_9912_has_few_pieces_and_loads_in_mujoco(tmp_path):
    """Laptop 9912: 118 part meshes, flat groups among them. Its output has at
    most MAX_PIECES_PER_LINK pieces per link and MuJoCo imports the URDF."""
    mujoco = pytest.importorskip("mujoco")
    out = _write(SHARED / "9912", tmp_path / "out", {"joint_1": -1.5})
    files = _collision_files(out.urdf)
    assert max(len(v) for v in files.values()) <= cp.MAX_PIECES_PER_LINK
    m = mujoco.MjModel.from_xml_path(str(out.urdf))
    assert m.ngeom <= 2 * cp.MAX_PIECES_PER_LINK
    # the MJCF dropped from 5 cm: few contacts, no MuJoCo warning (arena / stack overflow)
    from asset2sim.engines.base import SessionOptions
    from asset2sim.engines.mjcf import urdf_to_mjcf

    build = urdf_to_mjcf(out.urdf, SessionOptions(initial_state={"joint_1": -1.5}))
    mj = mujoco.MjModel.from_xml_string(build.xml, assets=build.assets())
    d = mujoco.MjData(mj)
    mujoco.mj_resetDataKeyframe(mj, d, 0)
    d.qpos[2] += 0.05
    most = 0
    for _ in range(int(1.0 / mj.opt.timestep)):
        mujoco.mj_step(mj, d)
        most = max(most, d.ncon)
    assert all(w.number == 0 for w in d.warning)
    assert 0 < most <= 4 * cp.MAX_PIECES_PER_LINK  # it was 372 with the 118 part meshes
    assert d.qpos[2] > -0.01  # still above the floor


def test_a_link_far_lighter_than_its_object_is_raised_to_the_floor(tmp_path):
    """A 0.05 g lid on a box of grams: raised to MIN_LINK_MASS_FRACTION of
    the object's mass (inertia scaled alike), reported, and validation is then
    idempotent."""
    from asset2sim import demo_assets
    from asset2sim.tasks.synthesize.validate_overlay import MIN_LINK_MASS_FRACTION

    asset = extract_asset(demo_assets.build_box_with_lid(tmp_path / "box"))
    geometry = analyze_asset(asset)
    ov, _ = validate_overlay(Overlay(estimator=EstimatorInfo(name="t"), scale=0.3), asset, geometry)
    lid = next(n for n in ov.links if n != "base" and any(j.child == n for j in asset.movable_joints()))
    light = ov.links[lid].model_copy(update={"mass": 5e-5, "inertia": ov.links[lid].inertia})
    ov.links[lid] = light
    fixed, issues = validate_overlay(ov, asset, geometry)
    assert any(i.code == "OVL_MASS_TOO_SMALL" and i.where == lid for i in issues)
    total = sum(lp.mass for lp in fixed.links.values())
    assert fixed.links[lid].mass == pytest.approx(MIN_LINK_MASS_FRACTION * total, rel=1e-9)
    k = fixed.links[lid].mass / 5e-5
    assert np.allclose(fixed.links[lid].inertia.matrix(), light.inertia.matrix() * k)
    _, again = validate_overlay(fixed, asset, geometry)
    assert not any(i.code == "OVL_MASS_TOO_SMALL" for i in again)


def _plates_and_blade(tmp_path: Path) -> Path:
    """18 upright plates (one OBJ group each, 10 mm thick, 100 mm tall) in a
    row along x, 40 mm apart except one 30 mm gap (the cheapest to merge
    across); a blade hinged about y above that gap lies flat over the plates
    at q = -pi/2 and hangs down into the gap at q = 0."""
    d = tmp_path / "plates"
    (d / "textured_objs").mkdir(parents=True)
    xs, x = [], 0.0
    for i in range(18):
        xs.append(x)
        x += 0.01 + (0.03 if i == 8 else 0.04)
    plates = [_box([x0, 0, 0], [x0 + 0.01, 0.1, 0.1]) for x0 in xs]
    gap = xs[8] + 0.01 + 0.015  # the middle of the narrow gap
    blade = [_box([-0.005, -0.01, -0.09], [0.005, 0.01, -0.01])]  # at q = 0 it hangs down into the gap
    (d / "textured_objs" / "body.obj").write_text(_obj(plates))
    (d / "textured_objs" / "blade.obj").write_text(_obj(blade))
    (d / "mobility.urdf").write_text(f"""<?xml version="1.0"?>
<robot name="plates">
  <link name="base"/>
  <link name="body"><collision><geometry><mesh filename="textured_objs/body.obj"/></geometry></collision></link>
  <link name="blade"><collision><geometry><mesh filename="textured_objs/blade.obj"/></geometry></collision></link>
  <joint name="fix" type="fixed"><parent link="base"/><child link="body"/></joint>
  <joint name="hinge" type="revolute"><parent link="body"/><child link="blade"/>
    <origin xyz="{gap!r} 0.05 0.115"/><axis xyz="1 0 0"/><limit lower="0" upper="1.5708"/></joint>
</robot>
""")
    return d


def _blade_depth(model: urdf.UrdfModel, pieces: dict, q: float) -> float:
    return pp.containment_depths(model, pieces, {"hinge": q})[("body", "blade")]


def groups_of(model: urdf.UrdfModel) -> dict:
    notes: list[str] = []
    return {n: cg._group_pieces(ln, lambda g: g.path, notes).pieces for n, ln in model.links.items()}


def test_merge_keeps_the_swept_volume_of_a_joint_free(tmp_path):
    """The narrow gap is the cheapest merge, and at the initial state (blade
    flat above the plates, q = pi/2) nothing is inside it; the blade swings
    down into that gap at q = 0. The merged pieces must leave the gap open over
    the whole range, so the joint can travel it (merging at the initial
    state alone closed it)."""
    folder = _plates_and_blade(tmp_path)
    model = urdf.read_urdf(folder / "mobility.urdf")
    pieces, notes = cg.link_pieces(model, lambda g: g.path, {"hinge": 1.5708})
    assert len(pieces["body"]) == cp.MAX_PIECES_PER_LINK
    assert any("merged" in n for n in notes)
    assert _blade_depth(model, groups_of(model), 1.5708) == 0.0
    for q in np.linspace(0.0, 1.5708, 7):
        assert _blade_depth(model, pieces, q) <= cp.CONTAINMENT_TOLERANCE, q
    # the test can fail: merging across the narrow gap (what a guard at the initial state allows) holds the blade
    groups = groups_of(model)
    unguarded = {**groups, "body": cp.merge_pieces(groups["body"], cp.MAX_PIECES_PER_LINK)}
    assert _blade_depth(model, unguarded, 0.0) > 0.004


def test_pieces_do_not_depend_on_the_initial_state(tmp_path):
    """The tray holding a block on a hinge: the pieces written at two
    different initial states are the same, and the block sits no deeper than
    the tolerance inside the tray's pieces anywhere over its range (cutting
    the tray around the block at one state only left other states inside)."""
    folder, model = _tray_with_block(tmp_path)
    a, _ = cg.link_pieces(model, lambda g: g.path, {"hinge": 0.0})
    b, _ = cg.link_pieces(model, lambda g: g.path, {"hinge": 0.4})
    assert [p.points.tobytes() for p in a["body"]] == [p.points.tobytes() for p in b["body"]]
    hinge = model.joint("hinge")
    for q in np.linspace(hinge.lower, hinge.upper, 9):
        assert pp.containment_depths(model, a, {"hinge": float(q)})[("body", "lid")] <= cp.CONTAINMENT_TOLERANCE + 5e-4, q


def test_a_limit_clipped_to_the_geometry_gives_the_parent_back_its_material_beyond_the_stop(tmp_path):
    """The tray holding a block on a hinge declared over 0-1.5 rad, written as declared and with the overlay's upper
    limit clipped to 0.4 rad (what tasks.geometry.limits writes where the geometry stops the part): the tray is cut
    around the block only over the range it can reach, so the clipped output keeps more of the tray (cut for the
    declared range, PartNet-Mobility's suitcase 101668 lost 16 % of its body's pieces' volume around lid positions its
    stop excludes, and tipped when its lid was pulled), and the block stays clear of it over that range."""
    folder, model = _tray_with_block(tmp_path)
    declared = _write(folder, tmp_path / "declared")
    out = _write(folder, tmp_path / "clipped", upper={"hinge": 0.4})
    assert urdf.read_urdf(out.urdf).joint("hinge").upper == 0.4

    def pieces(urdf_path):
        return {n: [cp.Piece.of(read_mesh(p).vertices) for p in ps] for n, ps in _collision_files(urdf_path).items()}

    kept, cut = pieces(out.urdf), pieces(declared.urdf)
    assert sum(p.volume for p in kept["body"]) > 1.02 * sum(p.volume for p in cut["body"])
    for q in np.linspace(0.0, 0.4, 5):
        assert pp.containment_depths(model, kept, {"hinge": float(q)})[("body", "lid")] <= cp.CONTAINMENT_TOLERANCE + 5e-4, q


def test_a_piece_overlapped_by_a_child_is_trimmed_by_the_overlap():
    """A drawer's side 3 mm into a convex 20 mm side panel (the meshes
    overlap; no cut of a convex piece frees it): the panel's piece is
    trimmed on its inner face just enough that no drawer vertex sits deeper
    than half the tolerance; a part that no move of one face by at most half
    the piece's width frees is not trimmed."""
    panel = cp.Piece.of(_box([0.0, 0.0, 0.0], [0.02, 0.3, 0.2])[0])
    drawer = _box([0.017, 0.0, 0.05], [0.2, 0.25, 0.15])[0]
    swept = np.vstack([drawer - [0.0, q, 0.0] for q in np.linspace(0.0, 0.2, 9)])
    assert cp.depth_inside(swept, panel) == pytest.approx(0.003)
    trimmed = cc.shave_piece(panel, swept)
    assert cp.depth_inside(swept, trimmed) <= 0.5 * cp.CONTAINMENT_TOLERANCE + 1e-9
    assert np.ptp(trimmed.points, axis=0) == pytest.approx([0.018, 0.3, 0.2])  # only the inner face moved, by 2 mm
    across = np.array([[0.005, 0.15, 0.1], [0.015, 0.15, 0.1]])  # a part across the panel's middle
    assert cc.shave_piece(panel, across) is None


def test_a_child_overlapping_a_panel_over_its_slide_is_kept_out(tmp_path):
    """A drawer whose side overlaps its carcass's side panel by 3 mm over its
    whole slide (the two meshes overlap): the written pieces hold the drawer
    within the tolerance at every position of the slide (cut into facets or
    trimmed)."""
    d = tmp_path / "drawer"
    (d / "textured_objs").mkdir(parents=True)
    (d / "textured_objs" / "panel.obj").write_text(_obj([_box([0.0, 0.0, 0.0], [0.02, 0.3, 0.2])]))
    (d / "textured_objs" / "drawer.obj").write_text(_obj([_box([0.017, 0.0, 0.05], [0.2, 0.25, 0.15])]))
    (d / "mobility.urdf").write_text("""<?xml version="1.0"?>
<robot name="drawer">
  <link name="carcass"><collision><geometry><mesh filename="textured_objs/panel.obj"/></geometry></collision></link>
  <link name="drawer"><collision><geometry><mesh filename="textured_objs/drawer.obj"/></geometry></collision></link>
  <joint name="slide" type="prismatic"><parent link="carcass"/><child link="drawer"/><axis xyz="0 -1 0"/>
    <limit lower="0" upper="0.2"/></joint>
</robot>
""")
    model = urdf.read_urdf(d / "mobility.urdf")
    raw = groups_of(model)
    for q in (0.0, 0.1, 0.2):
        assert pp.containment_depths(model, raw, {"slide": q})[("carcass", "drawer")] > 0.0029  # the test can fail
    pieces, notes = cg.link_pieces(model, lambda g: g.path, {"slide": 0.0})
    for q in np.linspace(0.0, 0.2, 9):
        assert pp.containment_depths(model, pieces, {"slide": float(q)})[("carcass", "drawer")] <= cp.CONTAINMENT_TOLERANCE


def test_slivers_and_duplicates_left_by_cuts_are_dropped():
    """A cut can leave a duplicate of a piece and a 0.1 mm flake on its cut
    plane (PyBullet collided such a flake 2 mm deep); both go, the pieces
    with volume stay."""
    a = cp.Piece.of(_box([0, 0, 0], [0.1, 0.05, 0.02])[0])
    b = cp.Piece.of(_box([0.1, 0, 0], [0.2, 0.05, 0.02])[0])
    dup = cp.Piece.of(_box([0.01, 0.01, 0.0], [0.05, 0.04, 0.02])[0])  # inside a
    flake = cp.Piece.of(_box([0.1, 0.0, 0.0], [0.1016, 0.0015, 0.0001])[0])  # 0.24 mm^3
    kept = cp.drop_slivers([a, dup, flake, b])
    assert [k is a or k is b for k in kept] == [True, True]


def test_penetration_depth_is_the_smallest_separating_overlap():
    """Two boxes overlapping 5 mm along x (and 40 mm along y, z): depth 5 mm
    along x; apart: 0; a slab crossing a rotated slab edge to edge (no vertex
    of either inside the other) still reads its depth."""
    a = cp.Piece.of(_box([0, 0, 0], [0.1, 0.1, 0.1])[0])
    b = cp.Piece.of(_box([0.095, 0.03, 0.03], [0.2, 0.07, 0.07])[0])
    d, n = pp.penetration_depth(a, b)
    assert d == pytest.approx(0.005, abs=1e-9)
    assert np.allclose(np.abs(n), [1, 0, 0])
    far = cp.Piece.of(_box([0.15, 0, 0], [0.2, 0.1, 0.1])[0])
    assert pp.penetration_depth(a, far)[0] == 0.0
    bar = _box([-0.1, -0.005, -0.005], [0.1, 0.005, 0.005])[0]  # along x
    R = np.array([[0, -1, 0], [1, 0, 0], [0, 0, 1]], float)  # along y, 8 mm lower: crossing by 2 mm
    cross = cp.Piece.of(bar @ R.T + [0, 0, 0.008])
    assert cp.depth_inside(cross.points, cp.Piece.of(bar)) == 0.0 and cp.depth_inside(bar, cross) == 0.0
    assert pp.penetration_depth(cp.Piece.of(bar), cross)[0] == pytest.approx(0.002, abs=1e-9)


def _post_in_lid(tmp_path: Path) -> Path:
    """A body (a slab and a thin post) whose post stands 20 mm inside the
    lid's hull (a closed box) at the initial state: no lid vertex lies in a
    body piece, so only the body's post inside the lid's hull overlaps."""
    slab, post = _box([0, 0, 0], [0.1, 0.1, 0.01]), _box([0.045, 0.045, 0.01], [0.055, 0.055, 0.04])
    lid = _box([0.02, 0.02, 0.02], [0.08, 0.08, 0.05])
    return _asset(tmp_path, [slab, post], [lid])


def test_a_child_that_starts_around_its_parent_is_separated(tmp_path):
    """The lid's hull holds the body's post 20 mm deep: measured with the
    pair collided (PyBullet's closest points, margins removed, as refine's
    post-check does) the input penetrates, the written output does not
    (<= 2 mm) at any position of the hinge, and the lid keeps its volume."""
    from asset2sim.tasks.check.parent_child import parent_child_penetration

    folder = _post_in_lid(tmp_path)
    model = urdf.read_urdf(folder / "mobility.urdf")
    before, _ = cg.link_pieces(model, lambda g: g.path, {}, decompose=False)
    assert pp.containment_depths(model, before, {"hinge": 0.0})[("body", "lid")] == 0.0  # no lid vertex inside the body
    assert pp.parent_child_depths(model, before, {"hinge": 0.0})[("body", "lid")] > 0.015
    assert parent_child_penetration(UrdfFile(folder / "mobility.urdf"), {"hinge": 0.0}).value > 15.0
    out = _write(folder, tmp_path / "out")
    m = parent_child_penetration(UrdfFile(out.urdf), {"hinge": 0.0})
    assert m.passed and m.value <= cp.CONTAINMENT_TOLERANCE * 1000
    written = urdf.read_urdf(out.urdf)
    after, _ = cg.link_pieces(written, lambda g: g.path, {}, decompose=False)
    for q in np.linspace(0.0, 1.5, 7):
        assert pp.parent_child_depths(written, after, {"hinge": float(q)})[("body", "lid")] <= cp.CONTAINMENT_TOLERANCE + 1e-9
    assert sum(p.volume for p in after["lid"]) == pytest.approx(0.06 * 0.06 * 0.03, rel=1e-6)  # the post was cut, not the lid
    mujoco = pytest.importorskip("mujoco")
    assert parent_child_penetration(UrdfFile(out.urdf), {"hinge": 0.0}, engine="mujoco").value <= cp.CONTAINMENT_TOLERANCE * 1000
    assert mujoco.MjModel.from_xml_path(str(out.urdf)).ngeom >= 2


def test_a_child_sliding_through_its_parent_keeps_the_overlap_and_notes_its_depth():
    """A bar (the child, one convex piece) slides up through a crossing bar
    (the parent, one piece): the overlap is carried from the reference
    position until the child clears the parent, and the direction that
    separates them flips on the way (down at first, up from 7.5 mm on), so
    cutting either piece at every carried position removes it whole. A link's
    last piece is never removed: both pieces are kept and the note gives the
    depth kept. This raised ``TypeError: cannot unpack non-iterable int
    object`` (the kept-overlap note iterated the positions' depths, a dict
    position -> (depth, direction), as if it were the list of pairs it was
    before), which ended a flow's refine on a hidden-dataset bucket."""
    model = urdf.parse_urdf_bytes(b"""<robot name="crossing">
  <link name="body"/><link name="slider"/>
  <joint name="slide" type="prismatic"><parent link="body"/><child link="slider"/><axis xyz="0 0 1"/>
    <limit lower="0" upper="0.05"/></joint>
</robot>""")
    body = cp.Piece.of(_box([0.0, 0.0, 0.0], [0.01, 0.1, 0.02])[0])  # along y, 20 mm high
    slider = cp.Piece.of(_box([-0.03, 0.045, -0.01], [0.04, 0.055, 0.015])[0])  # along x, across the body
    joint = model.joint("slide")
    d0, n0 = pp.penetration_depth(body, pp._transformed(slider, js._joint_motion(joint, 0.0)))
    d1, n1 = pp.penetration_depth(body, pp._transformed(slider, js._joint_motion(joint, 0.02)))
    assert d0 == pytest.approx(0.015) and d1 == pytest.approx(0.01)
    assert np.allclose(n0, -n1) and abs(n0[2]) == pytest.approx(1.0)  # the situation: the direction flips
    pieces = {"body": [body], "slider": [slider]}
    notes: list[str] = []
    pcs.separate_parent_child(model, pieces, notes)
    assert [p is body for p in pieces["body"]] == [True] and [p is slider for p in pieces["slider"]] == [True]  # nothing cut
    (note,) = notes
    m = re.search(r"up to ([0-9.]+) mm .*; 1 overlap\(s\) of a link's last piece held whole inside another kept \(([0-9.]+) mm\)", note)
    assert m is not None, note
    assert float(m.group(1)) == float(m.group(2)) >= 15.0, note


def test_sliding_contacts_between_parts_are_given_running_clearance(tmp_path):
    """Two drawers stacked with no gap (siblings, both prismatic along +x): the
    writer's pieces keep the engines' margins apart (gap >= RUNNING_CLEARANCE),
    the lower drawer (first joint in file order) squeezed at its top face only;
    the upper one is then clear and unchanged."""
    from tests.tasks.state.test_clearance import write_stacked_drawers

    urdf_path = write_stacked_drawers(tmp_path / "drawers")
    model = urdf.read_urdf(urdf_path)
    pieces, notes = cg.link_pieces(model, lambda g: urdf_path.parent / str(g.filename))
    (lower,), (upper,) = pieces["lower"], pieces["upper"]
    assert lower.points[:, 2].min() == pytest.approx(0.005) and lower.points[:, 2].max() == pytest.approx(0.025 - sc.RUNNING_CLEARANCE)
    assert np.ptp(lower.points[:, 0]) == pytest.approx(0.06) and np.ptp(lower.points[:, 1]) == pytest.approx(0.04)
    assert upper.points[:, 2].min() == pytest.approx(0.025) and upper.points[:, 2].max() == pytest.approx(0.045)
    g, _ = sc.sat_gap(lower.points, upper.points)
    assert g >= sc.RUNNING_CLEARANCE - 1e-12
    clear = [n for n in notes if sc.RUNNING_CLEARANCE_NOTE in n]
    assert len(clear) == 1 and "'lower'" in clear[0] and "'slide_lower'" in clear[0]


def test_a_thin_piece_leaves_the_rest_of_its_clearance_to_the_other_face(tmp_path):
    """A thin sheet (3 mm: a small stapler's arm plate) sliding on its neighbour with no gap can give at most
    MAX_SQUEEZE of its width; the neighbour's face gives the rest, so the pair still reads apart through the
    engines' margins (gap >= RUNNING_CLEARANCE) where a small object's parts slide past each other."""
    from tests.tasks.state.test_clearance import W, write_stacked_drawers

    model = urdf.read_urdf(write_stacked_drawers(tmp_path / "drawers"))
    pieces = {"lower": [cp.Piece.of(_box([-0.03, -W, 0.022], [0.03, W, 0.025])[0])],
              "upper": [cp.Piece.of(_box([-0.03, -W, 0.025], [0.03, W, 0.045])[0])]}
    notes: list[str] = []
    assert sc.running_clearance(model, pieces, notes) == {("lower", "upper")}
    (lower,), (upper,) = pieces["lower"], pieces["upper"]
    assert lower.points[:, 2].max() == pytest.approx(0.025 - 0.0015) and lower.points[:, 2].min() == pytest.approx(0.022)
    assert upper.points[:, 2].min() == pytest.approx(0.025 + sc.RUNNING_CLEARANCE - 0.0015)
    assert upper.points[:, 2].max() == pytest.approx(0.045)  # its far face kept
    assert sc.sat_gap(lower.points, upper.points)[0] == pytest.approx(sc.RUNNING_CLEARANCE)
    (note,) = notes
    assert "1.5 mm running clearance" in note and "1 mm from its piece 0" in note, note


def test_a_stop_along_the_motion_keeps_its_contact(tmp_path):
    """A slider between two walls that touch its sides and against an end wall
    that touches its +x face at q = 0: the sides slide (squeezed in y on both
    sides), the end wall is a stop (the slider keeps its length in x)."""
    from tests.tasks.state.test_clearance import W, write_channel

    urdf_path = write_channel(tmp_path / "channel", side_gap=0.0, end_stop=True)
    model = urdf.read_urdf(urdf_path)
    pieces, notes = cg.link_pieces(model, lambda g: urdf_path.parent / str(g.filename))
    (slider,) = pieces["slider"]
    assert np.ptp(slider.points[:, 0]) == pytest.approx(0.06)
    assert slider.points[:, 0].max() == pytest.approx(0.03)
    assert np.ptp(slider.points[:, 1]) == pytest.approx(2 * W - 2 * sc.RUNNING_CLEARANCE)
    assert len([n for n in notes if sc.RUNNING_CLEARANCE_NOTE in n]) == 2


def test_clear_sliding_contact_leaves_deep_overlaps_and_stops():
    """The sliding test on two boxes: touching side by side across the motion
    slides; touching along the motion is a stop; an overlap deeper than
    ``deepest`` is left to the state search."""
    a = np.array([[x, y, z] for x in (0.0, 1.0) for y in (0.0, 1.0) for z in (0.0, 1.0)])
    along_x = lambda c: np.array([1.0, 0.0, 0.0])  # noqa: E731
    pts, used, g = sc.clear_sliding_contact(a, a + [0.0, 1.0, 0.0], along_x)
    assert g == pytest.approx(0.0) and used == pytest.approx(sc.RUNNING_CLEARANCE)
    assert pts[:, 1].max() == pytest.approx(1.0 - sc.RUNNING_CLEARANCE) and pts[:, 1].min() == pytest.approx(0.0)
    assert sc.clear_sliding_contact(a, a + [1.0, 0.0, 0.0], along_x) is None  # a stop
    assert sc.clear_sliding_contact(a, a + [0.0, 1.1, 0.0], along_x) is None  # apart
    assert sc.clear_sliding_contact(a, a + [0.0, 0.9, 0.0], along_x, deepest=0.05) is None  # 0.1 m deep


def test_a_square_dial_is_shrunk_about_its_axis_to_pass_a_slab_below_it():
    """A 20 mm square dial turning about z through its centre, 13.9 mm above a
    slab's top (3.9 mm clear at 0, its corners 14.1 mm out at 45 deg): passing
    the slab slides, so the dial is shrunk about its axis until every sampled
    turn clears by RUNNING_CLEARANCE; a slab it is already near at 0, one it
    clears all round, and a wall a lever's tip turns into head-on (a stop) are
    left alone."""
    h = 0.01
    dial = np.array([[x, y, z] for x in (-h, h) for y in (-h, h) for z in (0.0, 0.01)])
    slab = np.array([[x, y, z] for x in (-0.05, 0.05) for y in (-0.05, -0.0139) for z in (-0.01, 0.02)])
    origin, axis = np.zeros(3), np.array([0.0, 0.0, 1.0])
    turn = np.linspace(0.0, 2 * np.pi, sc.SWEPT_SAMPLES, endpoint=False)
    pts, shrink, least = sc._clear_turning_piece(dial, slab, origin, axis, turn)
    assert least < 0.0 and 0.15 < shrink < sc.MAX_RADIAL_SHRINK  # the corners reached 0.24 mm into the slab
    assert sc._swept_gap(pts, slab, origin, axis, turn)[0] >= sc.RUNNING_CLEARANCE - 1e-6
    assert np.allclose(pts[:, 2], dial[:, 2])  # along the axis unchanged
    assert sc._clear_turning_piece(dial, slab + [0.0, 0.002, 0.0], origin, axis, turn) is None  # near at 0 already
    assert sc._clear_turning_piece(dial, slab - [0.0, 0.01, 0.0], origin, axis, turn) is None  # clear all round
    lever = np.array([[x, y, z] for x in (0.0, 0.03) for y in (-0.002, 0.002) for z in (0.0, 0.01)])
    wall = np.array([[x, y, z] for x in (0.02, 0.04) for y in (0.01, 0.05) for z in (-0.01, 0.02)])
    assert sc._swept_gap(lever, wall, origin, axis, np.linspace(0.0, 0.25, 6))[0] < sc.RUNNING_CLEARANCE
    assert sc._clear_turning_piece(lever, wall, origin, axis, np.linspace(0.0, 0.25, 6)) is None  # its tip runs into it


def test_pieces_are_kept_on_disk_by_content_and_code(tmp_path, monkeypatch):
    """A second process (the in-memory caches cleared) loads the same pieces
    and notes from the on-disk cache (asset2sim.array_cache) instead of
    computing them; a copy of the meshes elsewhere hits the same entry; a
    changed mesh, a changed limit or a changed source of the code misses; an
    unreadable entry is ignored and rewritten; ASSET2SIM_CACHE=off writes nothing."""
    from asset2sim import array_cache
    from tests.tasks.state.test_clearance import write_stacked_drawers

    monkeypatch.setenv("ASSET2SIM_CACHE", str(tmp_path / "cache"))

    def fresh():
        cg._PIECE_CACHE.clear()
        cg._STATE_CACHE.clear()

    def pieces_of(folder: Path, model=None):
        model = model or urdf.read_urdf(folder / "mobility.urdf")
        return cg.link_pieces(model, lambda g: folder / str(g.filename))

    folder = write_stacked_drawers(tmp_path / "a").parent
    fresh()
    computed, notes = pieces_of(folder)
    entries = list((tmp_path / "cache" / "pieces").glob("*.npz"))
    assert len(entries) == 1
    fresh()
    calls = []
    monkeypatch.setattr(cg, "_resolve_containment", lambda *a, **k: calls.append(a))
    loaded, notes2 = pieces_of(folder)
    assert calls == [] and notes2 == notes and set(loaded) == set(computed)
    for name in computed:
        for a, b in zip(computed[name], loaded[name], strict=True):
            assert np.array_equal(a.points, b.points) and np.array_equal(a.equations, b.equations)
            assert a.volume == b.volume and a.sources == b.sources
    # the same meshes in another folder: the same entry
    import shutil
    shutil.copytree(folder, tmp_path / "b")
    fresh()
    pieces_of(tmp_path / "b")
    assert calls == []
    monkeypatch.undo()
    monkeypatch.setenv("ASSET2SIM_CACHE", str(tmp_path / "cache"))
    # a changed limit, a changed mesh: misses (new entries)
    model = urdf.read_urdf(folder / "mobility.urdf")
    model.joint("slide_upper").limit.upper = 0.05
    fresh()
    pieces_of(folder, model)
    (tmp_path / "b" / "upper.obj").write_text((tmp_path / "b" / "upper.obj").read_text().replace("0.045", "0.044"))
    fresh()
    pieces_of(tmp_path / "b")
    assert len(list((tmp_path / "cache" / "pieces").glob("*.npz"))) == 3
    # an unreadable entry is ignored and rewritten
    entries[0].write_bytes(b"not an npz")
    fresh()
    with pytest.warns(array_cache.CacheWarning, match=r"rejected: not a readable entry .*computing it again"):
        again, _ = pieces_of(folder)
    assert all(np.array_equal(a.points, b.points) for n in computed for a, b in zip(computed[n], again[n]))
    assert array_cache.load("pieces", entries[0].stem) is not None
    # the code's source is part of the key
    array_cache.source_digest.cache_clear()
    monkeypatch.setattr(cg, "PIECES_CODE", cg.PIECES_CODE + ("asset2sim.atomic",))
    assert cg._piece_keys(urdf.read_urdf(folder / "mobility.urdf"), lambda g: folder / str(g.filename), 16, True)[1] != entries[0].stem
    # off: nothing written
    monkeypatch.setenv("ASSET2SIM_CACHE", "off")
    assert array_cache.cache_dir() is None
    shutil.rmtree(tmp_path / "cache")
    fresh()
    pieces_of(folder)
    assert not (tmp_path / "cache").exists()



def test_pieces_made_once_per_process_wherever_the_meshes_lie(tmp_path, monkeypatch):
    """With the on-disk cache off, the same meshes under the same names in another folder (a candidate written into
    the workspace, then published into the output folder) are not cut into pieces again; a changed mesh is."""
    import shutil
    from tests.tasks.state.test_clearance import write_stacked_drawers

    monkeypatch.setenv("ASSET2SIM_CACHE", "off")
    cg._PIECE_CACHE.clear()
    cg._STATE_CACHE.clear()
    made = []
    real = cg._made_pieces
    monkeypatch.setattr(cg, "_made_pieces", lambda *a, **k: made.append(a) or real(*a, **k))
    a = write_stacked_drawers(tmp_path / "a").parent
    shutil.copytree(a, tmp_path / "b")
    results = [cg.link_pieces(urdf.read_urdf(f / "mobility.urdf"), lambda g, f=f: f / str(g.filename), {})
               for f in (a, tmp_path / "b")]
    assert len(made) == 1 and results[0][1] == results[1][1]
    (tmp_path / "b" / "upper.obj").write_text((tmp_path / "b" / "upper.obj").read_text().replace("0.045", "0.044"))
    cg.link_pieces(urdf.read_urdf(tmp_path / "b" / "mobility.urdf"), lambda g: tmp_path / "b" / str(g.filename))
    assert len(made) == 2

def _wobbly(tmp_path: Path, short: float) -> Path:
    """A 0.2 m square slab on four 1 cm feet, one foot ``short`` m shorter
    (the body, z up), with a lid hinged on top."""
    feet = [_box([x, y, 0.0 if k else short], [x + 0.03, y + 0.03, 0.01])
            for k, (x, y) in enumerate([(-0.1, -0.1), (0.07, -0.1), (-0.1, 0.07), (0.07, 0.07)])]
    # the short foot is the first one: k == 0
    return _asset(tmp_path, [_box([-0.1, -0.1, 0.01], [0.1, 0.1, 0.03]), *feet], [_box([-0.1, -0.1, 0.03], [0.1, 0.1, 0.04])])


def _foot_bottoms(pieces: list) -> list[float]:
    """Lowest z of each piece below the slab (the feet), sorted by x then y."""
    feet = [p for p in pieces if p.points[:, 2].max() <= 0.01 + 1e-9]
    feet.sort(key=lambda p: (round(float(p.points[:, 0].min()), 3), round(float(p.points[:, 1].min()), 3)))
    return [float(p.points[:, 2].min()) for p in feet]


def test_a_free_standing_body_stands_on_every_foot(tmp_path):
    """A foot 0.6 mm short (within LEVEL_TOLERANCE) is brought down onto the
    plane of the others when the object is free-standing, and a note says
    so; without levelling (a mounted root) it stays short."""
    folder = _wobbly(tmp_path, 0.0006)
    model = urdf.read_urdf(folder / "mobility.urdf")
    path = lambda g: folder / str(g.filename)  # noqa: E731
    plain, _ = cg.link_pieces(model, path, {"hinge": 0.0})
    assert _foot_bottoms(plain["body"]) == pytest.approx([0.0006, 0.0, 0.0, 0.0], abs=1e-9)
    level, notes = cg.link_pieces(model, path, {"hinge": 0.0}, level=True)
    assert _foot_bottoms(level["body"]) == pytest.approx([0.0, 0.0, 0.0, 0.0], abs=1e-9)
    (line,) = [n for n in notes if fp.LEVEL_NOTE in n]
    assert "'body'" in line and "0.6 mm" in line
    assert [p.points.tolist() for p in level["lid"]] == [p.points.tolist() for p in plain["lid"]]  # a moving link is left alone


def test_a_foot_far_off_the_ground_is_not_levelled(tmp_path):
    """A foot 3 mm short is a shape, not modelling noise: kept."""
    folder = _wobbly(tmp_path, 0.003)
    model = urdf.read_urdf(folder / "mobility.urdf")
    level, notes = cg.link_pieces(model, lambda g: folder / str(g.filename), {"hinge": 0.0}, level=True)
    assert _foot_bottoms(level["body"]) == pytest.approx([0.003, 0.0, 0.0, 0.0], abs=1e-9)
    assert not [n for n in notes if fp.LEVEL_NOTE in n]


def test_an_appliance_stands_on_its_levelling_feet(tmp_path):
    """The same 3 mm short foot on an object whose category has levelling feet is set down onto the others' plane by
    its bottom face (its height kept), and the note says the feet were set; on feet that take up 8 mm, a foot 9 mm
    short stays as modelled; the slab 10 mm up stays on its feet under 5 mm feet."""
    folder = _wobbly(tmp_path, 0.003)
    model = urdf.read_urdf(folder / "mobility.urdf")
    level, notes = cg.link_pieces(model, lambda g: folder / str(g.filename), {"hinge": 0.0}, level=True, feet=0.005)
    assert _foot_bottoms(level["body"]) == pytest.approx([0.0, 0.0, 0.0, 0.0], abs=1e-9)
    short = min((p for p in level["body"] if p.points[:, 2].max() <= 0.01 + 1e-9), key=lambda p: (p.points[:, 0].min(), p.points[:, 1].min()))
    assert float(short.points[:, 2].max()) == pytest.approx(0.01)  # the foot reaches the slab still
    assert min(float(p.points[:, 2].min()) for p in level["body"] if p.points[:, 2].max() > 0.01 + 1e-9) == pytest.approx(0.01)
    (line,) = [n for n in notes if fp.LEVEL_NOTE in n]
    assert "3 mm" in line and "its levelling feet set" in line
    assert load_priors().categories["Refrigerator"].levelling_feet_m == 0.012
    deep = _wobbly(tmp_path / "deep", 0.009)  # 9 mm short of a 1 cm foot
    kept, _ = cg.link_pieces(urdf.read_urdf(deep / "mobility.urdf"), lambda g: deep / str(g.filename), {"hinge": 0.0},
                             level=True, feet=0.008)
    assert _foot_bottoms(kept["body"]) == pytest.approx([0.009, 0.0, 0.0, 0.0], abs=1e-9)


def _feet_on_the_ground(urdf_path: Path) -> int:
    """Feet (quadrants of the 0.2 m slab) touching the ground after 1 s at
    rest in PyBullet, the root free."""
    from asset2sim.engines.base import SessionOptions
    from asset2sim.engines.registry import open_session

    with open_session("pybullet", urdf_path, SessionOptions(initial_state={"hinge": 0.0})) as s:
        s.step(240)
        x0, y0 = s.link_frame("body")[0][:2]
        cps = s._p.getContactPoints(bodyA=s.body, bodyB=s.plane, physicsClientId=s.cid)
        return len({(c[5][0] > x0, c[5][1] > y0) for c in cps if c[8] < 1e-4})


def test_written_free_standing_object_rests_on_four_feet_mounted_one_is_not_levelled(tmp_path):
    """Through the writer: free-standing (the SPEC's default), PyBullet puts
    the object on the ground touching all four feet; with a fixed root the
    written feet keep their shape."""
    from asset2sim.schemas.overlay import RootMount

    folder = _wobbly(tmp_path, 0.0006)
    _write(folder, tmp_path / "free")
    assert _feet_on_the_ground(tmp_path / "free" / "mobility.urdf") == 4
    model = urdf.read_urdf(tmp_path / "free" / "mobility.urdf")
    lows = sorted(float(read_mesh(c.path).vertices[:, 2].min()) for c in model.links["body"].collisions
                  if float(read_mesh(c.path).vertices[:, 2].max()) <= 0.01 + 1e-9)
    assert lows == pytest.approx([0.0] * 4, abs=1e-9)

    asset = extract_asset(folder)
    ov = Overlay(estimator=EstimatorInfo(name="test"), scale=1.0, mounting=RootMount(kind="wall-mounted", fixed=True),
                 joints={j.name: JointDynamics(damping=0.1, friction=0.01) for j in asset.movable_joints()})
    ov, _ = validate_overlay(ov, asset, analyze_asset(asset))
    write_output(asset, ov, tmp_path / "mounted", {"hinge": 0.0})
    model = urdf.read_urdf(tmp_path / "mounted" / "mobility.urdf")
    lows = sorted(float(read_mesh(c.path).vertices[:, 2].min()) for c in model.links["body"].collisions
                  if float(read_mesh(c.path).vertices[:, 2].max()) <= 0.01 + 1e-9)
    assert lows == pytest.approx([0.0, 0.0, 0.0, 0.0006], abs=1e-9)
    assert _feet_on_the_ground(tmp_path / "mounted" / "mobility.urdf") == 3  # put down free, it stands on three


def test_surface_rows_are_numpy_s_distinct_rows_with_signed_zeros_merged():
    """:func:`containment_cuts._unique_rows` gives ``np.unique(points, axis=0)`` (sorted by x, y, z) on points with
    repeated rows, a -0.0 counted as 0.0 (one row, never a negative zero)."""
    rng = np.random.default_rng(5)
    pts = rng.integers(-3, 4, size=(400, 3)).astype(float) / 4
    pts[rng.random(pts.shape) < 0.1] = -0.0
    got = cc._unique_rows(pts)
    want = np.unique(pts + 0.0, axis=0)
    assert got.tobytes() == want.tobytes() and len(got) < len(pts)
    assert not np.signbit(got[got == 0]).any()
    tri = np.array([[[0.0, 0, 0], [1, 0, 0], [0, 1, 0]], [[-0.0, 0, 0], [1, 0, 0], [0, 1, 0]]])  # the same triangle twice
    samples = cc.surface_samples(tri, 0.25)
    # the longest edge sqrt(2) in ceil(sqrt(2) / 0.25) = 6 steps: a grid of 28 points, once for both triangles
    assert len(samples) == 28 and samples.tobytes() == np.unique(samples, axis=0).tobytes()


def test_a_hull_keeps_the_vertices_qhull_names_in_input_order():
    """:func:`convex_pieces._hull`'s vertices are scipy's ``hull.points[hull.vertices]`` (sorted indices)."""
    from scipy.spatial import ConvexHull

    pts = np.random.default_rng(7).random((300, 3))
    verts, eqs, vol = cp._hull(pts)
    ref = ConvexHull(pts)
    assert verts.tobytes() == ref.points[ref.vertices].tobytes()
    assert np.array_equal(eqs, ref.equations) and vol == ref.volume


def _drop_slivers_reference(pieces):
    """drop_slivers as the full plane test over every vertex, the definition the quick test must not change."""
    if len(pieces) <= 1:
        return list(pieces)
    kept = []
    for i in sorted(range(len(pieces)), key=lambda i: -pieces[i].volume):
        p = pieces[i]
        if kept and p.volume < cp.MIN_PIECE_VOLUME:
            continue
        size = float(np.ptp(p.points, axis=0).max())
        if any(np.all(p.points @ q.equations[:, :3].T + q.equations[:, 3] <= 1e-9 * max(size, 1e-9)) for q in kept):
            continue
        kept.append(p)
    return [p for p in pieces if any(p is k for k in kept)]


def test_the_quick_outside_test_never_contradicts_the_full_one():
    """A point clearly beyond a face is found on the few points tested; a point on a face (within rounding) is
    left to the full test: the quick test never says outside where the full test finds every point inside."""
    box = cp.Piece.of(_box([0, 0, 0], [0.1, 0.05, 0.02])[0])
    tol = 1e-9 * 0.1
    assert cp._surely_outside(np.array([[0.05, 0.025, 0.03]]), box, tol)  # 1 cm above the top
    on_face = np.array([[0.1, 0.025, 0.01], [0.0, 0.0, 0.0], [0.1 + 0.5 * tol, 0.05, 0.02]])
    assert not cp._surely_outside(on_face, box, tol)
    assert np.all(on_face @ box.equations[:, :3].T + box.equations[:, 3] <= tol)  # the full test: inside
    assert not cp._surely_outside(np.zeros((0, 3)), box, tol)


@pytest.mark.slow  # end to end: a real object's whole decomposition
@needs_shared
def test_drop_slivers_on_a_real_object_equals_the_full_plane_test():
    """On the pieces of laptop 9912's parts and of toilet 102703's, their cut halves and duplicates (every piece
    again, and a piece's own half inside it), the quick test keeps exactly what the full test keeps."""
    for aid in ("9912", "102703"):
        model = urdf.read_urdf(SHARED / aid / "mobility.urdf")
        pieces = []
        for link in model.links.values():
            for c in link.collisions:
                if c.kind != "mesh":
                    continue
                v = read_mesh(Path(c.path) if c.path else SHARED / aid / str(c.filename)).vertices
                pc = cp.solid_piece(np.asarray(v, float) * np.asarray(c.scale, float))
                if pc is not None:
                    pieces.append(pc)
        pieces = pieces[:60]
        halves = [h for p in pieces[:20] for h in [cp.clip_piece(p, np.array([1.0, 0, 0]), -float(p.points[:, 0].mean()))] if h is not None]
        mixed = pieces + halves + pieces[:10]
        got = cp.drop_slivers(mixed)
        assert [id(p) for p in got] == [id(p) for p in _drop_slivers_reference(mixed)]
        assert len(got) < len(mixed)  # the test can fail: duplicates and halves inside their pieces go


def test_a_surface_is_split_once_per_content(monkeypatch):
    """split_surface kept by content: the same samples around the same points are split once (the cuts
    measured once), the answer equals a fresh split and cannot be changed through it, the caller's
    samples stay writable; other points kept out are split anew."""
    rng = np.random.default_rng(5)
    shell = rng.uniform(-0.05, 0.05, (3000, 3))
    shell /= np.abs(shell).max(axis=1, keepdims=True) / 0.05  # points on a 10 cm box's surface
    child = rng.uniform(-0.01, 0.01, (200, 3))  # a child in its middle
    measured: list[int] = []
    real = cc.depth_inside

    def counting(points, piece):
        measured.append(1)
        return real(points, piece)

    monkeypatch.setattr(cc, "depth_inside", counting)
    cc._SPLITS.clear()
    first = cc.split_surface(shell, child, cp.CONTAINMENT_TOLERANCE, 8, 0.004)
    n = len(measured)
    assert len(first) > 1 and n > 0  # the box was cut around the child
    again = cc.split_surface(shell.copy(), child.copy(), cp.CONTAINMENT_TOLERANCE, 8, 0.004)
    assert len(measured) == n  # nothing measured again
    fresh = cc._split_surface(shell.copy(), child, cp.CONTAINMENT_TOLERANCE, 8, 0.004)
    assert len(again) == len(fresh) and all(np.array_equal(a, b) for a, b in zip(again, fresh))
    with pytest.raises(ValueError):
        again[0][0, 0] = 1.0
    assert shell.flags.writeable
    cc.split_surface(shell, child + 0.001, cp.CONTAINMENT_TOLERANCE, 8, 0.004)
    assert len(measured) > n
