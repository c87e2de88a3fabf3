"""The evaluation of an asset, ``evaluation.json`` and ``report.html``: one record, one reading.

A refine's evaluation is its own record presented (:func:`refined_evaluation`): the metrics of ``report.json``, which
decided the verdict, and the semantic measures beside them (scale and state against GenSim2's reference, mass
plausibility, prompt alignment), with the runs the checks were graded from as the report's evidence; nothing is read
back or simulated again. Any other folder, a refine's output included, is read into the asset model the refine uses
(:func:`asset2sim.tasks.synthesize.context.build_context`; the folder's files through
:class:`~asset2sim.refined_asset.RefinedAsset`) and measured by the same checks
(:func:`asset2sim.tasks.check.postcheck.check_object`, :func:`asset2sim.tasks.check.as_asked.as_asked_tier`) with the
closed ends its ``report.json`` recorded, so ``asset2sim evaluate OUT`` gives the verdict the refine gave
(:func:`evaluate_asset`). Definitions: ``docs/design/metrics.md``.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from asset2sim import output_folder
from asset2sim.atomic import jsonable, write_json
from asset2sim.engines.source import SimObject
from asset2sim.inert import one_line
from asset2sim.output_folder import EVALUATION_NAME, REPORT_HTML_NAME
from asset2sim.output_paths import raise_refusal
from asset2sim.refined_asset import RefinedAsset
from asset2sim.schemas.config import RefineConfig, SimConventions
from asset2sim.schemas.evaluation import Evaluation
from asset2sim.schemas.overlay import Overlay
from asset2sim.schemas.realism import ClipSet
from asset2sim.schemas.report import MetricResult, RefineReport
from asset2sim.engines.base import EngineUnavailable
from asset2sim.schemas.metrics import unit
from asset2sim.tasks.check import as_asked, manipulation, postcheck, probes as probe_tier, task_tier
from asset2sim.tasks.check.verdict import readiness
from asset2sim.tasks.evaluation import clips as clip_files, semantic_metrics as sem
from asset2sim.tasks.evaluation.folder_reading import (EvaluationError, closed_ends, file_overlay, read_records, reference_state,
                                                       sim_object, stated_scale)
from asset2sim.tasks.evaluation.report_html import portable_urdf, write_report
from asset2sim.tasks.geometry.closed_state import ClosedState, closed_tuples
from asset2sim.tasks.ingest import partnet_mobility
from asset2sim.tasks.ingest.errors import AssetError
from asset2sim.tasks.ingest.extract import extract_asset
from asset2sim.tasks.interpret.size_priors import scaled_mass_range, size_mass_prior
from asset2sim.tasks.interpret.request import request_warnings
from asset2sim.tasks.synthesize.context import EstimationContext, build_context
from asset2sim.tasks.synthesize.request_apply import StateResolution, task_relevant_joints
from asset2sim.tasks.tune.attempt import Attempt
from asset2sim.urdf import MOVABLE, UrdfError, UrdfModel, read_urdf

__all__ = ["Evaluation", "EvaluationError", "EngineRun", "clip_joints", "evaluate_asset", "refined_evaluation", "write_evaluation"]


@dataclass
class EngineRun:
    """The runs one engine's verdicts were graded from, the report's evidence: the rest test (``trace``, per-step
    ``root_series`` (K, 3) m and ``joint_series`` joint -> (K,) rad or m), the manipulation tiers' runs
    (``robust_rest``, ``sweep``, ``task``) and the probes; ``error`` when the engine could not run."""

    engine: str
    error: str | None = None
    trace: Any = None
    root_series: np.ndarray | None = None
    joint_series: dict[str, np.ndarray] = field(default_factory=dict)
    robust_rest: Any = None
    sweep: Any = None
    task: Any = None
    probes: list[Any] = field(default_factory=list)


@dataclass(frozen=True)
class Evidence:
    """What ``report.html`` draws beside the metrics: the evaluated ``urdf`` and its ``model`` as written, the
    folder's records (``report``, ``overlay``, ``baseline``: JSON objects or None), the measurement ``conventions``."""

    urdf: Path
    model: UrdfModel
    conventions: SimConventions
    report: dict[str, Any] | None = None
    overlay: dict[str, Any] | None = None
    baseline: dict[str, Any] | None = None


def evidence_runs(check: postcheck.PostCheck, probes: list[Any] | None = None) -> dict[str, EngineRun]:
    """engine -> :class:`EngineRun` of a post-check: PyBullet's rest test and manipulation runs (and ``probes``), the
    other engines' verdicts only (their metrics, no recording)."""
    rec = check.recording
    return {"pybullet": EngineRun(
                "pybullet", trace=rec.trace if rec else check.trace, root_series=rec.root_series if rec else None,
                joint_series=dict(rec.joint_series) if rec else {}, robust_rest=check.runs.get("robust_rest"),
                sweep=check.runs.get("joint_sweep"), task=check.runs.get("task_execution"), probes=list(probes or [])),
            **{e: EngineRun(e, error=next((str(m.details.get("error")) for m in results if m.details.get("error")), None))
               for e, results in check.engine_results.items()}}


# ---------------------------------------------------------------- the semantic measures
def semantic_metrics(ctx: EstimationContext, model: UrdfModel, state: dict[str, float], closed: dict[str, ClosedState],
                     resolution: StateResolution | None, masses: dict[str, dict[str, Any]], scale: float | None, scale_source: str,
                     reference: Path | None, length_scale: float = 1.0) -> list[MetricResult]:
    """The SPEC's semantic measures of one object, reported and never deciding the verdict: ``scale_deviation`` and
    ``initial_joint_deviation`` against GenSim2's ``reference`` folder, ``total_mass`` against the category's range at the
    object's size, ``prompt_alignment`` of the request's states (the joints ``resolution`` set them on, graded from
    the ``closed`` ends at ``state``) and size. ``masses``: link -> {"mass" kg, "source"}; ``scale``: the object's scale
    relative to the raw input (None: unknown); ``length_scale``: the object's lengths over ``ctx``'s (its closed
    extents), 1 when ``ctx`` was read from the object itself.

    Raises:
        EvaluationError: the reference folder or its files cannot be read.
    """
    ref, types = None, {j.name: j.type for j in model.joints}
    m = MetricResult(name="initial_joint_deviation", value=None, unit="rad", details={"reason": "no reference given"},
                     engine="none")
    if reference is not None:
        try:
            ref = partnet_mobility.read_reference(reference)
            ref_state, rule = reference_state(ref, model, scale)
        except (ValueError, OSError, UrdfError) as exc:
            raise EvaluationError(f"reference {reference}: {exc}") from exc
        tj = [j for j in ref.task_joints if j in state] or task_relevant_joints(ctx)
        m = sem.initial_joint_deviation(state, ref_state, tj, types)
        m.details["reference_rule"] = rule
    extents = np.asarray(ctx.closed_extents, float) * length_scale
    largest = float(np.max(extents)) if extents.size and float(np.max(extents)) > 0 else None
    prior = size_mass_prior(ctx.category, ctx.request)
    rng, f = scaled_mass_range(prior, extents)
    mass = sem.mass_plausibility(float(sum(v["mass"] for v in masses.values())), rng, per_link=masses, category=ctx.category)
    mass.details.update({"size_factor_vs_prior": f, "largest_extent_m": largest, "extent_state": "closed state",
                         "base_mass_range_kg": prior.get("base_mass_range"), "prior_source": prior.get("source")})
    if rng is not None:
        mass.threshold = f"{rng[0]:.3g} kg <= m <= {rng[1]:.3g} kg (category range scaled to the asset's size, f = {f:.3g})"
    spec = ctx.request
    aligned = MetricResult(name="prompt_alignment", value=None, unit="fraction", details={"reason": "no prompt"}, engine="none")
    if spec.text:
        # the joints the request set (``resolution.requests``, the one reading of the request)
        res = resolution or StateResolution({})
        checks = []
        for name, jr in res.requests.items():
            c, q = closed.get(name), state.get(name)
            known = c is not None and q is not None
            label = ctx.asset.link(ctx.asset.joint(name).child).semantic_label
            checks.append(sem.JointStateCheck(name, jr.band, c.fraction(q) if known else None, label, jr.phrase, jr.target,
                                              c.direction * (q - c.q_closed) if known else None, types.get(name, "revolute")))
        unmatched = [p for p, _ in res.unapplied]
        dims = prior.get("base_dims")
        aligned = sem.prompt_alignment(size_requested=spec.size_class is not None, largest_extent=largest,
                                       typical_largest=dims[0] if dims else None, size_factor=float(prior.get("factor", 1.0)),
                                       joint_checks=checks, state_requested=bool(spec.joint_states), unmatched_requests=unmatched,
                                       text=spec.text, understood=spec.understood,
                                       warnings=request_warnings(spec, unmatched, ctx.category) + res.warnings)
        aligned.details.update({"size_class": spec.size_class, "category": ctx.category, "variant": prior.get("variant"),
                                "extent_state": "closed state", "prior_note": prior.get("note")})
    return [sem.scale_deviation(scale, getattr(ref, "scale", None), scale_source=scale_source), m, mass, aligned]


def _masses(overlay: Overlay | None, model: UrdfModel) -> dict[str, dict[str, Any]]:
    """link -> {"mass" kg, "source"}: the overlay's, else the URDF's ``<inertial>``, else the engines' default 1 kg for
    a link with geometry."""
    if overlay is not None:
        return {n: {"mass": float(lp.mass), "source": "overlay.json"} for n, lp in overlay.links.items()}
    out = {}
    for n, ln in model.links.items():
        if ln.inertial is not None and ln.inertial.mass is not None:
            out[n] = {"mass": float(ln.inertial.mass), "source": "file <inertial>"}
        elif ln.collisions or ln.visuals:
            out[n] = {"mass": 1.0, "source": "engine default (no <inertial>)"}
    return out


# ---------------------------------------------------------------- a refine's record presented
def refined_evaluation(ctx: EstimationContext, att: Attempt, report: RefineReport, resolution: StateResolution | None,
                       out_dir: Path, *, reference: Path | str | None = None, shown: Path | None = None) -> Evaluation:
    """The evaluation of a refine's output from its record: ``report``'s metrics (the verdict's, decided once, with its
    failure mode) and the semantic measures, the final attempt ``att``'s runs as the report's evidence; ``ctx``: the
    refine's context (input units), ``resolution``: its reading of the request; ``out_dir``: where the output's files
    are (``shown``: the folder as its user names it). Nothing is read back or simulated."""
    t0 = time.perf_counter()
    model = read_urdf(out_dir / output_folder.URDF_NAME, mode="lenient")
    ref = Path(reference).resolve() if reference is not None else None
    state = dict(report.initial_joint_positions)
    semantic = semantic_metrics(ctx, model, state, att.closed_out, resolution, _masses(att.overlay, model), report.scale,
                                output_folder.OVERLAY_NAME, ref, length_scale=report.scale)
    ev = _evaluation((shown or out_dir) / output_folder.URDF_NAME, ref, att.closed_out, [*report.metrics, *semantic],
                     report.failure_mode, asset_id=report.asset_id, method="asset2sim", prompt=report.prompt or None,
                     category=report.category, scale=report.scale, scale_source=output_folder.OVERLAY_NAME,
                     engines=list(dict.fromkeys(["pybullet", *att.check.engine_results])), initial_state=state,
                     initial_state_source=output_folder.STATE_NAME, task_joints=task_relevant_joints(ctx),
                     seconds=time.perf_counter() - t0)
    ev._runs = evidence_runs(att.check)
    ev._context = Evidence(out_dir / output_folder.URDF_NAME, model, att.check.recording.conventions if att.check.recording else SimConventions(),
                           report=report.model_dump(mode="json"), overlay=att.overlay.model_dump(mode="json"))
    return ev


def _evaluation(urdf: Path, reference: Path | None, closed: dict[str, ClosedState], metrics: list[MetricResult], failure_mode: str,
                **fields: Any) -> Evaluation:
    """The :class:`Evaluation` of ``metrics`` (its failures ``metric@engine`` as :func:`readiness` reads them) with the
    ``closed`` ends and the other ``fields`` of :class:`Evaluation` as given."""
    return Evaluation(urdf=str(urdf), reference=str(reference) if reference else None,
                      closed_positions={n: {"q_closed": c.q_closed, "direction": c.direction, "open_range": c.open_range}
                                        for n, c in closed.items()},
                      metrics=metrics, passed=failure_mode == "none", failure_mode=failure_mode, failures=readiness(metrics).failures,
                      **fields)


def evaluate_asset(
    asset: Path | str, *, reference: Path | str | None = None, prompt: str | None = None,
    engines: tuple[str, ...] | list[str] | None = None, seed: int = 0, category: str | None = None, method: str | None = None,
    out_dir: Path | str | None = None, write_report: bool = False, probes: bool = False, task: str | None = None, clips: bool = True,
) -> Evaluation:
    """Evaluate any asset folder or URDF file with the checks a refine runs (module docstring).

    Args:
        asset: folder (its URDF found as refine finds one) or URDF file; ``overlay.json``, ``initial_state.json`` (state,
            root), ``report.json`` (the closed ends a refine decided), ``baseline.json``, ``semantics.txt`` and
            ``meta.json`` beside it are read when present.
        reference: GenSim2's reference folder (None: no reference measures); prompt: the request (None: the report's).
        engines: the engines to measure in, the manipulation tiers (sweep, operability, robust rest) in each (unavailable
            ones: skipped); None: as a refine checks, the tiers in PyBullet and the SPEC's rest metrics in the engines a
            refined folder's ``report.json`` measured in (else PyBullet alone). seed, method: recorded.
        category: overrides the folder's; the measurement conventions are the SPEC's.
        out_dir: where ``evaluation.json`` and (``write_report``) ``report.html`` and the clips (``clips``) go.
        probes: also run the passive probes (a learnability stand-in: reported, never deciding the verdict).
        task: the manipulation task the task tier performs (None: the report's task, else none).

    Raises:
        EvaluationError: the asset, its records or the reference cannot be read.
        ValueError: ``write_report`` without ``out_dir``; no engine given.
    """
    if write_report and out_dir is None:
        raise ValueError("write_report needs out_dir")
    if engines is not None and not engines:
        raise ValueError("at least one engine is needed")
    t0 = time.perf_counter()
    if reference is not None and not Path(reference).is_dir():
        raise EvaluationError(f"reference {reference}: no such folder")
    try:
        urdf = partnet_mobility.find_urdf(asset).resolve()
        files = RefinedAsset(urdf.parent, urdf.name)
        model = files.model
        desc = extract_asset(asset, category=category)
    except (AssetError, UrdfError, OSError) as exc:
        why = one_line(" ".join(str(exc).split()), 600)  # a validation refusal lists its findings after its first line
        # the reason names the asset when it holds its name (its path holds the name too)
        raise EvaluationError(why if Path(asset).name in why else f"{asset}: {why}") from exc
    notes: list[str] = []
    report, raw_report, baseline, overlay = read_records(files, notes)
    prompt = prompt if prompt is not None else getattr(report, "prompt", None)
    task = task if task is not None else getattr(report, "task", None)
    cat = category or getattr(report, "category", None) or (baseline or {}).get("category")
    every = engines is not None  # the engines named: the manipulation tiers in each of them
    recorded = sorted({m.engine for m in report.metrics} - {"none", "pybullet"}) if report is not None else []
    engines = list(dict.fromkeys(["pybullet", *(engines if every else recorded)]))
    config = RefineConfig(engines=engines)
    obj, state_source = sim_object(files, config.sim)
    state = dict(obj.state)
    physics = overlay if overlay is not None else file_overlay(model)
    closed = closed_ends(files)[0] if report is not None and report.closed_ends else {}
    if obj.fixed_base:
        notes.append("root fixed as initial_state.json declares (mounted asset): every simulation holds it, no ground plane")
    with build_context(desc, prompt or "", config, category=cat) as (ctx, kin):
        closed = closed or ctx.closed
        ct = closed_tuples(closed)
        spec = task_tier.task_spec_for(task, desc, ctx.category, task_relevant_joints(ctx), state, ct) if task else None
        if spec is not None:
            notes.append(f"task {task!r}: {', '.join(spec.actions)} {', '.join(spec.joints) or 'no joint'} ({spec.rule})"
                         + "".join(f"; {n}" for n in spec.notes))
        check = postcheck.check_object(replace(ctx, task=task), obj, config, ct, spec)
        measured = check.metrics + [m for res in check.engine_results.values() for m in res]
        measured += [m for e in engines if every and e != "pybullet" for m in _manipulation(e, obj, ct, ctx, check)]
        asked = as_asked.as_asked_tier(ctx, kin, physics.model_copy(update={"scale": 1.0}), state, closed, measured,
                                       rounds=getattr(report, "escalation", None))
        found = _probes(ctx, obj, closed, spec, notes) if probes else None
        ref = Path(reference).resolve() if reference is not None else None
        scale, source = stated_scale(report, overlay, baseline, ctx, ref)
        semantic = semantic_metrics(ctx, model, state, closed, asked.resolution, _masses(overlay, model), scale, source, ref)
        metrics = [*asked.metrics, *semantic, *([probe_tier.probes_metric(found)] if found is not None else [])]
        ev = _evaluation(urdf, ref, closed, metrics, readiness(metrics).failure_mode,
                         asset_id=getattr(report, "asset_id", None) or (baseline or {}).get("asset_id") or desc.asset_id,
                         method=method or (baseline or {}).get("method") or ("asset2sim" if overlay is not None else None),
                         prompt=prompt, category=ctx.category, scale=scale, scale_source=source, engines=list(engines),
                         initial_state=state, initial_state_source=state_source, task_joints=task_relevant_joints(ctx), notes=notes,
                         seed=seed, seconds=time.perf_counter() - t0)
    ev._runs = evidence_runs(check, found)
    ev._context = Evidence(urdf, model, config.sim, report=raw_report, overlay=files.record(output_folder.OVERLAY_NAME),
                           baseline=baseline)
    if out_dir is not None:
        clip_set = _write_clips(ev, out_dir) if write_report and clips else None
        write_evaluation(ev, out_dir, report=write_report, clips=clip_set)
    return ev


def _manipulation(engine: str, obj: SimObject, closed: dict[str, tuple[float, float, float]], ctx: EstimationContext,
                  check: postcheck.PostCheck) -> list[MetricResult]:
    """The manipulation tiers (joint sweep, operability, robust rest) of ``obj`` in another ``engine``, as the post-check
    measures them in PyBullet (the parts asked to move freely those of ``check``); skipped where the engine is not
    installed, failed where it cannot load or step the object."""
    free = tuple(sorted((check.metric("robust_rest").details.get("free_moving") or {}))) if check.runs else ()
    try:
        return manipulation.measure_manipulation(engine, obj, closed, category=ctx.category,
                                                 labels=task_tier.link_labels(ctx.asset), free_joints=free)
    except (EngineUnavailable, KeyError) as exc:  # not installed, or no such engine
        why, passed = {"skipped": str(exc)}, None
    except Exception as exc:  # the object does not load or step in this engine: a failure there
        why, passed = {"error": f"{type(exc).__name__}: {one_line(exc)}"}, False
    return [MetricResult(name=n, value=None, unit=unit(n), passed=passed, details=dict(why), engine=engine)
            for n in manipulation.MANIPULATION_METRICS]


def recorded_evaluation(out_dir: Path | str, *, reference: Path | str | None = None) -> Evaluation:
    """A refined output's ``evaluation.json`` (the record as the refine presented it; measured anew when the folder has
    none), with the runs of its checks run again on the folder (:func:`evaluate_asset`) as ``report.html``'s evidence:
    what the media phase draws, never a second verdict. Raises EvaluationError: the folder cannot be read."""
    measured = evaluate_asset(out_dir, reference=reference)
    try:
        ev = Evaluation.model_validate(output_folder.read_record(Path(out_dir) / EVALUATION_NAME))
    except (OSError, ValueError):
        return measured
    ev._runs, ev._context = measured._runs, measured._context
    return ev


def _probes(ctx: EstimationContext, obj: SimObject, closed: dict[str, ClosedState], spec: Any, notes: list[str]) -> list[Any]:
    """The passive probes (:func:`asset2sim.tasks.check.probes.probe_object`) of the task's joints and actions (``spec``),
    else of the task-relevant joints both ways; a spring's joint rebounds by design. Notes go to ``notes``."""
    joints = spec.joints if spec is not None else task_relevant_joints(ctx)
    targets = {n: (c.q_closed, c.direction, c.open_range) for n, c in closed.items() if n in joints}
    hold = task_tier.hold_required(ctx.asset, list(targets), dict(obj.springs), ctx.category, free_moving=ctx.request.free_moving,
                                   spring_requested=ctx.request.spring)
    found, more = probe_tier.probe_object(obj, targets, actions=tuple(spec.actions) if spec is not None else ("close", "open"),
                                          holds_position=bool(ctx.request.holds_position),
                                          returns={n for n, h in hold.items() if not h})
    notes += more
    return found


def clip_joints(task_joints: list[str], swept: list[str], labels: dict[str, str | None]) -> list[str]:
    """The joints whose sweeps get clips, in the order they get them (:func:`clip_files.sweep_clips` keeps the first
    :data:`~asset2sim.tasks.evaluation.clips.MAX_CLIP_JOINTS`): one of each kind of part first (by part
    label; an unlabelled joint is a kind of its own), the task-relevant joints' kinds before the others, then more of
    the task's joints, then the rest (four buttons and a door give a button and the door before a second button).
    ``swept``: the joints with a recorded sweep, in sweep order; ``labels``: joint -> part label."""
    task = [j for j in task_joints if j in swept]
    order = task + [j for j in swept if j not in task]
    kinds: dict[str, str] = {}
    for j in order:
        kinds.setdefault(labels.get(j) or f"joint:{j}", j)
    first = list(kinds.values())
    return first + [j for j in order if j not in first]


def _write_clips(ev: Evaluation, out_dir: Path | str) -> ClipSet | None:
    """The sweep clips of PyBullet's run (:func:`clip_files.sweep_clips`) of the task-relevant joints, else every swept
    joint; None, with a note in ``ev.notes``, when they cannot be drawn (no sweep, no PyAV, a render error)."""
    run = ev._runs.get("pybullet")
    sweep = getattr(run, "sweep", None)
    if sweep is None or not sweep.joints:
        ev.notes.append("clips: none (pybullet ran no joint sweep)")
        return None
    ctx = ev._context
    # joint -> its moving link's part label (``semantics.txt`` beside the URDF; None without one)
    try:
        semantics = partnet_mobility.read_semantics(ctx.urdf.parent)
    except AssetError:
        semantics = {}
    labels = {j.name: (semantics.get(j.child) or (None, None))[1] for j in ctx.model.joints if j.type in MOVABLE}
    joints = clip_joints(ev.task_joints, [js.joint for js in sweep.joints], labels)
    try:
        return clip_files.sweep_clips(ctx.urdf, sweep, joints, dict(ev.initial_state), out_dir, task_run=run.task)
    except ImportError as exc:
        ev.notes.append(f"clips skipped: {exc} (pip install av)")
    except Exception as exc:  # a clip must not cost the evaluation (a full disk shows again writing evaluation.json)
        raise_refusal(exc)  # a write the output guard refused is the output's problem, not the clip's
        ev.notes.append(f"clips failed: {one_line(exc)}")
    return None


def write_media(ev: Evaluation, out_dir: Path | str, *, views: dict[str, np.ndarray] | None = None, clips: bool = True) -> Path:
    """``report.html`` of ``ev`` (and its clips, with ``clips``) into ``out_dir``; returns the report's path."""
    return write_report(ev, Path(out_dir) / REPORT_HTML_NAME, views=views, clips=_write_clips(ev, out_dir) if clips else None)


def write_evaluation(ev: Evaluation, out_dir: Path | str, *, report: bool = True, clips: ClipSet | None = None) -> dict[str, Path]:
    """Write ``evaluation.json`` and, with ``report``, ``report.html`` (``clips`` the clips written in ``out_dir/clips/``,
    played in the report) into ``out_dir`` atomically; returns file name -> path for the files written."""
    out_dir = Path(out_dir)
    data = ev.model_dump(mode="json", exclude={"seconds"})  # its wall time apart (timings.json): the same files, the same bytes
    data["urdf"] = portable_urdf(ev, out_dir)  # no absolute path: the same refine into two folders writes the same bytes
    paths = {EVALUATION_NAME: write_json(out_dir / EVALUATION_NAME, jsonable(data))}
    output_folder.merge_timings(out_dir, {"evaluation_seconds": ev.seconds})
    if report:
        paths[REPORT_HTML_NAME] = write_report(ev, out_dir / REPORT_HTML_NAME, clips=clips)
    return paths
