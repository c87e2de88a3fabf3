"""Per-asset learnability flags (asset2sim.flows.learnability): the rule over the learnability benchmark's records
(PyBullet harness and ManiSkill), the flags written onto the latest finished rows of a catalog (an earlier run, a
failed row, an asset of another input and an asset without a row left alone), the failure-mode breakdown by the new
column, and ``bench_learnability.py --table ... --catalog`` end to end on a results file."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import pandas as pd
import pytest
import yaml

from asset2sim.flows import queries
from asset2sim.flows.catalog import ResultCatalog
from asset2sim.flows.learnability import learnability_flags, record_learnability
from asset2sim.schemas.catalog import CatalogRow

ROOT = Path(__file__).resolve().parents[2]


def _ppo(rid: str, seed: int, rate: float, method: str = "asset2sim", action: str = "close", kind: str = "ppo") -> dict:
    return {"kind": kind, "method": method, "id": rid, "seed": seed, "success_rate": rate, "action": action,
            "task": f"{action} the lid", "env_steps": 4096, "engine_steps": 49152, "train_episodes": 40,
            "train_seconds": 60.0, "eval_episodes": 5}


RECORDS = [
    # 9912 is learned by one seed of three; 100221 by none while 9912 is: flagged; 47645 is an open task nobody learned
    _ppo("9912", 0, 0.0), _ppo("9912", 1, 0.6), _ppo("9912", 2, 0.0),
    _ppo("100221", 0, 0.0), _ppo("100221", 1, 0.0), _ppo("100221", 2, 0.0),
    _ppo("47645", 0, 0.0, action="open"), _ppo("47645", 1, 0.0, action="open"),
    {"kind": "passive", "method": "asset2sim", "id": "100221", "success_rate": 0.0},
    {"kind": "ppo", "method": "asset2sim", "id": "103275", "seed": 0, "error": "RuntimeError: crashed"},
    _ppo("100221", 0, 1.0, method="raw"),  # another method's success says nothing about asset2sim's asset
]


def test_flags_follow_the_rule_learned_not_learned_where_others_were_and_undecided():
    flags = learnability_flags(RECORDS)
    assert set(flags) == {"9912", "100221", "47645"}  # the errored run left out
    assert flags["9912"].verdict == "learned" and flags["9912"].learnable is True
    assert flags["9912"].seeds == {0: 0.0, 1: 0.6, 2: 0.0}
    bad = flags["100221"]
    assert bad.verdict == "not_learned" and bad.learnable is False and bad.learned_on == ("9912",) and bad.passive == 0.0
    assert flags["47645"].verdict == "undecided" and flags["47645"].learnable is None  # nothing learned to open
    data = json.loads(bad.to_json())
    assert data["success"] == 0.0 and data["seeds"] == {"0": 0.0, "1": 0.0, "2": 0.0} and data["framework"] == "pybullet"
    raw = learnability_flags(RECORDS, method="raw")
    assert raw["100221"].verdict == "learned"


def test_maniskill_records_are_read_the_same_way():
    recs = [_ppo("a", s, r, kind="ppo_eval") for s, r in ((0, 0.2), (1, 0.0))] + \
           [_ppo("b", s, 0.0, kind="ppo_eval") for s in (0, 1)] + \
           [dict(_ppo("c", s, 0.0, kind="ppo_eval"), split="held-out") for s in (0, 1)] + \
           [{"kind": "ppo_train", "method": "asset2sim", "seed": 0, "env_steps": 9000, "n_envs": 3, "device": "cpu",
             "sim_backend": "cpu"}]
    flags = learnability_flags(recs)
    assert flags["a"].verdict == "learned" and flags["b"].verdict == "not_learned"
    assert flags["b"].framework == "maniskill" and flags["b"].budget["env_steps"] == 9000
    assert "c" not in flags  # held out: the policy never trained on it


def _row(aid: str, status: str = "done", input_hash: str = "in-", mode: str = "none") -> CatalogRow:
    return CatalogRow(asset_id=aid, category="Laptop", prompt="a laptop", status=status, failure_mode=mode if status != "failed" else None,
                      error="boom" if status == "failed" else None, input_hash=input_hash + aid, total_mass_kg=1.5)


@pytest.fixture
def catalog(tmp_path) -> Path:
    """A project with catalog.yaml, dataset ``dev``: run 1 holds every asset, run 2 (later) 9912 again and a
    failed 100221."""
    (tmp_path / "raw").mkdir()
    path = tmp_path / "catalog.yaml"
    path.write_text(yaml.safe_dump({"version": 1, "default_dataset": "dev", "catalog_root": "catalog",
                                    "datasets": {"dev": {"root": "raw"}}}))
    store = ResultCatalog(tmp_path / "catalog")
    for aid in ("9912", "100221", "47645"):
        store.append_row("dev", "20261101T000000Z-a", _row(aid))
    store.compact("dev", "20261101T000000Z-a")
    store.append_row("dev", "20261102T000000Z-b", _row("9912", mode="not_operable"))
    store.append_row("dev", "20261102T000000Z-b", _row("100221", status="failed"))
    return path


def test_flags_land_on_each_asset_s_latest_finished_row_and_nothing_else_changes(catalog):
    store = ResultCatalog(catalog.parent / "catalog")
    before = store.read("dev")
    flags = learnability_flags(RECORDS + [_ppo("ghost", 0, 0.0)])
    done = record_learnability(store, "dev", flags, input_hashes={"47645": "another input"})
    assert done.written == {"9912": "20261102T000000Z-b", "100221": "20261101T000000Z-a"}  # the failed row is not a result
    assert done.missing == ["ghost"] and list(done.other_input) == ["47645"]
    after = store.read("dev")
    assert len(after) == len(before)
    got = {(r["run"], r["asset_id"]): r for r in after.to_dict("records")}
    assert got[("20261102T000000Z-b", "9912")]["learnable"] is True
    assert got[("20261102T000000Z-b", "9912")]["failure_mode"] == "not_operable"  # the rest of the row as it was
    assert got[("20261101T000000Z-a", "100221")]["learnable"] is False
    assert json.loads(got[("20261101T000000Z-a", "100221")]["learnability"])["learned_on"] == ["9912"]
    for key in (("20261101T000000Z-a", "9912"), ("20261102T000000Z-b", "100221"), ("20261101T000000Z-a", "47645")):
        assert pd.isna(got[key]["learnability"]), key  # earlier, failed and other-input rows untouched
    for col in ("total_mass_kg", "input_hash", "prompt", "status"):
        assert [r[col] for r in after.to_dict("records")] == [r[col] for r in before.to_dict("records")], col
    table = queries.failure_modes(after, by=["learnable"])  # a key as `asset2sim failures --by learnable` prints it
    assert table.loc["true", "total"] == 1 and table.loc["false", "total"] == 1


def test_bench_learnability_writes_the_flags_of_a_results_file_into_the_catalog(catalog, tmp_path, capsys):
    sys.path.insert(0, str(ROOT / "benchmarks"))
    import bench_learnability

    results = tmp_path / "results.jsonl"
    results.write_text("".join(json.dumps(r) + "\n" for r in RECORDS))
    assert bench_learnability.main(["--table", str(results), "--catalog", str(catalog), "--out", str(tmp_path / "bench")]) == 0
    out = capsys.readouterr().out
    assert "learnability 100221: not_learned" in out and "written to run 20261101T000000Z-a" in out
    rows = ResultCatalog(catalog.parent / "catalog").read("dev")
    assert rows["learnable"].notna().sum() == 2  # 9912 (latest run), 100221 (its finished run); 47645 undecided -> null
