"""Baseline methods for the benchmark (SPEC, "Baselines the product can reproduce";
docs/design/metrics.md, section 5): ``defaults``, ``human``, ``direct``,
``asset2sim``, each turning one manifest row into an asset folder
(``mobility.urdf``, ``initial_state.json``, ``baseline.json``); looked up by
name (:func:`run_method`, :func:`register_method`).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

from asset2sim.atomic import write_json
from asset2sim.schemas.config import RefineConfig
from asset2sim.tasks import refine
from asset2sim.tasks.ingest import partnet_mobility
from asset2sim.tasks.ingest.errors import AssetError
from asset2sim.tasks.ingest.partnet_mobility import ManifestRow, read_manifest, scale_urdf, urdf_joints
from asset2sim.tasks.assemble import write
from asset2sim.tasks.synthesize import backends, estimate
from asset2sim.tasks.synthesize.context import build_context
from asset2sim.output_folder import STATE_NAME, URDF_NAME

__all__ = [
    "BaselineError",
    "BaselineResult",
    "ManifestRow",
    "available_methods",
    "make_asset2sim",
    "make_defaults",
    "make_direct",
    "make_human",
    "read_manifest",
    "register_method",
    "run_method",
    "scale_urdf",
    "urdf_joints",
]

class BaselineError(RuntimeError):
    """A baseline could not be produced (message names the asset and why)."""


@dataclass
class BaselineResult:
    """What a method produced for one asset."""

    method: str
    asset_id: str
    out_dir: Path
    scale: float | None
    initial_state: dict[str, float] = field(default_factory=dict)
    seconds: float = 0.0
    model_queries: int = 0
    notes: list[str] = field(default_factory=list)


def make_defaults(row: ManifestRow, out_dir: Path | str) -> BaselineResult:
    """``defaults`` baseline for one manifest row (module docstring).
    Raises BaselineError: no ``mobility.urdf`` in the row's folder."""
    t0 = time.perf_counter()
    out_dir = Path(out_dir)
    src = row.folder / partnet_mobility.URDF_NAMES[0]
    if not src.is_file():
        raise BaselineError(f"{row.id}: no mobility.urdf in {row.folder}")
    ref = partnet_mobility.read_reference(row.folder)
    scale = ref.scale if ref.scale is not None else row.reference_scale
    notes = []
    if scale is None:
        scale = 1.0
        notes.append("no reference scale: raw scale 1.0")
    urdf = scale_urdf(src, out_dir / URDF_NAME, scale, header=f"asset2sim baseline 'defaults' of {row.id} at scale {scale}")
    state = partnet_mobility.reference_initial_state(urdf_joints(urdf), [], None, scale)  # every movable joint: 0 clipped
    write_json(out_dir / STATE_NAME, {"initial_joint_positions": state})
    notes.append("no <inertial>: PyBullet uses 1 kg and inertia diag(1,1,1) kg*m^2 per link; no <dynamics>: zero damping and friction")
    write_json(out_dir / "baseline.json", {"method": "defaults", "asset_id": row.id, "source": str(src), "scale": scale,
                                           "category": row.category, "initial_state_rule": "0 clipped to the joint limits",
                                           "notes": notes})
    return BaselineResult("defaults", row.id, out_dir, scale, state, time.perf_counter() - t0, 0, notes)


def make_human(row: ManifestRow, out_dir: Path | str) -> BaselineResult:
    """``human`` baseline (GenSim2's reference,
    :func:`asset2sim.tasks.ingest.partnet_mobility.write_reference`) for one manifest row.
    Raises BaselineError: no ``reference_gensim2.urdf`` in the row's folder."""
    t0 = time.perf_counter()
    out_dir = Path(out_dir)
    try:
        ref = partnet_mobility.write_reference(row.folder, out_dir, f"asset2sim baseline 'human' (GenSim2 reference) of {row.id}")
    except AssetError as exc:
        raise BaselineError(f"{row.id}: {exc}") from exc
    rng = ref.joint_position_range
    write_json(out_dir / "baseline.json", {
        "method": "human", "asset_id": row.id, "source": str(ref.source), "scale": ref.scale, "category": row.category,
        "joint_position_range": list(rng) if rng else None, "task_joints": ref.task_joints,
        "initial_state_rule": "lower end of joint_position_range (else 0) clipped to the limits", "notes": ref.notes})
    return BaselineResult("human", row.id, out_dir, ref.scale, ref.initial_state, time.perf_counter() - t0, 0, ref.notes)


def make_direct(row: ManifestRow, out_dir: Path | str, *, seed: int = 0, estimator: str = "offline") -> BaselineResult:
    """``direct`` baseline: refine's estimation context, one ``estimate`` call of ``estimator``, its overlay written as is
    with the state its bands imply (no validation, state refinement, post-check or escalation). Raises BaselineError: a
    stage failed (the message names it)."""
    t0 = time.perf_counter()
    out_dir = Path(out_dir)
    try:
        with build_context(row.folder, row.prompt, category=row.category or None, asset_id=row.id) as (ctx, kin):
            result = backends.get_estimator(estimator).estimate(ctx, kin)
        overlay = result.overlay
        prismatic = {j.name for j in ctx.asset.movable_joints() if j.type == "prismatic"}
        state = estimate.state_from_bands(ctx.closed, result.bands, overlay.scale, prismatic)
        state.update(overlay.initial_joint_positions or {})
        write.write_output(ctx.asset, overlay, out_dir, state)
    except Exception as exc:
        raise BaselineError(f"{row.id}: direct ({estimator}) failed: {type(exc).__name__}: {exc}") from exc
    write_json(out_dir / "baseline.json", {
        "method": "direct", "asset_id": row.id, "source": str(row.folder), "scale": overlay.scale, "category": ctx.category,
        "estimator": overlay.estimator.name, "initial_state_rule": "the estimator's requested bands, unrefined",
        "notes": ["one estimator call; no validation, no state refinement, no post-check"]})
    return BaselineResult("direct", row.id, out_dir, overlay.scale, state, time.perf_counter() - t0,
                          int(overlay.estimator.queries or (0 if estimator == "offline" else 1)))


def make_asset2sim(row: ManifestRow, out_dir: Path | str, *, seed: int = 0) -> BaselineResult:
    """``asset2sim``: :func:`asset2sim.tasks.refine.refine_asset` with the row's task, no extras.
    Raises BaselineError: the refine pipeline failed."""
    t0 = time.perf_counter()
    out_dir = Path(out_dir)
    try:
        res = refine.refine_asset(row.folder, row.prompt, out_dir, RefineConfig(seed=seed),
                                  category=row.category or None, asset_id=row.id, extras=False, task=row.task or None)
    except Exception as exc:
        raise BaselineError(f"{row.id}: refine_asset failed: {type(exc).__name__}: {exc}") from exc
    report = res.report
    return BaselineResult("asset2sim", row.id, out_dir, report.scale, dict(report.initial_joint_positions or {}),
                          time.perf_counter() - t0, int(report.model_queries or 0))


MethodFn = Callable[..., BaselineResult]

_REGISTRY: dict[str, MethodFn] = {
    "defaults": lambda row, out_dir, seed=0: make_defaults(row, out_dir),
    "human": lambda row, out_dir, seed=0: make_human(row, out_dir),
    "direct": make_direct,
    "asset2sim": make_asset2sim,
}


def register_method(name: str, fn: MethodFn) -> None:
    """Register ``fn(row, out_dir, seed=0) -> BaselineResult`` as method ``name``."""
    _REGISTRY[name] = fn


def available_methods() -> list[str]:
    """Registered method names."""
    return list(_REGISTRY)


def run_method(method: str, row: ManifestRow, out_dir: Path | str, *, seed: int = 0) -> BaselineResult:
    """Produce ``method``'s asset for ``row`` in ``out_dir``; KeyError: unknown method, BaselineError: not produced."""
    if method not in _REGISTRY:
        raise KeyError(f"unknown method {method!r}; known: {sorted(_REGISTRY)}")
    return _REGISTRY[method](row, Path(out_dir), seed=seed)
