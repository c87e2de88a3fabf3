"""Catalog queries, the run's artifacts and the ``asset2sim failures`` command."""

from __future__ import annotations

import argparse
import re
import json
from datetime import datetime, timedelta, timezone
from pathlib import Path

import pytest

from asset2sim.commands._status import CommandError
from asset2sim.flows import queries, tracking
from asset2sim.flows.catalog import ResultCatalog

T0 = datetime(2026, 3, 1, 2, 0, tzinfo=timezone.utc)


def _row(aid, cat, mode="none", status="done", wall=1.0, stable=True, osc=True, pen=0.0, stages=None):
    return {
        "asset_id": aid,
        "category": cat,
        "prompt": "p",
        "status": status,
        "failure_mode": mode,
        "error": None if mode == "none" else f"{mode} happened\nsecond line",
        "estimator": "offline",
        "scale": 0.3,
        "total_mass_kg": 1.0,
        "initial_state": "{}",
        "penetration_mm": pen,
        "rest_stable": stable,
        "oscillation_pass": osc,
        "model_queries": 2,
        "tokens": 100,
        "wall_seconds": wall,
        "stage_seconds": json.dumps(stages or {"prepare": 0.1, "refine": wall - 0.1, "refine.post_check": wall / 2}),
        "input_hash": "i",
        "config_hash": "c",
        "started_at": T0,
        "finished_at": T0,
    }


@pytest.fixture
def store(tmp_path) -> ResultCatalog:
    s = ResultCatalog(tmp_path / "catalog")
    r1, r2 = "20260301T020000Z-aaaaaa", "20260302T020000Z-bbbbbb"
    for row in [
        _row("box", "Box", wall=3.0, pen=2.0),
        _row("box2", "Box", mode="unstable", stable=False, wall=9.0, pen=4.0),
        _row("cab", "StorageFurniture", mode="timeout", status="failed", stable=None, osc=None, pen=None, wall=30.0),
        _row("lap", "Laptop", wall=5.0),
    ]:
        s.append_row("demo", r1, row)
    for row in [
        _row("box", "Box", status="skipped", wall=0.1),
        _row("box2", "Box", wall=8.0),
        _row("cab", "StorageFurniture", mode="oscillating", osc=False, wall=20.0),
        _row("mic", "Microwave", wall=4.0),
    ]:
        row["started_at"] = T0 + timedelta(days=1)
        s.append_row("demo", r2, row)
    return s


def test_failure_modes_by_category_and_run(store):
    df = store.read("demo")
    run = queries.latest_run(df)
    assert run == "20260302T020000Z-bbbbbb"
    t = queries.failure_modes(df, "category", run=run)
    assert t.loc["StorageFurniture", "oscillating"] == 1 and t.loc["Box", "none"] == 2
    assert t.loc["total", "total"] == 4 and list(t.columns)[:2] == ["none", "invalid_input"]
    by_run = queries.failure_modes(df, "run")
    assert by_run.loc["20260301T020000Z-aaaaaa", "timeout"] == 1 and by_run.loc["total", "total"] == 8
    both = queries.failure_modes(df, ("run", "category"))
    assert both.loc[("20260301T020000Z-aaaaaa", "Box"), "unstable"] == 1
    with pytest.raises(KeyError):
        queries.failure_modes(df, "colour")


def test_run_summary_and_pass_rates_over_time(store):
    df = store.read("demo")
    s = queries.run_summary(df[df["run"] == "20260301T020000Z-aaaaaa"])
    assert s["assets"] == 4 and s["failed"] == 1 and s["pass_rate_all"] == 0.5
    assert s["stability_pass_rate"] == pytest.approx(2 / 3)  # the timed-out row has no verdict
    assert s["penetration_mm_mean"] == pytest.approx(2.0)
    assert s["queries_per_asset"] == 2.0 and s["failure_modes"]["timeout"] == 1
    over = queries.pass_rates_over_time(df)
    assert list(over["run"]) == sorted(over["run"])
    assert list(over["pass_rate_all"]) == [0.5, 0.75]
    assert over["started_at"].iloc[1] > over["started_at"].iloc[0]


def test_slowest_assets_and_verdict_changes(store):
    df = store.read("demo")
    slow = queries.slowest_assets(df, n=2)
    assert list(slow["asset_id"]) == ["cab", "cab"] and slow["wall_seconds"].iloc[0] == 30.0
    assert slow["slowest_stage"].iloc[0] == "refine.post_check"
    assert "box" not in set(queries.slowest_assets(df, 10, run="20260302T020000Z-bbbbbb")["asset_id"])  # skipped
    ch = queries.verdict_changes(df, "20260301T020000Z-aaaaaa", "20260302T020000Z-bbbbbb")
    assert set(ch["asset_id"]) == {"box2", "cab", "lap", "mic"}
    changes = dict(zip(ch["asset_id"], ch["change"]))
    assert "failure_mode: unstable -> none" in changes["box2"]
    assert changes["mic"].startswith("only in 20260302") and changes["lap"].startswith("only in 20260301")
    with pytest.raises(KeyError):
        queries.verdict_changes(df, "nope", "20260302T020000Z-bbbbbb")


def test_run_artifacts_and_tracking_metrics(store, tmp_path):
    df = store.read("demo", "20260301T020000Z-aaaaaa")
    paths = tracking.write_run_artifacts(df, tmp_path / "out", title="demo")
    assert paths["failure_modes.png"].read_bytes()[:4] == b"\x89PNG"
    import pandas as pd

    table = pd.read_csv(paths["summary.csv"])
    assert list(table.columns[:4]) == ["asset_id", "category", "status", "failure_mode"]
    assert sorted(table["asset_id"]) == ["box", "box2", "cab", "lap"]
    assert table.set_index("asset_id").loc["cab", "error"] == "timeout happened\nsecond line"
    assert json.loads(paths["summary.json"].read_text())["failure_modes"]["unstable"] == 1
    m = tracking.flow_metrics(queries.run_summary(df))
    assert m["failures_timeout"] == 1.0 and m["pass_rate_all"] == 0.5 and "failure_modes" not in m
    assert tracking.resolve_tracking_uri(tmp_path, None).startswith("sqlite:///")


def test_an_assets_mlflow_run_spans_its_own_work():
    """An asset that waited 40 s for a worker and worked 6 s: its MLflow run starts 6 s before it finished (its
    stages' wall time), not when it was queued; without a wall time, when it was recorded to start."""
    finished = T0 + timedelta(seconds=46)
    row = {"started_at": T0, "finished_at": finished, "wall_seconds": 6.0}
    assert tracking._asset_start(row) == int(finished.timestamp() * 1000) - 6000
    assert tracking._asset_start({**row, "wall_seconds": None}) == int(T0.timestamp() * 1000)
    assert tracking._asset_start({**row, "wall_seconds": 99.0}) == int(T0.timestamp() * 1000)  # never before its start


def test_failures_passes_over_a_rerun_with_nothing_to_do(store, tmp_path, capsys):
    """A rerun that reused every asset (``_run.json`` outcome ``nothing_to_do``, as the flow records it) is not "the
    latest run" of ``failures``: the breakdown is of the latest run that refined, and the passed-over run is named."""
    from asset2sim.commands import failures

    r3 = "20260303T020000Z-cccccc"
    for aid in ("box", "box2", "cab", "mic"):
        store.append_row("demo", r3, _row(aid, "Box", status="skipped", wall=0.01))
    store.write_run_info("demo", r3, {"status": "finished", "outcome": "nothing_to_do"})
    catalog = tmp_path / "catalog.yaml"
    catalog.write_text(f"default_dataset: demo\ncatalog_root: {store.root}\ndatasets: {{demo: {{root: raw}}}}\n")
    assert failures.run(_args(catalog)) == 0
    out = capsys.readouterr().out
    assert out.startswith(f"passed over 1 later run(s) with nothing to do (every asset reused): {r3}")
    assert "failure modes of run 20260302T020000Z-bbbbbb of dataset demo: 4 assets, 3 done, 1 skipped" in out


def _args(catalog: Path, **kw) -> argparse.Namespace:
    d = dict(catalog=catalog, dataset=None, run="latest", by="category", over_time=False, slowest=0, changes=None)
    d.update(kw)
    return argparse.Namespace(**d)


def test_failures_command_prints_the_latest_breakdown(store, tmp_path, capsys):
    from asset2sim.commands import failures

    catalog = tmp_path / "catalog.yaml"
    catalog.write_text(f"default_dataset: demo\ncatalog_root: {store.root}\ndatasets: {{demo: {{root: raw}}}}\n")
    assert failures.run(_args(catalog)) == 0
    out = capsys.readouterr().out
    assert "run 20260302T020000Z-bbbbbb of dataset demo" in out
    assert "oscillating" in out and "StorageFurniture" in out
    assert "timeout" not in out  # the older run's failure is not in this breakdown
    assert failures.run(_args(catalog, slowest=2)) == 0  # --slowest is a query of its own
    out = capsys.readouterr().out
    assert out.startswith("2 slowest assets of run 20260302T020000Z-bbbbbb") and "refine.post_check" in out
    assert failures.run(_args(catalog, run="all", by="run")) == 0
    assert "20260301T020000Z-aaaaaa" in capsys.readouterr().out
    assert failures.run(_args(catalog, over_time=True)) == 0  # each run's start as people read it, not a raw timestamp
    out = capsys.readouterr().out
    assert re.search(r"\d{4}-\d\d-\d\d \d\d:\d\d UTC", out) and "+00:00" not in out and ":00.0" not in out, out
    assert failures.run(_args(catalog, changes=["20260301T020000Z-aaaaaa", "20260302T020000Z-bbbbbb"])) == 0
    assert "box2" in capsys.readouterr().out
    assert failures.run(_args(catalog, over_time=True)) == 0
    with pytest.raises(CommandError) as bad:
        failures.run(_args(catalog, run="nope"))
    assert bad.value.status == 2 and bad.value.code == "RUN_UNKNOWN"
    empty = tmp_path / "empty.yaml"
    empty.write_text(f"default_dataset: demo\ncatalog_root: {tmp_path / 'none'}\ndatasets: {{demo: {{root: raw}}}}\n")
    assert failures.run(_args(empty)) == 1


def test_slowest_of_a_run_that_reused_every_asset_says_so(store, tmp_path, capsys):
    """A rerun with nothing to do has no timings of its own: --slowest says
    so in words (it printed pandas' "Empty DataFrame")."""
    from asset2sim.commands import failures

    r3 = "20260303T020000Z-cccccc"
    for aid in ("box", "box2", "lap"):
        store.append_row("demo", r3, _row(aid, "Box", status="skipped", wall=0.01))
    catalog = tmp_path / "catalog.yaml"
    catalog.write_text(f"default_dataset: demo\ncatalog_root: {store.root}\ndatasets: {{demo: {{root: raw}}}}\n")
    assert failures.run(_args(catalog, slowest=3)) == 0
    out = capsys.readouterr().out
    assert out.startswith(f"no asset was refined in run {r3}") and "Empty DataFrame" not in out


@pytest.mark.slow  # end to end: the command line in a child process
def test_failures_into_a_pipe_closed_early_ends_quietly(store, tmp_path):
    """``asset2sim failures | head -2``: the reader closes the pipe before the breakdown is written; the command
    ends with status 0 and nothing on stderr (it ended with status 70, INTERNAL_ERROR: BrokenPipeError)."""
    import subprocess
    import sys

    catalog = tmp_path / "catalog.yaml"
    catalog.write_text(f"default_dataset: demo\ncatalog_root: {store.root}\ndatasets: {{demo: {{root: raw}}}}\n")
    p = subprocess.Popen([sys.executable, "-m", "asset2sim", "failures", "--catalog", str(catalog), "--run", "all", "--by", "run"],
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, cwd=tmp_path)
    p.stdout.close()  # before the child has written anything: its first write meets a closed pipe
    err = p.stderr.read().decode()
    assert p.wait(timeout=120) == 0, err
    assert err == ""
    shell = subprocess.run(["bash", "-c", f"{sys.executable} -m asset2sim failures --catalog {catalog} | head -2; "
                            "echo status ${PIPESTATUS[0]}"], capture_output=True, text=True, timeout=120, cwd=tmp_path)
    assert shell.stdout.splitlines()[-1] == "status 0" and shell.stderr == ""
