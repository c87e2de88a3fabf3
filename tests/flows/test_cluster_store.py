"""The guide's recipe for N machines (``docs/guide/pipeline.md``, "On N machines"), run on 127.0.0.1 as written: a
Prefect server and a Dask scheduler as processes of their own, two single-threaded ``dask worker`` processes (two
"machines" of one core), a moto S3 server as the store, and the driver's ``asset2sim flow --scheduler ...`` with
catalog and outputs in the store. Its catalog and every output file equal what ``asset2sim flow`` makes of the
same dataset on one machine, in local folders, timings aside (``benchmarks/cluster_run.py``)."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

try:  # package layout or rootdir-on-sys.path layout
    from .flowproject import make_project  # type: ignore[no-redef]
except ImportError:
    from flowproject import make_project  # type: ignore[no-redef]

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "benchmarks"))

import cluster_run  # noqa: E402

from asset2sim.flows import flow_runtime  # noqa: E402

BUCKET = "a2s-cluster"


def test_the_recipe_is_what_the_flow_sets_for_its_own_cluster():
    """The recipe's Dask settings are the ones the flow's local cluster gets (one list, two places)."""
    recipe = cluster_run.recipe()
    dask_env = {k: v for k, v in recipe.env.items() if k.startswith("DASK_")}
    assert dask_env == flow_runtime.dask_settings_env()
    assert recipe.worker[:2] == ["dask", "worker"] and "--nthreads" in recipe.worker
    assert recipe.worker[recipe.worker.index("--nthreads") + 1] == "1"
    assert {"PREFECT_API_URL", "AWS_ENDPOINT_URL"} <= set(recipe.env)


@pytest.mark.slow  # end to end: the guide's cluster recipe, a moto server and two flow runs (about 2 minutes)
def test_the_guides_recipe_for_n_machines_gives_the_local_flows_catalog_and_files(tmp_path):
    raw = make_project(tmp_path / "proj", {"box_lid": "box_lid", "laptop": "laptop"}).parent / "raw"
    # the verdict's files, no media (a shorter run; a deferred media phase would leave the store's outputs deferred)
    run = {"workers": 2, "evaluate": True, "extras": False, "time_limit_seconds": 300}
    local, cluster = cluster_run.write_catalogs(tmp_path, raw, raw / "manifest.csv", BUCKET, run)
    with cluster_run.S3Server(tmp_path / "s3", BUCKET) as s3, \
            cluster_run.RecipeCluster(tmp_path / "cluster-logs", s3.store, machines=2) as rc:
        # the local flow: its own Dask cluster, the recipe's Prefect server, catalog and outputs in local folders
        done = rc.local_flow(local, workers=2)
        assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
        on_cluster = rc.flow(cluster)
        assert on_cluster.returncode == 0, on_cluster.stdout[-3000:] + on_cluster.stderr[-3000:]
        with pytest.MonkeyPatch.context() as mp:
            for k, v in s3.environ().items():
                mp.setenv(k, v)
            a, b = cluster_run.run_rows(local), cluster_run.run_rows(cluster)
            assert list(b["status"]) == ["done", "done"] and all(str(d).startswith(f"s3://{BUCKET}/") for d in b["out_dir"])
            assert set(b["worker"]).isdisjoint(set(a["worker"]))  # refined by the recipe's workers, not the local ones
            problems = cluster_run.compare_runs(a, b)
            assert problems == [], "\n".join(problems)
