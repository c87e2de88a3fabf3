"""Why an asset failed, in sentences a user acts on: per failing tier, what moved or touched, by how much
against its band (mm for prismatic joints, rad for revolute ones), in which engine, and what to ask for instead
(:data:`TIER_ADVICE`); :func:`why_it_failed` gathers them for the refine report, the terminal and ``report.html``.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Any

from asset2sim.tasks.interpret.request import parse_request
from asset2sim.tasks.check.verdict import (
    HOLD_METRICS, PENETRATION_METRICS, TIERS, UNRESOLVED_PENETRATION_MM, metric_verdict, mode_of,
)
from asset2sim.package_data import package_yaml


#: The words of this module (``failure_words.yaml`` beside it): what a user can do, what a check did, how a trial
#: disturbed the object.
_WORDS = package_yaml(__package__, "failure_words.yaml")
#: How each robust-rest trial disturbed the object, for :func:`robust_rest_why`.
_TRIAL_WORDS: dict[str, str] = _WORDS["trial_words"]
#: What a user can do about a penetration, a part that swung or an object that did not rest or toppled.
_ADVICE: dict[str, str] = _WORDS["advice"]


def _failing(metrics: list[Any], names) -> list[Any]:
    """The measures of ``metrics`` named in ``names`` that fail (:func:`metric_verdict` False), in order."""
    return [m for m in metrics if m.name in names and metric_verdict(m) is False]


@dataclass(frozen=True)
class PenetrationFailure:
    """A failing penetration measure (``metric``) and its worst pair: ``kind`` ``self-contact`` (links ``link_a`` and
    ``link_b`` are not parent and child; the deepest pair) or ``parent-child`` (``link_a`` the parent, ``link_b`` the
    child; the pair deepest beyond its modelled pose, what the readiness rule grades); ``depth_mm`` that pair's depth
    (the measure's value where it names no pair, links then None)."""

    metric: Any
    kind: str
    link_a: str | None
    link_b: str | None
    depth_mm: float


def penetration_failures(metrics: list[Any]) -> list[PenetrationFailure]:
    """Every failing penetration measure of ``metrics`` (:data:`PENETRATION_METRICS`) with its worst pair, the one
    the sentences (:func:`penetration_why`) and the report's frames name."""
    out = []
    for m in _failing(metrics, PENETRATION_METRICS):
        d = m.details
        if m.name == "penetration":
            top = min(d.get("pairs") or [], key=lambda p: -float(p.get("max_depth_mm") or 0.0), default=None)  # the deepest
            out.append(PenetrationFailure(m, "self-contact", top and top["link_a"], top and top["link_b"],
                                          float(top["max_depth_mm"]) if top else float(m.value or 0.0)))
            continue
        pairs, modelled = d.get("pairs") or {}, d.get("modelled") or {}
        worst = max(pairs, key=lambda k: pairs[k] - modelled.get(k, 0.0), default=None)
        parent, _, child = worst.partition("/") if worst else (None, "", None)
        out.append(PenetrationFailure(m, "parent-child", parent, child, float(pairs[worst]) if worst else float(m.value or 0.0)))
    return out


def penetration_why(metrics: list[Any]) -> list[str]:
    """Why the penetration tier failed (``unresolved_penetration``), one sentence per failing measure
    (:func:`penetration_failures`): which penetration, the links, the measured depth against
    :data:`UNRESOLVED_PENETRATION_MM`, and what a user can do; empty when the tier passes. The terminal summary and
    ``report.html`` print the same sentences."""
    out = []
    for f in penetration_failures(metrics):
        m = f.metric
        if f.kind == "self-contact":
            links = f"links '{f.link_a}' and '{f.link_b}' (not parent and child) overlap by up to {f.depth_mm:.1f} mm" \
                if f.link_a else "links that are not parent and child overlap"
            out.append(f"self-contact penetration {m.value:.1f} mm ({m.engine}) is above {UNRESOLVED_PENETRATION_MM:g} mm: "
                       f"{links} at the initial state. {_ADVICE['self_contact']}")
            continue
        out.append(f"parent-child penetration ({m.engine}): link '{f.link_b or '?'}' is {f.depth_mm:.1f} mm inside its parent "
                   f"'{f.link_a or '?'}' at the initial state, {float(m.details.get('beyond_modelled_mm') or 0.0):.1f} mm "
                   f"deeper than at its modelled pose (fails above {UNRESOLVED_PENETRATION_MM:g} mm). {_ADVICE['parent_child']}")
    return out


def robust_rest_why(metrics: list[Any], skip: frozenset[str] | set[str] = frozenset()) -> list[str]:
    """Why robust rest failed (``not_robust_at_rest``), one sentence per part that moved (its largest drift over the
    trials against its tolerance, and the trial) or per toppling, with what a user can do; empty when it passes. A
    part's friction and damping stay within what a hand overcomes (the operability tier), so a drift here is the
    part's momentum when the object lands, not a search that stopped short (``docs/guide/metrics.md``). A trial
    the object did not come to rest in (or diverged) is one sentence too; a part that moved in a trial the object
    toppled in is said to swing as the object falls. ``skip``: joints the rest tier already found not held
    (:func:`why_it_failed`): their drift is said to be the same motion, with the rest tier's advice."""
    out: list[str] = []
    for m in _failing(metrics, ("robust_rest",)):
        # step 1: per failed trial, the object not at rest, each failing joint's worst drift and the largest topple
        trials = m.details.get("trials") or {}
        worst: dict[str, tuple[float, float, str]] = {}
        toppled: tuple[float, str] | None = None
        restless: dict[str, str] = {}
        for name, t in trials.items():
            if not isinstance(t, dict) or t.get("passed") is not False:
                continue
            moving = [w for w in str(t.get("failure", "")).split("; ") if w.startswith(("not at rest", "diverged"))]
            if moving and moving[0].startswith("not at rest") and t.get("d_pos") is not None and t.get("d_ori") is not None:
                restless[name] = f"not at rest (D_pos {float(t['d_pos']):.3e} m, D_ori {float(t['d_ori']):.3e} rad)"
            elif moving:
                restless[name] = moving[0]
            for j in t.get("failing_joints") or []:
                drift, tol = float((t.get("joint_drift") or {}).get(j, 0.0)), float((t.get("joint_tolerance") or {}).get(j, 0.0))
                if j not in worst or drift / max(tol, 1e-12) > worst[j][0] / max(worst[j][1], 1e-12):
                    worst[j] = (drift, tol, name)
            if "toppled" in str(t.get("failure", "")) and (toppled is None or float(t.get("topple") or 0) > toppled[0]):
                toppled = (float(t.get("topple") or 0.0), name)
        # step 2: one sentence per joint that moved: swung in a topple, moving at rest too, or carried by its momentum
        for j, (drift, tol, name) in sorted(worst.items()):
            t, how = trials.get(name) or {}, _TRIAL_WORDS.get(name, name)
            unit = (t.get("joint_units") or {}).get(j, "rad")
            peak = (t.get("joint_peak") or {}).get(j)
            moving = j in (t.get("moving_joints") or [])
            amount = (f"{_joint_amount(drift, unit)} from its state{' and was still moving' if moving else ''} (band "
                      f"{_joint_amount(tol, unit)}" + (f"; largest excursion {_joint_amount(peak, unit)}" if peak is not None else "") + ")")
            if "toppled" in str(t.get("failure", "")):
                out.append(f"joint '{j}' moved {amount} when the object {how} and toppled "
                           f"({m.engine}): the part swings as the object falls (the toppling is explained next). {_ADVICE['swing']}")
            elif j in skip:
                out.append(f"joint '{j}' moved {amount} when the object {how} ({m.engine}), as "
                           "it moves at rest with no disturbance (the rest tier). " + advice("hold", asked_weight(metrics)))
            else:
                out.append(f"joint '{j}' came to rest {amount} when the object {how} ({m.engine}); its friction and damping stay "
                           "within what a hand may use on it, and at that the part's momentum carries it out of its band. "
                           + _holding_choices(m, metrics, j, unit == "m"))
        # step 3: the trials the object did not come to rest in
        for name, what in restless.items():
            rest = re.search(r"at rest \(([^)]*)\)", m.threshold or "")
            out.append(f"the object was {what} when it {_TRIAL_WORDS.get(name, name)} ({m.engine}; at rest means "
                       f"{rest.group(1) if rest else 'still'} at the end of the trial): it rocks or slides on its support. "
                       + _ADVICE["restless"])
        # step 4: the toppling
        if toppled is not None:
            out.append(f"the object toppled ({toppled[0]:.2f} rad) when it {_TRIAL_WORDS.get(toppled[1], toppled[1])} "
                       f"({m.engine}): its centre of mass lies near the edge of its footprint in this state. {_ADVICE['toppled']}")
    return out


def _holding_choices(rr: Any, metrics: list[Any], joint: str, prismatic: bool) -> str:
    """The choices that remain for a part robust rest found not held within a hand's operating range, only those
    that fit the object: a lighter part (where the request gave it no mass or material: else that weight, kept); a
    stiffer slide or hinge than that range (which the operability tier then
    fails); mounting, where its category is mounted in use (``rr.details["category_mounting"]``)."""
    op = next((m for m in metrics if m.name == "operability" and m.engine == rr.engine), None)
    eff = (op.details.get("efforts") or {}).get(joint) or {} if op is not None else {}
    label = eff.get("label") or "part"
    top = (eff.get("force_range_n") or [None, None])[1]
    mech = "slide" if prismatic else "hinge"
    asked = asked_weight(metrics)
    choices = [f"the weight the request gives it ({asked}) kept (Ask for the {label} without those words to have its weight "
               "estimated)" if asked else f"a lighter {label} (its mass in the request, 'a 2 kg {label}', or --material)"]
    choices.append(f"a stiffer {mech} than a hand may operate" + (f" (more than the {top:g} N of its range, {eff.get('range_of')})"
                                                                 if top is not None else "")
                   + ", which the operability tier then fails")
    kind = rr.details.get("category_mounting")
    if kind and kind != "free-standing":
        choices.append(f"--mount fixed, as the category is used ({kind})")
    return "What remains: " + "; ".join(choices) + "."


def _num(v: Any) -> str:
    return "?" if v is None else f"{float(v):.3g}"


def _joint_amount(value: float, unit: str) -> str:
    """``12.0 mm`` for a prismatic joint's metres, ``0.050 rad`` for a revolute joint's radians."""
    return f"{1000.0 * float(value):.1f} mm" if unit == "m" else f"{float(value):.3f} rad"


#: What a user can do about each tier (the tail of every sentence of :func:`why_it_failed`).
TIER_ADVICE: dict[str, str] = _WORDS["tier_advice"]

#: The advice of a tier without its own entry in :data:`TIER_ADVICE`.
_FALLBACK_ADVICE = {"rest": "stand", "penetration": "sweep", "robust_rest": "stand"}


def _rest_why(metrics: list[Any]) -> list[str]:
    """One sentence per failing rest-tier metric: what moved, by how much against its threshold, the advice."""
    out = []
    told: set[tuple[str, str]] = set()  # (joint, engine) a hold measure said: the post-check's and the evaluation's once
    for m in _failing(metrics, TIERS["rest"][0]):
        d = m.details
        if m.name == "rest_stability":
            what = ("the rest test diverged" if d.get("diverged") else
                    f"the object moved D_pos {_num(d.get('D_pos_m'))} m and turned D_ori {_num(d.get('D_ori_rad'))} rad at rest")
            out.append(f"{what} ({m.engine}; passes when {m.threshold}). {TIER_ADVICE['stand']}")
        elif m.name == "settle_tilt":
            out.append(f"the object tipped {_num(m.value)} rad while settling ({m.engine}; passes when {m.threshold}): "
                       f"it falls over as it stands. {TIER_ADVICE['stand']}")
        elif m.name == "divergence":
            reasons = "; ".join(d.get("reasons") or []) or "non-finite state"
            out.append(f"the simulation diverged ({m.engine}: {reasons}). {TIER_ADVICE['divergence']}")
        elif m.name == "ground_penetration":
            out.append(f"the object sank {_num(m.value)} mm into the ground ({m.engine}; passes when {m.threshold}). "
                       f"{TIER_ADVICE['ground']}")
        elif m.name == "oscillation":
            joints = d.get("joints") or {}
            for j in d.get("failing") or []:
                e = joints.get(j) or {}
                amp = "diverged" if e.get("diverged") else (f"{e.get('sign_changes')} sign changes of its motion, peak to peak "
                                                            f"{_joint_amount(e.get('amplitude') or 0.0, e.get('unit', 'rad'))}")
                out.append(f"joint '{j}' oscillates at rest ({m.engine}: {amp}; passes when {m.threshold}). "
                           f"{TIER_ADVICE['oscillation']}")
        else:  # state_hold: drift, sagging
            for j in d.get("sagging") or []:
                if (j, m.engine) in told:
                    continue
                told.add((j, m.engine))
                drift, unit = float((d.get("drift") or {}).get(j, 0.0)), (d.get("units") or {}).get(j, "rad")
                tol = (d.get("tolerances") or {}).get(j)
                against = f"tolerance {_joint_amount(tol, unit)}" if tol is not None else f"passes when {m.threshold}"
                out.append(f"joint '{j}' left its initial state by {_joint_amount(drift, unit)} at rest ({m.engine}; {against}): "
                           f"its friction does not hold the part's weight there. {advice('hold', asked_weight(metrics))}")
    return out


#: What the check of a tier told by its metrics' ``details["failures"]`` did (:func:`why_it_failed`).
_DONE: dict[str, str] = _WORDS["done"]


#: Reasons of an unmet phrase that names a part the object lacks (``as_asked.not_applied``'s, refine's and the
#: evaluation's words): only then is the advice to name a part the object has.
_MISSING_PART = re.compile(r"no such part|names no part|carries that label|no task-relevant|no part that opens")

#: What a user can do about an unmet item of the request, by its kind (``as_asked``'s items); a conflict's own text
#: says it.
REQUEST_ADVICE: dict[str, str] = {"missing": TIER_ADVICE["request"], **_WORDS["request_advice"]}


def _request_advice(item: dict) -> str:
    """The advice of one unmet item: from what failed (a part the object lacks, a number missed, a phrase applied
    to the wrong part), never a generic one."""
    kind = str(item.get("kind") or "")
    if kind == "not_applied" and _MISSING_PART.search(str(item.get("reason") or "")):
        return REQUEST_ADVICE["missing"]
    return REQUEST_ADVICE.get("state" if kind == "band" else kind, REQUEST_ADVICE["not_applied"])


def _request_why(metrics: list[Any]) -> list[str]:
    """One sentence per unmet item of the request (its text carries the gap against its tolerance), with the advice
    of what failed (:func:`_request_advice`)."""
    return [f"the output is not what was asked: {u.get('text') or u.get('phrase')} (passes when {m.threshold})."
            + (f" {_request_advice(u)}" if _request_advice(u) else "")
            for m in _failing(metrics, ("request_met",)) for u in m.details.get("unmet") or []]


def asked_weight(metrics: list[Any]) -> str | None:
    """The request's words that set a mass or a material ("'ceramic'", "'a 3 kg lid'"), read from ``request_met``'s
    request; None when it set none. Advice never asks for a lighter part or another material against them."""
    text = next((m.details.get("request") for m in metrics if m.name == "request_met"), None)
    if not text:
        return None
    props = [p.phrase for p in parse_request(str(text)).properties if p.mass is not None or p.material or p.mass_range]
    return ", ".join(f"'{w}'" for w in props) or None


#: An advice's clauses that ask for a lighter part or another material, and what stays where the request set them.
_LIGHTER = ((re.compile(r"Ask for a lighter part or another material \(--mass, --material\); a"), "A"),
            (re.compile(r",? (?:or )?a lighter part(?: \(--mass, --material\))?"), ""),
            (re.compile(r"Give the object a real mass or material \(--mass, --material\) so its parts weigh what real ones "
                        r"do, or ask"), "Ask"))


def advice(tier: str, asked: str | None) -> str:
    """:data:`TIER_ADVICE` of ``tier``; where the request set the mass or material (``asked``, :func:`asked_weight`) without
    the clause that asks for a lighter part or another material, and saying the weight is as asked."""
    text = kept = TIER_ADVICE[tier]
    if asked is None:
        return text
    for rx, repl in _LIGHTER:
        kept = rx.sub(repl, kept)
    return text if kept == text else f"{kept} The part weighs what the {asked} asked makes it."


def why_it_failed(metrics: list[Any]) -> list[str]:
    """Why an output is not interaction-ready: for every failing tier of :data:`TIERS`, in tier order (the failure
    mode's first), one sentence per failing measure, ``MODE (TIER tier): what failed, the part(s) or joint(s), the
    measured value against its threshold, and what a user can do`` (a request to change, an option such as
    ``--state``, ``--mount``, ``--mass``, ``--task``, or a repair of the input). Empty when ready. The penetration
    and robust-rest tiers are explained by :func:`penetration_why` and :func:`robust_rest_why`.

    ``metrics``: :class:`~asset2sim.schemas.report.MetricResult` s (any engines), read as :func:`readiness` reads
    them. ``refine``'s and ``evaluate``'s terminal print each as ``why it failed SENTENCE``; ``report.html`` shows
    the same sentences in its "Why it failed" block (``docs/guide/metrics.md``). The modes of a run that stopped
    before a verdict (:data:`STOPPED_MODES`) have no metrics: their error line names the code and the file instead.
    """
    metrics = list(metrics)
    asked = asked_weight(metrics)
    held_not = {j for m in _failing(metrics, HOLD_METRICS) for j in m.details.get("sagging") or []}
    explain = {"rest": _rest_why, "penetration": penetration_why, "robust_rest": lambda ms: robust_rest_why(ms, skip=held_not),
               "request": _request_why}
    out: list[str] = []
    for tier, (names, _) in TIERS.items():
        bad = _failing(metrics, names)
        if not bad:
            continue
        mode = mode_of(tier, bad)
        # a tier told by its metrics' details["failures"] (each names its joint and the measured value): what its
        # check did, one sentence per failing metric
        sentences = (explain[tier](metrics) if tier in explain else
                     [f"{_DONE[tier]} ({m.engine}): {'; '.join(m.details.get('failures') or [f'{_num(m.value)} {m.unit}'])} "
                      f"(passes when {m.threshold}). {advice(tier, asked)}" for m in bad]) or [
            f"{', '.join(dict.fromkeys(f'{m.name}@{m.engine}' for m in bad))} failed (passes when {bad[0].threshold}). "
            + advice(_FALLBACK_ADVICE.get(tier, tier), asked)]
        out += [f"{mode} ({tier} tier): {s}" for s in sentences]
    return out
