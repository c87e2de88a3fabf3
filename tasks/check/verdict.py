"""The failure mode of an asset, decided in one place.

The fixed vocabulary is :data:`asset2sim.schemas.report.FAILURE_MODES`. Two
decisions use it:

- :func:`post_check_failure_mode`: the refine report's mode from the final
  post-check (``tasks.refine``): ``unstable`` (rest stability or toppling
  while settling, in any engine), ``oscillating``, ``unresolved_penetration``
  (Phi above :data:`UNRESOLVED_PENETRATION_MM`), else ``none``.
- :func:`asset_failure_mode`: the catalog row's mode from what each stage of
  the flow recorded (the manifest row, the flow's input check, the refine
  stage, the metrics stage, an exception that stopped the chain). A manifest
  row that cannot be read is :data:`INVALID_MANIFEST_ROW`: that asset alone
  fails, the others run.

A row without a recorded mode counts as :data:`MISSING_FAILURE_MODE`
(``queries``).

Interaction-readiness is decided here too, tier by tier (:data:`TIERS`,
:func:`readiness`): ``rest`` (the SPEC's passive half: rest stability,
oscillation, joints held, no toppling, no divergence, ground penetration),
``sweep`` (:mod:`asset2sim.tasks.check.sweep`), ``robust_rest``
(:mod:`asset2sim.tasks.check.robust_rest`), ``probes``
(:mod:`asset2sim.tasks.check.probes`) and, when a task is given, ``task``
(:mod:`asset2sim.tasks.check.task_execution`) and ``force``
(:mod:`asset2sim.tasks.check.force_ranges`). An asset is interaction-ready iff no
measured metric of any tier fails, in any engine. Semantic accuracy (scale,
mass, prompt alignment) is reported beside it and does not decide it. The
refine report (``readiness``, ``failure_mode``), the terminal summary,
``report.html`` and the catalog row all take the verdict from here, so they
agree.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

#: Phi (mm) above which penetration counts as unresolved (refine's verdict).
UNRESOLVED_PENETRATION_MM = 5.0
#: What a catalog row without a failure mode counts as.
MISSING_FAILURE_MODE = "crash"
#: Stage statuses of a stage that ran and failed (``flows.isolation``).
FAILED_STATUSES = ("error", "timeout", "crash")
#: Mode of an asset whose manifest row cannot be used (too long for the CSV
#: reader, a missing or unsafe id, no prompt column, an invalid number); the
#: row's code (``MANIFEST_*``) is in the error text.
INVALID_MANIFEST_ROW = "invalid_manifest_row"


#: Interaction-readiness tiers: tier -> (metrics that decide it, failure mode
#: when one fails), in the order a failure is reported (the post-check's order:
#: :func:`post_check_failure_mode`). Penetration at the initial state has no
#: pass threshold of its own in the SPEC; here it fails above
#: :data:`UNRESOLVED_PENETRATION_MM` (refine's tolerance for unresolved penetration).
TIERS: dict[str, tuple[tuple[str, ...], str]] = {
    "rest": (("rest_stability", "settle_tilt", "divergence", "ground_penetration", "oscillation", "state_hold",
              "joint_hold"), "unstable"),
    "penetration": (("penetration",), "unresolved_penetration"),
    "sweep": (("joint_sweep",), "blocked_joint"),
    "robust_rest": (("robust_rest",), "not_robust_at_rest"),
    "probes": (("probes",), "probe_failed"),
    "task": (("task_execution",), "task_failed"),
    "force": (("operating_force",), "implausible_force"),
}


#: Rest-tier metrics of a joint that leaves its state (the object itself at rest).
HOLD_METRICS: tuple[str, ...] = ("state_hold", "joint_hold")


@dataclass
class Readiness:
    """The interaction-readiness verdict of a set of metric results.

    ``tiers``: tier -> True (every measured metric of it passes), False (one
    fails), None (none measured); ``failures``: ``metric@engine`` of the
    failing metrics, in tier order; ``failure_mode``: the first failing
    tier's mode (in the rest tier ``oscillating`` when only oscillation
    fails, ``joint_not_held`` when only a joint leaves its state), ``none``
    when ready."""

    tiers: dict[str, bool | None]
    failures: list[str]
    failure_mode: str

    @property
    def ready(self) -> bool:
        """No tier fails (tiers not measured do not count)."""
        return not any(v is False for v in self.tiers.values())

    def line(self) -> str:
        """One line for people: ``interaction-ready (rest, sweep, ...)`` or
        ``NOT READY: probes@pybullet, ...``, then the tiers."""
        tiers = ", ".join(f"{t} {'pass' if v else ('FAIL' if v is False else 'n/a')}" for t, v in self.tiers.items())
        if self.ready:
            return f"interaction-ready ({tiers})"
        return f"NOT READY: {', '.join(self.failures)} ({tiers})"


def _verdict(m: Any) -> bool | None:
    """A metric's pass/fail for readiness: ``passed``; penetration (mm, no
    SPEC threshold): fails above :data:`UNRESOLVED_PENETRATION_MM`."""
    if m.name == "penetration":
        return None if m.value is None else bool(m.value <= UNRESOLVED_PENETRATION_MM)
    return m.passed


def readiness(metrics: list[Any]) -> Readiness:
    """The verdict of :class:`~asset2sim.schemas.report.MetricResult` s
    (post-check, evaluation or both, any engines): see :data:`TIERS`.
    A metric with ``passed`` None (skipped, no threshold) does not count."""
    tiers: dict[str, bool | None] = {}
    failures: list[str] = []
    mode = "none"
    for tier, (names, tier_mode) in TIERS.items():
        ms = [m for m in metrics if m.name in names and _verdict(m) is not None]
        bad = [m for m in ms if _verdict(m) is False]
        tiers[tier] = None if not ms else not bad
        failures += list(dict.fromkeys(f"{m.name}@{m.engine}" for m in bad))
        if bad and mode == "none":
            mode = tier_mode
            if tier == "rest" and all(m.name == "oscillation" for m in bad):
                mode = "oscillating"
            elif tier == "rest" and all(m.name in HOLD_METRICS for m in bad):
                mode = "joint_not_held"
    return Readiness(tiers, failures, mode)


def combine_verdict(report: Any, evaluation_metrics: list[Any]) -> Readiness:
    """Refine's final verdict once its evaluation ran (probes included): the
    evaluation measured the written files itself and recorded the
    post-check's checks it does not measure (``evaluate_asset(checks=...)``),
    so :func:`readiness` of its metrics is the verdict ``report.html`` shows;
    ``report.readiness`` gets its tiers and ``report.failure_mode`` its mode.

    Args:
        report: a :class:`~asset2sim.schemas.report.RefineReport` (changed in place).
        evaluation_metrics: the :class:`~asset2sim.schemas.evaluation.Evaluation`'s metrics.
    """
    r = readiness(list(evaluation_metrics))
    report.readiness = r.tiers
    report.failure_mode = r.failure_mode
    return r


def post_check_failure_mode(check: Any) -> str:
    """Failure mode of a refine run from its final post-check.

    Args:
        check: a :class:`asset2sim.tasks.check.postcheck.PostCheck` (its
            ``stable`` property and ``penetration`` (mm) and ``oscillation``
            metrics are used).

    Returns:
        ``unstable``, ``oscillating``, ``unresolved_penetration``, then the
        first failing manipulation tier's mode of the post-check's metrics
        (``blocked_joint``, ``not_robust_at_rest``: :func:`readiness`), or
        ``none``, the first that applies in this order.
    """
    osc = check.metric("oscillation")
    pen = check.metric("penetration")
    if not check.stable:
        return "unstable"
    if not osc.passed:
        return "oscillating"
    if pen.value is not None and pen.value > UNRESOLVED_PENETRATION_MM:
        return "unresolved_penetration"
    return readiness(list(check.metrics)).failure_mode


def status_failure_mode(status: str, recorded: str | None = None) -> str:
    """Mode of a stage that failed with ``status`` (``error``, ``timeout``,
    ``crash``): the mode the stage's exception carried, else ``timeout`` for a
    timeout and ``crash`` otherwise."""
    return recorded or ("crash" if status == "error" else status)


def exception_failure_mode(exc: BaseException, retryable: type[BaseException] | None = None) -> str:
    """Mode of an exception that stopped an asset's chain outside its stages:
    ``estimator_failure`` for ``retryable`` (a failed model call), ``timeout``
    for a time-out, else ``crash``."""
    if retryable is not None and isinstance(exc, retryable):
        return getattr(exc, "failure_mode", "estimator_failure")
    if isinstance(exc, TimeoutError) or "Timeout" in type(exc).__name__:
        return "timeout"
    return "crash"


@dataclass
class AssetVerdict:
    """The failure mode of a catalog row and the error notes that explain it."""

    failure_mode: str
    errors: list[str] = field(default_factory=list)


def asset_failure_mode(
    *,
    manifest_error: str | None = None,
    input_failure: str | None = None,
    refine_status: str | None = None,
    refine_mode: str | None = None,
    measured_status: str | None = None,
    rest_stable: bool | None = None,
    oscillation_pass: bool | None = None,
    chain_error_mode: str | None = None,
    measured_failures: list[str] | None = None,
) -> AssetVerdict:
    """Failure mode of one asset in a flow run.

    Args:
        manifest_error: the code (``MANIFEST_*``) and message of a manifest
            row that could not be used: the mode is :data:`INVALID_MANIFEST_ROW`
            whatever else is given (no stage ran).
        input_failure: mode of the input check when it refused the asset
            (``invalid_input``).
        refine_status: the refine stage's status (``ok``, ``error``,
            ``timeout``, ``crash``, ``skipped`` or None when it did not run).
        refine_mode: with ``ok``: the refine report's mode; with a failed
            status: the mode its exception carried (may be None).
        measured_status: the metrics stage's status.
        rest_stable, oscillation_pass: the metrics stage's verdicts (it may
            find a failure the post-check did not).
        chain_error_mode: mode of an exception that stopped the chain outside
            the stages (:func:`exception_failure_mode`).
        measured_failures: the metrics stage's failing metrics
            (``metric@engine``); a failing readiness tier (:data:`TIERS`:
            sweep, robust rest, probes) gives its mode when nothing failed
            before, so the catalog agrees with ``report.html``.

    Returns:
        The :class:`AssetVerdict`: the first failure in stage order; a metrics
        stage failure or a chain error only when nothing failed before;
        ``crash`` when no stage recorded anything.
    """
    mode: str | None = None
    errors: list[str] = []
    if manifest_error is not None:
        return AssetVerdict(INVALID_MANIFEST_ROW, [f"manifest: {manifest_error}"])
    if input_failure is not None:
        mode = input_failure
    if refine_status == "ok":
        mode = refine_mode or "none"
    elif refine_status in FAILED_STATUSES:
        mode = status_failure_mode(refine_status, refine_mode)
    if measured_status == "ok" and mode == "none":
        if rest_stable is False:
            mode = "unstable"
            errors.append("metrics stage: rest stability failed although the refine post-check passed")
        elif oscillation_pass is False:
            mode = "oscillating"
            errors.append("metrics stage: oscillation failed although the refine post-check passed")
        elif measured_failures:
            failing = {f.split("@", 1)[0] for f in measured_failures}
            for tier, (names, tier_mode) in TIERS.items():
                if tier != "rest" and failing & set(names):
                    mode = tier_mode
                    errors.append(f"metrics stage: {tier} failed ({', '.join(f for f in measured_failures if f.split('@', 1)[0] in names)})")
                    break
    elif measured_status in FAILED_STATUSES and mode in (None, "none"):
        mode = "timeout" if measured_status == "timeout" else "crash"
    if chain_error_mode is not None and mode in (None, "none"):
        mode = chain_error_mode
    if mode is None:
        mode = MISSING_FAILURE_MODE
    return AssetVerdict(mode, errors)
