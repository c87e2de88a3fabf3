"""Evaluate any URDF asset: the interaction-readiness protocol as one task
(:func:`evaluate_asset`; :func:`evaluate_refined` is refine's extra step).
Context, closed ends, one run per engine, the metric registry: the sibling
modules. Definitions: ``docs/design/metrics.md``.
"""

from __future__ import annotations

import math
import time
from pathlib import Path
from typing import Any

import numpy as np

from asset2sim.atomic import write_json
from asset2sim.schemas.config import SimConventions
from asset2sim.schemas.evaluation import Evaluation
from asset2sim.schemas.metrics import REST_TEST_METRICS
from asset2sim.schemas.realism import ClipSet
from asset2sim.schemas.report import MetricResult, RefineReport
from asset2sim.tasks.check.postcheck import RestRecording
from asset2sim.tasks.check.recorded_runs import RecordedRuns
from asset2sim.tasks.check.sweep import SweepRun
from asset2sim.tasks.evaluation import clips as clip_files
from asset2sim.tasks.check.asset_files import EvaluationError, JointInfo
from asset2sim.tasks.evaluation.engine_run import EngineRun, run_engine, set_closed_ends
from asset2sim.tasks.evaluation.eval_context import Context, build_context, task_joints
from asset2sim.tasks.check import as_asked
from asset2sim.tasks.evaluation.metric_defs import METRICS, MetricSpec, divergence_check, metric_names
from asset2sim.tasks.interpret.named_parts import labelled_joints, motion_joints, requested_joints
from asset2sim.tasks.check.task_spec import parse_task, with_work_to_do
from asset2sim.tasks.evaluation.report_html import portable_urdf, write_report
from asset2sim import output_folder
from asset2sim.output_folder import EVALUATION_NAME, REPORT_HTML_NAME, URDF_NAME
from asset2sim.inert import one_line
from asset2sim.output_paths import raise_refusal

__all__ = ["METRICS", "Evaluation", "EvaluationError", "JointInfo", "divergence_check", "evaluate_asset", "evaluate_refined",
           "metric_names", "requested_joints", "write_evaluation"]


def evaluate_asset(
    urdf_dir_or_path: Path | str, *, reference: Path | str | None = None, prompt: str | None = None,
    engines: tuple[str, ...] | list[str] = ("pybullet",), seed: int = 0, category: str | None = None, method: str | None = None,
    out_dir: Path | str | None = None, write_report: bool = False, probes: bool = True, conventions: SimConventions | None = None,
    measured: list[MetricResult] | None = None, recording: RestRecording | None = None, views: dict[str, np.ndarray] | None = None,
    views_state: dict[str, float] | None = None, checks: list[MetricResult] | None = None, task: str | None = None,
    recorded: RecordedRuns | None = None, shown_urdf: Path | str | None = None, clips: bool = True,
    evaluation_json: bool = True,
) -> Evaluation:
    """Evaluate one asset with every registered metric.

    Args:
        urdf_dir_or_path: asset folder or URDF file (sidecars beside it used when present).
        reference: GenSim2's reference folder (None: no reference metrics); prompt: the request.
        engines: engine names (unavailable ones: skipped metrics); seed, method: recorded.
        out_dir: where ``evaluation.json`` and (``write_report``) ``report.html`` go.
        measured: the first engine's rest-test metrics already measured (the post-check's):
            recorded as they are, that engine's rest test not run again.
        recording: the post-check's rest test (``RestRecording``), reused where it matches.
        views, views_state: renders already taken (view -> (H, W, 3) uint8) at ``views_state`` (rad/m).
        checks: the post-check's results: those not measured here (same name and engine) are recorded.
        task: the manipulation task the probes and ``task_execution`` try (None: no task execution).
        recorded: the post-check's sweep and robust-rest runs (``RecordedRuns``), reused when inputs match.
        shown_urdf: the URDF path recorded instead of the evaluated one.
        clips: with ``write_report``, also write the clips of each task-relevant joint's sweep into
            ``out_dir/clips/`` (:func:`asset2sim.tasks.evaluation.clips.sweep_clips`) and play them in the report;
            a clip that cannot be drawn is a note, never a failed evaluation.
        evaluation_json: write ``evaluation.json`` into ``out_dir`` (False: only ``report.html`` and the clips, for
            the media phase of an output whose evaluation is already written).

    Raises:
        EvaluationError: the asset or reference cannot be read.
        ValueError: ``write_report`` without ``out_dir``; no engine given.
    """
    if write_report and out_dir is None:
        raise ValueError("write_report needs out_dir")
    if not engines:
        raise ValueError("at least one engine is needed")
    t0 = time.perf_counter()
    ctx = build_context(urdf_dir_or_path, reference=reference, prompt=prompt, category=category, conventions=conventions)
    need_closed = _joints_to_close(ctx)
    _set_task(ctx, task, need_closed)
    reuse_engine = engines[0] if measured is not None else None
    runs = _run_engines(ctx, engines, need_closed, probes=probes, keep_geometry=write_report, reuse_engine=reuse_engine,
                        recording=recording, recorded=recorded)
    results = _metric_results(ctx, runs, probes=probes, measured=measured, reuse_engine=reuse_engine, checks=checks)
    ev = _evaluation(ctx, runs, results, engines=engines, method=method, prompt=prompt, seed=seed, shown_urdf=shown_urdf, t0=t0)
    if out_dir is not None:
        same_state = views is not None and views_state is not None and dict(views_state) == dict(ev.initial_state)
        clip_set = _write_clips(ev, runs, engines[0], out_dir) if write_report and clips else None
        write_evaluation(ev, out_dir, report=write_report, views=views if same_state else None, clips=clip_set,
                         evaluation_json=evaluation_json)
    return ev


def clip_joints(task_joints: list[str], swept: list[str], labels: dict[str, str | None]) -> list[str]:
    """The joints whose sweeps get clips, in the order they get them (:func:`clip_files.sweep_clips` keeps the first
    :data:`~asset2sim.tasks.evaluation.clips.MAX_CLIP_JOINTS`): one of each kind of part first (by part
    label; an unlabelled joint is a kind of its own), the task-relevant joints' kinds before the others, then more of
    the task's joints, then the rest (four buttons and a door give a button and the door before a second button).
    ``swept``: the joints with a recorded sweep, in sweep order; ``labels``: joint -> part label."""
    task = [j for j in task_joints if j in swept]
    order = task + [j for j in swept if j not in task]
    first, seen = [], set()
    for j in order:
        kind = labels.get(j) or f"joint:{j}"
        if kind not in seen:
            seen.add(kind)
            first.append(j)
    rest = [j for j in task if j not in first] + [j for j in order if j not in first and j not in task]
    return first + rest


def _write_clips(ev: Evaluation, runs: dict[str, EngineRun], engine: str, out_dir: Path | str) -> ClipSet | None:
    """The sweep clips of ``engine``'s run (:func:`clip_files.sweep_clips`) of the task-relevant joints, else every swept
    joint; None, with a note in ``ev.notes``, when they cannot be drawn (no sweep, no PyAV, a render error)."""
    sweep = getattr(runs.get(engine), "sweep", None)
    if not isinstance(sweep, SweepRun) or not sweep.joints:
        ev.notes.append(f"clips: none ({engine} ran no joint sweep)")
        return None
    ctx = ev._context
    labels = {n: (ctx.semantics or {}).get(j.child, (None, None))[1] for n, j in ctx.joints.items()}
    joints = clip_joints(ev.task_joints, [js.joint for js in sweep.joints], labels)
    ctx_urdf = ev._context.urdf  # the files evaluated (a refine's staging folder; ``ev.urdf`` names the published one)
    try:
        return clip_files.sweep_clips(ctx_urdf, sweep, joints, dict(ev.initial_state), out_dir,
                                      task_run=getattr(runs.get(engine), "task", None))
    except ImportError as exc:
        ev.notes.append(f"clips skipped: {exc} (pip install av)")
    except Exception as exc:  # a clip must not cost the evaluation (a full disk shows again writing evaluation.json)
        raise_refusal(exc)  # a write the output guard refused is the output's problem, not the clip's
        ev.notes.append(f"clips failed: {one_line(exc)}")
    return None


def _joints_to_close(ctx: Context) -> list[str]:
    """The joints whose closed ends the evaluation needs: the task-relevant ones (set into ``ctx.task_joints``, their
    rule noted), those the request names, then every movable joint (the joint sweep drives every one)."""
    pre_req = labelled_joints(ctx.request, ctx.joints, ctx.semantics, ctx.category)
    ctx.task_joints, tj_rule = task_joints(ctx.joints, ctx.reference_dir, pre_req, ctx.category, ctx.semantics)
    ctx.notes.append(f"task-relevant joints: {', '.join(ctx.task_joints) or 'none'} ({tj_rule})")
    return list(dict.fromkeys(ctx.task_joints + pre_req + ctx.movable))


def _set_task(ctx: Context, task: str | None, need_closed: list[str]) -> None:
    """``task`` parsed into ``ctx.task`` (None without a task: task execution is not run) and noted; of a task on
    several joints only those with work to do at the initial state (:func:`with_work_to_do`, the closed ends first)."""
    tspec = parse_task(task, ctx.joints, ctx.semantics, ctx.category, ctx.task_joints) if task else None
    if tspec is not None and len(tspec.joints) > 1:
        if need_closed and not ctx.closed:
            set_closed_ends(ctx, need_closed)
        tspec = with_work_to_do(tspec, {n: c.fraction(ctx.initial_state[n]) for n, c in ctx.closed.items()
                                        if n in ctx.initial_state and c.open_range > 0})
    ctx.task = tspec
    if tspec is not None:
        ctx.notes.append(f"task {task!r}: {', '.join(tspec.actions)} {', '.join(tspec.joints) or 'no joint'} ({tspec.rule})"
                         + "".join(f"; {n}" for n in tspec.notes))


def _run_engines(ctx: Context, engines: tuple[str, ...] | list[str], need_closed: list[str], *, probes: bool, keep_geometry: bool,
                 reuse_engine: str | None, recording: RestRecording | None, recorded: RecordedRuns | None) -> dict[str, EngineRun]:
    """engine -> its :class:`EngineRun`, in the order of ``engines``; errors noted. PyBullet runs first and computes
    the closed ends of ``need_closed`` (else they are computed after the runs); ``reuse_engine`` runs no rest test."""
    runs: dict[str, EngineRun] = {}
    for e in sorted(engines, key=lambda e: e != "pybullet"):
        pending = need_closed if (e == "pybullet" and not ctx.closed) else None
        runs[e] = run_engine(ctx, e, probes=probes and e == "pybullet", keep_geometry=keep_geometry, closed_for=pending,
                             rest_test=e != reuse_engine, recording=recording, recorded=recorded)
        if runs[e].error:
            ctx.notes.append(f"{e}: {runs[e].error}")
    if need_closed and not ctx.closed:
        set_closed_ends(ctx, need_closed)
    return {e: runs[e] for e in engines}


def _metric_results(ctx: Context, runs: dict[str, EngineRun], *, probes: bool, measured: list[MetricResult] | None,
                    reuse_engine: str | None, checks: list[MetricResult] | None) -> list[MetricResult]:
    """Every registered metric's results in registry order (``reuse_engine``'s rest-test metrics taken from
    ``measured``), then those of ``checks`` the evaluation did not measure itself (same name and engine)."""
    results: list[MetricResult] = []
    for spec in METRICS.values():
        if spec.name == "probes" and not probes:
            continue
        if reuse_engine is not None and spec.name in REST_TEST_METRICS:
            results += [m for m in measured if m.name == spec.name and m.engine == reuse_engine]
            others = {e: r for e, r in runs.items() if e != reuse_engine}
            results += _apply(spec, ctx, others) if others else []
        else:
            results += _apply(spec, ctx, runs)
    if checks:
        have = {(m.name, m.engine) for m in results}
        results += [m for m in checks if (m.name, m.engine) not in have]
    # a word about motion the physical verdict contradicts, on the joints whose overlay says it applied the word; a
    # word naming one part by its place ("the main door") the overlay applied to another
    sources = {n: str(j.get("source") or "") for n, j in ((ctx.overlay or {}).get("joints") or {}).items()}
    r = next(iter(runs.values()), None)
    named = motion_joints(ctx.request, ctx.joints, ctx.semantics, ctx.task_joints, ctx.category,
                          r.link_centres if r is not None else {}, r.link_volumes if r is not None else {})
    words = [(w, [n for n in joints if f"request '{w.phrase}'" in sources.get(n, "")]) for w, joints in named]
    strays = [(w, [n for n, src in sources.items() if f"request '{w.phrase}'" in src  # a part named by its place
                   and not any(n in js for v, js in named if v.phrase == w.phrase)]) for w, _ in named if w.ordinal is not None]
    return as_asked.word_conflicts(results, words, strays)


def _apply(spec: MetricSpec, ctx: Context, runs: dict[str, EngineRun]) -> list[MetricResult]:
    """``spec``'s results, or one failed result naming the error: one broken metric must not hide the others."""
    try:
        return list(spec.fn(ctx, runs))
    except Exception as exc:
        return [MetricResult(name=spec.name, value=None, unit="", passed=False, details={"error": f"{type(exc).__name__}: {exc}"},
                             engine="none")]


def _evaluation(ctx: Context, runs: dict[str, EngineRun], results: list[MetricResult], *, engines: tuple[str, ...] | list[str],
                method: str | None, prompt: str | None, seed: int, shown_urdf: Path | str | None, t0: float) -> Evaluation:
    """The :class:`Evaluation` (``seconds`` since ``t0``, :func:`time.perf_counter`), with ``runs`` and ``ctx`` attached."""
    failures = [f"{m.name}@{m.engine}" for m in results if m.passed is False]
    ev = Evaluation(
        asset_id=ctx.asset_id, urdf=str(shown_urdf or ctx.urdf),
        method=method or (ctx.baseline or {}).get("method") or ("asset2sim" if ctx.overlay else None), prompt=prompt,
        reference=str(ctx.reference_dir) if ctx.reference_dir else None, category=ctx.category, scale=ctx.scale,
        scale_source=ctx.scale_source, engines=list(engines), seed=seed, initial_state=ctx.initial_state,
        initial_state_source=ctx.initial_state_source, task_joints=ctx.task_joints,
        closed_positions={n: {"q_closed": c.q_closed, "direction": c.direction, "open_range": c.open_range} for n, c in ctx.closed.items()},
        metrics=results, passed=not failures and all(r.error is None for r in runs.values()),
        failures=failures + [f"engine@{e}" for e, r in runs.items() if r.error], notes=ctx.notes, seconds=time.perf_counter() - t0,
    )
    ev._runs = runs
    ev._context = ctx
    return ev


def evaluate_refined(out_dir: Path | str, report: RefineReport, *, recording: RestRecording | None = None,
                     reference: Path | str | None = None, views: dict[str, np.ndarray] | None = None,
                     views_state: dict[str, float] | None = None, checks: list[MetricResult] | None = None,
                     recorded: RecordedRuns | None = None, shown: Path | str | None = None, clips: bool = True,
                     html: bool = True, evaluation_json: bool = True) -> dict[str, Path]:
    """Evaluate a refined output folder and write ``evaluation.json`` and ``report.html`` beside its ``report.json``
    (refine's extras); the report's ``prompt``, ``category`` and ``task`` are used, the other arguments as in
    :func:`evaluate_asset`. ``shown``: the output folder as its user will find it (the staging folder of a rerun is swapped
    in later; None: ``out_dir``); ``clips``: write the sweep clips (``clips/``) too; ``html``: write ``report.html`` (False:
    the verdict's phase alone, no clips); ``evaluation_json``: write ``evaluation.json`` (False: the media phase of an
    output evaluated before). Returns the paths written ({"evaluation": path, "report": path}). Raises EvaluationError:
    the folder cannot be read."""
    out_dir = Path(out_dir)
    evaluate_asset(out_dir, reference=reference, prompt=report.prompt or None, category=report.category,
                   method="asset2sim", out_dir=out_dir, write_report=html, recording=recording,
                   views=views, views_state=views_state, checks=checks, recorded=recorded, task=report.task,
                   shown_urdf=None if shown is None else Path(shown) / URDF_NAME, clips=clips and html,
                   evaluation_json=evaluation_json)
    return {**({"evaluation": out_dir / EVALUATION_NAME} if evaluation_json else {}),
            **({"report": out_dir / REPORT_HTML_NAME} if html else {})}


def write_evaluation(ev: Evaluation, out_dir: Path | str, *, report: bool = True,
                     views: dict[str, np.ndarray] | None = None, clips: ClipSet | None = None,
                     evaluation_json: bool = True) -> dict[str, Path]:
    """Write ``evaluation.json`` (unless ``evaluation_json`` is False) and, with ``report``, ``report.html`` (``views`` the
    renders at ``ev.initial_state`` when taken; ``clips`` the clips written in ``out_dir/clips/``, played in the report)
    into ``out_dir`` atomically; returns {"evaluation": path, "report": path} for the files written."""
    out_dir = Path(out_dir)
    paths = {}
    if evaluation_json:  # its wall time apart (timings.json), so two evaluations of the same files write the same bytes
        data = ev.model_dump(mode="json", exclude={"seconds"})
        data["urdf"] = portable_urdf(ev, out_dir)  # no absolute path: the same refine into two folders writes the same bytes
        paths["evaluation"] = write_json(out_dir / EVALUATION_NAME, _jsonable(data))
        output_folder.merge_timings(out_dir, {"evaluation_seconds": ev.seconds})
    if report:
        paths["report"] = write_report(ev, out_dir / REPORT_HTML_NAME, views=views, clips=clips)
    return paths


def _jsonable(obj: Any) -> Any:
    """Replace non-finite floats by None (strict JSON); for ``model_dump(mode="json")`` output and plain records."""
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {k: _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_jsonable(v) for v in obj]
    return obj
