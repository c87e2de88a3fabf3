"""Semantic-accuracy metrics over plain numbers: scale deviation, initial joint
deviation, total mass, prompt alignment (definitions: docs/design/metrics.md,
section 3 "Semantic accuracy").
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from asset2sim.schemas.report import MetricResult
from asset2sim.schemas.request import BAND_INTERVAL, StateTarget

#: |ln(L / L_target)| bounds for a full and a half size score (dimensionless).
SIZE_FULL_RATIO = 1.5
SIZE_HALF_RATIO = 2.25
#: Distance (opening fraction) outside a band's interval that still scores 0.5.
BAND_HALF_MARGIN = 0.10


def _result(name: str, value: float | None, unit: str, threshold: str, details: dict[str, Any],
            passed: bool | None = None) -> MetricResult:
    """A semantic metric's result (``engine="none"``; ``passed`` None: reported without a threshold)."""
    return MetricResult(name=name, value=value, unit=unit, passed=passed, threshold=threshold, details=details, engine="none")


def scale_deviation(scale: float | None, reference_scale: float | None, *, scale_source: str = "") -> MetricResult:
    """``scale_deviation``: |s - s_ref| / s_ref in % (``passed`` None), ``scale`` relative to the raw input,
    ``reference_scale`` GenSim2's; value None when either is missing or s_ref <= 0."""
    details: dict[str, Any] = {"scale": scale, "reference_scale": reference_scale, "scale_source": scale_source}
    value = None
    if scale is None:
        details["reason"] = "scale of the evaluated asset unknown"
    elif reference_scale is None or not reference_scale > 0:
        details["reason"] = "the reference has no scale"
    else:
        value = abs(float(scale) - float(reference_scale)) / float(reference_scale) * 100.0
    return _result("scale_deviation", value, "%", "reported: |s - s_ref| / s_ref (no pass/fail threshold)", details)


def initial_joint_deviation(state: dict[str, float], reference_state: dict[str, float], joints: list[str],
                            joint_types: dict[str, str]) -> MetricResult:
    """``initial_joint_deviation``: mean |q - q_ref| (rad or m) over the task-relevant
    ``joints`` found in both states (others in ``details.skipped``); unit ``rad``,
    ``m`` when all are prismatic, else ``mixed``; value None when none compares."""
    skipped = [j for j in joints if j not in state or j not in reference_state]
    per = {j: {"q": float(state[j]), "q_ref": float(reference_state[j]),
               "deviation": abs(float(state[j]) - float(reference_state[j])),
               "unit": "m" if joint_types.get(j) == "prismatic" else "rad"} for j in joints if j not in skipped}
    units = {v["unit"] for v in per.values()}
    unit = units.pop() if len(units) == 1 else ("mixed" if units else "rad")
    value = float(np.mean([v["deviation"] for v in per.values()])) if per else None
    return _result("initial_joint_deviation", value, unit, "reported: |q - q_ref| of the task-relevant joint (no pass/fail threshold)",
                   {"joints": per, "skipped": skipped})


def mass_plausibility(total_mass: float, mass_range: tuple[float, float] | None, *,
                      per_link: dict[str, dict[str, Any]] | None = None, category: str | None = None) -> MetricResult:
    """``total_mass`` (kg, the simulator's link masses) against ``mass_range`` ((low, high) kg at the asset's size, or None:
    ``passed`` None). Raises ValueError: ``mass_range`` with low > high, or a non-finite mass."""
    if not math.isfinite(total_mass):
        raise ValueError(f"total mass must be finite, got {total_mass}")
    details: dict[str, Any] = {"category": category, "per_link": per_link or {}}
    passed = None
    if mass_range is not None:
        lo, hi = float(mass_range[0]), float(mass_range[1])
        if lo > hi:
            raise ValueError(f"mass range ({lo}, {hi}) has low > high")
        details["range_kg"] = [lo, hi]
        passed = bool(lo <= total_mass <= hi)
        threshold = f"{lo:.3g} kg <= m <= {hi:.3g} kg"
    else:
        details["reason"] = "no mass prior for the category"
        threshold = "no prior for the category"
    return _result("total_mass", float(total_mass), "kg", threshold, details, passed)


@dataclass(frozen=True, slots=True)
class SizeScore:
    """The size half of prompt alignment (:func:`size_score`): ``score`` 0 / 0.5 / 1, ``reason`` (one line) and
    ``ratio`` L / L_target (dimensionless)."""

    score: float
    reason: str
    ratio: float


def size_score(largest_extent: float, typical_largest: float, size_factor: float = 1.0) -> SizeScore:
    """Size half of prompt alignment, L = ``largest_extent`` m against L_target = ``typical_largest`` m x
    ``size_factor``. Raises ValueError: non-positive inputs."""
    if not (largest_extent > 0 and typical_largest > 0 and size_factor > 0):
        raise ValueError(f"size inputs must be > 0 (got {largest_extent}, {typical_largest}, {size_factor})")
    target = typical_largest * size_factor
    r = largest_extent / target
    lr = abs(math.log(r))
    if lr <= math.log(SIZE_FULL_RATIO):
        score, verdict = 1.0, "matches"
    elif lr <= math.log(SIZE_HALF_RATIO):
        score, verdict = 0.5, "near miss"
    else:
        score, verdict = 0.0, "miss"
    return SizeScore(score, f"largest extent {largest_extent:.3f} m vs target {target:.3f} m "
                            f"(typical {typical_largest:.3f} m x {size_factor:g}): ratio {r:.2f}, {verdict}", r)


def band_score(fraction: float, band: str) -> tuple[float, str]:
    """(score, reason) of opening fraction ``fraction`` against ``band``'s interval
    (``schemas.request.BAND_INTERVAL``; KeyError: unknown band)."""
    lo, hi = BAND_INTERVAL[band]
    if lo <= fraction <= hi:
        return 1.0, f"opening {fraction:.2f} inside {band} [{lo}, {hi}]"
    dist = lo - fraction if fraction < lo else fraction - hi
    near = dist <= BAND_HALF_MARGIN
    return (0.5 if near else 0.0), f"opening {fraction:.2f} {'just ' if near else ''}outside {band} [{lo}, {hi}] (by {dist:.2f})"


#: Relative tolerance of a number asked in a request, its half-score bound,
#: and the absolute floors per kind (rad, m, fraction of the range).
TARGET_REL_TOL = 0.05
TARGET_HALF_REL_TOL = 0.10
TARGET_ABS_TOL = {"angle": math.radians(0.5), "distance": 1e-3, "fraction": 0.01}
#: Opening fraction within which a joint sits at a travel end (the closed band's width).
END_FRACTION_TOL = 0.03


@dataclass
class JointStateCheck:
    """One requested joint: its band and measured opening fraction; ``target`` replaces the band for a number or an end,
    graded on ``opening`` = direction * (q - q_closed), rad or m."""

    joint: str
    band: str
    fraction: float | None
    label: str | None = None
    phrase: str = ""
    target: StateTarget | None = None
    opening: float | None = None
    joint_type: str = "revolute"


def target_score(check: JointStateCheck) -> tuple[float | None, str]:
    """(score 1 / 0.5 / 0, or None when not graded; reason) of a joint asked by a
    number or an end. Raises ValueError: ``check.target`` is None."""
    t = check.target
    if t is None:
        raise ValueError(f"joint {check.joint}: no target to grade")
    if check.fraction is None:
        return 0.0, "closed end unknown"
    if t.kind == "end":
        at_end = check.fraction <= END_FRACTION_TOL or check.fraction >= 1.0 - END_FRACTION_TOL
        return (1.0 if at_end else 0.0), f"opening {check.fraction:.2f}: {'' if at_end else 'not '}at a travel end ({t.end})"
    if t.kind == "fraction":
        achieved, unit = check.fraction, ""
    else:
        prismatic = check.joint_type == "prismatic"
        if t.kind == "distance" and not prismatic:
            return None, "a distance asked on a hinge (gap at the far edge) is not graded by the evaluation"
        if t.kind == "angle" and prismatic:
            return 0.0, "an angle asked on a sliding joint"
        if check.opening is None:
            return 0.0, "opening unknown"
        achieved, unit = check.opening, (" m" if prismatic else " rad")
    asked = float(t.value or 0.0)
    err = abs(achieved - asked)
    tol = max(TARGET_REL_TOL * abs(asked), TARGET_ABS_TOL[t.kind])
    why = f"asked {asked:.4g}{unit}, measured {achieved:.4g}{unit} (error {err:.3g}, tolerance {tol:.3g})"
    if err <= tol:
        return 1.0, why
    return (0.5 if err <= max(TARGET_HALF_REL_TOL * abs(asked), 2 * TARGET_ABS_TOL[t.kind]) else 0.0), why


def prompt_alignment(*, size_requested: bool, largest_extent: float | None, typical_largest: float | None, size_factor: float,
                     joint_checks: list[JointStateCheck], state_requested: bool, unmatched_requests: list[str] | None = None,
                     text: str = "", understood: bool = True, warnings: list[str] | None = None) -> MetricResult:
    """``prompt_alignment`` in [0, 1]: the mean of the size half (when ``typical_largest`` m and ``largest_extent`` m are
    known) and the joint-state half (when ``state_requested``: mean over ``joint_checks``). Only what was understood
    counts: ``unmatched_requests`` (phrases naming no part of the object) are listed in ``details["not_counted"]``,
    not scored; a request of which nothing was understood (``understood`` False) scores 0. ``warnings``: the
    request's warnings, kept in ``details["warnings"]`` for the report."""
    details: dict[str, Any] = {"request": text, "size": None, "joints": [], "warnings": list(warnings or []),
                               "not_counted": [{"phrase": p, "reason": "names no part of this object"} for p in unmatched_requests or []]}
    if not understood:
        why = "no word of the request was understood"
        details.update(joint_state_score=None, joint_state_reason=why, size={"score": None, "reason": why})
        return _result("prompt_alignment", 0.0, "fraction", "nothing understood: not aligned", details)
    halves = []
    if typical_largest and largest_extent:
        size = size_score(largest_extent, typical_largest, size_factor)
        details["size"] = {"score": size.score, "reason": size.reason, "ratio": size.ratio, "requested": size_requested,
                           "largest_extent_m": largest_extent, "target_m": typical_largest * size_factor}
        halves.append(size.score)
    else:
        details["size"] = {"score": None, "reason": "no typical size known for the category or no extent measured"}
    if state_requested and joint_checks:
        scores = []
        for c in joint_checks:
            if c.fraction is None:
                scores.append(0.0)
                details["joints"].append({"joint": c.joint, "band": c.band, "score": 0.0, "reason": "closed end unknown"})
                continue
            sc, reason = target_score(c) if c.target is not None else band_score(c.fraction, c.band)
            if sc is not None:
                scores.append(sc)
            details["joints"].append(
                {"joint": c.joint, "band": c.band, "label": c.label, "fraction": c.fraction, "score": sc, "reason": reason,
                 "target": c.target.model_dump() if c.target is not None else None}
            )
        js = float(np.mean(scores)) if scores else None
        details["joint_state_score"] = js
        if js is not None:
            halves.append(js)
    else:
        details.update(joint_state_score=None, joint_state_reason="no state the request asks names a part of this object"
                       if state_requested else "the request asks for no joint state")
    return _result("prompt_alignment", float(np.mean(halves)) if halves else None, "fraction",
                   "reported: 0.5 size + 0.5 joint state, each 1 / 0.5 / 0", details)
