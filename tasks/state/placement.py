"""Stages 5-6 of the refine on the written candidate: the synthesis as a value (:class:`Synthesis`), the closed
ends measured on the output and the requested state placed on them (:func:`closed_on_output`), the joint limits
clipped to the geometry (:func:`clip_limits`, :func:`clip_synthesis`), the collision pieces that let the object
shut (:func:`shut_repair`) and the state search (:func:`search_state`)."""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from asset2sim.engines.base import SimSession
from asset2sim.schemas.config import RefineConfig
from asset2sim.schemas.overlay import Overlay
from asset2sim.schemas.report import StateRefinement
from asset2sim.schemas.request import BAND_INTERVAL
from asset2sim.stage_log import StageLog
from asset2sim.tasks.assemble import (collision_geometry, container_pieces, footprint, parent_child_separation,
                                      sliding_clearance, write)
from asset2sim.tasks.assemble.candidate import Candidate, Workspace
from asset2sim.tasks.geometry import limits, urdf_closed
from asset2sim.tasks.geometry.closed_state import ClosedState, closed_tuples
from asset2sim.tasks.state import refine_state, state_search
from asset2sim.tasks.synthesize import estimate, request_apply
from asset2sim.tasks.synthesize.context import EstimationContext


@dataclass(frozen=True, slots=True)
class Retargeted:
    """The request's targets once the closed ends or ranges moved (:meth:`Synthesis.retargeted`): ``targets``
    (joint -> target), ``moved`` (those that changed) and ``bands`` (joint -> band, a moved joint taking its
    target's)."""

    targets: dict[str, request_apply.JointTarget]
    moved: dict[str, request_apply.JointTarget]
    bands: dict[str, str]


@dataclass
class Synthesis:
    """Stage 4's result: the validated overlay and the state it asks for."""

    overlay: Overlay
    issues: list
    bands: dict[str, str]
    prismatic: set[str]
    closed_out: dict[str, ClosedState]  # at the overlay's scale
    requested: dict[str, float]  # joint positions, output units
    targets: dict[str, request_apply.JointTarget] = field(default_factory=dict)  # numbers / ends the request asked
    #: joint -> the opening fractions (lo, hi; < 0 past its closed end) around where its weight left a part the request
    #: asks to move freely and gives no state (:func:`~asset2sim.tasks.tune.attempt.hanging_fractions`)
    rests: dict[str, tuple[float, float]] = field(default_factory=dict)

    def candidate(self, ctx: EstimationContext, overrides=None) -> Candidate:
        """The candidate of this synthesis: its overlay at the requested state, with the collision ``overrides``."""
        return Candidate(ctx.asset, self.overlay, self.requested, overrides or {}, ctx.root_rotation)

    def retargeted(self, closed: dict[str, ClosedState]) -> Retargeted:
        """The targets, those that changed and the bands once the closed ends or ranges moved to ``closed`` (output units): an
        angle or distance asked stays that opening from the closed end (:func:`request_apply.retarget`), and a
        retargeted joint takes its target's band."""
        targets = request_apply.retarget(self.targets, self.closed_out, closed)
        moved = {n: t for n, t in targets.items() if t is not self.targets[n]}
        return Retargeted(targets, moved, {**self.bands, **{n: t.band for n, t in moved.items()}})

    def fractions(self) -> dict[str, tuple[float, float]]:
        """joint -> the opening fractions its band allows, a number or end asked winning (:func:`estimate.band_intervals`)."""
        return estimate.band_intervals(self.bands, self.intervals())

    def intervals(self) -> dict[str, tuple[float, float]]:
        """joint -> the opening fractions a number or end asked, or a part's rest (:attr:`rests`), allows."""
        return {**{n: t.interval for n, t in self.targets.items() if t.interval is not None}, **self.rests}


def scaled_closed(closed: dict[str, ClosedState], scale: float, prismatic: set[str]) -> dict[str, ClosedState]:
    """Closed ends at ``scale`` (prismatic positions and ranges times ``scale``)."""
    return {n: replace(cs, q_closed=cs.q_closed * scale, open_range=cs.open_range * scale, lower=cs.lower * scale,
                       upper=cs.upper * scale) if n in prismatic else cs for n, cs in closed.items()}


def at_fractions(closed: dict[str, ClosedState], fractions: dict[str, float]) -> dict[str, float]:
    """Joint -> position (rad or m) at each opening fraction (joints without a closed state left out)."""
    return {n: closed[n].position(f) for n, f in fractions.items() if n in closed}


def closed_on_output(ctx: EstimationContext, syn: Synthesis, ws: Workspace, log: StageLog, overrides: dict) -> Synthesis:
    """Stage 5a: the closed ends measured on the synthesis' candidate (with the collision ``overrides``;
    :mod:`asset2sim.tasks.geometry.urdf_closed`), the requested state and the overlay's initial positions
    moved onto them. Unchanged when the measurement fails."""
    try:
        measured = urdf_closed.measure_closed(ws.source(syn.candidate(ctx, overrides)), ctx.push_buttons)
    except Exception as exc:
        log.say("closed_state", f"closed ends not measured on the output ({type(exc).__name__}: {exc}); the input's are used")
        return syn
    new = {n: measured.get(n, c) for n, c in syn.closed_out.items()}
    moved = [n for n, c in new.items() if abs(c.q_closed - syn.closed_out[n].q_closed) > 1e-9 or c.direction != syn.closed_out[n].direction]
    if not moved:
        return replace(syn, closed_out=new)
    keep = {n for n, t in syn.targets.items() if t.kind in ("angle", "distance")}
    requested = urdf_closed.replace_positions(syn.requested, syn.closed_out, new, keep)
    overlay = syn.overlay
    if overlay.initial_joint_positions:
        overlay = overlay.model_copy(update={"initial_joint_positions": urdf_closed.replace_positions(
            overlay.initial_joint_positions, syn.closed_out, new, keep)})
    for n in moved:
        log.say("closed_state", f"joint {n}: closed end {new[n].q_closed:.4g} on the output's collision pieces "
                                f"({syn.closed_out[n].q_closed:.4g} before); the state is placed from it")
    # the spring of each closer (``holding.mechanism`` "closer": :func:`~asset2sim.tasks.synthesize.spring_holds.closer`)
    # among the joints moved shifted with its closed end (the same opening direction): its preload and centre were set
    # from the closed end the synthesis knew, so a closer set from a closed end 0.15 rad off the output's (a faucet's
    # lever) pressed or centred the part there, not where the output shuts
    joints = {}
    for n in moved:
        d, was = overlay.joints.get(n), syn.closed_out[n]
        if (d is None or d.holding is None or d.holding.mechanism != "closer" or d.spring_reference is None
                or new[n].direction != was.direction):
            continue
        shift = new[n].q_closed - was.q_closed
        joints[n] = d.model_copy(update={"spring_reference": float(d.spring_reference + shift)})
        log.say("closed_state", f"joint {n}: its closer's spring reference moved {shift:+.4g} with its closed end")
    if joints:
        overlay = overlay.model_copy(update={"joints": {**overlay.joints, **joints}})
    rt = syn.retargeted(new)  # the angle asked, from the new closed end
    return replace(syn, overlay=overlay, closed_out=new, requested=requested, targets=rt.targets, bands=rt.bands)


def clip_synthesis(ctx: EstimationContext, syn: Synthesis, config: RefineConfig, ws: Workspace, log: StageLog,
                    overrides: dict, fractions: dict[str, float] | None) -> Synthesis:
    """Stage 5b: the limits clipped to the geometry of the synthesis' candidate (with the collision
    ``overrides``) before the state search and the requested state recomputed from the bands over the
    clipped ranges (``fractions`` win over the bands' targets). ``syn`` itself when nothing was clipped."""
    overlay, closed_out = clip_limits(syn.candidate(ctx, overrides), syn.closed_out, ws, config, log)
    if overlay is syn.overlay:
        return syn
    s = overlay.scale
    rt = syn.retargeted(closed_out)  # an angle asked stays that angle from the closed end
    if rt.moved and overlay.initial_joint_positions:
        overlay = overlay.model_copy(update={"initial_joint_positions": {
            **overlay.initial_joint_positions, **{n: closed_out[n].position(t.fraction) for n, t in rt.moved.items()}}})
    unscaled = scaled_closed(closed_out, 1.0 / s, syn.prismatic)
    requested = estimate.state_from_bands(unscaled, rt.bands, s, syn.prismatic)
    requested.update(overlay.initial_joint_positions or {})
    requested.update(at_fractions(closed_out, fractions or {}))
    return replace(syn, overlay=overlay, closed_out=closed_out, requested=requested, targets=rt.targets, bands=rt.bands)


def shut_repair(ctx: EstimationContext, syn: Synthesis, config: RefineConfig, ws: Workspace,
                 log: StageLog) -> tuple[dict, list[str]]:
    """Stage 5 (before 5a): collision pieces that let the object shut. When the request opens a joint and the
    closed configuration overlaps beyond the tolerance, the state search with its collision repair runs as for
    a closed request. Returns (collision overrides, notes for ``state.collision_changes``); ({}, []) when not run."""
    closed = {n: c.q_closed for n, c in syn.closed_out.items()}
    opened = [n for n, c in syn.closed_out.items()
              if abs(c.fraction(syn.requested.get(n, c.q_closed))) > BAND_INTERVAL["closed"][1]]
    if not (config.convex_decomposition and opened
            and state_search.phi_at(ws, syn.candidate(ctx), closed, config) > config.penetration_tolerance):
        return {}, []
    shut, kept = state_search.refine_state_with_decomposition(
        replace(syn.candidate(ctx), state=closed), syn.closed_out, {n: "closed" for n in syn.closed_out}, config, ws, log.say)
    overrides = kept.collision_overrides
    head = (f"closed configuration (the request opens {', '.join(opened)}): self-penetration {shut.phi_requested * 1000:.3g} -> "
            f"{shut.phi_result * 1000:.3g} mm" + ("" if overrides else "; collision pieces kept"))
    log.say("shut_repair", head)
    log.lap("shut_repair")
    return overrides, [head + (":" if shut.collision_changes else "")] + list(shut.collision_changes)


def search_state(ctx: EstimationContext, kin: SimSession, est, syn: Synthesis, base: Candidate, config: RefineConfig,
                 ws: Workspace, log: StageLog) -> tuple[StateRefinement, Candidate]:
    """Stage 6: state refinement of the synthesis' candidate ``base`` (with the estimator's joint proposer when
    it has one; ``kin``, the input's kinematics session, for the joints the request addresses). Returns (refinement, the candidate with the collision overrides kept: ``base`` when unchanged)."""
    proposer = est.joint_proposer(ctx) if hasattr(est, "joint_proposer") else None
    st, kept = state_search.refine_state_with_decomposition(
        base, syn.closed_out, syn.bands, config, ws, log.say, proposer=proposer,
        intervals=syn.intervals(), addressed=lambda: request_apply.resolve_states(ctx, kin, syn.overlay.scale).addressed)
    log.say("refine_state", f"self-penetration {st.phi_requested * 1000:.3g} mm -> {st.phi_result * 1000:.3g} mm in {st.evaluations} evaluations ({st.method})")
    log.lap("refine_state")
    return st, kept


def clearance_notes(ctx: EstimationContext, overlay: Overlay, state: dict[str, float], overrides: dict, ws: Workspace) -> list[str]:
    """The writer's clearance notes for the output as written with ``overlay``, ``state`` and
    ``overrides`` (cached pieces: nothing recomputed, no file changes)."""
    notes: list[str] = []
    write.build_urdf(ctx.asset, overlay, overrides, ctx.root_rotation, (ws.root, state), notes, ws.open_containers)
    return clearance_lines(notes)


def clearance_lines(notes: list[str]) -> list[str]:
    """The writer's collision notes on running clearance, a levelled footprint, pieces thinner than their part,
    a child kept inside its parent past a stop and containers kept open."""
    return [n for n in notes if any(w in n for w in (sliding_clearance.RUNNING_CLEARANCE_NOTE, footprint.LEVEL_NOTE,
                                                     collision_geometry.DENSITY_NOTE, parent_child_separation.PAST_STOP_NOTE,
                                                     container_pieces.CAVITY_NOTE))]


@dataclass(frozen=True, slots=True)
class Reclipped:
    """The synthesis after the limits were clipped again (:func:`reclipped`): ``synthesis``, ``state`` (joint
    -> rad or m) and ``notes`` (one line per joint moved back into its band)."""

    synthesis: Synthesis
    state: dict[str, float]
    notes: list[str]


def ends_over_raw_limits(raw: dict[str, ClosedState], measured: dict[str, ClosedState]) -> dict[str, ClosedState]:
    """``raw`` (joint -> the closed end over the raw limits, which the limits are clipped from again when a repair
    changes the collision pieces: :func:`clip_limits`) with the closed end and opening direction of ``measured``
    (:func:`closed_on_output` on the pieces of the clipped limits, which the state was placed from): a later clip
    keeps the closed end the state and the report read, not the one measured before the clip. The opening range is
    the raw range's from that end (rad or m); a joint without finite raw limits keeps its own."""
    out = dict(raw)
    for n, m in measured.items():
        r = raw.get(n)
        if r is None or (m.q_closed == r.q_closed and m.direction == r.direction):
            continue
        far = r.upper if m.direction > 0 else r.lower
        span = abs(far - m.q_closed) if np.isfinite(far) else r.open_range
        out[n] = replace(r, q_closed=m.q_closed, direction=m.direction, open_range=span)
    return out


def reclipped(syn: Synthesis, overlay: Overlay, closed_after: dict[str, ClosedState],
              state: dict[str, float]) -> Reclipped:
    """The synthesis and ``state`` (joint -> rad or m) after the limits were clipped again (the collision pieces
    changed after the state search: :func:`clip_limits` on the new pieces gave ``overlay`` and the closed ends
    ``closed_after``). Angles and distances asked stay the same opening from the closed end (retargeted as in
    :func:`clip_synthesis`); a joint that its band (the request's number or end first) held on ``syn.closed_out``
    but that the new range puts outside it is moved to the nearest position the band allows on ``closed_after`` (an
    opening fraction is of the range the output has); every other joint keeps its position (one a stage moved out of
    its band on purpose, e.g. onto the floor, stays there)."""
    rt = syn.retargeted(closed_after)
    bands = rt.bands
    new = replace(syn, overlay=overlay, closed_out=closed_after, targets=rt.targets, bands=bands)
    before = refine_state.allowed_intervals(syn.closed_out, syn.fractions())
    after = refine_state.allowed_intervals(closed_after, new.fractions())
    out, notes = dict(state), []
    for n, q in state.items():
        if n not in before or n not in after or not before[n].lo - 1e-9 <= q <= before[n].hi + 1e-9:
            continue
        kept = after[n].clip(q)
        if abs(kept - q) > 1e-9:
            out[n] = kept
            notes.append(f"joint {n}: {q:.4g} -> {kept:.4g} ({closed_after[n].fraction(q):.3f} -> {closed_after[n].fraction(kept):.3f} "
                         f"of its range): the limits clipped again on the changed collision pieces moved its range; kept "
                         f"inside its band ({bands.get(n, 'closed')})")
    return Reclipped(new, out, notes)


def clip_limits(candidate: Candidate, closed_out: dict[str, ClosedState], ws: Workspace, config: RefineConfig,
                 log: StageLog) -> tuple[Overlay, dict[str, ClosedState]]:
    """Stage 6b: the joint limits of ``candidate``'s overlay clipped to what its geometry allows at its state
    (:mod:`asset2sim.tasks.geometry.limits`; with a carrying chain, also against the chain opened).
    Returns (overlay, closed ends)."""
    overlay, state = candidate.overlay, dict(candidate.state)
    with state_search.kinematic_session(ws, candidate, config, state) as sess:
        clips = limits.geometric_limits(sess, ws.model(candidate), closed_tuples(closed_out), state)
    if any(c.clipped for c in clips.values()):
        overlay, notes = limits.apply_clips(overlay, clips)
        for line in notes:
            log.say("limits", line)
        # the clipped joints' limits and opening range
        closed_out = {**closed_out, **{n: replace(closed_out[n], q_closed=c.q_closed, lower=c.lower, upper=c.upper,
                                                  open_range=c.open_range)
                                       for n, c in clips.items() if n in closed_out and c.clipped}}
    log.lap("limits")
    return overlay, closed_out
