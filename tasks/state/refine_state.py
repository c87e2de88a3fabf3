"""State refinement in the simulator (SPEC stage 3): within each joint's allowed
interval (requested band within its limits), minimise

    Phi(q) + lambda * sum_j ((q_j - q_req_j) / R_j)^2

Phi (m) the self-penetration score, q_req the requested state, R_j the
joint's opening range, lambda (m) the trade-off: line searches of the joints
on the worst pairs' paths, random perturbations, a pattern search.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from asset2sim.schemas.asset import AssetDescription
from asset2sim.schemas.config import RefineConfig
from asset2sim.schemas.report import StateRefinement
from asset2sim.tasks.geometry.closed_state import ClosedState, tree_path
from asset2sim.tasks.state.penetration import StatePenetration


@dataclass
class Interval:
    """Allowed positions of one joint (output units)."""

    lo: float
    hi: float

    @property
    def width(self) -> float:
        return self.hi - self.lo

    def clip(self, q: float) -> float:
        return float(min(max(q, self.lo), self.hi))


def allowed_intervals(closed: dict[str, ClosedState], fractions: dict[str, tuple[float, float]]) -> dict[str, Interval]:
    """Positions allowed per joint: the band's opening fractions mapped through
    the closed state and clipped to the limits (``closed`` in output units)."""
    return {name: Interval(*sorted(map(cs.position, fractions.get(name, (0.0, 0.03))))) for name, cs in closed.items()}


def joints_in_the_way(asset: AssetDescription, worst_pairs: list[dict], bands: dict[str, str], addressed: set[str],
                      tolerance: float) -> list[str]:
    """Joints the request did not address (``addressed``) and left closed, on the kinematic path of a link pair penetrating
    deeper than ``tolerance`` (m) on which the request opened a joint: the parts in the way of a requested opening (a
    toilet's lid in the way of its seat), first-seen order. ``worst_pairs``: ``StateRefinement.worst_pairs``; ``bands``:
    joint -> band name."""
    out: list[str] = []
    for pair in worst_pairs:
        if not float(pair["depth_m"]) > tolerance:
            continue
        path = path_joints(asset, pair["link_a"], pair["link_b"])
        if not any(j in addressed and bands.get(j, "closed") != "closed" for j in path):
            continue
        out.extend(j for j in path if j not in addressed and bands.get(j, "closed") == "closed" and j not in out)
    return out


def path_joints(asset: AssetDescription, link_a: str, link_b: str) -> list[str]:
    """Movable joints on the kinematic path between two links (from ``link_a`` up, then from ``link_b`` up)."""
    from_a, from_b = tree_path(asset.joints, link_a, link_b)
    return [j.name for j in from_a + from_b if j.is_movable]


def refine_initial_state(session, asset: AssetDescription, closed: dict[str, ClosedState], requested: dict[str, float],
                         fractions: dict[str, tuple[float, float]], config: RefineConfig | None = None, *,
                         proposer=None, opened: frozenset[str] = frozenset()) -> StateRefinement:
    """Lowest-objective state near ``requested`` (module docstring) as a
    :class:`~asset2sim.schemas.report.StateRefinement` (Phi in m).

    Args:
        session: fixed-base PyBullet session of the output (scaled) URDF.
        closed, requested: closed states and joint -> requested position, output units.
        fractions: joint -> allowed opening-fraction interval (band).
        config: the search's knobs: ``penetration_tolerance`` (Phi, m, at which the search stops),
            ``state_lambda`` (lambda, m per squared fraction of range), ``max_state_evaluations`` (budget of
            contact queries) and ``seed`` (of the perturbation phase); default ``RefineConfig()``.
        proposer: optional ``proposer(state, worst_pairs, intervals) -> (list of
            {joint: value}, queries)``, asked once when the search stalls above
            the tolerance; proposals are clipped and kept only if they improve.
        opened: joints the request opens (a band other than closed). Their line searches come first in each round,
            so that a part left closed leaves its closed end (where its stop holds it) only where the opened parts
            cannot clear alone: a suitcase's handle folded fully open comes to rest on the closed lid rather than
            lifting the lid 3 degrees off its stop, where only friction would hold it.
    """
    cfg = config or RefineConfig()
    t0 = time.perf_counter()
    names = [n for n in session.joint_names if n in closed]
    box = allowed_intervals({n: closed[n] for n in names}, fractions)
    q_req = {n: box[n].clip(requested.get(n, closed[n].q_closed)) for n in names}
    scale = {n: max(closed[n].open_range, 1e-9) for n in names}
    s = _Search(session, asset, names, box, q_req, scale, cfg, opened)
    phi_req = s.best_phi
    worst = [{"link_a": c.link_a, "link_b": c.link_b, "depth_m": c.depth, "max_depth_m": c.max_depth, "points": c.points}
             for c in s.pairs_at_best()[:5]]
    _line_search_focus_joints(s)
    _perturb_focus_joints(s, np.random.default_rng(cfg.seed))
    _pattern_search(s)
    model_queries = _ask_proposer(s, proposer) if proposer is not None and s.best_phi > s.tolerance else 0
    session.set_joint_positions(s.best_q)
    return StateRefinement(requested={k: float(v) for k, v in q_req.items()}, result={k: float(v) for k, v in s.best_q.items()},
                           phi_requested=float(phi_req), phi_result=float(s.best_phi), evaluations=s.evals,
                           method=" -> ".join(s.method), worst_pairs=worst, seconds=time.perf_counter() - t0,
                           model_queries=model_queries)


class _Search:
    """The search's state: the best candidate (``best_q``, ``best_f``, ``best_phi``,
    m), evaluations made, phases that improved (``method``); its knobs from ``cfg`` (:func:`refine_initial_state`)."""

    def __init__(self, session, asset: AssetDescription, names: list[str], box: dict[str, Interval],
                 q_req: dict[str, float], scale: dict[str, float], cfg: RefineConfig, opened: frozenset[str]):
        self.session, self.asset, self.names, self.box, self.q_req, self.scale, self.opened = (session, asset, names, box, q_req,
                                                                                              scale, opened)
        self.lam, self.tolerance, self.max_evaluations = cfg.state_lambda, cfg.penetration_tolerance, cfg.max_state_evaluations
        self.evals = 0
        if session.traits.incremental_penetration:
            # the same Phi as the engine's fresh query, re-queried only for moved pairs
            self.penetration = StatePenetration(session, asset, names)
        else:
            self.penetration = lambda q: session.self_penetration()  # noqa: E731
        self.best_q = dict(q_req)
        self.best_f, self.best_phi = self.objective(self.best_q)
        self.method = ["requested state"]

    def objective(self, q: dict[str, float]) -> tuple[float, float]:
        """(objective, Phi), both m, at ``q`` (counts one evaluation)."""
        self.evals += 1
        self.session.set_joint_positions(q)
        phi, _ = self.penetration(q)
        return phi + self.lam * sum(((q[n] - self.q_req[n]) / self.scale[n]) ** 2 for n in self.names), phi

    def accept(self, cand: dict[str, float]) -> bool:
        """Evaluate ``cand``; True (and it becomes the best) when it lowers the objective."""
        f, phi = self.objective(cand)
        if f < self.best_f - 1e-12:
            self.best_q, self.best_f, self.best_phi = cand, f, phi
            return True
        return False

    def budget(self) -> bool:
        return self.evals < self.max_evaluations and self.best_phi > self.tolerance

    def pairs_at_best(self) -> list:
        """Penetrating link pairs at the best state, deepest first."""
        self.session.set_joint_positions(self.best_q)
        return self.penetration(self.best_q)[1]

    def focus_joints(self) -> list[str]:
        """Movable joints on the paths between the links of the 3 worst pairs at the best state, the opened ones
        first (each group in path order)."""
        # in first-seen order
        out = dict.fromkeys(j for c in self.pairs_at_best()[:3] for j in path_joints(self.asset, c.link_a, c.link_b)
                            if j in self.box and self.box[j].width > 0)
        return sorted(out, key=lambda j: j not in self.opened)

    def movable(self) -> list[str]:
        return [n for n in self.names if self.box[n].width > 0]


def _line_search_focus_joints(s: _Search) -> None:
    """Phase 1: up to 6 rounds of 25-point line searches of each focus joint over its interval."""
    for _round in range(6):
        if not s.budget():
            break
        focus = s.focus_joints()
        if not focus:
            break
        improved = False
        for j in focus:
            if not s.budget():
                break
            for q in np.linspace(s.box[j].lo, s.box[j].hi, 25):
                improved |= s.accept({**s.best_q, j: float(q)})
        if improved:
            s.method.append("focus-joint line search")
        else:
            break


def _perturb_focus_joints(s: _Search, rng: np.random.Generator) -> None:
    """Phase 2: up to 400 Gaussian perturbations (sigma a quarter of the
    interval) of the focus joints (all movable joints when none)."""
    if not s.budget():
        return
    focus = s.focus_joints() or s.movable()
    improved = False
    for _ in range(min(400, s.max_evaluations - s.evals)):
        if not s.budget():
            break
        cand = dict(s.best_q)
        for j in focus:
            # sigma a quarter of the interval
            cand[j] = s.box[j].clip(s.best_q[j] + rng.normal(0.0, 0.25 * s.box[j].width))
        improved |= s.accept(cand)
    if improved:
        s.method.append("random perturbations")


def _pattern_search(s: _Search) -> None:
    """Phase 3: coordinate pattern search around the best state, steps from a
    quarter of each interval halved while nothing improves."""
    if not s.budget():
        return
    movable = s.movable()
    steps = {n: 0.25 * s.box[n].width for n in movable}
    improved_any = False
    while s.budget() and movable and max(steps.values()) > 1e-4 * max(s.box[n].width for n in movable):
        improved = False
        for j in movable:
            for sgn in (1.0, -1.0):
                if not s.budget():
                    break
                improved |= s.accept({**s.best_q, j: s.box[j].clip(s.best_q[j] + sgn * steps[j])})
        improved_any |= improved
        if not improved:
            steps = {n: v * 0.5 for n, v in steps.items()}
    if improved_any:
        s.method.append("local pattern search")


def _ask_proposer(s: _Search, proposer) -> int:
    """Phase 4, when the search stalls: the proposer's states (clipped to the
    intervals), each kept only if it improves; returns its model queries."""
    worst_now = [{"link_a": c.link_a, "link_b": c.link_b, "depth_m": c.depth} for c in s.pairs_at_best()[:5]]
    model_queries = 0
    try:
        proposals, model_queries = proposer(dict(s.best_q), worst_now, {n: (s.box[n].lo, s.box[n].hi) for n in s.names})
    except Exception as exc:  # a failed model call must not lose the search result
        proposals = []
        s.method.append(f"model proposals failed: {type(exc).__name__}")
    accepted = 0
    for prop in proposals:
        accepted += s.accept({**s.best_q, **{n: s.box[n].clip(float(v)) for n, v in prop.items() if n in s.box}})
    s.method.append(f"model proposals ({len(proposals)} asked, {accepted} accepted)")
    return model_queries
