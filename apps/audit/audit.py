"""Audit one asset that carries physics: read what it declares (URDF, MJCF or OpenUSD), judge every value
against the product's estimates (:mod:`.judge`), run the simulation checks on the declared and on the
patched physics, and, given an output folder, write ``audit.json``, ``audit.md`` (the verdicts, the checks and
the changes) and the patch in the input's format (:mod:`.patch`). The input is only read."""

from __future__ import annotations

import tempfile
from dataclasses import dataclass, replace
from pathlib import Path

from asset2sim import atomic, output_folder
from asset2sim.engines.quiet import quiet_stdout
from asset2sim.engines.source import UrdfFile
from asset2sim.urdf import read_urdf, write_urdf
from asset2sim.schemas.asset import AssetDescription
from asset2sim.schemas.audit import AuditReport, SimulationChecks
from asset2sim.schemas.config import RefineConfig
from asset2sim.schemas.overlay import Overlay, RootMount
from asset2sim.refined_asset import read_initial_state, springs_from_overlay
from asset2sim.tasks.assemble import write
from asset2sim.apps.audit import patch, report_md
from asset2sim.tasks.check.plausibility import Judgement, judge
from asset2sim.tasks.geometry.closed_state import closed_tuples
from asset2sim.tasks.check import postcheck
from asset2sim.tasks.ingest import declared as declared_mod, extract
from asset2sim.formats import ReadOptions
from asset2sim.tasks.interpret import mounting
from asset2sim.tasks.interpret.categories import recognize_category
from asset2sim.tasks.interpret.part_labels import labels_from_names
from asset2sim.tasks.synthesize.context import build_context

__all__ = ["AUDIT_JSON", "AUDIT_MD", "AuditError", "AuditResult", "audit_asset"]

#: File names in an asset's audit folder.
AUDIT_JSON = "audit.json"
AUDIT_MD = "audit.md"


class AuditError(RuntimeError):
    """The asset cannot be audited (the message names the file, link or joint)."""


@dataclass(frozen=True)
class AuditResult:
    """What :func:`audit_asset` produced: the report and, with an output folder, the folder it wrote."""

    report: AuditReport
    out_dir: Path | None = None


def audit_asset(path: Path | str, out_dir: Path | str | None = None, *, category: str | None = None,
                asset_id: str | None = None, simulate: bool = True, config: RefineConfig | None = None) -> AuditResult:
    """Audit the asset at ``path``.

    Args:
        path: a URDF asset (folder or file), an MJCF file, an OpenUSD file, or a folder holding one MJCF or USD file.
        out_dir: where to write ``audit.json``, ``audit.md`` and ``patch/`` (the input's format); None writes
            nothing. Must not lie inside the input's folder.
        category: the object category (default: ``meta.json``'s, else recognised from labels and names).
        asset_id: the name to report (default: the folder name, or the file stem).
        simulate: run the rest, robust-rest and sweep checks on the declared and patched physics (PyBullet).
        config: the simulation conventions (``config.sim``) and how an MJCF input is read (``config.body``,
            ``config.mjcf``); default :class:`RefineConfig`.

    Returns:
        :class:`AuditResult` with the :class:`~asset2sim.schemas.audit.AuditReport`.

    Raises:
        AuditError: the asset cannot be read (validation errors, an MJCF or USD file the asset model cannot
            take, mesh analysis failing), or ``out_dir`` lies inside the input.
    """
    config = config or RefineConfig()
    try:
        reading = ReadOptions(body=config.body, mjcf_angle=config.mjcf.angle)
        asset, findings = extract.extract_asset_checked(path, asset_id=asset_id, category=category, reading=reading)
        dp = declared_mod.read_declared(path, asset.urdf_path, reading)
    except Exception as exc:
        raise AuditError(_cannot(path, exc)) from exc
    asset = labels_from_names(asset)  # as the context builder labels it
    # the asset's own names as phrases (storage_box -> storage box), for recognising its category
    words = ". ".join(dict.fromkeys(" ".join(w for w in s.replace("-", "_").split("_") if w)
                                    for s in (asset.robot_name, asset.asset_id)))
    match = recognize_category(category or asset.category, [ln.semantic_label for ln in asset.links], words)
    source = asset.staged_from or asset.urdf_path
    if out_dir is not None:
        out_dir = Path(out_dir)
        try:
            output_folder.check_location(asset.source_dir, out_dir)
            output_folder.check_location(Path(source).parent, out_dir)
        except output_folder.OutputError as exc:
            raise AuditError(str(exc)) from exc
    try:
        if dp.format == "urdf":  # a URDF input's state and springs lie in the files beside it
            (initial, declared_root), dp = _state_file(asset), _overlay_springs(asset, dp)
        else:
            initial, declared_root = dict(dp.initial_state), None
        with build_context(asset, "", config, category=match.name) as (ctx, kin):
            # the root as the file declares it (MJCF: no free joint welds it; USD: a fixed joint to the world), read as a
            # --mount override reads, else the category's prior
            mount = (declared_root or mounting.declared_mounting(ctx.category, dp.root_fixed, f"the {dp.format.upper()} file")
                     or mounting.category_mounting(ctx.category))
            judged = judge(ctx, kin, dp, mount)
            with quiet_stdout():  # engines print from C; the library must not
                checks = _simulate(ctx, judged, config, initial) if simulate else []
    except AuditError:
        raise
    except Exception as exc:
        raise AuditError(_cannot(source, exc, with_type=True)) from exc
    report = AuditReport(asset_id=asset.asset_id, source=str(source), format=dp.format, category=ctx.category,
                         category_reason=match.reason, labels={ln.name: ln.semantic_label for ln in asset.links if ln.semantic_label}, root_fixed=mount.fixed,
                         root_source=mount.source, values=judged.values, checks=checks,
                         notes=[*(f"WARNING: {f.describe()}" for f in findings if f.code == "JOINT_RANGE_WRONG_UNIT"),
                                *judged.notes, *asset.staging_notes])
    if out_dir is None:
        return AuditResult(report=report)
    # audit.json, audit.md and the patch (when a value changes), atomic writes
    out_dir.mkdir(parents=True, exist_ok=True)
    with output_folder.guarding(out_dir):  # nothing through a symlinked patch/ (or out_dir/..)
        if any(v.patched is not None for v in report.values):
            written = patch.write_patch(asset, dp, report.values, judged.patched, out_dir / patch.PATCH_DIR)
            report = report.model_copy(update={"patch": written.relative_to(out_dir).as_posix()})
        atomic.write_json(out_dir / AUDIT_JSON, report.model_dump(mode="json"))
        atomic.write_text(out_dir / AUDIT_MD, report_md.render(report))
    return AuditResult(report=report, out_dir=out_dir)


def _cannot(path: Path | str, exc: BaseException, with_type: bool = False) -> str:
    """``<path>: cannot audit: <why>``, the path said once (the reason may start with it already)."""
    why, before = str(exc), None
    while why != before:
        before = why
        for prefix in (f"{path}: ", f"{Path(path).resolve()}: ", "cannot read this MJCF file: ", "cannot read this USD file: "):
            why = why.removeprefix(prefix)
    return f"{path}: cannot audit: " + (f"{type(exc).__name__}: " if with_type else "") + why


def _overlay_springs(asset: AssetDescription, dp: declared_mod.DeclaredPhysics) -> declared_mod.DeclaredPhysics:
    """``dp`` with the joint springs of the asset folder's ``overlay.json`` (an asset2sim output keeps them there,
    URDF having no element for them; read as the MJCF exporter reads them); unchanged without the file.

    Raises:
        AuditError: the file is not an overlay.
    """
    try:
        springs = springs_from_overlay(asset.source_dir)
    except ValueError as exc:
        raise AuditError(str(exc)) from exc
    return replace(dp, joints={n: replace(j, stiffness=springs[n].stiffness, reference=springs[n].reference) if n in springs
                               else j for n, j in dp.joints.items()})


def _state_file(asset: AssetDescription) -> tuple[dict[str, float], RootMount | None]:
    """The joint positions (rad or m) and the root declaration of the asset folder's ``initial_state.json`` (the
    output contract's, :mod:`asset2sim.tasks.assemble.write`): ({}, None) without the file or its entries.

    Raises:
        AuditError: the file is not the contract's shape.
    """
    if not (asset.source_dir / write.STATE_NAME).is_file():
        return {}, None
    try:
        state = read_initial_state(asset.source_dir)
        root = write.read_root(asset.source_dir)
    except (ValueError, output_folder.OutputError) as exc:
        raise AuditError(str(exc)) from exc
    known = {j.name for j in asset.movable_joints()}
    return {k: v for k, v in state.items() if k in known}, (root if root.source else None)


def _simulate(ctx, judged: Judgement, config: RefineConfig, initial: dict[str, float]) -> list[SimulationChecks]:
    """Rest, robust rest and the joint sweep (:func:`asset2sim.tasks.check.postcheck.run_post_check`) on the
    declared and on the patched physics, each from ``initial`` (the asset's ``initial_state.json``, or an MJCF
    keyframe), else the
    joints' closed ends (a spring's joint: its reference within the limits), with the asset's own collision
    geometry as a simulator loading the file gets it (:func:`_physics_urdf`)."""
    state = {**ctx.closed_state(), **initial}
    closed = closed_tuples(ctx.closed)
    out = []
    with tempfile.TemporaryDirectory(prefix="asset2sim-audit-") as tmp:
        for kind, overlay in (("declared", judged.declared), ("patched", judged.patched)):
            # the closed end, or a spring's reference within the joint's limits
            start = dict(state)
            for name, dyn in overlay.joints.items():
                if dyn.stiffness > 0 and dyn.spring_reference is not None and name in ctx.closed:
                    cs = ctx.closed[name]
                    start[name] = min(max(dyn.spring_reference, cs.lower), cs.upper)
            start.update(initial)
            try:
                urdf = _physics_urdf(ctx.asset, overlay, Path(tmp) / f"{kind}.urdf")
                check = postcheck.run_post_check(postcheck.overlay_object(UrdfFile(urdf), start, overlay, config.sim), config,
                                                 closed=closed)
            except Exception as exc:  # a simulator that cannot load or step these values: said, not raised
                out.append(SimulationChecks(physics=kind, passed=False, error=f"{type(exc).__name__}: {exc}"))
                continue
            failures = [m.name for m in check.metrics if m.passed is False]
            out.append(SimulationChecks(physics=kind, passed=check.passed and not failures, failures=failures, metrics=check.metrics))
    return out


def _physics_urdf(asset: AssetDescription, overlay: Overlay, path: Path) -> Path:
    """The asset's URDF (for MJCF and USD: the staged one) with ``overlay``'s inertials, damping and friction, its
    collision geometry as written (meshes by absolute path) and no visuals, written to ``path`` for the engines."""
    model = patch.apply_physics(read_urdf(asset.urdf_path, mode="lenient"), dict(overlay.links), dict(overlay.joints))
    for link in model.links.values():
        link.visuals = []
        for g in link.collisions:
            if g.kind == "mesh" and g.path is not None:
                g.filename = str(g.path)
    atomic.write_bytes(path, write_urdf(model))
    return path
