"""The per-run API server of a flow run (``start_local_server(..., ephemeral=True)``) registers no Prefect block types
(a flow run reads none; on a new project's database the registration was a third of the server's start) and leaves
no memo of a registration, so that the project's full server (``serve``) still registers them on its first start."""

from __future__ import annotations

import json
import urllib.request

import pytest

from asset2sim.flows import server


def _block_type_slugs(url: str) -> list[str]:
    req = urllib.request.Request(url + "/block_types/filter", data=b"{}", method="POST",
                                 headers={"Content-Type": "application/json"})
    with urllib.request.urlopen(req, timeout=30) as resp:
        return [b["slug"] for b in json.loads(resp.read())]


@pytest.mark.slow  # two Prefect servers started on a new project's database
def test_a_flow_runs_server_registers_no_block_types_and_the_full_server_still_does(tmp_path, monkeypatch):
    home = tmp_path / ".prefect"
    monkeypatch.setenv("PREFECT_HOME", str(home))
    for name in ("PREFECT_API_BLOCKS_REGISTER_ON_START", "PREFECT_MEMOIZE_BLOCK_AUTO_REGISTRATION"):
        monkeypatch.delenv(name, raising=False)
    proc, url = server.start_local_server(tmp_path, ephemeral=True)
    try:
        assert _block_type_slugs(url) == []
    finally:
        server.stop_server(proc)
    assert not (home / "memo_store.toml").exists()
    proc, url = server.start_local_server(tmp_path)
    try:
        assert {"local-file-system", "secret"} <= set(_block_type_slugs(url))
    finally:
        server.stop_server(proc)
