"""MLflow tracking of realism scores: one run through the given tracking URI (never the process-wide one),
every method's score as metrics, the ratings table as an artifact."""

from __future__ import annotations

import pytest

from asset2sim.flows.realism_tracking import log_realism_scores, metric_key
from asset2sim.schemas.realism import MethodScore

pytestmark = pytest.mark.slow  # end to end: the flows (Prefect, Dask, stage processes)


def _scores():
    return [MethodScore(source="people", method="asset2sim", strength=0.7, ci_low=0.1, ci_high=1.3, elo=1121.6,
                        comparisons=12, wins=10),
            MethodScore(source="people", method="defect:mass_x100", strength=-0.7, ci_low=-1.3, ci_high=-0.1,
                        elo=878.4, comparisons=12, wins=2)]


def test_log_realism_scores(tmp_path, monkeypatch):
    import mlflow
    from mlflow.tracking import MlflowClient

    monkeypatch.chdir(tmp_path)
    mlflow.set_tracking_uri("sqlite:///" + str(tmp_path / "elsewhere.db"))  # the process-wide URI: not used
    ratings = tmp_path / "ratings.parquet"
    ratings.write_bytes(b"PAR1")
    uri = "sqlite:///" + str(tmp_path / "store" / "mlflow.db")
    (tmp_path / "store").mkdir()
    try:
        run_id = log_realism_scores(_scores(), tracking_uri=uri, ratings_parquet=ratings, experiment="realism-test")
    finally:
        mlflow.set_tracking_uri(None)
    client = MlflowClient(tracking_uri=uri)
    run = client.get_run(run_id)
    assert run.info.status == "FINISHED"
    assert run.data.metrics["people/asset2sim/strength"] == pytest.approx(0.7)
    assert run.data.metrics[metric_key("people", "defect:mass_x100", "ci_high")] == pytest.approx(-0.1)
    assert metric_key("people", "defect:mass_x100", "elo") == "people/defect_mass_x100/elo"
    assert run.data.metrics["people/asset2sim/comparisons"] == 12
    assert run.data.params["methods"] == "asset2sim,defect:mass_x100" and run.data.params["sources"] == "people"
    assert {a.path for a in client.list_artifacts(run_id)} == {"ratings.parquet", "realism_scores.json"}
    assert (tmp_path / "store" / "mlruns").is_dir() and not (tmp_path / "mlruns").exists()
    assert not (tmp_path / "elsewhere.db").exists()
    again = log_realism_scores(_scores(), tracking_uri=uri, experiment="realism-test")  # same experiment, new run
    assert again != run_id and len(client.search_runs([run.info.experiment_id])) == 2


def test_nothing_to_log(tmp_path):
    with pytest.raises(ValueError, match="no realism scores"):
        log_realism_scores([], tracking_uri="sqlite:///" + str(tmp_path / "m.db"))
    with pytest.raises(ValueError, match="no such ratings table"):
        log_realism_scores(_scores(), tracking_uri="sqlite:///" + str(tmp_path / "m.db"),
                           ratings_parquet=tmp_path / "none.parquet")
