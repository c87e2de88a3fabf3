"""``asset2sim init``: a starter catalog.yaml outside a clone (an installed wheel ships none)."""

from __future__ import annotations

import shutil

import pytest

from asset2sim import demo_assets
from asset2sim.cli import main
from asset2sim.flows.catalog_config import load_catalog, read_manifest_entries
from asset2sim.flows.starter import write_starter_catalog
from asset2sim.schemas.config import RefineConfig
from tests.tasks.ingest.host_layouts import robosuite_door


def test_init_writes_a_catalog_the_pipeline_loads(tmp_path, capsys, monkeypatch):
    """In an empty folder, ``asset2sim init`` writes a catalog.yaml that loads, whose default dataset is the demo
    (generated on first use) and whose refine settings are valid; a second init refuses to replace it."""
    monkeypatch.chdir(tmp_path)
    assert main(["init"]) == 0
    out = capsys.readouterr().out
    assert "wrote catalog.yaml (default dataset demo)" in out and "next: asset2sim flow" in out
    cat = load_catalog(tmp_path / "catalog.yaml")
    assert cat.config.default_dataset == "demo" and cat.config.datasets["demo"].generate == "demo"
    assert cat.config.schedule.dataset == "demo"
    RefineConfig.model_validate(cat.config.refine)
    before = (tmp_path / "catalog.yaml").read_bytes()
    assert main(["init"]) == 4
    assert "OUTPUT_EXISTS" in capsys.readouterr().err and (tmp_path / "catalog.yaml").read_bytes() == before
    assert main(["init", "--force"]) == 0


def test_init_with_a_folder_of_objects_lists_them_and_leaves_the_folder_alone(tmp_path, capsys):
    """``--objects DIR``: DIR (URDF, MJCF files, one object per sub-folder) becomes the default dataset, a manifest
    listing every object is written beside the catalog, each row read back without an error; DIR is not written."""
    objects = tmp_path / "my objects"
    demo_assets.build_box_with_lid(objects / "box")
    robosuite_door(objects / "door" / "door.xml")
    (objects / "notes").mkdir()  # no object in it: not listed
    before = sorted(p.relative_to(objects) for p in objects.rglob("*"))
    project = tmp_path / "project"
    assert main(["init", str(project), "--objects", str(objects)]) == 0
    out = capsys.readouterr().out
    assert "2 object(s)" in out and f"--catalog {project / 'catalog.yaml'}" in out
    cat = load_catalog(project / "catalog.yaml")
    ds = cat.config.datasets[cat.config.default_dataset]
    assert cat.config.default_dataset == "my_objects" and ds.root == "../my objects"
    entries, errors = read_manifest_entries(project / ds.manifest, project / ds.root)
    assert not errors and [e.asset_id for e in entries] == ["box", "door"]
    assert sorted(p.relative_to(objects) for p in objects.rglob("*")) == before
    shutil.rmtree(objects / "box"), shutil.rmtree(objects / "door")
    with pytest.raises(ValueError, match="no object folder"):
        write_starter_catalog(tmp_path / "other", objects)
    assert main(["init", str(tmp_path / "third"), "--objects", str(tmp_path / "missing")]) == 1
