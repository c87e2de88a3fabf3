"""The estimator protocol and its registry (SPEC stage 2): an estimator turns an
``EstimationContext`` (values) and the input's kinematics session (what poses
the parts) into an :class:`Estimate` and registers a factory under its name on
import (:mod:`asset2sim.tasks.synthesize.backends` imports the built-in ones)."""

from __future__ import annotations

import difflib
from dataclasses import dataclass, field
from typing import Callable, Protocol

from asset2sim.engines.base import SimSession
from asset2sim.schemas.overlay import Overlay
from asset2sim.tasks.synthesize import request_apply
from asset2sim.tasks.synthesize.context import EstimationContext

__all__ = ["Estimate", "Estimator", "EstimatorUnknown", "get_estimator", "register_estimator"]


@dataclass
class Estimate:
    """What an estimator returns: the overlay, the band (``BAND_TARGET`` name) it chose for every movable
    joint, and notes on how it read the request."""

    overlay: Overlay
    bands: dict[str, str]
    notes: list[str] = field(default_factory=list)
    targets: dict[str, request_apply.JointTarget] = field(default_factory=dict)
    """joint -> the number or end the request asked, resolved; its interval replaces the band's in the state search."""


class Estimator(Protocol):
    """Produces an overlay from a context."""

    name: str

    def estimate(self, ctx: EstimationContext, kin: SimSession) -> Estimate:
        """Return the overlay (validated afterwards by the caller) and the bands; ``kin`` (the input's fixed-base,
        gravity-free kinematics session, :func:`~asset2sim.tasks.synthesize.context.build_context`) may be moved."""


_REGISTRY: dict[str, Callable[..., Estimator]] = {}


class EstimatorUnknown(KeyError):
    """An estimator name no backend is registered under; ``str()`` is the message alone (a ``KeyError`` would quote
    it)."""

    def __str__(self) -> str:
        return str(self.args[0]) if self.args else ""


def register_estimator(name: str, factory: Callable[..., Estimator]) -> None:
    """Register ``factory(**settings) -> Estimator`` under ``name``."""
    _REGISTRY[name] = factory


def get_estimator(name: str, **settings) -> Estimator:
    """Instantiate the estimator registered as ``name`` with ``settings`` (e.g. ``model``, ``base_url``).

    Raises:
        EstimatorUnknown: unknown name (one sentence: the closest known name and every known one).
    """
    if name not in _REGISTRY:
        close = difflib.get_close_matches(name, sorted(_REGISTRY), n=1, cutoff=0.6)
        raise EstimatorUnknown(f"--estimator {name}: no such estimator" + (f"; did you mean {close[0]}?" if close else "")
                               + f" (known: {', '.join(sorted(_REGISTRY))})")
    return _REGISTRY[name](**settings)
