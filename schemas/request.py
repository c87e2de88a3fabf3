"""A natural-language request parsed into what the estimator needs (:func:`asset2sim.tasks.interpret.request.parse_request`):
size, state and dynamics words and per-joint phrases, nothing object-specific; the overrides that win over them.
"""

from __future__ import annotations

import math
import re
from typing import Literal

from pydantic import ConfigDict, Field, field_validator

from asset2sim.schemas import Frozen, Strict

SizeClass = Literal["tiny", "very_small", "small", "regular", "large", "very_large"]
StateBand = Literal["closed", "slightly_open", "quarter", "halfway", "mostly", "fully"]
DampingLevel = Literal["low", "moderate", "high"]

#: Target opening fraction per band: |q - q_closed| / (largest opening from q_closed) (docs/design/requests.md).
BAND_TARGET: dict[str, float] = {"closed": 0.0, "slightly_open": 0.12, "quarter": 0.25, "halfway": 0.5, "mostly": 0.75, "fully": 1.0}

#: Acceptance interval per band (fractions of the opening range): what
#: "lands in its band" means.
BAND_INTERVAL: dict[str, tuple[float, float]] = {
    "closed": (0.0, 0.03), "slightly_open": (0.05, 0.35), "quarter": (0.15, 0.35), "halfway": (0.35, 0.65),
    "mostly": (0.6, 0.9), "fully": (0.85, 1.0),
}


TargetKind = Literal["fraction", "angle", "distance", "end"]
EndName = Literal["high", "low", "on", "off"]
Dimension = Literal["height", "width", "depth", "length", "largest", "volume"]
OrderAxis = Literal["vertical", "left_right", "right_left", "front_back", "middle", "size"]
#: The words of the first and the last part along each order, seen facing the object's front.
ORDER_ENDS: dict[str, tuple[str, str]] = {"vertical": ("highest", "lowest"), "left_right": ("leftmost", "rightmost"),
                                          "right_left": ("rightmost", "leftmost"), "front_back": ("frontmost", "backmost"),
                                          "size": ("smallest", "largest")}
#: How each order counts, for a part named by its number ("the 2nd door from the top").
ORDER_FROM: dict[str, str] = {"vertical": "from the top", "left_right": "from the left", "right_left": "from the right",
                              "front_back": "from the front", "size": "by size, smallest first"}


def ordinal_words(ordinal: int, order: str, label: str | None) -> str:
    """A part named by its place among its kind, in words: ``the largest door`` (``ordinal`` -1, ``order`` size),
    ``the highest drawer`` (0, vertical), ``the middle drawer``, ``the 2nd door from the left`` (1, left_right),
    ``the 2nd door from the end, from the top`` (-2); ``label`` None: ``part``."""
    what = label or "part"
    if order == "middle":
        return f"the middle {what}"
    first, last = ORDER_ENDS.get(order, ("first", "last"))
    if ordinal == 0:
        return f"the {first} {what}"
    if ordinal == -1:
        return f"the {last} {what}"
    n = abs(ordinal) + (1 if ordinal >= 0 else 0)
    suffix = "th" if 10 <= n % 100 <= 20 else {1: "st", 2: "nd", 3: "rd"}.get(n % 10, "th")
    return f"the {n}{suffix} {what} " + (ORDER_FROM.get(order, "") if ordinal >= 0 else f"from the end, {ORDER_FROM.get(order, '')}")
"""How an ordinal counts, facing the object's front: top to bottom, left to right, right to left, front to back;
``middle`` the middle one of an odd count along the direction the parts are spread in (ordinal 0); ``size`` by the
moving part's box volume, smallest first ("the freezer door" 0, "the main door" -1)."""


class StateTarget(Strict):
    """A state in numbers or by a physical end, resolved against the scaled
    geometry: ``kind`` ``fraction`` (``value`` 0..1 from the closed end),
    ``angle`` (rad), ``distance`` (m, output scale) or ``end`` (``high`` /
    ``low`` world z of the moving part, ``on`` / ``off`` a toggle's ends)."""

    kind: TargetKind
    value: float | None = None
    end: EndName | None = None


class SizeTarget(Strict):
    """A size in numbers: ``value`` m along ``dimension`` (height: world z of
    the closed object; width / depth: larger / smaller horizontal extent), or
    for ``volume`` m^3, a container's volume ("a 500 ml bottle") compared with
    the closed object's convex-hull volume."""

    dimension: Dimension
    value: float = Field(gt=0.0)
    phrase: str = ""


class PartProperty(Strict):
    """A mass (kg) or material (``materials.yaml`` key) asked for the whole
    object (``label`` None), its body (``label`` "body") or a named part."""

    label: str | None = None
    mass: float | None = None
    mass_range: tuple[float, float] | None = None
    """A range of masses asked (kg, low <= high: "between 20 and 30 kg"): the estimate is kept inside it, brought to
    its nearer end when outside; ``mass`` is then None."""
    material: str | None = None
    phrase: str = ""


class DynamicsValue(Strict):
    """An explicit joint damping, friction or stiffness (SI units of the joint
    type); ``motion`` the joints its unit fits; ``label`` the part (None: the
    task-relevant joints)."""

    quantity: Literal["damping", "friction", "stiffness"]
    value: float = Field(ge=0.0)
    motion: Literal["rotational", "linear", "any"] = "any"
    label: str | None = None
    phrase: str = ""


MotionKind = Literal["free", "stiff", "hold", "spring", "self_closing", "soft_close", "low_damping", "high_damping",
                     "moderate_damping", "slides"]

#: What each word about a part's motion asks of its joint (``tasks/synthesize/estimate.py`` applies it, with its
#: source; ``tasks/tune/word_guard.py`` keeps every later step from moving the joint against it): the parameters it
#: sets and whether no later step may raise (``"max"``) or lower (``"min"``) each.
MOTION_GUARDS: dict[str, dict[str, str]] = {
    "free": {"friction": "max", "damping": "max"},
    "low_damping": {"damping": "max"},
    "stiff": {"friction": "min", "damping": "min"},
    "hold": {"friction": "min"},
    "high_damping": {"damping": "min"},
    "soft_close": {"damping": "min"},
    "spring": {"stiffness": "min"},
    # a closer shuts its part against friction of at most a share of its preload (spring_holds.closer): friction
    # raised past that to hold the part open would keep it from shutting, the one thing the word asks
    "self_closing": {"stiffness": "min", "friction": "max"},
    "moderate_damping": {},
    "slides": {},  # the slide's own friction range bounds it (``asset2sim/priors/slides.yaml``)
}


class MotionPhrase(Strict):
    """A word about how a part moves ("the door swings freely", "a stiff handle joint", "the lid stays where it is
    put", "a self-closing door"): ``kind`` (:data:`MOTION_GUARDS`), ``label`` the part it names (None: the parts the
    object's task acts on) and ``phrase`` the request's words."""

    kind: MotionKind
    label: str | None = None
    phrase: str = ""
    mechanism: str | None = None
    """for ``slides``: the kind of slide named (a key of ``asset2sim/priors/slides.yaml``: ``ball_bearing``, ``roller``,
    ``lubricated``, ``wood_runners``)"""
    ordinal: int | None = None
    """one of the parts ``label`` names, by its place (0-based, in ``order``; negative from the end): "the main door
    has a stiff hinge" names the largest door only; None: every part the label names"""
    order: OrderAxis = "vertical"
    """How ``ordinal`` counts, as a state's (:class:`JointStateRequest`)."""

    def short(self) -> str:
        """``'swings freely' (door): free``, ``'stiff' (the largest door): stiff`` for the report's and the summary's
        lines."""
        what = self.kind.replace("_", " ") if self.mechanism is None else f"slides: {self.mechanism.replace('_', ' ')}"
        part = ordinal_words(self.ordinal, self.order, self.label) if self.ordinal is not None else self.label
        return f"'{self.phrase}'" + (f" ({part})" if part else "") + f": {what}"


class JointStateRequest(Strict):
    """The state asked for one joint or a group: ``selector`` ``all`` (the
    task-relevant joints), ``joint`` (named ``joint``) or ``label`` (moving
    links labelled ``label``), narrowed by ``ordinal`` (0-based, in ``order``)."""

    selector: Literal["all", "label", "joint"] = "all"
    label: str | None = None
    joint: str | None = None
    """The joint's name when ``selector`` is ``joint`` (an override names joints)."""
    ordinal: int | None = None
    band: StateBand
    """The band asked for (for a ``target``: nominal until the geometry resolves it)."""
    target: StateTarget | None = None
    """A number or a physical end ("30 degrees", "lever up"); wins over ``band``."""
    order: OrderAxis = "vertical"
    """How ``ordinal`` counts, seen facing the object's front."""
    phrase: str = ""
    """The words of the request this came from."""
    bare: bool = False
    """A lone "open" that says no more than open (``mostly``): how far is the part's own, and a part its weight
    carries open, a drop-down door, is open resting on its open stop (``request_apply``)."""

    def short(self) -> str:
        """The request in a few symbols, for tests and logs (:meth:`words` says it for people): who (label, joint or
        "all", "#n" an ordinal, "@order" when not top to bottom) and what: a number as asked from the closed end
        ("lid=30 deg from closed", "drawer=20 mm from closed", "door=40 %"), an end ("lever=up"), else the band
        ("door=halfway")."""
        who = (self.joint if self.selector == "joint" else self.label) or "all"
        if self.ordinal is not None:
            who += f"#{self.ordinal}" + ("" if self.order == "vertical" else f"@{self.order}")
        return f"{who}={self._what()}"

    def words(self) -> str:
        """The request for people, as the progress lines say it: ``the largest door halfway``, ``lid 30 deg from
        closed``, ``every task-relevant part closed`` (a part named by its place in words, :func:`ordinal_words`)."""
        who = (self.joint if self.selector == "joint" else self.label) or "every task-relevant part"
        if self.ordinal is not None:
            who = ordinal_words(self.ordinal, self.order, self.label)
        return f"{who} {self._what().replace('_', ' ')}"

    def _what(self) -> str:
        t = self.target
        if t is None:
            return self.band
        if t.kind == "end":
            return {"high": "up", "low": "down"}.get(str(t.end), str(t.end))
        if t.kind == "angle":
            return f"{math.degrees(float(t.value or 0.0)):.4g} deg from closed"
        if t.kind == "distance":
            return f"{1000.0 * float(t.value or 0.0):.4g} mm from closed"
        return f"{100.0 * float(t.value or 0.0):.4g} %"

    @property
    def names_part(self) -> bool:
        """Whether this names a part (a label) or a joint, not the object as a whole ("half open")."""
        return self.selector == "joint" or (self.selector != "all" and bool(self.label))


class RequestSpec(Strict):
    """What a request asks for."""

    text: str = ""
    category_hint: str | None = None
    """Category named by the request (e.g. ``Stapler``), if any."""
    size_class: SizeClass | None = None
    size_factor: float = 1.0
    """Multiplier on the category's typical size implied by the size words."""
    size_phrase: str = ""
    joint_states: list[JointStateRequest] = []
    damping: DampingLevel = "moderate"
    holds_position: bool = False
    """"holds its position": friction must hold the requested state against gravity."""
    spring: bool = False
    """A spring is asked for (stiffness > 0)."""
    stiff: bool = False
    """"stiff"/"heavy" joints asked for (higher friction / damping)."""
    free_moving: bool = False
    """"moving freely": low friction."""
    motions: list[MotionPhrase] = []
    """The words about how parts move, each with the part it names (None: the task's parts), in the request's order;
    ``damping``, ``holds_position``, ``spring``, ``stiff`` and ``free_moving`` summarise them for the whole object."""
    pose_hint: Literal["upright", "lying_flat", "sideways"] | None = None
    sizes: list[SizeTarget] = []
    """Sizes in numbers ("30 cm tall"); they win over the size words."""
    mass_level: Literal["light", "heavy"] | None = None
    """"a heavy box": the upper (lower) end of the plausible mass range."""
    properties: list[PartProperty] = []
    """Masses and materials, whole object or per part."""
    dynamics_values: list[DynamicsValue] = []
    """Explicit damping / friction / stiffness values."""
    ignored: list[str] = []
    """Groups of consecutive words no rule used (function words aside)."""
    part_counts: dict[str, int] = {}
    """Counts of parts named ("a two-drawer cabinet" -> {"drawer": 2}); a
    different count on the object is a warning."""
    warnings: list[str] = []
    """Contradictions and numbers the parser could not use."""
    overridden: list[str] = []
    """Phrases of joint states a later phrase for the same part replaced ("the door open 90 degrees and the door
    closed": the first), each once: asked and not applied (the as-asked verdict, ``tasks/check/as_asked.py``)."""
    matched: list[str] = []
    """Every phrase the parser recognised (for the report)."""
    mount: Literal["fixed", "free"] | None = None
    """The mounting an override gives (wins over the words and the category prior)."""
    scale: float | None = Field(None, gt=0.0)
    """The uniform scale an override gives (wins over sizes and size words)."""
    overrides: list[str] = []
    """The overrides as the user gave them (``--mass 12 kg`` ...), for the report."""
    unused_words: list[str] = []
    """Words of the request no rule used (function words, part labels and
    category names excepted), in order, each once."""
    parser: Literal["offline", "model"] = "offline"
    """Which parse the intent fields come from: the offline parser's, or a model's (``--request-parser model``)."""
    parse_note: str = ""
    """Why that parse was used ("" for the offline parser by default): the model's parse was valid, or why the
    offline parse was kept (no model backend, the call failed, the reply did not validate)."""

    @property
    def understood(self) -> bool:
        """False for a non-empty request of which no word was recognised."""
        return bool(self.matched) or not self.text.strip()


class PartCount(Strict):
    """A count of parts the request names ("a two-drawer cabinet": ``label`` drawer, ``count`` 2)."""

    label: str = Field(min_length=1, max_length=64)
    count: int = Field(ge=1, le=64)


# The docstring below is this schema's description, sent to models verbatim with every request parse: it
# stays word for word (the module it names is now tasks/interpret/reading.py), or every request changes and
# every cached parse is asked again.
class RequestIntent(Strict):
    """The typed intent of a request: per part the reference (label, ordinal and order), the state (band), the
    amount and its unit (``target``: a fraction, an angle in rad, a distance in m or an end) and the source words
    (``phrase``); the object's size (class and numbers in m or m^3), pose, mass (kg), materials, dynamics and
    mounting. The same fields, with the same types, as :class:`RequestSpec` (:data:`INTENT_FIELDS`;
    ``part_counts`` as a list); a model's parse is validated into it (``tasks/synthesize/llm_request.py``)."""

    category_hint: str | None = None
    """The object's category named by the request (e.g. ``Stapler``, ``Refrigerator``), or null."""
    size_class: SizeClass | None = None
    """The size words' class, or null when none is said."""
    joint_states: list[JointStateRequest] = Field([], max_length=64)
    """One entry per part state asked, in the request's order."""
    sizes: list[SizeTarget] = Field([], max_length=16)
    pose_hint: Literal["upright", "lying_flat", "sideways"] | None = None
    mass_level: Literal["light", "heavy"] | None = None
    properties: list[PartProperty] = Field([], max_length=64)
    dynamics_values: list[DynamicsValue] = Field([], max_length=64)
    damping: DampingLevel = "moderate"
    holds_position: bool = False
    spring: bool = False
    stiff: bool = False
    free_moving: bool = False
    motions: list[MotionPhrase] = Field([], max_length=64)
    """One entry per word about how a part moves, with the part it names (null: the task's parts)."""
    part_counts: list[PartCount] = Field([], max_length=64)
    mount: Literal["fixed", "free"] | None = None
    """The mounting asked ("mounted on the wall": fixed; "free-standing": free), or null."""

    @classmethod
    def of(cls, spec: "RequestSpec") -> "RequestIntent":
        """The intent of a parsed request (``part_counts`` sorted by label)."""
        data = {k: getattr(spec, k) for k in INTENT_FIELDS}
        data["part_counts"] = [PartCount(label=k, count=v) for k, v in sorted(spec.part_counts.items())]
        return cls.model_validate(data).model_copy(deep=True)

    def fields(self) -> dict[str, object]:
        """The intent as :class:`RequestSpec` field values (``part_counts`` a dict; copies of the nested models)."""
        out = {k: [x.model_copy(deep=True) for x in v] if isinstance(v := getattr(self, k), list) else v for k in INTENT_FIELDS}
        out["part_counts"] = {c.label: c.count for c in self.part_counts}
        return out


#: The fields of :class:`RequestSpec` that say what is asked (the typed intent); the others are the parse's account
#: of the text (the words used and unused, warnings, phrases replaced) and the overrides.
INTENT_FIELDS = tuple(RequestIntent.model_fields)


class QuantityOutcome(Strict):
    """A number the request asked and what the output has (same unit)."""

    what: str
    """e.g. ``joint_0 angle``, ``height``, ``total mass``."""
    phrase: str = ""
    asked: float | None = None
    achieved: float | None = None
    unit: str = ""
    within_tolerance: bool = True
    why: str = ""
    """How the target was decided; why it was missed (a limit, the geometry)."""
    asked_high: float | None = None
    """The upper end when a range was asked (``asked`` its lower end): met anywhere inside it."""
    kind: Literal["state", "size", "mass", "dynamics", ""] = ""
    """What was asked: a joint ``state`` (an angle, a distance or a fraction from the closed end, or an end), a
    ``size``, the total ``mass``, a joint's ``dynamics`` value; "" in reports written before it was recorded."""


class RequestFindings(Strict):
    """The report's account of the request: unused word groups, warnings,
    what was asked beyond bands and every number with what was achieved."""

    ignored: list[str] = []
    warnings: list[str] = []
    asked: list[str] = []
    quantities: list[QuantityOutcome] = []
    phrases: list[str] = []
    """Each state phrase of the request with the parts it set (joint and label), the amount set from the closed
    end and the amount asked, or why it was not applied, in the request's order."""


#: Units an override may carry -> factor to SI (kg, m, rad).
MASS_UNITS = {"kg": 1.0, "g": 1e-3}
LENGTH_UNITS = {"m": 1.0, "cm": 1e-2, "mm": 1e-3}
ANGLE_UNITS = {"deg": math.pi / 180.0, "rad": 1.0}
_QUANTITY = re.compile(r"^\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)\s*([a-zA-Z°]*)\s*$")


#: The SI range in which a size (m) or a mass (kg) of an articulated household object lies (a 1 cm stapler button to a
#: 10 m garage door; a 10 g lid to a 1 t machine): the units a number without one is suggested with.
PLAUSIBLE_SI = {"size": (0.01, 10.0), "mass": (0.01, 1000.0)}


def unit_suggestion(number: str, units: dict[str, float], what: str) -> str:
    """``30cm (0.3 m) or 30mm (0.03 m)``: ``number`` with each of ``units`` that puts it in :data:`PLAUSIBLE_SI`
    for ``what`` (every unit when none does, or ``what`` has no range), with its SI value."""
    si = "kg" if units is MASS_UNITS else "m" if units is LENGTH_UNITS else next(iter(units))
    lo, hi = PLAUSIBLE_SI.get(what, (0.0, math.inf))
    fits = [u for u, f in units.items() if lo <= float(number) * f <= hi] or list(units)
    return " or ".join(f"{number}{u}" + ("" if units[u] == 1.0 else f" ({float(number) * units[u]:g} {si})") for u in fits)


def parse_quantity(text: str | float | int, units: dict[str, float], what: str) -> float:
    """A number with one of ``units`` ("12kg", "50 cm") in SI; a plain number
    is SI already. ValueError (naming ``what``): no number, an unknown unit, or a string without a unit (the
    message suggests the units that make it a plausible ``what``: :func:`unit_suggestion`)."""
    if isinstance(text, (int, float)) and not isinstance(text, bool):
        return float(text)
    m = _QUANTITY.match(str(text))
    if m is None:
        raise ValueError(f"{what}: {text!r} is not a number with a unit ({', '.join(units)})")
    value, unit = float(m.group(1)), m.group(2).replace("°", "deg").lower()
    if not unit:
        raise ValueError(f"{what}: unit missing in {text!r}; write e.g. {unit_suggestion(m.group(1), units, what)} "
                         f"(units: {', '.join(units)})")
    if unit not in units:
        raise ValueError(f"{what}: unknown unit {unit!r} in {text!r} (use {', '.join(units)})")
    return value * units[unit]


class StateOverride(Frozen):
    """One joint's state as an override: ``fraction`` (0..1), ``angle`` (rad)
    or ``distance`` (m) from the closed end, or a ``band``; ``text`` as written."""

    kind: Literal["fraction", "angle", "distance", "band"]
    value: float | None = None
    band: StateBand | None = None
    text: str = ""

    @classmethod
    def parse(cls, text: str | float | int, where: str = "state") -> "StateOverride":
        """``"30deg"``, ``"2cm"``, ``"0.4"`` (a fraction), ``"halfway"`` (a band).
        ValueError: a unitless number above 1, a negative value, an unknown unit or word."""
        if isinstance(text, (int, float)) and not isinstance(text, bool):
            text = repr(float(text))
        raw = str(text).strip()
        band = raw.lower().replace("-", "_").replace(" ", "_")
        if band in BAND_TARGET:
            return cls(kind="band", band=band, text=raw)
        if band == "open":
            return cls(kind="band", band="fully", text=raw)
        m = _QUANTITY.match(raw)
        if m is None:
            raise ValueError(f"{where}: {raw!r} is neither a band ({', '.join(BAND_TARGET)}), an opening fraction 0-1, "
                             f"an angle ({', '.join(ANGLE_UNITS)}) nor a distance ({', '.join(LENGTH_UNITS)})")
        value, unit = float(m.group(1)), m.group(2).replace("°", "deg").lower()
        if value < 0:
            raise ValueError(f"{where}: {raw!r} is negative; states are measured from the closed end")
        if not unit:
            if value > 1.0:
                raise ValueError(f"{where}: unit missing in {raw!r}: an opening fraction is 0-1; an angle needs deg or rad, "
                                 "a distance m, cm or mm")
            return cls(kind="fraction", value=value, text=raw)
        for kind, units in (("angle", ANGLE_UNITS), ("distance", LENGTH_UNITS)):
            if unit in units:
                return cls(kind=kind, value=value * units[unit], text=raw)
        raise ValueError(f"{where}: unknown unit {unit!r} in {raw!r} (angles: deg, rad; distances: m, cm, mm)")


class RequestOverrides(Frozen):
    """Typed values that win over the request's words (command line, API,
    configuration file; strings carry units, numbers are SI): ``mass`` kg in
    (0, 1e5], ``size`` m (largest extent) in (0, 100], ``scale`` in [1e-4, 1e4]
    (the overlay's range; wins over ``size``), ``state`` (joint or part label
    -> :class:`StateOverride`, at most 256), ``mount``, ``material`` (a name of
    at most 64 characters). Finite numbers only."""

    model_config = ConfigDict(allow_inf_nan=False)
    mass: float | None = Field(None, gt=0.0, le=1e5)
    size: float | None = Field(None, gt=0.0, le=100.0)
    scale: float | None = Field(None, ge=1e-4, le=1e4)
    state: dict[str, StateOverride] = Field({}, max_length=256)
    mount: Literal["fixed", "free"] | None = None
    material: str | None = Field(None, min_length=1, max_length=64)

    @field_validator("mass", "size", mode="before")
    @classmethod
    def _quantity(cls, v, info):
        return None if v is None else parse_quantity(v, MASS_UNITS if info.field_name == "mass" else LENGTH_UNITS, info.field_name)

    @field_validator("state", mode="before")
    @classmethod
    def _state(cls, v):
        if v is None:
            return {}
        if not isinstance(v, dict):
            raise ValueError("state: expected a mapping of joint name or part label to a state")
        return {str(k): s if isinstance(s, StateOverride) else StateOverride.model_validate(s) if isinstance(s, dict)
                else StateOverride.parse(s, f"state {k}") for k, s in v.items()}

    def given(self) -> list[str]:
        """Each override as the report lists it (``--mass 12 kg`` ...)."""
        out = [f"--{k} {v:g}{unit}" for k, v, unit in (("mass", self.mass, " kg"), ("size", self.size, " m"), ("scale", self.scale, ""))
               if v is not None]
        out += [f"--state {k}={s.text or s.value}" for k, s in self.state.items()]
        return out + [f"--{k} {v}" for k, v in (("mount", self.mount), ("material", self.material)) if v is not None]

    def __bool__(self) -> bool:
        return bool(self.given())
