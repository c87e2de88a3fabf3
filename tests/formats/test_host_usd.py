"""A USD input's refined object back in its own stage: a cabinet in centimetres, Y up, refined interaction-ready;
``usd/host/cabinet.usda`` opens with pxr, has the input's prim paths, holds the refined mass, center of mass,
inertia, damping, friction and initial state in the stage's units (read back by the project's USD reader, in SI)
and nothing else changed; the changes alone as a layer compose over the untouched input to the same values."""

from __future__ import annotations

import hashlib
import math

import numpy as np
import pytest

pytest.importorskip("pxr")
pytest.importorskip("pybullet")

from pxr import Sdf, Usd

from asset2sim.schemas.config import RefineConfig
from asset2sim.schemas.request import RequestOverrides
from asset2sim.formats.usd.reader import read_usd_asset
from asset2sim.formats.usd.physics import applied_schemas
from asset2sim.tasks.refine import refine_asset
from asset2sim.urdf import read_urdf
from tests.formats.usd_cabinet import CARCASS, DOOR, HINGE, cabinet_usd

CONFIG = RefineConfig(engines=["pybullet"])
PHYSICS = ("physics:mass", "physics:centerOfMass", "physics:diagonalInertia", "physics:principalAxes",
           "drive:angular:physics:", "asset2sim:friction", "newton:", "state:angular:physics:", "physics:lowerLimit",
           "physics:upperLimit")


def _attributes(stage) -> dict[tuple[str, str], object]:
    """(prim path, attribute) -> value, every attribute with a value on the stage."""
    out = {}
    for prim in stage.Traverse(Usd.TraverseInstanceProxies(Usd.PrimAllPrimsPredicate)):
        for a in prim.GetAttributes():
            if a.HasValue():
                out[(str(prim.GetPath()), a.GetName())] = a.Get()
    return out


def test_a_usd_cabinet_goes_back_into_its_stage_with_the_refined_physics(tmp_path, refine_once):
    src = cabinet_usd(tmp_path / "in" / "cabinet.usda")
    digest = hashlib.sha256(src.read_bytes()).hexdigest()
    res = refine_once(src, "A cabinet, door slightly open.", CONFIG, extras=False)
    assert res.report.failure_mode == "none", res.report.failure_mode
    host = res.out_dir / "usd" / "host"
    assert sorted(p.name for p in host.iterdir()) == ["cabinet.diff", "cabinet.physics.usda", "cabinet.usda"]
    assert any(n.startswith("host USD: usd/host/cabinet.usda is cabinet.usda") for n in res.report.notes)
    assert hashlib.sha256(src.read_bytes()).hexdigest() == digest  # the input is only read

    original, written = Usd.Stage.Open(str(src)), Usd.Stage.Open(str(host / "cabinet.usda"))
    before, after = _attributes(original), _attributes(written)
    assert {p for p, _ in after} == {p for p, _ in before}  # the same prim paths
    changed = {k for k in set(before) | set(after) if k not in before or k not in after or before[k] != after[k]}
    assert changed and all(name.startswith(PHYSICS) for _, name in changed), sorted(changed)
    assert {p for p, _ in changed} == {CARCASS, DOOR, HINGE}
    assert written.GetPrimAtPath(DOOR).GetAttribute("physics:mass").Get() != 4.0  # the refined mass, not the authored one

    model = read_urdf(res.out_dir / "mobility.urdf")  # refined, SI, the reader's link frames
    back = read_usd_asset(host / "cabinet.usda").model  # the written stage read as the input was: cm and Y up undone
    for name in ("carcass", "door"):
        want, got = model.links[name].inertial, back.links[name].inertial
        assert got.mass == pytest.approx(want.mass, rel=1e-6), name
        assert np.allclose(got.com(), want.com(), atol=1e-6), name
        assert np.allclose(got.inertia_in_link_axes(), want.inertia_in_link_axes(), rtol=1e-5, atol=1e-9), name
    (j,) = [x for x in model.joints if x.name == "hinge"]
    (b,) = [x for x in back.joints if x.name == "hinge"]
    assert b.dynamics.damping == pytest.approx(j.dynamics.damping, rel=1e-6)
    assert b.dynamics.friction == pytest.approx(j.dynamics.friction, rel=1e-6)
    assert (b.limit.lower, b.limit.upper) == pytest.approx((j.limit.lower, j.limit.upper), abs=1e-6)
    hinge = written.GetPrimAtPath(HINGE)
    state = res.report.initial_joint_positions["hinge"]
    assert 0.0 < state < math.radians(45.0)  # slightly open
    assert hinge.GetAttribute("state:angular:physics:position").Get() == pytest.approx(math.degrees(state), rel=1e-6)
    assert "PhysicsJointStateAPI:angular" in applied_schemas(hinge)

    layer = Sdf.Layer.CreateAnonymous(".usda")  # the changes alone, above the untouched input
    layer.subLayerPaths.append(str(host / "cabinet.physics.usda"))
    layer.subLayerPaths.append(str(src))
    stacked = _attributes(Usd.Stage.Open(layer))
    assert all(stacked[k] == after[k] for k in after), "the layer over the input differs from the flattened stage"
    diff = (host / "cabinet.diff").read_text().splitlines()
    assert f"{DOOR}.physics:mass: 4 -> {after[(DOOR, 'physics:mass')]:.9g}" in diff
    assert len([line for line in diff if "->" in line]) == len(changed)


def test_a_rescaled_usd_object_is_not_written_back(tmp_path, refine_once):
    src = cabinet_usd(tmp_path / "in" / "cabinet.usda")
    res = refine_once(src, "A cabinet, door slightly open.",
                       CONFIG.model_copy(update={"overrides": RequestOverrides(scale=0.5)}), extras=False)
    assert any(n.startswith("host USD not written: ") and "rescaled" in n for n in res.report.notes), res.report.notes
    assert not (res.out_dir / "usd" / "host").exists()


def test_a_binary_usd_goes_back_as_a_binary_layer_of_the_same_name(tmp_path, refine_once):
    text = cabinet_usd(tmp_path / "src" / "cabinet.usda")
    src = tmp_path / "in" / "cabinet.usdc"
    src.parent.mkdir()
    assert Sdf.Layer.FindOrOpen(str(text)).Export(str(src))
    res = refine_once(src, "A cabinet, door slightly open.", CONFIG, extras=False)
    assert res.report.failure_mode == "none", res.report.failure_mode
    host = res.out_dir / "usd" / "host" / "cabinet.usdc"
    assert host.read_bytes().startswith(b"PXR-USDC")  # crate, as a .usdc must be
    written = Usd.Stage.Open(str(host))
    assert {p for p, _ in _attributes(written)} == {p for p, _ in _attributes(Usd.Stage.Open(str(src)))}
    model = read_urdf(res.out_dir / "mobility.urdf")
    assert read_usd_asset(host).model.links["door"].inertial.mass == pytest.approx(model.links["door"].inertial.mass, rel=1e-6)


@pytest.mark.slow
def test_a_partnet_mobility_object_as_a_usd_stage_goes_back_with_its_meshes(shared_dataset, tmp_path):
    """A dataset object (148, a faucet, real meshes) refined and exported to USD, the stage refined as an input in
    its own right: the host stage keeps every prim path and every mesh's points, and holds the second refine's
    masses."""
    import csv

    from asset2sim.formats.usd.export import export_usd

    if not (shared_dataset / "148" / "mobility.urdf").is_file():
        pytest.skip("dev object 148 not present")
    with open(shared_dataset / "manifest.csv", newline="") as f:
        prompt = next(r["prompt"] for r in csv.DictReader(f) if r["id"] == "148")
    first = refine_asset(shared_dataset / "148", prompt, tmp_path / "first", CONFIG, extras=False)
    src = tmp_path / "in" / "faucet.usd"
    src.parent.mkdir()
    src.write_bytes(export_usd(first.out_dir).path.read_bytes())
    res = refine_asset(src, prompt, tmp_path / "out", CONFIG, extras=False)
    host = res.out_dir / "usd" / "host" / "faucet.usd"
    assert host.is_file(), res.report.notes
    original, written = Usd.Stage.Open(str(src)), Usd.Stage.Open(str(host))
    before, after = _attributes(original), _attributes(written)
    assert {p for p, _ in after} == {p for p, _ in before}
    points = [k for k in before if k[1] == "points"]
    assert points and all(np.array_equal(np.asarray(after[k]), np.asarray(before[k])) for k in points)
    changed = {k for k in before if before[k] != after.get(k)} | (set(after) - set(before))
    assert changed and all(name.startswith(PHYSICS) for _, name in changed), sorted(changed)
    model, back = read_urdf(res.out_dir / "mobility.urdf"), read_usd_asset(host).model
    for name, link in model.links.items():
        if link.inertial is not None:
            assert back.links[name].inertial.mass == pytest.approx(link.inertial.mass, rel=1e-6), name
