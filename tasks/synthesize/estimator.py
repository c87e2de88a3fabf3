"""The estimator protocol and its registry (SPEC stage 2).

An estimator turns an :class:`~asset2sim.tasks.synthesize.context.EstimationContext`
into an :class:`Estimate`; it registers a factory under its name
(:func:`register_estimator`) when its module is imported.
:mod:`asset2sim.tasks.synthesize.backends` imports every built-in one
(offline, llm, openai) and is what callers use to get one by name.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable, Protocol

from asset2sim.schemas.overlay import Overlay
from asset2sim.tasks.synthesize import request_apply
from asset2sim.tasks.synthesize.context import EstimationContext

__all__ = ["Estimate", "Estimator", "get_estimator", "register_estimator", "registered"]


@dataclass
class Estimate:
    """What an estimator returns: the overlay, the state band it chose for
    every movable joint, and notes on how it read the request.

    ``bands``: joint name -> band name (:data:`asset2sim.schemas.request.BAND_TARGET`),
    every movable joint present; the refine stage turns them into the
    requested state (:func:`state_from_bands`) and the allowed intervals of
    the state search (:func:`band_intervals`).
    """

    overlay: Overlay
    bands: dict[str, str]
    notes: list[str] = field(default_factory=list)
    targets: dict[str, request_apply.JointTarget] = field(default_factory=dict)
    """joint -> a number or end the request asked ("30 degrees", "lever up"),
    resolved (:mod:`asset2sim.tasks.synthesize.request_apply`); its interval
    replaces the band's in the state search."""


class Estimator(Protocol):
    """Produces an overlay from a context."""

    name: str

    def estimate(self, ctx: EstimationContext) -> Estimate:
        """Return the overlay (validated afterwards by the caller) and the bands."""


_REGISTRY: dict[str, Callable[..., Estimator]] = {}


def register_estimator(name: str, factory: Callable[..., Estimator]) -> None:
    """Register ``factory(**settings) -> Estimator`` under ``name``."""
    _REGISTRY[name] = factory


def registered() -> list[str]:
    """Names of the registered estimators, sorted."""
    return sorted(_REGISTRY)


def get_estimator(name: str, **settings) -> Estimator:
    """Instantiate the estimator registered as ``name`` (import
    :mod:`asset2sim.tasks.synthesize.backends` for the built-in ones).

    Raises:
        KeyError: unknown name (the message lists the known ones).
    """
    if name not in _REGISTRY:
        raise KeyError(f"unknown estimator {name!r}; known: {sorted(_REGISTRY)}")
    return _REGISTRY[name](**settings)
