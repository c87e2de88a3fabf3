"""The request against what came out: the departures of an overlay from the
request (:func:`check_overlay`, noted on the overlay by :func:`check_against_request`)
and ``report.json``'s ``request`` section (:func:`findings`: each asked number
against the achieved one within :data:`~.request_apply.NUMBER_TOLERANCE` or
:data:`~.request_apply.END_TOLERANCE`, and one line per phrase and motion word).
Masses in kg, lengths in m, angles in rad, opening fractions in [0, 1].
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from asset2sim.schemas.overlay import Overlay
from asset2sim.schemas.request import QuantityOutcome, RequestFindings, RequestSpec
from asset2sim.tasks.interpret.part_priors import request_label_matches
from asset2sim.tasks.interpret.named_parts import joints_of, unit_fits
from asset2sim.tasks.synthesize.request_apply import (END_TOLERANCE, NUMBER_TOLERANCE, JointTarget, StateResolution,
                                                      requested_material, resolve_states, size_residuals,
                                                      task_relevant_joints, whole_masses)

if TYPE_CHECKING:  # typing only: the context module imports this stage's parser
    from asset2sim.engines.base import SimSession
    from asset2sim.tasks.synthesize.context import EstimationContext


def check_overlay(ctx: EstimationContext, overlay: Overlay, res: StateResolution) -> list[str]:
    """One line per departure of an overlay from the request: total mass and sizes (5 %), materials, explicit
    joint parameters, initial positions vs the targets' intervals."""
    sizes, masses = _size_and_mass_outcomes(ctx, overlay)
    out = [f"total mass {o.achieved:.4g} kg but the request asks "
           + (f"{o.asked:.4g}" if o.asked_high is None else f"{o.asked:g}-{o.asked_high:g}") + " kg" for o in masses if not o.within_tolerance]
    out += [f"'{o.phrase}': {o.achieved:.4g} {o.unit} at scale {overlay.scale:.4g}, asked {o.asked:.4g} {o.unit}"
            for o in sizes if not o.within_tolerance]
    for name, lp in overlay.links.items():
        mat = requested_material(ctx, name) if name in ctx.geometry else None  # links with geometry only
        if mat is not None and (lp.density is None or abs(lp.density - mat.density) > 1e-6 * mat.density):
            out.append(f"link {name}: density {lp.density:g} kg/m^3 but the request names {mat.name} ({mat.density:g})")
    for d in ctx.request.dynamics_values:
        for n, jd in overlay.joints.items():
            linear = n in ctx.prismatic
            if not unit_fits(d, linear) or (n not in task_relevant_joints(ctx) if d.label is None else not request_label_matches(
                    ctx.category, d.label, ctx.joint_label(n))):
                continue
            v = getattr(jd, d.quantity)
            if abs(v - d.value) > NUMBER_TOLERANCE * max(d.value, 1e-12):
                out.append(f"joint {n}: {d.quantity} {v:.4g} but the request asks {d.value:g} ('{d.phrase}')")
    if overlay.initial_joint_positions:
        for n, t in res.targets.items():
            if n not in overlay.initial_joint_positions:
                continue
            unit = overlay.scale if n in ctx.prismatic else 1.0
            f = ctx.closed[n].fraction(overlay.initial_joint_positions[n] / unit)
            if not (t.interval[0] - 1e-9 <= f <= t.interval[1] + 1e-9):
                out.append(f"joint {n}: initial opening fraction {f:.3g} outside {t.interval[0]:.3g}..{t.interval[1]:.3g} asked by '{t.phrase}'")
    return out


def summary(spec: RequestSpec) -> list[str]:
    """One line per override, then per thing the request asks beyond bands (sizes, masses, materials, ...)."""
    out = [f"given by the user: {o}" for o in spec.overrides]
    if spec.sizes:
        out.append("sizes: " + ", ".join(f"{s.dimension} {s.value:g} m" for s in spec.sizes))
    for p in spec.properties:
        mass = f"{p.mass:g} kg" if p.mass is not None else f"{p.mass_range[0]:g}-{p.mass_range[1]:g} kg" if p.mass_range else ""
        out.append(f"{p.label or 'object'}: " + ", ".join(x for x in (mass, p.material) if x))
    if spec.mass_level:
        out.append(f"mass: {spec.mass_level}")
    return out + [f"{d.label or 'joints'}: {d.quantity} {d.value:g} ({d.motion})" for d in spec.dynamics_values]


def phrase_lines(ctx: EstimationContext, res: StateResolution, closed_out: dict, state: dict[str, float]) -> list[str]:
    """One line per state phrase of the request, in its order: the joints it set with their labels, the amount
    each has from its closed end (``closed_out`` at the output's scale, ``state`` output units) and what was asked
    ("'lid open 30 degrees': joint_2 (lid) 30.0 deg from closed, 25 % open (asked 30 deg from closed)"), or why it
    was not applied."""
    by_phrase: dict[str, list[str]] = {}
    for n, jr in res.requests.items():
        by_phrase.setdefault(jr.phrase, []).append(n)
    why_not = dict(res.unapplied)
    out = []
    low = " ".join(ctx.request.text.lower().split())
    for jr in sorted(ctx.request.joint_states, key=lambda jr: (low.find(jr.phrase) % (len(low) + 1))):  # in the request's order
        if jr.phrase in why_not:
            out.append(f"'{jr.phrase}': not applied: {why_not.pop(jr.phrase)}")
            continue
        if not (joints := by_phrase.pop(jr.phrase, None)):
            continue
        asked = jr.short().split("=", 1)[1]
        got = []
        for n in joints:
            cs, q = closed_out.get(n), state.get(n)
            if cs is None or q is None:
                got.append(_named(ctx, n))
                continue
            d = abs(q - cs.q_closed)
            amount = f"{1000.0 * d:.4g} mm" if n in ctx.prismatic else f"{np.degrees(d):.1f} deg"
            got.append(_named(ctx, n) + f" {amount} from closed, {100.0 * abs(cs.fraction(q)):.0f} % open")
        out.append(f"'{jr.phrase}': " + "; ".join(got) + f" (asked {asked})")
    return out


def _named(ctx: EstimationContext, joint: str) -> str:
    """``joint_2 (lid)``: a joint with its moving part's label, or its name alone."""
    label = ctx.joint_label(joint)
    return joint + (f" ({label})" if label else "")


#: Units of a joint's damping, friction and stiffness (revolute, prismatic), for the report's lines.
DYNAMICS_UNITS = {"damping": ("N m s/rad", "N s/m"), "friction": ("N m", "N"), "stiffness": ("N m/rad", "N/m")}


def motion_lines(ctx: EstimationContext, overlay: Overlay, words: dict[str, list], escalation: list | None = None) -> list[str]:
    """One line per word of the request about a part's motion, in its order: the joints it applies to with the
    damping, friction and stiffness they end with ("'swings freely' (door): free on joint_1 (door): friction 0.0056 N m,
    damping 0.30 N m s/rad, stiffness 0 N m/rad"), what it kept from the post-check (``escalation``'s ``words_kept``),
    or why it was not applied. ``words``: joint -> the :class:`~asset2sim.schemas.request.MotionPhrase` s applied to
    it (``joint_dynamics.motion_choices``)."""
    out = []
    kept = [line for r in escalation or [] for line in (getattr(r, "words_kept", None) or [])]
    for word in ctx.request.motions:
        joints = [n for n, ws in words.items() if any(w is word or w == word for w in ws)]
        if not joints:
            continue
        got = [_named(ctx, n) + ": " + ", ".join(f"{p} {getattr(d, p):.3g} {DYNAMICS_UNITS[p][n in ctx.prismatic]}"
                                                 for p in ("friction", "damping", "stiffness"))
               for n in joints if (d := overlay.joints.get(n)) is not None]
        line = f"{word.short()} on " + "; ".join(got)
        held = [x for x in kept if f"'{word.phrase}'" in x]
        out.append(line + (f" (kept through the post-check: {'; '.join(dict.fromkeys(held))})" if held else ""))
    return out


def findings(ctx: EstimationContext, targets: dict[str, JointTarget], closed_out: dict, state: dict[str, float],
             overlay: Overlay, escalation: list | None = None, resolution: StateResolution | None = None,
             motion_words: dict[str, list] | None = None) -> RequestFindings:
    """The report's account of the request: ignored words, warnings (the parser's and the ``WARNING`` lines of the
    ``overlay``'s notes), what was asked, every number against the output (``closed_out`` at the output's scale,
    ``state`` in output units, the ``overlay``'s scale, total mass (kg) and joint parameters; ``escalation`` rounds
    explain changed parameters) and, with the ``resolution`` of the request, each state phrase with what it set
    (:func:`phrase_lines`)."""
    warnings = list(ctx.request.warnings) + [n for n in overlay.notes.other if n.startswith("WARNING")]
    if not ctx.request.understood:
        warnings.insert(0, "WARNING: no word of the request was understood; refined with the category's defaults")
    q: list[QuantityOutcome] = []
    for n, t in targets.items():
        cs = closed_out.get(n)
        if cs is None or n not in state:
            continue
        f = cs.fraction(state[n])
        if t.kind == "end":
            asked, got, unit = t.fraction, f, "opening fraction"
        elif t.kind == "angle" or t.kind == "distance" and n in ctx.prismatic:
            asked, got, unit = t.asked, f * cs.open_range, "rad" if t.kind == "angle" else "m"
        elif t.kind == "distance":
            asked, got, unit = t.asked, (t.asked or 0.0) * f / max(t.fraction, 1e-12), "m"
        else:
            asked, got, unit = t.asked, f, "opening fraction"
        ok = (abs(f - t.fraction) <= END_TOLERANCE + 1e-9 if t.kind == "end"
              else asked is not None and abs(got - asked) <= NUMBER_TOLERANCE * abs(asked) + 1e-9)
        why = t.note
        if not ok and t.kind != "end":
            if t.interval[1] >= 1.0 - 1e-9 and f >= 1.0 - 1e-6 or t.fraction >= 1.0 - 1e-9:
                why += "; the joint's limit is below the number"
            else:
                why += "; the state search moved it inside its interval to remove self-penetration"
        q.append(QuantityOutcome(what=f"{n} {t.kind}", phrase=t.phrase, asked=asked, achieved=got, unit=unit, within_tolerance=ok, why=why,
                                 kind="state"))
    sizes, masses = _size_and_mass_outcomes(ctx, overlay)
    q += sizes + masses + _dynamics_outcomes(ctx, overlay, escalation or [])
    phrases = phrase_lines(ctx, resolution, closed_out, state) if resolution is not None else []
    phrases += motion_lines(ctx, overlay, motion_words or {}, escalation)
    return RequestFindings(ignored=list(ctx.request.ignored), warnings=warnings, asked=summary(ctx.request), quantities=q, phrases=phrases)


def _size_and_mass_outcomes(ctx: EstimationContext, overlay: Overlay) -> tuple[list[QuantityOutcome], list[QuantityOutcome]]:
    """(the sizes in numbers, the total mass and the range of masses asked) against ``overlay``'s scale and total mass."""
    sizes, masses = [], []
    for sz, (phrase, asked, got) in zip(ctx.request.sizes, size_residuals(ctx, overlay.scale)):
        ok = abs(got - asked) <= NUMBER_TOLERANCE * asked
        sizes.append(QuantityOutcome(what="volume" if sz.dimension == "volume" else "size", phrase=phrase, asked=asked, achieved=got,
                                     unit="m^3" if sz.dimension == "volume" else "m", within_tolerance=ok,
                                     why="" if ok else "one uniform scale cannot meet every size asked", kind="size"))
    total_req, rng = whole_masses(ctx.request)
    total_mass = overlay.total_mass()
    if total_req is not None:
        ok = abs(total_mass - total_req.mass) <= NUMBER_TOLERANCE * total_req.mass
        masses.append(QuantityOutcome(what="total mass", phrase=total_req.phrase, asked=total_req.mass, achieved=total_mass, unit="kg",
                                      within_tolerance=ok, why="" if ok else "the parts' requested masses exceed it", kind="mass"))
    if rng is not None:
        lo, hi = rng.mass_range
        ok = lo * (1 - NUMBER_TOLERANCE) <= total_mass <= hi * (1 + NUMBER_TOLERANCE)
        masses.append(QuantityOutcome(what="total mass", phrase=rng.phrase, asked=lo, asked_high=hi, achieved=total_mass, unit="kg",
                                      within_tolerance=ok, why="a range: met anywhere in it" if ok else "the parts' requested masses exceed it",
                                      kind="mass"))
    return sizes, masses


def _dynamics_outcomes(ctx: EstimationContext, overlay: Overlay, escalation: list) -> list[QuantityOutcome]:
    """Explicit joint parameters asked vs the final overlay, a change explained by its post-check round."""
    out = []
    relevant = task_relevant_joints(ctx)
    for d in ctx.request.dynamics_values:
        for n in joints_of(ctx, d, relevant):
            jd = overlay.joints.get(n)
            linear = n in ctx.prismatic
            if jd is None or not unit_fits(d, linear):
                continue
            got = float(getattr(jd, d.quantity))
            ok = abs(got - d.value) <= NUMBER_TOLERANCE * max(d.value, 1e-12)
            why = ""
            if not ok:
                rounds = [r for r in escalation if n in (getattr(r, "changes", None) or {}) and d.quantity in r.changes[n]]
                why = (f"raised by the post-check's escalation ({len(rounds)} rounds; round {rounds[-1].round}: {rounds[-1].reason})"
                       if rounds else "changed by the overlay validation (stability bound of the simulator)")
            out.append(QuantityOutcome(what=f"{n} {d.quantity}", phrase=d.phrase, asked=d.value, achieved=got,
                                       unit=DYNAMICS_UNITS[d.quantity][linear].replace(" ", "*"),
                                       within_tolerance=ok, why=why, kind="dynamics"))
    return out


def check_against_request(ctx: EstimationContext, kin: SimSession, overlay: Overlay,
                          targets: dict[str, JointTarget]) -> tuple[Overlay, dict[str, JointTarget]]:
    """(overlay, targets): every :func:`check_overlay` departure added as a ``WARNING`` note; ``targets``
    resolved here at the overlay's scale when the estimator gave none (a model backend; ``kin`` moved then)."""
    if not targets:
        targets = resolve_states(ctx, kin, overlay.scale).targets
    if departures := check_overlay(ctx, overlay, StateResolution(bands={}, targets=targets)):
        notes = overlay.notes.model_copy(update={"other": list(overlay.notes.other)
                                                 + [f"WARNING: the overlay departs from the request: {d}" for d in departures]})
        overlay = overlay.model_copy(update={"notes": notes})
    return overlay, targets
