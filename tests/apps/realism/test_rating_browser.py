"""End to end in a real browser: ``asset2sim rate FOLDER`` started as a process, Chromium driven with
Playwright. One rater rates 10 pairs (Left / Right clicks, a score on some), the server is stopped and
started again: the 10 answers are in ratings.parquet and the app goes on with an 11th unseen pair. Then two
raters rate 20 pairs each, preferring one method, and ``asset2sim rate --scores --tracking-uri`` gives
Bradley-Terry scores with intervals in realism_scores.parquet and an MLflow run."""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import time
import urllib.request
from contextlib import contextmanager
from pathlib import Path

import pandas as pd
import pytest

from asset2sim.apps.realism.ratings import left_slot, read_pair_set, side
from tests.helpers import free_port
from tests.realism_fixtures import write_pair_set

pytestmark = pytest.mark.slow  # end to end: the browser

#: The scripted raters' preference, best first: the side whose method comes first is chosen.
PREFERENCE = ("asset2sim", "human", "direct", "defaults")


def _chromium() -> str:
    try:
        import playwright.sync_api  # noqa: F401
    except ImportError:
        pytest.skip("playwright is not installed (pip install playwright)")
    for path in ("/usr/bin/chromium", shutil.which("chromium"), shutil.which("chromium-browser")):
        if path and os.access(path, os.X_OK):
            return path
    pytest.skip("no chromium executable (/usr/bin/chromium or chromium on PATH)")


@contextmanager
def _rate_server(folder: Path, log: Path):
    """``python -m asset2sim rate FOLDER --port P`` until the block ends (Ctrl-C: SIGINT, expecting status 0)."""
    port = free_port()
    with open(log, "ab") as out:
        proc = subprocess.Popen([sys.executable, "-m", "asset2sim", "rate", str(folder), "--port", str(port)],
                                stdout=out, stderr=subprocess.STDOUT, cwd=log.parent)
    url = f"http://127.0.0.1:{port}"
    try:
        deadline = time.monotonic() + 90
        while True:
            try:
                with urllib.request.urlopen(url + "/", timeout=2) as r:
                    if r.status == 200:
                        break
            except OSError:
                pass
            assert proc.poll() is None, log.read_text()
            assert time.monotonic() < deadline, "the rating app did not start: " + log.read_text()
            time.sleep(0.2)
        yield url
    finally:
        if proc.poll() is None:
            proc.send_signal(signal.SIGINT)
        try:
            rc = proc.wait(timeout=60)
        except subprocess.TimeoutExpired:
            proc.kill()
            raise
    assert rc == 0, log.read_text()
    assert "stopped; ratings in" in log.read_text()


def _rate(page, folder: Path, rater: str, n: int, choose) -> list[tuple[str, str, int | None]]:
    """Answer ``n`` pairs on ``page`` (at the rating page of ``rater``); returns (pair id, choice, score)."""
    pairs = read_pair_set(folder).pairs
    done = []
    for k in range(n):
        page.wait_for_selector("#choose-left")
        pair = pairs[int(page.input_value("input[name=pair]"))]
        left = side(pair, left_slot(rater, pair.pair_id)).method
        right = side(pair, "b" if left_slot(rater, pair.pair_id) == "a" else "a").method
        choice = choose(k, left, right)
        score = 1 + k % 5 if k % 3 == 0 else None
        if score is not None:
            page.check(f"#score-{score}")
        if k == 1:
            page.fill("#comment", "the lid falls too slowly")
        with page.expect_navigation():
            page.click(f"#choose-{choice}")
        done.append((pair.pair_id, choice, score))
    return done


def _preferred(k: int, left: str, right: str) -> str:
    return "left" if PREFERENCE.index(left) < PREFERENCE.index(right) else "right"


def test_rating_in_a_browser_survives_a_restart_and_scores(tmp_path):
    from playwright.sync_api import sync_playwright

    chromium = _chromium()
    one, two = tmp_path / "one", tmp_path / "two"
    write_pair_set(one, 12, seed=1)
    write_pair_set(two, 20, seed=2)
    log = tmp_path / "server.log"
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=chromium, args=["--no-sandbox", "--disable-background-networking"])
        try:
            page = browser.new_page()
            with _rate_server(one, log) as url:
                page.goto(url + "/")
                page.fill("#rater", "alice")
                with page.expect_navigation():
                    page.click("#start")
                assert page.url == url + "/rate/alice"
                # the clips play: both views of both sides decode in the browser
                page.wait_for_function("['left-0', 'left-1', 'right-0', 'right-1'].every("
                                       "id => document.getElementById(id).videoWidth === 64)", timeout=30000)
                answers = _rate(page, one, "alice", 10, lambda k, left, right: "left" if k % 2 == 0 else "right")
            table = pd.read_parquet(one / "ratings.parquet")
            assert len(table) == 10
            got = {r.pair_id: (r.choice, None if pd.isna(r.score) else int(r.score)) for r in table.itertuples()}
            assert got == {pid: (choice, score) for pid, choice, score in answers}
            assert (table["rater"] == "alice").all() and (table["seconds"] >= 0).all()
            assert "the lid falls too slowly" in set(table["comment"])

            with _rate_server(one, log) as url:  # restarted: the 11th pair, never one answered before
                page.goto(url + "/rate/alice")
                assert page.inner_text("#progress") == "11"
                eleventh = read_pair_set(one).pairs[int(page.input_value("input[name=pair]"))].pair_id
                assert eleventh not in got
                assert len(pd.read_parquet(one / "ratings.parquet")) == 10

            with _rate_server(two, log) as url:
                pages = {r: browser.new_page() for r in ("r1", "r2")}
                for rater, pg in pages.items():
                    pg.goto(f"{url}/rate/{rater}")
                for _ in range(20):  # the two raters take turns
                    for rater, pg in pages.items():
                        _rate(pg, two, rater, 1, _preferred)
                for pg in pages.values():
                    assert pg.inner_text("#done") == "Thank you"
        finally:
            browser.close()

    ratings = pd.read_parquet(two / "ratings.parquet")
    assert len(ratings) == 40 and ratings.groupby("rater").pair_id.nunique().to_dict() == {"r1": 20, "r2": 20}
    assert (ratings["winner"].map(PREFERENCE.index) < ratings["loser"].map(PREFERENCE.index)).all()
    uri = "sqlite:///" + str(tmp_path / "mlflow" / "mlflow.db")
    (tmp_path / "mlflow").mkdir()
    proc = subprocess.run([sys.executable, "-m", "asset2sim", "rate", str(two), "--scores", "--tracking-uri", uri],
                          capture_output=True, text=True, cwd=tmp_path, timeout=300)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "asset2sim" in proc.stdout and "95 % interval" in proc.stdout and "MLflow run" in proc.stdout
    scores = pd.read_parquet(two / "realism_scores.parquet").set_index("method")
    assert list(scores.index) == list(PREFERENCE) and (scores["source"] == "people").all()
    assert scores.loc["asset2sim", "ci_low"] > scores.loc["defaults", "ci_high"]
    assert (scores["ci_low"] < scores["strength"]).all() and (scores["strength"] < scores["ci_high"]).all()
    assert scores["strength"].sum() == pytest.approx(0, abs=1e-9)
    assert scores.loc["asset2sim", "wins"] == scores.loc["asset2sim", "comparisons"] == 22

    from mlflow.tracking import MlflowClient

    client = MlflowClient(tracking_uri=uri)
    experiment = client.get_experiment_by_name("asset2sim-realism")
    runs = client.search_runs([experiment.experiment_id])
    assert len(runs) == 1 and runs[0].info.status == "FINISHED"
    metrics = runs[0].data.metrics
    assert metrics["people/asset2sim/strength"] == pytest.approx(scores.loc["asset2sim", "strength"])
    assert metrics["people/defaults/ci_high"] == pytest.approx(scores.loc["defaults", "ci_high"])
    artifacts = {a.path for a in client.list_artifacts(runs[0].info.run_id)}
    assert {"ratings.parquet", "realism_scores.json"} <= artifacts
    assert (tmp_path / "mlflow" / "mlruns").is_dir() and not (tmp_path / "mlruns").exists()  # beside the database
