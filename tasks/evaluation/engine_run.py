"""One engine's raw measurements of the evaluated asset (:func:`run_engine`),
read by the metrics (:mod:`asset2sim.tasks.evaluation.metric_defs`).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from asset2sim.engines.base import EngineUnavailable
from asset2sim.mesh_io import MeshReadError
from asset2sim.schemas.report import MetricResult
from asset2sim.tasks.check import metrics as spec_metrics
from asset2sim.tasks.check.postcheck import RestRecording, measure_rest_test, record_rest_test
from asset2sim.tasks.check.recorded_runs import RecordedRuns
from asset2sim.tasks.check.probes import OPEN_FAR_TARGET, run_probes
from asset2sim.tasks.check.support import rolling_joints
from asset2sim.tasks.check.asset_files import LinkInfo
from asset2sim.tasks.evaluation.closed_ends import compute_closed
from asset2sim.tasks.evaluation.eval_context import Context, hold_required
from asset2sim.tasks.geometry.limits import subtrees
from asset2sim.tasks.geometry.urdf_closed import aabb_extents
from asset2sim.tasks.state.ground_clearance import floor_stops
from asset2sim.urdf import read_urdf


@dataclass
class EngineRun:
    """Raw measurements in one engine (shared by the metrics)."""

    engine: str
    error: str | None = None
    penetration: MetricResult | None = None
    trace: spec_metrics.RestTrace | None = None
    ground_series: np.ndarray | None = None  # (K,) m deepest ground penetration per step (settle + test)
    root_series: np.ndarray | None = None  # (K, 3) m root position per step (settle + test)
    joint_series: dict[str, np.ndarray] = field(default_factory=dict)
    extents: np.ndarray | None = None  # (3,) m AABB of the links with collision at the initial state
    link_centres: dict[str, np.ndarray] = field(default_factory=dict)
    link_volumes: dict[str, float] = field(default_factory=dict)  # link -> m^3 volume of its AABB (which part is smaller)
    masses: dict[str, dict[str, Any]] = field(default_factory=dict)
    probes: list[Any] = field(default_factory=list)
    point_cloud: dict[str, np.ndarray] = field(default_factory=dict)  # link -> (N, 3) m world collision vertices
    seconds: float = 0.0
    recorded: RecordedRuns | None = None  # the post-check's manipulation runs, reused when their inputs match
    robust_rest: Any = None  # the RobustRestRun the robust_rest metric was graded from (the report's evidence)
    sweep: Any = None  # the SweepRun the joint_sweep metric was graded from (the report's evidence)
    task: Any = None  # the TaskRun the task_execution metric was graded from (the clips of the task)


def link_centres(session) -> dict[str, np.ndarray]:
    """Link -> (3,) m centre of the engine's AABB of the link (world frame)."""
    return {name: 0.5 * np.add(*session.link_aabb(name)) for name in session.link_names}


def link_volumes(session) -> dict[str, float]:
    """Link -> volume (m^3) of the engine's AABB of the link (world frame): "the smaller door" is the smaller box."""
    return {name: float(np.prod(np.maximum(np.subtract(*session.link_aabb(name)[::-1]), 0.0))) for name in session.link_names}


def link_masses(session, links: dict[str, LinkInfo]) -> dict[str, dict[str, Any]]:
    """Link -> {"mass" (kg, as the engine loaded it), "source"} (the file's ``<inertial>``, else the engine's default)."""
    return {name: {"mass": m, "source": "file <inertial>" if getattr(links.get(name), "mass", None) is not None
                   else "engine default (no <inertial>)"} for name, m in session.link_masses().items()}


def point_cloud(session, max_points: int = 1500) -> dict[str, np.ndarray]:
    """Link -> (N, 3) m collision vertices in the world frame at the
    session's current state, at most ``max_points`` per link (evenly picked)."""
    out = {}
    for name in session.link_names:
        v = session.link_collision_vertices(name)
        if not len(v):
            continue
        pos, R = session.link_frame(name)
        w = v @ R.T + pos
        if len(w) > max_points:
            w = w[np.linspace(0, len(w) - 1, max_points).astype(int)]
        out[name] = w
    return out


def _floor_stops(model, ctx: Context, targets: dict[str, tuple[float, float, float]]) -> dict[str, float]:
    """joint -> opening (rad or m) where the floor stops a probed part before the
    open probe's target (:func:`~asset2sim.tasks.state.ground_clearance.floor_stops`);
    none when a collision file cannot be read. Notes go to ``ctx.notes``."""
    try:
        stops = floor_stops(model, ctx.urdf, dict(ctx.initial_state), targets)
    except (OSError, MeshReadError) as exc:
        ctx.notes.append(f"probes: where the floor stops the parts was not measured ({exc}): no stop")
        return {}
    out = {}
    for name, stop in stops.items():
        _, _, rng = targets[name]
        if stop / rng >= OPEN_FAR_TARGET:
            continue
        out[name] = stop
        unit = "m" if ctx.joints[name].type == "prismatic" else "rad"
        ctx.notes.append(f"probes: the floor stops {name} {stop:.3g} {unit} from its closed end, of its {rng:.3g} {unit} "
                         "range (the object resting as it is): an open probe's target ends there")
    return out


def set_closed_ends(ctx: Context, joints: list[str]) -> None:
    """The closed ends of ``joints`` into ``ctx.closed`` (with their extents and notes), in a fresh
    session (:func:`compute_closed`: contact manifolds cached in a used one would change its tie-breaks)."""
    ext: list = []
    ctx.closed, cnotes = compute_closed(ctx.urdf, ctx.joints, joints, extents_out=ext)
    ctx.closed_extents = ext[0] if ext else None
    ctx.notes += cnotes


def run_engine(ctx: Context, engine: str, *, probes: bool = True, keep_geometry: bool = False,
               closed_for: list[str] | None = None, rest_test: bool = True,
               recording: RestRecording | None = None, recorded: RecordedRuns | None = None) -> EngineRun:
    """Open ``engine`` on the asset and take every raw measurement once: penetration at the initial state, extents,
    masses, the rest test per step, and (PyBullet) the probes from the unstepped initial state. ``closed_for``: joints
    whose closed ends go into ``ctx.closed``; ``rest_test=False``: no rest test (``trace`` and series stay None);
    ``recording``: the post-check's rest test, used when it matches; the probes try the task's joints and actions
    (``ctx.task``), without a task the task-relevant joints, close and open; ``recorded``: kept for the
    manipulation metrics. Errors are caught into ``EngineRun.error``."""
    probe_joints = ctx.task.joints if ctx.task is not None else None
    probe_actions = ctx.task.actions if ctx.task is not None else ("close", "open")
    t0 = time.perf_counter()
    run = EngineRun(engine, recorded=recorded)
    try:
        session = ctx.sim_object.open(engine)  # the root as declared
    except EngineUnavailable as exc:
        run.error = f"engine unavailable: {exc}"
        return run
    except Exception as exc:
        run.error = f"could not load: {type(exc).__name__}: {exc}"
        return run
    try:
        pyb = session.traits.reference  # the reference engine takes the extra measurements
        # Phi first, in the fresh session: Bullet keeps contact manifolds across later queries (docs/design/metrics.md)
        run.penetration = spec_metrics.penetration(session)
        saved = None
        if pyb:
            run.extents = aabb_extents(session)
            run.link_centres = link_centres(session)
            run.link_volumes = link_volumes(session)
            run.masses = link_masses(session, ctx.links)
            if keep_geometry:
                run.point_cloud = point_cloud(session)
            saved = session.save_state()
        if rest_test:
            if recording is None or not recording.matches(engine, ctx.sim_object):
                if pyb and probes:  # in a session of its own, as the post-check does: the probes start unstepped
                    _, recording = measure_rest_test(engine, ctx.sim_object)
                else:
                    recording = record_rest_test(session, ctx.sim_object)
            for name in ("trace", "root_series", "ground_series", "joint_series"):
                setattr(run, name, getattr(recording, name))
        if pyb and closed_for is not None:
            set_closed_ends(ctx, closed_for)
        if pyb and probes and saved is not None:
            session.restore_state(saved)
            model = read_urdf(ctx.urdf, mode="lenient")
            rolling = set(rolling_joints(session, subtrees(model)))  # wheels on the ground: the object is rolled, not them
            targets = {
                n: (c.q_closed, c.direction, c.open_range)
                for n, c in ctx.closed.items()
                if n in (ctx.task_joints if probe_joints is None else probe_joints) and c.open_range > 0 and n not in rolling
            }
            stops = _floor_stops(model, ctx, targets)
            holds = bool(getattr(ctx.request, "holds_position", False))
            returns = {n for n, h in hold_required(ctx, list(targets)).items() if not h}  # sprung by design
            run.probes = run_probes(session, targets, actions=tuple(probe_actions), holds_position=holds, model=model,
                                    returns=returns, floor_stops=stops)
    except Exception as exc:
        run.error = f"{type(exc).__name__}: {exc}"
    finally:
        session.close()
    run.seconds = time.perf_counter() - t0
    return run
