"""Semantic-accuracy metrics: scale, initial joint state, mass, prompt alignment.

Plain functions over numbers, so they can be re-derived by hand and tested
without a simulator. Definitions (SPEC, "How quality is measured", "Semantic
accuracy"; the exact conventions are in ``docs/design/metrics.md``):

- **Scale deviation** |s - s_ref| / s_ref (dimensionless, reported in %), where
  s is the uniform scale of the evaluated asset relative to the *raw* input
  asset and s_ref GenSim2's ``scale`` (``reference_gensim2.json``). No pass
  threshold (reported).
- **Initial joint deviation** |q - q_ref| of the task-relevant joint(s), rad
  (revolute) or m (prismatic); the mean over the task-relevant joints is the
  value. No pass threshold (reported).
- **Total mass** kg, with a plausibility verdict against the category's mass
  range scaled to the asset's size (f = largest extent / the category's largest
  typical dimension; range [lo f^3, hi f^2] when smaller, [lo f^2, hi f^3]
  when larger: solid to thin-walled, ``asset2sim.tasks.interpret.priors.scale_mass_range``).
- **Prompt alignment** in [0, 1]: half for size, half for joint state. Each half
  scores 1 (matches), 0.5 (near miss) or 0 (miss), with a reason:

  * size: ratio r = L / L_target, L the largest extent of the asset (m) and
    L_target = size_factor(request) * largest typical dimension of the category
    (m). |ln r| <= ln 1.5 scores 1, <= ln 2.25 scores 0.5, else 0.
  * joint state: per requested joint, the opening fraction f = direction *
    (q - q_closed) / open_range (measured from the geometric closed end,
    :mod:`asset2sim.tasks.geometry.closed_state`) against the band's acceptance interval
    (``schemas.request.BAND_INTERVAL``): inside scores 1, within 0.1 of it
    0.5, else 0; the joint half is the mean over requested joints.
  * a joint asked in numbers or by an end (``RequestSpec`` joint state with a
    ``target``, ``docs/guide/requests.md``) is graded against the number instead of
    its nominal band, by :func:`target_score`: the opening o = direction *
    (q - q_closed) (rad or m) or the fraction f against the asked value,
    within 5 % of it (the request issue's tolerance; at least 0.5 deg,
    1 mm or 0.01 of the range) scores 1, within 10 % scores 0.5, else 0. An
    end target ("lever up", "switch on") scores 1 at either travel end
    (f <= 0.03 or f >= 0.97: which end is high is refine's geometric decision,
    checked by its own tests), else 0. A distance asked on a hinge (the gap at
    the part's far edge) is not graded here (the hinge radius is geometry the
    evaluation does not re-derive) and says so.
  * When the request names no joint state, the score is the size half alone
    (and vice versa); with neither, the metric is not applicable (value None).
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
    """|s - s_ref| / s_ref in percent.

    Args:
        scale: uniform scale of the evaluated asset relative to the raw input
            (dimensionless) or None when unknown.
        reference_scale: GenSim2's ``scale`` (dimensionless) or None.
        scale_source: where ``scale`` came from (for the report).

    Returns:
        MetricResult ``scale_deviation`` (unit ``%``, ``passed`` None); value
        None when either scale is missing or s_ref <= 0.
    """
    details: dict[str, Any] = {"scale": scale, "reference_scale": reference_scale, "scale_source": scale_source}
    value = None
    if scale is None:
        details["reason"] = "scale of the evaluated asset unknown"
    elif reference_scale is None or not reference_scale > 0:
        details["reason"] = "the reference has no scale"
    else:
        value = abs(float(scale) - float(reference_scale)) / float(reference_scale) * 100.0
    return _result("scale_deviation", value, "%", "reported: |s - s_ref| / s_ref (no SPEC threshold)", details)


def initial_joint_deviation(
    state: dict[str, float],
    reference_state: dict[str, float],
    joints: list[str],
    joint_types: dict[str, str],
) -> MetricResult:
    """Mean |q - q_ref| over the task-relevant ``joints``.

    Args:
        state: joint -> initial position of the evaluated asset (rad or m).
        reference_state: joint -> reference position (rad or m, same units).
        joints: task-relevant joint names; joints missing from either state are
            skipped and listed in ``details.skipped``.
        joint_types: joint -> ``revolute``/``continuous``/``prismatic``.

    Returns:
        MetricResult ``initial_joint_deviation``; unit ``rad`` (``m`` when every
        compared joint is prismatic, ``mixed`` otherwise); value None when no
        joint could be compared.
    """
    per = {}
    skipped = []
    for j in joints:
        if j not in state or j not in reference_state:
            skipped.append(j)
            continue
        per[j] = {
            "q": float(state[j]),
            "q_ref": float(reference_state[j]),
            "deviation": abs(float(state[j]) - float(reference_state[j])),
            "unit": "m" if joint_types.get(j) == "prismatic" else "rad",
        }
    units = {v["unit"] for v in per.values()}
    unit = units.pop() if len(units) == 1 else ("mixed" if units else "rad")
    value = float(np.mean([v["deviation"] for v in per.values()])) if per else None
    return _result("initial_joint_deviation", value, unit, "reported: |q - q_ref| of the task-relevant joint (no SPEC threshold)",
                   {"joints": per, "skipped": skipped})


def mass_plausibility(
    total_mass: float,
    mass_range: tuple[float, float] | None,
    *,
    per_link: dict[str, dict[str, Any]] | None = None,
    category: str | None = None,
) -> MetricResult:
    """Total mass (kg) and whether it lies in the plausible range.

    Args:
        total_mass: sum of the link masses the simulator uses, kg.
        mass_range: (low, high) kg plausible for an object of this category *at
            the asset's size* (the caller scales the category's range, see
            :func:`asset2sim.tasks.check.request_match.scaled_mass_range`), or None when no
            prior exists (then ``passed`` is None).
        per_link: link -> {mass, source} for the report.
        category: for the report.

    Raises:
        ValueError: ``mass_range`` with low > high, or a non-finite mass.
    """
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


def size_score(largest_extent: float, typical_largest: float, size_factor: float = 1.0) -> tuple[float, str, float]:
    """Size half of prompt alignment.

    Args:
        largest_extent: largest side of the asset's axis-aligned bounding box at
            its initial state, m.
        typical_largest: largest typical dimension of the category, m.
        size_factor: multiplier the request's size words imply (dimensionless).

    Returns:
        (score in {0, 0.5, 1}, reason, ratio L / L_target).

    Raises:
        ValueError: non-positive inputs.
    """
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
    reason = (
        f"largest extent {largest_extent:.3f} m vs target {target:.3f} m "
        f"(typical {typical_largest:.3f} m x {size_factor:g}): ratio {r:.2f}, {verdict}"
    )
    return score, reason, r


def band_score(fraction: float, band: str) -> tuple[float, str]:
    """Joint-state score of one joint: opening fraction vs the band's interval.

    Args:
        fraction: opening fraction f (0 closed, 1 fully open), dimensionless.
        band: a key of ``schemas.request.BAND_INTERVAL``.

    Raises:
        KeyError: unknown band.
    """
    lo, hi = BAND_INTERVAL[band]
    if lo <= fraction <= hi:
        return 1.0, f"opening {fraction:.2f} inside {band} [{lo}, {hi}]"
    dist = lo - fraction if fraction < lo else fraction - hi
    if dist <= BAND_HALF_MARGIN:
        return 0.5, f"opening {fraction:.2f} just outside {band} [{lo}, {hi}] (by {dist:.2f})"
    return 0.0, f"opening {fraction:.2f} outside {band} [{lo}, {hi}] (by {dist:.2f})"


#: Relative tolerance of a number asked in a request (5 %, the request
#: issue's "numeric requests land within 5 %"), its half-score bound, and
#: the absolute floors per kind (rad, m, fraction of the range).
TARGET_REL_TOL = 0.05
TARGET_HALF_REL_TOL = 0.10
TARGET_ABS_TOL = {"angle": math.radians(0.5), "distance": 1e-3, "fraction": 0.01}
#: Opening fraction within which a joint sits at a travel end (the closed band's width).
END_FRACTION_TOL = 0.03


@dataclass
class JointStateCheck:
    """One requested joint: its band and measured opening fraction.

    ``target`` (a :class:`asset2sim.schemas.request.StateTarget`) replaces the
    band when the request asked a number or an end; ``opening`` is then
    direction * (q - q_closed) (rad for revolute, m for prismatic) and
    ``joint_type`` the URDF joint type.
    """

    joint: str
    band: str
    fraction: float | None
    label: str | None = None
    phrase: str = ""
    target: StateTarget | None = None
    opening: float | None = None
    joint_type: str = "revolute"


def target_score(check: JointStateCheck) -> tuple[float | None, str]:
    """Score of a joint asked by a number or an end (module docstring).

    Args:
        check: the joint, with ``target`` set, ``fraction`` (dimensionless) and
            ``opening`` (rad or m from the geometric closed end).

    Returns:
        (score 1 / 0.5 / 0, or None when not graded; the reason).

    Raises:
        ValueError: ``check.target`` is None.
    """
    t = check.target
    if t is None:
        raise ValueError(f"joint {check.joint}: no target to grade")
    if check.fraction is None:
        return 0.0, "closed end unknown"
    if t.kind == "end":
        at_end = check.fraction <= END_FRACTION_TOL or check.fraction >= 1.0 - END_FRACTION_TOL
        where = f"opening {check.fraction:.2f}"
        return (1.0, f"{where}: at a travel end ({t.end})") if at_end else (0.0, f"{where}: not at a travel end ({t.end})")
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
    if err <= max(TARGET_HALF_REL_TOL * abs(asked), 2 * TARGET_ABS_TOL[t.kind]):
        return 0.5, why
    return 0.0, why


def prompt_alignment(
    *,
    size_requested: bool,
    largest_extent: float | None,
    typical_largest: float | None,
    size_factor: float,
    joint_checks: list[JointStateCheck],
    state_requested: bool,
    unmatched_requests: list[str] | None = None,
    text: str = "",
) -> MetricResult:
    """Prompt alignment in [0, 1] (module docstring for the definition).

    Args:
        size_requested: the request contained size words (or a category whose
            typical size applies; the size half is scored whenever a typical
            size is known).
        largest_extent: m, or None when unknown.
        typical_largest: the category's largest typical dimension, m, or None.
        size_factor: the request's size multiplier.
        joint_checks: the requested joints with their measured fractions.
        state_requested: the request asked for a joint state.
        unmatched_requests: joint-state phrases that matched no joint (score 0).
        text: the request, for the report.
    """
    details: dict[str, Any] = {"request": text, "size": None, "joints": []}
    halves = []
    if typical_largest and largest_extent:
        s, reason, ratio = size_score(largest_extent, typical_largest, size_factor)
        details["size"] = {
            "score": s,
            "reason": reason,
            "ratio": ratio,
            "requested": size_requested,
            "largest_extent_m": largest_extent,
            "target_m": typical_largest * size_factor,
        }
        halves.append(s)
    else:
        details["size"] = {"score": None, "reason": "no typical size known for the category or no extent measured"}
    if state_requested:
        scores = []
        for c in joint_checks:
            if c.fraction is None:
                scores.append(0.0)
                details["joints"].append({"joint": c.joint, "band": c.band, "score": 0.0, "reason": "closed end unknown"})
                continue
            if c.target is not None:
                sc, reason = target_score(c)
            else:
                sc, reason = band_score(c.fraction, c.band)
            if sc is not None:
                scores.append(sc)
            details["joints"].append(
                {"joint": c.joint, "band": c.band, "label": c.label, "fraction": c.fraction, "score": sc, "reason": reason,
                 "target": c.target.model_dump() if c.target is not None else None}
            )
        for phrase in unmatched_requests or []:
            scores.append(0.0)
            details["joints"].append({"joint": None, "band": None, "score": 0.0, "reason": f"no joint matches {phrase!r}"})
        graded = bool(scores) or not joint_checks
        js = float(np.mean(scores)) if scores else (0.0 if graded else None)
        details["joint_state_score"] = js
        if js is not None:
            halves.append(js)
    else:
        details["joint_state_score"] = None
        details["joint_state_reason"] = "the request asks for no joint state"
    value = float(np.mean(halves)) if halves else None
    return _result("prompt_alignment", value, "fraction", "reported: 0.5 size + 0.5 joint state, each 1 / 0.5 / 0", details)
