"""Outputs and catalog on object storage: a local S3-compatible server
(moto in server mode on 127.0.0.1) holds the catalog and the refined
folders of a flow run whose workers refine in local temporary folders and
upload (completion marker last); the rerun's skip decision reads the store;
a folder made incomplete in the store is redone."""

from __future__ import annotations


import pytest

try:  # package layout or rootdir-on-sys.path layout
    from .flowproject import make_project  # type: ignore[no-redef]
except ImportError:
    from flowproject import make_project  # type: ignore[no-redef]

from asset2sim.flows.catalog import ResultCatalog
from asset2sim.flows.catalog_config import load_catalog
from asset2sim.flows import store
from asset2sim.tasks.publish.contract import is_complete
from asset2sim.output_folder import MARKER_NAME
from tests.helpers import download_folder, local_s3_server

pytestmark = pytest.mark.slow  # end to end: the flows (Prefect, Dask, stage processes)

BUCKET = "a2s-flow"


@pytest.fixture()
def s3_server(monkeypatch):
    """moto's S3 server on 127.0.0.1 with one bucket; the environment (inherited
    by the worker processes the flow starts) points S3 clients at it."""
    with local_s3_server(monkeypatch, BUCKET) as endpoint:
        yield endpoint


def _keys(endpoint: str, prefix: str = "") -> list[str]:
    import boto3

    client = boto3.client("s3", endpoint_url=endpoint, region_name="us-east-1")
    keys, token = [], None
    while True:
        kw = {"Bucket": BUCKET, "Prefix": prefix, **({"ContinuationToken": token} if token else {})}
        page = client.list_objects_v2(**kw)
        keys += [o["Key"] for o in page.get("Contents", [])]
        if not page.get("IsTruncated"):
            return sorted(keys)
        token = page["NextContinuationToken"]


def test_upload_marker_last_and_completeness_read_from_the_store(s3_server, tmp_path):
    folder = tmp_path / "a"
    (folder / "textured_objs").mkdir(parents=True)
    (folder / "textured_objs" / "m.obj").write_text("v 0 0 0\n")
    (folder / "report.json").write_text("{}")
    from asset2sim import __version__, atomic

    files = ["report.json", "textured_objs/m.obj"]
    atomic.write_json(folder / MARKER_NAME, {"input_hash": "i", "config_hash": "c", "version": __version__,
                                             "files": {f: atomic.sha256_file(folder / f) for f in files}})
    uri = f"s3://{BUCKET}/out/d/r/a"
    assert not store.store_complete(uri, "i", "c")
    up = store.upload_folder(folder, uri)
    assert up["files"] == 3
    assert store.store_complete(uri, "i", "c")
    assert not store.store_complete(uri, "other", "c") and not store.store_complete(uri, "i", "other")
    back = download_folder(uri, tmp_path / "back")
    assert is_complete(back, "i", "c")
    import boto3

    boto3.client("s3", endpoint_url=s3_server).delete_object(Bucket=BUCKET, Key="out/d/r/a/textured_objs/m.obj")
    assert not store.store_complete(uri, "i", "c")  # a listed file missing: not complete
    assert store.join_uri("s3://b/p?endpoint_override=x", "d", "r") == "s3://b/p/d/r?endpoint_override=x"


def test_catalog_and_outputs_round_trip_through_a_local_s3_server(s3_server, tmp_path, prefect_server, monkeypatch):
    from asset2sim.flows.refine_flow import run_refine_flow

    monkeypatch.setenv("TMPDIR", str(tmp_path / "worker-tmp"))  # the workers' local folders
    (tmp_path / "worker-tmp").mkdir()
    import tempfile

    monkeypatch.setattr(tempfile, "tempdir", None)
    catalog = make_project(tmp_path / "proj", {"box_lid": "box_lid", "laptop": "laptop"}, catalog_extra={
        "catalog_root": f"s3://{BUCKET}/catalog", "output_store": f"s3://{BUCKET}/refined",
        "run": {"workers": 1, "evaluate": True, "time_limit_seconds": 120}, "tracking": {"enabled": False},
        "results": {"code_change": "keep"}})  # an edit of the package source meanwhile must not redo the assets
    cat = load_catalog(catalog)
    assert cat.output_store == f"s3://{BUCKET}/refined"

    first = run_refine_flow(catalog)
    assert first["done"] == 2, first
    assert first["output_store"] == f"s3://{BUCKET}/refined/gen/{first['run']}"
    rows = ResultCatalog(cat.catalog_root).read("gen", first["run"]).set_index("asset_id")
    assert set(rows["out_dir"]) == {f"s3://{BUCKET}/refined/gen/{first['run']}/{a}" for a in ("box_lid", "laptop")}
    keys = _keys(s3_server)
    for a in ("box_lid", "laptop"):
        assert f"refined/gen/{first['run']}/{a}/{MARKER_NAME}" in keys
        assert f"refined/gen/{first['run']}/{a}/report.json" in keys
        assert f"refined/gen/{first['run']}/_metrics/{a}/evaluation.json" in keys
    assert any(k.startswith(f"catalog/dataset=gen/run={first['run']}/") for k in keys)
    assert not list(cat.output_root.rglob(MARKER_NAME))  # no refined folder in the driver's output_root
    keys = _keys(s3_server)
    assert f"refined/gen/{first['run']}/comparison.json" in keys  # the run's report files beside its assets
    assert not list((tmp_path / "worker-tmp").rglob(MARKER_NAME))  # local copies removed after the upload
    # the folder comes back whole
    back = download_folder(rows.loc["box_lid", "out_dir"], tmp_path / "back")
    assert is_complete(back, rows.loc["box_lid", "input_hash"], rows.loc["box_lid", "refine_config_hash"])

    # rerun: the skip rule reads the store
    second = run_refine_flow(catalog)
    assert second["skipped"] == 2 and second["done"] == 0

    # a folder made incomplete in the store is redone, the other skipped
    import boto3

    boto3.client("s3", endpoint_url=s3_server).delete_object(
        Bucket=BUCKET, Key=f"refined/gen/{first['run']}/laptop/report.json")
    third = run_refine_flow(catalog)
    rows3 = ResultCatalog(cat.catalog_root).read("gen", third["run"]).set_index("asset_id")
    assert rows3.loc["laptop", "status"] == "done" and rows3.loc["box_lid", "status"] == "skipped"
    assert rows3.loc["laptop", "out_dir"] == f"s3://{BUCKET}/refined/gen/{third['run']}/laptop"
