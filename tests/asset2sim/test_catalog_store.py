"""The result catalog's storage: compaction, the row-file-wins rule, schema
versions (old files stay readable), the code part of the skip key, and the
same catalog on object storage (a local S3-compatible server, moto) and on
an fsspec filesystem."""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest

from asset2sim.flows import catalog_fs
from asset2sim.flows.catalog import COMPACTED_NAME, ResultCatalog
from asset2sim.flows.catalog_config import CatalogConfig, load_catalog
from asset2sim.schemas.catalog import SCHEMA_VERSION, SCHEMA_VERSION_KEY, CatalogRow
from asset2sim.tasks.publish import contract
from tests.helpers import catalog_reader_counts, local_s3_server

RUN1, RUN2 = "20260101T020000Z-aaaaaa", "20260102T020000Z-bbbbbb"


def _row(aid: str, **kw) -> CatalogRow:
    base = dict(asset_id=aid, category="Box", status="done", failure_mode="none", rest_stable=True,
                oscillation_pass=True, penetration_mm=0.1, wall_seconds=1.0, input_hash="i" * 16,
                config_hash="c" * 16, code_hash="k" * 16, out_dir=f"/out/{aid}")  # fmt: skip
    base.update(kw)
    return CatalogRow(**base)


def _files(store: ResultCatalog, dataset: str, run: str) -> list[str]:
    return sorted(i.base_name for i in catalog_fs.list_files(store.location, store._run_path(dataset, run)))


def _exercise(store: ResultCatalog) -> None:
    """The whole life of two runs on any filesystem; asserts as it goes."""
    for aid in ("a1", "a2", "a3"):
        store.append_row("d", RUN1, _row(aid))
    store.write_run_info("d", RUN1, {"status": "finished"})
    assert store.run_info("d", RUN1) == {"status": "finished"}
    assert _files(store, "d", RUN1) == ["_run.json", "a1.parquet", "a2.parquet", "a3.parquet"]
    before = store.read("d", RUN1)

    comp = store.compact("d", RUN1)
    assert (comp.rows, comp.files_removed) == (3, 3)
    assert _files(store, "d", RUN1) == ["_run.json", COMPACTED_NAME]
    after = store.read("d", RUN1)
    assert after.drop(columns=[]).equals(before)  # same rows, same order, same values
    assert store.recorded_assets("d", RUN1) == {"a1", "a2", "a3"}
    assert store.compact("d", RUN1).files_removed == 0  # nothing left to fold

    # a row written after compaction (a later run restoring a killed run's row) wins over the compacted one
    store.append_row("d", RUN1, _row("a2", failure_mode="unstable", rest_stable=False))
    rows = {r["asset_id"]: r for r in store.read("d", RUN1).to_dict("records")}
    assert len(rows) == 3 and rows["a2"]["failure_mode"] == "unstable"
    local = isinstance(store.root, Path)  # the readers are pointed at a local folder here
    assert not local or catalog_reader_counts(store.root) == {"pandas": 3, "pyarrow": 3, "duckdb": 3}  # each row once
    store.compact("d", RUN1)
    rows = {r["asset_id"]: r for r in store.read("d", RUN1).to_dict("records")}
    assert len(rows) == 3 and rows["a2"]["failure_mode"] == "unstable"
    assert _files(store, "d", RUN1) == ["_run.json", COMPACTED_NAME]
    assert not local or catalog_reader_counts(store.root) == {"pandas": 3, "pyarrow": 3, "duckdb": 3}

    # the second run: one asset skipped, made by other code
    store.append_row("d", RUN2, _row("a1", status="skipped", source_run=RUN1))
    store.append_row("d", RUN2, _row("a3", code_hash="z" * 16))
    assert store.runs("d") == [("d", RUN1), ("d", RUN2)]
    assert len(store.read("d")) == 5 and len(store.read(None, [RUN1, RUN2])) == 5
    fin = store.finished("d")
    assert {k.split("|")[0]: v["run"] for k, v in fin.items()} == {"a1": RUN2, "a2": RUN1, "a3": RUN2}
    same_code = store.finished("d", code_hash="k" * 16)  # rerun policy: a3's newest result is other code
    assert {k.split("|")[0]: v["run"] for k, v in same_code.items()} == {"a1": RUN2, "a2": RUN1, "a3": RUN1}

    assert store.delete_row("d", RUN1, "a2") and not store.has_row("d", RUN1, "a2")
    assert store.recorded_assets("d", RUN1) == {"a1", "a3"}
    assert not store.delete_row("d", RUN1, "a2")


def test_compaction_row_files_win_and_the_skip_lookup_on_a_local_folder(tmp_path):
    store = ResultCatalog(tmp_path / "catalog")
    _exercise(store)
    assert isinstance(store.run_dir("d", RUN1), Path)


def test_an_interrupted_compaction_counts_each_row_once(tmp_path):
    store = ResultCatalog(tmp_path)
    for aid in ("a1", "a2"):
        store.append_row("d", RUN1, _row(aid))
    # compacted file written, row files not yet removed (killed in between)
    table = store.read_table("d", RUN1).drop_columns(["dataset", "run"])
    from asset2sim.flows.catalog import _parquet_bytes

    (Path(store.run_dir("d", RUN1)) / COMPACTED_NAME).write_bytes(_parquet_bytes(table))
    assert sorted(store.read("d", RUN1)["asset_id"]) == ["a1", "a2"]
    assert store.compact("d", RUN1).files_removed == 2
    assert sorted(store.read("d", RUN1)["asset_id"]) == ["a1", "a2"]


def test_files_of_an_older_schema_version_stay_readable(tmp_path):
    import pyarrow as pa
    import pyarrow.parquet as pq

    store = ResultCatalog(tmp_path)
    store.append_row("d", RUN2, _row("new"))
    # a row file as schema version 1 wrote it: no code_hash column, no version metadata
    old_fields = [f for f in store.read_table("d", RUN2).schema if f.name not in ("code_hash", "dataset", "run")]
    old = pa.table({f.name: pa.array([None], f.type) for f in old_fields})
    old = old.set_column(old.schema.get_field_index("asset_id"), "asset_id", pa.array(["old"]))
    old = old.set_column(old.schema.get_field_index("status"), "status", pa.array(["done"]))
    old = old.set_column(old.schema.get_field_index("failure_mode"), "failure_mode", pa.array(["none"]))
    run_dir = Path(store.run_dir("d", RUN1))
    run_dir.mkdir(parents=True)
    pq.write_table(old, run_dir / "old.parquet")
    assert SCHEMA_VERSION_KEY not in (pq.read_schema(run_dir / "old.parquet").metadata or {})  # version 1
    df = store.read("d")
    assert list(df["asset_id"]) == ["old", "new"]
    assert df["code_hash"].isna().tolist() == [True, False] and df.loc[1, "code_hash"] == "k" * 16
    # the new file records the current version; compacting the old run writes it in the current schema
    new_file = Path(store.run_dir("d", RUN2)) / "new.parquet"
    assert pq.read_schema(new_file).metadata[SCHEMA_VERSION_KEY] == str(SCHEMA_VERSION).encode()
    store.compact("d", RUN1)
    compacted = pq.read_schema(run_dir / COMPACTED_NAME)
    assert "code_hash" in compacted.names and int(compacted.metadata[SCHEMA_VERSION_KEY]) == SCHEMA_VERSION
    # a column a newer writer added is ignored by this reader, not an error
    newer = pq.read_table(new_file).append_column("from_the_future", pa.array([1.5]))
    pq.write_table(newer, Path(store.run_dir("d", RUN2)) / "new.parquet")
    assert "from_the_future" not in store.read("d", RUN2).columns


def test_import_rows_and_bad_names(tmp_path):
    import pyarrow as pa

    store = ResultCatalog(tmp_path)
    store.import_rows("d", RUN1, pa.table({"asset_id": ["b", "a"], "status": ["done", "failed"]}))
    assert list(store.read("d", RUN1)["asset_id"]) == ["a", "b"]
    with pytest.raises(ValueError, match="unknown catalog column"):
        store.import_rows("d", RUN1, pa.table({"asset_id": ["a"], "colour": ["red"]}))
    with pytest.raises(ValueError, match="invalid asset name"):
        store.import_rows("d", RUN1, pa.table({"asset_id": ["../x"], "status": ["done"]}))
    with pytest.raises(KeyError, match="no catalog column"):
        store.read("d", columns=["colour"])


def test_code_hash_is_the_source_and_the_policy_picks_it():
    contract.code_hash.cache_clear()
    h = contract.code_hash()
    assert len(h) == 16 and int(h, 16) >= 0
    contract.code_hash.cache_clear()
    assert contract.code_hash() == h  # deterministic
    dirs = {p.name for p in contract._package_dirs()}
    assert {"asset2sim", "tasks", "schemas", "apps", "flows"} <= dirs
    assert contract.skip_code_hash("rerun") == h and contract.skip_code_hash("keep") is None
    with pytest.raises(ValueError, match="code_change"):
        contract.skip_code_hash("sometimes")
    assert contract.code_version().startswith(contract.__version__ + "+")
    assert CatalogConfig.model_validate({"default_dataset": "d", "datasets": {"d": {"root": "r"}}}).results.code_change == "rerun"


def test_code_hash_changes_with_the_source(tmp_path, monkeypatch):
    pkg = tmp_path / "pkg"
    pkg.mkdir()
    (pkg / "a.py").write_text("x = 1\n")
    monkeypatch.setattr(contract, "_package_dirs", lambda: [pkg])
    contract.code_hash.cache_clear()
    first = contract.code_hash()
    (pkg / "README.md").write_text("docs do not count\n")
    contract.code_hash.cache_clear()
    assert contract.code_hash() == first
    (pkg / "a.py").write_text("x = 2\n")
    contract.code_hash.cache_clear()
    assert contract.code_hash() != first
    contract.code_hash.cache_clear()


def test_a_uri_catalog_root_is_kept_as_written(tmp_path):
    (tmp_path / "catalog.yaml").write_text(
        "default_dataset: d\ncatalog_root: s3://bucket/prefix\ndatasets: {d: {root: raw}}\n")
    assert load_catalog(tmp_path / "catalog.yaml").catalog_root == "s3://bucket/prefix"
    (tmp_path / "catalog.yaml").write_text("default_dataset: d\ncatalog_root: rows\ndatasets: {d: {root: raw}}\n")
    assert load_catalog(tmp_path / "catalog.yaml").catalog_root == (tmp_path / "rows").resolve()
    with pytest.raises(ValueError, match="no filesystem"):
        ResultCatalog("nosuchscheme://x/y")


def test_the_catalog_on_an_fsspec_filesystem():
    pytest.importorskip("fsspec")
    import fsspec

    fsspec.filesystem("memory").store.clear()
    store = ResultCatalog("memory://bucket/catalog")
    assert not store.location.local and store.run_dir("d", RUN1) == f"memory://bucket/catalog/dataset=d/run={RUN1}"
    _exercise(store)


@pytest.fixture()
def s3_server(monkeypatch):
    """A local S3-compatible server (moto in server mode) on 127.0.0.1 with
    one bucket; the environment points S3 clients at it."""
    with local_s3_server(monkeypatch, "a2s-test") as endpoint:
        yield endpoint


def test_the_catalog_round_trips_through_a_local_s3_server(s3_server, tmp_path, capsys):
    import boto3

    store = ResultCatalog("s3://a2s-test/nightly/catalog")
    assert not store.location.local
    _exercise(store)
    keys = sorted(o["Key"] for o in boto3.client("s3", endpoint_url=s3_server).list_objects_v2(Bucket="a2s-test")["Contents"])
    assert f"nightly/catalog/dataset=d/run={RUN1}/{COMPACTED_NAME}" in keys
    assert f"nightly/catalog/dataset=d/run={RUN2}/a1.parquet" in keys  # RUN2 not compacted yet
    assert not any(k.endswith(".tmp") for k in keys)

    # the endpoint can also be given in the URI instead of the environment
    os.environ.pop("AWS_ENDPOINT_URL")
    again = ResultCatalog(f"s3://a2s-test/nightly/catalog?endpoint_override={s3_server}&region=us-east-1")
    assert len(again.read("d")) == 4

    # the failures command reads the same catalog through catalog.yaml
    from asset2sim import cli

    cfg = tmp_path / "catalog.yaml"
    cfg.write_text(f"default_dataset: d\ncatalog_root: 's3://a2s-test/nightly/catalog?endpoint_override={s3_server}'\n"
                   "datasets: {d: {root: raw}}\n")
    assert cli.main(["failures", "--catalog", str(cfg), "--over-time"]) == 0
    out = capsys.readouterr().out
    assert RUN1 in out and RUN2 in out
    assert json.loads(json.dumps(again.run_info("d", RUN1))) == {"status": "finished"}


def test_a_row_file_beside_the_compacted_file_wins_in_every_column_selection(tmp_path):
    import pyarrow.dataset as pads

    store = ResultCatalog(tmp_path)
    for aid in ("a1", "a2"):
        store.append_row("d", RUN1, _row(aid, wall_seconds=1.0))
    store.compact("d", RUN1)
    store.append_row("d", RUN1, _row("a2", wall_seconds=9.0))
    assert sorted(store.read("d", columns=["wall_seconds"])["wall_seconds"]) == [1.0, 9.0]
    assert list(store.read("d", columns=["wall_seconds"], filter=pads.field("wall_seconds") > 5)["wall_seconds"]) == [9.0]
    assert store.read_table("d", columns=["status"]).num_rows == 2


def test_a_catalog_of_the_hidden_legacy_layout_is_read_and_made_visible_at_compaction(tmp_path):
    """Runs compacted before schema version 3 lie in ``_compacted.parquet``,
    which pandas and pyarrow skip as hidden: asset2sim still reads them, and the
    next compaction moves them to the visible name."""
    store = ResultCatalog(tmp_path / "cat")
    for aid in ("a1", "a2"):
        store.append_row("d", RUN1, _row(aid))
    store.compact("d", RUN1)
    run_dir = Path(store.run_dir("d", RUN1))
    (run_dir / COMPACTED_NAME).rename(run_dir / "_compacted.parquet")
    assert catalog_reader_counts(store.root)["pyarrow"] == 0 and len(store.read("d", RUN1)) == 2
    store.append_row("d", RUN1, _row("a2", failure_mode="unstable"))  # taken out of the legacy file
    assert len(store.read("d", RUN1)) == 2
    store.compact("d", RUN1)
    assert _files(store, "d", RUN1) == [COMPACTED_NAME]
    assert catalog_reader_counts(store.root) == {"pandas": 2, "pyarrow": 2, "duckdb": 2}
    assert dict(zip(*store.read("d", RUN1)[["asset_id", "failure_mode"]].T.values)) == {"a1": "none", "a2": "unstable"}

