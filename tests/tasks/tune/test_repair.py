"""Stage 7b's candidate repairs (asset2sim.tasks.tune.repair) on a generated
two-drawer asset: the parts-held-together trigger and the running-clearance
candidate."""

from __future__ import annotations

from asset2sim.schemas.overlay import EstimatorInfo, Inertia, JointDynamics, LinkPhysics, Overlay
from asset2sim.schemas.report import MetricResult
from asset2sim.tasks.tune.escalation import kept_dynamics
from asset2sim.tasks.state import clearance
from asset2sim.tasks.tune import repair
from asset2sim.urdf import read_urdf
from tests.tasks.state.test_clearance import write_stacked_drawers


def _metrics(failing: str | None, pairs: list[tuple[str, str]]) -> list[MetricResult]:
    pen = MetricResult(name="penetration", value=2.0 if pairs else 0.0, unit="mm",
                       details={"pairs": [{"link_a": a, "link_b": b, "depth_mm": 2.0} for a, b in pairs]})
    tiers = [MetricResult(name=n, value=0.0, unit="", passed=n != failing) for n in ("joint_sweep", *repair.HELD_TOGETHER_TIERS)]
    return [pen, *tiers]


def test_held_together_pairs_need_a_failing_tier_and_a_contact():
    assert repair.held_together_pairs(_metrics("robust_rest", [("lower", "upper")])) == [("lower", "upper")]
    assert repair.held_together_pairs(_metrics("task_execution", [("lower", "upper")])) == [("lower", "upper")]
    assert repair.held_together_pairs(_metrics(None, [("lower", "upper")])) == []  # every tier passes: nothing to repair
    assert repair.held_together_pairs(_metrics("robust_rest", [])) == []  # nothing touches
    assert repair.held_together_pairs(_metrics("joint_sweep", [("lower", "upper")])) == []  # the sweep's own repairs


def test_clearance_candidate_keeps_earlier_overrides_and_writes_its_pieces(tmp_path):
    urdf = write_stacked_drawers(tmp_path)
    model = read_urdf(urdf)
    state = {"slide_lower": 0.0, "slide_upper": 0.02}
    touching = clearance.touching_joints(model, [("lower", "upper")], state, repair.limits.subtrees(model))
    earlier = {"frame": []}
    rep = repair.clearance_repair(model, urdf, touching, state, earlier, 1.0, tmp_path, "collision")
    assert rep is not None and rep.what == "running clearance"
    assert set(rep.overrides) == {"frame", "lower"} and len(rep.notes) == 1
    assert rep.overrides["lower"] and all((tmp_path / p.filename).is_file() for p in rep.overrides["lower"])
    # a pair that does not touch along a sliding contact: no candidate
    assert repair.clearance_repair(model, urdf, {}, state, earlier, 1.0, tmp_path, "collision") is None


def test_a_repair_is_checked_at_the_dynamics_the_escalation_kept_and_the_limits_clipped_again():
    """The repaired candidate's post-check starts from the damping and friction the first escalation kept (not from
    the estimate, which would replay the same rounds), with the limits clipped to the repaired pieces."""
    link = LinkPhysics(mass=1.0, inertia=Inertia(ixx=0.01, iyy=0.01, izz=0.01), com=(0.0, 0.0, 0.0))
    clipped = Overlay(scale=1.0, estimator=EstimatorInfo(name="offline"), links={"lid": link}, joints={
        "hinge": JointDynamics(damping=0.01, friction=0.02, lower=0.0, upper=1.2, source="estimate"),
        "slide": JointDynamics(damping=1.0, friction=2.0, lower=0.0, upper=0.3, source="estimate")})
    kept = clipped.model_copy(update={"joints": {
        "hinge": JointDynamics(damping=0.38, friction=1.77, lower=0.0, upper=1.5, source="estimate; escalated x3")}})
    start = kept_dynamics(clipped, kept)
    hinge = start.joints["hinge"]
    assert (hinge.damping, hinge.friction, hinge.source) == (0.38, 1.77, "estimate; escalated x3")
    assert (hinge.lower, hinge.upper) == (0.0, 1.2)  # the repaired pieces' clip, not the kept one's
    assert start.joints["slide"] == clipped.joints["slide"]  # a joint the kept overlay lacks stays as clipped
