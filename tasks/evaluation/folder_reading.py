"""What an asset folder holds as the checks read it: its physics when it has no ``overlay.json``
(:func:`file_overlay`), its joints' closed ends (:func:`closed_ends`), the object every check simulates
(:func:`sim_object`), its task-relevant joints and GenSim2's reference state (:func:`task_joints`,
:func:`reference_state`), its records (:func:`read_records`) and its scale (:func:`stated_scale`).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from asset2sim import output_folder
from asset2sim.engines.source import SimObject, UrdfFile
from asset2sim.inert import one_line
from asset2sim.output_folder import OutputError
from asset2sim.refined_asset import RefinedAsset
from asset2sim.schemas.asset import AssetDescription
from asset2sim.schemas.config import SimConventions
from asset2sim.schemas.overlay import EstimatorInfo, Inertia, JointDynamics, LinkPhysics, Overlay
from asset2sim.schemas.report import RefineReport
from asset2sim.tasks.geometry.closed_state import ClosedState
from asset2sim.tasks.geometry.urdf_closed import measure_closed_ends
from asset2sim.tasks.ingest import partnet_mobility
from asset2sim.tasks.ingest.errors import AssetError
from asset2sim.tasks.ingest.extract import extract_asset
from asset2sim.tasks.interpret.part_labels import labels_from_names
from asset2sim.tasks.interpret.part_priors import push_buttons, task_relevant_joints as part_task_joints
from asset2sim.tasks.synthesize.context import EstimationContext
from asset2sim.urdf import UrdfError, UrdfModel, read_urdf


class EvaluationError(ValueError):
    """The asset cannot be evaluated (the message names the file and why)."""


def read_asset(asset: Path | str, category: str | None = None) -> tuple[RefinedAsset, AssetDescription]:
    """(the files of the asset folder or URDF ``asset``, its URDF found as refine finds one; its description, of
    ``category`` when given). Raises EvaluationError: it cannot be read."""
    try:
        urdf = partnet_mobility.find_urdf(asset).resolve()
        return RefinedAsset(urdf.parent, urdf.name), extract_asset(asset, category=category)
    except AssetError as exc:
        raise EvaluationError(str(exc)) from exc


def reference_state(ref: partnet_mobility.GenSim2Reference, model: UrdfModel, scale: float | None) -> tuple[dict[str, float], str]:
    """(GenSim2's state of the reference's task joints present in ``model``, the rule): the lower end of
    ``joint_position_range`` (else 0) clipped to the reference URDF's limits, prismatic values times ``scale`` (else the
    reference's, else 1). Raises UrdfError: the reference URDF cannot be read."""
    if ref.urdf is None:
        return {}, ""
    have = {j.name for j in model.joints}
    ref_joints = {j.name: j for j in read_urdf(ref.urdf, mode="lenient").joints}
    rng = ref.joint_position_range
    k = scale if scale is not None else (ref.scale or 1.0)
    state = {n: float(np.clip(rng[0] if rng is not None else 0.0, jr.lower, jr.upper)) * (k if jr.type == "prismatic" else 1)
             for n in ref.task_joints if n in have and n in ref_joints for jr in [ref_joints[n]]}
    return state, (("lower end of joint_position_range" if rng is not None else "0")
                   + " clipped to reference_gensim2.urdf's limits (prismatic x the evaluated scale)")


def file_overlay(model: UrdfModel) -> Overlay:
    """The physics a simulator loads from ``model`` when the folder holds no ``overlay.json``: every ``<inertial>`` (a
    link with geometry and none: the engines' default 1 kg, unit inertia), every movable joint's ``<dynamics>`` (0 when
    not written), no springs, scale 1 (the file as it is)."""
    links = {}
    for n, ln in model.links.items():
        i = ln.inertial
        if i is not None and i.mass is not None and i.mass > 0:
            t = np.asarray(i.inertia_in_link_axes() if i.inertia is not None else np.eye(3), float)
            links[n] = LinkPhysics(mass=float(i.mass), inertia=Inertia(ixx=t[0, 0], ixy=t[0, 1], ixz=t[0, 2], iyy=t[1, 1], iyz=t[1, 2],
                                                                       izz=t[2, 2]), com=tuple(float(x) for x in i.com()),
                                   source="file <inertial>")
        elif ln.collisions or ln.visuals:
            links[n] = LinkPhysics(mass=1.0, inertia=Inertia(ixx=1.0, iyy=1.0, izz=1.0), com=(0.0, 0.0, 0.0),
                                   source="engine default (no <inertial>)")
    joints = {j.name: JointDynamics(damping=j.damping, friction=j.friction, source="file <dynamics>") for j in model.movable_joints}
    return Overlay(estimator=EstimatorInfo(name="file"), scale=1.0, links=links, joints=joints)


def closed_ends(files: RefinedAsset, joints: list[str] | None = None) -> tuple[dict[str, ClosedState], str]:
    """(joint -> closed end of ``joints`` (default every movable joint) of the folder's URDF, where they come from): those
    its ``report.json`` recorded when it holds them all (a refine's decision, read once), else measured
    (:func:`~asset2sim.tasks.geometry.urdf_closed.measure_closed_ends`), a joint that does not open there (or when the
    measurement fails) closed at its limit nearest 0 (a continuous joint at 0, range pi). Rad or m.

    Raises:
        EvaluationError: the URDF cannot be read.
    """
    try:
        model = files.model
    except (OSError, ValueError, UrdfError) as exc:
        raise EvaluationError(f"{files.folder}: {one_line(exc)}") from exc
    try:
        report = files.report if (files.folder / output_folder.REPORT_NAME).is_file() else None
    except (OSError, ValueError):  # not a refine's report: the closed ends are measured
        report = None
    names = [j.name for j in model.movable_joints] if joints is None else list(joints)
    rec = report.closed_ends if report is not None else {}
    if names and all(n in rec for n in names):
        def bound(v, default: float) -> float:
            return default if v is None else float(v)
        return {n: ClosedState(n, float(rec[n]["q_closed"]), float(rec[n]["direction"]), float(rec[n]["open_range"]),
                               bound(rec[n].get("lower"), -math.inf), bound(rec[n].get("upper"), math.inf)) for n in names}, "report.json"
    try:  # push buttons closed where they rest, as the refine measured them (part_priors.push_buttons)
        pushed = push_buttons(labels_from_names(extract_asset(files.urdf_path)), getattr(report, "category", None))
        measured = measure_closed_ends(UrdfFile(files.urdf_path), pushed).closed
    except Exception:  # the geometry cannot be measured: every joint closed at its limit nearest 0
        measured = {}
    return {n: c if (c := measured.get(n)) is not None and c.open_range > 0 else _closed_fallback(model.joint(n))
            for n in names}, "geometry (closed_state)"


def _closed_fallback(j) -> ClosedState:
    """The closed end of joint ``j`` without geometry: the limit nearest 0 (continuous: 0, range pi)."""
    lo, hi = j.lower, j.upper
    if j.type == "continuous" or not (math.isfinite(lo) and math.isfinite(hi)) or lo > hi:
        return ClosedState(j.name, 0.0, 1.0, math.pi, -math.inf, math.inf)
    qc = lo if abs(lo) <= abs(hi) else hi
    return ClosedState(j.name, float(qc), 1.0 if qc == lo else -1.0, float(hi - lo), float(lo), float(hi))


def sim_object(files: RefinedAsset, conventions: SimConventions | None = None) -> tuple[SimObject, str]:
    """(the folder's URDF as every check simulates it, where its state comes from): at ``initial_state.json``'s state
    (the other movable joints at 0 clipped to their limits), with ``overlay.json``'s springs and the root as declared,
    under ``conventions`` (default the SPEC's).

    Raises:
        EvaluationError: the URDF, ``initial_state.json`` or ``overlay.json`` cannot be read.
    """
    try:
        model, given = files.model, files.initial_state
        state = {j.name: float(given.get(j.name, np.clip(0.0, j.lower, j.upper))) for j in model.movable_joints}
        obj = SimObject(UrdfFile(files.urdf_path), state, files.springs_about(state), conventions or SimConventions(), files.root.fixed)
    except (OSError, ValueError, UrdfError, OutputError) as exc:
        raise EvaluationError(f"{files.folder}: {one_line(exc)}") from exc
    return obj, output_folder.STATE_NAME if given else "none: 0 clipped to the limits"


def task_joints(asset: AssetDescription, category: str, reference: Path | None = None) -> tuple[list[str], str]:
    """(the task-relevant joints of ``asset``, the rule): the movable joints of GenSim2's ``reference`` that ``asset``
    has (GenSim2 keeps only the task's joint movable), else the category's choice by part label
    (:func:`asset2sim.tasks.interpret.part_priors.task_relevant_joints`). Raises EvaluationError: an unreadable reference."""
    movable = [j.name for j in asset.movable_joints()]
    if reference is not None:
        try:
            tj = [j for j in partnet_mobility.read_reference(reference).task_joints if j in movable]
        except (ValueError, OSError, UrdfError) as exc:
            raise EvaluationError(f"reference {reference}: {exc}") from exc
        if tj:
            return tj, "movable joints of reference_gensim2.urdf"
    return part_task_joints(category, [(n, asset.link(asset.joint(n).child).semantic_label) for n in movable])


def stated_scale(report: RefineReport | None, overlay: Overlay | None, baseline: dict | None, ctx: EstimationContext,
                  reference: Path | None) -> tuple[float | None, str]:
    """(the evaluated object's scale relative to the raw input, its source): the first record stating one
    (``report.json``, ``overlay.json``, ``baseline.json``), else its closed extents against those of the ``reference``
    folder's raw ``mobility.urdf`` (largest over largest), else unknown."""
    for value, name in ((report.scale if report else None, "report.json"), (overlay.scale if overlay else None, "overlay.json"),
                        ((baseline or {}).get("scale"), "baseline.json")):
        if isinstance(value, (int, float)):
            return float(value), name
    raw = reference / partnet_mobility.URDF_NAMES[0] if reference is not None else None
    if raw is not None and raw.is_file():
        try:
            b = float(np.max(measure_closed_ends(UrdfFile(raw)).extents))
        except Exception:  # the raw geometry cannot be measured: the scale stays unknown
            b = 0.0
        a = float(np.max(ctx.closed_extents))
        if a > 0 and b > 0:
            return a / b, "geometry: largest closed extent vs the reference folder's raw mobility.urdf"
    return None, "unknown"


def read_records(folder: RefinedAsset, notes: list[str]) -> tuple[RefineReport | None, dict | None, dict | None, Overlay | None]:
    """(``report.json`` as a refine's report, as JSON, ``baseline.json``, ``overlay.json``) of ``folder``, each None when
    absent; a ``report.json`` that is not a refine's is shown in the report but not read as one (noted in ``notes``).
    Raises EvaluationError: a file exists but cannot be read."""
    try:
        raw = folder.record(output_folder.REPORT_NAME)
        baseline = folder.record("baseline.json")
        overlay = folder.overlay
    except (OSError, ValueError) as exc:
        raise EvaluationError(f"{folder.folder}: {one_line(exc)}") from exc
    report = None
    if isinstance(raw, dict):
        try:
            report = folder.report
        except (OSError, ValueError) as exc:
            notes.append(f"report.json is not a refine's report ({one_line(exc, 200)}): its closed ends, request and task not used")
    return report, raw if isinstance(raw, dict) else None, baseline if isinstance(baseline, dict) else None, overlay
