"""The built-in estimators, registered: ``offline``
(:mod:`asset2sim.tasks.synthesize.offline`) and the model backends ``llm``
and ``openai`` (:mod:`asset2sim.tasks.synthesize.llm_estimator`; litellm
itself is imported only when a client is made). Callers get an estimator by
name here."""

from __future__ import annotations

from asset2sim.tasks.synthesize import llm_estimator, offline  # noqa: F401  (they register on import)
from asset2sim.tasks.synthesize.estimator import Estimator
from asset2sim.tasks.synthesize.estimator import get_estimator as _get

__all__ = ["get_estimator"]


def get_estimator(name: str, **settings) -> Estimator:
    """Instantiate the built-in or registered estimator ``name`` with
    ``settings`` (e.g. ``model``, ``base_url``).

    Raises:
        KeyError: unknown name (the message lists the known ones).
    """
    return _get(name, **settings)
