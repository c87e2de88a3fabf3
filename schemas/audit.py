"""The audit of an asset that carries physics: the contents of ``audit.json``
(:func:`asset2sim.apps.audit.audit.audit_asset`).

Every value is in SI units and radians: mass kg, density kg/m^3, inertia
kg*m^2, center of mass m, scale dimensionless, revolute damping N*m*s/rad,
friction N*m, stiffness N*m/rad, prismatic N*s/m, N, N/m, limits rad or m.
"""

from __future__ import annotations

from typing import Literal

from asset2sim.schemas import Strict
from asset2sim.schemas.report import MetricResult

#: Version of the ``audit.json`` layout.
AUDIT_VERSION = "1"

#: The quantities an audit judges, in report order.
Quantity = Literal["scale", "mass", "density", "inertia", "center_of_mass", "damping", "friction", "stiffness", "limits"]

Verdict = Literal["plausible", "implausible", "not_declared"]


class ValueVerdict(Strict):
    """One declared value against the product's estimate.

    ``where``: ``object``, ``link <name>`` or ``joint <name>``; ``declared`` the value the file gives (None
    when it gives none); ``estimate`` the product's value for it and ``low`` / ``high`` the band a real
    object's value lies in (``docs/guide/audit.md``); ``factor`` declared / estimate (None when either is 0
    or missing); ``verdict`` ``plausible``, ``implausible`` or ``not_declared``; ``reason`` one sentence
    with the numbers; ``patched`` the value the patch writes (None: left as declared)."""

    where: str
    quantity: Quantity
    unit: str
    declared: float | None
    estimate: float | None = None
    low: float | None = None
    high: float | None = None
    factor: float | None = None
    verdict: Verdict
    reason: str = ""
    patched: float | None = None


class SimulationChecks(Strict):
    """The rest, robust-rest and sweep tiers run on one set of physics (``declared`` or ``patched``):
    ``passed`` every tier passed; ``failures`` the names of the failing tiers; ``metrics`` what was measured."""

    physics: Literal["declared", "patched"]
    passed: bool
    failures: list[str] = []
    metrics: list[MetricResult] = []
    error: str = ""
    """Why the checks could not run (then ``passed`` is False and ``metrics`` empty)."""


class AuditReport(Strict):
    """Contents of ``audit.json``: the asset, its format, what the audit read it as, every judged value, the
    simulation checks on the declared and on the patched physics, and the patch written."""

    version: str = AUDIT_VERSION
    asset_id: str
    source: str
    """The input file (URDF, MJCF or USD)."""
    format: Literal["urdf", "mjcf", "usd"]
    category: str
    category_reason: str = ""
    labels: dict[str, str] = {}
    """link -> the part label the audit used (from ``semantics.txt`` or inferred from the link name)."""
    root_fixed: bool
    root_source: str = ""
    values: list[ValueVerdict] = []
    checks: list[SimulationChecks] = []
    patch: str | None = None
    """The patched file, relative to the audit's output folder (None: nothing implausible, or no ``--out``)."""
    notes: list[str] = []

    @property
    def implausible(self) -> list[ValueVerdict]:
        """The values judged implausible."""
        return [v for v in self.values if v.verdict == "implausible"]

    @property
    def failure_mode(self) -> str:
        """``none`` (every value plausible and the declared physics passes its checks), ``implausible_values``,
        ``values_missing`` (no value implausible, but masses or inertias not declared), or
        ``declared_physics_fails`` (plausible values, yet a simulation check fails)."""
        if self.implausible:
            return "implausible_values"
        if any(v.verdict == "not_declared" and v.quantity in ("mass", "inertia") for v in self.values):
            return "values_missing"
        declared = next((c for c in self.checks if c.physics == "declared"), None)
        return "declared_physics_fails" if declared is not None and not declared.passed else "none"


class AuditRow(Strict):
    """One asset's row of the audit catalog (``audit_assets.parquet``): ``failure_mode`` as
    :attr:`AuditReport.failure_mode`, or ``audit_failed`` with ``error`` when the asset could not be audited;
    ``implausible`` ``<where>: <quantity>`` of each implausible value; ``declared_passed`` / ``patched_passed``
    the simulation checks on each physics (None: not run)."""

    asset_id: str
    source: str
    format: str = ""
    category: str = ""
    failure_mode: str
    values: int = 0
    implausible_count: int = 0
    implausible: list[str] = []
    declared_passed: bool | None = None
    declared_failures: list[str] = []
    patched_passed: bool | None = None
    patch: str | None = None
    out_dir: str | None = None
    error: str = ""
    seconds: float = 0.0

    @classmethod
    def of(cls, report: AuditReport, out_dir: str | None, seconds: float) -> "AuditRow":
        """The row of a finished audit."""
        checks = {c.physics: c for c in report.checks}
        declared, patched = checks.get("declared"), checks.get("patched")
        return cls(asset_id=report.asset_id, source=report.source, format=report.format, category=report.category,
                   failure_mode=report.failure_mode, values=len(report.values), implausible_count=len(report.implausible),
                   implausible=[f"{v.where}: {v.quantity}" for v in report.implausible],
                   declared_passed=declared and declared.passed, declared_failures=declared.failures if declared else [],
                   patched_passed=patched and patched.passed,
                   patch=report.patch, out_dir=out_dir, seconds=seconds)
