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
