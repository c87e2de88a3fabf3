"""Real operating forces by part function (canonical part label) and, where a category's data state otherwise,
per category: the table ``asset2sim/priors/operating_forces.yaml`` (a source for every range), read once. Used by
the estimate (how heavy a lid a hand lifts unaided), the operability tier and the operating budgets of the post-check,
and the force check of task execution (``tasks/check/force_ranges.py``).
"""

from __future__ import annotations

import functools

from pydantic import ValidationError, model_validator

from asset2sim.schemas import Frozen
from asset2sim.tasks.interpret.part_labels import canonical_label
from asset2sim.package_data import package_yaml

_FILE = "operating_forces.yaml"


class OperatingForcesError(ValueError):
    """Bad operating-force data; the message names the yaml file and key."""


class ForceRange(Frozen):
    """A part's real operating range: ``force_n`` (lo, hi) N and/or ``torque_nm``
    (lo, hi) N m about the axis; ``sources`` keys of the table's ``sources``."""

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


class OperatingForces(Frozen):
    """The whole table (``operating_forces.yaml``)."""

    sources: dict[str, str]
    default: ForceRange
    parts: dict[str, ForceRange]
    """canonical part label -> its function's range, in any category"""
    categories: dict[str, dict[str, ForceRange]]

    @model_validator(mode="after")
    def _known_sources(self) -> "OperatingForces":
        ranges = [("default", self.default)] + [(f"parts.{l}", r) for l, r in self.parts.items()] + [
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
    return parse_operating_forces(package_yaml("asset2sim.priors", _FILE), _FILE)


def operating_range(category: str | None, label: str | None, table: OperatingForces | None = None
                    ) -> tuple[ForceRange, str]:
    """(range of the part, where from): the category's entry for the label as the asset writes it (``Toilet.pump_lid``:
    a toilet's tank lid, whose label's canonical form names a button elsewhere), else for the canonical ``label``
    (``<category>.<label>``), else the part function's (``<label>``: a lid is judged as a lid in every category), else
    the category's default (``<category>.default``), else ``default`` (ADA 309.4)."""
    t = table or load_operating_forces()
    cat = t.categories.get(category or "") or {}
    raw = "_".join(label.lower().replace("-", " ").split()) if label else None
    if raw and raw in cat:
        return cat[raw], f"{category}.{raw}"
    lab = canonical_label(label)
    if lab and lab in cat:
        return cat[lab], f"{category}.{lab}"
    if lab and lab in t.parts:
        return t.parts[lab], lab
    if "default" in cat:
        return cat["default"], f"{category}.default"
    return t.default, "default"
