"""Inverse-variance weighting (IVW) of estimates with reported uncertainties (the
``ivw`` baseline): w_i = 1 / sigma_i^2, x_hat = sum(w_i x_i) / sum(w_i),
sigma_hat = (sum w_i)^(-1/2) (Hartung, Knapp & Sinha, Statistical Meta-Analysis
with Applications, 2008, ch. 4), a lower bound for correlated estimates.
Units: the inputs'.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Iterable, Mapping


@dataclass(frozen=True)
class Fused:
    """A fused estimate: ``value`` and ``std``."""

    value: float
    std: float


def fuse(estimates: Iterable[tuple[float, float]]) -> Fused:
    """Fuse (value, std) pairs by inverse-variance weighting.

    Raises:
        ValueError: no estimates; a value or std not finite; std <= 0.
    """
    pairs = [(float(v), float(s)) for v, s in estimates]
    if not pairs:
        raise ValueError("inverse-variance weighting needs at least one estimate")
    for i, (v, s) in enumerate(pairs):
        if not (math.isfinite(v) and math.isfinite(s)):
            raise ValueError(f"estimate {i}: value {v} and std {s} must be finite")
        if s <= 0:
            raise ValueError(f"estimate {i}: std {s} must be > 0")
    w = [1.0 / (s * s) for _, s in pairs]
    W = math.fsum(w)
    if not math.isfinite(W) or W <= 0:
        raise ValueError(f"weights sum to {W}; stds too small to weight ({min(s for _, s in pairs)})")
    return Fused(math.fsum(wi * v for wi, (v, _) in zip(w, pairs)) / W, 1.0 / math.sqrt(W))


def fuse_all(groups: Mapping[str, Iterable[tuple[float, float]]]) -> dict[str, Fused]:
    """:func:`fuse` per parameter name; parameters with no estimates are left out.

    Raises:
        ValueError: as :func:`fuse`, the message naming the parameter.
    """
    out: dict[str, Fused] = {}
    for name, est in groups.items():
        est = list(est)
        if not est:
            continue
        try:
            out[name] = fuse(est)
        except ValueError as exc:
            raise ValueError(f"{name}: {exc}") from None
    return out
