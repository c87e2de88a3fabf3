"""An object that rests as modelled but topples when put down (a slim case
standing on its narrow edge, robust rest's 5 deg tilt) is turned to rest on
its stablest face when the request names no pose, as an unstable one is."""
from __future__ import annotations

import pytest

from asset2sim.engines.source import SimObject, UrdfFile
from asset2sim.tasks.check import robust_rest
from asset2sim.tasks.ingest import extract
from asset2sim.tasks.assemble import write
from tests.tasks.check.failure_assets import build_edge_standing_case


@pytest.fixture(scope="module")
def case(tmp_path_factory):
    return build_edge_standing_case(tmp_path_factory.mktemp("case") / "edge_standing_case")


@pytest.fixture(scope="module")
def refined(case, tmp_path_factory, refine_factory):
    return refine_factory(case, "A suitcase.", extras=False)


def test_as_modelled_it_rests_but_a_tilt_topples_it(case, refined, tmp_path):
    """The failure mode: the refined overlay written in the modelled
    orientation passes rest (statically on its edge) and a 5 deg tilt tips it
    over (up direction off by far more than 0.05 rad)."""
    asset, _ = extract.extract_asset_checked(case)
    paths = write.write_output(asset, refined.overlay, tmp_path / "modelled", refined.report.initial_joint_positions)
    run = robust_rest.run_robust_rest("pybullet", SimObject(UrdfFile(paths.urdf), refined.report.initial_joint_positions))
    topple = max(t.topple for t in run.trials if t.topple is not None)
    assert topple > 1.0, topple
    assert not robust_rest.robust_rest_metric(run).passed


def test_refine_rests_it_on_a_stable_face_and_says_why(refined):
    r = refined.report
    assert r.failure_mode == "none", r.failure_mode
    assert r.readiness["robust_rest"] is True and r.readiness["rest"] is True
    note = next(n for n in r.notes if n.startswith("resting pose"))
    assert "toppled by a robust-rest disturbance as modelled" in note and "rests pitched" in note
    assert r.initial_joint_positions == r.state.result  # the state is not what changed
