"""OpenUSD (``usd-core``, an optional extra) imported on first use, and the attribute reads the USD reader and
writer share."""

from __future__ import annotations

from asset2sim.extras import import_extra

__all__ = ["authored", "pxr_modules", "value_or"]


def pxr_modules():
    """``(Gf, Sdf, Tf, Usd, UsdGeom, UsdPhysics)`` from ``pxr``.

    Raises:
        MissingExtra (an ImportError): ``usd-core`` is not installed (the message names the extra, ``[usd]``).
    """
    return tuple(import_extra(f"pxr.{m}", "OpenUSD") for m in ("Gf", "Sdf", "Tf", "Usd", "UsdGeom", "UsdPhysics"))


def authored(prim, name: str):
    """The authored value of attribute ``name`` of ``prim``; None when the attribute is absent or not authored."""
    a = prim.GetAttribute(name)
    return a.Get() if a and a.HasAuthoredValue() else None


def value_or(prim, name: str, default):
    """Attribute ``name``'s value (its schema fallback included); ``default`` when it has none."""
    a = prim.GetAttribute(name)
    value = a.Get() if a else None
    return default if value is None else value
