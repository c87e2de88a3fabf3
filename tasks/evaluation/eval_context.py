"""What an evaluation knows before any simulator runs: the :class:`Context`
(:func:`build_context`: the URDF and its sidecars, the reference, the request,
the category prior, the scale and its source).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from asset2sim.engines.base import Spring
from asset2sim.engines.source import SimObject, UrdfFile
from asset2sim.engines.loading import joint_spring
from asset2sim.schemas.config import RefineConfig, SimConventions
from asset2sim.schemas.request import RequestSpec
from asset2sim.tasks.check.asset_files import (
    MOVABLE,
    EvaluationError,
    JointInfo,
    LinkInfo,
    clip_to_limits,
    find_urdf,
    parse_urdf,
    read_category,
    read_json,
    read_semantics,
)
from asset2sim.tasks.evaluation.closed_ends import ClosedEnd, infer_scale_from_geometry
from asset2sim.tasks.interpret.categories import category_name
from asset2sim.tasks.interpret.request import parse_prompt
from asset2sim.tasks.interpret.size_priors import size_mass_prior
from asset2sim.tasks.check.task_spec import TaskSpec
from asset2sim.tasks.ingest import partnet_mobility
from asset2sim.tasks.interpret.part_priors import task_relevant_joints
from asset2sim.output_folder import OVERLAY_NAME, REPORT_NAME, STATE_NAME, OutputError
from asset2sim.refined_asset import RefinedAsset


@dataclass
class Context:
    """Everything the metrics need besides the simulator runs. Joint positions rad/m, scale relative to the raw input;
    ``closed`` and ``task_joints`` are filled in by the evaluation."""

    urdf: Path
    folder: Path
    asset_id: str
    links: dict[str, LinkInfo]
    joints: dict[str, JointInfo]
    initial_state: dict[str, float]
    initial_state_source: str
    overlay: dict[str, Any] | None
    report: dict[str, Any] | None
    baseline: dict[str, Any] | None
    semantics: dict[str, tuple[str, str]]
    category: str | None
    prompt: str | None
    request: RequestSpec | None
    request_error: str | None
    reference_dir: Path | None
    reference_scale: float | None
    reference_state: dict[str, float]
    reference_rule: str
    scale: float | None
    scale_source: str
    task_joints: list[str]
    closed: dict[str, ClosedEnd]
    springs: dict[str, Spring]
    prior: dict[str, Any]
    conventions: SimConventions
    sag_tol_revolute: float
    sag_tol_prismatic: float
    notes: list[str] = field(default_factory=list)
    closed_extents: np.ndarray | None = None  # (3,) m AABB with every joint at its closed end
    root_fixed: bool = False  # a mounted asset: every simulation holds the root fixed
    task: TaskSpec | None = None  # the parsed manipulation task; None: task execution not run

    @property
    def source(self) -> UrdfFile:
        """The evaluated ``urdf`` as the checks simulate it."""
        return UrdfFile(self.urdf)

    @property
    def sim_object(self) -> SimObject:
        """The evaluated asset as the checks simulate it: ``source`` at ``initial_state`` with ``springs``,
        ``conventions`` and the root as declared (``root_fixed``)."""
        return SimObject(self.source, self.initial_state, self.springs, self.conventions, self.root_fixed)

    @property
    def movable(self) -> list[str]:
        """Names of the revolute, continuous and prismatic joints, in file order."""
        return [n for n, j in self.joints.items() if j.type in MOVABLE]


def task_joints(joints: dict[str, JointInfo], reference_dir: Path | None, requested: list[str],
                category: str | None = None, semantics: dict[str, tuple[str, str]] | None = None) -> tuple[list[str], str]:
    """The task-relevant joints and the rule that chose them: the reference's movable joints present here; else those the
    request names (``requested``); else, with part labels (``semantics``: link -> (kind, label)) and a ``category``,
    refine's own choice (:func:`asset2sim.tasks.interpret.part_priors.task_relevant_joints`); else every movable joint.
    Raises ValueError / asset2sim.urdf.UrdfError: the reference's JSON / URDF is malformed."""
    movable = [n for n, j in joints.items() if j.type in MOVABLE]
    if reference_dir is not None:
        ref = partnet_mobility.read_reference(reference_dir)
        tj = [j for j in ref.task_joints if j in movable]
        if tj:
            return tj, "movable joints of reference_gensim2.urdf"
    if requested:
        return [j for j in movable if j in requested], "joints the request names"
    labels = {n: (semantics or {}).get(joints[n].child, (None, None))[1] for n in movable}
    if category and any(labels.values()):
        return task_relevant_joints(category, list(labels.items()))
    return movable, "every movable joint"


def _stated_scale(overlay: dict[str, Any] | None, report: dict[str, Any] | None, baseline: dict[str, Any] | None,
                  urdf: Path, ref_dir: Path | None) -> tuple[float | None, str]:
    """(scale, source): the first sidecar stating one, else geometry against the reference's raw URDF, else unknown."""
    for data, name in ((overlay, OVERLAY_NAME), (report, REPORT_NAME), (baseline, "baseline.json")):
        if data is not None and isinstance(data.get("scale"), (int, float)):
            return float(data["scale"]), name
    if ref_dir is not None and (ref_dir / partnet_mobility.URDF_NAMES[0]).is_file():
        inferred = infer_scale_from_geometry(urdf, ref_dir / partnet_mobility.URDF_NAMES[0])
        if inferred is not None:
            return inferred, "geometry: largest AABB extent vs the raw mobility.urdf at q = 0"
    return None, "unknown"


def _reference_state(ref: partnet_mobility.GenSim2Reference, joints: dict[str, JointInfo], scale: float | None
                     ) -> tuple[dict[str, float], str]:
    """(reference state of the task joints, rule): the lower end of ``joint_position_range``
    (else 0) clipped to the reference's limits, prismatic values times the scale (else the
    reference's, else 1). Raises EvaluationError: the reference URDF cannot be read."""
    state: dict[str, float] = {}
    _, ref_joints = parse_urdf(UrdfFile(ref.urdf))
    rng = ref.joint_position_range
    for n in ref.task_joints:
        if n not in joints:
            continue
        jr = ref_joints[n]
        q = clip_to_limits(rng[0] if rng is not None else 0.0, jr.lower, jr.upper)
        if jr.type == "prismatic":
            q *= scale if scale is not None else (ref.scale or 1.0)
        state[n] = q
    return state, (("lower end of joint_position_range" if rng is not None else "0")
                   + " clipped to reference_gensim2.urdf's limits (prismatic x the evaluated scale)")


def build_context(asset: Path | str, *, reference: Path | str | None = None, prompt: str | None = None,
                  category: str | None = None, conventions: SimConventions | None = None) -> Context:
    """Read the asset (folder or URDF file) and its sidecars, the reference and the request (``category`` overrides theirs);
    ``task_joints`` and ``closed`` stay empty. Raises EvaluationError: no URDF, unreadable URDF/JSON, a missing reference
    folder."""
    urdf = find_urdf(asset).resolve()
    folder = urdf.parent
    links, joints = parse_urdf(UrdfFile(urdf))
    notes: list[str] = []
    files = RefinedAsset(folder, urdf.name)
    overlay, report, baseline = (read_json(files, name) for name in (OVERLAY_NAME, REPORT_NAME, "baseline.json"))
    initial, src = _initial_state(read_json(files, STATE_NAME), joints)
    root_fixed = _root_fixed(files, notes)
    ref_dir = Path(reference).resolve() if reference is not None else None
    if ref_dir is not None and not ref_dir.is_dir():
        raise EvaluationError(f"reference {ref_dir}: no such folder")
    semantics = read_semantics(folder) or (read_semantics(ref_dir) if ref_dir else {})
    cat = (category or (overlay or {}).get("category") or (report or {}).get("category") or (baseline or {}).get("category")
           or category_name(prompt, read_category(folder) or (read_category(ref_dir) if ref_dir else None),
                                 [lab for _, lab in semantics.values()]))
    spec, req_err = parse_prompt(prompt)
    if req_err:
        notes.append(req_err)
    ref_info = partnet_mobility.read_reference(ref_dir) if ref_dir is not None else None
    scale, scale_src = _stated_scale(overlay, report, baseline, urdf, ref_dir)
    springs = _springs(overlay, joints, initial)
    ref_state, rule = _reference_state(ref_info, joints, scale) if ref_info is not None and ref_info.urdf is not None else ({}, "")
    return Context(
        urdf=urdf, folder=folder, asset_id=(report or {}).get("asset_id") or (baseline or {}).get("asset_id") or folder.name,
        links=links, joints=joints, initial_state=initial, initial_state_source=src, overlay=overlay, report=report,
        baseline=baseline, semantics=semantics, category=cat, prompt=prompt, request=spec, request_error=req_err,
        reference_dir=ref_dir, reference_scale=ref_info.scale if ref_info is not None else None, reference_state=ref_state,
        reference_rule=rule, scale=scale, scale_source=scale_src, task_joints=[], closed={},
        springs=springs, prior=size_mass_prior(cat, spec), conventions=conventions or SimConventions(),
        sag_tol_revolute=RefineConfig().sag_tolerance_revolute, sag_tol_prismatic=RefineConfig().sag_tolerance_prismatic,
        notes=notes, root_fixed=root_fixed,
    )


def _initial_state(st: dict[str, Any] | None, joints: dict[str, JointInfo]) -> tuple[dict[str, float], str]:
    """(joint -> initial position rad/m from ``st``, other movable joints 0 clipped to the limits; its source)."""
    raw = {} if st is None else st.get("initial_joint_positions", st)
    initial = {k: float(v) for k, v in raw.items() if k in joints}
    for n, j in joints.items():
        if j.type in MOVABLE and n not in initial:
            initial[n] = clip_to_limits(0.0, j.lower, j.upper)
    return initial, STATE_NAME if st is not None else "none: 0 clipped to the limits"


def _root_fixed(files: RefinedAsset, notes: list[str]) -> bool:
    """Whether ``initial_state.json`` declares the root fixed (noted); EvaluationError when unreadable."""
    try:
        root_fixed = files.root.fixed
    except OutputError as exc:
        raise EvaluationError(str(exc)) from exc
    if root_fixed:
        notes.append("root fixed as initial_state.json declares (mounted asset): every simulation holds it, no ground plane")
    return root_fixed


def _springs(overlay: dict[str, Any] | None, joints: dict[str, JointInfo], initial: dict[str, float]) -> dict[str, Spring]:
    """joint -> the overlay's spring (stiffness > 0; reference rad/m, else the initial position;
    :func:`~asset2sim.formats.mjcf.export.joint_spring`)."""
    springs: dict[str, Spring] = {}
    for jn, jd in ((overlay or {}).get("joints") or {}).items():
        if jn in joints and float(jd.get("stiffness") or 0.0) > 0:
            springs[jn] = joint_spring(jd, initial.get(jn, 0.0))
    return springs


def hold_required(ctx: Context, joints: list[str]) -> dict[str, bool]:
    """joint -> whether it must hold where an operation leaves it
    (:func:`asset2sim.tasks.check.task_tier.hold_required_by_label` with the context's labels, springs, request)."""
    from asset2sim.tasks.check.task_tier import hold_required_by_label

    labels = {n: ((ctx.semantics.get(ctx.joints[n].child) or (None, None))[1] if n in ctx.joints else None)
              for n in joints}
    req = ctx.request
    return hold_required_by_label(labels, ctx.springs, ctx.category, free_moving=bool(req is not None and req.free_moving),
                                  spring_requested=bool(req is not None and req.spring))
