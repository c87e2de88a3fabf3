"""Real operating forces per category and part label, and the force
plausibility check of task execution (``operating_force``). The table, with a
source for every range, is ``asset2sim/priors/operating_forces.yaml``.
"""

from __future__ import annotations

import functools
from importlib import resources

import yaml
from pydantic import BaseModel, ConfigDict, ValidationError, model_validator

from asset2sim.schemas.report import MetricResult
from asset2sim.tasks.check.task_execution import TaskRun
from asset2sim.tasks.interpret.part_labels import canonical_label

_FILE = "operating_forces.yaml"


class OperatingForcesError(ValueError):
    """Bad operating-force data; the message names the yaml file and key."""


class ForceRange(BaseModel):
    """A part's real operating range: ``force_n`` (lo, hi) N and/or ``torque_nm``
    (lo, hi) N m about the axis; ``sources`` keys of the table's ``sources``."""

    model_config = ConfigDict(extra="forbid", frozen=True)
    force_n: tuple[float, float] | None = None
    torque_nm: tuple[float, float] | None = None
    sources: tuple[str, ...]
    estimate: bool = False
    note: str = ""

    @model_validator(mode="after")
    def _check(self) -> "ForceRange":
        if self.force_n is None and self.torque_nm is None:
            raise ValueError("a range needs force_n or torque_nm")
        for name in ("force_n", "torque_nm"):
            r = getattr(self, name)
            if r is not None and not (0.0 <= r[0] <= r[1]):
                raise ValueError(f"{name} must be [lo, hi] with 0 <= lo <= hi, got {list(r)}")
        if not self.sources:
            raise ValueError("a range needs at least one source")
        return self


class OperatingForces(BaseModel):
    """The whole table (``operating_forces.yaml``)."""

    model_config = ConfigDict(extra="forbid", frozen=True)
    sources: dict[str, str]
    default: ForceRange
    breakaway: ForceRange
    """pulling a part off its catch at the closed end, from rest (any part)"""
    categories: dict[str, dict[str, ForceRange]]

    @model_validator(mode="after")
    def _known_sources(self) -> "OperatingForces":
        ranges = [("default", self.default), ("breakaway", self.breakaway)] + [
            (f"{c}.{l}", r) for c, d in self.categories.items() for l, r in d.items()]
        for where, r in ranges:
            unknown = [s for s in r.sources if s not in self.sources]
            if unknown:
                raise ValueError(f"{where}: unknown source(s) {unknown}")
        return self


def parse_operating_forces(data: object, where: str = _FILE) -> OperatingForces:
    """Validate a parsed table.

    Raises:
        OperatingForcesError: malformed (names ``where`` and the key).
    """
    try:
        return OperatingForces.model_validate(data)
    except ValidationError as exc:
        raise OperatingForcesError(f"{where}: {exc}") from exc


@functools.lru_cache(maxsize=1)
def load_operating_forces() -> OperatingForces:
    """The packaged table (``asset2sim/priors/operating_forces.yaml``).

    Raises:
        OperatingForcesError: malformed data.
    """
    text = resources.files("asset2sim.priors").joinpath(_FILE).read_text(encoding="utf-8")
    return parse_operating_forces(yaml.load(text, Loader=getattr(yaml, "CSafeLoader", yaml.SafeLoader)), _FILE)  # libyaml when built in


def operating_range(category: str | None, label: str | None, table: OperatingForces | None = None
                    ) -> tuple[ForceRange, str]:
    """(range of the part, where from: ``<category>.<label>``, ``<category>.default`` or ``default``)."""
    t = table or load_operating_forces()
    cat = t.categories.get(category or "")
    lab = canonical_label(label) if label else None
    if cat is not None:
        if lab and lab in cat:
            return cat[lab], f"{category}.{lab}"
        if "default" in cat:
            return cat["default"], f"{category}.default"
    return t.default, "default"


def breakaway_force(table: OperatingForces | None = None) -> float:
    """Top of the breakaway range (N): the most a hand pulls to take a part off its catch, from rest."""
    t = table or load_operating_forces()
    return float(t.breakaway.force_n[1]) if t.breakaway.force_n is not None else 0.0


def _inside(v: float | None, r: tuple[float, float] | None) -> bool | None:
    if r is None or v is None:
        return None
    return bool(r[0] <= v <= r[1])


def force_metric(run: TaskRun, category: str | None, link_labels: dict[str, str | None],
                 table: OperatingForces | None = None) -> MetricResult:
    """``operating_force``: the peak operating force (N) and torque (N m) of
    every attempt that moved a joint, against :func:`operating_range` of the
    category and the grasped child link's label (``link_labels``: link ->
    semantic label; a parent-side grasp takes the category's default). Value:
    the largest peak operating force; ``passed`` None when nothing moved.
    """
    t = table or load_operating_forces()
    rows = []
    bad = []
    for a in run.attempts:
        if not a.moved:
            continue
        label = link_labels.get(a.link) if a.side == "child" else None
        r, where = operating_range(category, label, t)
        f_ok = _inside(a.peak_operating_force_n, r.force_n)
        tau = a.peak_torque_nm
        t_ok = _inside(tau, r.torque_nm)
        ok = f_ok is not False and t_ok is not False
        row = {"joint": a.joint, "action": a.action, "peak_operating_force_n": a.peak_operating_force_n,
               "peak_gripper_force_n": a.peak_force_n, "peak_torque_nm": tau,
               "force_range_n": list(r.force_n) if r.force_n else None,
               "torque_range_nm": list(r.torque_nm) if r.torque_nm else None,
               "range_of": where, "sources": [t.sources[s] for s in r.sources], "estimate": r.estimate, "passed": ok}
        rows.append(row)
        if not ok:
            what = []
            if f_ok is False:
                what.append(f"force {a.peak_operating_force_n:.1f} N outside {r.force_n[0]:g}-{r.force_n[1]:g} N")
            if t_ok is False:
                what.append(f"torque {tau:.2f} N m outside {r.torque_nm[0]:g}-{r.torque_nm[1]:g} N m")
            bad.append(f"{a.joint} {a.action}: {', '.join(what)} ({where})")
    return MetricResult(
        name="operating_force", value=max((r["peak_operating_force_n"] for r in rows), default=None), unit="N",
        passed=(not bad) if rows else None,
        threshold="the task's peak operating force (and torque about the axis) inside the real operating range of the "
                  "category and part (asset2sim/priors/operating_forces.yaml)",
        details={"attempts": rows, "failures": bad, "category": category}, engine=run.engine)
