"""asset2sim: articulated-object assets in, interaction-ready simulation assets out.

The public API (:mod:`asset2sim.api`, e.g. ``asset2sim.refine(asset, request,
out_dir)``) is reached from here, loaded on first use so the import stays light.
"""

from __future__ import annotations

import importlib

__version__ = "0.2.0"

#: The public names, all defined in :mod:`asset2sim.api`.
__all__ = [
    "AuditError", "AuditResult", "Evaluation", "Finding", "RefineConfig", "RefineError", "RefineResult", "RequestOverrides",
    "SimConventions", "audit", "declare_physics", "evaluate", "export", "load_config", "load_mujoco", "load_pybullet", "load_sapien",
    "make_media", "refine",
    "validate",
]


def __getattr__(name: str):
    """A public name from :mod:`asset2sim.api`, imported on first use (else AttributeError)."""
    if name in __all__:
        value = getattr(importlib.import_module("asset2sim.api"), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'asset2sim' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
