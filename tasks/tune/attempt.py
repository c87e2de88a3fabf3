"""One attempt of the refine: synthesize -> validate -> write -> refine the state -> post-check, as a value
the report and the extras read (:class:`Attempt`)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np

from asset2sim.schemas.asset import AssetDescription
from asset2sim.schemas.overlay import Overlay
from asset2sim.schemas.report import EscalationRound, StateRefinement
from asset2sim.schemas.request import BAND_INTERVAL
from asset2sim.inert import one_line
from asset2sim.stage_log import StageLog
from asset2sim.tasks.assemble.candidate import Candidate, Workspace
from asset2sim.tasks.state import balance, pose
from asset2sim.tasks.interpret.categories import category_prior
from asset2sim.tasks.synthesize import estimate, joint_dynamics, request_apply
from asset2sim.tasks.synthesize.context import EstimationContext
from asset2sim.tasks.synthesize.opening_fractions import weight_moment
from asset2sim.tasks.check import as_asked, postcheck
from asset2sim.tasks.geometry.closed_state import ClosedState


@dataclass(frozen=True)
class Attempt:
    """One synthesize -> validate -> write -> refine state -> post-check pass (frozen: a later stage that adds
    to it hands on a copy, ``dataclasses.replace``)."""

    asset: AssetDescription
    overlay: Overlay
    issues: list
    bands: dict[str, str]
    prismatic: set[str]
    closed_out: dict[str, ClosedState]
    st: StateRefinement
    state: dict[str, float]
    overrides: dict
    root_rotation: object
    check: postcheck.PostCheck
    rounds: list[EscalationRound]
    design: list[str] = field(default_factory=list)  # what stability by design changed and why
    targets: dict = field(default_factory=dict)  # joint -> request_apply.JointTarget

    @property
    def candidate(self) -> Candidate:
        return Candidate(self.asset, self.overlay, self.state, self.overrides, self.root_rotation)

    @property
    def off_band(self) -> list[str]:
        """Joints a band set (:attr:`bands`) whose opening fraction at :attr:`state` lies outside that band, by more
        than the request tier's slack (:func:`~asset2sim.tasks.check.as_asked.band_missed`)."""
        return [n for n, b in self.bands.items() if b in BAND_INTERVAL and n in self.closed_out and n in self.state
                and as_asked.band_missed(n, n, b, abs(self.closed_out[n].fraction(self.state[n]))) is not None]

    @property
    def intervals(self) -> dict[str, tuple[float, float]]:
        """Joint -> the opening-fraction interval it may take: its band's, or the one of a number or end the request
        asked (:func:`~asset2sim.tasks.synthesize.estimate.band_intervals`)."""
        return estimate.band_intervals(self.bands, {n: t.interval for n, t in self.targets.items() if t.interval is not None})

    @property
    def settles(self) -> bool:
        """Whether it passes every check, no disturbance topples it and every band is met."""
        return self.check.passed and not self.check.topples and not self.off_band


def least_openings(att: Attempt, intervals: dict[str, tuple[float, float]]) -> dict[str, float]:
    """Joint -> the lower end of its opening-fraction interval, for the joints the attempt opened past
    that end (> 0) by more than 0.01 of the range."""
    return {name: float(lo) for name, (lo, hi) in intervals.items() if att.closed_out.get(name) is not None and name in att.state
            and 0 < lo < hi and att.closed_out[name].fraction(att.state[name]) > lo + 0.01}


def steadier_opening(ws: Workspace, att: Attempt, log: StageLog) -> tuple[dict[str, float], str] | None:
    """Stability by design through the opening after an unsteady attempt ``att``: the opened joints where,
    within their bands, the object stands steadiest (:func:`asset2sim.tasks.state.balance.steadiest_fractions`),
    or, when statically steady yet unstable or toppled in simulation, the least opening each band allows.
    Returns (joint -> opening fraction, the design note, logged), or None when the opening alone cannot make it
    steady or the measurement fails (noted). ``ws``: the workspace the attempt's candidate is loaded from; ``log``: the
    refine's stage log."""
    intervals = att.intervals
    try:
        steadiest = balance.steadiest_fractions(ws.source(att.candidate), att.overlay, att.state, att.closed_out, intervals)
    except Exception as exc:  # a measurement that fails leaves the attempt as it was
        log.say("stability", f"steadier opening not measured ({type(exc).__name__}: {one_line(exc)})")
        return None
    why = "unstable" if not att.check.stable else "toppled by a robust-rest disturbance"
    head = f"stability by design: {why} at the bands' targets"
    fractions = steadiest.fractions
    if fractions and steadiest.after.stable:
        note = (f"{head}; "
                + ", ".join(f"{n} opened to {f:.2f} of its range (allowed {intervals[n][0]:.2f}-{intervals[n][1]:.2f})" for n, f in fractions.items())
                + f", where the object stands steadiest: static margin {steadiest.before.margin * 1000:.3g} -> {steadiest.after.margin * 1000:.3g} mm"
                f" (asked >= {steadiest.after.required * 1000:.3g} mm)")
    elif steadiest.before.stable:  # statically steady, yet unstable or toppled in simulation
        fractions = least_openings(att, intervals)
        if not fractions:
            return None
        note = (f"{head} although statically steady (margin "
                f"{steadiest.before.margin * 1000:.3g} mm, asked >= {steadiest.before.required * 1000:.3g} mm); "
                + ", ".join(f"{n} opened to {f:.2f} of its range, the least its band allows ({intervals[n][0]:.2f}-{intervals[n][1]:.2f})"
                            for n, f in fractions.items()))
    else:  # the opening alone does not make it steady: the resting pose may
        return None
    log.say("stability", note)
    return fractions, note


def settled_attempt(att: Attempt, pose_note: str, redo: Callable[[np.ndarray], Attempt]) -> tuple[Attempt, str]:
    """For a resting pose the request named: when ``att`` failed rest by leaning out of it as it settled, at most
    :data:`~asset2sim.tasks.state.pose.SETTLE_LEAN_LIMIT`, the attempt ``redo`` (stages 4-7 on a root rotation (3, 3),
    world = R root) makes on the pose it came to rest in (:func:`~asset2sim.tasks.state.pose.settled_rotation`), kept
    when it rests there and passes at least as much; else ``att``. Returns (attempt, pose note)."""
    trace = att.check.trace
    settled = None if att.check.stable or trace.diverged or trace.initial_root_quat is None else \
        pose.settled_rotation(trace.initial_root_quat, trace.root_quat[-1])
    if settled is None:
        return att, pose_note
    rotation, angle = settled
    second = redo(rotation @ (np.eye(3) if att.root_rotation is None else np.asarray(att.root_rotation, float)))
    if not (second.check.stable and (second.check.passed or not att.check.passed)):
        return att, pose_note
    leaned = f"put down leaning {np.degrees(angle):.1f} deg, where it came to rest on its supports as it settled"
    return second, "; ".join(filter(None, (pose_note, leaned)))


def hanging_fractions(att: Attempt, free: set[str], addressed: set[str]) -> dict[str, float]:
    """Joint -> the opening fraction where its own weight left it in ``att``'s undisturbed rest test, for the parts
    the request asks to move freely (``free``) and gives no state (not in ``addressed``) that left their state there
    (``state_hold``) and came to rest (not ``moving``): a freely swinging handle hangs where it falls, as a person
    who sets the object down finds it. Empty when there is none, or the rest test diverged."""
    hold = next((m for m in att.check.metrics if m.name == "state_hold"), None)
    trace = att.check.trace
    if hold is None or hold.passed is not False or trace.diverged:
        return {}
    moving = set(hold.details.get("moving", ()))
    out = {}
    for n in hold.details.get("sagging", ()):
        cs, q = att.closed_out.get(n), trace.joints.get(n)
        f = cs.fraction(float(q[-1])) if cs is not None and q is not None and len(q) else None
        if n in free and n not in addressed and n not in moving and f is not None and abs(f) <= 1.01:
            out[n] = float(np.clip(f, -1.0, 1.0))  # < 0: fallen to the other side of a closed end inside its limits
    return out


def rested_attempt(ctx: EstimationContext, kin, att: Attempt, redo: Callable[[dict[str, float]], Attempt], log: StageLog) -> Attempt:
    """``att`` made once more by ``redo`` (stages 4-7 with joint -> opening fraction of the parts left where their
    weight took them) where the request asks a part to move freely, gives it no state, and the rest test found it
    leaving its state and coming to rest (:func:`hanging_fractions`); kept when those parts hold there and it passes
    at least as much, else ``att``. ``kin``: the input's kinematics session (what the request addressed)."""
    if not att.check.sagging:
        return att
    choices, _ = joint_dynamics.motion_choices(ctx, request_apply.task_relevant_joints(ctx))
    free = {n for n, c in choices.items() if c.free_moving and n in att.check.sagging}
    hung = hanging_fractions(att, free, request_apply.resolve_states(ctx, kin, att.overlay.scale).addressed) if free else {}
    if not hung:
        return att
    second = redo(hung)
    if set(hung) & set(second.check.sagging) or not (second.check.passed or not att.check.passed):
        log.say("post_check", "where the freely moving parts came to rest they do not hold: the closed state kept")
        return att
    return second


#: Openings sampled across a band for the one where the part's weight turns it least (:func:`balanced_openings`).
BALANCE_SAMPLES = 13
#: Tried there only where the weight's moment is at most this share of its moment at the attempt's state.
BALANCE_GAIN = 0.75


def balanced_openings(ctx: EstimationContext, kin, att: Attempt) -> dict[str, float]:
    """Joint -> the opening fraction, within its band, at which its hinged part's weight turns it least
    (:func:`~asset2sim.tasks.synthesize.opening_fractions.weight_moment` at :data:`BALANCE_SAMPLES` openings across the
    band of the written range), for the banded revolute joints ``att`` left unheld whose weight turns them there at
    most :data:`BALANCE_GAIN` of what it does at ``att``'s state: a suitcase's lid laid back past upright, asked open,
    set where it stands nearly balanced, as a person leaves one open. ``ctx`` carries the attempt's resting pose;
    ``kin``: the input's kinematics session (moved). Empty when there is none."""
    intervals = att.intervals
    closed = ctx.closed_state()
    out = {}
    unheld = as_asked.failing_joints(att.check.metrics)[0]  # robust rest's or the rest test's
    for n in sorted(set(unheld) & set(intervals)):
        cs = att.closed_out.get(n)
        if cs is None or n not in att.state or ctx.asset.joint(n).type != "revolute":
            continue
        now = abs(weight_moment(ctx, kin, n, {**closed, n: att.state[n]}))
        fractions = np.linspace(*intervals[n], BALANCE_SAMPLES)
        moments = [abs(weight_moment(ctx, kin, n, {**closed, n: cs.position(float(f))})) for f in fractions]
        i = int(np.argmin(moments))
        if moments[i] <= BALANCE_GAIN * now and abs(fractions[i] - abs(cs.fraction(att.state[n]))) > 0.01:
            out[n] = float(fractions[i])
    return out


def balanced_attempt(ctx: EstimationContext, kin, att: Attempt, redo: Callable[[dict[str, float]], Attempt],
                     log: StageLog) -> Attempt:
    """Stability by design through the opening where a part's weight turns it off its state: ``att`` made once more by
    ``redo`` (stages 4-7 with joint -> opening fraction) at :func:`balanced_openings`, with the design note, when
    ``att`` does not settle and that one does; else ``att``. ``ctx``: with the attempt's resting pose; ``kin``: the
    input's kinematics session."""
    balanced = {} if att.settles else balanced_openings(ctx, kin, att)
    if not balanced:
        return att
    opened = ", ".join(f"{n} opened to {f:.2f} of its range" for n, f in balanced.items())
    why = (f"stability by design: its weight turns {', '.join(balanced)} off the bands' targets; {opened}, where it turns it "
           "least within its band")
    log.say("stability", why)
    second = redo(balanced)
    if not second.settles:
        log.say("stability", "not every check passes there: the bands' targets kept")
        return att
    return replace(second, design=[why, *second.design])


def opened_lying(ctx: EstimationContext, kin, att: Attempt, moving_links: list[str], posed: Callable[..., Attempt],
                 log: StageLog) -> tuple[Attempt, str] | None:
    """For an object its category opens lying on its back (``categories.yaml`` ``opened_lying``: a suitcase), asked for
    an opening and no pose, whose modelled pose ``att`` does not settle (upright, the floor stops its lid, or a large
    case's lid swings out sideways too heavy for a hand): the attempt ``posed`` (stages 4-7 on a root rotation (3, 3),
    ``fractions``: joint -> opening fraction) makes laid on its largest face, moving parts up
    (:func:`~asset2sim.tasks.state.pose.resting_rotation` with ``kin``, the input's kinematics session, and
    ``moving_links``, the task parts' links), with the pose note, when it settles there, at the bands' targets or, where
    a part's weight turns it off them, at the opening its band allows where the weight turns it least
    (:func:`balanced_attempt`); else None."""
    if ctx.request.pose_hint is not None or att.settles or all(b == "closed" for b in att.bands.values()) or not category_prior(
            ctx.category).opened_lying:
        return None
    rotation, note = pose.resting_rotation(kin, ctx.asset, ctx.closed_state(), ctx.hull_points, moving_links)
    if np.allclose(rotation, np.eye(3)):
        return None
    second = balanced_attempt(replace(ctx, root_rotation=rotation), kin, posed(rotation),
                              lambda fractions: posed(rotation, fractions=fractions), log)
    failed = ", ".join(m.name for m in att.check.metrics if m.passed is False) or "a check"
    short = (f"{', '.join(att.off_band)} short of the band asked" if att.off_band else f"{failed} failed") + " as modelled"
    if not second.settles:
        log.say("post_check", f"{short}; laid down to open, not every check passes: kept as modelled")
        return None
    why = f"opened lying on its back, as a {ctx.category.lower()} is ({short}); {note}"
    log.say("post_check", why)
    return second, why
