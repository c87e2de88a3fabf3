"""Configuration classes, with units on every field.

:class:`SimConventions` are the SPEC's measurement conventions ("How quality is
measured"); :class:`RefineConfig` the knobs of the refine pipeline. Both hash
stably (:meth:`RefineConfig.config_hash`) so converters can skip unchanged work.
"""

from __future__ import annotations

import hashlib
import importlib.util
import json
from typing import Literal

from pydantic import BaseModel, ConfigDict, Field

from asset2sim.schemas.request import RequestOverrides


class SimConventions(BaseModel):
    """SPEC conventions for every simulator measurement."""

    model_config = ConfigDict(extra="forbid", frozen=True)
    timestep: float = 1.0 / 240.0
    """s"""
    gravity: float = -9.81
    """m/s^2 along z"""
    settle_time: float = 1.0
    """T_set, s"""
    test_time: float = 2.0
    """T_test, s"""
    stability_pos_tol: float = 1e-3
    """D_pos pass threshold, m"""
    stability_ori_tol: float = 1e-2
    """D_ori pass threshold, rad"""
    oscillation_sign_changes: int = 3
    """a joint fails with at least this many sign changes of its step-to-step motion ..."""
    oscillation_amp_revolute: float = 0.05
    """... and amplitude above this, rad"""
    oscillation_amp_prismatic: float = 0.005
    """... or above this for prismatic joints, m"""


def default_engines() -> list[str]:
    """The post-check's default engines: PyBullet, and PhysX (SAPIEN 3) when
    ``sapien`` is installed (``docs/design/simulators.md``)."""
    return ["pybullet", "physx"] if importlib.util.find_spec("sapien") is not None else ["pybullet"]


class MjcfConfig(BaseModel):
    """How an MJCF input is read."""

    model_config = ConfigDict(extra="forbid", frozen=True)
    angle: Literal["radian", "degree"] | None = None
    """The unit of the file's angles (joint ranges, ``euler``, ``ref``), winning over its ``<compiler angle>``
    and its host package's convention; None: as the package that compiles it reads it
    (:mod:`asset2sim.tasks.ingest.host_conventions`, ``docs/guide/inputs.md``)."""


class RefineConfig(BaseModel):
    """Knobs of the refine pipeline (units on every field)."""

    model_config = ConfigDict(extra="forbid")
    estimator: str = "offline"
    """Registered estimator name (``offline``, ``llm``, ``openai`` ...)."""
    model: str | None = None
    """Model string for model-backed estimators (litellm form, e.g. ``gemini/gemini-2.5-flash``)."""
    base_url: str | None = None
    """Base URL of an OpenAI-compatible server for model-backed estimators."""
    sim: SimConventions = Field(default_factory=SimConventions)
    penetration_tolerance: float = 1e-3
    """Phi below which the state is accepted, m (sum over contact points)."""
    state_lambda: float = 0.05
    """lambda in Phi(q) + lambda*||q - q_request||^2, m per rad^2 (or per m^2)."""
    max_state_evaluations: int = 4000
    """Budget of contact queries during state refinement (count)."""
    max_escalation_rounds: int = 5
    """Post-check rounds changing damping/friction (count;
    :mod:`asset2sim.tasks.check.dynamics_search`)."""
    escalation_factor: float = 3.0
    """Multiplier on damping/friction per escalation round (dimensionless)."""
    sag_tolerance_revolute: float = 0.02
    """Largest drift of a requested joint state during the rest test, rad."""
    sag_tolerance_prismatic: float = 0.002
    """Largest drift of a requested joint state during the rest test, m."""
    convex_decomposition: bool = True
    """Allow CoACD decomposition of collision meshes: of those whose hulls always overlap and, with
    ``open_containers``, of containers."""
    open_containers: bool = False
    """Give a part modelled as one mesh group with an open inside (a bucket, a trash can's body, a dishwasher
    tub) a convex decomposition that leaves the inside open, instead of one solid hull, so that things can be put
    into it (needs CoACD and ``convex_decomposition``; off by default: it costs CoACD time per container;
    ``docs/guide/outputs.md``)."""
    engines: list[str] = Field(default_factory=lambda: default_engines())
    """Engines the post-check must pass in (worst case); PyBullet first."""
    max_decompositions: int = Field(32, ge=0)
    """CoACD decompositions one collision repair may try (a count, never
    seconds: same input, same files); beyond it meshes keep their hulls."""
    seed: int = 0
    keep_declared: bool = False
    """Keep the masses, inertia tensors, centers of mass, joint damping, friction and springs the asset declares
    where ``asset2sim audit`` judges them plausible, and its size when plausible (``docs/guide/audit.md``)."""
    clips: bool = True
    """Write clips of each task-relevant joint's sweep (``clips/``, WebM and PNG) with the report
    (``docs/guide/outputs.md``); ``False`` (``--no-clips``) leaves them out."""
    body: str | None = None
    """The body (MJCF) whose subtree is the object, in a scene holding several objects with joints; None: the one
    subtree under the world body that carries hinge or slide joints (``docs/guide/inputs.md``)."""
    mjcf: MjcfConfig = Field(default_factory=MjcfConfig)
    """How an MJCF input is read (:class:`MjcfConfig`)."""
    overrides: RequestOverrides = Field(default_factory=RequestOverrides)
    """Typed values that win over the request's words (:class:`~asset2sim.schemas.request.RequestOverrides`)."""

    def config_hash(self) -> str:
        """sha256 (hex, 16 chars) of the canonical JSON of this configuration."""
        data = self.model_dump(mode="json")
        if not data.get("keep_declared"):  # off: the hash of every configuration before the option existed
            data.pop("keep_declared", None)
        if data.get("clips", True):  # on (the default): the hash of every configuration before the option existed
            data.pop("clips", None)
        if not data.get("open_containers", False):  # off (the default): the hash of every configuration before the option existed
            data.pop("open_containers", None)
        if data.get("body") is None:  # the default: the hash of every configuration before the option existed
            data.pop("body", None)
        if data.get("mjcf") == MjcfConfig().model_dump(mode="json"):  # the default, likewise
            data.pop("mjcf", None)
        blob = json.dumps(data, sort_keys=True).encode()
        return hashlib.sha256(blob).hexdigest()[:16]
