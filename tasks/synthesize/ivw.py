"""Inverse-variance weighting (IVW) of N estimates with reported uncertainties.

The ``ivw`` baseline (SPEC, "Baselines"): several model calls each report a
value and a standard deviation per parameter; the fused value is the
fixed-effect inverse-variance weighted mean

    w_i = 1 / sigma_i^2,   x_hat = sum(w_i x_i) / sum(w_i),   sigma_hat = (sum w_i)^(-1/2)

(e.g. Hartung, Knapp & Sinha, *Statistical Meta-Analysis with Applications*,
Wiley 2008, ch. 4; Cochran, Biometrics 10 (1954) 101-129). The fused standard
deviation assumes independent estimates, which repeated queries of one model
are not: it is a lower bound, reported for information only.

``log_space=True`` fuses ln x with sigma_ln = sigma / x (first-order delta
method) for strictly positive quantities whose errors are multiplicative
(scale, mass) and returns exp of the fused log and the delta-method sigma.
Units: whatever the estimates are in (the result has the same unit).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Iterable, Mapping


@dataclass(frozen=True)
class Fused:
    """A fused estimate: ``value`` and ``std`` in the unit of the inputs,
    ``n`` estimates used, ``weights`` their normalized weights (sum 1, input order)."""

    value: float
    std: float
    n: int
    weights: tuple[float, ...]


def fuse(estimates: Iterable[tuple[float, float]], *, log_space: bool = False, min_std: float = 0.0) -> Fused:
    """Fuse (value, std) pairs by inverse-variance weighting.

    Args:
        estimates: (value, one standard deviation) pairs, same unit.
        log_space: fuse ln(value) (values must be > 0); see the module docstring.
        min_std: floor applied to every std before weighting (same unit as the
            values; relative to the value when ``log_space``), so that one
            over-confident estimate cannot take all the weight. 0 = no floor.

    Returns:
        :class:`Fused`.

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


def fuse_all(groups: Mapping[str, Iterable[tuple[float, float]]], *, log_space: bool = False, min_std: float = 0.0) -> dict[str, Fused]:
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
            out[name] = fuse(est, log_space=log_space, min_std=min_std)
        except ValueError as exc:
            raise ValueError(f"{name}: {exc}") from None
    return out
