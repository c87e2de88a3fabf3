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


def post_check_failure_mode(check: Any) -> str:
    """Failure mode of a refine run from its final post-check.

    Args:
        check: a :class:`asset2sim.tasks.check.postcheck.PostCheck` (its
            ``stable`` property and ``penetration`` (mm) and ``oscillation``
            metrics are used).

    Returns:
        ``unstable``, ``oscillating``, ``unresolved_penetration`` or ``none``,
        the first that applies in this order.
    """
    osc = check.metric("oscillation")
    pen = check.metric("penetration")
    if not check.stable:
        return "unstable"
    if not osc.passed:
        return "oscillating"
    if pen.value is not None and pen.value > UNRESOLVED_PENETRATION_MM:
        return "unresolved_penetration"
    return "none"


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
    elif measured_status in FAILED_STATUSES and mode in (None, "none"):
        mode = "timeout" if measured_status == "timeout" else "crash"
    if chain_error_mode is not None and mode in (None, "none"):
        mode = chain_error_mode
    if mode is None:
        mode = MISSING_FAILURE_MODE
    return AssetVerdict(mode, errors)
