"""Baseline methods for the benchmark (SPEC, "Baselines the product can reproduce";
docs/design/metrics.md, section 5): ``defaults``, ``human``, ``direct``,
``asset2sim``, each turning one manifest row into an asset folder
(``mobility.urdf``, ``initial_state.json``, ``baseline.json``); looked up by
name (:func:`run_method`, :func:`register_method`).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

from asset2sim.atomic import copy_file, sha256_file, write_bytes, write_json
from asset2sim.schemas.config import RefineConfig
from asset2sim.tasks import refine
from asset2sim.tasks.ingest import partnet_mobility
from asset2sim.tasks.ingest.partnet_mobility import ManifestRow, read_manifest
from asset2sim.tasks.assemble import copied_meshes, write
from asset2sim.tasks.synthesize import backends, estimate
from asset2sim.tasks.synthesize.context import build_context
from asset2sim.urdf import UrdfLimit, read_urdf, scale_model, write_urdf
from asset2sim.output_folder import STATE_NAME, URDF_NAME

__all__ = [
    "BaselineError",
    "BaselineResult",
    "ManifestRow",
    "available_methods",
    "human_initial_state",
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


# ---------------------------------------------------------------- URDF scaling
def scale_urdf(src: Path | str, dst: Path | str, scale: float, *, joint_limits: dict[str, tuple[float, float]] | None = None,
               header: str = "", copy_meshes: bool = True) -> Path:
    """Write a copy of URDF ``src`` with the uniform scale ``scale`` (> 0) baked in
    (:func:`asset2sim.urdf.scale_model`: mesh scales, primitive sizes, origins,
    prismatic limits, inertia x s^2, masses kept) to ``dst``; returns ``dst``.

    ``joint_limits``: joint -> (lower, upper), input units, replacing the file's;
    ``header``: a comment atop ``<robot>``; ``copy_meshes``: copy the meshes inside
    ``src``'s folder beside ``dst`` (relative paths), else absolute paths.
    Raises ValueError: bad scale, ``package://`` mesh paths, an unknown joint; UrdfError: ``src`` unreadable."""
    if not (math.isfinite(scale) and scale > 0):
        raise ValueError(f"scale must be a finite number > 0, got {scale}")
    src = Path(src).resolve()
    model = read_urdf(src, mode="lenient")
    to_copy: set[Path] = set()
    for link in model.links.values():
        for g in link.visuals + link.collisions:
            if g.kind != "mesh":
                continue
            fname = g.filename or ""
            if fname.startswith("package://"):
                raise ValueError(f"{src}: link {link.name!r}: package:// mesh paths are not supported")
            mesh_src = (src.parent / fname.removeprefix("file://")).resolve()
            if copy_meshes and mesh_src.is_relative_to(src.parent):
                to_copy.add(mesh_src)
                g.filename = mesh_src.relative_to(src.parent).as_posix()
            else:
                g.filename = str(mesh_src)
    dst_dir = Path(dst).parent
    for mesh_src in sorted(to_copy):
        for f in [mesh_src] + copied_meshes.mesh_dependencies(mesh_src, src.parent):
            out = dst_dir / f.relative_to(src.parent)
            if not (out.is_file() and sha256_file(out) == sha256_file(f)):
                copy_file(f, out)
    names = {j.name: j for j in model.joints}
    missing = set(joint_limits or {}) - set(names)
    if missing:
        raise ValueError(f"{src}: joints {sorted(missing)} not found")
    for name, (lo, hi) in (joint_limits or {}).items():
        joint = names[name]
        if joint.limit is None:
            joint.limit = UrdfLimit()
        joint.limit.lower, joint.limit.upper = float(lo), float(hi)
    scale_model(model, float(scale))
    write_bytes(Path(dst), write_urdf(model, comment=f" {header} " if header else None))
    return Path(dst)


def urdf_joints(urdf: Path | str) -> dict[str, dict[str, Any]]:
    """Joint name -> {type, lower, upper} (rad or m; None when absent) of a URDF (lenient reading).
    Raises UrdfError: unreadable XML or a malformed number."""
    return {j.name: {"type": j.type, "lower": None if j.limit is None else j.limit.lower,
                     "upper": None if j.limit is None else j.limit.upper} for j in read_urdf(urdf, mode="lenient").joints}


def _clip(q: float, lo: float | None, hi: float | None) -> float:
    if lo is not None:
        q = max(q, lo)
    if hi is not None:
        q = min(q, hi)
    return float(q)


def human_initial_state(joints: dict[str, dict[str, Any]], task_joints: list[str], rng: tuple[float, float] | None,
                        scale: float) -> dict[str, float]:
    """The human baseline's initial state (output units): the task joints at the lower
    end of ``rng`` (prismatic times ``scale``), others at 0, clipped to the limits."""
    out = {}
    for name, j in joints.items():
        if j["type"] in ("revolute", "continuous", "prismatic"):
            q = rng[0] * (scale if j["type"] == "prismatic" else 1.0) if rng is not None and name in task_joints else 0.0
            out[name] = _clip(q, j["lower"], j["upper"])
    return out


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
    joints = urdf_joints(urdf)
    state = {n: _clip(0.0, j["lower"], j["upper"]) for n, j in joints.items() if j["type"] in ("revolute", "continuous", "prismatic")}
    write_json(out_dir / STATE_NAME, {"initial_joint_positions": state})
    notes.append("no <inertial>: PyBullet uses 1 kg and inertia diag(1,1,1) kg*m^2 per link; no <dynamics>: zero damping and friction")
    write_json(out_dir / "baseline.json", {"method": "defaults", "asset_id": row.id, "source": str(src), "scale": scale,
                                           "category": row.category, "initial_state_rule": "0 clipped to the joint limits",
                                           "notes": notes})
    return BaselineResult("defaults", row.id, out_dir, scale, state, time.perf_counter() - t0, 0, notes)


def make_human(row: ManifestRow, out_dir: Path | str) -> BaselineResult:
    """``human`` baseline (GenSim2's reference) for one manifest row.
    Raises BaselineError: no ``reference_gensim2.urdf`` in the row's folder."""
    t0 = time.perf_counter()
    out_dir = Path(out_dir)
    ref = partnet_mobility.read_reference(row.folder)
    if ref.urdf is None:
        raise BaselineError(f"{row.id}: no reference_gensim2.urdf in {row.folder}")
    notes = []
    scale = ref.scale
    if scale is None:
        scale = 1.0
        notes.append("reference_gensim2.json has no scale: 1.0 (SAPIEN's default)")
    rng = ref.joint_position_range
    limits = None
    if rng is not None:
        # GenSim2's range, within the file's own limits (an empty intersection keeps the range)
        file_joints = urdf_joints(ref.urdf)
        limits = {}
        for j in ref.task_joints:
            lo = max(rng[0], file_joints[j]["lower"]) if file_joints[j]["lower"] is not None else rng[0]
            hi = min(rng[1], file_joints[j]["upper"]) if file_joints[j]["upper"] is not None else rng[1]
            limits[j] = (lo, hi) if lo <= hi else rng
    urdf = scale_urdf(ref.urdf, out_dir / URDF_NAME, scale, joint_limits=limits,
                      header=f"asset2sim baseline 'human' (GenSim2 reference) of {row.id} at scale {scale}")
    joints = urdf_joints(urdf)
    state = human_initial_state(joints, ref.task_joints, rng, scale)
    write_json(out_dir / STATE_NAME, {"initial_joint_positions": state})
    write_json(out_dir / "baseline.json", {
        "method": "human", "asset_id": row.id, "source": str(ref.urdf), "scale": scale, "category": row.category,
        "joint_position_range": list(rng) if rng else None, "task_joints": ref.task_joints,
        "initial_state_rule": "lower end of joint_position_range (else 0) clipped to the limits", "notes": notes})
    return BaselineResult("human", row.id, out_dir, scale, state, time.perf_counter() - t0, 0, notes)


def make_direct(row: ManifestRow, out_dir: Path | str, *, seed: int = 0, estimator: str = "offline") -> BaselineResult:
    """``direct`` baseline: refine's estimation context, one ``estimate`` call of ``estimator``, its overlay written as is
    with the state its bands imply (no validation, state refinement, post-check or escalation). Raises BaselineError: a
    stage failed (the message names it)."""
    t0 = time.perf_counter()
    out_dir = Path(out_dir)
    try:
        with build_context(row.folder, row.prompt, category=row.category or None, asset_id=row.id, settings={"seed": seed}) as ctx:
            result = backends.get_estimator(estimator).estimate(ctx)
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
