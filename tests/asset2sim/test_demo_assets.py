"""The demo-asset generator: PartNet-Mobility layout, kinematics, clearances, determinism."""

from __future__ import annotations

import csv
import hashlib
import json
import os
from pathlib import Path
from xml.etree import ElementTree as ET

import numpy as np
import pytest

from asset2sim import atomic, demo_assets, demo_objects
from asset2sim.demo_assets import DEMO_OBJECTS, LAPTOP_MODEL_OPENING
from asset2sim.demo_geometry import DemoArticulation, Part, Pose, box_xyz, fmt_number, mtl_text, obj_text, open_box
from tests.helpers import tree_hashes

IDS = [o.asset_id for o in DEMO_OBJECTS]

# id -> joint -> (type, axis in the object frame, lower, upper)
EXPECTED_JOINTS = {
    "box_lid": {"joint_0": ("revolute", (-1, 0, 0), -0.5, 1.9)},
    "cabinet_2drawer": {
        "joint_0": ("prismatic", (0, 0, 1), 0.0, 0.5),
        "joint_1": ("prismatic", (0, 0, 1), 0.0, 0.5),
    },
    "laptop": {"joint_1": ("revolute", (-1, 0, 0), -LAPTOP_MODEL_OPENING, 0.35)},
    "microwave": {"joint_0": ("revolute", (0, -1, 0), 0.0, 1.75)},
    "trash_can": {"joint_0": ("revolute", (1, 0, 0), -1.9, 0.0)},
    "door": {"joint_0": ("revolute", (0, -1, 0), 0.0, 1.75)},
}
EXPECTED_CATEGORY = {
    "box_lid": "Box",
    "cabinet_2drawer": "StorageFurniture",
    "laptop": "Laptop",
    "microwave": "Microwave",
    "trash_can": "TrashCan",
    "door": "Door",
}


@pytest.fixture(scope="module")
def dataset(tmp_path_factory) -> Path:
    return demo_assets.build_demo_dataset(tmp_path_factory.mktemp("demo") / "raw")


def _load_bullet(urdf: Path, self_collision_with_parent: bool = True):
    import pybullet as p

    cid = p.connect(p.DIRECT)
    flags = p.URDF_USE_SELF_COLLISION
    if self_collision_with_parent:
        flags |= p.URDF_USE_SELF_COLLISION_INCLUDE_PARENT
    body = p.loadURDF(str(urdf), useFixedBase=True, flags=flags, physicsClientId=cid)
    joints = {}
    links = {-1: p.getBodyInfo(body, physicsClientId=cid)[0].decode()}
    for j in range(p.getNumJoints(body, physicsClientId=cid)):
        info = p.getJointInfo(body, j, physicsClientId=cid)
        joints[info[1].decode()] = (j, info)
        links[j] = info[12].decode()
    return p, cid, body, joints, links


def _min_distances(p, cid, body, links) -> dict[frozenset, float]:
    """Smallest signed distance (units) between every pair of links with geometry,
    keyed by the pair's names (a frozenset)."""
    p.performCollisionDetection(physicsClientId=cid)
    out = {}
    idx = sorted(links)
    for a in idx:
        for b in idx:
            if b <= a:
                continue
            pts = p.getClosestPoints(body, body, 0.05, a, b, physicsClientId=cid)
            if pts:
                out[frozenset((links[a], links[b]))] = min(pt[8] for pt in pts)
    return out


def test_manifest_and_folder_layout(dataset: Path):
    with open(dataset / "manifest.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert [r["id"] for r in rows] == IDS
    assert list(rows[0]) == ["id", "category", "prompt", "task"]
    for row in rows:
        folder = dataset / row["id"]
        assert row["category"] == EXPECTED_CATEGORY[row["id"]]
        assert len(row["prompt"]) > 20
        assert row["task"] == demo_objects.CATEGORY_TASKS[row["category"]]
        meta = json.loads((folder / "meta.json").read_text())
        assert meta["model_cat"] == row["category"]
        assert (folder / "mobility.urdf").is_file()
        bbox = json.loads((folder / "bounding_box.json").read_text())
        extent = np.array(bbox["max"]) - np.array(bbox["min"])
        assert 0.7 < extent.max() < 1.5, "roughly unit size like PartNet-Mobility"
        # semantics: every link but base, joint kinds from the PartNet vocabulary
        tree = ET.parse(folder / "mobility.urdf").getroot()
        link_names = {l.get("name") for l in tree.findall("link")} - {"base"}
        sem = [line.split() for line in (folder / "semantics.txt").read_text().splitlines()]
        assert {s[0] for s in sem} == link_names
        assert all(len(s) == 3 and s[1] in {"hinge", "slider", "free", "heavy", "static"} for s in sem)
    # a moving-joint prompt per object mentions a state or a dynamics word
    assert any("slightly open" in r["prompt"] for r in rows)


@pytest.mark.parametrize("asset_id", IDS)
def test_urdf_is_partnet_style_and_meshes_exist(dataset: Path, asset_id: str):
    import trimesh
    import yourdfpy

    folder = dataset / asset_id
    text = (folder / "mobility.urdf").read_text()
    assert "<inertial" not in text and "<dynamics" not in text and "<mass" not in text
    root = ET.fromstring(text)
    # base root link without geometry, fixed joint with PartNet's y-up -> z-up rotation
    base_joints = [j for j in root.findall("joint") if j.find("parent").get("link") == "base"]
    assert len(base_joints) == 1 and base_joints[0].get("type") == "fixed"
    assert base_joints[0].find("origin").get("rpy") == "1.570796326794897 0 -1.570796326794897"
    assert not list(root.find("link[@name='base']"))

    urdf = yourdfpy.URDF.load(str(folder / "mobility.urdf"), build_scene_graph=True, load_meshes=True)
    assert urdf.base_link == "base"
    moving_children = {j.child for j in urdf.robot.joints if j.type != "fixed"}
    for link in urdf.robot.links:
        if link.name == "base":
            continue
        assert link.collisions, f"{asset_id}/{link.name} has no collision geometry"
        files = [c.geometry.mesh.filename for c in link.collisions]
        assert files == [v.geometry.mesh.filename for v in link.visuals]
        if link.name in moving_children:
            pieces = 0
            for f in files:
                assert not Path(f).is_absolute() and f.startswith("textured_objs/")
                mesh = trimesh.load(folder / f, force="mesh")
                pieces += len(mesh.split(only_watertight=False))
            assert len(files) >= 2 and pieces >= 4, f"{asset_id}/{link.name} should be multi-piece"
    for obj in sorted((folder / "textured_objs").glob("*.obj")):
        assert obj.with_suffix(".mtl").is_file()
        # pieces of one OBJ share no vertex, so merging keeps every piece a closed volume
        mesh = trimesh.load(obj, force="mesh")
        assert mesh.is_watertight and mesh.is_winding_consistent, obj
        for piece in mesh.split(only_watertight=False):
            assert piece.is_volume and piece.volume > 0, obj


@pytest.mark.parametrize("asset_id", IDS)
def test_joints_and_limits_in_pybullet(dataset: Path, asset_id: str):
    import yourdfpy

    urdf = yourdfpy.URDF.load(str(dataset / asset_id / "mobility.urdf"), load_meshes=False)
    movable = {j.name: j for j in urdf.robot.joints if j.type != "fixed"}
    assert set(movable) == set(EXPECTED_JOINTS[asset_id])
    for name, (jtype, axis, lo, hi) in EXPECTED_JOINTS[asset_id].items():
        j = movable[name]
        assert j.type == jtype
        np.testing.assert_allclose(j.axis, axis)
        assert j.limit.lower == pytest.approx(lo, abs=1e-8)
        assert j.limit.upper == pytest.approx(hi, abs=1e-8)

    p, cid, body, joints, _ = _load_bullet(dataset / asset_id / "mobility.urdf")
    try:
        bullet_type = {"revolute": p.JOINT_REVOLUTE, "prismatic": p.JOINT_PRISMATIC}
        for name, (jtype, _axis, lo, hi) in EXPECTED_JOINTS[asset_id].items():
            _, info = joints[name]
            assert info[2] == bullet_type[jtype]
            assert info[8] == pytest.approx(lo, abs=1e-6) and info[9] == pytest.approx(hi, abs=1e-6)
    finally:
        p.disconnect(cid)


@pytest.mark.parametrize("entry", DEMO_OBJECTS, ids=IDS)
def test_closed_and_open_states_are_clear_of_the_parent(dataset: Path, entry):
    """No link overlaps another (parent included) in the closed state nor fully
    open; the clearance is small (a real fit, not a loose placement)."""
    p, cid, body, joints, links = _load_bullet(dataset / entry.asset_id / "mobility.urdf")
    try:
        for jname, q in entry.closed_positions.items():
            p.resetJointState(body, joints[jname][0], q, physicsClientId=cid)
        closed = _min_distances(p, cid, body, links)
        assert closed and min(closed.values()) > -1e-4, closed
        for jname in entry.closed_positions:
            child = joints[jname][1][12].decode()
            near = [d for pair, d in closed.items() if child in pair]
            assert min(near) < 0.02, f"{jname} is not seated when closed: {near}"
        # fully open: the limit away from the closed position
        for jname, q in entry.closed_positions.items():
            _, info = joints[jname]
            lo, hi = info[8], info[9]
            far = hi if abs(hi - q) > abs(lo - q) else lo
            p.resetJointState(body, joints[jname][0], far, physicsClientId=cid)
        opened = _min_distances(p, cid, body, links)
        assert min(opened.values(), default=1.0) > -1e-4, opened
    finally:
        p.disconnect(cid)


def test_zero_pose_is_not_always_closed(dataset: Path):
    """The laptop is modelled open (closed at its lower limit) and the box lid's
    range extends past closed into the box: closed-state detection must not
    assume q = 0 or a limit."""
    p, cid, body, joints, links = _load_bullet(dataset / "laptop" / "mobility.urdf")
    try:
        screen = joints["joint_1"][0]
        p.performCollisionDetection(physicsClientId=cid)
        top_open = p.getAABB(body, screen, physicsClientId=cid)[1][2]
        assert top_open > 0.6  # modelled standing up (units)
        d_zero = _min_distances(p, cid, body, links)[frozenset(("link_0", "link_1"))]
        p.resetJointState(body, screen, -LAPTOP_MODEL_OPENING, physicsClientId=cid)
        d_closed = _min_distances(p, cid, body, links)[frozenset(("link_0", "link_1"))]
        assert 0 < d_closed < 0.02 and d_zero > d_closed
        # the screen lies flat on the base when closed: its far edge is low
        closed_pts = p.getClosestPoints(body, body, 0.05, 0, screen, physicsClientId=cid)
        assert len(closed_pts) > 0
    finally:
        p.disconnect(cid)

    p, cid, body, joints, links = _load_bullet(dataset / "box_lid" / "mobility.urdf")
    try:
        p.resetJointState(body, joints["joint_0"][0], -0.5, physicsClientId=cid)
        d = _min_distances(p, cid, body, links)[frozenset(("link_0", "link_1"))]
        assert d < -0.01, "lower limit of the box lid should push it into the body"
    finally:
        p.disconnect(cid)


def test_loads_in_the_project_engine(dataset: Path):
    from asset2sim.engines.base import SessionOptions
    from asset2sim.engines.registry import open_session

    for entry in DEMO_OBJECTS:
        session = open_session(
            "pybullet",
            dataset / entry.asset_id / "mobility.urdf",
            SessionOptions(initial_state=entry.closed_positions, fixed_base=True, gravity=False),
        )
        try:
            assert set(session.joint_names) == set(EXPECTED_JOINTS[entry.asset_id])
            phi, _pairs = session.self_penetration()
            assert phi == 0.0
        finally:
            session.close()


def _generated(folder: Path) -> dict[str, str]:
    """tree_hashes of a generated folder without the generator's record."""
    return {k: v for k, v in tree_hashes(folder).items() if Path(k).name != demo_assets.RECORD_NAME}


def test_output_is_deterministic_and_rebuild_replaces_only_its_own(tmp_path: Path):
    a = demo_assets.build_demo_dataset(tmp_path / "a")
    b = demo_assets.build_demo_dataset(tmp_path / "b")
    ha, hb = tree_hashes(a), tree_hashes(b)
    assert ha == hb and len(ha) > 5 * 10
    # a rebuild over an earlier build gives the same tree; a file an older generator recorded and no longer
    # writes is removed
    laptop = a / "laptop"
    (laptop / "textured_objs" / "old.obj").write_text("an older generator's mesh")
    record = json.loads((laptop / demo_assets.RECORD_NAME).read_text())
    record["files"]["textured_objs/old.obj"] = hashlib.sha256(b"an older generator's mesh").hexdigest()
    (laptop / demo_assets.RECORD_NAME).write_text(json.dumps(record))
    demo_assets.build_demo_dataset(a)
    assert tree_hashes(a) == hb
    # in-memory files equal the written ones
    files = demo_assets.demo_files("microwave")
    assert {k: atomic.sha256_file(b / "microwave" / k) for k in files} == {
        k: hashlib.sha256(v).hexdigest() for k, v in files.items()
    }


def test_never_overwrites_foreign_data(tmp_path: Path):
    foreign = tmp_path / "mine"
    foreign.mkdir()
    (foreign / "notes.txt").write_text("keep me")
    with pytest.raises(demo_assets.OutputError) as info:
        demo_assets.build_box_with_lid(foreign)
    assert info.value.code == "OUTPUT_NOT_GENERATED" and "notes.txt" in str(info.value)
    assert (foreign / "notes.txt").read_text() == "keep me"
    with pytest.raises(KeyError):
        demo_assets.demo_files("no_such_object")


def _hostile_folders(tmp_path: Path) -> dict[str, tuple[Path, dict[str, str]]]:
    """Folders a rebuild must not touch: name -> (folder, the user's files relative path -> text)."""
    forged = tmp_path / "forged"
    (forged / "experiments").mkdir(parents=True)
    (forged / "meta.json").write_text(json.dumps({"source": "asset2sim demo generator (built from geometry)"}))
    (forged / "experiments" / "results.csv").write_text("trial,score\n1,0.9\n")
    added = demo_assets.build_box_with_lid(tmp_path / "added")
    (added / "my_notes.txt").write_text("notes")
    (added / "textured_objs" / "my_better_mesh.obj").write_text("v 0 0 0\n")
    edited = demo_assets.build_box_with_lid(tmp_path / "edited")
    (edited / "mobility.urdf").write_text((edited / "mobility.urdf").read_text().replace("box", "my box"))
    claimed = demo_assets.build_box_with_lid(tmp_path / "claimed")  # a record naming a path outside
    (tmp_path / "victim.txt").write_text("victim")
    record = json.loads((claimed / demo_assets.RECORD_NAME).read_text())
    record["files"]["../victim.txt"] = hashlib.sha256(b"victim").hexdigest()
    (claimed / demo_assets.RECORD_NAME).write_text(json.dumps(record))
    (claimed / "link.obj").symlink_to(tmp_path / "victim.txt")
    return {"forged": (forged, {"meta.json": (forged / "meta.json").read_text(), "experiments/results.csv": "trial,score\n1,0.9\n"}),
            "added": (added, {"my_notes.txt": "notes", "textured_objs/my_better_mesh.obj": "v 0 0 0\n"}),
            "edited": (edited, {"mobility.urdf": (edited / "mobility.urdf").read_text()}),
            "claimed": (claimed, {"../victim.txt": "victim"})}


def test_asset_out_refuses_folders_holding_what_the_generator_did_not_write(tmp_path: Path, capsys):
    """``demo --asset-out DIR`` (the command, in process): a folder with a forged ``meta.json``, files a user added
    to a generated folder, a generated file the user edited, or a record claiming a path outside are refused
    with exit 4 naming the file and the way out; every file stays as it was."""
    from asset2sim import cli

    for name, (folder, kept) in _hostile_folders(tmp_path).items():
        before = tree_hashes(folder)
        rc = cli.main(["demo", "--object", "box_lid", "--asset-out", str(folder), "--no-refine"])
        err = capsys.readouterr().err
        assert rc == 4, (name, err)
        assert "OUTPUT_NOT_GENERATED" in err and "move them away" in err, (name, err)
        assert tree_hashes(folder) == before, name
        for rel, text in kept.items():
            assert (folder / rel).read_text() == text, (name, rel)
        assert not [p for p in folder.parent.iterdir() if p.name.startswith(".")], name


def test_asset_out_through_a_symlink_writes_the_folder_it_names(tmp_path: Path, capsys):
    """A symlink to an empty folder is followed: the files land in that folder, the symlink stays the symlink it
    was, and nothing hidden is left beside it; a rebuild of the same folder is a no-op; a dangling symlink or one
    to a file is refused."""
    from asset2sim import cli

    target = tmp_path / "real"
    target.mkdir()
    link = tmp_path / "link"
    link.symlink_to(target)
    for _ in range(2):
        assert cli.main(["demo", "--object", "laptop", "--asset-out", str(link), "--no-refine"]) == 0
        assert link.is_symlink() and Path(os.readlink(link)) == target
        assert _generated(target) == {k: hashlib.sha256(v).hexdigest() for k, v in demo_assets.demo_files("laptop").items()}
        assert sorted(p.name for p in tmp_path.iterdir()) == ["link", "real"]
    (tmp_path / "file").write_text("x")
    for bad in ("dangling", "to_file"):
        (tmp_path / bad).symlink_to(tmp_path / ("nowhere" if bad == "dangling" else "file"))
        assert cli.main(["demo", "--asset-out", str(tmp_path / bad), "--no-refine"]) == 4
        assert "OUTPUT_NOT_A_FOLDER" in capsys.readouterr().err
    assert (tmp_path / "file").read_text() == "x"


def test_dataset_rebuild_refuses_a_foreign_manifest_before_writing(tmp_path: Path):
    root = demo_assets.build_demo_dataset(tmp_path / "ds")
    (root / "manifest.csv").write_text("id,category,prompt\nmine,Box,my own rows\n")
    (root / "my_results.parquet").write_text("kept")  # other files of the root are left alone
    (root / "laptop" / "mobility.urdf").unlink()
    with pytest.raises(demo_assets.OutputError) as info:
        demo_assets.build_demo_dataset(root)
    assert info.value.code == "OUTPUT_NOT_GENERATED" and "manifest.csv" in str(info.value)
    assert "my own rows" in (root / "manifest.csv").read_text()
    assert not (root / "laptop" / "mobility.urdf").exists()  # nothing written before the refusal
    (root / "manifest.csv").unlink()
    demo_assets.build_demo_dataset(root)
    assert demo_assets.demo_dataset_is_current(root) and (root / "my_results.parquet").read_text() == "kept"


def test_single_builders_and_ensure(tmp_path: Path):
    builders = {
        "box_lid": demo_assets.build_box_with_lid,
        "cabinet_2drawer": demo_assets.build_two_drawer_cabinet,
        "laptop": demo_assets.build_laptop,
        "microwave": demo_assets.build_microwave,
        "trash_can": demo_assets.build_trash_can,
        "door": lambda out: demo_assets.build_object("door", out),
    }
    assert set(builders) == set(IDS)
    for asset_id, build in builders.items():
        out = build(tmp_path / "single" / asset_id)
        assert _generated(out) == {
            k: hashlib.sha256(v).hexdigest() for k, v in demo_assets.demo_files(asset_id).items()
        }
    root = tmp_path / "ensure"
    assert not demo_assets.demo_dataset_is_current(root)
    demo_assets.ensure_demo_dataset(root)
    assert demo_assets.demo_dataset_is_current(root)
    stamp = (root / "box_lid" / "mobility.urdf").stat().st_mtime_ns
    demo_assets.ensure_demo_dataset(root)  # current: nothing rewritten
    assert (root / "box_lid" / "mobility.urdf").stat().st_mtime_ns == stamp
    (root / "manifest.csv").unlink()
    demo_assets.ensure_demo_dataset(root)
    assert demo_assets.demo_dataset_is_current(root)


# ------------------------------------------------- geometry and object modules
def test_registry_is_re_exported_and_builders_make_articulations():
    assert demo_assets.DEMO_OBJECTS is demo_objects.DEMO_OBJECTS
    assert demo_assets.DemoObject is demo_objects.DemoObject
    for entry in DEMO_OBJECTS:
        obj = entry.make()
        assert isinstance(obj, DemoArticulation) and obj.asset_id == entry.asset_id
        links = {ln.name for ln in obj.links}
        assert {j.child for j in obj.joints} == links  # every link hangs from one joint
        assert set(entry.closed_positions) <= {j.name for j in obj.joints if j.type != "fixed"}


def test_obj_text_has_closed_outward_boxes():
    """Every box piece is 8 vertices and 12 triangles wound outward: the signed
    volume of each piece equals the box's volume, also after a rigid pose."""
    pose = Pose(axis=(-1.0, 0.0, 0.0), angle=1.2, pivot=(0.0, 0.1, -0.2))
    part = Part("lid-1", [box_xyz(0, 1, 0, 2, 0, 3), box_xyz(-1, -0.5, 0, 0.25, 0, 0.5)], (0.5, 0.5, 0.5), pose)
    lines = obj_text(part, "a.mtl").splitlines()
    v = np.array([[float(c) for c in ln.split()[1:]] for ln in lines if ln.startswith("v ")])
    f = np.array([[int(c) - 1 for c in ln.split()[1:]] for ln in lines if ln.startswith("f ")])
    assert v.shape == (16, 3) and f.shape == (24, 3)
    for piece, volume in ((f[:12], 6.0), (f[12:], 0.5 * 0.25 * 0.5)):
        a, b, c = v[piece[:, 0]], v[piece[:, 1]], v[piece[:, 2]]
        signed = float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum()) / 6.0
        assert signed == pytest.approx(volume, rel=1e-5)
    assert "Kd 0.5 0.5 0.5" in mtl_text((0.5, 0.5, 0.5))
    assert fmt_number(-0.0) == "0" and fmt_number(1 / 3) == "0.333333333"
    with pytest.raises(ValueError, match="degenerate box"):
        box_xyz(0, 0, 0, 1, 0, 1)


def test_open_box_walls_do_not_overlap():
    parts = open_box(-0.5, 0.5, -0.3, 0.2, -0.35, 0.35, 0.03, "body", (1.0, 1.0, 1.0))
    assert [p.name for p in parts] == ["body_bottom-1", "body_front-2", "body_back-3", "body_side-4", "body_side-5"]
    boxes = [b for p in parts for b in p.boxes]
    for i, a in enumerate(boxes):
        for b in boxes[i + 1:]:
            overlap = [min(a.hi[k], b.hi[k]) - max(a.lo[k], b.lo[k]) for k in range(3)]
            assert min(overlap) <= 1e-12
