"""What a model backend must answer (SPEC stage 2): :func:`reply_json_schema` is the schema sent (entries are lists,
as structured-output APIs need fixed properties); :class:`ModelReply` also checks what a JSON schema cannot say. A
reply is a prior: :mod:`asset2sim.tasks.synthesize.llm_estimator` derives the overlay from its choices through the
geometry, the ``direct`` and ``ivw`` baselines apply its estimates. Units as :mod:`asset2sim.schemas.overlay`.
"""

from __future__ import annotations

from typing import Annotated, Any

from pydantic import AfterValidator, BaseModel, ConfigDict, Field, field_validator

from asset2sim.schemas import Strict
from asset2sim.schemas.request import DampingLevel, StateBand

REPLY_SCHEMA_NAME = "asset2sim_overlay_reply"

#: Longest free-text field accepted (characters); longer replies are rejected.
MAX_TEXT = 2000
#: Longest name field accepted (characters).
MAX_NAME = 200


class _Strict(Strict):
    model_config = ConfigDict(allow_inf_nan=False, use_attribute_docstrings=True)


def _short(v: str, limit: int) -> str:
    if len(v) > limit:
        raise ValueError(f"text of {len(v)} characters; at most {limit} allowed")
    return v


_Name = Annotated[str, AfterValidator(lambda v: _short(v, MAX_NAME))]
_Text = Annotated[str, AfterValidator(lambda v: _short(v, MAX_TEXT))]


class Estimate(_Strict):
    """A numeric estimate with its uncertainty: ``value`` and one standard
    deviation ``std`` (> 0), both in the unit of the field that holds it."""

    value: float
    std: float = Field(gt=0.0, le=1e9)


class LinkReply(_Strict):
    """The model's choice for one link."""

    link: _Name
    """Link name exactly as in the description."""
    material: _Name
    """Material note, e.g. ``ABS plastic``, ``painted steel sheet``."""
    density: float = Field(ge=10.0, le=25000.0)
    """kg/m^3 of the material."""
    shell: bool
    """True for a hollow molded / sheet / panel part (mass = area * wall * density)."""
    wall_thickness: float = Field(gt=0.0, le=0.1)
    """m; real-world wall thickness of shell parts (typical smallest section otherwise)."""
    mass: Estimate
    """kg; the model's own estimate of this link's mass at the requested size (mass.value > 0)."""

    @field_validator("mass")
    @classmethod
    def _mass(cls, v: Estimate) -> Estimate:
        if not (0.0 < v.value <= 1e4):
            raise ValueError(f"mass.value {v.value} kg must be in (0, 10000]")
        return v


class JointReply(_Strict):
    """The model's choice for one movable joint."""

    joint: _Name
    """Joint name exactly as in the description."""
    band: StateBand
    """Requested opening band (fraction of the opening range from the closed end)."""
    position: Estimate
    """Initial joint position, rad (revolute) or m (prismatic, output scale)."""
    damping_level: DampingLevel
    holds_position: bool
    """Friction must hold the state against gravity."""
    spring: bool
    """A return spring is intended (stiffness > 0)."""
    stiff: bool
    """A stiff / heavy joint is asked for."""
    free_moving: bool
    """The joint should move freely (low friction)."""
    damping: Estimate
    """N*m*s/rad or N*s/m, value >= 0."""
    friction: Estimate
    """N*m or N, value >= 0."""
    stiffness: Estimate
    """N*m/rad or N/m, value >= 0."""

    @field_validator("damping", "friction", "stiffness")
    @classmethod
    def _non_negative(cls, v: Estimate, info) -> Estimate:
        if not (0.0 <= v.value <= 1e6):
            raise ValueError(f"{info.field_name}.value {v.value} must be in [0, 1e6]")
        return v


class ReplyNotes(_Strict):
    """Reasoning notes (free text; the SPEC's validation notes)."""

    size: _Text
    material: _Text
    mass_arithmetic: _Text


class ModelReply(_Strict):
    """A model's answer for one asset (see the module docstring for units)."""

    category: _Name
    """Object category as the model sees it (e.g. ``Stapler``)."""
    scale: Estimate
    """Uniform scale s (dimensionless, value in [0.001, 1000])."""
    lateral_friction: float = Field(ge=0.0, le=2.0)
    """Coulomb friction coefficient of the object's contacts (dimensionless)."""
    restitution: float = Field(ge=0.0, le=1.0)
    links: list[LinkReply] = Field(max_length=500)
    joints: list[JointReply] = Field(max_length=500)
    notes: ReplyNotes

    @field_validator("scale")
    @classmethod
    def _scale(cls, v: Estimate) -> Estimate:
        if not (1e-3 <= v.value <= 1e3):
            raise ValueError(f"scale.value {v.value} must be in [0.001, 1000]")
        return v


#: JSON-schema keywords OpenAI strict structured outputs and Gemini accept.
_KEEP = {
    "type", "properties", "required", "additionalProperties", "items", "enum", "description",
    "$defs", "$ref", "anyOf", "minimum", "maximum", "exclusiveMinimum", "exclusiveMaximum", "maxItems",
}


def _prune(node: Any) -> Any:
    """``node`` (a JSON schema) anew with only :data:`_KEEP` keywords, every object's properties required and no
    additional properties."""
    if isinstance(node, dict):
        out = {k: {name: _prune(sub) for name, sub in v.items()} if k in ("properties", "$defs") else _prune(v)
               for k, v in node.items() if k in _KEEP}
        if out.get("type") == "object" and "properties" in out:
            out["required"] = list(out["properties"])
            out["additionalProperties"] = False
        return out
    if isinstance(node, list):
        return [_prune(x) for x in node]
    return node


PROPOSAL_SCHEMA_NAME = "asset2sim_joint_proposals"


class JointValue(_Strict):
    """One joint position of a proposed state (rad or m, output units)."""

    name: str = Field(max_length=MAX_NAME)
    value: float


class ProposedState(_Strict):
    """A candidate initial state: positions of some joints (the others stay)."""

    joints: list[JointValue] = Field(max_length=64)
    reason: str = Field("", max_length=MAX_TEXT)


class JointProposalReply(_Strict):
    """A model's answer when the state search stalls: a few candidate states
    that might remove the remaining self-penetration. The simulator accepts a
    candidate only if it lowers the search objective."""

    proposals: list[ProposedState] = Field(max_length=8)


def reply_json_schema(model: type[BaseModel] | None = None) -> dict[str, Any]:
    """The JSON schema of ``model`` (default :class:`ModelReply`) as sent to
    model APIs: every property required, no additional properties, only
    :data:`_KEEP` keywords. A fresh dict."""
    return _prune((model or ModelReply).model_json_schema())

