"""Inverse-variance weighting (IVW) of estimates with reported uncertainties (the
``ivw`` baseline): w_i = 1 / sigma_i^2, x_hat = sum(w_i x_i) / sum(w_i),
sigma_hat = (sum w_i)^(-1/2) (Hartung, Knapp & Sinha, Statistical Meta-Analysis
with Applications, 2008, ch. 4), a lower bound for correlated estimates.
``log_space`` fuses ln x with sigma / x (delta method). Units: the inputs'.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Iterable, Mapping


@dataclass(frozen=True)
class Fused:
    """A fused estimate: ``value``, ``std``, ``n`` estimates and their normalized ``weights`` (input order)."""

    value: float
    std: float
    n: int
    weights: tuple[float, ...]


def fuse(estimates: Iterable[tuple[float, float]], *, log_space: bool = False, min_std: float = 0.0) -> Fused:
    """Fuse (value, std) pairs by inverse-variance weighting; ``min_std`` floors every std (relative with
    ``log_space``) so one over-confident estimate cannot take all the weight.

    Raises:
        ValueError: no estimates; a value or std not finite; std <= 0 (after the
            floor); a value <= 0 with ``log_space``; a negative ``min_std``.
    """
    if not (math.isfinite(min_std) and min_std >= 0):
        raise ValueError(f"min_std must be a finite number >= 0, got {min_std}")
    pairs = [(float(v), float(s)) for v, s in estimates]
    if not pairs:
        raise ValueError("inverse-variance weighting needs at least one estimate")
    xs, sig = [], []
    for i, (v, s) in enumerate(pairs):
        if not (math.isfinite(v) and math.isfinite(s)):
            raise ValueError(f"estimate {i}: value {v} and std {s} must be finite")
        if log_space:
            if v <= 0:
                raise ValueError(f"estimate {i}: value {v} must be > 0 to fuse in log space")
            x, s_eff = math.log(v), s / v
        else:
            x, s_eff = v, s
        s_eff = max(s_eff, min_std)
        if s_eff <= 0:
            raise ValueError(f"estimate {i}: std {s} must be > 0")
        xs.append(x)
        sig.append(s_eff)
    w = [1.0 / (s * s) for s in sig]
    W = math.fsum(w)
    if not math.isfinite(W) or W <= 0:
        raise ValueError(f"weights sum to {W}; stds too small to weight ({min(sig)})")
    x_hat = math.fsum(wi * xi for wi, xi in zip(w, xs)) / W
    s_hat = 1.0 / math.sqrt(W)
    if log_space:
        value = math.exp(x_hat)
        return Fused(value, value * s_hat, len(xs), tuple(wi / W for wi in w))
    return Fused(x_hat, s_hat, len(xs), tuple(wi / W for wi in w))


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
