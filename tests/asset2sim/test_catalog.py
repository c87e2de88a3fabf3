"""catalog.yaml loading, manifests, and the partitioned Parquet result catalog."""

from __future__ import annotations

import json
import threading
from datetime import datetime, timezone
from pathlib import Path

import pytest

from asset2sim.flows.catalog import ROW_COLUMNS, ResultCatalog, result_key
from asset2sim.flows.catalog_config import CatalogError, load_catalog, read_manifest_entries

REPO = Path(__file__).resolve().parents[2]


def _row(aid: str, **kw) -> dict:
    base = {
        "asset_id": aid,
        "category": "Box",
        "prompt": "A small box.",
        "status": "done",
        "failure_mode": "none",
        "estimator": "offline",
        "scale": 0.25,
        "total_mass_kg": 0.8,
        "initial_state": json.dumps({"joint_0": 0.2}),
        "penetration_mm": 0.0,
        "rest_stable": True,
        "oscillation_pass": True,
        "model_queries": 0,
        "tokens": 0,
        "wall_seconds": 3.5,
        "stage_seconds": json.dumps({"prepare": 0.5, "refine": 3.0, "refine.extract": 1.0}),
        "input_hash": "a" * 64,
        "config_hash": "c" * 16,
        "out_dir": "/tmp/x",
        "started_at": datetime(2026, 1, 1, tzinfo=timezone.utc),
        "finished_at": datetime(2026, 1, 1, 0, 0, 4, tzinfo=timezone.utc),
    }
    base.update(kw)
    return base


def test_repository_catalog_declares_demo_and_partnet_dev():
    cat = load_catalog(REPO / "catalog.yaml")
    assert cat.config.default_dataset == "demo"
    assert cat.dataset_root("demo") == REPO / "data" / "raw" / "demo"
    assert cat.config.datasets["demo"].generate == "demo"
    assert cat.dataset_root("partnet_dev") == (REPO / ".." / "shared" / "datasets" / "partnet_mobility").resolve()
    assert cat.manifest_path("partnet_dev").name == "manifest.csv"
    assert cat.output_root == REPO / "data" / "refined"
    assert cat.refine_config().estimator == "offline"
    with pytest.raises(CatalogError):
        cat.dataset("nope")


def test_invalid_catalogs_name_the_problem(tmp_path):
    p = tmp_path / "catalog.yaml"
    with pytest.raises(CatalogError, match="cannot read"):
        load_catalog(p)
    p.write_text("datasets: {a: {root: x}}\ndefault_dataset: b\n")
    with pytest.raises(CatalogError, match="default_dataset"):
        load_catalog(p)
    p.write_text("datasets: {a: {root: x, colour: red}}\ndefault_dataset: a\n")
    with pytest.raises(CatalogError, match="colour"):
        load_catalog(p)
    p.write_text("datasets: {a: {root: x}}\ndefault_dataset: a\nrefine: {penetration_tolerance: -x}\n")
    with pytest.raises(CatalogError, match="refine"):
        load_catalog(p).refine_config()


def test_a_field_error_is_one_sentence_naming_the_field(tmp_path, capsys):
    """pydantic's errors in catalog.yaml and in a refine configuration read as one sentence naming the field: no type
    tag, input echo or pydantic URL, whether ``failures`` or ``refine --config`` meets them."""
    from asset2sim.cli import main

    p = tmp_path / "catalog.yaml"
    p.write_text("datasets: {a: {root: x}}\ndefault_dataset: a\nrefine: {extras: false}\n")
    with pytest.raises(CatalogError) as err:
        load_catalog(p).refine_config()
    p.write_text("datasets: {a: {root: x}}\ndefault_dataset: a\nbogus: 1\n")
    assert main(["failures", "--catalog", str(p)]) == 2
    config = tmp_path / "config.yaml"
    config.write_text("sim: {timestep: 0, colour: red}\n")
    assert main(["refine", str(tmp_path), "--config", str(config), "--out", str(tmp_path / "o")]) == 2
    lines = [str(err.value), *capsys.readouterr().err.splitlines()]
    assert "extras: Extra inputs are not permitted" in lines[0], lines
    assert "bogus: Extra inputs are not permitted" in lines[1] and "sim.colour" in lines[2] and "sim.timestep" in lines[2], lines
    for line in lines:
        assert "pydantic" not in line and "http" not in line and "type=" not in line and "\n" not in line, line


def test_manifest_parsing(tmp_path):
    m = tmp_path / "manifest.csv"
    m.write_text("id,category,prompt,reference_scale\n7119,Microwave,A microwave.,0.3\nbox,,A box.,\n")
    entries, errors = read_manifest_entries(m, tmp_path)
    assert [e.asset_id for e in entries] == ["7119", "box"] and errors == []
    assert entries[0].reference_scale == 0.3 and entries[0].category == "Microwave"
    assert entries[1].category is None and entries[1].asset_dir == tmp_path / "box"
    m.write_text("id,prompt\na,x\na,y\n")
    (dup,) = read_manifest_entries(m, tmp_path)[1]
    assert "duplicate" in dup.message
    m.write_text("id,prompt\n../evil,x\n")
    (bad,) = read_manifest_entries(m, tmp_path)[1]
    assert "invalid asset id" in bad.message
    m.write_text("id,category\na,b\n")
    with pytest.raises(CatalogError, match="prompt"):
        read_manifest_entries(m, tmp_path)
    # the tolerant reading keeps the good rows and types the bad ones
    m.write_text("id,prompt\na,x\n../evil,y\nb,z\n")
    entries, errors = read_manifest_entries(m, tmp_path)
    assert [(e.asset_id, e.line) for e in entries] == [("a", 2), ("b", 4)]
    assert [(e.line, e.id, e.code) for e in errors] == [(3, "../evil", "MANIFEST_INVALID_ID")]
    m.write_bytes(b"\xff\xfe\x00binary")
    with pytest.raises(CatalogError, match="not a CSV manifest"):
        read_manifest_entries(m, tmp_path)


def test_rows_append_atomically_into_partitions_and_read_back(tmp_path):
    store = ResultCatalog(tmp_path / "catalog")
    store.append_row("demo", "20260101T000000Z-aaaaaa", _row("box_lid"))
    store.append_row("demo", "20260101T000000Z-aaaaaa", _row("laptop", status="failed", failure_mode="timeout",
                                                               rest_stable=None, scale=float("nan")))
    store.append_row("demo", "20260102T000000Z-bbbbbb", _row("box_lid", status="skipped"))
    store.append_row("other", "20260103T000000Z-cccccc", _row("box_lid"))
    part = tmp_path / "catalog" / "dataset=demo" / "run=20260101T000000Z-aaaaaa"
    assert sorted(p.name for p in part.iterdir()) == ["box_lid.parquet", "laptop.parquet"]
    df = store.read("demo")
    assert list(df.columns) == [*ROW_COLUMNS, "dataset", "run"]
    assert len(df) == 3 and set(df["dataset"]) == {"demo"}
    lap = df[df["asset_id"] == "laptop"].iloc[0]
    assert lap["failure_mode"] == "timeout" and lap["scale"] != lap["scale"]  # NaN stored as null
    assert len(store.read()) == 4 and len(store.read("demo", "20260102T000000Z-bbbbbb")) == 1
    assert store.runs("demo") == [("demo", "20260101T000000Z-aaaaaa"), ("demo", "20260102T000000Z-bbbbbb")]
    # same asset in the same run: replaced, not duplicated
    store.append_row("demo", "20260101T000000Z-aaaaaa", _row("box_lid", failure_mode="unstable"))
    again = store.read("demo", "20260101T000000Z-aaaaaa")
    assert len(again) == 2 and set(again["failure_mode"]) == {"unstable", "timeout"}
    # run metadata is beside the rows and ignored by readers
    store.write_run_info("demo", "20260101T000000Z-aaaaaa", {"status": "finished"})
    assert store.run_info("demo", "20260101T000000Z-aaaaaa") == {"status": "finished"}
    assert len(store.read("demo")) == 3


def test_bad_rows_are_refused(tmp_path):
    store = ResultCatalog(tmp_path)
    with pytest.raises(ValueError, match="unknown catalog column"):
        store.append_row("d", "r", {**_row("a"), "colour": "red"})
    with pytest.raises(ValueError, match="status"):
        store.append_row("d", "r", _row("a", status="maybe"))
    with pytest.raises(ValueError, match="invalid"):
        store.append_row("d", "r", _row("../a"))
    with pytest.raises(ValueError, match="invalid dataset"):
        store.append_row("d/e", "r", _row("a"))
    assert store.read().empty


def test_finished_results_are_keyed_by_input_and_configuration(tmp_path):
    store = ResultCatalog(tmp_path)
    store.append_row("d", "20260101T000000Z-a", _row("box", config_hash="1" * 16))
    store.append_row("d", "20260101T000000Z-a", _row("cab", status="failed", failure_mode="crash"))
    store.append_row("d", "20260102T000000Z-b", _row("box", config_hash="2" * 16, failure_mode="unstable"))
    fin = store.finished("d")
    assert set(fin) == {result_key("box", "a" * 64, "1" * 16), result_key("box", "a" * 64, "2" * 16)}
    rec = fin[result_key("box", "a" * 64, "2" * 16)]
    assert rec["failure_mode"] == "unstable" and rec["run"] == "20260102T000000Z-b"
    json.dumps(rec)  # plain values only (shipped to workers as flow parameters)


def test_concurrent_appends_never_expose_partial_files(tmp_path):
    store = ResultCatalog(tmp_path)
    errors = []

    def writer(i: int) -> None:
        try:
            for k in range(5):
                store.append_row("d", "r1", _row(f"a{i}", wall_seconds=float(k)))
        except Exception as exc:  # pragma: no cover - reported below
            errors.append(exc)

    def reader() -> None:
        try:
            for _ in range(20):
                df = store.read("d")
                assert df["asset_id"].notna().all()
        except Exception as exc:  # pragma: no cover
            errors.append(exc)

    threads = [threading.Thread(target=writer, args=(i,)) for i in range(4)] + [threading.Thread(target=reader)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert not errors
    df = store.read("d")
    assert sorted(df["asset_id"]) == ["a0", "a1", "a2", "a3"] and set(df["wall_seconds"]) == {4.0}


def test_a_hostile_catalog_file_is_refused_unread(tmp_path):
    """A FIFO catalog.yaml is refused without blocking, an anchor bomb before it expands (asset2sim.input_files)."""
    import os
    import signal

    def on_alarm(signum, frame):
        raise TimeoutError("load_catalog blocked on a FIFO")

    fifo = tmp_path / "fifo.yaml"
    os.mkfifo(fifo)
    old = signal.signal(signal.SIGALRM, on_alarm)
    signal.alarm(20)  # a regression fails instead of hanging the suite
    try:
        with pytest.raises(CatalogError, match="INPUT_NOT_REGULAR_FILE"):
            load_catalog(fifo)
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, old)
    bomb = tmp_path / "bomb.yaml"
    bomb.write_text("a: &a [x,x,x,x,x,x,x,x,x]\n" + "".join(f"a{i}: &a{i} [{', '.join([f'*a{i - 1}' if i > 1 else '*a'] * 9)}]\n"
                                                          for i in range(1, 9)) + "datasets: *a8\n")
    with pytest.raises(CatalogError, match="YAML_ALIAS_LIMIT"):
        load_catalog(bomb)
