"""Post-check and escalation (refine stage 7).

The written asset is loaded under the SPEC's conventions and its penetration,
rest stability and oscillation are measured (``tasks.metrics``); in addition
each joint's *sag* — the largest departure from its initial position during
settling and the test — is compared with ``RefineConfig.sag_tolerance_*``. A
joint that oscillates or sags gets its damping and friction multiplied by
``RefineConfig.escalation_factor`` (bounded: at most ``max_escalation_rounds``
rounds); every round is recorded.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from asset2sim.engines.base import SessionOptions, Spring, open_session
from asset2sim.schemas.config import RefineConfig
from asset2sim.schemas.overlay import Overlay
from asset2sim.schemas.metrics import unit
from asset2sim.schemas.report import MetricResult
from asset2sim.tasks.check import metrics


@dataclass
class PostCheck:
    """Result of one post-check (metrics, the trace and per-joint sag)."""

    metrics: list[MetricResult]
    trace: metrics.RestTrace
    sag: dict[str, float]
    """joint -> largest |q - q_initial| (rad or m)"""
    sagging: list[str] = field(default_factory=list)
    engine_results: dict[str, list[MetricResult]] = field(default_factory=dict)
    """Other engines (``--engines``): engine -> [penetration, rest_stability, oscillation]."""

    def engine_failures(self) -> tuple[bool, list[str]]:
        """(any other engine unstable, joints oscillating in another engine);
        skipped engines are ignored."""
        unstable, joints = False, []
        for res in self.engine_results.values():
            for m in res:
                if m.name == "rest_stability" and m.passed is False:
                    unstable = True
                if m.name == "oscillation" and m.passed is False:
                    joints.extend(m.details.get("failing", []))
        return unstable, list(dict.fromkeys(joints))

    def metric(self, name: str) -> MetricResult:
        return next(m for m in self.metrics if m.name == name)

    @property
    def stable(self) -> bool:
        """SPEC rest stability (in every engine) and no toppling while settling."""
        return bool(self.metric("rest_stability").passed and self.metric("settle_tilt").passed and not self.engine_failures()[0])

    @property
    def passed(self) -> bool:
        return bool(self.stable and self.metric("oscillation").passed and not self.sagging and not self.engine_failures()[1])


def springs_of(overlay: Overlay) -> dict[str, Spring]:
    """Springs (stiffness > 0) of an overlay as engine options."""
    return {
        n: Spring(stiffness=d.stiffness, reference=float(d.spring_reference or 0.0))
        for n, d in overlay.joints.items()
        if d.stiffness > 0
    }


def run_post_check(
    urdf_path: Path,
    initial_state: dict[str, float],
    overlay: Overlay,
    config: RefineConfig,
    engine: str = "pybullet",
) -> PostCheck:
    """Measure penetration, rest stability, oscillation and sag of the written
    asset in ``engine`` (SPEC conventions), and the SPEC metrics in every other
    engine of ``config.engines`` (``tasks.parity``; missing engines skipped)."""
    conv = config.sim
    session = open_session(
        engine,
        urdf_path,
        SessionOptions(initial_state=initial_state, springs=springs_of(overlay), conventions=conv),
    )
    try:
        pen = metrics.penetration(session)
        trace = metrics.run_rest_test(session, conv)
    finally:
        session.close()
    stab = metrics.rest_stability(trace, conv, engine=engine)
    osc = metrics.oscillation(trace, conv, engine=engine)
    drift = metrics.joint_drift(trace)
    sagging = []
    for name, d in drift.items():
        tol = config.sag_tolerance_prismatic if trace.joint_types.get(name) == "prismatic" else config.sag_tolerance_revolute
        if d > tol:
            sagging.append(name)
    sag_metric = MetricResult(
        name="state_hold",
        value=max(drift.values()) if drift else 0.0,
        unit=unit("state_hold"),
        passed=not sagging,
        threshold=f"every joint within {config.sag_tolerance_revolute} rad / {config.sag_tolerance_prismatic} m of its initial state",
        details={"drift": drift, "sagging": sagging},
        engine=engine,
    )
    tilt = metrics.settle_tilt(trace, engine=engine)
    others = [e for e in dict.fromkeys(config.engines) if e != engine]
    engine_results = {}
    if others:
        from asset2sim.tasks.check import parity

        engine_results = parity.evaluate_engines(Path(urdf_path).parent, others, initial_state=initial_state, conventions=conv)
    return PostCheck(metrics=[pen, stab, osc, sag_metric, tilt], trace=trace, sag=drift, sagging=sagging, engine_results=engine_results)


def escalate(overlay: Overlay, check: PostCheck, factor: float) -> tuple[Overlay, dict[str, dict[str, float]], str]:
    """Raise damping and friction of the joints that oscillate or sag (all
    joints when the root is unstable and no joint is singled out).

    Returns (new overlay, changes joint -> {parameter: new value}, reason).
    """
    other_unstable, other_osc = check.engine_failures()
    osc = list(dict.fromkeys(list(check.metric("oscillation").details.get("failing", [])) + other_osc))
    targets = list(dict.fromkeys(list(osc) + list(check.sagging)))
    reason = []
    if osc:
        reason.append(f"oscillating: {', '.join(osc)}")
    if check.sagging:
        reason.append(f"sagging: {', '.join(check.sagging)}")
    if not targets and not check.stable:
        targets = list(overlay.joints)
        reason.append("root unstable: damping all joints")
    ov = overlay.model_copy(deep=True)
    changes: dict[str, dict[str, float]] = {}
    for name in targets:
        d = ov.joints.get(name)
        if d is None:
            continue
        damping = max(d.damping * factor, 1e-4)
        if d.inertia_axis:
            from asset2sim.tasks.synthesize.physics import max_stable_damping

            damping = min(damping, max(max_stable_damping(d.inertia_axis), d.damping))
        new = d.model_copy(
            update={
                "damping": damping,
                "friction": max(d.friction * factor, 1e-3),
                "source": d.source + f"; escalated x{factor:g}",
            }
        )
        ov.joints[name] = new
        changes[name] = {"damping": new.damping, "friction": new.friction}
    return ov, changes, "; ".join(reason)
