"""Generated-style URDFs: GLB and PLY meshes staged as OBJ, part labels read from link names, centimetre meshes
caught by the size priors; refined and audited, the input left unchanged."""

from __future__ import annotations

import hashlib
import json

import pytest

from asset2sim.apps.audit.audit import audit_asset
from asset2sim.tasks.ingest.extract import extract_asset_checked
from asset2sim.tasks.ingest.urdf_meshes import urdf_needing_conversion
from asset2sim.tasks.interpret.part_labels import label_from_name
from asset2sim.urdf import read_urdf
from tests.planted_assets import write_generated_urdf


def _digest(folder):
    return hashlib.sha256(b"".join(p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file())).hexdigest()


@pytest.mark.parametrize("name, label", [("link_0_handle", "handle"), ("LidLink", "lid"), ("drawer_2", "drawer"),
                                         ("door_left", "door"), ("link_3", None), ("base", "base"), ("knob2", "knob")])
def test_part_labels_are_read_from_link_names(name, label):
    assert label_from_name(name) == label


def test_glb_and_ply_meshes_are_staged_as_obj_with_labels_from_names(tmp_path):
    src = write_generated_urdf(tmp_path / "gen")
    assert urdf_needing_conversion(src) == src / "model.urdf"
    asset, _ = extract_asset_checked(src)
    assert asset.staged_from == (src / "model.urdf").resolve() and asset.asset_id == "gen"
    meshes = [g.path for ln in asset.links for g in ln.collisions]
    assert meshes and all(p.suffix == ".obj" and p.is_file() for p in meshes)
    assert any("read with trimesh and written as OBJ" in n for n in asset.staging_notes)


def test_a_generated_urdf_is_refined_with_labels_from_names(tmp_path, refine_once):
    src = write_generated_urdf(tmp_path / "gen")
    before = _digest(src)
    res = refine_once(src, "a cabinet, door halfway open", extras=False)
    assert res.result.ready, res.report.failure_mode
    assert any("part labels read from link names" in n and "link_1_door -> door" in n for n in res.report.notes)
    assert not any("no part of this" in n for n in res.report.notes)  # the request's 'door' found its part
    assert _digest(src) == before


def test_centimetre_meshes_are_caught_by_the_size_priors(tmp_path, refine_once):
    src = write_generated_urdf(tmp_path / "gen_cm", unit=100.0)
    res = refine_once(src, "a cabinet, door halfway open", extras=False)
    assert 0.005 < res.overlay.scale < 0.03
    assert any("look like centimetres read as metres" in n for n in res.report.notes)
    report = audit_asset(src, tmp_path / "audit", simulate=False).report
    scale = next(v for v in report.values if v.quantity == "scale")
    assert scale.verdict == "implausible" and 30 < scale.factor < 150
    patched = read_urdf(tmp_path / "audit" / report.patch)  # the original URDF, its GLB and PLY meshes copied
    assert {g.filename for ln in patched.links.values() for g in ln.collisions} == {"meshes/base.glb", "meshes/door.ply", "meshes/handle.glb"}
    assert all(g.path.is_file() for ln in patched.links.values() for g in ln.collisions)
    assert json.loads((tmp_path / "audit" / "audit.json").read_text())["format"] == "urdf"


@pytest.mark.parametrize("scale, unit", [(0.01, "centimetres"), (0.0254, "inches"), (0.001, "millimetres"), (0.014, "centimetres"),
                                         (0.2, None), (4.0, None), (0.05, None), (0.3, None)])
def test_a_unit_mistake_is_named_only_near_a_unit_factor(scale, unit):
    from asset2sim.tasks.synthesize.estimate import unit_warning

    text = unit_warning(scale)
    assert (f"look like {unit} read as metres" in text) if unit else text == ""


def test_a_partnet_mobility_model_is_never_called_a_unit_mistake(tmp_path, refine_once):
    src = write_generated_urdf(tmp_path / "gen_cm", unit=100.0)
    (src / "model.urdf").rename(src / "mobility.urdf")  # the dataset's convention: normalized size, not units
    res = refine_once(src, "a cabinet", extras=False)
    assert res.overlay.scale < 0.03 and not any("read as metres" in n for n in res.report.notes)
