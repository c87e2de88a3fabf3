"""``report.json``'s model of a refine (:func:`build_report`) from its final attempt, and the report's lines
on the input, the root's mounting and the engines side by side."""

from __future__ import annotations

import math

from asset2sim import __version__
from asset2sim.schemas.report import RefineReport
from asset2sim.tasks.check import as_asked, parity
from asset2sim.tasks.tune.attempt import Attempt
from asset2sim.tasks.check.verdict import penetration_measures, readiness
from asset2sim.tasks.interpret.request import request_notes
from asset2sim.tasks.geometry.closed_state import ClosedState
from asset2sim.tasks.synthesize.context import EstimationContext
from asset2sim.schemas.overlay import Overlay


def post_check_line(att: Attempt) -> str:
    """The terminal's line on the final post-check: penetration, rest stability (D_pos m, D_ori rad),
    oscillation and the escalation rounds."""
    stab, osc = (att.check.metric(n) for n in ("rest_stability", "oscillation"))
    return (f"penetration {'; '.join(penetration_measures(att.check.metrics)) or 'n/a'}; rest stability {'PASS' if stab.passed else 'FAIL'} (D_pos {stab.details.get('D_pos_m', float('nan')):.2e} m, D_ori {stab.details.get('D_ori_rad', float('nan')):.2e} rad); oscillation {'PASS' if osc.passed else 'FAIL'}; escalation rounds {len(att.rounds) - 1}")


def staging_notes(asset) -> list[str]:
    """The report's lines on an MJCF or USD input read and staged as a URDF, and on part labels read from link
    names (none for a PartNet-Mobility input)."""
    head = [] if asset.staged_from is None else [f"input: {asset.staged_from} read into the asset model and staged as a URDF"]
    return head + [f"input: {n}" for n in asset.staging_notes]


def build_report(ctx: EstimationContext, prompt: str, chash: str, att: Attempt, findings: list, pose_note: str, times: dict[str, float],
                 asked: as_asked.AsAsked) -> RefineReport:
    """``report.json``'s model from the final attempt and its as-asked tier (``asked``: :func:`as_asked.as_asked_tier`
    of the attempt's metrics): the verdict decided here, once, from every measurement it records."""
    asset, overlay, st, state, closed_out = ctx.asset, att.overlay, att.st, att.state, att.closed_out
    est = overlay.estimator
    metrics = asked.metrics
    verdict = readiness(metrics)
    return RefineReport(
        asset_id=asset.asset_id,
        source=str(asset.staged_from or asset.source_dir),
        prompt=prompt,
        category=ctx.category,
        task=ctx.task,
        version=__version__,
        input_hash=asset.input_hash,
        config_hash=chash,
        estimator=est.name,
        model=est.model,
        model_queries=est.queries + st.model_queries,
        model_tokens=est.tokens,
        model_cost_usd=est.cost_usd,
        model_seconds=est.seconds,
        scale=overlay.scale,
        total_mass=overlay.total_mass(),
        initial_joint_positions=state,
        closed_positions={n_: c.q_closed for n_, c in closed_out.items()},
        closed_ends={n_: closed_record(c) for n_, c in closed_out.items()},
        requested_bands=att.bands,
        opening_fractions={n_: abs(c.fraction(state[n_])) for n_, c in closed_out.items() if n_ in state},
        state=st,
        metrics=metrics,
        parity=parity_rows(att.check),
        escalation=att.rounds,
        validation=[f.to_issue().model_dump() for f in findings] + [i.model_dump() for i in att.issues],
        failure_mode=verdict.failure_mode,
        readiness=verdict.tiers,
        stage_seconds=times,
        notes=staging_notes(asset) + request_notes(ctx.request) + list(overlay.notes.other)
        + ([f"resting pose ({ctx.request.pose_hint or 'as it is put down'}): {pose_note}"] if pose_note else [])
        + [mounting_note(overlay)] + att.design,
        mounting=overlay.mounting,
        design_changes=att.design,
        request=asked.findings,
    )


def mounting_note(overlay: Overlay) -> str:
    """The report's line on how the root was held in every check."""
    m = overlay.mounting
    if m is None or not m.fixed:
        return "root: free-standing, free on the ground in every check (the measurement convention for objects that stand)" + (f"; {m.source}" if m else "")
    return f"root: mounted ({m.kind}), fixed in every check (rest, oscillation, probes, evaluation), no ground plane; {m.source}"


def parity_rows(check) -> list[dict]:
    """Side-by-side engine rows for the report (PyBullet first)."""
    if not check.engine_results:
        return []
    base = [m for m in check.metrics if m.name in parity.METRICS]
    rows = parity.parity_table({"pybullet": base, **check.engine_results})
    rows[0].update(check.reference_holding)  # PyBullet's joints held and breakaway
    return rows


def closed_record(c: ClosedState) -> dict[str, float]:
    """A joint's closed end as ``report.json`` records it (``closed_ends``; rad or m, output units): ``q_closed``,
    ``direction`` (+1 / -1), ``open_range`` and the ``lower`` / ``upper`` limits it was found in (None: unbounded)."""
    return {"q_closed": float(c.q_closed), "direction": float(c.direction), "open_range": float(c.open_range),
            "lower": float(c.lower) if math.isfinite(c.lower) else None, "upper": float(c.upper) if math.isfinite(c.upper) else None}
