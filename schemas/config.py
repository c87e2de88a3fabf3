"""Configuration classes, with units on every field.

:class:`SimConventions` are the SPEC's measurement conventions ("How quality is
measured"); :class:`RefineConfig` the knobs of the refine pipeline. Both hash
stably (:meth:`RefineConfig.config_hash`) so converters can skip unchanged work.
"""

from __future__ import annotations

import hashlib
import importlib.util
import json

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
    ``sapien`` is installed (it is with ``make setup``), the engine of Isaac
    Sim, SAPIEN and ManiSkill; on the 21 dev objects PhysX adds about 0.2 s
    per post-check round plus 0.9 s of import once per process
    (``docs/design/simulators.md``)."""
    return ["pybullet", "physx"] if importlib.util.find_spec("sapien") is not None else ["pybullet"]


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
    """Post-check rounds changing damping/friction (count): escalation and
    relief, bracketed by what each round measured
    (:mod:`asset2sim.tasks.check.dynamics_search`: a joint in conflict
    between robust rest and the task needs a round or two of bisection)."""
    escalation_factor: float = 3.0
    """Multiplier on damping/friction per escalation round (dimensionless)."""
    sag_tolerance_revolute: float = 0.02
    """Largest drift of a requested joint state during the rest test, rad."""
    sag_tolerance_prismatic: float = 0.002
    """Largest drift of a requested joint state during the rest test, m."""
    convex_decomposition: bool = True
    """Allow CoACD decomposition of collision meshes whose hulls always overlap."""
    engines: list[str] = Field(default_factory=lambda: default_engines())
    """Engines the post-check must pass in (worst case over them); PyBullet is
    always first (state refinement and escalation run there). Default:
    :func:`default_engines` (PyBullet, and PhysX where SAPIEN is installed)."""
    max_decompositions: int = Field(32, ge=0)
    """CoACD decompositions one collision repair may try (a count of calls,
    never seconds, so the same input gives the same files on a loaded or a
    quiet machine). The 21 dev rows with their manifest requests call CoACD
    at most 4 times per refine (102990; 103275: 2); a repair that reaches
    the cap keeps the remaining meshes as their hulls and says so."""
    seed: int = 0
    overrides: RequestOverrides = Field(default_factory=RequestOverrides)
    """Typed values that win over the request's words (mass kg, size m,
    scale, joint states, mounting, material;
    :class:`~asset2sim.schemas.request.RequestOverrides`)."""

    def config_hash(self) -> str:
        """sha256 (hex, 16 chars) of the canonical JSON of this configuration."""
        blob = json.dumps(self.model_dump(mode="json"), sort_keys=True).encode()
        return hashlib.sha256(blob).hexdigest()[:16]
