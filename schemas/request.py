"""A natural-language request, parsed into what the estimator needs.

Produced by :func:`asset2sim.tasks.interpret.request.parse_request`. Nothing here is
object-specific: size words, state words, dynamics words and per-joint phrases.
"""

from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, ConfigDict, Field

SizeClass = Literal["tiny", "very_small", "small", "regular", "large", "very_large"]
StateBand = Literal["closed", "slightly_open", "quarter", "halfway", "mostly", "fully"]
DampingLevel = Literal["low", "moderate", "high"]

#: Target opening fraction per band: |q - q_closed| / (largest opening from q_closed).
#: "slightly open" aims low in its band (a slightly open stapler or laptop is a
#: few tens of degrees open, not a third of a 200-degree range).
BAND_TARGET: dict[str, float] = {
    "closed": 0.0,
    "slightly_open": 0.12,
    "quarter": 0.25,
    "halfway": 0.5,
    "mostly": 0.75,
    "fully": 1.0,
}

#: Acceptance interval per band (fractions of the opening range), from the
#: refine issue's definition of "lands in its band".
BAND_INTERVAL: dict[str, tuple[float, float]] = {
    "closed": (0.0, 0.03),
    "slightly_open": (0.05, 0.35),
    "quarter": (0.15, 0.35),
    "halfway": (0.35, 0.65),
    "mostly": (0.6, 0.9),
    "fully": (0.85, 1.0),
}


TargetKind = Literal["fraction", "angle", "distance", "end"]
EndName = Literal["high", "low", "on", "off"]
Dimension = Literal["height", "width", "depth", "length", "largest"]
OrderAxis = Literal["vertical", "left_right", "right_left", "front_back"]


class StateTarget(BaseModel):
    """A state asked for in numbers or by a physical end, resolved against the
    geometry after scaling (:mod:`asset2sim.tasks.synthesize.request_apply`).

    ``kind``: ``fraction`` (``value`` opening fraction 0..1 from the geometric
    closed end), ``angle`` (``value`` rad from the closed end), ``distance``
    (``value`` m from the closed end, at the output's scale) or ``end``
    (``end``: ``high``/``low`` = the highest/lowest world-z position of the
    moving part over its travel after scaling and the resting pose; ``on``/
    ``off`` = a toggle switch's high/low end, see ``docs/requests.md``).
    """

    model_config = ConfigDict(extra="forbid")
    kind: TargetKind
    value: float | None = None
    end: EndName | None = None


class SizeTarget(BaseModel):
    """A size in numbers: ``value`` m along ``dimension`` (height = world z of
    the closed object; width/depth = larger/smaller horizontal extent; length or
    largest = the largest extent)."""

    model_config = ConfigDict(extra="forbid")
    dimension: Dimension
    value: float = Field(gt=0.0)
    phrase: str = ""


class PartProperty(BaseModel):
    """A mass (kg) or material (``materials.yaml`` key) asked for the whole
    object (``label`` None), its body (``label`` "body") or a named part."""

    model_config = ConfigDict(extra="forbid")
    label: str | None = None
    mass: float | None = None
    material: str | None = None
    phrase: str = ""


class DynamicsValue(BaseModel):
    """An explicit joint parameter: ``quantity`` damping (N*m*s/rad or N*s/m),
    friction (N*m or N) or stiffness (N*m/rad or N/m); ``motion`` says which
    joints the unit fits (``rotational``, ``linear`` or ``any`` when no unit
    was given); ``label`` the part named, None for the task-relevant joints."""

    model_config = ConfigDict(extra="forbid")
    quantity: Literal["damping", "friction", "stiffness"]
    value: float = Field(ge=0.0)
    motion: Literal["rotational", "linear", "any"] = "any"
    label: str | None = None
    phrase: str = ""


class JointStateRequest(BaseModel):
    """The state asked for one joint or a group of joints.

    ``selector`` says which joints: ``all`` (every task-relevant joint),
    ``label`` (joints whose moving link has semantic label ``label``, e.g.
    ``drawer``/``lid``/``door``), optionally narrowed by ``ordinal`` (0-based
    index among those joints, ordered top-to-bottom / front-to-back as the
    refine stage defines).
    """

    model_config = ConfigDict(extra="forbid")
    selector: Literal["all", "label"] = "all"
    label: str | None = None
    ordinal: int | None = None
    band: StateBand
    """The band asked for; for a ``target`` the nominal band until the geometry
    resolves it (the nearest band of a fraction; ``fully``/``closed`` for a
    high/low end)."""
    target: StateTarget | None = None
    """A number or a physical end ("30 degrees", "lever up"); wins over ``band``."""
    order: OrderAxis = "vertical"
    """How ``ordinal`` counts: top to bottom (default), left to right, right to
    left or front to back, as seen by a viewer facing the object's front."""
    phrase: str = ""
    """The words of the request this came from."""


class RequestSpec(BaseModel):
    """What a request asks for."""

    model_config = ConfigDict(extra="forbid")
    text: str = ""
    category_hint: str | None = None
    """Category named by the request (e.g. ``Stapler``), if any."""
    size_class: SizeClass | None = None
    size_factor: float = 1.0
    """Multiplier on the category's typical size implied by the size words."""
    size_phrase: str = ""
    joint_states: list[JointStateRequest] = Field(default_factory=list)
    damping: DampingLevel = "moderate"
    holds_position: bool = False
    """"holds its position": friction must hold the requested state against gravity."""
    spring: bool = False
    """A spring is asked for (stiffness > 0)."""
    stiff: bool = False
    """"stiff"/"heavy" joints asked for (higher friction / damping)."""
    free_moving: bool = False
    """"moving freely": low friction."""
    pose_hint: Literal["upright", "lying_flat", "sideways"] | None = None
    sizes: list[SizeTarget] = Field(default_factory=list)
    """Sizes in numbers ("30 cm tall"); they win over the size words."""
    mass_level: Literal["light", "heavy"] | None = None
    """"a heavy box": the upper (lower) end of the plausible mass range."""
    properties: list[PartProperty] = Field(default_factory=list)
    """Masses and materials, whole object or per part."""
    dynamics_values: list[DynamicsValue] = Field(default_factory=list)
    """Explicit damping / friction / stiffness values."""
    ignored: list[str] = Field(default_factory=list)
    """Groups of consecutive words no rule used (function words aside)."""
    part_counts: dict[str, int] = Field(default_factory=dict)
    """Counts of parts named ("a two-drawer cabinet" -> {"drawer": 2}); a
    different count on the object is a warning."""
    warnings: list[str] = Field(default_factory=list)
    """Contradictions and numbers the parser could not use."""
    matched: list[str] = Field(default_factory=list)
    """Every phrase the parser recognised (for the report)."""
    unused_words: list[str] = Field(default_factory=list)
    """Words of the request that no rule used (common function words, part
    labels and category names excepted), in order, each once: nothing is
    silently ignored; the report lists them."""

    @property
    def understood(self) -> bool:
        """False for a non-empty request of which no word was recognised
        (e.g. one in a language other than English): refine then uses the
        category's defaults and says so."""
        return bool(self.matched) or not self.text.strip()


class QuantityOutcome(BaseModel):
    """A number the request asked and what the output has (same unit)."""

    model_config = ConfigDict(extra="forbid")
    what: str
    """e.g. ``joint_0 angle``, ``height``, ``total mass``."""
    phrase: str = ""
    asked: float | None = None
    achieved: float | None = None
    unit: str = ""
    within_tolerance: bool = True
    why: str = ""
    """How the target was decided; why it was missed (a limit, the geometry)."""


class RequestFindings(BaseModel):
    """The report's account of the request (``report.json`` ``request``):
    word groups no rule used, warnings (contradictions, parts the object lacks,
    numbers beyond a limit), what was asked beyond bands and every number with
    what the output achieved."""

    model_config = ConfigDict(extra="forbid")
    ignored: list[str] = Field(default_factory=list)
    warnings: list[str] = Field(default_factory=list)
    asked: list[str] = Field(default_factory=list)
    quantities: list[QuantityOutcome] = Field(default_factory=list)
