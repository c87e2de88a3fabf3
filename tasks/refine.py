"""Refine one asset end to end: a folder and a request in, the SPEC's output
folder out, verified in PyBullet.

Stages (each a plain function of its own module; this module chains them and
records wall time per stage):

1. extract (``tasks.extract``), 2. analyze (``tasks.analyze``),
3. request + category (``tasks.request``, ``tasks.priors``) and the geometric
closed states (``tasks.closed_state``), 4. synthesize the overlay
(``tasks.estimate``) and validate it (``tasks.validate_overlay``), 5. write
(``tasks.write``), 6. refine the initial state (``tasks.refine_state``),
7. post-check and escalation (``tasks.postcheck``), 8. report, exports and a
completion marker written last.

The library never prints: progress goes to the optional ``progress`` callback.
"""

from __future__ import annotations

import hashlib
import json
import time
import traceback
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

from asset2sim import __version__, atomic
from asset2sim.engines.base import SessionOptions, open_session
from asset2sim.schemas.asset import AssetDescription, LinkGeometry
from asset2sim.schemas.config import RefineConfig
from asset2sim.schemas.overlay import Overlay
from asset2sim.schemas.report import EscalationRound, RefineReport
from asset2sim.tasks.geometry.closed_state import ClosedState, closed_positions, link_hull_points, object_extents, subtree_links

MARKER_NAME = ".asset2sim-complete.json"
REPORT_NAME = "report.json"

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
    skipped: bool = False
    extras: dict[str, str] = field(default_factory=dict)


def run_hash(input_hash: str, config: RefineConfig, prompt: str, category: str | None) -> str:
    """Configuration hash of one run: config + prompt + category override (hex, 16)."""
    blob = json.dumps(
        {"config": config.config_hash(), "prompt": prompt, "category": category, "version": __version__},
        sort_keys=True,
    ).encode()
    return hashlib.sha256(blob).hexdigest()[:16]


def is_complete(out_dir: Path, input_hash: str, config_hash: str) -> bool:
    """True when ``out_dir`` holds a completion marker for exactly this input
    and configuration, and every file it lists exists with its recorded hash."""
    marker = Path(out_dir) / MARKER_NAME
    try:
        data = json.loads(marker.read_text())
    except (OSError, ValueError):
        return False
    if data.get("input_hash") != input_hash or data.get("config_hash") != config_hash or data.get("version") != __version__:
        return False
    for rel, digest in data.get("files", {}).items():
        p = Path(out_dir) / rel
        if not p.is_file() or atomic.sha256_file(p) != digest:
            return False
    return True


def _scaled_closed(closed: dict[str, ClosedState], scale: float, prismatic: set[str]) -> dict[str, ClosedState]:
    out = {}
    for n, cs in closed.items():
        if n in prismatic:
            out[n] = ClosedState(
                joint=n,
                q_closed=cs.q_closed * scale,
                direction=cs.direction,
                open_range=cs.open_range * scale,
                lower=cs.lower * scale,
                upper=cs.upper * scale,
                compactness_ratio=cs.compactness_ratio,
                notes=cs.notes,
            )
        else:
            out[n] = cs
    return out


def _subtree_height(session, links: list[str], hull: dict[str, np.ndarray]) -> float:
    from asset2sim.tasks.geometry.closed_state import _aabb

    box = _aabb(session, links, hull)
    return 0.0 if box is None else float(0.5 * (box[0][2] + box[1][2]))


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
) -> RefineResult:
    """Refine ``asset_dir`` for the natural-language ``prompt`` into ``out_dir``.

    Args:
        asset_dir: PartNet-Mobility-style folder (or a URDF file).
        prompt: the request, e.g. "I want a slightly open stapler.".
        out_dir: output folder (created; must not be inside the input).
        config: pipeline knobs (default :class:`RefineConfig`).
        category: overrides the asset's own category (e.g. a manifest column).
        asset_id: identifier for reports (default: folder name).
        progress: callback(stage, message) for user-facing progress.
        skip_if_complete: return the existing result when the completion
            marker matches the input and configuration hashes.
        extras: also write exports (MJCF), renders and the HTML report when
            those modules are available.

    Returns:
        :class:`RefineResult`; ``report.failure_mode`` is "none" when every
        check passed, else the first failing check's mode (the output is still
        written: the report shows the evidence).

    Raises:
        RefineError: input invalid, estimator failure or invalid overlay
            (``failure_mode`` says which); nothing but partial-free atomic files
            are left in ``out_dir``.
    """
    from asset2sim.tasks.geometry import analyze
    from asset2sim.tasks.synthesize import estimate
    from asset2sim.tasks.ingest import extract
    from asset2sim.tasks.interpret import priors
    from asset2sim.tasks.interpret import request
    from asset2sim.tasks.publish import write

    config = config or RefineConfig()
    say = progress or (lambda stage, msg: None)
    out_dir = Path(out_dir)
    # the estimator first: a model backend without its key fails before any work
    try:
        est = estimate.get_estimator(config.estimator, **{k: v for k, v in (("model", config.model), ("base_url", config.base_url)) if v})
    except Exception as exc:
        raise RefineError(f"estimator {config.estimator!r} unavailable: {exc}", "estimator_failure") from exc
    times: dict[str, float] = {}
    t = time.perf_counter()

    def lap(stage: str) -> None:
        nonlocal t
        now = time.perf_counter()
        times[stage] = times.get(stage, 0.0) + (now - t)
        t = now

    # 1. extract
    try:
        asset, findings = extract.extract_asset_checked(asset_dir, asset_id=asset_id, category=category)
        write.check_output_folder(asset, out_dir)
    except (extract.AssetError, write.OutputError) as exc:
        err = RefineError(str(exc), "invalid_input")
        err.codes = list(getattr(exc, "codes", []) or [])
        raise err from exc
    chash = run_hash(asset.input_hash, config, prompt, category)
    if skip_if_complete and is_complete(out_dir, asset.input_hash, chash):
        report = RefineReport.model_validate_json((out_dir / REPORT_NAME).read_text())
        overlay = Overlay.model_validate_json((out_dir / write.OVERLAY_NAME).read_text())
        say("skip", f"{out_dir} is complete for this input and configuration")
        return RefineResult(out_dir=out_dir, report=report, overlay=overlay, skipped=True)
    _start_output(out_dir)
    say("extract", f"{asset.urdf_path}: {len(asset.links)} links, {len(asset.movable_joints())} movable joints, category {asset.category}"
        + (f"; {len(findings)} validation findings (none fatal)" if findings else ""))
    lap("extract")

    # 2. analyze
    mesh_cache = analyze.MeshCache()
    try:
        geometry: dict[str, LinkGeometry] = analyze.analyze_asset(asset, cache=mesh_cache)
    except Exception as exc:
        raise RefineError(f"{asset.urdf_path}: mesh analysis failed: {exc}", "invalid_input") from exc
    say("analyze", f"{len(geometry)} links with geometry, volumes " + ", ".join(f"{k}={g.volume:.3g}" for k, g in geometry.items()))
    lap("analyze")

    # 3. request, category, closed states
    spec = request.parse_request(prompt)
    labels = [ln.semantic_label for ln in asset.links if ln.semantic_label]
    match = priors.recognize_category(category or asset.category, labels, prompt)
    cat_name = getattr(match, "name", None) or str(match)
    kin = open_session("pybullet", asset.urdf_path, SessionOptions(fixed_base=True, gravity=False, ground=False, conventions=config.sim))
    try:
        hull = link_hull_points(asset, cache=mesh_cache)
        closed = closed_positions(kin, asset, hull_points=hull)
        closed_state = {n: c.q_closed for n, c in closed.items()}
        extents = object_extents(kin, closed_state, asset, hull)
        subtrees = {j.name: subtree_links(asset, j.child) for j in asset.movable_joints()}
        heights = {n: _subtree_height(kin, links, hull) for n, links in subtrees.items()}
        ctx = estimate.EstimationContext(
            asset=asset,
            geometry=geometry,
            request=spec,
            category=cat_name,
            category_reason=getattr(match, "reason", ""),
            closed=closed,
            closed_extents=extents,
            session=kin,
            subtrees=subtrees,
            joint_heights=heights,
        )
        moving = sorted({ln for j in estimate.task_relevant_joints(ctx) for ln in subtrees[j]})
        pose_note = ""
        if spec.pose_hint in ("lying_flat", "sideways"):
            from asset2sim.tasks.state import pose

            ctx.root_rotation, pose_note = pose.resting_rotation(kin, asset, closed_state, hull, moving)
            say("request", f"pose '{spec.pose_hint}': {pose_note}")
        say("request", f"category {cat_name}; size {spec.size_class or 'regular'}; states " + (", ".join(f"{js.label or 'all'}{'' if js.ordinal is None else '#' + str(js.ordinal)}={js.band}" for js in spec.joint_states) or "none asked"))
        lap("closed_state")

        att = _attempt(ctx, est, config, out_dir, mesh_cache, say, lap)
        if not att.check.stable and spec.pose_hint is None:
            # the object tips or slides as modelled: try resting it on its stablest face
            from asset2sim.tasks.state import pose

            state_in = estimate.state_from_bands(closed, att.bands, 1.0, att.prismatic)
            R, note = pose.most_stable_rotation(kin, asset, att.overlay.links, state_in, att.overlay.scale, hull, moving, exclude_modelled=True)
            if R is not None:
                say("post_check", f"unstable as modelled; {note}")
                ctx.root_rotation = R
                second = _attempt(ctx, est, config, out_dir, mesh_cache, say, lap)
                if second.check.stable and (second.check.passed or not att.check.passed):
                    att, pose_note = second, note
                else:
                    ctx.root_rotation = None
                    att.rewrite(out_dir)  # the first attempt stays the result
                    pose_note = f"{note}; not better in simulation, kept as modelled"
    finally:
        kin.close()
    overlay, st, check, rounds, issues, bands, state, closed_out = (
        att.overlay, att.st, att.check, att.rounds, att.issues, att.bands, att.state, att.closed_out
    )
    s = overlay.scale
    _remove_stale_collision(out_dir, att.overrides)
    pen = check.metric("penetration")
    stab = check.metric("rest_stability")
    osc = check.metric("oscillation")
    say("post_check", f"penetration {pen.value:.3g} mm; rest stability {'PASS' if stab.passed else 'FAIL'} (D_pos {stab.details.get('D_pos_m', float('nan')):.2e} m, D_ori {stab.details.get('D_ori_rad', float('nan')):.2e} rad); oscillation {'PASS' if osc.passed else 'FAIL'}; escalation rounds {len(rounds) - 1}")

    if not check.stable:
        failure = "unstable"
    elif not osc.passed:
        failure = "oscillating"
    elif pen.value is not None and pen.value > 5.0:
        failure = "unresolved_penetration"
    else:
        failure = "none"
    report = RefineReport(
        asset_id=asset.asset_id,
        source=str(asset.source_dir),
        prompt=prompt,
        category=cat_name,
        version=__version__,
        input_hash=asset.input_hash,
        config_hash=chash,
        estimator=overlay.estimator.name,
        model=overlay.estimator.model,
        model_queries=overlay.estimator.queries + (st.model_queries if st is not None else 0),
        model_tokens=overlay.estimator.tokens,
        model_cost_usd=overlay.estimator.cost_usd,
        model_seconds=overlay.estimator.seconds,
        scale=s,
        total_mass=overlay.total_mass(),
        initial_joint_positions=state,
        closed_positions={n_: c.q_closed for n_, c in closed_out.items()},
        requested_bands=bands,
        opening_fractions={n_: abs(c.fraction(state[n_])) for n_, c in closed_out.items() if n_ in state},
        state=st,
        metrics=check.metrics + [m for res in check.engine_results.values() for m in res],
        parity=_parity_rows(check),
        escalation=rounds,
        validation=[_finding_dict(f) for f in findings] + [i.model_dump() for i in issues],
        failure_mode=failure,
        stage_seconds=times,
        notes=list(overlay.notes.other) + ([f"resting pose ({spec.pose_hint or 'stability'}): {pose_note}"] if pose_note else []),
    )
    atomic.write_json(out_dir / REPORT_NAME, report.model_dump(mode="json"))
    extra_paths: dict[str, str] = {}
    if extras:
        from asset2sim.engines.pybullet_engine import _quiet_stdout

        with _quiet_stdout():  # engines and renderers print from C; the library must not
            extra_paths = _write_extras(out_dir, report, check, say)
        lap("extras")
        report.stage_seconds = times
        atomic.write_json(out_dir / REPORT_NAME, report.model_dump(mode="json"))
    files = sorted(
        str(p_.relative_to(out_dir)) for p_ in out_dir.rglob("*")
        if p_.is_file() and p_.name != MARKER_NAME and not p_.name.endswith(".tmp")
    )
    atomic.write_json(
        out_dir / MARKER_NAME,
        {
            "input_hash": asset.input_hash,
            "config_hash": chash,
            "version": __version__,
            "files": {f: atomic.sha256_file(out_dir / f) for f in files},
        },
    )
    return RefineResult(out_dir=out_dir, report=report, overlay=overlay, extras=extra_paths)



@dataclass
class _Attempt:
    """One synthesize -> validate -> write -> refine state -> post-check pass."""

    asset: AssetDescription
    overlay: Overlay
    issues: list
    bands: dict[str, str]
    prismatic: set[str]
    closed_out: dict[str, ClosedState]
    st: object
    state: dict[str, float]
    overrides: dict
    root_rotation: object
    check: object
    rounds: list[EscalationRound]

    def rewrite(self, out_dir: Path) -> None:
        """Write this attempt's files again (after another attempt overwrote them)."""
        from asset2sim.tasks.publish import write

        write.write_output(
            self.asset, self.overlay, out_dir, self.state, copy=False,
            collision_overrides=self.overrides, root_rotation=self.root_rotation,
        )


def _attempt(ctx, est, config: RefineConfig, out_dir: Path, mesh_cache, say: Progress, lap) -> _Attempt:
    """Stages 4-7 for the context's current resting pose (``ctx.root_rotation``)."""
    from asset2sim.tasks.synthesize import estimate
    from asset2sim.tasks.check import postcheck
    from asset2sim.tasks.synthesize import validate_overlay
    from asset2sim.tasks.publish import write

    asset, geometry, closed = ctx.asset, ctx.geometry, ctx.closed
    prismatic = {j.name for j in asset.movable_joints() if j.type == "prismatic"}
    root_rotation = ctx.root_rotation
    # 4. synthesize + validate
    try:
        overlay = est.estimate(ctx)
    except Exception as exc:
        raise RefineError(f"{asset.asset_id}: estimator {config.estimator!r} failed: {exc}", "estimator_failure") from exc
    bands, _ = estimate.requested_bands(ctx)
    bands.update(ctx.settings.get("model_bands", {}))  # a model backend's band choice wins
    lap("synthesize")
    try:
        overlay, issues = validate_overlay.validate_overlay(overlay, asset, geometry)
    except validate_overlay.OverlayInvalid as exc:
        raise RefineError(f"{asset.asset_id}: {exc}", "invalid_overlay") from exc
    s = overlay.scale
    closed_out = _scaled_closed(closed, s, prismatic)
    requested = estimate.state_from_bands(closed, bands, s, prismatic)
    if overlay.initial_joint_positions:
        requested.update(overlay.initial_joint_positions)
    say("synthesize", f"{overlay.estimator.name}: scale {s:.4g}, total mass {overlay.total_mass():.4g} kg, {len(issues)} validation findings")
    lap("validate")

    # 5. write (meshes copied once; later writes only rewrite the small files)
    paths = write.write_output(asset, overlay, out_dir, requested, root_rotation=root_rotation)
    lap("write")

    # 6. state refinement on the written (scaled) asset
    proposer = est.joint_proposer(ctx) if hasattr(est, "joint_proposer") else None
    st, overrides = _refine_state_with_decomposition(
        asset, overlay, closed_out, bands, requested, paths.urdf, root_rotation, config, out_dir, mesh_cache, say, proposer=proposer
    )
    state = dict(st.result)
    say("refine_state", f"Phi {st.phi_requested * 1000:.3g} mm -> {st.phi_result * 1000:.3g} mm in {st.evaluations} evaluations ({st.method})")
    lap("refine_state")

    # 7. post-check and escalation
    if overlay.initial_joint_positions is not None:
        overlay = overlay.model_copy(update={"initial_joint_positions": state})
    rounds: list[EscalationRound] = []
    write.write_output(asset, overlay, out_dir, state, copy=False, collision_overrides=overrides, root_rotation=root_rotation)
    check = postcheck.run_post_check(paths.urdf, state, overlay, config)
    rounds.append(EscalationRound(round=0, metrics=check.metrics, reason="initial post-check"))
    n = 0
    while not check.passed and n < config.max_escalation_rounds:
        n += 1
        overlay, changes, reason = postcheck.escalate(overlay, check, config.escalation_factor)
        if not changes:
            break
        write.write_output(asset, overlay, out_dir, state, copy=False, collision_overrides=overrides, root_rotation=root_rotation)
        check = postcheck.run_post_check(paths.urdf, state, overlay, config)
        rounds.append(EscalationRound(round=n, metrics=check.metrics, changes=changes, reason=reason))
    lap("post_check")
    return _Attempt(
        asset=asset, overlay=overlay, issues=issues, bands=bands, prismatic=prismatic, closed_out=closed_out,
        st=st, state=state, overrides=overrides, root_rotation=root_rotation, check=check, rounds=rounds,
    )


def _refine_state_with_decomposition(asset, overlay, closed_out, bands, requested, urdf, root_rotation, config, out_dir, mesh_cache, say, proposer=None):
    """State refinement; when hull overlaps keep Phi above tolerance, CoACD
    decomposition of the colliding pieces and a second search (kept only if
    it lowers Phi). Returns (StateRefinement, collision overrides)."""
    from asset2sim.tasks.synthesize import estimate
    from asset2sim.tasks.state import refine_state
    from asset2sim.tasks.publish import write

    fractions = estimate.band_intervals(bands)
    s = overlay.scale

    def search(start: dict[str, float]):
        sess = open_session("pybullet", urdf, SessionOptions(fixed_base=True, gravity=False, ground=False, conventions=config.sim))
        try:
            return refine_state.refine_initial_state(
                sess, asset, closed_out, start, fractions,
                tolerance=config.penetration_tolerance, lam=config.state_lambda,
                max_evaluations=config.max_state_evaluations, seed=config.seed,
                proposer=proposer,
            )
        finally:
            sess.close()

    st = search(requested)
    if not (st.phi_result > config.penetration_tolerance and config.convex_decomposition):
        return st, {}
    from asset2sim.tasks.state import collision

    deep = [(p_["link_a"], p_["link_b"]) for p_ in st.worst_pairs if p_["depth_m"] > config.penetration_tolerance]
    links = sorted({ln for pair in deep for ln in pair})
    sess = open_session("pybullet", urdf, SessionOptions(fixed_base=True, gravity=False, ground=False, initial_state=st.result))
    try:
        overrides, dnotes = collision.improve_collisions(
            sess, asset, deep, s, out_dir, cache=mesh_cache, budget_s=config.decomposition_budget
        )
    except (collision.DecompositionUnavailable, ValueError) as exc:
        say("refine_state", f"collision improvement skipped: {exc}")
        st.collision_changes = [f"collision improvement skipped: {exc}"]
        return st, {}
    finally:
        sess.close()
    if not overrides:
        st.collision_changes = dnotes or [f"no collision piece change lowered the overlap of {', '.join(links)}"]
        return st, {}
    before = st
    write.write_output(asset, overlay, out_dir, requested, copy=False, collision_overrides=overrides, root_rotation=root_rotation)
    st = search(requested)
    st.evaluations += before.evaluations
    st.model_queries += before.model_queries
    st.phi_requested = before.phi_requested
    if st.phi_result >= before.phi_result:
        # the decomposition did not help (pieces of neighbours can bulge): keep the original hulls
        write.write_output(asset, overlay, out_dir, requested, copy=False, root_rotation=root_rotation)
        before.evaluations = st.evaluations
        before.model_queries = st.model_queries
        before.collision_changes = [
            f"collision pieces changed for {', '.join(links)} but Phi went {before.phi_result * 1000:.3g} -> "
            f"{st.phi_result * 1000:.3g} mm; original collision meshes kept"
        ] + dnotes
        return before, {}
    st.collision_changes = dnotes
    st.method = before.method + " | collision pieces improved -> " + st.method
    return st, overrides


def _start_output(out_dir: Path) -> None:
    """Before (re)writing an output folder: drop its completion marker (the
    folder is not complete until the run finishes) and temporary files a
    killed run left behind."""
    (out_dir / MARKER_NAME).unlink(missing_ok=True)
    if out_dir.is_dir():
        for tmp in out_dir.rglob(".*.tmp"):
            try:
                tmp.unlink()
            except OSError:
                pass


def _finding_dict(f) -> dict:
    """A validation finding of the extraction stage as a JSON-able dict."""
    if hasattr(f, "to_issue"):
        return f.to_issue().model_dump()
    if hasattr(f, "model_dump"):
        return f.model_dump(mode="json")
    return dict(vars(f))


def _parity_rows(check) -> list[dict]:
    """Side-by-side engine rows for the report (PyBullet first)."""
    if not check.engine_results:
        return []
    from asset2sim.tasks.check import parity

    base = [m for m in check.metrics if m.name in parity.METRICS]
    return parity.parity_table({"pybullet": base, **check.engine_results})


def _remove_stale_collision(out_dir: Path, overrides: dict) -> None:
    """Delete ``collision/`` pieces the final URDF does not reference."""
    used = {p_.filename for pcs in overrides.values() for p_ in pcs}
    folder = out_dir / "collision"
    if folder.is_dir():
        for f in folder.iterdir():
            if f"collision/{f.name}" not in used:
                f.unlink(missing_ok=True)
        if not any(folder.iterdir()):
            folder.rmdir()


def _write_extras(out_dir: Path, report: RefineReport, check, say: Progress) -> dict[str, str]:
    """Optional outputs: MJCF export, renders, HTML report. Each is skipped
    (with a note in the report) when its module or engine is unavailable."""
    out: dict[str, str] = {}
    try:
        from asset2sim.tasks.publish import export_mjcf
    except ImportError:
        export_mjcf = None
    if export_mjcf is not None:
        try:
            out["mjcf"] = str(export_mjcf.export_mjcf(out_dir))
        except ImportError as exc:
            report.notes.append(f"MJCF export skipped: {exc}")
        except Exception as exc:  # export must not lose the refined asset
            report.notes.append(f"MJCF export failed: {exc}")
    try:
        from asset2sim.tasks.publish import render
    except ImportError:
        render = None
    if render is not None:
        try:
            render.render_views(out_dir / "mobility.urdf", report.initial_joint_positions, out_dir / "views")
            out["views"] = str(out_dir / "views")
        except Exception as exc:
            report.notes.append(f"renders failed: {exc}")
    try:
        from asset2sim.tasks.publish import report_html
    except ImportError:
        report_html = None
    if report_html is not None and hasattr(report_html, "write_refine_report"):
        try:
            out["html"] = str(report_html.write_refine_report(out_dir, report, check.trace))
        except Exception as exc:
            report.notes.append(f"HTML report failed: {exc}\n{traceback.format_exc(limit=3)}")
    return out
