"""State refinement in the simulator (SPEC stage 3).

Solves, within each joint's allowed interval,

    min_q  Phi(q) + lambda * sum_j ((q_j - q_req_j) / R_j)^2

where Phi(q) (m) is the self-penetration score of the SPEC measured in
PyBullet (sum over self-contact points of max(0, -separation); queried per link pair
with ``getClosestPoints`` so that no value depends on contact points Bullet
cached at earlier states of the session; pairs that did not move since
their last query are not re-queried: :mod:`~asset2sim.tasks.state.penetration`), q_req the
requested state projected onto the intervals, R_j the joint's opening range
(so deviations are measured as fractions of the range) and lambda (m) the
trade-off (``RefineConfig.state_lambda``). The allowed interval of a joint is
its requested band (``schemas.request.BAND_INTERVAL``, as opening fractions
from the geometric closed end) intersected with its limits, so the search
never drifts to a state that contradicts the request.

Search, in the order the SPEC describes: start from q_req; while Phi >
tolerance: group penetrations by link pair, map the worst pairs to the joints
on the kinematic path between the two links (focus joints), line-search each
focus joint over its interval and accept only decreases of the objective;
then random perturbations of the focus joints; then a coordinate pattern
search with shrinking steps around the best state. The lowest-objective state
found is returned. A contact query after setting joint states costs tens of
microseconds here, so thousands of candidates are affordable
(``RefineConfig.max_state_evaluations``).
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from asset2sim.schemas.asset import AssetDescription
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


def allowed_intervals(
    closed: dict[str, ClosedState], fractions: dict[str, tuple[float, float]]
) -> dict[str, Interval]:
    """Positions allowed per joint: the band's opening fractions mapped through
    the closed state and clipped to the limits (``closed`` in output units)."""
    out = {}
    for name, cs in closed.items():
        f0, f1 = fractions.get(name, (0.0, 0.03))
        a, b = cs.position(f0), cs.position(f1)
        out[name] = Interval(min(a, b), max(a, b))
    return out


def joints_in_the_way(asset: AssetDescription, worst_pairs: list[dict], bands: dict[str, str], addressed: set[str],
                      tolerance: float) -> list[str]:
    """Joints the request did not address (``addressed``: the joints a phrase
    of the request set; the others are closed by default, band "closed") on
    the kinematic path of a link pair that penetrates deeper than
    ``tolerance`` (m) and on whose path the request opened a joint (band
    other than "closed"): the parts in the way of a requested opening. A
    toilet's seat asked fully open lies through the lid closed by default; a
    person who opens the seat has opened the lid first. First-seen order.

    Args:
        worst_pairs: :attr:`~asset2sim.schemas.report.StateRefinement.worst_pairs`
            (``link_a``, ``link_b``, ``depth_m`` in m).
        bands: joint -> band name of the search.
    """
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
    """Movable joints on the kinematic path between two links (from
    ``link_a`` up, then from ``link_b`` up:
    :func:`asset2sim.tasks.geometry.closed_state.tree_path`)."""
    from_a, from_b = tree_path(asset.joints, link_a, link_b)
    return [j.name for j in from_a + from_b if j.is_movable]


def refine_initial_state(
    session,
    asset: AssetDescription,
    closed: dict[str, ClosedState],
    requested: dict[str, float],
    fractions: dict[str, tuple[float, float]],
    *,
    tolerance: float = 1e-4,
    lam: float = 0.05,
    max_evaluations: int = 4000,
    seed: int = 0,
    proposer=None,
) -> StateRefinement:
    """Lowest-objective state near ``requested`` (see module docstring).

    Args:
        session: fixed-base PyBullet session of the *output* (scaled) URDF.
        asset: the input description (kinematic tree, link names).
        closed: closed states in output units (prismatic in metres).
        requested: joint -> requested position (output units).
        fractions: joint -> allowed opening-fraction interval (band).
        tolerance: Phi (m) at which the search stops.
        lam: lambda (m per squared fraction of range).
        max_evaluations: budget of contact queries.
        seed: random seed of the perturbation phase.
        proposer: optional ``proposer(state, worst_pairs, intervals) ->
            (list of {joint: value}, queries)`` asked once when the local search
            stalls above ``tolerance`` (a model backend); each proposal is
            clipped to the intervals and accepted only if it lowers the
            objective.

    Returns:
        :class:`~asset2sim.schemas.report.StateRefinement` (Phi in m).
    """
    t0 = time.perf_counter()
    rng = np.random.default_rng(seed)
    names = [n for n in session.joint_names if n in closed]
    box = allowed_intervals({n: closed[n] for n in names}, fractions)
    q_req = {n: box[n].clip(requested.get(n, closed[n].q_closed)) for n in names}
    scale = {n: max(closed[n].open_range, 1e-9) for n in names}
    s = _Search(session, asset, names, box, q_req, scale, lam, tolerance, max_evaluations)
    phi_req = s.best_phi
    worst = [
        {"link_a": c.link_a, "link_b": c.link_b, "depth_m": c.depth, "max_depth_m": c.max_depth, "points": c.points}
        for c in s.pairs_at_best()[:5]
    ]
    _line_search_focus_joints(s)
    _perturb_focus_joints(s, rng)
    _pattern_search(s)
    model_queries = _ask_proposer(s, proposer) if proposer is not None and s.best_phi > tolerance else 0
    session.set_joint_positions(s.best_q)
    return StateRefinement(
        requested={k: float(v) for k, v in q_req.items()},
        result={k: float(v) for k, v in s.best_q.items()},
        phi_requested=float(phi_req),
        phi_result=float(s.best_phi),
        evaluations=s.evals,
        method=" -> ".join(s.method),
        worst_pairs=worst,
        seconds=time.perf_counter() - t0,
        model_queries=model_queries,
    )


class _Search:
    """The search's state: the best candidate so far (``best_q``, objective
    ``best_f`` in m, ``best_phi`` in m), the evaluations made and the phases
    that improved (``method``). Starts by evaluating ``q_req``."""

    def __init__(self, session, asset: AssetDescription, names: list[str], box: dict[str, Interval],
                 q_req: dict[str, float], scale: dict[str, float], lam: float, tolerance: float, max_evaluations: int):
        self.session, self.names, self.box, self.q_req, self.scale = session, names, box, q_req, scale
        self.lam, self.tolerance, self.max_evaluations = lam, tolerance, max_evaluations
        self.asset = asset
        self.evals = 0
        if hasattr(session, "self_penetration_fresh"):
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
        reg = sum(((q[n] - self.q_req[n]) / self.scale[n]) ** 2 for n in self.names)
        return phi + self.lam * reg, phi

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
        """Movable joints on the paths between the links of the 3 worst pairs at the best state."""
        out: list[str] = []
        for c in self.pairs_at_best()[:3]:
            for j in path_joints(self.asset, c.link_a, c.link_b):
                if j in self.box and self.box[j].width > 0 and j not in out:
                    out.append(j)
        return out

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
            sigma = 0.25 * s.box[j].width
            cand[j] = s.box[j].clip(s.best_q[j] + rng.normal(0.0, sigma))
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
        if improved:
            improved_any = True
        else:
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
        cand = dict(s.best_q)
        for n, v in prop.items():
            if n in s.box:
                cand[n] = s.box[n].clip(float(v))
        accepted += s.accept(cand)
    s.method.append(f"model proposals ({len(proposals)} asked, {accepted} accepted)")
    return model_queries
