"""Bradley-Terry realism scores of methods from paired comparisons (people's ratings or a model judge's kept
verdicts): maximum a-posteriori log strengths, centred to mean 0, with 95 % intervals from the observed
information, and the same on the Elo scale.

Model (Bradley & Terry 1952, "Rank analysis of incomplete block designs: I. The method of paired
comparisons", Biometrika 39): ``P(i beats j) = 1 / (1 + exp(-(s_i - s_j)))`` with log strengths ``s``.
The likelihood alone has no finite maximum when a method won (or lost) every comparison, so each method
also plays :data:`PRIOR_GAMES` virtual wins and as many virtual losses against a virtual method of
strength 0 -- the prior of Coulom's Whole-History Rating (2008, "Whole-History Rating: A Bayesian rating
system for players of time-varying strength", sec. 3: one virtual win and one virtual loss against a
virtual player of rating 0) and the pseudo-count habit of Elo-style leaderboards. Its weight is that of
two comparisons per method, small beside tens of ratings, and it keeps every strength and interval finite.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from typing import Any

import numpy as np
from scipy.sparse.csgraph import connected_components
from scipy.special import expit, log_expit, ndtri

from asset2sim.schemas.realism import MethodScore

#: Virtual wins (and as many virtual losses) of each method against a virtual method of strength 0
#: (Coulom 2008, Whole-History Rating; see the module docstring).
PRIOR_GAMES = 1.0
#: Elo points per unit of log strength: 400 / ln 10 (Elo's logistic scale: 400 points = odds of 10).
ELO_PER_UNIT = 400.0 / math.log(10.0)
#: Elo of a method of mean strength.
ELO_MEAN = 1000.0
#: Two-sided 95 % normal quantile, 1.959964... (the standard normal's inverse CDF at 0.975, as scipy.stats.norm.ppf
#: computes it, without importing scipy.stats: about 1 s of every command's start-up)
Z95 = float(ndtri(0.975))


def _pairs(comparisons: Any) -> list[tuple[str, str]]:
    """(winner, loser) pairs of a DataFrame with ``winner`` / ``loser`` columns, or of an iterable of
    2-tuples or of objects with ``winner`` / ``loser`` attributes (:class:`Rating`, :class:`JudgeVerdict`)."""
    columns = getattr(comparisons, "columns", None)
    if columns is not None:
        missing = [c for c in ("winner", "loser") if c not in columns]
        if missing:
            raise ValueError(f"comparisons: the table has no column(s) {', '.join(missing)} "
                             f"(columns: {', '.join(map(str, columns))})")
        rows: Iterable[Any] = zip(comparisons["winner"].tolist(), comparisons["loser"].tolist())
    else:
        rows = comparisons
    out = []
    for k, row in enumerate(rows):
        if hasattr(row, "winner") and hasattr(row, "loser"):
            row = (row.winner, row.loser)
        try:
            winner, loser = row
        except (TypeError, ValueError):
            raise ValueError(f"comparison {k}: expected a (winner, loser) pair, got {row!r}") from None
        if not isinstance(winner, str) or not isinstance(loser, str) or not winner or not loser:
            raise ValueError(f"comparison {k}: winner and loser must be method names, got {winner!r}, {loser!r}")
        if winner == loser:
            raise ValueError(f"comparison {k}: method {winner!r} cannot beat itself")
        out.append((winner, loser))
    return out


def _objective(s: np.ndarray, wins: np.ndarray, prior: float) -> tuple[float, np.ndarray, np.ndarray]:
    """Negative log posterior of strengths ``s`` (n,), its gradient (n,) and Hessian (n, n);
    ``wins[i, j]`` how often method i beat method j."""
    d = s[:, None] - s[None, :]
    nll = -float(np.sum(wins * log_expit(d))) - prior * float(np.sum(log_expit(s) + log_expit(-s)))
    p = expit(d)
    g = wins * (1.0 - p)  # d/ds_i of wins_ij * log p_ij is +g_ij, d/ds_j is -g_ij
    grad = -(g.sum(axis=1) - g.sum(axis=0)) - prior * (1.0 - 2.0 * expit(s))
    games = wins + wins.T
    m = games * p * (1.0 - p)
    hess = np.diag(m.sum(axis=1)) - m
    q = expit(s)
    hess = hess + np.diag(2.0 * prior * q * (1.0 - q))
    return nll, grad, hess


def _centred_basis(n: int) -> np.ndarray:
    """An orthonormal basis (n, n-1) of the vectors whose entries sum to 0."""
    return np.linalg.qr(np.eye(n) - 1.0 / n)[0][:, : n - 1]


def _newton(objective, basis: np.ndarray, tol: float, max_iter: int = 200) -> tuple[np.ndarray, np.ndarray]:
    """Minimise the convex ``objective(s) -> (value, gradient, Hessian)`` over ``s = basis @ t`` with Newton's
    method and a backtracking (Armijo) line search (Boyd & Vandenberghe 2004, "Convex Optimization", 9.5);
    returns ``t`` and the Hessian in ``t`` there. Stops when the largest gradient entry is below ``tol``.
    Raises ValueError when it does not converge in ``max_iter`` steps."""
    t = np.zeros(basis.shape[1])
    for _ in range(max_iter):
        value, grad, hess = objective(t)
        g, h = basis.T @ grad, basis.T @ hess @ basis
        if float(np.max(np.abs(g))) < tol:
            return t, h
        step = np.linalg.solve(h, g)
        decrement = float(g @ step)  # the squared Newton decrement
        alpha = 1.0
        if decrement > 1e-9 * (1.0 + abs(value)):  # far from the optimum: damped; near it, full steps (quadratic)
            while alpha > 1e-12 and objective(t - alpha * step)[0] > value - 0.25 * alpha * decrement:
                alpha *= 0.5
        t = t - alpha * step
    raise ValueError(f"Bradley-Terry: Newton's method did not converge in {max_iter} steps")


def fit_bradley_terry(comparisons: Any, *, source: str, prior_games: float = PRIOR_GAMES) -> list[MethodScore]:
    """Bradley-Terry scores of the methods in ``comparisons``.

    Args:
        comparisons: (winner, loser) method names, one row per comparison: a DataFrame with columns
            ``winner`` and ``loser``, or an iterable of 2-tuples (or of objects with ``winner`` / ``loser``).
        source: who compared (``people`` or a judge model), copied into each score.
        prior_games: virtual wins and as many virtual losses of each method against a virtual method of
            strength 0 (default :data:`PRIOR_GAMES`; 0 gives the plain maximum-likelihood fit, which
            diverges when a method won or lost every comparison).

    Returns:
        One :class:`MethodScore` per method, strongest first (ties by name): ``strength`` the log strength
        (dimensionless; the methods' mean is 0), ``ci_low`` / ``ci_high`` its 95 % Wald interval,
        ``elo = 1000 + 400 / ln 10 * strength``, ``comparisons`` and ``wins`` counted from the input.

    Method: the negative log posterior (likelihood of Bradley & Terry 1952 plus the virtual games of
    Coulom 2008) is minimised over the sum-to-zero subspace ``s = B t`` (``B`` an orthonormal basis of the
    vectors summing to 0, ``t`` in R^(n-1)) with Newton's method and a backtracking line search, from
    ``t = 0``; the objective is strictly convex there, so the optimum is unique and the result deterministic
    (it equals the fixed point of Hunter's 2004 MM algorithm when ``prior_games`` is 0).
    The covariance of ``s`` is ``B (B^T H B)^-1 B^T`` with ``H`` the observed information (the Hessian of
    the negative log posterior, i.e. the Laplace approximation) at the optimum: the interval of each strength is relative to the methods' mean, the constraint the scale is fixed by.
    Interval: ``strength +- 1.96 * sqrt(cov_ii)``.

    Raises:
        ValueError: no comparisons, a single method, a method compared with itself, a row that is not a
            (winner, loser) pair of names, a DataFrame without those columns, or ``prior_games`` < 0;
            with ``prior_games == 0``, comparisons whose "i beat j" graph is not strongly connected (no finite
            maximum exists then; Ford 1957, "Solution of a ranking problem from binary comparisons",
            Amer. Math. Monthly 64).
    """
    if not (prior_games >= 0 and math.isfinite(prior_games)):
        raise ValueError(f"prior_games must be a finite number >= 0, got {prior_games!r}")
    pairs = _pairs(comparisons)
    if not pairs:
        raise ValueError("no comparisons: Bradley-Terry scores need at least one (winner, loser) pair")
    methods = sorted({m for pair in pairs for m in pair})
    index = {m: i for i, m in enumerate(methods)}
    n = len(methods)
    wins = np.zeros((n, n))
    for winner, loser in pairs:
        wins[index[winner], index[loser]] += 1.0
    if prior_games == 0 and connected_components(wins > 0, directed=True, connection="strong")[0] > 1:
        # Ford (1957): the maximum-likelihood strengths exist iff the graph "i beat j" is strongly connected
        raise ValueError("Bradley-Terry without a prior: no finite maximum (a method won or lost every comparison, "
                         "or some methods never beat the others); use prior_games > 0")
    basis = _centred_basis(n)
    t_hat, info = _newton(lambda t: _objective(basis @ t, wins, prior_games), basis, tol=1e-10 * (1.0 + len(pairs)))
    strength = basis @ t_hat
    cov = basis @ np.linalg.inv(info) @ basis.T
    se = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    strength = strength - strength.mean()  # exact mean 0 despite rounding
    games = wins + wins.T
    scores = [
        MethodScore(source=source, method=m, strength=float(strength[i]),
                    ci_low=float(strength[i] - Z95 * se[i]), ci_high=float(strength[i] + Z95 * se[i]),
                    elo=float(ELO_MEAN + ELO_PER_UNIT * strength[i]),
                    comparisons=int(games[i].sum()), wins=int(wins[i].sum()))
        for i, m in enumerate(methods)
    ]
    return sorted(scores, key=lambda s: (-round(s.strength, 12), s.method))
