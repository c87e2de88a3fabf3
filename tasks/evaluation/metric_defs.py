"""The evaluation's metrics: ``fn(context, runs) -> [MetricResult]`` per metric,
registered with :func:`register_metric` into :data:`METRICS` in evaluation
order (group and description from :data:`asset2sim.schemas.metrics.METRIC_INFO`).
Definitions: ``docs/design/metrics.md``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable

import numpy as np

from asset2sim.schemas.metrics import METRIC_INFO
from asset2sim.schemas.metrics import unit as unit_of
from asset2sim.schemas.report import MetricResult
from asset2sim.tasks.check import metrics as spec_metrics
from asset2sim.tasks.check import operability, recorded_runs, robust_rest, sweep
from asset2sim.tasks.check import task_execution
from asset2sim.tasks.check.force_ranges import force_metric
from asset2sim.tasks.check.probes import probes_metric
from asset2sim.tasks.evaluation import semantic_metrics as sem
from asset2sim.tasks.evaluation.engine_run import EngineRun
from asset2sim.tasks.evaluation.eval_context import Context, hold_required
from asset2sim.tasks.interpret.named_parts import requested_joints, unmatched_properties
from asset2sim.tasks.interpret.request import request_warnings
from asset2sim.tasks.interpret.size_priors import scaled_mass_range
from asset2sim.tasks.check import as_asked

#: Largest ground penetration during the rest test that passes, m.
GROUND_PENETRATION_TOL = 0.005
#: Explosion thresholds (divergence): root speed m/s, revolute rad/s, prismatic m/s.
EXPLOSION_ROOT_SPEED = 10.0
EXPLOSION_JOINT_SPEED_REVOLUTE = 100.0
EXPLOSION_JOINT_SPEED_PRISMATIC = 10.0
#: Root travel that counts as an explosion: max(1 m, 5 x largest extent).
EXPLOSION_TRAVEL_MIN = 1.0
EXPLOSION_TRAVEL_FACTOR = 5.0


# ------------------------------------------------------------------ registry
MetricFn = Callable[[Context, dict[str, EngineRun]], list[MetricResult]]


@dataclass
class MetricSpec:
    """A registered metric: ``fn(context, runs) -> [MetricResult]``; ``group``
    ``physical`` / ``semantic`` / ``behaviour``; ``description`` one line."""

    name: str
    group: str
    fn: MetricFn
    description: str


METRICS: dict[str, MetricSpec] = {}


def register_metric(name: str) -> Callable[[MetricFn], MetricFn]:
    """Decorator registering ``fn(context, runs) -> list[MetricResult]`` for metric ``name``, with the group and
    description of the registry table (:data:`asset2sim.schemas.metrics.METRIC_INFO`; else ``physical``, none)."""
    info = METRIC_INFO.get(name)

    def deco(fn: MetricFn) -> MetricFn:
        METRICS[name] = MetricSpec(name, info.group if info else "physical", fn, info.description if info else "")
        return fn

    return deco


def metric_names() -> list[str]:
    """Registered metric names in evaluation order."""
    return list(METRICS)


# ------------------------------------------------------------------ metrics
def _skip(name: str, unit: str, engine: str, reason: str) -> MetricResult:
    return MetricResult(name=name, value=None, unit=unit, passed=None, threshold="", details={"skipped": reason}, engine=engine)


def _per_engine(runs: dict[str, EngineRun], name: str, unit: str, measure: Callable[[str, EngineRun], MetricResult],
                missing: Callable[[EngineRun], bool] = lambda r: r.trace is None) -> list[MetricResult]:
    """``measure(engine, run)`` of every engine in ``runs``; skipped (the run's error, else "not measured") where ``missing(run)``."""
    return [_skip(name, unit, e, r.error or "not measured") if missing(r) else measure(e, r) for e, r in runs.items()]


@register_metric("penetration")
def _m_penetration(ctx: Context, runs: dict[str, EngineRun]) -> list[MetricResult]:
    return _per_engine(runs, "penetration", "mm", lambda e, r: r.penetration, lambda r: r.penetration is None)


@register_metric("ground_penetration")
def _m_ground(ctx: Context, runs: dict[str, EngineRun]) -> list[MetricResult]:
    return _per_engine(runs, "ground_penetration", "mm", lambda e, r: _ground_result(ctx, e, r.ground_series),
                       lambda r: r.ground_series is None)


def _ground_result(ctx: Context, engine: str, g: np.ndarray) -> MetricResult:
    """``ground_penetration`` (mm) of one engine from its ground penetration per rest-test step ``g`` (K,) m."""
    finite = g[np.isfinite(g)]
    worst = float(np.max(finite)) if len(finite) else 0.0
    at = int(np.argmax(finite)) if len(finite) else 0
    return MetricResult(name="ground_penetration", value=worst * 1000.0, unit="mm",
                        passed=bool(worst <= GROUND_PENETRATION_TOL and len(finite) == len(g)),
                        threshold=f"<= {GROUND_PENETRATION_TOL * 1000:g} mm at every step of the rest test",
                        details={"worst_step": at, "worst_time_s": (at + 1) * ctx.conventions.timestep, "steps": int(len(g))},
                        engine=engine)


@register_metric("rest_stability")
def _m_rest(ctx: Context, runs: dict[str, EngineRun]) -> list[MetricResult]:
    return _per_engine(runs, "rest_stability", "m", lambda e, r: spec_metrics.rest_stability(r.trace, ctx.conventions, engine=e))


@register_metric("oscillation")
def _m_osc(ctx: Context, runs: dict[str, EngineRun]) -> list[MetricResult]:
    return _per_engine(runs, "oscillation", "joints", lambda e, r: spec_metrics.oscillation(r.trace, ctx.conventions, engine=e))


def divergence_check(root: np.ndarray, joints: dict[str, np.ndarray], joint_types: dict[str, str],
                     dt: float, largest_extent: float) -> dict[str, Any]:
    """Divergence (non-finite values or an explosion) of one run: ``root`` (K, 3) m
    and ``joints`` (joint -> (K,)) per step, ``dt`` s, ``largest_extent`` m. Returns
    {diverged, nan, reasons, peak_root_speed m/s, root_travel m, travel_limit, peak_joint_speed}."""
    reasons = []
    nan = not (np.all(np.isfinite(root)) and all(np.all(np.isfinite(v)) for v in joints.values()))
    if nan:
        reasons.append("non-finite pose or joint position")
    r = root[np.all(np.isfinite(root), axis=1)] if len(root) else root
    speed = float(np.max(np.linalg.norm(np.diff(r, axis=0), axis=1)) / dt) if len(r) > 1 else 0.0
    travel = float(np.max(np.linalg.norm(r - r[0], axis=1))) if len(r) else 0.0
    travel_lim = max(EXPLOSION_TRAVEL_MIN, EXPLOSION_TRAVEL_FACTOR * largest_extent)
    if speed > EXPLOSION_ROOT_SPEED:
        reasons.append(f"root speed {speed:.3g} m/s > {EXPLOSION_ROOT_SPEED} m/s")
    if travel > travel_lim:
        reasons.append(f"root travelled {travel:.3g} m > {travel_lim:.3g} m")
    peak = {}
    for n, q in joints.items():
        q = q[np.isfinite(q)]
        v = float(np.max(np.abs(np.diff(q))) / dt) if len(q) > 1 else 0.0
        peak[n] = v
        lim = EXPLOSION_JOINT_SPEED_PRISMATIC if joint_types.get(n) == "prismatic" else EXPLOSION_JOINT_SPEED_REVOLUTE
        if v > lim:
            reasons.append(f"joint {n} speed {v:.3g} > {lim}")
    return {"diverged": bool(reasons), "nan": bool(nan), "reasons": reasons, "peak_root_speed": speed, "root_travel": travel,
            "travel_limit": travel_lim, "peak_joint_speed": peak}


@register_metric("divergence")
def _m_div(ctx: Context, runs: dict[str, EngineRun]) -> list[MetricResult]:
    return _per_engine(runs, "divergence", "", lambda e, r: _divergence_result(ctx, e, r),
                       lambda r: r.trace is None or r.root_series is None)


def _divergence_result(ctx: Context, engine: str, r: EngineRun) -> MetricResult:
    """``divergence`` of one engine's rest test (:func:`divergence_check`, or the trace's own divergence)."""
    largest = float(np.max(r.extents)) if r.extents is not None else 0.0
    d = divergence_check(r.root_series, r.joint_series, r.trace.joint_types, ctx.conventions.timestep, largest)
    d["nan"] = d["nan"] or r.trace.diverged
    d["diverged"] = d["diverged"] or r.trace.diverged
    threshold = (f"finite, root speed <= {EXPLOSION_ROOT_SPEED} m/s, joint speed <= {EXPLOSION_JOINT_SPEED_REVOLUTE} rad/s "
                 f"({EXPLOSION_JOINT_SPEED_PRISMATIC} m/s), root travel <= max({EXPLOSION_TRAVEL_MIN} m, "
                 f"{EXPLOSION_TRAVEL_FACTOR} x largest extent)")
    return MetricResult(name="divergence", value=float(d["diverged"]), unit="flag", passed=not d["diverged"], threshold=threshold,
                        details=d, engine=engine)


@register_metric("joint_hold")
def _m_hold(ctx: Context, runs: dict[str, EngineRun]) -> list[MetricResult]:
    return _per_engine(runs, "joint_hold", "rad", lambda e, r: _hold_result(ctx, e, r))


def _hold_result(ctx: Context, engine: str, r: EngineRun) -> MetricResult:
    """``joint_hold`` of one engine: where each task joint came to rest (rad or m) after settle + test, against its
    band (:func:`~asset2sim.tasks.check.metrics.joint_settling`)."""
    settling = spec_metrics.joint_settling(r.trace, {"revolute": ctx.sag_tol_revolute, "prismatic": ctx.sag_tol_prismatic},
                                           initial=ctx.initial_state)
    per, failing = {}, []
    for n in ctx.task_joints:
        if n not in settling:
            continue
        s = settling[n]
        q_end = float(r.trace.joints[n][-1])
        c = ctx.closed.get(n)
        per[n] = {"drift": s.settled, "peak": s.peak, "moving": s.moving, "unit": "m" if ctx.joints[n].type == "prismatic" else "rad",
                  "tolerance": s.band, "q_initial": ctx.initial_state.get(n), "q_end": q_end,
                  "fraction_initial": c.fraction(ctx.initial_state.get(n, 0.0)) if c else None,
                  "fraction_end": c.fraction(q_end) if c else None, "failed": not s.held}
        if not s.held:
            failing.append(n)
    return MetricResult(name="joint_hold", value=float(max([v["drift"] for v in per.values()], default=0.0)), unit="rad/m",
                        passed=(not failing) if per else None,
                        threshold=(f"every task joint at rest after settle + test within max({ctx.sag_tol_revolute} rad / "
                                   f"{ctx.sag_tol_prismatic} m, {spec_metrics.REST_BAND_RANGE_SHARE:.0%} of its range) of its "
                                   "initial state"),
                        details={"joints": per, "failing": failing}, engine=engine)


@register_metric("scale_deviation")
def _m_scale(ctx: Context, runs: dict[str, EngineRun]) -> list[MetricResult]:
    return [sem.scale_deviation(ctx.scale, ctx.reference_scale, scale_source=ctx.scale_source)]


@register_metric("initial_joint_deviation")
def _m_initdev(ctx: Context, runs: dict[str, EngineRun]) -> list[MetricResult]:
    if ctx.reference_dir is None:
        return [MetricResult(name="initial_joint_deviation", value=None, unit="rad", passed=None,
                             details={"reason": "no reference given"}, engine="none")]
    m = sem.initial_joint_deviation(ctx.initial_state, ctx.reference_state, ctx.task_joints,
                                    {n: j.type for n, j in ctx.joints.items()})
    m.details["reference_rule"] = ctx.reference_rule
    return [m]


def _first_run(runs: dict[str, EngineRun]) -> EngineRun | None:
    return next((r for r in runs.values() if r.extents is not None), None)


def _largest_extent(ctx: Context, runs: dict[str, EngineRun]) -> tuple[float | None, str]:
    """Largest extent (m) of the object: closed state when known, else initial."""
    if ctx.closed_extents is not None and float(np.max(ctx.closed_extents)) > 0:
        return float(np.max(ctx.closed_extents)), "closed state"
    r = _first_run(runs)
    if r is not None and float(np.max(r.extents)) > 0:
        return float(np.max(r.extents)), "initial state"
    return None, "unknown"


@register_metric("total_mass")
def _m_mass(ctx: Context, runs: dict[str, EngineRun]) -> list[MetricResult]:
    r = _first_run(runs)
    if r is None:
        total = sum((li.mass if li.mass is not None else 1.0) for li in ctx.links.values())
        per = {n: {"mass": li.mass if li.mass is not None else 1.0, "source": "file" if li.mass is not None else "default 1 kg"} for n, li in ctx.links.items()}
    else:
        total = sum(v["mass"] for v in r.masses.values())
        per = r.masses
    largest, where = _largest_extent(ctx, runs)
    extents = ctx.closed_extents if ctx.closed_extents is not None else (r.extents if r is not None else None)
    rng, f = scaled_mass_range(ctx.prior, extents)
    m = sem.mass_plausibility(total, rng, per_link=per, category=ctx.category)
    m.details.update({"size_factor_vs_prior": f, "largest_extent_m": largest, "extent_state": where,
                      "base_mass_range_kg": ctx.prior.get("base_mass_range"), "prior_source": ctx.prior.get("source")})
    if rng is not None:
        m.threshold = f"{rng[0]:.3g} kg <= m <= {rng[1]:.3g} kg (category range scaled to the asset's size, f = {f:.3g})"
    return [m]


@register_metric("prompt_alignment")
def _m_prompt(ctx: Context, runs: dict[str, EngineRun]) -> list[MetricResult]:
    if not ctx.prompt:
        return [MetricResult(name="prompt_alignment", value=None, unit="fraction", details={"reason": "no prompt"}, engine="none")]
    spec = ctx.request
    if spec is None:
        return [MetricResult(name="prompt_alignment", value=None, unit="fraction",
                             details={"reason": ctx.request_error or "request not parsed"}, engine="none")]
    r = _first_run(runs)
    centres = r.link_centres if r is not None else {}
    largest, where = _largest_extent(ctx, runs)
    req, unmatched = requested_joints(spec, ctx.joints, ctx.semantics, centres, ctx.task_joints, ctx.category,
                                      r.link_volumes if r is not None else {})
    checks = []
    for name, band, label, phrase, target in req:
        c = ctx.closed.get(name)
        q = ctx.initial_state[name]
        checks.append(sem.JointStateCheck(name, band, c.fraction(q) if c else None, label, phrase, target,
                                          c.direction * (q - c.q_closed) if c else None, ctx.joints[name].type))
    dims = ctx.prior.get("base_dims")
    m = sem.prompt_alignment(size_requested=spec.size_class is not None, largest_extent=largest, typical_largest=dims[0] if dims else None,
                             size_factor=float(ctx.prior.get("factor", 1.0)), joint_checks=checks,
                             state_requested=bool(spec.joint_states), unmatched_requests=unmatched, text=ctx.prompt,
                             understood=spec.understood, warnings=request_warnings(spec, unmatched, ctx.category))
    m.details.update({"size_class": spec.size_class, "category": ctx.category, "variant": ctx.prior.get("variant"),
                      "extent_state": where, "prior_note": ctx.prior.get("note")})
    return [m]


def _target_miss(c: sem.JointStateCheck) -> dict[str, Any] | None:
    """The unmet item of a joint asked by a number or an end (:func:`sem.target_score` below 1: outside its tolerance),
    None when met or not graded; the same tolerances as prompt alignment's full score."""
    t = c.target
    score, why = sem.target_score(c)
    if score is None or score >= 1.0 or t is None:
        return None
    if c.fraction is None or (t.kind in ("angle", "distance") and c.opening is None):
        return as_asked.not_applied(c.phrase, f"{c.joint}: {why}", c.joint)
    if t.kind == "angle" and c.joint_type == "prismatic":
        return as_asked.not_applied(c.phrase, f"{c.joint}: {why}", c.joint)
    if t.kind == "end":
        end = 0.0 if c.fraction < 0.5 else 1.0
        return as_asked.missed(c.phrase, kind="state", target=end, achieved=c.fraction, unit="opening fraction",
                               tolerance=sem.END_FRACTION_TOL, joint=c.joint, reason=f"'{t.end}' is a travel end")
    asked = float(t.value or 0.0)
    achieved, unit = (c.fraction, "opening fraction") if t.kind == "fraction" else (c.opening, "m" if t.kind == "distance" else "rad")
    tol = max(sem.TARGET_REL_TOL * abs(asked), sem.TARGET_ABS_TOL[t.kind])
    return as_asked.missed(c.phrase, kind="state", target=asked, achieved=float(achieved), unit=unit, tolerance=tol, joint=c.joint)


def _size_along(ext: np.ndarray, dimension: str) -> float:
    """The closed extent (m) along a size ``dimension`` of ``ext`` ((3,) m, world axes): height z, width / depth the
    larger / smaller horizontal, length / largest the largest (as refine's ``request_apply`` reads sizes)."""
    horiz = sorted([float(ext[0]), float(ext[1])], reverse=True)
    return {"height": float(ext[2]), "width": horiz[0], "depth": horiz[1]}.get(dimension, float(np.max(ext)))


@register_metric("request_met")
def _m_request_met(ctx: Context, runs: dict[str, EngineRun]) -> list[MetricResult]:
    """As asked (:mod:`asset2sim.tasks.check.as_asked`) measured on the output itself: phrases of the request naming
    no part of it, replaced by a later phrase for the same part, masses / materials / joint parameters naming a part
    it lacks; each requested joint's state from its closed end (bands, numbers and ends, prompt alignment's
    tolerances), sizes in numbers against the closed extents, the total mass asked against the simulator's.
    Not measured without a request or when none of it was understood."""
    if not ctx.prompt:
        return [as_asked.not_measured("no request")]
    spec = ctx.request
    if spec is None:
        return [as_asked.not_measured(ctx.request_error or "request not parsed", ctx.prompt)]
    if not spec.understood:
        return [as_asked.not_measured("no word of the request was understood", ctx.prompt)]
    r = _first_run(runs)
    req, unmatched = requested_joints(spec, ctx.joints, ctx.semantics, r.link_centres if r is not None else {}, ctx.task_joints,
                                      ctx.category, r.link_volumes if r is not None else {})
    what = ctx.category or "object"
    unmet = [as_asked.not_applied(p, f"names no part of this {what}") for p in unmatched]
    unmet += as_asked.overridden_items(spec)
    won = {item[3] for item in req}
    unmet += [as_asked.not_applied(js.phrase, "every part it names is set by a later phrase of the request") for js in spec.joint_states
              if js.names_part and js.selector == "label" and js.phrase not in won and js.phrase not in unmatched]
    unmet += [as_asked.not_applied(p, why) for p, why in unmatched_properties(spec, ctx.joints, ctx.semantics, ctx.task_joints, ctx.category)]
    graded, not_graded = len(unmet), []
    phrases = {js.phrase: js for js in spec.joint_states}
    bands = []
    for name, band, label, phrase, target in req:
        c, q = ctx.closed.get(name), ctx.initial_state.get(name)
        if c is None or q is None:
            not_graded.append({"phrase": phrase, "joint": name, "reason": "closed end unknown"})
            continue
        check = sem.JointStateCheck(name, band, c.fraction(q), label, phrase, target, c.direction * (q - c.q_closed), ctx.joints[name].type)
        if target is not None and sem.target_score(check)[0] is None:
            not_graded.append({"phrase": phrase, "joint": name, "reason": sem.target_score(check)[1]})
            continue
        graded += 1
        if target is not None or phrase not in phrases:
            item = _target_miss(check) if target is not None else as_asked.band_missed(phrase or band, name, band, abs(check.fraction))
            if item is not None:
                unmet.append(item)
            continue
        bands.append((phrases[phrase], name, as_asked.band_missed(phrase or band, name, band, abs(check.fraction))))
    missed_bands, spared = as_asked.object_states(bands)
    unmet += missed_bands
    not_graded += spared
    graded -= len(spared)
    for sz in spec.sizes:
        if sz.dimension == "volume":
            not_graded.append({"phrase": sz.phrase, "reason": "a volume is measured by refine on the closed object's convex hull "
                                                             "(report.json request.quantities); the evaluation measures extents"})
            continue
        if ctx.closed_extents is None:
            not_graded.append({"phrase": sz.phrase, "reason": "closed extents not measured"})
            continue
        graded += 1
        got = _size_along(np.asarray(ctx.closed_extents, float), sz.dimension)
        tol = max(sem.TARGET_REL_TOL * sz.value, sem.TARGET_ABS_TOL["distance"])
        if abs(got - sz.value) > tol:
            unmet.append(as_asked.missed(sz.phrase, kind="size", target=sz.value, achieved=got, unit="m", tolerance=tol,
                                         reason=f"{sz.dimension} of the closed object"))
    total = next((p for p in spec.properties if (p.mass is not None or p.mass_range is not None) and p.label is None), None)
    if total is not None:
        graded += 1
        got = sum(v["mass"] for v in r.masses.values()) if r is not None else sum(
            (li.mass if li.mass is not None else 1.0) for li in ctx.links.values())
        lo, hi = (float(total.mass), float(total.mass)) if total.mass is not None else total.mass_range
        target = min(max(float(got), lo), hi)  # a range is met anywhere in it: its nearer end
        tol = sem.TARGET_REL_TOL * target
        if abs(got - target) > tol:
            unmet.append(as_asked.missed(total.phrase, kind="mass", target=target, achieved=float(got), unit="kg", tolerance=tol,
                                         reason="total mass in the simulator" + ("" if lo == hi else f" (asked {lo:g}-{hi:g} kg)")))
    m = as_asked.request_met_metric(unmet, request=ctx.prompt, graded=graded, not_graded=not_graded,
                                    source="the evaluation (the output measured, closed ends its own)")
    return [m]


@register_metric("probes")
def _m_probes(ctx: Context, runs: dict[str, EngineRun]) -> list[MetricResult]:
    r = runs.get("pybullet")
    if r is None:
        return [_skip("probes", "failed probes", "pybullet", "probes run in PyBullet only; pybullet not among the engines")]
    if r.error and not r.probes:
        return [_skip("probes", "failed probes", "pybullet", r.error)]
    return [probes_metric(r.probes)]


# ------------------------------------------------ interaction under manipulation
@register_metric("joint_sweep")
def _m_sweep(ctx: Context, runs: dict[str, EngineRun]) -> list[MetricResult]:
    """:mod:`asset2sim.tasks.check.sweep` in every engine that loaded the asset
    (its own fixed-root session), closed ends from ``ctx.closed``."""
    closed = {n: (c.q_closed, c.direction, c.open_range) for n, c in ctx.closed.items() if n in ctx.movable}

    def graded(e: str, r: EngineRun) -> MetricResult:
        r.sweep = recorded_runs.sweep_run(e, ctx.sim_object, closed, recorded=r.recorded)
        return sweep.sweep_metric(r.sweep)

    return _per_engine(runs, "joint_sweep", unit_of("joint_sweep"), graded, lambda r: bool(r.error))


@register_metric("operability")
def _m_operability(ctx: Context, runs: dict[str, EngineRun]) -> list[MetricResult]:
    """:mod:`asset2sim.tasks.check.operability` in every engine that loaded the asset (its own fixed-root session
    with gravity), closed ends from ``ctx.closed``, operating ranges by ``ctx.category`` and part label."""
    closed = {n: (c.q_closed, c.direction, c.open_range) for n, c in ctx.closed.items() if n in ctx.movable}
    labels = {link: lab for link, (_, lab) in ctx.semantics.items()}

    def graded(e: str, r: EngineRun) -> MetricResult:
        run = recorded_runs.operability_run(e, ctx.sim_object, closed, category=ctx.category, labels=labels,
                                            recorded=r.recorded)
        m = operability.operability_metric(run)
        m.details["root"] = "fixed (mounted)" if ctx.root_fixed else "fixed (held by the other hand)"
        return m

    return _per_engine(runs, "operability", unit_of("operability"), graded, lambda r: bool(r.error))


@register_metric("robust_rest")
def _m_robust(ctx: Context, runs: dict[str, EngineRun]) -> list[MetricResult]:
    """:mod:`asset2sim.tasks.check.robust_rest` in every engine that loaded the
    asset, the root as the asset declares (``ctx.root_fixed``: skipped)."""
    def graded(e: str, r: EngineRun) -> MetricResult:
        r.robust_rest = recorded_runs.robust_rest_run(e, ctx.sim_object, recorded=r.recorded)
        return robust_rest.robust_rest_metric(r.robust_rest)

    return _per_engine(runs, "robust_rest", unit_of("robust_rest"), graded, lambda r: bool(r.error))


def _task_joints(ctx: Context) -> dict[str, tuple[float, float, float]]:
    """joint -> (q_closed, direction, open range) of the task's joints with a closed end and a range."""
    names = ctx.task.joints if ctx.task is not None else []
    return {n: (c.q_closed, c.direction, c.open_range) for n, c in ctx.closed.items() if n in names and c.open_range > 0}


@register_metric("task_execution")
def _m_task(ctx: Context, runs: dict[str, EngineRun]) -> list[MetricResult]:
    """:mod:`asset2sim.tasks.check.task_execution` in every engine that loaded the asset (fresh sessions, the root as
    declared), and from the same run the ``operating_force`` check (:mod:`asset2sim.tasks.check.force_ranges`). Without a
    task (``ctx.task`` None) both are skipped."""
    out = []
    labels = {link: lab for link, (_, lab) in ctx.semantics.items()}
    for e, r in runs.items():
        if ctx.task is None or r.error:
            why = r.error or "no task given (--task, the manifest's task column)"
            out += [_skip("task_execution", unit_of("task_execution"), e, why),
                    _skip("operating_force", unit_of("operating_force"), e, why)]
            continue
        joints = _task_joints(ctx)
        actions = tuple(a for a in ctx.task.actions if a in ("close", "open"))
        run = recorded_runs.task_run(e, ctx.sim_object, joints, actions=actions, targets=dict(ctx.task.targets),
                                     hold_required=hold_required(ctx, list(joints)), task=ctx.task.text, recorded=r.recorded)
        r.task = run
        tm = task_execution.task_metric(run)
        tm.details["joints_rule"] = ctx.task.rule
        out += [tm, force_metric(run, ctx.category, labels)]
    return out


@register_metric("operating_force")
def _m_force(ctx: Context, runs: dict[str, EngineRun]) -> list[MetricResult]:
    """Measured with ``task_execution`` (one gripper run gives both): nothing here."""
    return []
