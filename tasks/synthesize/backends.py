"""The built-in estimators, registered on import (``offline``, ``llm``,
``openai``): callers get one by name here with :func:`get_estimator`."""

from __future__ import annotations

from asset2sim.tasks.synthesize import llm_estimator, offline  # noqa: F401  (they register on import)
from asset2sim.tasks.synthesize.estimator import get_estimator

__all__ = ["get_estimator"]
