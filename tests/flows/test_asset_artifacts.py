"""An asset's MLflow run carries every file its report.html shows: the clips' videos and posters beside it, at the
relative paths the report names, so the report plays in MLflow's artifact view."""

from __future__ import annotations

import re

import pytest

from asset2sim import demo_assets
from asset2sim.flows.tracking import _artifact_dir, asset_artifacts
from asset2sim.tasks.refine import refine_asset

pytestmark = pytest.mark.slow  # end to end: the flows (Prefect, Dask, stage processes)


def test_the_artifacts_hold_every_file_the_report_names(tmp_path):
    box = demo_assets.build_object("box_lid", tmp_path / "box")
    out = tmp_path / "out"
    refine_asset(box, "A small box with its lid slightly open.", out)
    html = (out / "report.html").read_text()
    named = set(re.findall(r"(?:src|poster)='([^':]+)'", html))
    assert any(n.endswith(".webm") for n in named) and any(n.endswith(".png") for n in named)
    logged = {((_artifact_dir(p, out) + "/") if _artifact_dir(p, out) else "") + p.name for p in asset_artifacts(out)}
    assert named <= logged, sorted(named - logged)
    assert {"report.html", "report.json", "evaluation.json", "timings.json", "clips/clips.json"} <= logged
