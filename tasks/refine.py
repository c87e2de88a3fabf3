"""Refine one asset end to end: a folder and a request in, the SPEC's output
folder out, verified in PyBullet. The stages (extract, analyze, interpret,
synthesize, write, refine the state, post-check, report and extras) are
chained one small function each, with wall time per stage; progress goes to
the optional ``progress`` callback (the library never prints).
"""

from __future__ import annotations

import errno
import json
import time
import traceback
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Callable

from asset2sim import __version__, array_cache, atomic, output_folder
from asset2sim.engines.base import SessionOptions
from asset2sim.engines.quiet import quiet_stdout
from asset2sim.extras import install_hint
from asset2sim.engines.registry import open_session
from asset2sim.schemas.asset import AssetDescription, LinkGeometry
from asset2sim.schemas.config import RefineConfig
from asset2sim.schemas.evaluation import Evaluation
from asset2sim.schemas.overlay import Overlay
from asset2sim.schemas.report import EscalationRound, RefineReport, StateRefinement
from asset2sim.schemas.request import BAND_INTERVAL, RequestSpec
from asset2sim.tasks.audit import keep
from asset2sim.tasks.ingest.declared import read_declared
from asset2sim.tasks.ingest.host_conventions import ReadOptions
from asset2sim.tasks.check import dynamics_search, manipulation, operating, parity, postcheck, repair, robust_rest, sweep, task_tier
from asset2sim.tasks.check import as_asked
from asset2sim.tasks.check.verdict import combine_verdict, penetration_measures, post_check_failure_mode, readiness
from asset2sim.tasks.evaluation import evaluate
from asset2sim.tasks.evaluation.clips import CLIPS_JSON
from asset2sim.tasks.geometry import analyze, limits, urdf_closed
from asset2sim.tasks.geometry.closed_state import ClosedState
from asset2sim.tasks.geometry.decomposition import DecompositionUnavailable
from asset2sim.tasks.ingest import extract, staged
from asset2sim.tasks.ingest.validate_input import Finding
from asset2sim.tasks.interpret import mounting, overrides, request
from asset2sim.tasks.synthesize import request_apply
from asset2sim.tasks.assemble import (collision_geometry, container_pieces, export_mjcf, footprint, parent_child_separation,
                                      sliding_clearance, write)
from asset2sim.tasks.assemble.candidate import Candidate, Workspace
from asset2sim.tasks.publish import export_usd, host_mjcf, host_usd, output
from asset2sim.tasks.publish import media as media_phase
from asset2sim.tasks.publish.contract import (MARKER_NAME, REPORT_NAME, is_complete, read_report_json, run_hash, write_completion_marker,
                                              write_report_json)
from asset2sim.tasks.state import balance, clearance, collision, ground_clearance, pose, refine_state, stability
from asset2sim.tasks.synthesize import backends, estimate, estimator, validate_overlay
from asset2sim.tasks.synthesize.context import EstimationContext, build_context
from asset2sim.output_folder import CLIPS_DIR, URDF_NAME, VIEWS_DIR

__all__ = ["MARKER_NAME", "REPORT_NAME", "Progress", "RefineError", "RefineResult", "is_complete", "refine_asset", "request_notes", "run_hash"]

Progress = Callable[[str, str], None]
"""progress(stage, message)"""


class RefineError(RuntimeError):
    """A refine run failed; ``failure_mode`` is from the fixed vocabulary;
    ``codes`` the validation codes when the input was refused."""

    def __init__(self, message: str, failure_mode: str, codes: list[str] | None = None):
        super().__init__(message)
        self.failure_mode = failure_mode
        self.codes = list(codes or [])


@dataclass
class RefineResult:
    """What :func:`refine_asset` produced."""

    out_dir: Path
    report: RefineReport
    overlay: Overlay
    skipped: bool = False  # ``out_dir`` was already complete for this input and configuration (nothing recomputed)
    extras: dict[str, str] = field(default_factory=dict)  # what the extras wrote: name (``html``, ``mjcf`` ...) -> path

    @property
    def ready(self) -> bool:
        """Interaction-ready: every check passed (``report.failure_mode == "none"``)."""
        return self.report.failure_mode == "none"

    def to_json(self) -> str:
        """The result as JSON: ``out_dir``, ``ready``, ``skipped``, ``extras``,
        ``report`` and ``overlay`` (their JSON forms, SI units)."""
        return json.dumps({"out_dir": str(self.out_dir), "ready": self.ready, "skipped": self.skipped, "extras": dict(self.extras),
                           "report": self.report.model_dump(mode="json"), "overlay": self.overlay.model_dump(mode="json")})


def refine_asset(
    asset_dir: Path | str,
    prompt: str,
    out_dir: Path | str,
    config: RefineConfig | None = None,
    *,
    category: str | None = None,
    asset_id: str | None = None,
    progress: Progress | None = None,
    skip_if_complete: bool = True,
    extras: bool = True,
    overwrite: bool = False,
    extracted: tuple[AssetDescription, list[Finding]] | None = None,
    reference: Path | str | None = None,
    task: str | None = None,
    media: bool = True,
) -> RefineResult:
    """Refine ``asset_dir`` for the natural-language ``prompt`` into ``out_dir``: the engine of
    :func:`asset2sim.api.refine`, whose docstring gives the output, the result and the errors
    (:class:`RefineError`; no partial file is left in ``out_dir``).

    Args beyond the API's: ``asset_id`` (for reports; default the folder name); ``skip_if_complete``
    (return the recorded result when the completion marker matches the input and configuration
    hashes); ``extracted`` ((description, findings) the flow's prepare stage already read with
    :func:`asset2sim.tasks.ingest.extract.extract_asset_checked`); ``reference`` (a PartNet-Mobility
    folder with the GenSim2 reference for the extras' evaluation); ``media`` (with ``extras``: make the renders,
    clips and ``report.html`` too; False defers them to :func:`asset2sim.tasks.publish.media.make_media`, and a later
    refine with ``media`` over the complete output makes them there).
    """
    config = config or RefineConfig()
    out_dir = Path(out_dir)
    _check_prompt(prompt)
    est = _open_estimator(config)  # first: a model backend without its key fails before any work
    log = _StageLog(progress)
    asset, findings = _extract(asset_dir, out_dir, asset_id, category, extracted, config)
    _check_overrides(asset, config)
    if config.keep_declared:
        est = _keep_declared(est, asset_dir, asset)
    chash = run_hash(asset.input_hash, config, prompt + (f"\ntask: {task}" if task else ""), category)
    if skip_if_complete and is_complete(out_dir, asset.input_hash, chash):
        output_folder.remove_stale_staging(out_dir)  # what a killed --force run left beside it
        if extras and media and media_phase.media_pending(out_dir):  # a deferred media phase, resumed
            made = media_phase.make_media(out_dir, reference=reference, clips=config.clips)
            log.say("media", f"{out_dir}: " + ", ".join(sorted(made)) + " made (the deferred media phase)")
        return _completed_result(out_dir, log)
    owner = _start_output(asset, out_dir, overwrite)
    work = owner.write_path(out_dir)  # out_dir, or the staging folder that replaces a complete earlier output
    staged_input = asset.staged_from.parent if asset.staged_from is not None else None  # an MJCF / USD file's own folder
    with array_cache.guard(asset.source_dir, staged_input, out_dir, owner.root, reference):  # no cache entry in the input or output
        try:
            _announce_extract(asset, findings, log)
            cache = analyze.MeshCache()
            geometry = _analyze(asset, cache, log)
            with build_context(asset, prompt, config, category=category, geometry=geometry, cache=cache) as ctx, \
                    Workspace(asset, open_containers=config.open_containers and config.convex_decomposition) as ws:
                ctx.task = task
                pose_note = _interpret(ctx, log)
                att, pose_note = _synthesize_and_check(ctx, est, config, ws, cache, log, pose_note)
                resolution = request_apply.resolve_states(ctx, att.overlay.scale)  # what each phrase set (the as-asked tier)
                output.publish(att.candidate, ws, work)  # the output folder's files, written once
            _announce_post_check(att, log)
            report = _build_report(ctx, prompt, chash, att, findings, pose_note, log.times, resolution)
            host = _host_mjcf(work, asset, config, report) or _host_usd(work, asset, report)
            report.media = "off"
            write_report_json(work, report)
            extra_paths = _extras(work, report, att, log, reference, shown=out_dir, clips=config.clips, media=media) if extras else {}
            extra_paths.update(host)
            write_completion_marker(owner.root, asset.input_hash, chash, owner=owner)  # last, once every file exists
        except BaseException:
            owner.abandon()
            raise
    extra_paths = {k: str(out_dir / Path(v).relative_to(work)) if Path(v).is_relative_to(work) else v for k, v in extra_paths.items()}
    return RefineResult(out_dir=out_dir, report=report, overlay=att.overlay, extras=extra_paths)


# ------------------------------------------------------------------ progress
class _StageLog:
    """Progress messages and wall time per stage (s, summed over repeats)."""

    def __init__(self, progress: Progress | None):
        self.say: Progress = progress or (lambda stage, msg: None)
        self.times: dict[str, float] = {}
        self._t = time.perf_counter()

    def lap(self, stage: str) -> None:
        """Charge the time since the previous lap to ``stage``."""
        now = time.perf_counter()
        self.times[stage] = self.times.get(stage, 0.0) + (now - self._t)
        self._t = now


# ---------------------------------------------------------- 1-3: extract .. interpret
def _check_prompt(prompt: str) -> None:
    """A request over the length cap is refused before any work:
    RefineError("invalid_input", ["REQUEST_TOO_LONG"]) from ``RequestTooLong``."""
    try:
        request.check_request_length(prompt)
    except request.RequestTooLong as exc:
        raise RefineError(str(exc), "invalid_input", exc.codes) from exc


def _open_estimator(config: RefineConfig) -> estimator.Estimator:
    """The configured estimator; RefineError("estimator_failure") when it cannot be made."""
    try:
        return backends.get_estimator(config.estimator, **{k: v for k, v in (("model", config.model), ("base_url", config.base_url)) if v})
    except Exception as exc:
        raise RefineError(f"estimator {config.estimator!r} unavailable: {exc}", "estimator_failure", ["ESTIMATOR_UNAVAILABLE"]) from exc


def _extract(asset_dir: Path | str, out_dir: Path, asset_id: str | None, category: str | None,
             extracted: tuple[AssetDescription, list[Finding]] | None = None,
             config: RefineConfig | None = None) -> tuple[AssetDescription, list[Finding]]:
    """Stage 1: the checked asset and its validation findings (``extracted`` when
    already read; an MJCF input read as ``config.body`` and ``config.mjcf`` say); the output folder checked against
    it. RefineError("invalid_input") with the codes, also for a joint range that only makes sense in the other
    unit (``JOINT_RANGE_WRONG_UNIT``: never part of an interaction-ready output)."""
    config = config or RefineConfig()
    try:
        if extracted is None:
            reading = ReadOptions(body=config.body, mjcf_angle=config.mjcf.angle)
            asset, findings = extract.extract_asset_checked(asset_dir, asset_id=asset_id, category=category, reading=reading)
        else:
            asset, findings = extracted[0], list(extracted[1])
        output_folder.check_location(asset.source_dir, out_dir)
        if asset.staged_from is not None:  # never into the folder the MJCF or USD file lies in
            output_folder.check_location(asset.staged_from.parent, out_dir)
    except (extract.AssetError, output_folder.OutputError) as exc:
        raise RefineError(str(exc), "invalid_input", getattr(exc, "codes", None)) from exc
    wrong = [f for f in findings if f.code == "JOINT_RANGE_WRONG_UNIT"]
    if wrong:
        lines = "\n  ".join(f.describe() for f in wrong)
        raise RefineError(f"{asset.staged_from or asset.urdf_path}: a joint range in the wrong unit; not refined:\n  {lines}\n"
                          "  (an MJCF fragment: --mjcf-angle radian|degree, config mjcf.angle, says which unit its angles are in)",
                          "invalid_input", ["JOINT_RANGE_WRONG_UNIT"])
    return asset, findings


def _keep_declared(est: estimator.Estimator, asset_dir: Path | str, asset: AssetDescription) -> estimator.Estimator:
    """``est`` keeping the asset's plausible declared physics (:class:`asset2sim.tasks.audit.keep.KeepDeclared`);
    RefineError("invalid_input") when the declared physics cannot be read."""
    try:
        declared = read_declared(asset_dir, asset.urdf_path)
    except Exception as exc:
        raise RefineError(f"{asset.urdf_path}: the declared physics cannot be read: {exc}", "invalid_input") from exc
    return keep.KeepDeclared(est, declared)


def _check_overrides(asset: AssetDescription, config: RefineConfig) -> None:
    """RefineError("invalid_input", [OVERRIDE_*]) unless ``config.overrides`` fit the asset."""
    try:
        overrides.apply_overrides(RequestSpec(), config.overrides, asset)
    except overrides.OverrideError as exc:
        raise RefineError(f"{asset.urdf_path}: {exc}", "invalid_input", [exc.code]) from exc


def _completed_result(out_dir: Path, log: _StageLog) -> RefineResult:
    """The result recorded in a complete output folder (nothing recomputed)."""
    report = read_report_json(out_dir)
    overlay = Overlay.model_validate_json(atomic.read_regular(out_dir / write.OVERLAY_NAME, output_folder.MAX_RECORD_BYTES))
    log.say("skip", f"{out_dir} is complete for this input and configuration")
    return RefineResult(out_dir=out_dir, report=report, overlay=overlay, skipped=True)


def _announce_extract(asset: AssetDescription, findings: list, log: _StageLog) -> None:
    log.say("extract", f"{asset.urdf_path}: {len(asset.links)} links, {len(asset.movable_joints())} movable joints, category {asset.category}"
            + (f"; {len(findings)} validation findings (none fatal)" if findings else ""))
    log.lap("extract")


def _analyze(asset: AssetDescription, cache: analyze.MeshCache, log: _StageLog) -> dict[str, LinkGeometry]:
    """Stage 2: mesh analysis of every link; RefineError("invalid_input") on failure."""
    try:
        geometry = analyze.analyze_asset(asset, cache=cache)
    except Exception as exc:
        raise RefineError(f"{asset.urdf_path}: mesh analysis failed: {exc}", "invalid_input") from exc
    log.say("analyze", f"{len(geometry)} links with geometry, volumes " + ", ".join(f"{k}={g.volume:.3g}" for k, g in geometry.items()))
    log.lap("analyze")
    return geometry


def _moving_links(ctx: EstimationContext) -> list[str]:
    """Links moved by the task-relevant joints (sorted)."""
    return sorted({ln for j in estimate.task_relevant_joints(ctx) for ln in ctx.subtrees[j]})


def _interpret(ctx: EstimationContext, log: _StageLog) -> str:
    """Stage 3: the resting pose the request asks for ("lying flat", "sideways") into
    ``ctx.root_rotation``. Returns the pose note ("" when none was asked)."""
    spec = ctx.request
    pose_note = ""
    if spec.pose_hint in ("lying_flat", "sideways"):
        ctx.root_rotation, pose_note = pose.resting_rotation(ctx.session, ctx.asset, ctx.closed_state(), ctx.hull_points, _moving_links(ctx))
        log.say("request", f"pose '{spec.pose_hint}': {pose_note}")
    for note in request_notes(spec):
        log.say("request", note)
    log.say("request", f"category {ctx.category}; size {spec.size_class or 'regular'}; states " + (", ".join(js.short() for js in spec.joint_states) or "none asked"))
    log.lap("closed_state")
    return pose_note


def request_notes(spec: RequestSpec) -> list[str]:
    """The report's and the terminal's lines on the request's unused words: a warning when none was
    understood (the category's defaults are used), else the unused words; empty when every word was used. A note
    on which parse was used and why comes first when the model was asked to parse (``--request-parser model``)."""
    if not spec.understood:
        return ([spec.parse_note] if spec.parse_note else []) + [f"WARNING: request not understood (English words only; none recognised): {spec.text[:120]!r}; "
                "refined with the category's defaults (typical size, closed, moderate damping)"]
    out = [f"WARNING: {w}" for w in spec.warnings] + ([spec.parse_note] if spec.parse_note else [])
    if spec.ignored:
        out.append("request words not used: " + "; ".join(f"'{g}'" for g in spec.ignored[:30]) + (" ..." if len(spec.ignored) > 30 else ""))
    return out


# ----------------------------------------------------- 4-7: synthesize .. post-check
@dataclass
class _Synthesis:
    """Stage 4's result: the validated overlay and the state it asks for."""

    overlay: Overlay
    issues: list
    bands: dict[str, str]
    prismatic: set[str]
    closed_out: dict[str, ClosedState]  # at the overlay's scale
    requested: dict[str, float]  # joint positions, output units
    targets: dict[str, request_apply.JointTarget] = field(default_factory=dict)  # numbers / ends the request asked


@dataclass
class _Attempt:
    """One synthesize -> validate -> write -> refine state -> post-check pass."""

    asset: AssetDescription
    overlay: Overlay
    issues: list
    bands: dict[str, str]
    prismatic: set[str]
    closed_out: dict[str, ClosedState]
    st: StateRefinement
    state: dict[str, float]
    overrides: dict
    root_rotation: object
    check: postcheck.PostCheck
    rounds: list[EscalationRound]
    design: list[str] = field(default_factory=list)  # what stability by design changed and why
    targets: dict = field(default_factory=dict)  # joint -> request_apply.JointTarget
    rewritten: bool = False  # loaded again after another attempt: its files may differ from those ``check`` measured

    @property
    def candidate(self) -> Candidate:
        return Candidate(self.asset, self.overlay, self.state, self.overrides, self.root_rotation)

    def rewrite(self, ws: Workspace) -> None:
        """Load this attempt into the workspace again (after another attempt replaced it)."""
        self.rewritten = True
        ws.load(self.candidate)


def _synthesize_and_check(ctx: EstimationContext, est, config: RefineConfig, ws: Workspace, cache, log: _StageLog, pose_note: str) -> tuple[_Attempt, str]:
    """Stages 4-7 once; when the object is unstable or toppled as modelled and the request named no
    pose, a steadier opening, else once more on its stablest face (kept only if better). Returns (attempt, pose note)."""
    att = _attempt(ctx, est, config, ws, cache, log)
    if (att.check.stable and not att.check.topples) or ctx.request.pose_hint is not None:
        return att, pose_note
    steadier = _steadier_state(ctx, est, config, ws, cache, log, att)
    if steadier is not None:
        return steadier, pose_note
    state_in = estimate.state_from_bands(ctx.closed, att.bands, 1.0, att.prismatic)
    R, note = pose.most_stable_rotation(ctx.session, ctx.asset, att.overlay.links, state_in, att.overlay.scale, ctx.hull_points, _moving_links(ctx), exclude_modelled=True)
    if R is None:
        return att, pose_note
    why = "unstable as modelled" if not att.check.stable else "toppled by a robust-rest disturbance as modelled"
    log.say("post_check", f"{why}; {note}")
    ctx.root_rotation = R
    second = _attempt(ctx, est, config, ws, cache, log)
    if second.check.stable and (second.check.passed or not att.check.passed) and not (
            second.check.topples and not att.check.topples):
        return second, f"{why}; {note}"
    ctx.root_rotation = None
    att.rewrite(ws)  # the first attempt stays the result
    return att, f"{note}; not better in simulation, kept as modelled"


def _steadier_state(ctx: EstimationContext, est, config: RefineConfig, ws: Workspace, cache, log: _StageLog,
                    att: _Attempt) -> _Attempt | None:
    """Stability by design through the opening after an unsteady attempt ``att``: the opened joints where,
    within their bands, the object stands steadiest (:func:`asset2sim.tasks.state.balance.steadiest_fractions`),
    or, when statically steady yet unstable or toppled in simulation, the least opening each band allows. Stages 4-7 run once more from
    there. Returns that attempt when it passes every check, else None (``att`` loaded again)."""
    intervals = estimate.band_intervals(att.bands, {n: t.interval for n, t in att.targets.items() if t.interval is not None})
    try:
        fractions, before, after = balance.steadiest_fractions(ws.model(), att.overlay, att.state, att.closed_out, intervals)
    except Exception as exc:  # a measurement that fails leaves the attempt as it was
        log.say("stability", f"steadier opening not measured ({type(exc).__name__}: {exc})")
        return None
    why = "unstable" if not att.check.stable else "toppled by a robust-rest disturbance"
    if fractions and after.stable:
        note = (f"stability by design: {why} at the bands' targets; "
                + ", ".join(f"{n} opened to {f:.2f} of its range (allowed {intervals[n][0]:.2f}-{intervals[n][1]:.2f})" for n, f in fractions.items())
                + f", where the object stands steadiest: static margin {before.margin * 1000:.3g} -> {after.margin * 1000:.3g} mm"
                f" (asked >= {after.required * 1000:.3g} mm)")
    elif before.stable:  # statically steady, yet unstable or toppled in simulation
        fractions = _least_openings(att, intervals)
        if not fractions:
            return None
        note = (f"stability by design: {why} at the bands' targets although statically steady (margin "
                f"{before.margin * 1000:.3g} mm, asked >= {before.required * 1000:.3g} mm); "
                + ", ".join(f"{n} opened to {f:.2f} of its range, the least its band allows ({intervals[n][0]:.2f}-{intervals[n][1]:.2f})"
                            for n, f in fractions.items()))
    else:  # the opening alone does not make it steady: the resting pose may
        return None
    log.say("stability", note)
    second = _attempt(ctx, est, config, ws, cache, log, fractions=fractions)
    if second.check.passed and not second.check.topples:
        second.design = [note, *second.design]
        return second
    log.say("stability", "the steadier opening did not pass every check: the bands' targets kept")
    att.rewrite(ws)
    return None


def _least_openings(att: _Attempt, intervals: dict[str, tuple[float, float]]) -> dict[str, float]:
    """Joint -> the lower end of its opening-fraction interval, for the joints the attempt opened past
    that end (> 0) by more than 0.01 of the range."""
    return {name: float(lo) for name, (lo, hi) in intervals.items() if att.closed_out.get(name) is not None and name in att.state
            and 0 < lo < hi and att.closed_out[name].fraction(att.state[name]) > lo + 0.01}


def _at_fractions(closed: dict[str, ClosedState], fractions: dict[str, float]) -> dict[str, float]:
    """Joint -> position (rad or m) at each opening fraction (joints without a closed state left out)."""
    return {n: closed[n].position(f) for n, f in fractions.items() if n in closed}


def _attempt(ctx: EstimationContext, est, config: RefineConfig, ws: Workspace, cache, log: _StageLog,
             fractions: dict[str, float] | None = None) -> _Attempt:
    """Stages 4-7 for the current ``ctx.root_rotation``; ``fractions`` (joint -> opening fraction)
    replace the requested state of those joints."""
    syn = _synthesize(ctx, est, config, log)
    if fractions:
        syn = replace(syn, requested={**syn.requested, **_at_fractions(syn.closed_out, fractions)})
    urdf, first_clear = _write(ctx, syn, ws, log)
    shut, shut_notes = _shut_repair(ctx, syn, urdf, config, ws, cache, log)
    syn = _closed_on_output(ctx, syn, urdf, ws, log, shut)
    closed_raw = syn.closed_out
    clipped = _clip_synthesis(ctx, syn, urdf, config, ws, log, shut, fractions)
    if clipped is not syn:  # clipped limits change the pieces and the range the closed end is found in: measured once more
        clipped = _closed_on_output(ctx, clipped, urdf, ws, log, shut)
    syn = clipped
    st, overrides = _refine_state(ctx, est, syn, urdf, config, ws, cache, log, shut)
    st.collision_changes = shut_notes + list(st.collision_changes)
    state = dict(st.result)
    room = [f"{j} ({ctx.asset.link(ctx.asset.joint(j).child).semantic_label or 'part'}) opened to {f:.2f} of its range: the request "
            f"did not address it (closed by default) and a part the request opened lay through it closed" for j, f in st.room_made.items()]
    if st.room_made:
        syn = replace(syn, bands={**syn.bands, **{j: request_apply.band_of(f) for j, f in st.room_made.items()}})
        for line in room:
            log.say("refine_state", line)
    state, overrides, floored, lifted = ground_clearance.apply_ground_clearance(
        ctx.asset, syn.overlay, ws, state, overrides, manipulation.closed_tuples(syn.closed_out), ctx.root_rotation)
    st.collision_changes = list(st.collision_changes) + lifted
    if overrides is not shut:  # the state search changed the collision pieces: the limits are clipped again on them (stage 6b)
        unclipped = limits.strip_clips(syn.overlay)
        ws.load(Candidate(ctx.asset, unclipped, state, overrides, ctx.root_rotation))
        reclipped, closed_re = _clip_limits(unclipped, closed_raw, state, ws, config, log)
        syn = replace(syn, overlay=reclipped, closed_out=closed_re)
    balanced, design = stability.design_for_stability(ws.model(), ctx.asset, syn.overlay, state, ctx.category, ctx.geometry)
    design = floored + design
    for line in design:
        log.say("stability", line)
    design = room + design
    closed_out = syn.closed_out
    overlay, check, rounds = _post_check(ctx, balanced, state, overrides, urdf, config, ws, log,
                                         closed=manipulation.closed_tuples(closed_out))
    overlay, check, rounds, overrides, closed_out = _repair_sweep(
        ctx, limits.strip_clips(balanced), closed_raw, (overlay, check, rounds, overrides, closed_out), st, state, urdf, config, ws, log)
    # the clearance of the first pieces (carried on by pieces a repair rewrote from them) and of the final ones
    clear = list(dict.fromkeys(first_clear + _clearance_notes(ctx, overlay, state, overrides, ws)))
    st.collision_changes = clear + list(st.collision_changes)
    return _Attempt(asset=ctx.asset, overlay=overlay, issues=syn.issues, bands=syn.bands, prismatic=syn.prismatic, closed_out=closed_out,
                    st=st, state=state, overrides=overrides, root_rotation=ctx.root_rotation, check=check, rounds=rounds,
                    design=design, targets=syn.targets)


def _synthesize(ctx: EstimationContext, est, config: RefineConfig, log: _StageLog) -> _Synthesis:
    """Stage 4: the estimator's overlay (validated) and bands, the requested state at its scale.
    RefineError("estimator_failure" or "invalid_overlay")."""
    asset = ctx.asset
    prismatic = {j.name for j in asset.movable_joints() if j.type == "prismatic"}
    try:
        result = est.estimate(ctx)
    except Exception as exc:
        raise RefineError(f"{asset.asset_id}: estimator {config.estimator!r} failed: {exc}", "estimator_failure", ["ESTIMATOR_FAILED"]) from exc
    bands = dict(result.bands)
    log.lap("synthesize")
    try:
        overlay, issues = validate_overlay.validate_overlay(result.overlay, asset, ctx.geometry)
    except validate_overlay.OverlayInvalid as exc:
        raise RefineError(f"{asset.asset_id}: {exc}", "invalid_overlay") from exc
    overlay = overlay.model_copy(update={"mounting": _root_mounting(ctx, config)})
    s = overlay.scale
    overlay, targets = request_apply.check_against_request(ctx, overlay, result.targets)
    requested = estimate.state_from_bands(ctx.closed, bands, s, prismatic)
    requested.update(overlay.initial_joint_positions or {})
    log.say("synthesize", f"{overlay.estimator.name}: scale {s:.4g}, total mass {overlay.total_mass():.4g} kg, {len(issues)} validation findings")
    log.lap("validate")
    return _Synthesis(overlay, issues, bands, prismatic, _scaled_closed(ctx.closed, s, prismatic), requested, targets)


def _scaled_closed(closed: dict[str, ClosedState], scale: float, prismatic: set[str]) -> dict[str, ClosedState]:
    """Closed ends at ``scale`` (prismatic positions and ranges times ``scale``)."""
    return {n: replace(cs, q_closed=cs.q_closed * scale, open_range=cs.open_range * scale, lower=cs.lower * scale,
                       upper=cs.upper * scale) if n in prismatic else cs for n, cs in closed.items()}


def _write(ctx: EstimationContext, syn: _Synthesis, ws: Workspace, log: _StageLog) -> tuple[Path, list[str]]:
    """Stage 5: the candidate at the requested state loaded into the workspace.
    Returns (the URDF path, the writer's clearance notes)."""
    urdf = ws.load(Candidate(ctx.asset, syn.overlay, syn.requested, {}, ctx.root_rotation))
    clear = _clearance_lines(ws.collision_notes)
    for line in clear:
        log.say("write", line)
    log.lap("write")
    return urdf, clear


def _clearance_notes(ctx: EstimationContext, overlay: Overlay, state: dict[str, float], overrides: dict, ws: Workspace) -> list[str]:
    """The writer's clearance notes for the output as written with ``overlay``, ``state`` and
    ``overrides`` (cached pieces: nothing recomputed, no file changes)."""
    notes: list[str] = []
    write.build_urdf(ctx.asset, overlay, overrides, ctx.root_rotation, (ws.root, state), notes, ws.open_containers)
    return _clearance_lines(notes)


def _clearance_lines(notes: list[str]) -> list[str]:
    """The writer's collision notes on running clearance, a levelled footprint, pieces thinner than their part,
    a child kept inside its parent past a stop and containers kept open."""
    return [n for n in notes if any(w in n for w in (sliding_clearance.RUNNING_CLEARANCE_NOTE, footprint.LEVEL_NOTE,
                                                     collision_geometry.DENSITY_NOTE, parent_child_separation.PAST_STOP_NOTE,
                                                     container_pieces.CAVITY_NOTE))]


def _refine_state(ctx: EstimationContext, est, syn: _Synthesis, urdf: Path, config: RefineConfig, ws: Workspace, cache, log: _StageLog,
                  base: dict | None = None) -> tuple[StateRefinement, dict]:
    """Stage 6: state refinement on the written asset (with the estimator's joint proposer when it has
    one); ``base``: the collision overrides written. Returns (refinement, collision overrides)."""
    proposer = est.joint_proposer(ctx) if hasattr(est, "joint_proposer") else None
    st, overrides = _refine_state_with_decomposition(
        ctx.asset, syn.overlay, syn.closed_out, syn.bands, syn.requested, urdf, ctx.root_rotation, config, ws, cache, log.say, proposer=proposer,
        intervals={n: t.interval for n, t in syn.targets.items() if t.interval is not None},
        addressed=lambda: request_apply.resolve_states(ctx, syn.overlay.scale).addressed, base=base)
    log.say("refine_state", f"Phi {st.phi_requested * 1000:.3g} mm -> {st.phi_result * 1000:.3g} mm in {st.evaluations} evaluations ({st.method})")
    log.lap("refine_state")
    return st, overrides


def _closed_on_output(ctx: EstimationContext, syn: _Synthesis, urdf: Path, ws: Workspace, log: _StageLog,
                      overrides: dict | None = None) -> _Synthesis:
    """Stage 5a: the closed ends measured on the written output (:mod:`asset2sim.tasks.geometry.urdf_closed`),
    the requested state and the overlay's initial positions moved onto them and the candidate loaded again
    (with the collision ``overrides``). Unchanged when the measurement fails."""
    try:
        measured = urdf_closed.measure_closed(ws.model())
    except Exception as exc:
        log.say("closed_state", f"closed ends not measured on the output ({type(exc).__name__}: {exc}); the input's are used")
        return syn
    new = {n: measured.get(n, c) for n, c in syn.closed_out.items()}
    moved = [n for n, c in new.items() if abs(c.q_closed - syn.closed_out[n].q_closed) > 1e-9 or c.direction != syn.closed_out[n].direction]
    if not moved:
        return replace(syn, closed_out=new)
    keep = {n for n, t in syn.targets.items() if t.kind in ("angle", "distance")}
    requested = urdf_closed.replace_positions(syn.requested, syn.closed_out, new, keep)
    overlay = syn.overlay
    if overlay.initial_joint_positions:
        overlay = overlay.model_copy(update={"initial_joint_positions": urdf_closed.replace_positions(
            overlay.initial_joint_positions, syn.closed_out, new, keep)})
    for n in moved:
        log.say("closed_state", f"joint {n}: closed end {new[n].q_closed:.4g} on the output's collision pieces "
                                f"({syn.closed_out[n].q_closed:.4g} before); the state is placed from it")
    ws.load(Candidate(ctx.asset, overlay, requested, overrides, ctx.root_rotation))
    targets = request_apply.retarget(syn.targets, syn.closed_out, new)  # the angle asked, from the new closed end
    bands = {**syn.bands, **{n: t.band for n, t in targets.items() if t is not syn.targets[n]}}
    return replace(syn, overlay=overlay, closed_out=new, requested=requested, targets=targets, bands=bands)


def _clip_synthesis(ctx: EstimationContext, syn: _Synthesis, urdf: Path, config: RefineConfig, ws: Workspace, log: _StageLog,
                    overrides: dict | None = None, fractions: dict[str, float] | None = None) -> _Synthesis:
    """Stage 5b: the limits clipped to the geometry before the state search, the requested state
    recomputed from the bands over the clipped ranges (``fractions`` win over the bands' targets) and the
    candidate loaded again (with the collision ``overrides``). ``syn`` itself when nothing was clipped."""
    overlay, closed_out = _clip_limits(syn.overlay, syn.closed_out, syn.requested, ws, config, log)
    if overlay is syn.overlay:
        return syn
    s = overlay.scale
    targets = request_apply.retarget(syn.targets, syn.closed_out, closed_out)  # an angle asked stays that angle from the closed end
    moved = {n: t for n, t in targets.items() if t is not syn.targets[n]}
    bands = {**syn.bands, **{n: t.band for n, t in moved.items()}}
    if moved and overlay.initial_joint_positions:
        overlay = overlay.model_copy(update={"initial_joint_positions": {
            **overlay.initial_joint_positions, **{n: closed_out[n].position(t.fraction) for n, t in moved.items()}}})
    unscaled = _scaled_closed(closed_out, 1.0 / s, syn.prismatic)
    requested = estimate.state_from_bands(unscaled, bands, s, syn.prismatic)
    requested.update(overlay.initial_joint_positions or {})
    requested.update(_at_fractions(closed_out, fractions or {}))
    ws.load(Candidate(ctx.asset, overlay, requested, overrides, ctx.root_rotation))
    return replace(syn, overlay=overlay, closed_out=closed_out, requested=requested, targets=targets, bands=bands)


def _clip_limits(overlay: Overlay, closed_out: dict[str, ClosedState], state: dict[str, float], ws: Workspace, config: RefineConfig,
                 log: _StageLog) -> tuple[Overlay, dict[str, ClosedState]]:
    """Stage 6b: joint limits clipped to what the geometry allows at ``state`` (:mod:`asset2sim.tasks.geometry.limits`;
    with a carrying chain, also against the chain opened). Returns (overlay, closed ends)."""
    with open_session("pybullet", ws.urdf, SessionOptions(fixed_base=True, gravity=False, ground=False, initial_state=state,
                                                       conventions=config.sim)) as sess:
        clips = limits.geometric_limits(sess, ws.model(), manipulation.closed_tuples(closed_out), state)
    if any(c.clipped for c in clips.values()):
        overlay, notes = limits.apply_clips(overlay, clips)
        for line in notes:
            log.say("limits", line)
        closed_out = limits.clipped_closed(closed_out, clips)
    log.lap("limits")
    return overlay, closed_out


def _repair_sweep(ctx: EstimationContext, unclipped: Overlay, closed_raw: dict[str, ClosedState], result: tuple, st: StateRefinement,
                  state: dict[str, float], urdf: Path, config: RefineConfig, ws: Workspace, log: _StageLog):
    """Stage 7b: collision repairs where the post-check shows a part held by its neighbours' pieces: a
    blocked joint sweep (:func:`asset2sim.tasks.check.repair.sweep_repairs`, better = a better sweep score)
    or parts held together (running clearance, better = fewer failing tiers). Each repair is loaded, the
    limits clipped again from ``unclipped`` and ``closed_raw``, and post-checked; the first that is better
    while no passed metric fails is kept. ``result``: (overlay, check, rounds, collision overrides, closed
    ends), returned unchanged or replaced; notes go to ``st.collision_changes``."""
    overlay, check, rounds, overrides, closed_out = result
    sw = next((m for m in check.metrics if m.name == "joint_sweep"), None)
    blocked = {} if sw is None or sw.passed is not False else sweep.blocked_positions(sw)
    pairs = [] if blocked else repair.held_together_pairs(check.metrics)
    if not blocked and not pairs:
        return result  # the common case: nothing read, nothing simulated
    model = ws.model()
    folder = write.collision_folder(ctx.asset)
    if blocked:
        label = "sweep blocked"
        repairs = repair.sweep_repairs(model, urdf, ctx.asset, sw, blocked, state, overrides, unclipped.scale, ws.root,
                                       folder, config)

        def better(chk2) -> bool:
            return sweep.sweep_score(next(m for m in chk2.metrics if m.name == "joint_sweep")) < sweep.sweep_score(sw)
    else:
        label = "parts held together"
        touching = clearance.touching_joints(model, pairs, state, limits.subtrees(model))
        one = repair.clearance_repair(model, urdf, touching, state, overrides, unclipped.scale, ws.root, folder) if touching else None
        repairs = iter([one] if one is not None else [])

        def better(chk2) -> bool:
            return dynamics_search.failing_tiers(chk2.metrics) < dynamics_search.failing_tiers(check.metrics)
    passed_before = {(m.name, m.engine) for m in check.metrics if m.passed}
    for rep in repairs:
        ws.load(Candidate(ctx.asset, unclipped, state, rep.overrides, ctx.root_rotation))
        clipped, closed2 = _clip_limits(unclipped, closed_raw, state, ws, config, log)
        ov2, check2, rounds2 = _post_check(ctx, clipped, state, rep.overrides, urdf, config, ws, log,
                                           closed=manipulation.closed_tuples(closed2))
        lost = [m.name for m in check2.metrics if (m.name, m.engine) in passed_before and m.passed is False]
        if better(check2) and not lost:
            for line in rep.notes:
                log.say("sweep_repair", line)
            st.collision_changes = list(st.collision_changes) + rep.notes
            n = len(rounds)
            rounds = rounds + [r.model_copy(update={"round": n + r.round, "reason": f"{rep.what} ({label}): {r.reason}"})
                               for r in rounds2]
            return ov2, check2, rounds, rep.overrides, closed2
        log.say("sweep_repair", f"{rep.what} not kept ({label}; failing metrics {dynamics_search.failing_tiers(check.metrics)} -> "
                                f"{dynamics_search.failing_tiers(check2.metrics)}{'; would fail ' + ', '.join(lost) if lost else ''}); "
                                "the asset kept as it was")
        ws.load(Candidate(ctx.asset, overlay, state, overrides, ctx.root_rotation))
    return result


def _post_check(ctx: EstimationContext, overlay: Overlay, state: dict[str, float], overrides: dict, urdf: Path, config: RefineConfig, ws: Workspace, log: _StageLog,
                closed: dict[str, tuple[float, float, float]] | None = None) -> tuple[Overlay, postcheck.PostCheck, list[EscalationRound]]:
    """Stage 7: post-check the refined state (``closed``: closed ends at the output scale, for the sweep and
    robust rest) and escalate damping and friction up to ``config.max_escalation_rounds`` times while it
    fails. Returns (final overlay, last check, rounds)."""
    asset, root_rotation = ctx.asset, ctx.root_rotation
    if overlay.initial_joint_positions is not None:
        overlay = overlay.model_copy(update={"initial_joint_positions": state})
    rounds: list[EscalationRound] = []
    ws.load(Candidate(asset, overlay, state, overrides, root_rotation))
    recorded = postcheck.RecordedRuns()  # the manipulation tiers' runs, handed on to the evaluation
    labels = task_tier.link_labels(asset)
    n = 0
    spec = task_tier.task_spec_for(ctx.task, ws.model(), asset, ctx.category, estimate.task_relevant_joints(ctx), state, closed) \
        if ctx.task and closed else None
    # what the task's gripper can still operate on the task's joints (task_tier.operating_limits); estimates above it are lowered
    lim = task_tier.operating_limits(ws.model(), state, overlay, asset, ctx.geometry, closed, category=ctx.category, task=ctx.task,
                                     free_moving=ctx.request.free_moving, conventions=config.sim,
                                     joints=spec.joints if spec is not None else None)
    bounded, notes = operating.bound_overlay(overlay, lim.budgets)
    for line in notes:
        log.say("post_check", line)
    if bounded != overlay:
        overlay = bounded
        ws.load(Candidate(asset, overlay, state, overrides, root_rotation))
    caps, dcaps = lim.friction_caps, lim.damping_caps
    floors = operating.tilt_floors(overlay, overlay, asset, robust_rest.RobustRestConfig().tilt)

    def escalated(chk: postcheck.PostCheck) -> bool:  # this loop escalates ``chk`` (the post-check then skips the sweep)
        return n < config.max_escalation_rounds and bool(postcheck.escalate(overlay, chk, config.escalation_factor, caps, floors, dcaps)[1])

    def with_task(chk: postcheck.PostCheck) -> postcheck.PostCheck:  # the task tier appended when refine was given a task
        if spec is not None:
            chk.metrics = [*chk.metrics, *task_tier.run_task_tier(
                "pybullet", ws.model(), state, export_mjcf.overlay_springs(overlay), config.sim, closed, spec, asset, ctx.category,
                fixed_base=bool(overlay.mounting is not None and overlay.mounting.fixed),
                free_moving=ctx.request.free_moving, spring_requested=ctx.request.spring, recorded=recorded)]
        return chk

    check = with_task(postcheck.run_post_check(ws.model(), state, overlay, config, closed=closed, escalated=escalated, recorded=recorded,
                                                     category=ctx.category, labels=labels))
    rounds.append(EscalationRound(round=0, metrics=check.metrics, reason="initial post-check"))
    search = dynamics_search.DynamicsSearch(lim.budgets, lim.hand_caps)  # relief and escalation bracketed by what each round measured
    search.record(overlay, check.metrics)
    tried = [(overlay, check)]
    while (not check.passed or task_tier.task_failing(check.metrics)) and n < config.max_escalation_rounds:
        n += 1
        before = overlay
        # a task that needed more than a real operating force first: lower friction / damping (and their caps)
        overlay, changes, reason = task_tier.relieve(overlay, check.metrics, lim)
        if not changes:
            overlay, changes, reason = postcheck.escalate(overlay, check, config.escalation_factor, caps, floors, dcaps)
        overlay, changes, notes = search.settle(before, overlay, changes, caps)
        reason = "; ".join([reason, *notes]) if reason and notes else reason or "; ".join(notes)
        if not changes:
            break
        ws.load(Candidate(asset, overlay, state, overrides, root_rotation))
        check = with_task(postcheck.run_post_check(ws.model(), state, overlay, config, closed=closed, escalated=escalated, recorded=recorded,
                                                     category=ctx.category, labels=labels))
        rounds.append(EscalationRound(round=n, metrics=check.metrics, changes=changes, reason=reason))
        search.record(overlay, check.metrics)
        tried.append((overlay, check))
    best = dynamics_search.fewest_failures([c.metrics for _, c in tried])
    earlier = best != len(tried) - 1
    sweep_skipped = postcheck.sweep_not_run(check.metrics)  # an escalation round: the sweep (and the other engines) not run
    if earlier or sweep_skipped:  # checked again, the sweep included
        reason = (f"round {best} failed the fewest tiers: its friction and damping kept" if earlier
                  else "the last round's setting checked again with the joint sweep")
        if earlier:
            overlay = tried[best][0]
            ws.load(Candidate(asset, overlay, state, overrides, root_rotation))
        check = with_task(postcheck.run_post_check(ws.model(), state, overlay, config, closed=closed, recorded=recorded,
                                                   category=ctx.category, labels=labels))
        changes = {n_: {"damping": d.damping, "friction": d.friction} for n_, d in overlay.joints.items()}
        rounds.append(EscalationRound(round=rounds[-1].round + 1, metrics=check.metrics, changes=changes, reason=reason))
    log.lap("post_check")
    return overlay, check, rounds


def _phi_at(urdf: Path, state: dict[str, float], config: RefineConfig) -> float:
    """Phi (m, the SPEC's self-penetration) of ``urdf`` at ``state`` (joint -> rad or m)."""
    with open_session("pybullet", urdf, SessionOptions(fixed_base=True, gravity=False, ground=False, initial_state=state,
                                                       conventions=config.sim)) as sess:
        return float(sess.self_penetration_fresh()[0])


def _shut_repair(ctx: EstimationContext, syn: _Synthesis, urdf: Path, config: RefineConfig, ws: Workspace, cache,
                 log: _StageLog) -> tuple[dict, list[str]]:
    """Stage 5 (before 5a): collision pieces that let the object shut. When the request opens a joint and the
    closed configuration overlaps beyond the tolerance, the state search with its collision repair runs as for
    a closed request. Returns (collision overrides, notes for ``state.collision_changes``); ({}, []) when not run."""
    closed = {n: c.q_closed for n, c in syn.closed_out.items()}
    opened = [n for n, c in syn.closed_out.items()
              if abs(c.fraction(syn.requested.get(n, c.q_closed))) > BAND_INTERVAL["closed"][1]]
    if not (config.convex_decomposition and opened and _phi_at(urdf, closed, config) > config.penetration_tolerance):
        return {}, []
    ws.load(Candidate(ctx.asset, syn.overlay, closed, {}, ctx.root_rotation))
    shut, overrides = _refine_state_with_decomposition(
        ctx.asset, syn.overlay, syn.closed_out, {n: "closed" for n in syn.closed_out}, closed, urdf, ctx.root_rotation,
        config, ws, cache, log.say)
    ws.load(Candidate(ctx.asset, syn.overlay, syn.requested, overrides, ctx.root_rotation))
    head = (f"closed configuration (the request opens {', '.join(opened)}): Phi {shut.phi_requested * 1000:.3g} -> "
            f"{shut.phi_result * 1000:.3g} mm" + ("" if overrides else "; collision pieces kept"))
    log.say("shut_repair", head)
    log.lap("shut_repair")
    return overrides, [head + (":" if shut.collision_changes else "")] + list(shut.collision_changes)


def _refine_state_with_decomposition(asset, overlay, closed_out, bands, requested, urdf, root_rotation, config, ws, mesh_cache, say, proposer=None, intervals=None,
                                     addressed: Callable[[], set[str]] | None = None, base: dict | None = None):
    """State refinement; then, each kept only if it lowers Phi: a search with the parts the request left
    closed (not in ``addressed()``) free where an opened part penetrates them, and CoACD decomposition of the
    colliding pieces with another search. ``base``: the collision overrides written (the pieces changed here
    replace those of the same links). Returns (StateRefinement, collision overrides)."""
    fractions = estimate.band_intervals(bands, intervals)
    s = overlay.scale

    def search(start: dict[str, float]):
        with open_session("pybullet", urdf, SessionOptions(fixed_base=True, gravity=False, ground=False, conventions=config.sim)) as sess:
            return refine_state.refine_initial_state(
                sess, asset, closed_out, start, fractions, tolerance=config.penetration_tolerance, lam=config.state_lambda,
                max_evaluations=config.max_state_evaluations, seed=config.seed, proposer=proposer)

    st = search(requested)
    in_the_way = [] if addressed is None or not st.phi_result > config.penetration_tolerance else \
        refine_state.joints_in_the_way(asset, st.worst_pairs, bands, addressed(), config.penetration_tolerance)
    if in_the_way:
        held = fractions
        fractions = {**fractions, **{j: (0.0, 1.0) for j in in_the_way}}
        room = search(st.result)
        if room.phi_result < st.phi_result:
            room.requested, room.phi_requested = st.requested, st.phi_requested
            room.evaluations += st.evaluations
            room.model_queries += st.model_queries
            room.method = f"{st.method} | {', '.join(in_the_way)} free to make room -> {room.method}"
            room.room_made = {j: float(abs(closed_out[j].fraction(room.result[j]))) for j in in_the_way if j in closed_out}
            st = room
        else:
            fractions = held
    base = {} if base is None else base  # returned as it is when nothing changes (the caller tells by identity)
    if not (st.phi_result > config.penetration_tolerance and config.convex_decomposition):
        return st, base
    deep = [(p_["link_a"], p_["link_b"]) for p_ in st.worst_pairs if p_["depth_m"] > config.penetration_tolerance]
    links = sorted({ln for pair in deep for ln in pair})
    sess = open_session("pybullet", urdf, SessionOptions(fixed_base=True, gravity=False, ground=False, initial_state=st.result))
    try:
        overrides, dnotes = collision.improve_collisions(sess, asset, deep, s, ws.root, cache=mesh_cache,
                                                         max_decompositions=config.max_decompositions,
                                                         folder=write.collision_folder(asset))
    except (DecompositionUnavailable, ValueError) as exc:
        say("refine_state", f"collision improvement skipped: {exc}")
        st.collision_changes = [f"collision improvement skipped: {exc}"]
        return st, base
    finally:
        sess.close()
    if not overrides:
        st.collision_changes = dnotes or [f"no collision piece change lowered the overlap of {', '.join(links)}"]
        return st, base
    overrides = {**base, **overrides}
    before = st
    ws.load(Candidate(asset, overlay, requested, overrides, root_rotation))
    st = search(requested)
    st.evaluations += before.evaluations
    st.model_queries += before.model_queries
    st.phi_requested = before.phi_requested
    if st.phi_result >= before.phi_result:
        # the decomposition did not help (pieces of neighbours can bulge): keep the original hulls
        ws.load(Candidate(asset, overlay, requested, base, root_rotation))
        before.evaluations = st.evaluations
        before.model_queries = st.model_queries
        before.collision_changes = [
            f"collision pieces changed for {', '.join(links)} but Phi went {before.phi_result * 1000:.3g} -> "
            f"{st.phi_result * 1000:.3g} mm; original collision meshes kept"
        ] + dnotes
        return before, base
    st.collision_changes = dnotes
    st.method = before.method + " | collision pieces improved -> " + st.method
    return st, overrides


# ---------------------------------------------------------- 8: report, extras, marker
def _announce_post_check(att: _Attempt, log: _StageLog) -> None:
    stab, osc = (att.check.metric(n) for n in ("rest_stability", "oscillation"))
    log.say("post_check", f"penetration {'; '.join(penetration_measures(att.check.metrics)) or 'n/a'}; rest stability {'PASS' if stab.passed else 'FAIL'} (D_pos {stab.details.get('D_pos_m', float('nan')):.2e} m, D_ori {stab.details.get('D_ori_rad', float('nan')):.2e} rad); oscillation {'PASS' if osc.passed else 'FAIL'}; escalation rounds {len(att.rounds) - 1}")


def _staging_notes(asset) -> list[str]:
    """The report's lines on an MJCF or USD input read and staged as a URDF, and on part labels read from link
    names (none for a PartNet-Mobility input)."""
    head = [] if asset.staged_from is None else [f"input: {asset.staged_from} read into the asset model and staged as a URDF"]
    return head + [f"input: {n}" for n in asset.staging_notes]


def _build_report(ctx: EstimationContext, prompt: str, chash: str, att: _Attempt, findings: list, pose_note: str, times: dict[str, float],
                  resolution: request_apply.StateResolution | None = None) -> RefineReport:
    """``report.json``'s model from the final attempt; ``resolution``: what each phrase of the request set
    (``request_apply.resolve_states``), for the as-asked tier (``request_met``)."""
    asset, overlay, st, state, closed_out = ctx.asset, att.overlay, att.st, att.state, att.closed_out
    found = request_apply.findings(ctx, att.targets, closed_out, state, overlay.scale, overlay.total_mass(), list(overlay.notes.other),
                                   overlay, att.rounds, resolution)
    asked = as_asked.refine_request_met(ctx.request, resolution, found, closed_out, state, request_apply.unapplied_properties(ctx))
    metrics = att.check.metrics + [m for res in att.check.engine_results.values() for m in res] + [asked]
    mode = post_check_failure_mode(att.check)
    return RefineReport(
        asset_id=asset.asset_id,
        source=str(asset.staged_from or asset.source_dir),
        prompt=prompt,
        category=ctx.category,
        task=ctx.task,
        version=__version__,
        input_hash=asset.input_hash,
        config_hash=chash,
        estimator=overlay.estimator.name,
        model=overlay.estimator.model,
        model_queries=overlay.estimator.queries + st.model_queries,
        model_tokens=overlay.estimator.tokens,
        model_cost_usd=overlay.estimator.cost_usd,
        model_seconds=overlay.estimator.seconds,
        scale=overlay.scale,
        total_mass=overlay.total_mass(),
        initial_joint_positions=state,
        closed_positions={n_: c.q_closed for n_, c in closed_out.items()},
        requested_bands=att.bands,
        opening_fractions={n_: abs(c.fraction(state[n_])) for n_, c in closed_out.items() if n_ in state},
        state=st,
        metrics=metrics,
        parity=_parity_rows(att.check),
        escalation=att.rounds,
        validation=[f.to_issue().model_dump() for f in findings] + [i.model_dump() for i in att.issues],
        failure_mode=readiness([asked]).failure_mode if mode == "none" else mode,  # the as-asked tier after the physical ones
        readiness=readiness(metrics).tiers,
        stage_seconds=times,
        notes=_staging_notes(asset) + request_notes(ctx.request) + list(overlay.notes.other)
        + ([f"resting pose ({ctx.request.pose_hint or 'stability'}): {pose_note}"] if pose_note else [])
        + [mounting_note(overlay)] + att.design,
        mounting=overlay.mounting,
        design_changes=att.design,
        request=found,
    )


def mounting_note(overlay: Overlay) -> str:
    """The report's line on how the root was held in every check."""
    m = overlay.mounting
    if m is None or not m.fixed:
        return "root: free-standing, free on the ground in every check (SPEC convention)" + (f"; {m.source}" if m else "")
    return f"root: mounted ({m.kind}), fixed in every check (rest, oscillation, probes, evaluation), no ground plane; {m.source}"


def _start_output(asset: AssetDescription, out_dir: Path, overwrite: bool) -> output_folder.OwnedFolder:
    """The output folder claimed (:func:`asset2sim.output_folder.start`); RefineError("invalid_input") with
    the ``OUTPUT_*`` code when refused."""
    try:
        return output_folder.start(asset.source_dir, out_dir, overwrite=overwrite)
    except output_folder.OutputError as exc:
        raise RefineError(str(exc), "invalid_input", exc.codes) from exc


def _parity_rows(check) -> list[dict]:
    """Side-by-side engine rows for the report (PyBullet first)."""
    if not check.engine_results:
        return []
    base = [m for m in check.metrics if m.name in parity.METRICS]
    return parity.parity_table({"pybullet": base, **check.engine_results})


#: errno values of an OSError that says nothing more can be written to the
#: output folder: a full disk, an exhausted quota, a read-only file system.
_UNWRITABLE = frozenset(e for e in (errno.ENOSPC, getattr(errno, "EDQUOT", None), errno.EROFS) if e is not None)


def _raise_if_unwritable(exc: BaseException, out_dir: Path) -> None:
    """Raise ``OUTPUT_WRITE_FAILED`` (an :class:`~asset2sim.output_folder.OutputError`) when ``exc`` or an
    exception in its chain is an OSError whose errno is in :data:`_UNWRITABLE`; return otherwise."""
    seen: set[int] = set()
    cur: BaseException | None = exc
    while cur is not None and id(cur) not in seen:
        seen.add(id(cur))
        if isinstance(cur, OSError) and cur.errno in _UNWRITABLE:
            where = cur.filename or out_dir
            raise output_folder.OutputError(f"output folder {out_dir} cannot be written: {where}: {cur.strerror or cur}",
                                            "OUTPUT_WRITE_FAILED", where) from cur
        cur = cur.__cause__ or cur.__context__


def _root_mounting(ctx: EstimationContext, config: RefineConfig):
    """The root's mounting: ``--mount``, else the request's words, else an MJCF file's own declaration (a root
    without a free joint is welded to the world, as MuJoCo compiles it), else the category prior."""
    source = ctx.asset.staged_from
    if (ctx.request.mount is None and mounting.request_mounting(ctx.request.text, ctx.category) is None
            and source is not None and staged.input_format(source) == "mjcf"):
        reading = ReadOptions(body=config.body, mjcf_angle=config.mjcf.angle)
        declared = mounting.declared_mounting(ctx.category, read_declared(source, ctx.asset.urdf_path, reading).root_fixed,
                                              "the MJCF file")
        if declared is not None:
            return declared
    return mounting.resolve_mounting(ctx.category, ctx.request.text, ctx.request.mount)


def _host_mjcf(out_dir: Path, asset: AssetDescription, config: RefineConfig, report: RefineReport) -> dict[str, str]:
    """An MJCF input's refined object written back into its own file (``mjcf/host/``,
    :func:`asset2sim.tasks.publish.host_mjcf.write_host_mjcf`), noted in the report; {} for other inputs. A file
    that cannot be written (a rescaled object, MuJoCo missing) is a note, never the loss of the refined asset."""
    source = asset.staged_from
    if source is None or staged.input_format(source) != "mjcf":
        return {}
    try:
        with quiet_stdout():
            done = host_mjcf.write_host_mjcf(out_dir, source, ReadOptions(body=config.body, mjcf_angle=config.mjcf.angle))
    except Exception as exc:  # the host file must not lose the refined asset
        _raise_if_unwritable(exc, out_dir)
        report.notes.append(f"host MJCF not written: {exc}")
        return {}
    rel = done.path.relative_to(out_dir).as_posix()
    report.notes.append(f"host MJCF: {rel} is {source.name} with the refined physics (bodies {list(done.bodies)}, joints "
                        f"{list(done.joints)}, keyframe 'initial'), names and geometry as they were; the diff: "
                        f"{done.diff.relative_to(out_dir).as_posix()}"
                        + "".join(f"; {f.relative_to(out_dir).as_posix()}, the package's file with the same physics"
                                  for f in done.files))
    return {"host_mjcf": str(done.path)}


def _host_usd(out_dir: Path, asset: AssetDescription, report: RefineReport) -> dict[str, str]:
    """A USD input's refined object written back into its own stage (``usd/host/``,
    :func:`asset2sim.tasks.publish.host_usd.write_host_usd`), noted in the report with its changes; {} for other
    inputs. A stage that cannot be written (a rescaled object, usd-core missing) is a note, never the loss of the
    refined asset."""
    source = asset.staged_from
    if source is None or staged.input_format(source) != "usd":
        return {}
    try:
        done = host_usd.write_host_usd(out_dir, source)
    except Exception as exc:  # the host stage must not lose the refined asset
        _raise_if_unwritable(exc, out_dir)
        report.notes.append(f"host USD not written: {exc}")
        return {}
    rel = lambda p: p.relative_to(out_dir).as_posix()  # noqa: E731
    report.notes.append(f"host USD: {rel(done.path)} is {source.name} with the refined physics and initial state "
                        f"({done.changes} attributes on {list(done.prims)}), prim paths as they were; the changes alone as a "
                        f"layer: {rel(done.layer)}; prim path -> attribute old -> new: {rel(done.diff)}")
    return {"host_usd": str(done.path), "host_usd_layer": str(done.layer)}


def _extras(out_dir: Path, report: RefineReport, att: _Attempt, log: _StageLog, reference: Path | str | None,
            shown: Path, clips: bool = True, media: bool = True) -> dict[str, str]:
    """Optional outputs: MJCF and USD exports, the evaluation, and with ``media`` the renders and the HTML report (the
    renders reused in it; without, ``report.json`` says the media phase is deferred: :mod:`asset2sim.tasks.publish.media`),
    then ``report.json`` again with their notes and the final stage times. Each failure (an engine or
    renderer unavailable included) is a note in the report, never the loss of the refined asset, except a
    full disk, a quota or a read-only file system (``OUTPUT_WRITE_FAILED``). The evaluation reuses the final
    post-check's rest test when it measured the files as they are now; ``shown``: the output folder as the
    user named it (``out_dir`` may be a staging folder); ``clips``: the sweep clips too (``clips/``). Returns name -> path."""
    recording = None if att.rewritten else att.check.recording
    if recording is not None:  # measured on the workspace's files; publish wrote the same bytes here
        recording = replace(recording, urdf=(out_dir / URDF_NAME).resolve())
    out: dict[str, str] = {}
    with quiet_stdout():  # engines and renderers print from C; the library must not
        for key, make, what in (("mjcf", lambda: export_mjcf.export_mjcf(out_dir), "MJCF export"),
                                ("usd", lambda: export_usd.export_usd(out_dir).path, "USD export")):
            try:
                out[key] = str(make())
            except ImportError as exc:  # MuJoCo / usd-core (pxr) not installed: the extra that would do it named
                report.notes.append(f"{what} skipped: {install_hint(exc)}")
            except Exception as exc:  # export must not lose the refined asset
                _raise_if_unwritable(exc, out_dir)
                report.notes.append(f"{what} failed: {exc}")
            log.lap(f"extras_{key}")
        views = None
        if media:
            try:
                views = media_phase.output_views(out_dir, report.initial_joint_positions)
                out["views"] = str(out_dir / VIEWS_DIR)
            except Exception as exc:
                _raise_if_unwritable(exc, out_dir)
                report.notes.append(f"renders failed: {exc}")
            log.lap("extras_render")
        try:
            paths = evaluate.evaluate_refined(out_dir, report, recording=recording, reference=reference, recorded=att.check.recorded,
                                              views=views, views_state=report.initial_joint_positions,
                                              checks=list(report.metrics) if recording is not None else None,
                                              shown=shown, clips=clips, html=media)
            if media:
                out["html"] = str(paths["report"])
            if media and clips and (out_dir / CLIPS_DIR / CLIPS_JSON).is_file():
                out["clips"] = str(out_dir / CLIPS_DIR)
            ev = Evaluation.model_validate_json(atomic.read_regular(paths["evaluation"], output_folder.MAX_RECORD_BYTES))
            combine_verdict(report, ev.metrics)  # report.json says what report.html says
            asked = [m for m in ev.metrics if m.name == "request_met"]  # and names the unmet phrases the verdict read
            report.metrics = [m for m in report.metrics if m.name != "request_met" or not asked] + asked
        except Exception as exc:
            _raise_if_unwritable(exc, out_dir)
            report.notes.append(f"HTML report failed: {exc}\n{traceback.format_exc(limit=3)}")
        log.lap("extras_report" if media else "extras_evaluation")
    report.media = "done" if media else "deferred"
    if not media:
        report.notes.append(f"{media_phase.DEFERRED_NOTE} (views/, clips/, report.html): `asset2sim report {shown}` makes them")
    report.stage_seconds = log.times
    write_report_json(out_dir, report)
    return out
