"""The local Dask cluster keeps its temporary folder (its workers' scratch space, ``global.lock`` and ``purge.lock``)
inside the run's own folder and removes it at the end: nothing is left in the user's TMPDIR. The whole
``asset2sim flow`` under a fresh TMPDIR: ``tests/flows/test_quiet_terminal.py``."""

from __future__ import annotations

import tempfile


def test_a_local_cluster_leaves_nothing_in_tmpdir(tmp_path, monkeypatch):
    import dask
    from distributed import Client, LocalCluster

    from asset2sim.flows.flow_runtime import local_cluster_config

    tmpdir, run = tmp_path / "tmp", tmp_path / "run" / ".work"
    tmpdir.mkdir()
    monkeypatch.setenv("TMPDIR", str(tmpdir))
    monkeypatch.setattr(tempfile, "tempdir", None)  # read TMPDIR again
    with local_cluster_config(None, False, run):
        scratch = dask.config.get("temporary-directory")
        assert scratch.startswith(str(run) + "/.dask-"), scratch
        with LocalCluster(n_workers=1, threads_per_worker=1, processes=False, dashboard_address=None) as cluster, \
                Client(cluster) as client:
            assert client.submit(sum, [1, 2]).result() == 3
        assert list((run).iterdir())  # the workers' scratch space was there
    assert list(tmpdir.iterdir()) == [] and list(run.iterdir()) == []
