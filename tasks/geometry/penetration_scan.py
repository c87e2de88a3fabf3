"""Penetration scans along one joint for :mod:`asset2sim.tasks.geometry.limits`. Depths in m, positions
in rad or m; ``session`` a :class:`~asset2sim.engines.base.SimSession` answering ``link_distances``.
"""

from __future__ import annotations

import numpy as np

#: Deepest penetration increase (m) over the baseline that ends the free range.
EXCESS_TOLERANCE = 0.001
#: Excess (m) under which a contact has not yet begun (:func:`contact_onset`).
ONSET_TOLERANCE = 0.0002
#: Samples over the raw range on each side of the closed end.
SCAN_SAMPLES = 48
#: Bisection halvings between the last free and the first blocked sample.
BISECTIONS = 7


def collision_pairs(session, sub: list[str], against: set[str] | None = None) -> list[tuple[str, str]]:
    """(link of ``sub``, other link) pairs, both with collision geometry,
    the other one in ``against`` when given; session link order."""
    subset = set(sub)
    a = [n for n in sub if session.link_has_collision(n)]
    b = [n for n in session.link_names if n not in subset and session.link_has_collision(n) and (against is None or n in against)]
    return [(x, y) for x in a for y in b]


def pair_depths(session, pairs: list[tuple[str, str]]) -> np.ndarray:
    """Deepest penetration (m, >= 0) of each pair at the current state."""
    out = np.zeros(len(pairs))
    for i, (x, y) in enumerate(pairs):
        d = session.link_distances(x, y, 0.0)
        if d:
            out[i] = max(0.0, -min(d))
    return out


def _excess(session, joint: str, q: float, pairs: list[tuple[str, str]], baseline: np.ndarray) -> np.ndarray:
    """Each pair's depth over ``baseline`` (P,) m with ``joint`` at ``q``."""
    session.set_joint_positions({joint: q})
    return pair_depths(session, pairs) - baseline


def free_end(session, joint: str, q_from: float, q_to: float, pairs: list[tuple[str, str]], baseline: np.ndarray,
             samples: int = SCAN_SAMPLES, stop_depth: float | None = None) -> tuple[float, str | None]:
    """(free end, the link run into) of ``joint`` from ``q_from`` towards ``q_to``: the first sample whose
    excess over ``baseline`` ((P,) m) reaches ``stop_depth`` (:data:`EXCESS_TOLERANCE` when None) is in a stop;
    the last sample before it with excess <= :data:`EXCESS_TOLERANCE`, refined by bisection, is the free end. (``q_to``, None)
    when no sample reaches ``stop_depth``."""
    tol = EXCESS_TOLERANCE
    stop = tol if stop_depth is None else max(stop_depth, tol)
    qs = [q_from + (q_to - q_from) * k / samples for k in range(samples + 1)]
    exc_max: list[float] = []
    hit = None
    for k, q in enumerate(qs):
        exc_max.append(float(_excess(session, joint, q, pairs, baseline).max(initial=0.0)))
        if k > 0 and exc_max[-1] >= stop:
            hit = k
            break
    if hit is None:
        return float(q_to), None
    k = hit
    while k > 0 and exc_max[k - 1] > tol:
        k -= 1
    if k == 0:
        return float(q_from), None
    lo, hi = qs[k - 1], qs[k]
    worst = pairs[int(np.argmax(_excess(session, joint, hi, pairs, baseline)))][1]
    for _ in range(BISECTIONS):
        mid = 0.5 * (lo + hi)
        e = _excess(session, joint, mid, pairs, baseline)
        if float(e.max(initial=0.0)) > tol:
            hi, worst = mid, pairs[int(np.argmax(e))][1]
        else:
            lo = mid
    return float(lo), worst


def contact_onset(session, joint: str, q_end: float, q_free: float, pairs: list[tuple[str, str]], baseline: np.ndarray,
                  max_back: float) -> float:
    """Where the contact ending the free range at ``q_end`` begins: the first of 8 positions back
    towards ``q_free``, at most ``max_back`` away, with excess <= :data:`ONSET_TOLERANCE` m; else ``q_end`` moved ``max_back`` back."""
    sgn = 1.0 if q_free > q_end else -1.0
    back = min(max_back, abs(q_free - q_end))
    for k in range(1, 9):
        q = q_end + sgn * back * k / 8
        if float(_excess(session, joint, q, pairs, baseline).max(initial=0.0)) <= ONSET_TOLERANCE:
            return float(q)
    return float(q_end + sgn * back)


def depth_scan(session, joint: str, pairs: list[tuple[str, str]], lo: float, hi: float, q_extra: float,
               samples: int) -> tuple[np.ndarray, np.ndarray]:
    """Positions (n,) (``samples`` + 1 over [``lo``, ``hi``] and ``q_extra``, sorted, unique) and the
    depth (n, P) m of each pair at each."""
    qs = np.unique(np.concatenate([np.linspace(lo, hi, samples + 1), [q_extra]]))
    depth = []
    for q in qs:
        session.set_joint_positions({joint: q})
        depth.append(pair_depths(session, pairs))
    return qs, np.array(depth)
