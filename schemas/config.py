"""Configuration classes, with units on every field.

:class:`SimConventions` are the SPEC's measurement conventions ("How quality is
measured"); :class:`RefineConfig` the knobs of the refine pipeline. Both hash
stably (:meth:`RefineConfig.config_hash`) so converters can skip unchanged work.
"""

from __future__ import annotations

import hashlib
import importlib.util
import json
import math
import re
from typing import Literal

from pydantic import ConfigDict, Field, field_validator, model_validator

from asset2sim.schemas import Frozen, Strict
from asset2sim.schemas.request import RequestOverrides


#: Longest settle or test phase of one simulator measurement, s (the SPEC's are 1 s and 2 s).
MAX_PHASE_TIME = 60.0
#: Most simulator steps one settle + test measurement may take ((settle_time + test_time) / timestep): a time step
#: and times that ask for more would run for hours, not give a better verdict.
MAX_MEASUREMENT_STEPS = 200_000
#: Smallest time step, s: 42 times finer than the SPEC's 1/240 s and 20 times finer than MuJoCo's default 2 ms. Every
#: check derives its steps from simulated seconds over the time step (the sweep, robust rest's trials, operability's
#: strokes, the gripper, the escalation's rounds), so a finer step multiplies them all without a better verdict;
#: ``1e-7`` ran a refine past 360 s and ``1e-300`` for ever.
MIN_TIMESTEP = 1e-4
#: Most simulated steps of one refine, every phase, round and engine together (``asset2sim.engines.step_budget``; past
#: it the refine ends with ``SIM_STEPS_EXCEEDED``): 53 times the most a refine of the 21 dev objects took with the
#: SPEC's time step and its manifest task (56,190 steps, the suitcase 103755 over 3 rounds; the median 8,400), so
#: only a finer step or longer times reach it; about 3.5 minutes of PyBullet on such an object
#: (``docs/design/trust.md``).
MAX_REFINE_STEPS = 3_000_000
#: Wall-clock seconds the simulations of one refine may run (``asset2sim.engines.step_budget``, checked before every
#: step; past it the refine ends with ``SIM_TIME_EXCEEDED``, failure mode ``timeout``, never another verdict): the
#: step cap above bounds work in steps, but a step's cost grows with the object's bodies and contacts, and 32 revolute
#: links step about 5 times slower than a box with a lid (``benchmarks/bench_refine_deadline.py``), so the step cap alone
#: let one refine run 35-50 minutes. 15 minutes is several times the longest refine of a dev object measured in any
#: engine.
MAX_REFINE_SECONDS = 900.0
#: Simulated seconds every refine spends besides its rest tests, at least (robust rest's trials and the sweep of its
#: one joint): the smallest refine of the dev objects simulated 11.8 s (the door 8877). A configuration whose time step
#: makes even these exceed :data:`MAX_REFINE_STEPS` is refused before any work.
MIN_REFINE_SECONDS = 10.0


#: Smallest band a joint must come to rest in around its initial state after the object is put down (SPEC, robust
#: rest), rad (revolute and continuous) or m (prismatic) ...
REST_BAND_FLOORS: dict[str, float] = {"revolute": 0.02, "prismatic": 0.002}
#: ... or this share of its range where that is more (dimensionless; SPEC: 5 %): the state still reads as asked.
REST_BAND_RANGE_SHARE = 0.05


class SimConventions(Frozen):
    """SPEC conventions for every simulator measurement. Every field is finite and bounded (pydantic refuses
    the rest, naming the field): a time step in [:data:`MIN_TIMESTEP`, 0.05] s, settle and test times up to
    :data:`MAX_PHASE_TIME`, at most :data:`MAX_MEASUREMENT_STEPS` steps per measurement."""

    model_config = ConfigDict(allow_inf_nan=False)
    timestep: float = Field(1.0 / 240.0, ge=MIN_TIMESTEP, le=0.05)
    """s, at least :data:`MIN_TIMESTEP`"""
    gravity: float = Field(-9.81, ge=-100.0, le=100.0)
    """m/s^2 along z"""
    settle_time: float = Field(1.0, ge=0.0, le=MAX_PHASE_TIME)
    """T_set, s"""
    test_time: float = Field(2.0, gt=0.0, le=MAX_PHASE_TIME)
    """T_test, s"""
    stability_pos_tol: float = Field(1e-3, gt=0.0, le=1.0)
    """D_pos pass threshold, m"""
    stability_ori_tol: float = Field(1e-2, gt=0.0, le=math.pi)
    """D_ori pass threshold, rad"""
    oscillation_sign_changes: int = Field(3, ge=1, le=10_000)
    """a joint fails with at least this many sign changes of its step-to-step motion ..."""
    oscillation_amp_revolute: float = Field(0.05, gt=0.0, le=2 * math.pi)
    """... and amplitude above this, rad"""
    oscillation_amp_prismatic: float = Field(0.005, gt=0.0, le=10.0)
    """... or above this for prismatic joints, m"""

    @model_validator(mode="after")
    def _steps_bounded(self) -> "SimConventions":
        steps = (self.settle_time + self.test_time) / self.timestep
        if steps > MAX_MEASUREMENT_STEPS:
            raise ValueError(f"(settle_time + test_time) / timestep = {steps:.0f} simulator steps per measurement, above the "
                             f"cap of {MAX_MEASUREMENT_STEPS}: use a larger timestep or shorter times")
        return self


_ENGINE_NAME = re.compile(r"[a-z][a-z0-9_]{0,31}")


def default_engines() -> list[str]:
    """The post-check's default engines: PyBullet, and PhysX (SAPIEN 3) when
    ``sapien`` is installed (``docs/design/simulators.md``)."""
    return ["pybullet", "physx"] if importlib.util.find_spec("sapien") is not None else ["pybullet"]


class MjcfConfig(Frozen):
    """How an MJCF input is read."""

    angle: Literal["radian", "degree"] | None = None
    """The unit of the file's angles (joint ranges, ``euler``, ``ref``), winning over its ``<compiler angle>``
    and its host package's convention; None: as the package that compiles it reads it
    (:mod:`asset2sim.formats.mjcf.conventions`, ``docs/guide/inputs.md``)."""


#: Fields added after configurations were first hashed, left out of :meth:`RefineConfig.config_hash` at their defaults.
_ADDED_FIELDS = ("keep_declared", "clips", "open_containers", "request_parser", "body", "mjcf")


class RefineConfig(Strict):
    """Knobs of the refine pipeline (units on every field)."""

    model_config = ConfigDict(allow_inf_nan=False)
    estimator: str = Field("offline", min_length=1, max_length=64)
    """Registered estimator name (``offline``, ``llm``, ``openai`` ...)."""
    model: str | None = Field(None, min_length=1, max_length=256)
    """Model string for model-backed estimators (litellm form, e.g. ``gemini/gemini-2.5-flash``)."""
    base_url: str | None = Field(None, min_length=1, max_length=2048)
    """Base URL of an OpenAI-compatible server for model-backed estimators."""
    request_parser: Literal["offline", "model"] = "offline"
    """Who turns the request into its typed intent: the offline parser (the default), or the model of ``estimator``
    ``llm`` / ``openai`` (``model``) with the intent's JSON schema, the offline parse kept when the model's reply
    is invalid or the call fails (``docs/guide/requests.md``)."""
    sim: SimConventions = SimConventions()
    penetration_tolerance: float = Field(1e-3, gt=0.0, le=1.0)
    """Phi below which the state is accepted, m (sum over contact points)."""
    state_lambda: float = Field(0.05, ge=0.0, le=1e3)
    """lambda in Phi(q) + lambda*||q - q_request||^2, m per rad^2 (or per m^2)."""
    max_state_evaluations: int = Field(4000, ge=1, le=1_000_000)
    """Budget of contact queries during state refinement (count)."""
    max_escalation_rounds: int = Field(5, ge=0, le=50)
    """Post-check rounds changing damping/friction in one attempt, its collision repairs included (count;
    :mod:`asset2sim.tasks.tune.dynamics_search`)."""
    escalation_factor: float = Field(3.0, gt=1.0, le=100.0)
    """Multiplier on damping/friction per escalation round (dimensionless)."""
    sag_tolerance_revolute: float = Field(0.02, gt=0.0, le=math.pi)
    """Largest drift of a requested joint state during the rest test, rad."""
    sag_tolerance_prismatic: float = Field(0.002, gt=0.0, le=10.0)
    """Largest drift of a requested joint state during the rest test, m."""
    convex_decomposition: bool = True
    """Allow CoACD decomposition of collision meshes: of those whose hulls always overlap and, with
    ``open_containers``, of containers."""
    open_containers: bool = False
    """Give a part modelled as one mesh group with an open inside (a bucket, a trash can's body, a dishwasher
    tub) a convex decomposition that leaves the inside open, instead of one solid hull, so that things can be put
    into it (needs CoACD and ``convex_decomposition``; off by default: it costs CoACD time per container;
    ``docs/guide/outputs.md``)."""
    engines: list[str] = Field(default_factory=default_engines)
    """Engines the post-check must pass in (worst case); PyBullet first. One to 8 distinct engine names; which
    names exist is checked against the engine registry by :func:`asset2sim.api.load_config` (the CLI, the API and
    configuration files) and by refine."""
    max_decompositions: int = Field(32, ge=0, le=4096)
    """CoACD decompositions one collision repair may try (a count, never
    seconds: same input, same files); beyond it meshes keep their hulls."""
    seed: int = Field(0, ge=0, le=2**32 - 1)
    keep_declared: bool = False
    """Keep the masses, inertia tensors, centers of mass, joint damping, friction and springs the asset declares
    where ``asset2sim audit`` judges them plausible, and its size when plausible (``docs/guide/audit.md``)."""
    clips: bool = True
    """Write clips of each task-relevant joint's sweep (``clips/``, WebM and PNG) with the report
    (``docs/guide/outputs.md``); ``False`` (``--no-clips``) leaves them out."""
    body: str | None = None
    """The body (MJCF) whose subtree is the object, in a scene holding several objects with joints; None: the one
    subtree under the world body that carries hinge or slide joints (``docs/guide/inputs.md``)."""
    mjcf: MjcfConfig = MjcfConfig()
    """How an MJCF input is read (:class:`MjcfConfig`)."""
    overrides: RequestOverrides = RequestOverrides()
    """Typed values that win over the request's words (:class:`~asset2sim.schemas.request.RequestOverrides`)."""

    @field_validator("engines")
    @classmethod
    def _engine_names(cls, v: list[str]) -> list[str]:
        if not 1 <= len(v) <= 8:
            raise ValueError(f"engines: give 1 to 8 engine names, got {len(v)}")
        bad = [e for e in v if not isinstance(e, str) or not _ENGINE_NAME.fullmatch(e)]
        if bad:
            raise ValueError(f"engines: {bad[:3]} are not engine names (lower-case letters, digits and '_')")
        return v

    @model_validator(mode="after")
    def _refine_fits_its_step_cap(self) -> "RefineConfig":
        need = minimum_refine_steps(self)
        if need > MAX_REFINE_STEPS:
            raise ValueError(f"sim.timestep {self.sim.timestep:g} s: even the smallest refine would simulate {need:.0f} steps "
                             f"(at least {MIN_REFINE_SECONDS:g} s of checks plus settle + test in each of {len(self.engines)} "
                             f"engine(s)), above the cap of {MAX_REFINE_STEPS} steps per refine: use a larger timestep")
        return self

    def config_hash(self) -> str:
        """sha256 (hex, 16 chars) of the canonical JSON of this configuration."""
        default = RefineConfig().model_dump(mode="json")
        # an added field at its default: the hash of every configuration before the field existed
        data = {k: v for k, v in self.model_dump(mode="json").items() if k not in _ADDED_FIELDS or v != default[k]}
        return hashlib.sha256(json.dumps(data, sort_keys=True).encode()).hexdigest()[:16]


def minimum_refine_steps(config: RefineConfig) -> float:
    """The fewest simulated steps any refine with ``config`` takes: :data:`MIN_REFINE_SECONDS` of checks plus one
    settle + test rest measurement in each engine, over ``config.sim.timestep``. A configuration above
    :data:`MAX_REFINE_STEPS` is refused when it is made (:class:`RefineConfig`)."""
    sim = config.sim
    return (MIN_REFINE_SECONDS + len(config.engines) * (sim.settle_time + sim.test_time)) / sim.timestep
