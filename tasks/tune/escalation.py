"""Stage 7 of the refine, the tuning loop over the post-check: the post-check and its escalation
of damping and friction within the hand's range (:func:`post_check`; the step itself,
:func:`escalate`, and the friction factor robust rest asks, :func:`hold_factor`) and the
collision repairs the post-check calls for (:func:`repair_sweep`)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, replace

from asset2sim.schemas.config import RefineConfig
from asset2sim.schemas.overlay import Overlay
from asset2sim.schemas.report import EscalationRound, MetricResult, StateRefinement
from asset2sim.stage_log import StageLog
from asset2sim.tasks.assemble import write
from asset2sim.tasks.assemble.candidate import Candidate, Workspace
from asset2sim.tasks.check import postcheck, robust_rest, sweep_stalls, task_tier
from asset2sim.tasks.geometry import limits
from asset2sim.tasks.geometry.closed_state import ClosedState, closed_tuples
from asset2sim.tasks.state import clearance, placement
from asset2sim.tasks.synthesize import joint_dynamics, request_apply
from asset2sim.tasks.synthesize.context import EstimationContext
from asset2sim.tasks.synthesize.physics import max_stable_damping
from asset2sim.tasks.tune import dynamics_search, operating, repair, word_guard


@dataclass(frozen=True, slots=True)
class Tuned:
    """What the tuning loop hands on: ``overlay`` (the friction and damping it kept), ``check`` (the last
    post-check), ``rounds`` (its rounds in order); after :func:`repair_sweep`, also the collision pieces
    (``overrides``, link -> piece files) and the closed ends at the output scale (``closed``, joint ->
    :class:`ClosedState`) they were checked with (None from :func:`post_check`, which changes neither)."""

    overlay: Overlay
    check: postcheck.PostCheck
    rounds: list[EscalationRound]
    overrides: Mapping[str, tuple] | None = None
    closed: dict[str, ClosedState] | None = None


def post_check(ctx: EstimationContext, candidate: Candidate, config: RefineConfig, ws: Workspace, log: StageLog,
               closed: dict[str, tuple[float, float, float]]) -> Tuned:
    """Stage 7: post-check ``candidate`` at its refined state (``closed``: closed ends at the output scale, for the
    sweep and robust rest) and escalate damping and friction up to ``config.max_escalation_rounds`` times while
    it fails. Returns the final overlay, the last check and the rounds (no overrides or closed ends)."""
    asset, overlay, state = candidate.asset, candidate.overlay, dict(candidate.state)
    if overlay.initial_joint_positions is not None:
        overlay = overlay.model_copy(update={"initial_joint_positions": state})
    recorded = postcheck.RecordedRuns()  # the manipulation tiers' runs, reused by a round with the same inputs
    n = 0
    spec = task_tier.task_spec_for(ctx.task, asset, ctx.category, request_apply.task_relevant_joints(ctx), state, closed) \
        if ctx.task and closed else None

    def written(overlay: Overlay):
        """The candidate with ``overlay``, loaded from the workspace (a SimObject)."""
        return postcheck.overlay_object(ws.source(replace(candidate, overlay=overlay)), state, overlay, config.sim)

    # what the task's gripper can still operate on the task's joints (operating.operating_limits); estimates above it are lowered
    lim = operating.operating_limits(written(overlay), overlay, asset, ctx.geometry, closed, category=ctx.category, task=ctx.task,
                                     free_moving=ctx.request.free_moving, joints=getattr(spec, "joints", None))
    overlay, notes = operating.bound_overlay(overlay, lim.budgets)
    for line in notes:
        log.say("post_check", line)
    kept_words = word_guard.guards(ctx, overlay)  # the request's words about motion, at the values they set
    caps, dcaps = dict(lim.friction_caps), lim.damping_caps
    for name in overlay.joints:  # a drawer's friction never past its slide's range
        top = joint_dynamics.slide_cap(ctx, name, sum(overlay.links[ln].mass for ln in ctx.subtrees.get(name, []) if ln in overlay.links))
        if top is not None:
            caps[name] = min(caps.get(name, top), top)
    floors = operating.tilt_floors(overlay, asset, robust_rest.RobustRestConfig().tilt)

    def escalated(chk: postcheck.PostCheck) -> bool:  # this loop escalates ``chk`` (the post-check then skips the sweep)
        return n < config.max_escalation_rounds and bool(escalate(overlay, chk, config.escalation_factor, caps, floors, dcaps).changes)

    def checked(overlay: Overlay, escalated=None) -> postcheck.PostCheck:  # every tier, the task's included
        return postcheck.check_object(ctx, written(overlay), config, closed, spec, escalated=escalated, recorded=recorded)

    check = checked(overlay, escalated)
    rounds = [EscalationRound(round=0, metrics=check.metrics, reason="initial post-check")]
    search = dynamics_search.DynamicsSearch(lim.budgets, lim.hand_caps, floors)  # relief and escalation bracketed by what each round measured
    search.record(overlay, check.metrics)
    tried = [overlay]
    while (not check.passed or task_tier.task_failing(check.metrics)) and n < config.max_escalation_rounds:
        n += 1
        before = overlay
        # a task that needed more than a real operating force first: lower friction / damping (and their caps)
        step = dynamics_search.relieve(overlay, check.metrics, lim)
        if not step.changes:
            step = escalate(overlay, check, config.escalation_factor, caps, floors, dcaps)
        settled = search.settle(before, step.overlay, step.changes, caps)
        reason = "; ".join(filter(None, [step.reason, *settled.notes]))
        overlay, held = word_guard.keep(before, settled.overlay, kept_words)
        # joint -> {parameter: new value} of the damping, friction and stiffness the round changed
        changes: dict[str, dict[str, float]] = {}
        for name, d in overlay.joints.items():
            b = before.joints.get(name)
            diff = {k: float(getattr(d, k)) for k in ("damping", "friction", "stiffness")
                    if b is None or getattr(d, k) != getattr(b, k)}
            if diff:
                changes[name] = diff
        for line in held:
            log.say("post_check", line)
        if not changes:
            if held:
                rounds[-1] = rounds[-1].model_copy(update={"words_kept": [*rounds[-1].words_kept, *held]})
            break
        check = checked(overlay, escalated)
        rounds.append(EscalationRound(round=n, metrics=check.metrics, changes=changes, reason=reason, words_kept=held))
        search.record(overlay, check.metrics)
        tried.append(overlay)
    best = dynamics_search.fewest_failures([r.metrics for r in rounds])
    earlier = best != len(tried) - 1
    # an earlier round kept, or an escalation round's check (the sweep and the other engines not run): checked again,
    # the sweep included
    if earlier or postcheck.sweep_not_run(check.metrics):
        reason = (f"round {best} failed the fewest tiers: its friction and damping kept" if earlier
                  else "the last round's setting checked again with the joint sweep")
        if earlier:
            overlay = tried[best]
        check = checked(overlay)
        changes = {n_: {"damping": d.damping, "friction": d.friction} for n_, d in overlay.joints.items()}
        rounds.append(EscalationRound(round=rounds[-1].round + 1, metrics=check.metrics, changes=changes, reason=reason))
    log.lap("post_check")
    return Tuned(overlay, check, rounds)


#: Collision repairs of a part held by its neighbours' pieces, one after another while each is kept and the part is still
#: held: a repair that brings a part nearer its ends can leave it stalled where another pair meets (a retry of the sweep
#: with the joints between moved, which the first stall had not reached), and the next repair reads that stall.
SWEEP_REPAIRS = 2


def repair_sweep(ctx: EstimationContext, unclipped: Overlay, closed_raw: dict[str, ClosedState], result: Tuned, st: StateRefinement,
                  state: dict[str, float], config: RefineConfig, ws: Workspace, log: StageLog) -> Tuned:
    """Stage 7b: collision repairs where the post-check shows a part held by its neighbours' pieces: a
    blocked joint sweep (:func:`asset2sim.tasks.tune.repair.sweep_repairs`, better = a better sweep score)
    or parts held together (running clearance, better = fewer failing tiers). Each repair is loaded, the
    limits clipped again from ``unclipped`` and ``closed_raw``, and post-checked; the first that is better
    while no passed metric fails is kept, and the next one starts from it (at most :data:`SWEEP_REPAIRS`; the pieces
    of the n-th in a folder of their own, so that a repair not kept leaves the kept pieces as written). ``result``:
    the post-check's, with its collision overrides and closed ends, returned unchanged or replaced; notes go to
    ``st.collision_changes``."""
    for n in range(SWEEP_REPAIRS):
        before, result = result, _repair_once(ctx, unclipped, closed_raw, result, st, state, config, ws, log, n)
        if result is before:
            break
    return result


def _repair_once(ctx: EstimationContext, unclipped: Overlay, closed_raw: dict[str, ClosedState], result: Tuned,
                 st: StateRefinement, state: dict[str, float], config: RefineConfig, ws: Workspace, log: StageLog,
                 n: int) -> Tuned:
    """One repair of :func:`repair_sweep` (the ``n``-th, from 0): ``result`` itself when none is kept."""
    overlay, check, rounds, overrides = result.overlay, result.check, result.rounds, result.overrides
    sw = next((m for m in check.metrics if m.name == "joint_sweep"), None)
    blocked = {} if sw is None or sw.passed is not False else sweep_stalls.blocked_positions(sw)
    pairs = [] if blocked else repair.held_together_pairs(check.metrics)
    if not blocked and not pairs:
        return result  # the common case: nothing read, nothing simulated
    current = ws.source(Candidate(ctx.asset, overlay, state, overrides, ctx.root_rotation))
    model = current.model()
    folder = write.collision_folder(ctx.asset) + (f"/repair_{n + 1}" if n else "")
    if blocked:
        label = "sweep blocked"
        repairs = repair.sweep_repairs(postcheck.overlay_object(current, state, overlay, config.sim), ctx.asset, sw,
                                       blocked, overrides, unclipped.scale, ws.root, folder, config)

        def score(chk):  # sweep_stalls.sweep_score: lower is better
            return sweep_stalls.sweep_score(chk.metric("joint_sweep"))
    else:
        label = "parts held together"
        touching = clearance.touching_joints(model, pairs, state, limits.subtrees(model))
        one = repair.clearance_repair(model, current.path, touching, state, overrides, unclipped.scale, ws.root, folder) if touching else None
        repairs = [one] if one is not None else []

        def score(chk):  # failing tiers: fewer is better
            return dynamics_search.failing_tiers(chk.metrics)
    passed_before = {(m.name, m.engine) for m in check.metrics if m.passed}
    # the repaired pieces are checked at the dynamics the escalation kept, with the rounds it left (a work-counted
    # budget: the repair's check does not replay the escalation from the estimate)
    left = config.model_copy(update={"max_escalation_rounds": max(0, config.max_escalation_rounds - (len(rounds) - 1))})
    for rep in repairs:
        repaired = Candidate(ctx.asset, unclipped, state, rep.overrides, ctx.root_rotation)
        clipped, closed2 = placement.clip_limits(repaired, closed_raw, ws, config, log)
        tuned = post_check(ctx, replace(repaired, overlay=kept_dynamics(clipped, overlay)), left, ws, log,
                           closed=closed_tuples(closed2))
        check2 = tuned.check
        lost = [m.name for m in check2.metrics if (m.name, m.engine) in passed_before and m.passed is False]
        if score(check2) < score(check) and not lost:
            for line in rep.notes:
                log.say("sweep_repair", line)
            st.collision_changes = list(st.collision_changes) + rep.notes
            rounds = rounds + [r.model_copy(update={"round": len(rounds) + r.round,
                                                    "reason": f"{rep.what} ({label}): {r.reason}"}) for r in tuned.rounds]
            return Tuned(tuned.overlay, check2, rounds, rep.overrides, closed2)
        log.say("sweep_repair", f"{rep.what} not kept ({label}; failing metrics {dynamics_search.failing_tiers(check.metrics)} -> "
                                f"{dynamics_search.failing_tiers(check2.metrics)}{'; would fail ' + ', '.join(lost) if lost else ''}); "
                                "the asset kept as it was")
    return result


def kept_dynamics(clipped: Overlay, kept: Overlay) -> Overlay:
    """``clipped`` (limits clipped to the repaired pieces) with the damping, friction and their notes of ``kept`` (the
    dynamics the post-check's escalation kept) on every joint both hold; the limits stay ``clipped``'s."""
    joints = {name: dyn.model_copy(update={k: getattr(kept.joints[name], k) for k in ("damping", "friction", "source")})
              if name in kept.joints else dyn for name, dyn in clipped.joints.items()}
    return clipped.model_copy(update={"joints": joints})


def escalate(overlay: Overlay, check: postcheck.PostCheck, factor: float, friction_caps: dict[str, float],
             tilt_floors: dict[str, float], damping_caps: dict[str, float]) -> dynamics_search.Retuning:
    """Raise damping and friction of the joints that oscillate, sag or are not
    held by robust rest (all joints when the root is unstable and no joint is
    singled out). ``friction_caps`` (joint -> N*m or N) bound the friction,
    ``tilt_floors`` (N*m or N) raise that of a joint robust rest does not hold,
    ``damping_caps`` (N m s/rad or N s/m) bound the damping (never below the values before).

    Returns the new overlay, its changes (joint -> {parameter: new value}) and the reason.
    """
    osc = list(dict.fromkeys([*check.metric("oscillation").details.get("failing", []), *check.engine_failures()[1]]))
    not_held = joints_not_held(check.metrics)
    targets = list(dict.fromkeys([*osc, *check.sagging, *not_held]))
    reason = [f"{why}: {', '.join(joints)}" for why, joints in
              (("oscillating", osc), ("sagging", check.sagging), ("not held under robust rest", not_held)) if joints]
    if not targets and not check.stable:
        targets = list(overlay.joints)
        reason.append("root unstable: damping all joints")
    ov = overlay.model_copy(deep=True)
    changes: dict[str, dict[str, float]] = {}
    for name in targets:
        d = ov.joints.get(name)
        if d is None:
            continue
        f = factor
        if name in not_held and name not in osc and name not in check.sagging:  # only robust rest: as far as needed
            f = hold_factor(check.metrics, name, factor * factor)
        damping = max(d.damping * f, 1e-4)
        friction = max(d.friction * f, 1e-3)
        note = f"; escalated x{f:.3g}"
        floor = tilt_floors.get(name) if name in not_held else None
        if floor is not None and floor > friction:
            friction = floor
            note += f" (friction raised to {floor:.3g} for robust rest's tilts)"
        cap = friction_caps.get(name)
        if cap is not None and friction > cap:
            friction = max(cap, d.friction)
            note += f" (friction capped at {friction:.3g}: what a real operating force moves and its mechanism allows)"
        if d.inertia_axis:
            damping = min(damping, max(max_stable_damping(d.inertia_axis), d.damping))
        dcap = damping_caps.get(name)
        if dcap is not None and damping > dcap:
            damping = max(dcap, d.damping)
        if friction == d.friction and damping == d.damping:
            continue
        ov.joints[name] = d.model_copy(update={"damping": damping, "friction": friction, "source": d.source + note})
        changes[name] = {"damping": damping, "friction": friction}
    return dynamics_search.Retuning(ov, changes, "; ".join(reason))


def joints_not_held(metrics: list[MetricResult]) -> list[str]:
    """Joints that left their state in any robust-rest trial of ``metrics`` and,
    when one did, those whose drift exceeded :data:`HOLD_TARGET_SHARE` of their
    tolerance in some trial (coupled parts' drift varies between rounds), first-seen order."""
    failing_: list[str] = []
    near: list[str] = []
    for m in metrics:
        if m.name != "robust_rest":
            continue
        for trial in (m.details.get("trials") or {}).values():
            failing_.extend(trial.get("failing_joints") or [])
            for j, d in (trial.get("joint_drift") or {}).items():
                tol = (trial.get("joint_tolerance") or {}).get(j)
                if d is not None and tol and float(d) > HOLD_TARGET_SHARE * float(tol):
                    near.append(j)
    return list(dict.fromkeys(failing_ + near)) if failing_ else []


#: Share of a joint's tolerance that escalation aims its drift at (:func:`hold_factor`).
HOLD_TARGET_SHARE = 0.5
#: Exponents of :func:`hold_factor`: an impact's travel (drop, nudge) falls about
#: as 1 / friction^2, a slope load (tilt) needs friction about proportional to it.
HOLD_EXPONENT_IMPACT = 0.5
HOLD_EXPONENT_SLOPE = 1.0
#: Smallest friction step of :func:`hold_factor`.
HOLD_MIN_STEP = 1.2


def hold_factor(metrics: list[MetricResult], joint: str, largest: float) -> float:
    """Factor on the friction (and damping) of ``joint`` that should make it hold
    through robust rest: the largest over the trials of (drift /
    (HOLD_TARGET_SHARE tolerance)) ** e (e HOLD_EXPONENT_IMPACT for the drop
    and the nudge, HOLD_EXPONENT_SLOPE for the tilts), between HOLD_MIN_STEP and ``largest``."""
    best = HOLD_MIN_STEP
    for m in metrics:
        if m.name != "robust_rest":
            continue
        for name, trial in (m.details.get("trials") or {}).items():
            d = (trial.get("joint_drift") or {}).get(joint)
            tol = (trial.get("joint_tolerance") or {}).get(joint)
            if d is None or not tol or d <= HOLD_TARGET_SHARE * tol:
                continue
            e = HOLD_EXPONENT_SLOPE if name.startswith("tilt") else HOLD_EXPONENT_IMPACT
            best = max(best, (float(d) / (HOLD_TARGET_SHARE * float(tol))) ** e)
    return float(min(largest, best))
