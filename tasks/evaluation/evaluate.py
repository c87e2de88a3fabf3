"""Evaluate any URDF asset: the interaction-readiness protocol as one task.

:func:`evaluate_asset` loads a URDF (with ``initial_state.json`` beside it when
present), runs every registered metric under the SPEC's conventions
(``asset2sim.engines.base``) and returns an
:class:`~asset2sim.schemas.evaluation.Evaluation`; it writes
``evaluation.json`` and a self-contained ``report.html`` when asked
(:func:`write_evaluation`). :func:`evaluate_refined` is refine's extra step.

The stage, in the order it runs:

- :mod:`~asset2sim.tasks.evaluation.eval_context`: the asset's files
  (:mod:`~asset2sim.tasks.check.asset_files`), the reference, the
  request and category prior (:mod:`~asset2sim.tasks.check.request_match`)
  as one :class:`~asset2sim.tasks.evaluation.eval_context.Context`;
- :mod:`~asset2sim.tasks.evaluation.closed_ends`: the closed ends and extents
  the evaluation computes itself;
- :mod:`~asset2sim.tasks.evaluation.engine_run`: one session per engine,
  every raw measurement once (the SPEC's rest test is run once per engine, or
  taken from the post-check's recording, and shared by the rest-test metrics);
- :mod:`~asset2sim.tasks.evaluation.metric_defs`: the metric registry and the
  metrics (physical robustness per engine, semantic accuracy, behaviour).

Definitions, conventions and thresholds are in ``docs/design/metrics.md``. The names
of those modules that callers use are importable from here too.
"""

from __future__ import annotations

import math
import time
from pathlib import Path
from typing import Any

import numpy as np

from asset2sim.atomic import write_json
from asset2sim.schemas.config import SimConventions
from asset2sim.schemas.evaluation import EVALUATION_VERSION, Evaluation
from asset2sim.schemas.metrics import REST_TEST_METRICS
from asset2sim.schemas.report import MetricResult, RefineReport
from asset2sim.tasks.check.postcheck import RestRecording
from asset2sim.tasks.check.recorded_runs import RecordedRuns
from asset2sim.tasks.check.asset_files import EvaluationError, JointInfo, LinkInfo, find_urdf, parse_urdf
from asset2sim.tasks.evaluation.closed_ends import ClosedEnd, compute_closed, infer_scale_from_geometry
from asset2sim.tasks.evaluation.engine_run import EngineRun, run_engine
from asset2sim.tasks.evaluation.eval_context import Context, build_context, task_joints
from asset2sim.tasks.evaluation.metric_defs import (
    EXPLOSION_JOINT_SPEED_PRISMATIC,
    EXPLOSION_JOINT_SPEED_REVOLUTE,
    EXPLOSION_ROOT_SPEED,
    EXPLOSION_TRAVEL_FACTOR,
    EXPLOSION_TRAVEL_MIN,
    GROUND_PENETRATION_TOL,
    METRICS,
    MetricFn,
    MetricSpec,
    divergence_check,
    metric_names,
    movable_joints,
    register_metric,
)
from asset2sim.tasks.check.request_match import (
    category_prior,
    labelled_joints,
    parse_prompt,
    recognize_category,
    requested_joints,
    scaled_mass_range,
)
from asset2sim.tasks.check.task_spec import parse_task, with_work_to_do
from asset2sim.tasks.evaluation.report_html import write_report
from asset2sim.output_folder import EVALUATION_NAME, REPORT_HTML_NAME, URDF_NAME

__all__ = [
    "EVALUATION_VERSION",
    "EXPLOSION_JOINT_SPEED_PRISMATIC",
    "EXPLOSION_JOINT_SPEED_REVOLUTE",
    "EXPLOSION_ROOT_SPEED",
    "EXPLOSION_TRAVEL_FACTOR",
    "EXPLOSION_TRAVEL_MIN",
    "GROUND_PENETRATION_TOL",
    "METRICS",
    "ClosedEnd",
    "Context",
    "EngineRun",
    "Evaluation",
    "EvaluationError",
    "JointInfo",
    "LinkInfo",
    "MetricFn",
    "MetricSpec",
    "build_context",
    "category_prior",
    "compute_closed",
    "divergence_check",
    "evaluate_asset",
    "evaluate_refined",
    "find_urdf",
    "infer_scale_from_geometry",
    "metric_names",
    "parse_prompt",
    "parse_urdf",
    "recognize_category",
    "register_metric",
    "requested_joints",
    "run_engine",
    "scaled_mass_range",
    "write_evaluation",
]


# ------------------------------------------------------------------ entry point
def _closed_ends(ctx: Context, joints: list[str]) -> None:
    """The closed ends of ``joints`` into ``ctx.closed`` (with their extents
    and notes), in a fresh session (:func:`compute_closed`)."""
    ext: list = []
    ctx.closed, cnotes = compute_closed(ctx.urdf, ctx.joints, joints, extents_out=ext)
    ctx.closed_extents = ext[0] if ext else None
    ctx.notes += cnotes


def evaluate_asset(
    urdf_dir_or_path: Path | str, *, reference: Path | str | None = None, prompt: str | None = None,
    engines: tuple[str, ...] | list[str] = ("pybullet",), seed: int = 0, category: str | None = None, method: str | None = None,
    out_dir: Path | str | None = None, write_report: bool = False, probes: bool = True, conventions: SimConventions | None = None,
    measured: list[MetricResult] | None = None, recording: RestRecording | None = None, views: dict[str, np.ndarray] | None = None,
    views_state: dict[str, float] | None = None, checks: list[MetricResult] | None = None, task: str | None = None,
    recorded: RecordedRuns | None = None, shown_urdf: Path | str | None = None,
) -> Evaluation:
    """Evaluate one asset with every registered metric.

    Args:
        urdf_dir_or_path: asset folder (``mobility.urdf`` or one ``*.urdf``) or
            a URDF file; ``initial_state.json``, ``overlay.json``,
            ``report.json``, ``baseline.json``, ``semantics.txt`` beside it are
            used when present.
        reference: PartNet-Mobility folder with ``reference_gensim2.json`` /
            ``reference_gensim2.urdf`` (reference scale, task joint, reference
            state); None skips the reference metrics.
        prompt: the request; None skips prompt alignment.
        engines: engine names (``asset2sim.engines``); unavailable ones are
            recorded as skipped metrics.
        seed: recorded for reproducibility; every measurement here is
            deterministic (PyBullet DIRECT mode, fixed step), so it changes
            nothing today.
        category: overrides the category found in the sidecars.
        method: name recorded in the evaluation (benchmark).
        out_dir: where ``evaluation.json`` (always, when given) and
            ``report.html`` (when ``write_report``) go.
        write_report: write ``report.html`` into ``out_dir``.
        probes: run the passive probes.
        conventions: SPEC conventions (default :class:`SimConventions`).
        measured: results of the rest-test metrics
            (:data:`asset2sim.schemas.metrics.REST_TEST_METRICS`) already
            measured in the first engine under the same conventions and
            initial state (the refine post-check): recorded as they are, and
            that engine's rest test is not run again (the probes start from
            the unstepped initial state either way, :func:`run_engine`); the
            metrics that need its per-step trace (ground penetration,
            divergence, joint hold) are then recorded as skipped.
        recording: the post-check's rest test of this asset, step by step
            (:class:`~asset2sim.tasks.check.postcheck.RestRecording`): when it
            matches an engine's simulation (engine, URDF, initial state,
            springs, conventions) every rest-test metric of that engine
            (ground penetration, divergence and joint hold included) is
            computed from it and the rest test is not simulated again; the
            result equals a fresh rest test's (the simulation is
            deterministic). Otherwise it is ignored.
        views, views_state: renders of the object already taken
            (:func:`asset2sim.tasks.geometry.render.render_views`, view name ->
            (H, W, 3) uint8) at the joint positions ``views_state`` (rad/m):
            ``report.html`` shows them when that is the evaluated initial
            state, else it renders its own.
        checks: results the refine post-check already measured on these
            same files (its report's metrics): every one the evaluation does
            not measure itself (same name and engine: ``state_hold``,
            ``settle_tilt``, other engines' rest tests) is recorded as it is,
            so ``report.html``'s verdict is the refine report's
            (:func:`asset2sim.tasks.check.verdict.readiness`). The evaluation
            measures everything else itself (its own closed ends: no method
            grades itself).
        task: the manipulation task ("close the microwave door", a
            manifest's ``task``): the probes try only its joints and
            direction (:func:`asset2sim.tasks.check.task_spec.parse_task`),
            and a gripper executes it (``task_execution``,
            ``operating_force``: :mod:`asset2sim.tasks.check.task_execution`);
            None: the probes try every task-relevant joint, close and open,
            and task execution is not run.
        recorded: the post-check's joint sweep and robust rest runs
            (:class:`~asset2sim.tasks.check.recorded_runs.RecordedRuns`): a
            run whose inputs (URDF bytes and meshes, initial state, springs,
            conventions, root, configuration and, for the sweep, the
            evaluation's own closed ends) hash the same is taken from it
            instead of simulated again (the simulations are deterministic);
            any difference re-runs it.
        shown_urdf: the URDF path recorded in the evaluation (and its HTML
            report) instead of the evaluated file's, e.g. where a staged
            refine's output will lie once swapped in (None: the evaluated one).

    Returns:
        The :class:`Evaluation`.

    Raises:
        EvaluationError: the asset or reference cannot be read.
        ValueError: ``write_report`` without ``out_dir``; no engine given.
    """
    _check_arguments(write_report, out_dir, engines)
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
        write_evaluation(ev, out_dir, report=write_report, views=views if same_state else None)
    return ev


def _check_arguments(write_report: bool, out_dir: Path | str | None, engines: tuple[str, ...] | list[str]) -> None:
    """Raises ValueError: ``write_report`` without ``out_dir``; no engine given."""
    if write_report and out_dir is None:
        raise ValueError("write_report needs out_dir")
    if not engines:
        raise ValueError("at least one engine is needed")


def _joints_to_close(ctx: Context) -> list[str]:
    """The joints whose closed ends the evaluation needs: the task-relevant ones (set into ``ctx.task_joints``, their
    rule noted), those the request names, then every movable joint (the joint sweep drives every one)."""
    pre_req = labelled_joints(ctx.request, ctx.joints, ctx.semantics, ctx.category)
    ctx.task_joints, tj_rule = task_joints(ctx.joints, ctx.reference_dir, pre_req, ctx.category, ctx.semantics)
    ctx.notes.append(f"task-relevant joints: {', '.join(ctx.task_joints) or 'none'} ({tj_rule})")
    return list(dict.fromkeys(ctx.task_joints + pre_req + movable_joints(ctx)))


def _set_task(ctx: Context, task: str | None, need_closed: list[str]) -> None:
    """``task`` parsed into ``ctx.task`` (None without a task: task execution is not run) and noted; of a task on
    several joints only those with work to do at the initial state (:func:`with_work_to_do`, the closed ends first)."""
    tspec = parse_task(task, ctx.joints, ctx.semantics, ctx.category, ctx.task_joints) if task else None
    if tspec is not None and len(tspec.joints) > 1:
        if need_closed and not ctx.closed:
            _closed_ends(ctx, need_closed)
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
    tspec = ctx.task
    for e in sorted(engines, key=lambda e: e != "pybullet"):
        pending = need_closed if (e == "pybullet" and not ctx.closed) else None
        runs[e] = run_engine(ctx, e, probes=probes and e == "pybullet", keep_geometry=keep_geometry, closed_for=pending,
                             rest_test=e != reuse_engine, recording=recording, recorded=recorded,
                             **({} if tspec is None else {"probe_joints": tspec.joints, "probe_actions": tspec.actions}))
        if runs[e].error:
            ctx.notes.append(f"{e}: {runs[e].error}")
    if need_closed and not ctx.closed:
        _closed_ends(ctx, need_closed)
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
    return results


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


def evaluate_refined(
    out_dir: Path | str,
    report: RefineReport,
    *,
    recording: RestRecording | None = None,
    reference: Path | str | None = None,
    views: dict[str, np.ndarray] | None = None,
    views_state: dict[str, float] | None = None,
    checks: list[MetricResult] | None = None,
    recorded: RecordedRuns | None = None,
    shown: Path | str | None = None,
) -> dict[str, Path]:
    """Evaluate a refined output folder (PyBullet, SPEC conventions, probes)
    and write ``evaluation.json`` and ``report.html`` beside its
    ``report.json`` (refine's extras).

    Args:
        out_dir: the refined output folder.
        report: its :class:`~asset2sim.schemas.report.RefineReport` (the
            run's ``prompt``, ``category`` and ``task`` are used).
        recording: the final post-check's rest test
            (:class:`~asset2sim.tasks.check.postcheck.RestRecording`), reused
            when it matches (see :func:`evaluate_asset`).
        reference: the reference folder (GenSim2), None for none.
        views: the renders refine wrote (view -> (H, W, 3) uint8), taken at
            ``views_state`` (rad/m); used in ``report.html`` when that is the
            evaluated initial state, else the report renders its own.
        checks: the post-check's results of these files (see :func:`evaluate_asset`).
        recorded: the post-check's manipulation runs (see :func:`evaluate_asset`).
        shown: the output folder as its user will find it, recorded as the
            evaluated URDF's folder when ``out_dir`` is the staging folder a
            rerun swaps in at its end (None: ``out_dir``).

    Returns:
        {"evaluation": path, "report": path}.

    Raises:
        EvaluationError: the folder cannot be read.
    """
    out_dir = Path(out_dir)
    evaluate_asset(out_dir, reference=reference, prompt=report.prompt or None, category=report.category,
                   method="asset2sim", out_dir=out_dir, write_report=True, recording=recording,
                   views=views, views_state=views_state, checks=checks, recorded=recorded, task=report.task,
                   shown_urdf=None if shown is None else Path(shown) / URDF_NAME)
    return {"evaluation": out_dir / EVALUATION_NAME, "report": out_dir / REPORT_HTML_NAME}


def write_evaluation(ev: Evaluation, out_dir: Path | str, *, report: bool = True,
                     views: dict[str, np.ndarray] | None = None) -> dict[str, Path]:
    """Write ``evaluation.json`` (and ``report.html``, rendering ``ev``:
    :func:`asset2sim.tasks.evaluation.report_html.write_report`, with ``views``
    the renders at ``ev.initial_state`` when already taken) into ``out_dir``
    atomically.

    Returns:
        {"evaluation": path, "report": path (when written)}.
    """
    out_dir = Path(out_dir)
    paths = {"evaluation": write_json(out_dir / EVALUATION_NAME, _jsonable(ev.model_dump(mode="json")))}
    if report:
        paths["report"] = write_report(ev, out_dir / REPORT_HTML_NAME, views=views)
    return paths


def _jsonable(obj: Any) -> Any:
    """Replace non-finite floats by None (strict JSON)."""
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {k: _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_jsonable(v) for v in obj]
    if isinstance(obj, (np.floating,)):
        return _jsonable(float(obj))
    if isinstance(obj, (np.integer,)):
        return int(obj)
    if isinstance(obj, np.bool_):
        return bool(obj)
    return obj
