"""Refine one asset end to end: a folder and a request in, the SPEC's output
folder out, verified in PyBullet. The stages (extract, analyze, interpret,
synthesize, write, refine the state, post-check, report and extras) are
chained one small function each, with wall time per stage; progress goes to
the optional ``progress`` callback (the library never prints).
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field, replace
from pathlib import Path

from threadpoolctl import threadpool_limits

from asset2sim import array_cache, atomic, output_folder
from asset2sim.schemas.asset import AssetDescription, LinkGeometry
from asset2sim.schemas.config import MAX_REFINE_SECONDS, MAX_REFINE_STEPS, RefineConfig
from asset2sim.schemas.overlay import Overlay
from asset2sim.schemas.report import RefineReport
from asset2sim.schemas.request import RequestSpec
from asset2sim.tasks.ingest.declared import read_declared
from asset2sim.formats import ReadOptions
from asset2sim.tasks.geometry import analyze, limits
from asset2sim.tasks.ingest import extract
from asset2sim.tasks.ingest.validate_input import Finding
from asset2sim.tasks.interpret import overrides, request
from asset2sim.tasks.check import as_asked
from asset2sim.tasks.assemble import write
from asset2sim.tasks.assemble.candidate import Candidate, Workspace
from asset2sim.tasks.publish import extra_outputs, media as media_phase, output, refine_report
from asset2sim.tasks.geometry.closed_state import closed_tuples
from asset2sim.tasks.interpret.request import request_notes
from asset2sim.stage_log import Progress, StageLog
from asset2sim.tasks.publish.contract import (MARKER_NAME, REPORT_NAME, is_complete, read_report_json, run_hash, write_completion_marker,
                                              write_report_json)
from asset2sim.tasks.state import ground_clearance, placement, pose, stability
from asset2sim.tasks.synthesize import backends, estimate, estimator, request_apply, request_findings, validate_overlay
from asset2sim.tasks.synthesize.context import EstimationContext, build_context
from asset2sim.tasks.tune import escalation, keep_declared as keep
from asset2sim.tasks.tune.attempt import Attempt, balanced_attempt, opened_lying, rested_attempt, settled_attempt, steadier_opening
from asset2sim.inert import one_line
from asset2sim.engines.base import SimSession
from asset2sim.engines.step_budget import StepBudgetExceeded, step_budget

__all__ = ["MARKER_NAME", "REPORT_NAME", "Progress", "RefineError", "RefineResult", "is_complete", "refine_asset", "request_notes", "run_hash"]


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
    with _invalid_input(request.RequestTooLong):  # a request over the length cap: refused before any work
        request.check_request_length(prompt)
    est = _open_estimator(config)  # first: a model backend without its key fails before any work
    log = StageLog(progress)
    asset, findings = _extract(asset_dir, out_dir, asset_id, category, extracted, config)
    with _invalid_input(overrides.OverrideError):  # OVERRIDE_*: ``config.overrides`` do not fit the asset
        overrides.apply_overrides(RequestSpec(), config.overrides, asset)
    if config.keep_declared:  # the estimator keeps the asset's plausible declared physics (keep_declared.KeepDeclared)
        try:
            est = keep.KeepDeclared(est, read_declared(asset_dir, asset.urdf_path))
        except Exception as exc:
            raise RefineError(f"{asset.urdf_path}: the declared physics cannot be read: {exc}", "invalid_input") from exc
    chash = run_hash(config, prompt + (f"\ntask: {task}" if task else ""), category)
    if skip_if_complete and is_complete(out_dir, asset.input_hash, chash):
        output_folder.remove_stale_staging(out_dir)  # what a killed --force run left beside it
        if extras and media and media_phase.media_pending(out_dir):  # a deferred media phase, resumed
            made = media_phase.make_media(out_dir, reference=reference, clips=config.clips)
            log.say("media", f"{out_dir}: " + ", ".join(sorted(made)) + " made (the deferred media phase)")
        report = read_report_json(out_dir)  # the recorded result, nothing recomputed
        overlay = Overlay.model_validate_json(atomic.read_regular(out_dir / write.OVERLAY_NAME, output_folder.MAX_RECORD_BYTES))
        log.say("skip", f"{out_dir} is complete for this input and configuration")
        return RefineResult(out_dir=out_dir, report=report, overlay=overlay, skipped=True)
    with _invalid_input(output_folder.OutputError):  # the output folder claimed, or refused with its OUTPUT_* code
        owner = output_folder.start(asset.source_dir, out_dir, overwrite=overwrite)
    if owner.replaced:  # an earlier output of another request or configuration: said before it goes
        tops = sorted({r.split("/")[0] + ("/" if "/" in r else "") for r in owner.replaced})
        log.say("output", f"WARNING: {out_dir} holds an earlier output, which this run replaces: its {len(owner.replaced)} files "
                          f"({', '.join(tops[:8])}{', ...' if len(tops) > 8 else ''}) are removed")
    work = owner.write_path(out_dir)  # out_dir, or the staging folder that replaces a complete earlier output
    staged_input = getattr(asset.staged_from, "parent", None)  # an MJCF / USD file's own folder
    # no cache entry in the input or output; every simulated step of every phase counted against one cap; one BLAS thread,
    with array_cache.guard(asset.source_dir, staged_input, out_dir, owner.root, reference), threadpool_limits(1, "blas"), \
            step_budget(MAX_REFINE_STEPS, MAX_REFINE_SECONDS):  # as the CLI and the flow's workers run (docs/design/pipeline.md)
        try:
            said = (f"{asset.category} as declared (the category used is decided next, from the request and the parts)"
                    if asset.category else "not declared (recognised from the request and the parts next)")
            log.say("extract", f"{input_shown(asset_dir, asset)}: {len(asset.links)} links, {len(asset.movable_joints())} "
                    f"movable joints, category {said}"
                    + (f"; {len(findings)} validation findings (none fatal)" if findings else ""))
            log.lap("extract")
            cache = analyze.MeshCache()
            geometry = _analyze(asset, cache, log)
            with build_context(asset, prompt, config, category=category, geometry=geometry, cache=cache) as (ctx, kin), \
                    Workspace(asset, open_containers=config.open_containers and config.convex_decomposition,
                              mesh_cache=cache) as ws:
                ctx, pose_note = _interpret(replace(ctx, task=task), kin, log)
                att, pose_note = _synthesize_and_check(ctx, RefineRun(est, kin, config, ws, log), pose_note)
                ctx = replace(ctx, root_rotation=att.root_rotation)  # the resting pose the kept attempt was made on
                asked = as_asked.as_asked_tier(ctx, kin, att.overlay, att.state, att.closed_out, att.check.metrics + [
                    m for res in att.check.engine_results.values() for m in res], targets=att.targets, rounds=att.rounds)
                output.publish(att.candidate, ws, work)  # the output folder's files, written once
            log.say("post_check", refine_report.post_check_line(att))
            report = refine_report.build_report(ctx, prompt, chash, att, findings, pose_note, log.times, asked)
            extra_paths = extra_outputs.host_files(work, asset, config, report)
            report.media = "off"
            if extras:
                extra_paths.update(extra_outputs.write_extras(work, report, att, ctx, asked.resolution, log, reference, shown=out_dir,
                                                              clips=config.clips, media=media))
            report.stage_seconds = log.times
            write_report_json(work, report)  # once, every measurement and note in it
            output_folder.merge_timings(work, {"stage_cpu_seconds": log.cpu})
            write_completion_marker(owner.root, asset.input_hash, chash, owner=owner)  # last, once every file exists
        except StepBudgetExceeded as exc:
            owner.abandon()
            raise RefineError(f"{asset.asset_id}: {exc}", "timeout", [exc.code]) from None
        except BaseException:
            owner.abandon()
            raise
    extra_paths = {k: str(out_dir / Path(v).relative_to(work)) if Path(v).is_relative_to(work) else v for k, v in extra_paths.items()}
    return RefineResult(out_dir=out_dir, report=report, overlay=att.overlay, extras=extra_paths)


# ---------------------------------------------------------- 1-3: extract .. interpret
@contextmanager
def _invalid_input(*errors: type[Exception]) -> Iterator[None]:
    """Any of ``errors`` raised inside becomes RefineError("invalid_input") with its codes (``codes``, else ``code``)."""
    try:
        yield
    except errors as exc:
        codes = getattr(exc, "codes", None) or ([exc.code] if hasattr(exc, "code") else None)
        raise RefineError(str(exc), "invalid_input", codes) from exc


def _open_estimator(config: RefineConfig) -> estimator.Estimator:
    """The configured estimator; RefineError("estimator_failure") when it cannot be made."""
    try:
        return backends.get_estimator(config.estimator, **{k: v for k, v in (("model", config.model), ("base_url", config.base_url)) if v})
    except estimator.EstimatorUnknown as exc:  # a name: the option's error, one sentence
        raise RefineError(str(exc), "estimator_failure", ["ESTIMATOR_UNAVAILABLE"]) from exc
    except Exception as exc:
        why = one_line(exc)
        raise RefineError(why if why.startswith("--") else f"--estimator {config.estimator} cannot be used: {why}",
                          "estimator_failure", ["ESTIMATOR_UNAVAILABLE"]) from exc


def _extract(asset_dir: Path | str, out_dir: Path, asset_id: str | None, category: str | None,
             extracted: tuple[AssetDescription, list[Finding]] | None, config: RefineConfig) -> tuple[AssetDescription, list[Finding]]:
    """Stage 1: the checked asset and its validation findings (``extracted`` when
    already read; an MJCF input read as ``config.body`` and ``config.mjcf`` say); the output folder checked against
    it. RefineError("invalid_input") with the codes, also for a joint range that only makes sense in the other
    unit (``JOINT_RANGE_WRONG_UNIT``: never part of an interaction-ready output)."""
    with _invalid_input(extract.AssetError, output_folder.OutputError):
        if extracted is None:
            reading = ReadOptions(body=config.body, mjcf_angle=config.mjcf.angle)
            asset, findings = extract.extract_asset_checked(asset_dir, asset_id=asset_id, category=category, reading=reading)
        else:
            asset, findings = extracted[0], list(extracted[1])
        output_folder.check_location(asset.source_dir, out_dir)
        if asset.staged_from is not None:  # never into the folder the MJCF or USD file lies in
            output_folder.check_location(asset.staged_from.parent, out_dir)
    wrong = [f for f in findings if f.code == "JOINT_RANGE_WRONG_UNIT"]
    if wrong:
        lines = "\n  ".join(f.describe() for f in wrong)
        raise RefineError(f"{asset.staged_from or asset.urdf_path}: a joint range in the wrong unit; not refined:\n  {lines}\n"
                          "  (an MJCF fragment: --mjcf-angle radian|degree, config mjcf.angle, says which unit its angles are in)",
                          "invalid_input", ["JOINT_RANGE_WRONG_UNIT"])
    return asset, findings


def input_shown(asset_dir: Path | str, asset: AssetDescription) -> str:
    """The input as the user gave it, for the progress lines: ``asset_dir`` as given, and for an MJCF or USD file
    read into the asset model (staged as a URDF in a temporary folder) the file and its format, never the staged
    copy: ``objects/door.xml (MJCF)``; a folder holding one such file: ``cabinet_7/cabinet.xml (MJCF)``."""
    given = Path(asset_dir)
    if asset.staged_from is None:
        return str(given)
    fmt = "USD" if asset.staged_from.suffix.lower() in (".usd", ".usda", ".usdc", ".usdz") else "MJCF"
    return f"{given / asset.staged_from.name if given.is_dir() else given} ({fmt})"


def _analyze(asset: AssetDescription, cache: analyze.MeshCache, log: StageLog) -> dict[str, LinkGeometry]:
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
    return sorted({ln for j in request_apply.task_relevant_joints(ctx) for ln in ctx.subtrees[j]})


def _interpret(ctx: EstimationContext, kin: SimSession, log: StageLog) -> tuple[EstimationContext, str]:
    """Stage 3: the resting pose the request asks for ("lying flat", "sideways"). Returns ``ctx`` with it as
    ``root_rotation`` and the pose note ("" when none was asked)."""
    spec = ctx.request
    pose_note = ""
    if spec.pose_hint in ("lying_flat", "sideways"):
        rotation, pose_note = pose.resting_rotation(kin, ctx.asset, ctx.closed_state(), ctx.hull_points, _moving_links(ctx))
        ctx = replace(ctx, root_rotation=rotation)
        log.say("request", f"pose '{spec.pose_hint}': {pose_note}")
    for note in request_notes(spec):
        log.say("request", note)
    log.say("request", f"category {ctx.category} ({ctx.category_reason}); size {spec.size_class or 'regular'}; states " + (", ".join(js.words() for js in spec.joint_states) or "none asked"))
    log.lap("closed_state")
    return ctx, pose_note


# ----------------------------------------------------- 4-7: synthesize .. post-check


@dataclass(frozen=True)
class RefineRun:
    """What every attempt of one refine works with, unchanged between them: the estimator, the input's kinematics
    session (``kin``, :func:`~asset2sim.tasks.synthesize.context.build_context`), the configuration, the workspace
    the candidates are written to and the stage log. The estimation context travels beside it: an attempt on
    another resting pose re-poses it."""

    est: estimator.Estimator
    kin: SimSession
    config: RefineConfig
    ws: Workspace
    log: StageLog


def _synthesize_and_check(ctx: EstimationContext, run: RefineRun, pose_note: str) -> tuple[Attempt, str]:
    """Stages 4-7 once; when unstable or toppled as modelled, a named pose put down where it rests (:func:`settled_attempt`);
    else a steadier opening, then its stablest face (kept only if better); when none of these settles it, the whole mass
    transfer where a topple is all that fails, at the bands' targets and then at the steadier opening, then, when
    unstable, the modelled pose put down where it rests (each kept only if every check passes and every band is met).
    Returns (attempt, pose note)."""
    att = _attempt(ctx, run)

    def posed(rotation, most: bool = False, fractions: dict[str, float] | None = None) -> Attempt:  # on the root rotation (3, 3)
        return _attempt(replace(ctx, root_rotation=rotation), run, fractions=fractions, most=most)

    if ctx.request.pose_hint is not None:  # the pose asked is kept: put down where it rests when it leans as it settles
        return settled_attempt(att, pose_note, posed)
    if att.check.stable and not att.check.topples:  # laid down to open, or the opening where the weight turns a part least
        return opened_lying(ctx, run.kin, att, _moving_links(ctx), posed, run.log) or (
            balanced_attempt(ctx, run.kin, att, lambda fractions: _attempt(ctx, run, fractions=fractions), run.log), pose_note)
    opening, steadier = steadier_opening(run.ws, att, run.log), None
    if opening is not None:  # stages 4-7 once more at the steadier opening
        fractions, design = opening
        steadier = _attempt(ctx, run, fractions=fractions)
        if steadier.check.passed and not steadier.check.topples:
            return replace(steadier, design=[design, *steadier.design]), pose_note
        run.log.say("stability", "the steadier opening did not pass every check: the bands' targets kept")
    state_in = estimate.state_from_bands(ctx.closed, att.bands, 1.0, att.prismatic)
    R, note = pose.most_stable_rotation(run.kin, ctx.asset, att.overlay.links, state_in, att.overlay.scale, ctx.hull_points,
                                        _moving_links(ctx), exclude_modelled=True)
    chosen = (att, pose_note)
    if R is not None:
        why = "unstable as modelled" if not att.check.stable else "toppled by a robust-rest disturbance as modelled"
        run.log.say("post_check", f"{why}; {note}")
        second = posed(R)
        chosen = (second, f"{why}; {note}") if second.check.stable and (second.check.passed or not att.check.passed) and not (
            second.check.topples and not att.check.topples) else (att, f"{note}; not better in simulation, kept as modelled")
    if chosen[0].settles:
        return chosen
    best, best_note = chosen
    if best.check.only_topples and _more_to_move(ctx, run, best):  # toppled: opened parts as light as their sources allow
        heavier = posed(best.root_rotation, most=True)
        if heavier.settles:
            return heavier, best_note
        run.log.say("stability", "the whole transfer did not pass every check: the least transfer kept")
    if steadier is not None and steadier.check.only_topples and _more_to_move(ctx, run, steadier):
        lighter = _attempt(ctx, run, fractions=opening[0], most=True)  # the steadier opening with the whole transfer
        if lighter.settles:
            return replace(lighter, design=[opening[1], *lighter.design]), pose_note
    if att.check.stable:
        return chosen
    # no face passes: where it leans onto its supports as it settles as modelled (a swivel USB stick on its cover's
    # plate), it is put down there, kept when every check passes there
    leaned, lean_note = settled_attempt(att, pose_note, posed)
    if leaned is att or not leaned.settles:
        return chosen
    run.log.say("post_check", f"unstable as modelled; {lean_note}")
    return leaned, f"unstable as modelled; {lean_note}"


def _more_to_move(ctx: EstimationContext, run: RefineRun, att: Attempt) -> bool:
    """Whether stability by design's whole transfer would move mass on ``att``'s written candidate: an opened part
    heavier than its floor (:func:`~asset2sim.tasks.state.stability.design_for_stability`, ``most``)."""
    whole, _ = stability.design_for_stability(run.ws.source(att.candidate), ctx.asset, att.overlay, att.state, ctx.category,
                                              ctx.geometry, most=True)
    return whole is not att.overlay


def _attempt(ctx: EstimationContext, run: RefineRun, fractions: dict[str, float] | None = None, most: bool = False) -> Attempt:
    """Stages 4-7 for the current ``ctx.root_rotation`` (:func:`_stages`), once more where a part asked to move freely
    and given no state came to rest off its closed end (:func:`~asset2sim.tasks.tune.attempt.rested_attempt`).
    ``fractions`` (joint -> opening fraction) replace the requested state of those joints; ``most``: stability by
    design moves all the mass it may (:func:`~asset2sim.tasks.state.stability.design_for_stability`)."""
    att = _stages(ctx, run, fractions, most)
    return rested_attempt(ctx, run.kin, att, lambda hung: _stages(ctx, run, {**(fractions or {}), **hung}, most, hung=hung), run.log)


def _stages(ctx: EstimationContext, run: RefineRun, fractions: dict[str, float] | None = None, most: bool = False,
            hung: dict[str, float] | None = None) -> Attempt:
    """Stages 4-7 once for the current ``ctx.root_rotation``; ``fractions`` (joint -> opening fraction) replace the
    requested state of those joints; ``hung`` (joint -> opening fraction, of ``fractions``): parts left where their
    weight took them, their bands set there; ``most`` as :func:`_attempt`."""
    config, ws, log = run.config, run.ws, run.log
    syn = _synthesize(ctx, run)
    if fractions:
        syn = replace(syn, requested={**syn.requested, **placement.at_fractions(syn.closed_out, fractions)})
    rests = [f"{j} ({ctx.asset.link(ctx.asset.joint(j).child).semantic_label or 'part'}) starts at {abs(f):.2f} of its range"
             + (" past its closed end" if f < 0 else "") + ", where its weight took it in the rest test: the request asks it to "
             "move freely and gives it no state" for j, f in (hung or {}).items()]
    if hung:
        syn = replace(syn, bands={**syn.bands, **{j: request_apply.band_of(abs(f)) for j, f in hung.items()}},
                      rests={j: (f - request_apply.END_TOLERANCE, f + request_apply.END_TOLERANCE) for j, f in hung.items()})
        for line in rests:
            log.say("refine_state", line)
    first_clear = _write(ctx, syn, ws, log)
    shut, shut_notes = placement.shut_repair(ctx, syn, config, ws, log)
    syn = placement.closed_on_output(ctx, syn, ws, log, shut)
    closed_raw = syn.closed_out
    clipped = placement.clip_synthesis(ctx, syn, config, ws, log, shut, fractions)
    if clipped is not syn:  # clipped limits change the pieces and the range the closed end is found in: measured once more
        clipped = placement.closed_on_output(ctx, clipped, ws, log, shut)
        closed_raw = placement.ends_over_raw_limits(closed_raw, clipped.closed_out)  # the state's closed end, kept by a re-clip
    syn = clipped
    searched = syn.candidate(ctx, shut)
    st, kept = placement.search_state(ctx, run.kin, run.est, syn, searched, config, ws, log)
    state = dict(st.result)
    room = [f"{j} ({ctx.asset.link(ctx.asset.joint(j).child).semantic_label or 'part'}) opened to {f:.2f} of its range: the request "
            f"did not address it (closed by default) and a part the request opened lay through it closed" for j, f in st.room_made.items()]
    if st.room_made:
        syn = replace(syn, bands={**syn.bands, **{j: request_apply.band_of(f) for j, f in st.room_made.items()}})
        for line in room:
            log.say("refine_state", line)
    # a part left where its weight took it may lie on the floor, as it came to rest there
    lifted = ground_clearance.apply_ground_clearance(replace(kept, state=state), ws,
                                                     closed_tuples({n: c for n, c in syn.closed_out.items() if n not in syn.rests}))
    state, overrides, floored = lifted.state, lifted.overrides, lifted.state_notes
    st.collision_changes = shut_notes + list(st.collision_changes) + lifted.collision_notes
    refined = Candidate(ctx.asset, syn.overlay, state, overrides, ctx.root_rotation)
    measured, moved = refined, []  # the pieces the statics are measured on: those the limits were clipped on
    # the state search's repairs changed the collision pieces: the limits are clipped again on them (stage 6b); a lift
    # off the floor only shortens a piece from below, so the limits found before it stand
    if kept.collision_overrides is not searched.collision_overrides:
        measured = replace(refined, overlay=limits.strip_clips(syn.overlay))
        reclipped, closed_re = placement.clip_limits(measured, closed_raw, ws, config, log)
        again = placement.reclipped(syn, reclipped, closed_re, state)  # the state kept in its band
        syn, state, moved = again.synthesis, again.state, again.notes
        refined, measured = replace(refined, state=state), replace(measured, state=state)
        st.result = {n: state.get(n, q) for n, q in st.result.items()}
    balanced, design = stability.design_for_stability(ws.source(measured), ctx.asset, syn.overlay, state, ctx.category, ctx.geometry,
                                                       most=most)
    closed_out, ended = ground_clearance.ends_at_the_floor(syn.closed_out, lifted.stops, syn.bands)  # "fully": as far as it goes
    design = floored + ended + moved + design
    for line in design:
        log.say("stability", line)
    design = rests + room + design
    tuned = escalation.post_check(ctx, replace(refined, overlay=balanced), config, ws, log, closed=closed_tuples(closed_out))
    tuned = escalation.repair_sweep(ctx, limits.strip_clips(balanced), closed_raw, replace(tuned, overrides=overrides, closed=closed_out),
                                    st, state, config, ws, log)
    # the clearance of the first pieces (carried on by pieces a repair rewrote from them) and of the final ones
    clear = list(dict.fromkeys(first_clear + placement.clearance_notes(ctx, tuned.overlay, state, tuned.overrides, ws)))
    st.collision_changes = clear + list(st.collision_changes)
    return Attempt(asset=ctx.asset, overlay=tuned.overlay, issues=syn.issues, bands=syn.bands, prismatic=syn.prismatic,
                   closed_out=ground_clearance.ends_at_the_floor(tuned.closed, lifted.stops, syn.bands)[0], st=st, state=state, overrides=tuned.overrides, root_rotation=ctx.root_rotation,
                   check=tuned.check, rounds=tuned.rounds, design=design, targets=syn.targets)


def _synthesize(ctx: EstimationContext, run: RefineRun) -> placement.Synthesis:
    """Stage 4: the estimator's overlay (validated) and bands, the requested state at its scale.
    RefineError("estimator_failure" or "invalid_overlay")."""
    log, asset = run.log, ctx.asset
    prismatic = {j.name for j in asset.movable_joints() if j.type == "prismatic"}
    try:
        result = run.est.estimate(ctx, run.kin)
    except Exception as exc:
        code = getattr(exc, "code", None)  # a model call's fault by what happened (MODEL_REPLY_INVALID ...)
        raise RefineError(f"{asset.asset_id}: estimator {run.config.estimator!r} failed: {one_line(exc, 600)}",
                          "estimator_failure",
                          ["ESTIMATOR_FAILED", *([code] if isinstance(code, str) and code.startswith("MODEL_") else [])]) from exc
    bands = dict(result.bands)
    log.lap("synthesize")
    try:
        overlay, issues = validate_overlay.validate_overlay(result.overlay, asset, ctx.geometry)
    except validate_overlay.OverlayInvalid as exc:
        raise RefineError(f"{asset.asset_id}: {exc}", "invalid_overlay") from exc
    overlay = overlay.model_copy(update={"mounting": ctx.mounting})  # resolved with the context (build_context)
    s = overlay.scale
    overlay, targets = request_findings.check_against_request(ctx, run.kin, overlay, result.targets)
    requested = estimate.state_from_bands(ctx.closed, bands, s, prismatic)
    requested.update(overlay.initial_joint_positions or {})
    log.say("synthesize", f"{overlay.estimator.name}: scale {s:.4g}, total mass {overlay.total_mass():.4g} kg, {len(issues)} validation findings")
    log.lap("validate")
    return placement.Synthesis(overlay, issues, bands, prismatic, placement.scaled_closed(ctx.closed, s, prismatic), requested, targets)


def _write(ctx: EstimationContext, syn: placement.Synthesis, ws: Workspace, log: StageLog) -> list[str]:
    """Stage 5: the candidate at the requested state loaded into the workspace.
    Returns the writer's clearance notes."""
    clear = placement.clearance_lines(ws.collision_notes_of(syn.candidate(ctx)))
    for line in clear:
        log.say("write", line)
    log.lap("write")
    return clear
