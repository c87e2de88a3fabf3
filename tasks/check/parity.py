"""Cross-simulator parity: the SPEC's physical-robustness metrics (penetration,
rest stability, oscillation) of an output folder in several engines under the
same conventions (``docs/design/simulators.md``). A missing engine is skipped,
one that cannot load the asset fails; :func:`parity_table` gives report rows (the post-check fails on any engine
that fails, ``PostCheck.passed``).
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

from asset2sim.schemas.metrics import SPEC_METRICS, unit
from asset2sim.schemas.report import MetricResult
from asset2sim.tasks.check import breakaway, metrics
from asset2sim.refined_asset import RefinedAsset

from asset2sim.engines.base import EngineUnavailable, EngineUnsupported, SessionOptions
from asset2sim.engines.source import SimSource, UrdfFile

#: The metrics compared across engines (the registry's SPEC metrics).
METRICS = SPEC_METRICS


def _not_run(engine: str, key: str, reason: str, passed: bool | None) -> list[MetricResult]:
    return [MetricResult(name=n, value=None, unit=unit(n), passed=None if n == "penetration" else passed, details={key: reason},
                         engine=engine) for n in METRICS]


def evaluate_engines(urdf_dir: Path, engines: list[str], *, initial_state: dict[str, float] | None = None) -> dict[str, list[MetricResult]]:
    """engine -> [penetration (mm), rest stability, oscillation] of one output folder in each of ``engines``
    (duplicates dropped; :func:`session_metrics`), ``initial_state`` overriding the folder's, the root as the
    folder declares it, under the SPEC's conventions.

    Raises:
        FileNotFoundError: no ``mobility.urdf`` in ``urdf_dir``.
        ValueError: invalid ``initial_state.json`` or ``overlay.json``.
    """
    asset = RefinedAsset.existing(urdf_dir)
    options = asset.session_options(None, initial_state)
    return {e: session_metrics(UrdfFile(asset.urdf_path), e, options) for e in dict.fromkeys(engines)}


def session_metrics(source: SimSource, engine: str, options: SessionOptions) -> list[MetricResult]:
    """[penetration (mm), rest stability, oscillation] of ``source`` opened in ``engine`` with ``options``, each
    with ``details["root"]``; a missing package gives ``details.skipped``, a load or run error
    ``details.error`` and ``passed`` False."""
    conv = options.conventions
    try:
        session = source.open(engine, options)
    except EngineUnavailable as exc:
        results = _not_run(engine, "skipped", str(exc), None)
    except KeyError as exc:
        results = _not_run(engine, "skipped", f"unknown engine: {exc}", None)
    except Exception as exc:  # the asset does not load in this engine: a failure
        results = _not_run(engine, "error", f"could not load: {type(exc).__name__}: {exc}", False)
    else:
        try:
            try:
                pen = metrics.penetration(session)
                pen.details["ground_penetration_mm"] = float(session.ground_penetration()) * 1000.0
            except EngineUnsupported as exc:  # an engine that reads no contacts (ovphysx): not measured, not failed
                pen = MetricResult(name="penetration", value=None, unit=unit("penetration"), passed=None,
                                   details={"unsupported": str(exc)}, engine=engine)
            pen.details["engine_notes"] = list(session.notes)
            trace = metrics.run_rest_test(session, conv)
            rest = metrics.rest_stability(trace, conv, engine=engine)
            osc = metrics.oscillation(trace, conv, engine=engine)
            settling = metrics.joint_settling(trace, timestep=conv.timestep)
            rest.details.update(joint_drift={n: j.settled for n, j in settling.items()},
                                joints_held={n: j.held for n, j in settling.items()},
                                breakaway=engine_breakaway(source, engine, options))
            results = [pen, rest, osc]
        except Exception as exc:  # an engine error mid-run fails the asset in that engine
            results = _not_run(engine, "error", f"{type(exc).__name__}: {exc}", False)
        finally:
            session.close()
    for m in results:
        m.details["root"] = metrics.root_label(options.fixed_base)
    return results


def engine_breakaway(source: SimSource, engine: str, options: SessionOptions) -> dict:
    """Every joint with friction pushed in ``engine`` (:mod:`asset2sim.tasks.check.breakaway`: root fixed, gravity off,
    the options' springs and state): :func:`~asset2sim.tasks.check.breakaway.breakaway_summary`, ``measured`` False
    with the reason where the engine cannot push a joint or save its state or does not load the asset."""
    joints = source.model().movable_joints
    frictions = {j.name: float(j.friction) for j in joints}
    dampings = {j.name: float(j.damping) for j in joints}
    try:
        session = source.open(engine, dataclasses.replace(options, fixed_base=True, gravity=False, ground=False))
    except EngineUnavailable as exc:
        return breakaway.breakaway_summary(None, str(exc))
    try:
        return breakaway.breakaway_summary(breakaway.measure_breakaway(session, frictions, dampings, source.model()))
    except EngineUnsupported as exc:
        return breakaway.breakaway_summary(None, f"{engine} cannot push a joint: {exc}")
    finally:
        session.close()


def parity_table(results: dict[str, list[MetricResult]]) -> list[dict[str, Any]]:
    """One row per engine for reports and the catalog (``status`` ``ok``, ``skipped`` or ``error``)."""
    rows = []
    for engine, res in results.items():
        pen, rest, osc = (next((m for m in res if m.name == n), None) for n in ("penetration", "rest_stability", "oscillation"))
        status, reason = "ok", ""
        pen_d, rest_d, osc_d = found = [getattr(m, "details", {}) for m in (pen, rest, osc)]
        for d in found:
            if "skipped" in d:
                status, reason = "skipped", d["skipped"]
            elif "error" in d:
                status, reason = "error", d["error"]
        pairs, measured = pen_d.get("pairs", []), status == "ok" and pen.value is not None
        rows.append({
            "engine": engine, "status": status, "reason": reason,
            "penetration_mm": getattr(pen, "value", None),
            "max_depth_mm": max((p["max_depth_mm"] for p in pairs), default=0.0) if measured else None,
            "penetration_points": sum(p["points"] for p in pairs) if measured else None,
            "rest_stability": getattr(rest, "passed", None),
            "D_pos_m": rest_d.get("D_pos_m"), "D_ori_rad": rest_d.get("D_ori_rad"),
            "oscillation": getattr(osc, "passed", None),
            "failing_joints": list(osc_d.get("failing", [])), "joints_held": dict(rest_d.get("joints_held", {})),
            "breakaway": rest_d.get("breakaway"), "engine_notes": list(pen_d.get("engine_notes", [])),
        })
    return rows
