"""Baselines (defaults, human), URDF scaling, the manifest and the benchmark
runner on a generated PartNet-Mobility-like folder."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from asset2sim.apps.benchmark import baselines as bl
from asset2sim.apps.benchmark import benchmark
from asset2sim.tasks.ingest import partnet_mobility

CUBE_OBJ = "\n".join(
    [f"v {x} {y} {z}" for x in (-0.5, 0.5) for y in (-0.5, 0.5) for z in (-0.5, 0.5)]
    + ["f 1 3 4 2", "f 5 6 8 7", "f 1 2 6 5", "f 3 7 8 4", "f 1 5 7 3", "f 2 4 8 6"]
) + "\n"


def _urdf(lid_type="revolute", drawer_type="prismatic"):
    mesh = '<geometry><mesh filename="textured_objs/cube.obj"/></geometry>'
    return (
        '<?xml version="1.0"?><robot name="obj"><link name="base"/>'
        f'<link name="body"><visual><origin xyz="0 0 0.5"/>{mesh}</visual><collision><origin xyz="0 0 0.5"/>{mesh}</collision></link>'
        '<link name="lid"><collision><origin xyz="0.5 0 0.05"/><geometry><box size="1 1 0.1"/></geometry></collision></link>'
        '<link name="drawer"><collision><origin xyz="0 0 0"/><geometry><box size="0.4 0.8 0.3"/></geometry></collision></link>'
        '<joint name="root" type="fixed"><parent link="base"/><child link="body"/></joint>'
        f'<joint name="joint_lid" type="{lid_type}"><parent link="body"/><child link="lid"/><origin xyz="-0.5 0 1.0"/>'
        '<axis xyz="0 -1 0"/><limit lower="-0.5" upper="2.0"/></joint>'
        f'<joint name="joint_drawer" type="{drawer_type}"><parent link="body"/><child link="drawer"/><origin xyz="0.75 0 0.3"/>'
        '<axis xyz="1 0 0"/><limit lower="0.1" upper="0.6"/></joint>'
        "</robot>"
    )


@pytest.fixture
def dataset(tmp_path) -> Path:
    root = tmp_path / "ds"
    obj = root / "1001"
    (obj / "textured_objs").mkdir(parents=True)
    (obj / "textured_objs" / "cube.obj").write_text(CUBE_OBJ)
    (obj / "mobility.urdf").write_text(_urdf())
    # GenSim2 froze the drawer; the lid is the task joint
    (obj / "reference_gensim2.urdf").write_text(_urdf(drawer_type="fixed"))
    (obj / "reference_gensim2.json").write_text(json.dumps({"scale": 0.5, "joint_position_range": [0.2, 0.6]}))
    (obj / "meta.json").write_text(json.dumps({"model_cat": "Box"}))
    (obj / "semantics.txt").write_text("body free box_body\nlid hinge lid\ndrawer slider drawer\n")
    (root / "manifest.csv").write_text(
        "id,category,prompt,task,gensim2_task,reference_scale,reference_joint_range\n"
        '1001,Box,A box with its lid slightly open.,close the box lid,box_rotate,0.5,"[0.2, 0.6]"\n'
    )
    return root


def _aabb_extents(urdf: Path, drawer_q: float) -> np.ndarray:
    from asset2sim.engines.base import SessionOptions
    from asset2sim.engines.registry import open_session
    from asset2sim.tasks.geometry.urdf_closed import aabb_extents

    s = open_session("pybullet", urdf, SessionOptions(fixed_base=True, gravity=False, ground=False,
                                                      initial_state={"joint_lid": 0.0, "joint_drawer": drawer_q}))
    try:
        return aabb_extents(s)
    finally:
        s.close()


def test_scale_urdf_bakes_the_scale_into_meshes_origins_and_prismatic_limits(dataset, tmp_path):
    src = dataset / "1001" / "mobility.urdf"
    out = bl.scale_urdf(src, tmp_path / "o" / "mobility.urdf", 0.5)
    text = out.read_text()
    assert 'scale="0.5 0.5 0.5"' in text
    assert 'filename="textured_objs/cube.obj"' in text
    assert (tmp_path / "o" / "textured_objs" / "cube.obj").read_text() == CUBE_OBJ
    joints = bl.urdf_joints(out)
    assert joints["joint_drawer"]["lower"] == pytest.approx(0.05) and joints["joint_drawer"]["upper"] == pytest.approx(0.3)
    assert joints["joint_lid"]["lower"] == pytest.approx(-0.5) and joints["joint_lid"]["upper"] == pytest.approx(2.0)
    # Everything is half as big in the simulator (the drawer at its scaled lower limit).
    ext_src = _aabb_extents(src, 0.1)
    ext_out = _aabb_extents(out, 0.05)
    assert ext_out == pytest.approx(ext_src * 0.5, rel=0.02)


def test_scale_urdf_rejects_bad_scale_and_unknown_joints(dataset, tmp_path):
    src = dataset / "1001" / "mobility.urdf"
    with pytest.raises(ValueError, match="scale"):
        bl.scale_urdf(src, tmp_path / "x.urdf", 0.0)
    with pytest.raises(ValueError, match="not found"):
        bl.scale_urdf(src, tmp_path / "x.urdf", 1.0, joint_limits={"nope": (0, 1)})


def test_read_manifest(dataset, tmp_path):
    (row,) = bl.read_manifest(dataset / "manifest.csv")
    assert row.id == "1001" and row.reference_scale == 0.5 and row.reference_joint_range == (0.2, 0.6)
    assert row.folder == dataset / "1001"
    bad = tmp_path / "bad.csv"
    bad.write_text("id,category,prompt,reference_scale\n,Box,x,0.1\n")
    with pytest.raises(ValueError, match="without id"):
        bl.read_manifest(bad)
    bad.write_text("id,category,prompt,reference_scale\n7,Box,x,abc\n")
    with pytest.raises(ValueError, match="id 7"):
        bl.read_manifest(bad)


def test_defaults_baseline_is_the_raw_asset_at_the_reference_scale(dataset, tmp_path):
    (row,) = bl.read_manifest(dataset / "manifest.csv")
    res = bl.make_defaults(row, tmp_path / "d")
    assert res.scale == 0.5
    assert res.initial_state == {"joint_lid": 0.0, "joint_drawer": pytest.approx(0.05)}  # 0 clipped to [0.05, 0.3]
    text = (tmp_path / "d" / "mobility.urdf").read_text()
    assert "<inertial" not in text and "<dynamics" not in text  # PyBullet's defaults apply
    meta = json.loads((tmp_path / "d" / "baseline.json").read_text())
    assert meta["method"] == "defaults" and meta["scale"] == 0.5
    assert json.loads((tmp_path / "d" / "initial_state.json").read_text())["initial_joint_positions"] == res.initial_state


def test_human_baseline_uses_gensim2_scale_range_and_lower_end_state(dataset, tmp_path):
    (row,) = bl.read_manifest(dataset / "manifest.csv")
    res = bl.make_human(row, tmp_path / "h")
    joints = bl.urdf_joints(tmp_path / "h" / "mobility.urdf")
    assert joints["joint_drawer"]["type"] == "fixed"
    assert (joints["joint_lid"]["lower"], joints["joint_lid"]["upper"]) == (pytest.approx(0.2), pytest.approx(0.6))
    assert res.initial_state == {"joint_lid": pytest.approx(0.2)}
    assert res.scale == 0.5


def test_human_baseline_without_scale_or_range(dataset, tmp_path):
    (dataset / "1001" / "reference_gensim2.json").write_text(json.dumps({"keypoints": {}}))
    (row,) = bl.read_manifest(dataset / "manifest.csv")
    res = bl.make_human(row, tmp_path / "h")
    assert res.scale == 1.0 and res.initial_state == {"joint_lid": 0.0} and res.notes


def test_reference_info_and_missing_reference(dataset, tmp_path):
    info = partnet_mobility.read_reference(dataset / "1001")
    assert info.scale == 0.5 and info.task_joints == ["joint_lid"]
    (dataset / "1001" / "reference_gensim2.urdf").unlink()
    (row,) = bl.read_manifest(dataset / "manifest.csv")
    with pytest.raises(bl.BaselineError, match="reference_gensim2.urdf"):
        bl.make_human(row, tmp_path / "h")


def test_run_method_unknown():
    with pytest.raises(KeyError, match="unknown method"):
        bl.run_method("nope", bl.ManifestRow("1", "Box", "x"), Path("."))


def test_benchmark_runs_every_method_and_a_failing_method_does_not_stop_the_others(dataset, tmp_path):
    def broken(row, out_dir, seed=0):
        raise bl.BaselineError(f"{row.id}: broken on purpose")

    bl.register_method("broken_for_test", broken)
    try:
        records = benchmark.run_benchmark(dataset / "manifest.csv", ["defaults", "broken_for_test", "human"], tmp_path / "bench",
                                   reports=False)
    finally:
        bl._REGISTRY.pop("broken_for_test", None)
    by = {r["method"]: r for r in records}
    assert by["broken_for_test"]["error"].startswith("BaselineError")
    for m in ("defaults", "human"):
        r = by[m]
        assert r["error"] is None and r["id"] == "1001" and r["thesis_set"] is True
        assert r["rest_stability_pass"] in (True, False) and r["seconds"] > 0
        assert (tmp_path / "bench" / m / "1001" / "evaluation.json").is_file()
    assert by["human"]["scale_deviation"] == pytest.approx(0.0)
    assert by["human"]["initial_joint_deviation"] == pytest.approx(0.0)
    table = benchmark.summarize(records, ["defaults", "broken_for_test", "human"])
    assert table["broken_for_test"]["errors"] == 1 and table["broken_for_test"]["rest_stability_pass"] is None
    assert table["human"]["n"] == 1


def test_summarize_statistics():
    recs = [
        {"method": "m", "id": str(i), "category": cat, "error": None, "penetration": pen, "scale_deviation": 10.0 * i,
         "initial_joint_deviation": 0.1, "prompt_alignment": 0.5, "rest_stability_pass": i < 2, "oscillation_pass": True,
         "probes_pass": None, "all_pass": False, "seconds": float(i + 1)}
        for i, (cat, pen) in enumerate([("Toilet", 10.0), ("Stapler", 20.0), ("Box", 90.0)])
    ]
    t = benchmark.summarize(recs, ["m"])["m"]
    assert t["pen_ts_mean"] == pytest.approx(15.0) and t["pen_ts_sd"] == pytest.approx(np.std([10, 20], ddof=1))
    assert t["pen_mean"] == pytest.approx(40.0)
    assert t["scale_mean"] == pytest.approx(10.0) and t["scale_sd"] == pytest.approx(10.0)
    assert t["rest_stability_pass"] == pytest.approx(2 / 3) and t["rest_n"] == 3
    assert t["probes_pass"] is None and t["probes_n"] == 0
    assert t["median_seconds"] == 2.0


def test_compare_records_finds_differences_but_ignores_timings():
    from asset2sim.commands.benchmark import compare_records

    a = [{"method": "m", "id": "1", "penetration": 1.0, "seconds": 0.5, "all_pass": True}]
    b = [{"method": "m", "id": "1", "penetration": 1.0, "seconds": 0.9, "all_pass": True}]
    assert compare_records(a, b) == []
    b[0]["penetration"] = 1.1
    assert compare_records(a, b) == ["('m', '1') penetration: 1.0 vs 1.1"]


@pytest.mark.slow
def test_human_baseline_stability_on_the_thesis_set(shared_dataset, tmp_path):
    """The research saw 8 of 9 GenSim2 assets stable (Isaac Sim). Under the
    SPEC's PyBullet conventions with PyBullet's defaults for the missing
    inertials 7 of 9 are: the two staplers' and suitcases' cases are explained
    in docs/design/metrics.md (self-penetration of the stapler's hulls; the COM of
    every link at its link frame origin tips the suitcase)."""
    from asset2sim.tasks.evaluation.evaluate import evaluate_asset

    rows = bl.read_manifest(shared_dataset / "manifest.csv")[:9]
    verdicts = {}
    for row in rows:
        bl.make_human(row, tmp_path / row.id)
        ev = evaluate_asset(tmp_path / row.id, reference=row.folder, prompt=row.prompt, category=row.category, probes=False)
        verdicts[row.id] = ev.metric("rest_stability").passed
    assert sum(verdicts.values()) == 7
    assert {k for k, v in verdicts.items() if not v} == {"103275", "103755"}


def test_human_range_is_intersected_with_the_file_limits_and_matches_the_reference_state(dataset, tmp_path):
    (dataset / "1001" / "reference_gensim2.json").write_text(json.dumps({"scale": 0.5, "joint_position_range": [-1.0, 0.6]}))
    (row,) = bl.read_manifest(dataset / "manifest.csv")
    res = bl.make_human(row, tmp_path / "h")
    joints = bl.urdf_joints(tmp_path / "h" / "mobility.urdf")
    assert (joints["joint_lid"]["lower"], joints["joint_lid"]["upper"]) == (pytest.approx(-0.5), pytest.approx(0.6))
    assert res.initial_state == {"joint_lid": pytest.approx(-0.5)}
    from asset2sim.tasks.evaluation.evaluate import evaluate_asset

    ev = evaluate_asset(tmp_path / "h", reference=dataset / "1001", probes=False)
    assert ev.metric("initial_joint_deviation").value == pytest.approx(0.0)
