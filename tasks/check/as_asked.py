"""The as-asked verdict (SPEC, "Interaction under manipulation": "As asked"): a request phrase naming a part or a
part's state that was not applied, or a number the request asks (an angle, a length or an opening fraction from
the closed end, an end, a size, the total mass) missed beyond its tolerance, fails the ``request_met`` metric and
with it the verdict's ``request`` tier (``request_not_met``, :data:`asset2sim.tasks.check.verdict.TIERS`).

One builder (:func:`request_met_metric`) serves refine's own account of the request (:func:`refine_request_met`,
from its state resolution and findings, the verdict of ``refine --no-extras``) and the evaluation's measurement of
any output (``tasks/evaluation/metric_defs.py``, which wins once it ran). Every unmet item carries its phrase and,
for a number, the target, what the output has, the gap and the unit, states measured from the joint's closed end.
Reasoning, tolerances and their sources: ``docs/design/metrics.md`` ("As asked").
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from asset2sim.schemas.overlay import Overlay
from asset2sim.schemas.report import MetricResult
from asset2sim.schemas.request import BAND_INTERVAL, MOTION_GUARDS, JointStateRequest, MotionPhrase, RequestFindings, RequestSpec
from asset2sim.tasks.geometry.closed_state import ClosedState
from asset2sim.tasks.interpret.part_priors import task_relevant_rank
from asset2sim.tasks.synthesize import joint_dynamics, request_apply, request_findings
from asset2sim.tasks.synthesize.request_apply import END_TOLERANCE, MIN_TOLERANCE, NUMBER_TOLERANCE, JointTarget, StateResolution

if TYPE_CHECKING:
    from asset2sim.engines.base import SimSession
    from asset2sim.tasks.synthesize.context import EstimationContext

#: Opening fraction a state asked by a band may lie outside the band's interval (measurement slack): refine's
#: smallest acceptance half-width of a number (``request_apply.MIN_TOLERANCE``, half a percent of the range).
BAND_SLACK = MIN_TOLERANCE
#: Where every state (angle, length, opening fraction) is measured from.
MEASURED_FROM = "closed end"
#: The metric's unit: the number of unmet items (a phrase on several joints counts once per joint).
UNIT = "unmet phrases"
THRESHOLD = (f"every part and state the request names applied, every number within its tolerance ({NUMBER_TOLERANCE:.0%}; "
             "each unmet item's gap and tolerance in details.unmet)")
#: Kinds of :class:`~asset2sim.schemas.request.QuantityOutcome` graded here (a joint's damping, friction or
#: stiffness asked in numbers is reported, not graded: the post-check changes them to hold the state, with its reason).
GRADED_QUANTITIES = ("state", "size", "mass")


def quantity_text(value: float | None, unit: str) -> str:
    """``value`` for people: rad as degrees (``"20.8 deg"``), m as mm below 1 m, an opening fraction as a
    percentage of the range, kg; ``"-"`` for None."""
    if value is None or not math.isfinite(float(value)):
        return "-"
    v = float(value)
    if unit == "rad":
        return f"{math.degrees(v):.1f} deg"
    if unit == "m":
        return f"{v * 1000.0:.4g} mm" if abs(v) < 1.0 else f"{v:.4g} m"
    if unit == "m^3":
        return f"{v * 1e6:.4g} ml" if abs(v) < 1e-2 else f"{v * 1e3:.4g} l"
    if unit == "opening fraction":
        return f"{100.0 * v:.1f} % of the range"
    return f"{v:.4g} {unit}".rstrip()


def not_applied(phrase: str, reason: str) -> dict[str, Any]:
    """An unmet item: ``phrase`` applied to no part (``reason`` says why)."""
    return _unmet(phrase, "not_applied", None, reason, f"'{phrase}': not applied: {reason}")


def _unmet(phrase: str, kind: str, joint: str | None, reason: str, text: str) -> dict[str, Any]:
    """An unmet item that asks no number: ``phrase``, its ``kind``, the ``joint`` it concerns, ``reason`` and the one-line
    ``text``."""
    return {"phrase": phrase, "kind": kind, "joint": joint, "reason": reason, "target": None, "achieved": None, "gap": None,
            "unit": "", "text": text}


def missed(phrase: str, *, kind: str, target: float, achieved: float, unit: str, tolerance: float,
           joint: str | None = None, reason: str = "") -> dict[str, Any]:
    """An unmet item: a number asked (``target``) and what the output has (``achieved``), in ``unit`` (rad, m,
    kg, opening fraction); ``kind`` ``state`` (measured from the closed end), ``size`` or ``mass``; the gap
    |achieved - target| exceeds ``tolerance``; ``reason`` (why it was missed) kept beside the one-line ``text``."""
    gap = abs(float(achieved) - float(target))
    where = f"{joint} " if joint else ""
    frame = " from the closed end" if kind == "state" else ""
    text = (f"'{phrase}': {where}{quantity_text(achieved, unit)}{frame}, asked {quantity_text(target, unit)} "
            f"(gap {quantity_text(gap, unit)}, tolerance {quantity_text(tolerance, unit)})")
    item = {"phrase": phrase, "kind": kind, "joint": joint, "reason": reason, "target": float(target), "achieved": float(achieved),
            "gap": gap, "unit": unit, "tolerance": float(tolerance), "text": text}
    if kind == "state":
        item["measured_from"] = MEASURED_FROM
    return item


def band_missed(phrase: str, joint: str, band: str, fraction: float) -> dict[str, Any] | None:
    """The unmet item of a state asked by ``band`` when opening fraction ``fraction`` (from the closed end) lies
    outside the band's interval (``schemas.request.BAND_INTERVAL``) by more than :data:`BAND_SLACK`, else None.
    Raises KeyError: an unknown band."""
    lo, hi = BAND_INTERVAL[band]
    f = float(fraction)
    gap = lo - f if f < lo else (f - hi if f > hi else 0.0)
    if gap <= BAND_SLACK + 1e-9:
        return None
    words = band.replace("_", " ")
    text = (f"'{phrase}': {joint} {100.0 * f:.1f} % open from the closed end, asked {words} ({100.0 * lo:.0f}-{100.0 * hi:.0f} % open; "
            f"gap {100.0 * gap:.1f} % of the range)")
    return {"phrase": phrase, "kind": "band", "joint": joint, "reason": "", "band": band, "target": [lo, hi], "achieved": f,
            "gap": gap, "unit": "opening fraction", "tolerance": BAND_SLACK, "measured_from": MEASURED_FROM, "text": text}


def request_met_metric(unmet: list[dict[str, Any]], *, request: str, graded: int = 0,
                       not_graded: list[dict[str, Any]] | None = None, source: str = "") -> MetricResult:
    """``request_met``: passes when nothing of the request is unmet. ``unmet``: items of :func:`not_applied`,
    :func:`missed`, :func:`band_missed`; ``graded``: how many phrases and numbers were checked; ``not_graded``:
    what could not be measured (reported, never a failure); ``source``: who measured (refine, the evaluation).
    Value: the number of unmet items (``engine="none"``)."""
    details = {"request": request, "unmet": list(unmet), "graded": int(graded), "not_graded": list(not_graded or []),
               "measured_from": MEASURED_FROM, "source": source}
    return MetricResult(name="request_met", value=float(len(unmet)), unit=UNIT, passed=not unmet, threshold=THRESHOLD,
                        details=details, engine="none")


def not_measured(reason: str, request: str = "") -> MetricResult:
    """``request_met`` not measured (``passed`` None: no request, or none of it understood)."""
    return MetricResult(name="request_met", value=None, unit=UNIT, passed=None, threshold=THRESHOLD,
                        details={"request": request, "reason": reason, "unmet": []}, engine="none")


def refine_request_met(spec: RequestSpec, res: StateResolution | None, found: RequestFindings | None,
                       closed_out: dict[str, ClosedState], state: dict[str, float],
                       properties: list[tuple[str, str]] | None = None, ranks: dict[str, int | None] | None = None) -> MetricResult:
    """Refine's ``request_met`` of its output: the state phrases ``res`` (refine's resolution of the request,
    ``request_apply.resolve_states``) applied to no joint, the phrases the parser replaced by a later one for the
    same part (``spec.overridden``), ``properties`` ((phrase, why) of masses, materials and joint parameters
    naming a part the object lacks, ``request_apply.unapplied_properties``), every number of ``found`` (its
    findings, ``request_findings.findings``) of a graded kind missed beyond its tolerance, and every joint a band
    set whose opening fraction at ``state`` (rad / m, output units; ``closed_out`` the output's closed ends) lies
    outside the band. Not measured when nothing was asked or no word of it was understood.

    A phrase naming a part must put each of its joints in the band; one naming no part ("a door, slightly open") asks
    it of the object's main part, met when one joint of the part it sets that ranks first among the category's
    task-relevant parts (``ranks``: joint -> its part's rank, 0 first,
    :func:`~asset2sim.tasks.interpret.part_priors.task_relevant_rank`; None or absent: no rank) is in the band: "a
    suitcase, mostly open" is its lid's state, not its carrying handle's. A joint it also set that the state does not
    suit (a latch that stays shut, a handle) is reported, not graded."""
    if spec is None or not (spec.text.strip() or spec.overrides):  # nothing asked: no request text, no typed override
        return not_measured("no request")
    if not spec.understood and not spec.overrides:
        return not_measured("no word of the request was understood", spec.text)
    unapplied = (res.unapplied if res is not None else []) + list(properties or [])
    # the phrases the parser replaced by a later one for the same part, each with the parser's contradiction as its reason
    unmet = [not_applied(phrase, next((w for w in spec.warnings if w.startswith(f"contradiction: '{phrase}' and ")), "")
                         .removeprefix("contradiction: ") or "a later phrase of the request sets the same part")
             for phrase in spec.overridden] + [not_applied(phrase, why) for phrase, why in unapplied]
    graded = len(spec.overridden) + len(unapplied)
    for q in (found.quantities if found is not None else []):
        if q.kind not in GRADED_QUANTITIES or q.asked is None or q.achieved is None:
            continue
        graded += 1
        if q.within_tolerance:
            continue
        joint = q.what.rsplit(" ", 1)[0] if q.kind == "state" else None
        tol = END_TOLERANCE if q.what.endswith(" end") else NUMBER_TOLERANCE * abs(q.asked)
        unmet.append(missed(q.phrase, kind=q.kind, target=q.asked, achieved=q.achieved, unit=q.unit, tolerance=tol, joint=joint,
                            reason=q.why))
    bands = []
    for joint, jr in (res.requests.items() if res is not None else []):
        if jr.target is not None or joint not in closed_out or joint not in state:
            continue  # a number or an end: graded through the findings
        band = res.bands.get(joint, jr.band)  # as resolved for this part: a drop-down door's lone "open" is fully open
        bands.append((jr, joint, band_missed(jr.phrase or band, joint, band, abs(closed_out[joint].fraction(state[joint])))))
    ranks = ranks or {}
    first: dict[int, int] = {}  # phrase -> the best rank among the joints it set
    for jr, joint, _ in bands:
        r = ranks.get(joint)
        if r is not None:
            first[id(jr)] = min(first.get(id(jr), r), r)

    def main(jr: JointStateRequest, joint: str) -> bool:
        return id(jr) not in first or ranks.get(joint) == first[id(jr)]

    not_graded = []
    met = {id(jr) for jr, joint, item in bands if item is None and main(jr, joint)}
    for jr, joint, item in bands:
        if item is None:
            continue
        if not jr.names_part and (id(jr) in met or not main(jr, joint)):
            why = "another part it set is in the band" if id(jr) in met else "the object's main part it set is graded"
            not_graded.append({"phrase": jr.phrase, "joint": joint, "reason": f"the phrase names no part and {why} ({item['text']})"})
            continue
        unmet.append(item)
    graded += len(bands) - len(not_graded)
    return request_met_metric(unmet, request=spec.text, graded=graded, not_graded=not_graded,
                              source="refine (its resolution of the request)")


def failing_joints(metrics: list[MetricResult]) -> tuple[dict[str, str], dict[str, str]]:
    """(joint -> why it is not held: a robust-rest trial or the rest test found it out of its band; joint -> why it is
    not operable) from ``metrics`` (any engines)."""
    held: dict[str, str] = {}
    operable: dict[str, str] = {}
    for m in (m for m in metrics if m.passed is False):
        d = m.details
        if m.name == "robust_rest":
            for trial, t in (d.get("trials") or {}).items():
                for j in (t or {}).get("failing_joints") or []:
                    held.setdefault(j, f"robust rest ({m.engine}, {trial}) finds it out of its band")
        elif m.name == "state_hold":
            for j in d.get("sagging") or []:
                held.setdefault(j, f"the rest test ({m.engine}) finds it leaving its state")
        elif m.name == "operability":
            for j in d.get("failing") or []:
                operable.setdefault(j, f"a hand inside its operating range cannot work it ({m.engine})")
    return held, operable


def word_conflicts(metrics: list[MetricResult], words: list[tuple[MotionPhrase, list[str]]],
                   strays: list[tuple[MotionPhrase, list[str]]] = ()) -> list[MetricResult]:
    """``metrics`` with the words about motion that the output's physical verdict contradicts added to
    ``request_met`` as unmet items (kind ``conflict``): a word that keeps a joint free or lightly damped
    (``MOTION_GUARDS`` "max": "swings freely", "low damping", a closer's friction) on a joint robust rest or the rest
    test finds not held (a self-closing part asked open: its closer shuts it), or one that keeps it stiff or held
    ("min": "stiff", "stays where it is put", "soft-close") on a joint no hand inside its range can work. The word was applied as asked; holding (or operating) the part needed what it rules
    out. ``words``: each word with the joints it applies to; ``strays``: each word with the joints it was applied to
    that its phrase does not name (kind ``not_named``: "the main door has a stiff hinge" made the freezer door stiff).
    ``metrics`` unchanged without a ``request_met`` (:func:`with_unmet`)."""
    held, operable = failing_joints(metrics)
    items = []
    for word, joints in words:
        ways = set(MOTION_GUARDS.get(word.kind, {}).values())
        for j in joints:
            not_held = held.get(j) if "max" in ways else None
            why = not_held or (operable.get(j) if "min" in ways else None)
            if why is None:
                continue
            head = f"'{word.phrase}': applied to {j} as asked, and {why}: "
            if word.kind == "self_closing" and not_held:  # its closer shuts it: the state asked away from shut cannot hold
                text = ("its closer shuts it from where it was asked, and holding it there needs more friction than lets "
                        "the closer shut it. Drop the word or ask for the part closed")
            elif not_held or word.kind == "hold":  # holding the part against its weight is what the word rules out
                need = ("needs more friction or damping than the word allows" if "max" in ways else
                        "needs more friction than a hand inside that range moves")
                text = (f"holding the part where it was asked {need}. "
                        "Drop the word, ask for the part at an end of its range, or --mount fixed where the object is mounted in use")
            elif word.kind == "self_closing":  # the closer itself: it outpulls the part's weight everywhere to shut it
                text = ("its closer, which must shut it from anywhere in its range against its weight, pulls so hard that "
                        "a hand inside that range cannot open it against that pull. Drop the word")
            elif word.kind == "spring":  # the friction that holds the state against the spring
                text = ("holding the part where it was asked against its spring needs more friction than a hand inside "
                        "that range moves. Drop the word or ask for the part where its spring rests")
            else:  # "stiff", "soft-close": the word itself makes the part too hard to work
                text = "working it needs less friction or damping than the word sets. Drop the word"
            items.append(_unmet(word.phrase, "conflict", j, why, head + text))
            break
    items += [_unmet(word.phrase, "not_named", j, "the phrase does not name this part",
                     f"'{word.phrase}': applied to {j}, a part the phrase does not name ({word.short()})")
              for word, joints in strays for j in joints]
    return with_unmet(metrics, items)


def with_unmet(metrics: list[MetricResult], items: list[dict[str, Any]]) -> list[MetricResult]:
    """``metrics`` with the unmet ``items`` added to ``request_met`` (then failing); unchanged without either."""
    asked = next((m for m in metrics if m.name == "request_met"), None)
    if asked is None or asked.passed is None or not items:
        return metrics
    d = dict(asked.details)
    d["unmet"] = list(d.get("unmet") or []) + items
    d["graded"] = int(d.get("graded") or 0) + len(items)
    fixed = asked.model_copy(update={"value": float(len(d["unmet"])), "passed": False, "details": d})
    return [fixed if m is asked else m for m in metrics]


@dataclass(frozen=True)
class AsAsked:
    """The request read once against one checked object (:func:`as_asked_tier`): ``metrics`` (the checks' metrics with
    ``request_met`` appended and every word about motion the physics contradicts named), ``findings`` (the report's
    account of the request) and ``resolution`` (which phrase set which joint)."""

    metrics: list[MetricResult]
    findings: RequestFindings
    resolution: StateResolution


def as_asked_tier(ctx: "EstimationContext", kin: "SimSession", overlay: Overlay, state: dict[str, float],
                  closed: dict[str, ClosedState], metrics: list[MetricResult], *, targets: dict[str, JointTarget] | None = None,
                  rounds: list | None = None) -> AsAsked:
    """The as-asked tier of an object checked by ``metrics`` (any engines): the request of ``ctx`` resolved on its
    parts at ``overlay.scale`` (:func:`~asset2sim.tasks.synthesize.request_apply.resolve_states`, ``kin`` the
    kinematics session of ``ctx``'s asset), graded at ``state`` (rad or m, output units) from the ``closed`` ends
    (output units) with ``targets`` (joint -> what a number or an end asked; default the resolution's) and the
    escalation ``rounds`` that explain changed parameters. One reading for the state, the dynamics, this tier and
    the report: the refine's final attempt and an output read back (``evaluate``) are graded by it alike."""
    resolution = request_apply.resolve_states(ctx, kin, overlay.scale)
    choices, missing = joint_dynamics.motion_choices(ctx, request_apply.task_relevant_joints(ctx))
    found = request_findings.findings(ctx, resolution.targets if targets is None else targets, closed, state, overlay,
                                      rounds or [], resolution, motion_words={n: list(c.words) for n, c in choices.items()})
    ranks = {j.name: task_relevant_rank(ctx.category, ctx.asset.link(j.child).semantic_label) for j in ctx.asset.movable_joints()}
    asked = refine_request_met(ctx.request, resolution, found, closed, state, request_apply.unapplied_properties(ctx) + missing,
                               ranks)
    words = [(w, [n for n, c in choices.items() if w in c.words]) for w in ctx.request.motions]
    strays = [(w, [n for n, d in overlay.joints.items() if f"request '{w.phrase}'" in d.source and n not in named])  # elsewhere
              for w, named in words if w.ordinal is not None]  # a word naming one part by its place ("the main door")
    free = free_motion_conflicts(overlay, words, resolution, {j.name: j.type == "prismatic" for j in ctx.asset.movable_joints()})
    unmet = free + not_shut(metrics, words)
    return AsAsked(with_unmet(word_conflicts([*metrics, asked], words, strays), unmet), found, resolution)


def not_shut(metrics: list[MetricResult], words: list[tuple[MotionPhrase, list[str]]]) -> list[dict[str, Any]]:
    """The unmet items (kind ``not_shut``) of each self-closing word (``words``: each with the joints it applies to)
    whose part the metric ``shuts_on_its_own`` of ``metrics`` (:mod:`~asset2sim.tasks.check.closer_release`) found
    short of shut after it was released fully open: where it stopped, as a fraction of its range from shut."""
    rows = {j: (r, m.engine, m.details.get("seconds")) for m in metrics if m.name == "shuts_on_its_own"
            for j, r in (m.details.get("joints") or {}).items()}
    items = []
    for word, joints in words:
        for j in joints:
            if word.kind != "self_closing" or j not in rows or rows[j][0].get("shut", True):
                continue
            r, engine, secs = rows[j]
            why = (f"released fully open, it stopped {100.0 * r['ended_at']:.1f} % open after {secs:g} s ({engine}; "
                   f"shut is within {100.0 * r['band']:.1f} %)")
            items.append(_unmet(word.phrase, "not_shut", j, why, f"'{word.phrase}': applied to {j}, and {why}"))
    return items


def free_motion_conflicts(overlay: Overlay, words: list[tuple[MotionPhrase, list[str]]],
                          resolution: StateResolution, prismatic: dict[str, bool]) -> list[dict[str, Any]]:
    """The unmet items (kind ``conflict``) of each part asked to move freely at a state its own weight moves it from
    (its holding mechanism :data:`~asset2sim.tasks.synthesize.joint_dynamics.HELD_AGAINST_FREE`): held there by
    friction, which a freely moving part lacks, so the two phrases (the word, the state) cannot both hold (SPEC,
    robust rest: the as-asked tier names the conflict). ``words``: each word with the joints it applies to;
    ``prismatic``: joint -> whether it slides (the loads' unit, N, else N m)."""
    items = []
    for word, joints in words:
        for j in joints:
            dyn = overlay.joints.get(j)
            if word.kind != "free" or dyn is None or dyn.holding is None or dyn.holding.mechanism != joint_dynamics.HELD_AGAINST_FREE:
                continue
            state = resolution.requests.get(j)
            other = f"'{state.phrase}'" if state is not None and state.phrase else "the state it is at"
            unit = "N" if prismatic.get(j) else "N m"
            why = (f"its weight {'slides' if prismatic.get(j) else 'turns'} it from {other} with {dyn.holding.static_load:.3g} "
                   f"{unit}: held there by {dyn.friction:.3g} {unit} of friction, which a part that moves freely does not have")
            items.append(_unmet(word.phrase, "conflict", j, why, f"'{word.phrase}' and {other} conflict on {j}: {why}. Drop one of "
                                "the two phrases, or ask for the part at an end of its range"))
    return items


def as_asked_lines(report) -> list[str]:
    """The as-asked verdict (``request_met``) of a report or an evaluation: one line per unmet phrase with its gap,
    states from the closed end; nothing when met or not measured."""
    m = report.metric("request_met")
    if m is None or m.passed is not False:
        return []
    return [f"NOT AS ASKED {u.get('text') or u.get('phrase')}" for u in (m.details or {}).get("unmet") or []]
