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
from typing import Any

from asset2sim.schemas.report import MetricResult
from asset2sim.schemas.request import BAND_INTERVAL, RequestFindings, RequestSpec
from asset2sim.tasks.geometry.closed_state import ClosedState
from asset2sim.tasks.synthesize.request_apply import END_TOLERANCE, MIN_TOLERANCE, NUMBER_TOLERANCE, StateResolution

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


def not_applied(phrase: str, reason: str, joint: str | None = None) -> dict[str, Any]:
    """An unmet item: ``phrase`` applied to no part (``reason`` says why)."""
    return {"phrase": phrase, "kind": "not_applied", "joint": joint, "reason": reason, "target": None, "achieved": None,
            "gap": None, "unit": "", "text": f"'{phrase}': not applied: {reason}"}


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


def overridden_items(spec: RequestSpec) -> list[dict[str, Any]]:
    """The unmet items of the phrases the parser replaced by a later one for the same part (``spec.overridden``),
    each with the parser's contradiction as its reason."""
    out = []
    for phrase in spec.overridden:
        why = next((w for w in spec.warnings if w.startswith(f"contradiction: '{phrase}' and ")), "")
        out.append(not_applied(phrase, why.removeprefix("contradiction: ") or "a later phrase of the request sets the same part"))
    return out


def asked_anything(spec: RequestSpec | None) -> bool:
    """Whether ``spec`` asks something: request text or a typed override."""
    return spec is not None and (bool(spec.text.strip()) or bool(spec.overrides))


def refine_request_met(spec: RequestSpec, res: StateResolution | None, found: RequestFindings | None,
                       closed_out: dict[str, ClosedState], state: dict[str, float],
                       properties: list[tuple[str, str]] | None = None) -> MetricResult:
    """Refine's ``request_met`` of its output: the state phrases ``res`` (refine's resolution of the request,
    ``request_apply.resolve_states``) applied to no joint, the phrases the parser replaced by a later one for the
    same part (``spec.overridden``), ``properties`` ((phrase, why) of masses, materials and joint parameters
    naming a part the object lacks, ``request_apply.unapplied_properties``), every number of ``found`` (its
    findings, ``request_apply.findings``) of a graded kind missed beyond its tolerance, and every joint a band
    set whose opening fraction at ``state`` (rad / m, output units; ``closed_out`` the output's closed ends) lies
    outside the band. Not measured when nothing was asked or no word of it was understood."""
    if not asked_anything(spec):
        return not_measured("no request")
    if not spec.understood and not spec.overrides:
        return not_measured("no word of the request was understood", spec.text)
    unmet: list[dict[str, Any]] = []
    graded = 0
    unmet += overridden_items(spec)
    for phrase, why in (res.unapplied if res is not None else []) + list(properties or []):
        unmet.append(not_applied(phrase, why))
    graded += len(spec.overridden) + len(properties or []) + (len(res.unapplied) if res is not None else 0)
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
    for joint, jr in (res.requests.items() if res is not None else []):
        if jr.target is not None or joint not in closed_out or joint not in state:
            continue  # a number or an end: graded through the findings
        graded += 1
        item = band_missed(jr.phrase or jr.band, joint, jr.band, abs(closed_out[joint].fraction(state[joint])))
        if item is not None:
            unmet.append(item)
    return request_met_metric(unmet, request=spec.text, graded=graded, source="refine (its resolution of the request)")
