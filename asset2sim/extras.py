"""The optional dependencies (the extras of ``pyproject.toml``) by the modules they provide, and the one-line hint
that names the extra a missing module belongs to: ``MuJoCo is not installed: pip install 'asset2sim[mujoco]'``,
never a bare "No module named 'mujoco'".
"""

from __future__ import annotations

import importlib
from types import ModuleType

from asset2sim.package_data import package_yaml

#: Top-level module -> (what it is, the extra of ``pyproject.toml`` that installs it): ``extras.yaml`` beside this module.
EXTRA_OF_MODULE: dict[str, tuple[str, str]] = {module: tuple(entry)
                                               for module, entry in package_yaml(__package__, "extras.yaml").items()}


def missing_module(exc: BaseException) -> str | None:
    """The name of the module an ImportError could not import (``exc.name``) as :data:`EXTRA_OF_MODULE` knows it: the
    dotted name where it is listed (``mujoco.mjx``, a package of its own), else its top-level name; or None."""
    name = getattr(exc, "name", None)
    if not (isinstance(name, str) and name):
        return None
    return name if name in EXTRA_OF_MODULE else name.split(".")[0]


def install_hint(exc: BaseException) -> str:
    """One line for an ImportError: ``MuJoCo is not installed: pip install 'asset2sim[mujoco]'`` when the missing
    module belongs to an extra (:data:`EXTRA_OF_MODULE`), else the first line of the error's own message."""
    module = missing_module(exc)
    if module in EXTRA_OF_MODULE:
        what, extra = EXTRA_OF_MODULE[module]
        return f"{what} is not installed: pip install 'asset2sim[{extra}]'"
    return (str(exc).strip().splitlines() or [""])[0] or type(exc).__name__


class MissingExtra(ImportError):
    """An optional dependency is not installed; the message is :func:`install_hint`'s line, prefixed by what
    needed it. ``name`` is the missing module's, as Python's own ImportError has it."""


def import_extra(module: str, needed_for: str) -> ModuleType:
    """Import ``module`` (an optional dependency) for ``needed_for`` ("the MJCF export").

    Raises:
        MissingExtra: it is not installed (``reading MJCF: MuJoCo is not installed: pip install
            'asset2sim[mujoco]'``).
    """
    try:
        return importlib.import_module(module)
    except ImportError as exc:
        raise MissingExtra(f"{needed_for}: {install_hint(exc)}", name=missing_module(exc) or module.split(".")[0]) from exc


def pxr_modules():
    """``(Gf, Sdf, Tf, Usd, UsdGeom, UsdPhysics)`` from ``pxr`` (OpenUSD, the ``usd`` extra).

    Raises:
        MissingExtra (an ImportError): ``usd-core`` is not installed (the message names the extra, ``[usd]``).
    """
    return tuple(import_extra(f"pxr.{m}", "OpenUSD") for m in ("Gf", "Sdf", "Tf", "Usd", "UsdGeom", "UsdPhysics"))
