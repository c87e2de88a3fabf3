"""Same input, same code, same files: a refine gives byte-equal outputs
(wall-clock timings and the output folder's own path aside) with an empty
on-disk cache, the same cache warm, a cache filled by another asset, and the
cache off. No wall-clock budget decides a result (the CoACD budget is a
count of calls, ``RefineConfig.max_decompositions``)."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

from asset2sim import demo_assets
from asset2sim.schemas.config import RefineConfig
from asset2sim.tasks.refine import MARKER_NAME, refine_asset
from tests import corpus_builder as cb

PROMPT = "a small box with its lid slightly open"


def _without_timings(obj, out: Path):
    """``obj`` (JSON) with every ``*seconds`` value dropped and the output
    folder's path replaced by ``OUT``."""
    if isinstance(obj, dict):
        return {k: _without_timings(v, out) for k, v in obj.items() if not k.endswith("seconds")}
    if isinstance(obj, list):
        return [_without_timings(v, out) for v in obj]
    if isinstance(obj, str):
        return obj.replace(str(out), "OUT")
    return obj


def _contents(out: Path) -> dict[str, object]:
    """Every file of ``out`` but the completion marker (it lists the hashes
    of files holding timings): JSON without timings, the HTML report without
    its evaluation time, other files as bytes."""
    res: dict[str, object] = {}
    for p in sorted(out.rglob("*")):
        if not p.is_file() or p.name == MARKER_NAME:
            continue
        rel = str(p.relative_to(out))
        if p.suffix == ".json":
            res[rel] = _without_timings(json.loads(p.read_text()), out)
        elif p.suffix == ".html":
            res[rel] = re.sub(r"evaluated in [0-9.e+-]+ s", "evaluated in T s", p.read_text().replace(str(out), "OUT"))
        else:
            res[rel] = p.read_bytes()
    return res


@pytest.mark.slow  # end to end: refines with every extra, cold and warm caches
def test_refine_files_do_not_depend_on_the_cache_state(tmp_path, monkeypatch):
    box = demo_assets.build_box_with_lid(tmp_path / "in" / "box")
    other = cb.build_valid(tmp_path / "in" / "other")
    runs: dict[str, dict[str, object]] = {}
    for name, cache in (("empty", "c1"), ("warm", "c1"), ("filled_by_another", "c2"), ("off", "off")):
        monkeypatch.setenv("ASSET2SIM_CACHE", cache if cache == "off" else str(tmp_path / cache))
        if name == "filled_by_another":
            refine_asset(other, "a cabinet with the drawer slightly open", tmp_path / "other_out", extras=False)
        out = tmp_path / f"out_{name}"
        refine_asset(box, PROMPT, out, config=RefineConfig())
        runs[name] = _contents(out)
    assert any((tmp_path / "c1").rglob("*.npz")) and any((tmp_path / "c2").rglob("*.npz"))
    base = runs["empty"]
    assert "mobility.urdf" in base and any(k.startswith("collision/") for k in base)
    for name, got in runs.items():
        assert sorted(got) == sorted(base), name
        diff = [k for k in base if got[k] != base[k]]
        assert not diff, (name, diff)


def test_two_refines_into_one_folder_are_byte_identical(tmp_path, monkeypatch):
    """The same input refined twice into the same folder, the on-disk cache cold then warm: every file byte for byte,
    the completion marker included, with no filter; wall times live in ``timings.json`` alone (listed in the marker
    as unhashed) and are still there for the summary."""
    box = demo_assets.build_box_with_lid(tmp_path / "in" / "box")
    monkeypatch.setenv("ASSET2SIM_CACHE", str(tmp_path / "cache"))
    out = tmp_path / "out"
    snapshots = []
    for _ in range(2):
        result = refine_asset(box, PROMPT, out, config=RefineConfig(), skip_if_complete=False)
        snapshots.append({str(p.relative_to(out)): p.read_bytes() for p in sorted(out.rglob("*"))
                          if p.is_file() and p.name != "timings.json"})
        assert result.report.stage_seconds and result.report.stage_seconds.get("post_check", 0) > 0
    first, second = snapshots
    assert sorted(first) == sorted(second) and "report.html" in first and MARKER_NAME in first
    assert [k for k in first if first[k] != second[k]] == []
    report = json.loads((out / "report.json").read_text())
    assert "stage_seconds" not in report and "seconds" not in (report.get("state") or {})
    timings = json.loads((out / "timings.json").read_text())
    assert timings["stage_seconds"]["post_check"] > 0 and timings["evaluation_seconds"] > 0
    marker = json.loads((out / MARKER_NAME).read_text())
    assert marker["unhashed"] == ["timings.json"] and "timings.json" not in marker["files"]
    again = refine_asset(box, PROMPT, out, config=RefineConfig())  # complete: the recorded result, its timings read back
    assert again.skipped and again.report.stage_seconds == timings["stage_seconds"]
