"""Counted references: the input caps count what MuJoCo, PyBullet and USD will build, not only the bytes of distinct
files. One mesh file named many times (a URDF's 60 ``<visual>`` and ``<collision>`` elements, an MJCF's 60 ``<mesh>``
assets, a USD stage's 60 prims referencing one mesh) is refused with a named code before any simulator builds it,
quickly and in little memory; the same file named a few times still reads. (MuJoCo's compiler took 6 GB for a
10 MB STL named by 60 assets and ended in ``Caught an unknown exception!``.)"""

from __future__ import annotations

import struct
import tracemalloc
from pathlib import Path

import numpy as np
import pytest

from asset2sim.tasks.ingest.validate_input import validate_asset
from tests.helpers import no_hang


def _grid(n: int) -> tuple[np.ndarray, np.ndarray]:
    """A closed box-like surface of about 4 n^2 triangles: (vertices (k, 3) m, triangles (m, 3))."""
    u = np.linspace(0.0, 0.1, n + 1)
    x, y = np.meshgrid(u, u)
    top = np.stack([x.ravel(), y.ravel(), np.full(x.size, 0.02)], axis=1)
    bottom = top * [1, 1, 0]
    idx = np.arange(x.size).reshape(n + 1, n + 1)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()
    quads = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])
    tris = np.concatenate([quads, quads[:, ::-1] + x.size])
    return np.concatenate([top, bottom]), tris


def _obj(path: Path, n: int) -> int:
    v, f = _grid(n)
    path.write_text("".join(f"v {a:.5f} {b:.5f} {c:.5f}\n" for a, b, c in v) + "".join(f"f {i + 1} {j + 1} {k + 1}\n" for i, j, k in f))
    return len(f)


def _stl(path: Path, n: int) -> int:
    v, f = _grid(n)
    rec = np.zeros(len(f), dtype=[("n", "<f4", 3), ("v", "<f4", (3, 3)), ("a", "<u2")])
    rec["v"] = v[f]
    path.write_bytes(b"\0" * 80 + struct.pack("<I", len(f)) + rec.tobytes())
    return len(f)


def test_a_urdf_naming_one_mesh_sixty_times_is_refused(tmp_path):
    folder = tmp_path / "asset"
    folder.mkdir()
    faces = _obj(folder / "part.obj", 120)  # 57,600 triangles: one file far under the cap
    geoms = "".join(f'<visual><geometry><mesh filename="part.obj"/></geometry></visual>'
                    f'<collision><geometry><mesh filename="part.obj"/></geometry></collision>' for _ in range(30))
    (folder / "mobility.urdf").write_text(f'<robot name="r"><link name="base">{geoms}</link>'
                                          '<link name="lid"><visual><geometry><box size="0.1 0.1 0.01"/></geometry></visual></link>'
                                          '<joint name="j" type="revolute"><parent link="base"/><child link="lid"/>'
                                          '<axis xyz="0 1 0"/><limit lower="0" upper="1"/></joint></robot>')
    findings = [f for f in validate_asset(folder) if f.code == "MESH_TOO_MANY_FACES"]
    assert findings and findings[0].severity == "error" and findings[0].values["built_faces"] == 60 * faces, findings
    assert "60 <mesh> references" in findings[0].message


def test_an_mjcf_naming_one_stl_sixty_times_is_refused_before_mujoco_builds_it(tmp_path):
    pytest.importorskip("mujoco")
    from asset2sim.tasks.ingest.extract import AssetError, extract_asset_checked

    folder = tmp_path / "in"
    folder.mkdir()
    faces = _stl(folder / "m.stl", 150)  # 90,000 triangles, 4.5 MB
    assets = "".join(f'<mesh name="m{k}" file="m.stl"/>' for k in range(60))
    geoms = "".join(f'<geom type="mesh" mesh="m{k}"/>' for k in range(60))
    (folder / "many.xml").write_text(f'<mujoco><asset>{assets}</asset><worldbody><body name="base"><freejoint/>{geoms}'
                                     '<body name="lid"><joint type="hinge" range="0 1"/><geom type="box" size="0.1 0.1 0.01"/>'
                                     '</body></body></worldbody></mujoco>')
    tracemalloc.start()
    try:
        with no_hang(60), pytest.raises(AssetError) as info:
            extract_asset_checked(folder / "many.xml")
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert "INPUT_TOO_LARGE" in info.value.codes and "triangles" in str(info.value), str(info.value)
    assert peak < 200 << 20, peak
    _stl(folder / "small.stl", 40)  # 6,400 triangles named three times: read
    few = "".join(f'<mesh name="s{k}" file="small.stl"/>' for k in range(3))
    (folder / "few.xml").write_text(f'<mujoco><asset>{few}</asset><worldbody><body name="base"><freejoint/>'
                                    + "".join(f'<geom type="mesh" mesh="s{k}"/>' for k in range(3))
                                    + '<body name="lid"><joint type="hinge" range="0 1"/><geom type="box" size="0.1 0.1 0.01"/>'
                                    '</body></body></worldbody></mujoco>')
    asset, _ = extract_asset_checked(folder / "few.xml")
    assert faces * 60 > 1_000_000 and asset.links


def test_a_usd_stage_instancing_one_mesh_sixty_times_is_refused(tmp_path):
    pytest.importorskip("pxr")
    from pxr import Sdf, Usd, UsdGeom, UsdPhysics, Vt

    from asset2sim.formats.staging import StagingError
    from asset2sim.formats.usd.reader import read_usd_asset

    path = tmp_path / "many.usda"
    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.z)
    root = UsdGeom.Xform.Define(stage, "/obj").GetPrim()
    stage.SetDefaultPrim(root)
    UsdPhysics.ArticulationRootAPI.Apply(root)
    v, f = _grid(120)
    proto = UsdGeom.Mesh.Define(stage, "/proto")
    proto.CreatePointsAttr(Vt.Vec3fArray([tuple(map(float, p)) for p in v]))
    proto.CreateFaceVertexCountsAttr([3] * len(f))
    proto.CreateFaceVertexIndicesAttr([int(i) for i in f.ravel()])
    bodies = []
    for name in ("base", "lid"):
        xf = UsdGeom.Xform.Define(stage, f"/obj/{name}")
        UsdPhysics.RigidBodyAPI.Apply(xf.GetPrim())
        bodies.append(xf.GetPrim())
    for k in range(60):
        copy = stage.DefinePrim(f"/obj/base/m{k}")
        copy.GetReferences().AddInternalReference(Sdf.Path("/proto"))
        UsdPhysics.CollisionAPI.Apply(copy)
    lid = UsdGeom.Cube.Define(stage, "/obj/lid/box")
    UsdPhysics.CollisionAPI.Apply(lid.GetPrim())
    hinge = UsdPhysics.RevoluteJoint.Define(stage, "/obj/hinge")
    hinge.CreateBody0Rel().SetTargets([bodies[0].GetPath()])
    hinge.CreateBody1Rel().SetTargets([bodies[1].GetPath()])
    hinge.CreateAxisAttr("Y")
    hinge.CreateLowerLimitAttr(0.0)
    hinge.CreateUpperLimitAttr(90.0)
    stage.GetRootLayer().Save()
    with no_hang(60), pytest.raises(StagingError) as info:
        read_usd_asset(path)
    assert info.value.code == "INPUT_TOO_LARGE" and "triangles" in str(info.value), str(info.value)
