"""The physics overlay: the only thing an estimator may produce (SPEC, stage 2).

Values refer to the *output* asset (scale baked in), SI and radians: mass kg,
inertia kg*m^2 about the COM in link axes, COM m in the link frame; revolute
damping N*m*s/rad, friction N*m, stiffness N*m/rad; prismatic N*s/m, N, N/m;
joint positions rad or m.
"""

from __future__ import annotations

from typing import Any, Literal

import numpy as np
from pydantic import ConfigDict, Field, model_validator

from asset2sim.schemas import Strict

SCHEMA_VERSION = "1.0"

Vec3 = tuple[float, float, float]


#: The overlay's uniform scale must lie in this range (``OVL_SCALE_INVALID``;
#: the input validator's ``ASSET_SIZE_IMPLAUSIBLE`` bound derives from it).
SCALE_RANGE: tuple[float, float] = (1e-4, 1e4)


class _Strict(Strict):
    model_config = ConfigDict(allow_inf_nan=False)


class Inertia(_Strict):
    """Inertia tensor (kg*m^2) as the six URDF values, about the COM."""

    ixx: float
    ixy: float = 0.0
    ixz: float = 0.0
    iyy: float
    iyz: float = 0.0
    izz: float

    def matrix(self) -> np.ndarray:
        """The tensor as a (3, 3) float array."""
        return np.array([[self.ixx, self.ixy, self.ixz], [self.ixy, self.iyy, self.iyz], [self.ixz, self.iyz, self.izz]], dtype=float)

    @classmethod
    def from_matrix(cls, m: np.ndarray) -> "Inertia":
        """Build from a (3, 3) array; the upper triangle is used (symmetrized)."""
        m = np.asarray(m, dtype=float)
        s = 0.5 * (m + m.T)
        return cls(ixx=float(s[0, 0]), ixy=float(s[0, 1]), ixz=float(s[0, 2]), iyy=float(s[1, 1]), iyz=float(s[1, 2]),
                   izz=float(s[2, 2]))


class ContactMaterial(_Strict):
    """Optional contact material: Coulomb friction coefficient (dimensionless)
    and restitution (dimensionless, 0..1)."""

    lateral_friction: float = Field(ge=0.0)
    restitution: float = Field(0.0, ge=0.0, le=1.0)
    note: str = ""


class LinkPhysics(_Strict):
    """Physical properties of one link of the output asset."""

    mass: float
    """kg"""
    inertia: Inertia
    """kg*m^2 about the COM, link-frame axes."""
    com: Vec3
    """m, in the link frame of the output (scaled) asset."""
    material: str = ""
    """Material note, e.g. ``ABS plastic`` or ``steel sheet``."""
    density: float | None = None
    """kg/m^3 of the material, when mass came from geometry."""
    hollow_fraction: float | None = None
    """eta in m = v * rho * s^3 * eta (1 = solid)."""
    source: str = ""
    """Where the values came from: ``geometry``, ``estimator``, ``default`` ..."""


class Holding(_Strict):
    """What holds a part where it was left, and the loads it was sized to (``tasks/synthesize/estimate.py``; N m for a
    revolute joint, N for a prismatic one): the hold margin of the output is its friction over ``static_load``."""

    mechanism: str
    """"friction hinge", "free hinge", "wood runners slides", "lid support", "counterbalance spring", "closer",
    "return spring", "balance", "moves freely (asked)" ..."""
    static_load: float = 0.0
    """the largest load friction holds: the gravity load around the state, the set-down's 5 deg lean (less what a spring
    carries), N m or N"""
    landing: float = 0.0
    """friction beyond the holding friction that stops the part within its band after the object lands, N m or N"""
    landing_trial: str = ""
    """the set-down trial whose landing needs the most ("drop", "tilt+y" ...)"""


#: Keys of a catch at a joint's closed end in overlays before 0.2.0 (:meth:`JointDynamics._drop_catches`).
LEGACY_CATCH_KEYS = ("catch_force", "catch_position", "catch_zone")


class JointDynamics(_Strict):
    """Passive dynamics of one non-fixed joint (units: see module docstring)."""

    damping: float
    friction: float
    stiffness: float = 0.0
    spring_reference: float | None = None
    """Rest position q_s of the spring (rad or m); required when stiffness > 0."""
    inertia_axis: float | None = None
    """Inertia of the moving subtree about / along the axis (kg*m^2 or kg), when
    known: bounds the damping a simulator integrates stably (c <= I / dt)."""
    lower: float | None = None
    """Clipped lower limit (rad or m, output scale) when the raw one lets the
    part pass into other links (``tasks.geometry.limits``); None: raw limit kept."""
    upper: float | None = None
    """Clipped upper limit (rad or m at the output scale); None: raw limit kept."""
    limit_source: str = ""
    """Why and by how much the limit was clipped (empty when not clipped)."""
    holding: Holding | None = None
    """What holds the part where it was left and the loads it was sized to; None where no estimate says."""
    source: str = ""

    @model_validator(mode="before")
    @classmethod
    def _drop_catches(cls, data: Any) -> Any:
        """Overlays written before 0.2.0 may carry a catch (``catch_force``, ``catch_position``, ``catch_zone``): no
        output format carries one, so no check applied it since; it is dropped on reading."""
        if isinstance(data, dict) and any(k in data for k in LEGACY_CATCH_KEYS):
            data = {k: v for k, v in data.items() if k not in LEGACY_CATCH_KEYS}
        return data


class EstimatorInfo(_Strict):
    """Which estimator produced the overlay."""

    name: str
    model: str | None = None
    version: str = ""
    queries: int = 0
    """Number of model calls made for this overlay (0 for offline)."""
    tokens: int = 0
    """Total tokens (prompt + completion) reported by the API, 0 when unknown."""
    cost_usd: float | None = None
    """Cost in US dollars when the provider library knows it."""
    seconds: float = 0.0
    """Wall time spent in model calls, s."""


class ValidationNotes(_Strict):
    """Reasoning notes required by the SPEC (free text)."""

    size: str = ""
    material: str = ""
    mass_arithmetic: str = ""
    units: str = "SI units; angles in radians; prismatic values in metres after scaling."
    other: list[str] = []


MountingKind = Literal["free-standing", "counter-mounted", "wall-mounted", "floor-mounted", "hangs-in-frame"]


class RootMount(_Strict):
    """How the asset is held (``tasks.interpret.mounting``): ``fixed`` root in
    every simulation, else free on the ground; ``source`` what decided it."""

    kind: MountingKind = "free-standing"
    fixed: bool = False
    source: str = ""


class Overlay(_Strict):
    """The full physics overlay of one asset."""

    schema_version: str = SCHEMA_VERSION
    estimator: EstimatorInfo
    scale: float
    """Uniform scale factor s applied to the input asset (dimensionless)."""
    category: str | None = None
    contact_material: ContactMaterial | None = None
    links: dict[str, LinkPhysics] = {}
    joints: dict[str, JointDynamics] = {}
    initial_joint_positions: dict[str, float] | None = None
    """Only when the request asks for a state (output units: rad or m)."""
    notes: ValidationNotes = ValidationNotes()
    mounting: RootMount | None = None
    """How the root is held (None: free-standing, the SPEC's convention)."""

    def total_mass(self) -> float:
        """Sum of link masses, kg."""
        return float(sum(lp.mass for lp in self.links.values()))


Severity = Literal["error", "warning", "info"]


class ValidationIssue(_Strict):
    """One finding of a validator: stable ``code``, ``where`` (link, joint or
    ``global``), ``severity`` (the default a policy may override)."""

    code: str
    severity: Severity
    where: str
    message: str
    fixed: bool = False
    """True when the validator replaced the offending value (see ``message``)."""
