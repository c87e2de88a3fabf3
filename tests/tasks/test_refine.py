"""The whole refine stage chain on generated assets and on real objects."""

from __future__ import annotations

import csv
import json
import math
import statistics
from pathlib import Path

import pytest

from asset2sim.engines.source import SimObject, UrdfFile
from asset2sim import demo_assets
from asset2sim.engines.base import SessionOptions
from asset2sim.engines.registry import open_session
from asset2sim.schemas.request import BAND_INTERVAL
from asset2sim.tasks import refine as refine_mod
from asset2sim.tasks.refine import MARKER_NAME, RefineError, is_complete, refine_asset
from asset2sim.tasks.synthesize.validate_overlay import inertia_problems
from tests.helpers import assert_ready_or_honestly_not_robust
from tests.conftest import SHARED, needs_shared
from tests.helpers import rest_tests_of_refine
from tests.helpers import tree_hashes


def check_output_contract(out, report):
    """The SPEC's output contract, checked on the written files."""
    import yourdfpy

    urdf = out / "mobility.urdf"
    state = json.loads((out / "initial_state.json").read_text())["initial_joint_positions"]
    overlay = json.loads((out / "overlay.json").read_text())
    assert json.loads((out / "report.json").read_text())["asset_id"] == report.asset_id
    model = yourdfpy.URDF.load(str(urdf), build_scene_graph=False, load_meshes=False)
    for link in model.robot.links:
        if link.visuals or link.collisions:
            assert link.inertial is not None and link.inertial.mass > 0, link.name
            assert inertia_problems(link.inertial.inertia) is None, link.name
        for elem in link.visuals + link.collisions:
            if elem.geometry.mesh is not None:
                fn = elem.geometry.mesh.filename
                assert not fn.startswith("/") and ".." not in fn
                assert (out / fn).is_file()
    limits = {}
    for joint in model.robot.joints:
        if joint.type in ("revolute", "prismatic", "continuous"):
            assert joint.dynamics is not None
            assert float(joint.dynamics.damping) >= 0 and float(joint.dynamics.friction) >= 0
            limits[joint.name] = (joint.limit.lower, joint.limit.upper)
            assert set(overlay["joints"][joint.name]) >= {"damping", "friction", "stiffness"}
    assert set(state) == set(limits)
    for name, q in state.items():
        lo, hi = limits[name]
        if lo is not None:
            assert lo - 1e-9 <= q <= hi + 1e-9
    # loads at scale 1.0 in PyBullet with the SPEC flags
    s = open_session("pybullet", urdf, SessionOptions(initial_state=state))
    s.close()
    assert "initial_state.json" in urdf.read_text()


@pytest.mark.parametrize("entry", demo_assets.DEMO_OBJECTS, ids=lambda e: e.asset_id)
def test_demo_objects_refine_to_interaction_ready(entry, demo_root, refine_once):
    before = tree_hashes(demo_root / entry.asset_id)  # the object as built
    res = refine_once(entry.asset_id, entry.prompt, extras=False)
    src = res.src
    r = res.report
    check_output_contract(res.out_dir, r)
    assert tree_hashes(src) == before
    # the demo cabinet's drawer slightly open and the laptop's screen slightly open are held at the friction a
    # hand overcomes, which robust rest's drop and tilts move beyond their tolerance: said, not jammed
    assert_ready_or_honestly_not_robust(r, res.overlay)
    if entry.asset_id in ("box_lid", "microwave", "trash_can"):
        assert r.failure_mode == "none", r.metrics
    assert r.metric("penetration").value <= 5.0
    for joint, band in r.requested_bands.items():
        lo, hi = BAND_INTERVAL[band]
        assert lo - 1e-9 <= r.opening_fractions[joint] <= hi + 1e-9, (joint, band, r.opening_fractions[joint])
    from asset2sim.tasks.ingest.extract import extract_asset

    asset = extract_asset(src)
    for joint, truth in entry.closed_positions.items():
        # closed ends found from geometry, not assumed (prismatic ones in output units)
        factor = r.scale if asset.joint(joint).type == "prismatic" else 1.0
        assert r.closed_positions[joint] == pytest.approx(truth * factor, abs=0.06)


def test_rerun_skips_complete_output_and_redoes_on_change(demo_root, tmp_path):
    src = demo_root / "box_lid"
    out = tmp_path / "out"
    first = refine_asset(src, "A small box with its lid slightly open.", out, extras=False)
    assert (out / MARKER_NAME).is_file()
    assert is_complete(out, first.report.input_hash, first.report.config_hash)
    again = refine_asset(src, "A small box with its lid slightly open.", out, extras=False)
    assert again.skipped and again.report == first.report
    changed = refine_asset(src, "A small box with its lid closed.", out, extras=False)
    assert not changed.skipped and changed.report.requested_bands["joint_0"] == "closed"
    # a damaged output is not trusted
    (out / "overlay.json").write_text("{}")
    assert not is_complete(out, changed.report.input_hash, changed.report.config_hash)


def test_output_inside_input_refused(demo_root):
    src = demo_root / "laptop"
    before = tree_hashes(src)
    with pytest.raises(RefineError) as err:
        refine_asset(src, "open", src / "out", extras=False)
    assert err.value.failure_mode == "invalid_input"
    assert tree_hashes(src) == before


def test_broken_asset_is_invalid_input(tmp_path):
    (tmp_path / "bad").mkdir()
    (tmp_path / "bad" / "mobility.urdf").write_text("<robot name='x'><link name='a'/><link name='b'/></robot>")
    with pytest.raises(RefineError) as err:
        refine_asset(tmp_path / "bad", "", tmp_path / "out", extras=False)
    assert err.value.failure_mode == "invalid_input"
    assert "root" in str(err.value)


@needs_shared
@pytest.mark.parametrize(
    "obj, prompt",
    [
        ("103275", "I want a slightly open stapler."),
        ("19179", "I want a very small two-drawer under-desk office cabinet, with the first drawer closed and the second slightly open, with low damping sliding joints."),
        ("101668", "A carry-on suitcase lying flat with its lid half open."),
    ],
)
@pytest.mark.slow  # end to end: dev objects refined on their own
def test_real_objects(obj, prompt, refine_once):
    res = refine_once(SHARED / obj, prompt, extras=False)  # the input and output checked unchanged after the test
    r = res.report
    check_output_contract(res.out_dir, r)
    assert r.metric("rest_stability").passed and r.metric("oscillation").passed
    assert r.metric("penetration").value <= 5.0
    for joint, band in r.requested_bands.items():
        lo, hi = BAND_INTERVAL[band]
        assert lo - 1e-9 <= r.opening_fractions[joint] <= hi + 1e-9


@needs_shared
@pytest.mark.slow  # end to end: a dev object refined on its own
def test_two_drawer_ordinals_follow_height(tmp_path):
    res = refine_asset(
        SHARED / "19179",
        "the first drawer closed and the second slightly open",
        tmp_path / "o",
        extras=False,
    )
    bands = res.report.requested_bands
    assert sorted(bands.values()) == ["closed", "slightly_open"]


@needs_shared
@pytest.mark.slow  # end to end: a dev object refined on its own
def test_escalation_for_robust_rest_keeps_the_drawers_sweepable(tmp_path):
    """A large cabinet (19179, scale ~0.85): robust rest's tilts slide its
    closed drawers, and escalation raised their damping 63-fold (3,900 N s/m)
    until the sweep's drive crawled 74 % of the 0.85 m range in its 3 s.
    With the sweep's damping cap the sweep passes; the drawers (15 and 28 kg
    drawer boxes) keep what a hand moves, and where a 5 degree tilt still
    slides the heavier one out the verdict says so."""
    from asset2sim.tasks.tune.operating import damping_caps
    from asset2sim.urdf import read_urdf

    res = refine_asset(SHARED / "19179", "A large cabinet.", tmp_path / "o", extras=False)
    r = res.report
    assert r.metric("joint_sweep").passed, r.metric("joint_sweep").details.get("failures")
    assert_ready_or_honestly_not_robust(r, res.overlay)
    urdf = res.out_dir / "mobility.urdf"
    model = read_urdf(urdf)  # the drawers close at their lower limit and open towards the upper
    closed = {j: (model.joint(j).lower, 1.0, model.joint(j).upper - model.joint(j).lower) for j in r.closed_positions}
    assert all(r.closed_positions[j] == pytest.approx(c[0]) for j, c in closed.items())
    caps = damping_caps(SimObject(UrdfFile(urdf), r.initial_joint_positions), closed)
    assert caps and all(res.overlay.joints[j].damping <= c * (1 + 1e-6) for j, c in caps.items())


@needs_shared
@pytest.mark.slow
def test_thesis_set_meets_the_refine_issue_targets(refine_once):
    """First nine manifest rows: stability 9/9, oscillation 9/9, penetration <= 5 mm,
    valid inertias, median scale deviation <= 25 %, every requested state in its band."""
    rows = list(csv.DictReader((SHARED / "manifest.csv").open()))[:9]
    devs = []
    for row in rows:
        res = refine_once(SHARED / row["id"], row["prompt"], extras=False)
        r = res.report
        assert r.metric("rest_stability").passed, row["id"]
        assert r.metric("oscillation").passed, row["id"]
        assert r.metric("penetration").value <= 5.0, row["id"]
        assert all(inertia_problems(lp.inertia.matrix()) is None for lp in res.overlay.links.values())
        for joint, band in r.requested_bands.items():
            lo, hi = BAND_INTERVAL[band]
            assert lo - 1e-9 <= r.opening_fractions[joint] <= hi + 1e-9, (row["id"], joint)
        ref = json.loads((SHARED / row["id"] / "reference_gensim2.json").read_text() or "{}")
        if ref.get("scale"):
            devs.append(abs(r.scale - ref["scale"]) / ref["scale"])
    assert statistics.median(devs) <= 0.25


@needs_shared
@pytest.mark.slow  # end to end: a dev object refined on its own
def test_a_request_naming_a_part_the_object_lacks_ends_request_not_met(tmp_path):
    """As asked (SPEC): the stapler 103275 has no drawer, so "its drawer open" is not applied; the verdict says so
    in report.json, evaluation.json and report.html (the evaluation, run as refine's extra, decides)."""
    res = refine_asset(SHARED / "103275", "A stapler with its drawer open.", tmp_path / "o")
    r = res.report
    assert r.failure_mode == "request_not_met", (r.failure_mode, r.readiness)
    assert r.readiness["request"] is False
    unmet = r.metric("request_met").details["unmet"]
    assert [u["phrase"] for u in unmet] == ["drawer open"] and unmet[0]["kind"] == "not_applied"
    on_disk = json.loads((res.out_dir / "report.json").read_text())
    assert on_disk["failure_mode"] == "request_not_met"
    ev = json.loads((res.out_dir / "evaluation.json").read_text())
    assert next(m for m in ev["metrics"] if m["name"] == "request_met")["passed"] is False
    assert "request_met@none" in ev["failures"]
    html = (res.out_dir / "report.html").read_text()
    assert "Not as asked" in html and "drawer open" in html and "request_not_met" in html


@needs_shared
def test_an_angle_asked_is_met_from_the_closed_end_when_the_limits_are_clipped(refine_once):
    """The suitcase 101668 lying flat: its lid's range is clipped to the geometry (180 -> about 119 degrees) after the
    30 degrees were resolved; the lid still stands 30 degrees from its closed end (it was left at 20.8, the 1/6 of
    the range the first resolution gave), and the as-asked tier passes."""
    r = refine_once(SHARED / "101668", "a carry-on suitcase lying flat with the lid open 30 degrees", extras=False).report
    (q,) = [q for q in r.request.quantities if q.kind == "state"]
    assert q.unit == "rad" and q.achieved == pytest.approx(math.radians(30), rel=0.05) and q.within_tolerance
    j = q.what.split()[0]
    assert abs(r.initial_joint_positions[j] - r.closed_positions[j]) == pytest.approx(math.radians(30), rel=0.05)
    assert r.metric("request_met").passed is True and r.readiness["request"] is True


def test_plain_urdf_without_partnet_extras(tmp_path):
    """Any URDF works: no semantics or meta, primitives, a root with geometry,
    a continuous joint (kept at its modelled pose)."""
    from tests.helpers import write_cupboard_without_extras

    src = write_cupboard_without_extras(tmp_path / "cupboard")
    res = refine_asset(src, "a cupboard with its door halfway open", tmp_path / "out", extras=False)
    r = res.report
    check_output_contract(res.out_dir, r)
    assert r.failure_mode == "none"
    assert r.closed_positions["door_hinge"] == pytest.approx(0.0, abs=0.05)
    assert r.requested_bands["door_hinge"] == "halfway"
    lo, hi = BAND_INTERVAL["halfway"]
    assert lo <= r.opening_fractions["door_hinge"] <= hi
    assert r.initial_joint_positions["wheel_j"] == 0.0


# ------------------------------------------------------------ each piece of work once


def test_refine_reads_once_decides_once_and_evaluate_gives_its_verdict(demo_root, tmp_path, monkeypatch):
    """The asset is read once and the rest test run once per check round, none in the extras: evaluation.json
    presents report.json's metrics and verdict (written once, with every tier the verdict reads), and ``asset2sim
    evaluate`` on the output folder, read back into the same model and checked by the same checks, measures the same
    metrics and gives the same verdict."""
    from asset2sim.tasks.check import metrics as check_metrics
    from asset2sim.tasks.check.verdict import TIERS
    from asset2sim.tasks.evaluation.evaluate import evaluate_asset
    from asset2sim.tasks.ingest import extract
    from asset2sim.tasks.publish import contract

    counts = {"extract": 0, "rest_test": 0, "report_json": 0}
    real_extract, real_rest, real_write = extract.extract_asset_checked, check_metrics.run_rest_test, contract.write_report_json

    def counting_extract(*a, **k):
        if Path(a[0]).resolve() == (demo_root / "laptop").resolve():  # the input (the evaluator reads the output URDF)
            counts["extract"] += 1
        return real_extract(*a, **k)

    def counting_rest(*a, **k):
        counts["rest_test"] += 1
        return real_rest(*a, **k)

    def counting_write(*a, **k):
        counts["report_json"] += 1
        return real_write(*a, **k)

    monkeypatch.setattr(extract, "extract_asset_checked", counting_extract)
    monkeypatch.setattr(check_metrics, "run_rest_test", counting_rest)
    monkeypatch.setattr(refine_mod, "write_report_json", counting_write)
    entry = next(e for e in demo_assets.DEMO_OBJECTS if e.asset_id == "laptop")
    out = tmp_path / "out"
    res = refine_asset(demo_root / entry.asset_id, entry.prompt, out)
    assert "html" in res.extras, res.report.notes
    assert counts["extract"] == 1 and counts["report_json"] == 1
    assert counts["rest_test"] == rest_tests_of_refine(res.report)
    report = json.loads((out / "report.json").read_text())
    written = json.loads((out / "evaluation.json").read_text())
    assert written["failure_mode"] == report["failure_mode"] == res.report.failure_mode
    assert written["metrics"][:len(report["metrics"])] == report["metrics"]  # the record, then the semantic measures
    deciding = {n for names, _ in TIERS.values() for n in names}
    assert not {m["name"] for m in written["metrics"][len(report["metrics"]):]} & deciding
    assert {"ground_penetration", "divergence", "state_hold"} <= {m["name"] for m in report["metrics"]}

    counts["rest_test"] = 0
    fresh = evaluate_asset(out)
    assert fresh.failure_mode == report["failure_mode"]
    got = {(m.name, m.engine): (m.value, m.passed) for m in fresh.metrics}
    for m in report["metrics"]:
        assert got[(m["name"], m["engine"])] == (m["value"], m["passed"]), m["name"]


def test_refine_takes_an_already_extracted_asset(refine_once, tmp_path, monkeypatch):
    """``extracted=`` (what the flow's prepare stage read) is used as it is: no
    second reading, and the same report as a run that reads the asset itself."""
    from asset2sim.tasks.ingest import extract

    entry = next(e for e in demo_assets.DEMO_OBJECTS if e.asset_id == "laptop")
    shared = refine_once(entry.asset_id, entry.prompt, extras=False)  # a run that read the asset itself
    src = shared.src
    assert src.name == "laptop"  # so its asset id is the one handed below
    asset, findings = extract.extract_asset_checked(src, asset_id="laptop")
    read_here = shared.report

    def no_reading(*a, **k):
        raise AssertionError("the asset was read again")

    monkeypatch.setattr(extract, "extract_asset_checked", no_reading)
    handed = refine_asset(src, entry.prompt, tmp_path / "b", asset_id="laptop", extras=False, extracted=(asset, findings)).report
    def strip(r):  # timing fields excepted
        d = r.model_dump(mode="json")
        d.pop("stage_seconds")
        d["state"].pop("seconds")
        return d

    assert strip(handed) == strip(read_here)


def test_a_refine_runs_its_stages_on_one_blas_thread(demo_root, tmp_path, monkeypatch):
    """In any process (the API's, a test's), a refine's stages run on one BLAS thread, as `asset2sim refine` and the
    flow's workers run them: OpenBLAS's threads spin on the refine's small arrays (CPU time, no wall time)."""
    from threadpoolctl import threadpool_info, threadpool_limits

    def blas_threads() -> set[int]:
        return {lib["num_threads"] for lib in threadpool_info() if lib["user_api"] == "blas"}

    seen = []

    def stop(*args):
        seen.append(blas_threads())
        raise KeyboardInterrupt("stopped after the first stage")

    monkeypatch.setattr(refine_mod, "_analyze", stop)
    with threadpool_limits(limits=2, user_api="blas"):
        caller = blas_threads()
        with pytest.raises(KeyboardInterrupt):
            refine_asset(demo_root / "laptop", "open", tmp_path / "out", extras=False, skip_if_complete=False)
        assert blas_threads() == caller  # the caller's setting back after the refine
    assert seen == [{1}]
