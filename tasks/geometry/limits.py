"""Joint limits clipped to what the geometry allows. The method (pairs and baselines, excess, stops,
contact onset, the ``chain_open`` scan of the carrying chain) is in ``docs/design/metrics.md``, before
the post-check; tolerances :data:`~asset2sim.tasks.geometry.penetration_scan.EXCESS_TOLERANCE`,
:data:`STOP_DEPTH`, :data:`MIN_CLIP_FRACTION`, :data:`MIN_FREE_FRACTION`; the scans are in
:mod:`asset2sim.tasks.geometry.penetration_scan`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from asset2sim.schemas.overlay import Overlay
from asset2sim.tasks.geometry.closed_state import subtree_links
from asset2sim.tasks.geometry.penetration_scan import (EXCESS_TOLERANCE, SCAN_SAMPLES, collision_pairs, contact_onset, depth_scan,
                                                       free_end, pair_depths)
from asset2sim.urdf import UrdfModel

#: Excess (m) a contact must reach on the way to be a stop: the sweep's 5 mm self-penetration bound.
STOP_DEPTH = 0.005
#: Farthest a clipped far end is moved back to the contact's onset, as a fraction of the opening range.
BACK_OFF_FRACTION = 0.1
#: A side is clipped only when the geometric end is inside the raw range by more than this fraction of it.
MIN_CLIP_FRACTION = 0.01
#: Below this fraction of the raw opening range the part is blocked at its closed end; the limit is kept.
MIN_FREE_FRACTION = 0.05


@dataclass
class LimitClip:
    """Geometric limits of one joint (rad or m at the session's scale)."""

    joint: str
    raw_lower: float
    raw_upper: float
    lower: float
    upper: float
    q_closed: float
    direction: float
    open_range: float  # from q_closed to the (clipped) far end, rad or m
    blocked_by: str | None = None  # the link the moving part runs into on the opening side (None: free)
    notes: list[str] = field(default_factory=list)

    @property
    def clipped(self) -> bool:
        """True when either side was clipped."""
        return self.lower != self.raw_lower or self.upper != self.raw_upper


def subtrees(model: UrdfModel) -> dict[str, list[str]]:
    """Movable joint -> the links it moves (its child and every link below, :func:`subtree_links`)."""
    return {j.name: subtree_links(model, j.child) for j in model.movable_joints}


def rigid_group(model: UrdfModel, link: str) -> set[str]:
    """``link`` and every link joined to it by fixed joints only (either way)."""
    out, stack = {link}, [link]
    while stack:
        ln = stack.pop()
        for j in model.joints:
            if j.type != "fixed":
                continue
            for a, b in ((j.parent, j.child), (j.child, j.parent)):
                if a == ln and b not in out:
                    out.add(b)
                    stack.append(b)
    return out


@dataclass(frozen=True, slots=True)
class _ChainEnd:
    """Where a part carried by a chain stops with the chain open (:func:`_chain_far_end`): ``far`` (rad or m, at
    the contact's onset), ``who`` (the link run into; None when the chain does not end the range) and ``opened``
    (the chain's joints opened)."""

    far: float
    who: str | None
    opened: list[str]


def _chain_far_end(session, model: UrdfModel, name: str, sub: list[str], closed: dict[str, tuple[float, float, float]],
                   state: dict[str, float], q_close: float, far_raw: float, range_: float) -> _ChainEnd:
    """The chain scan (``chain_open``): the far end, or ``far_raw`` run into nothing when the chain does not end
    the range or the part cannot open from ``q_close`` even then. The session is left at ``state`` with ``name``
    at ``q_close``."""
    parent_of, home = {j.child: j for j in model.joints}, model.joint(name).parent
    # the chain: the ancestors of the joint's parent beyond its rigid group (a stapler's base for the magazine hinged
    # on the top)
    chain, ln = set(), home
    while ln in parent_of:
        ln = parent_of[ln].parent
        chain |= rigid_group(model, ln)
    pairs = collision_pairs(session, sub, chain - rigid_group(model, home) - set(sub))
    none = _ChainEnd(float(far_raw), None, [])
    if not pairs:
        return none
    opened, ln = {}, home
    while ln in parent_of:
        j = parent_of[ln]
        if j.name in closed and j.name in session.joint_limits:
            kc, kd, kr = closed[j.name]
            if kr > 0:
                opened[j.name] = kc + kd * kr
        ln = j.parent
    if not opened:
        return none
    try:
        session.set_joint_positions({**state, **opened, name: q_close})
        _, depth = depth_scan(session, name, pairs, *sorted((q_close, far_raw)), q_close, SCAN_SAMPLES)
        base = depth.min(axis=0)
        session.set_joint_positions({name: q_close})
        if float((pair_depths(session, pairs) - base).max(initial=0.0)) > EXCESS_TOLERANCE:
            return none  # not free at its closed end even with the chain open: the sweep's finding
        far, who = free_end(session, name, q_close, far_raw, pairs, base, SCAN_SAMPLES, STOP_DEPTH)
        if who is None or abs(far - q_close) < MIN_FREE_FRACTION * range_:
            return none
        far = contact_onset(session, name, far, q_close, pairs, base, BACK_OFF_FRACTION * range_)
        return _ChainEnd(float(far), who, sorted(opened))
    finally:
        session.set_joint_positions({**state, name: q_close})


def geometric_limits(session, model: UrdfModel, closed: dict[str, tuple[float, float, float]],
                     state: dict[str, float]) -> dict[str, LimitClip]:
    """Geometric limits of every joint of ``closed`` (module docstring): each joint's range against the links
    rigid with its parent (:func:`rigid_group`) and, for a part carried by a chain of other parts (a stapler's
    magazine hinged on its top), against the chain's links with the chain's joints at the state and open
    (``chain_open``): a limit the part reaches in neither is clipped where it meets them.

    Args:
        session, model: a fixed-base :class:`~asset2sim.engines.base.SimSession` of the URDF ``model``.
        closed: joint -> (q_closed, direction +-1, open range), rad or m, at the session's scale.
        state: joint -> position (rad or m) the other joints hold (the sweep's start state).

    Returns:
        joint -> :class:`LimitClip` (continuous joints and joints not in the session are left out).
        The session is left at ``state``.
    """
    subs = subtrees(model)
    adjacent = model.adjacent_pairs()
    out: dict[str, LimitClip] = {}
    for name, (qc, d, rng) in closed.items():
        if name not in session.joint_limits or not rng > 0:
            continue
        lo, hi = session.joint_limits[name]
        if not (np.isfinite(lo) and np.isfinite(hi)):
            continue
        session.set_joint_positions({**state, name: qc})
        sub = subs.get(name, [session.joint_child[name]])
        pairs = collision_pairs(session, sub, rigid_group(model, model.joint(name).parent) - set(sub))
        out[name] = _raw_clip(name, lo, hi, qc, d, rng)
        if pairs:
            out[name] = _JointScan(session, name, lo, hi, qc, d, rng, pairs).clip(out[name], model, sub, adjacent, closed, state)
    session.set_joint_positions(state)
    return out


def _raw_clip(name: str, lo: float, hi: float, qc: float, d: float, rng: float, **kw) -> LimitClip:
    """A :class:`LimitClip` that keeps the raw limits [``lo``, ``hi``]."""
    return LimitClip(joint=name, raw_lower=float(lo), raw_upper=float(hi), lower=float(lo), upper=float(hi),
                     q_closed=float(qc), direction=float(d), open_range=float(rng), **kw)


def _limit_note(side: str, raw: float, new: float, tail: str) -> str:
    """The note of one clipped limit (``side``: "upper" or "lower")."""
    return f"{side} limit {raw:.4g} -> {new:.4g} ({abs(raw - new):.3g} clipped{tail}"


@dataclass
class _JointScan:
    """The scans of one joint (raw limits, closed end ``qc``, direction ``d``, range ``rng``, rad or m)
    against ``pairs``; ``base`` their baseline depths (P,) m once measured."""

    session: object
    name: str
    lo: float
    hi: float
    qc: float
    d: float
    rng: float
    pairs: list[tuple[str, str]]
    base: np.ndarray | None = None

    def free_end(self, q_from: float, q_to: float, stop_depth: float | None = None,
                 samples: int = SCAN_SAMPLES) -> tuple[float, str | None]:
        """:func:`free_end` of the joint from ``q_from`` towards ``q_to``."""
        return free_end(self.session, self.name, q_from, q_to, self.pairs, self.base, samples, stop_depth)

    def onset(self, q_end: float, q_free: float) -> float:
        """:func:`contact_onset`, at most ``BACK_OFF_FRACTION`` of the range back from ``q_end``."""
        return contact_onset(self.session, self.name, q_end, q_free, self.pairs, self.base, BACK_OFF_FRACTION * self.rng)

    def clips(self, raw: float, end: float) -> bool:
        """Whether ``end`` lies inside the raw limit ``raw`` by more than ``MIN_CLIP_FRACTION`` of the range."""
        return abs(raw - end) > MIN_CLIP_FRACTION * self.rng

    def clip(self, clip: LimitClip, model: UrdfModel, sub: list[str], adjacent: set[frozenset[str]],
             closed: dict[str, tuple[float, float, float]], state: dict[str, float]) -> LimitClip:
        """``clip`` with the clipped limits, or the raw limits with a note (``adjacent``: the parent-child link pairs)."""
        qs, depth = depth_scan(self.session, self.name, self.pairs, self.lo, self.hi, self.qc, SCAN_SAMPLES)
        k_c = int(np.flatnonzero(qs == self.qc)[0])
        # baseline: a parent-child pair's depth at the closed end; any other pair's least over the range
        self.base = np.where([frozenset(p) in adjacent for p in self.pairs], depth[k_c], depth.min(axis=0))
        q_close = self.closed_end(clip, qs, depth, k_c)
        if q_close is None:
            return clip
        far_raw, back_raw = (self.hi, self.lo) if self.d > 0 else (self.lo, self.hi)
        self.session.set_joint_positions({self.name: q_close})
        far, who = self.free_end(q_close, far_raw, STOP_DEPTH)
        span = abs(far - q_close)
        if span < MIN_FREE_FRACTION * self.rng:
            clip.notes.append(f"blocked at its closed end by {who} (free {span:.3g} of {self.rng:.3g}): collision geometry, limit kept")
            clip.blocked_by = who
            clip.notes = clip.notes[-1:]
            return clip
        chain_end = _chain_far_end(self.session, model, self.name, sub, closed, state, q_close, far_raw, self.rng)
        far, who = self.far_end(clip, far, who, q_close, far_raw, chain_end)
        back = self.back_end(clip, q_close, back_raw)
        clip.lower, clip.upper = (back, far) if self.d > 0 else (far, back)
        clip.q_closed, clip.open_range = q_close, abs(far - q_close)
        q0 = state.get(self.name)
        if q0 is not None and not clip.lower <= q0 <= clip.upper:
            # the refined state lies beyond the free range: the hulls, not the limit, disagree; keep the raw limit
            return _raw_clip(self.name, self.lo, self.hi, self.qc, self.d, self.rng, blocked_by=who,
                             notes=[f"not clipped: the initial state {q0:.4g} lies beyond the free range "
                                    f"[{clip.lower:.4g}, {clip.upper:.4g}] (hull overlap, not the limit)"])
        return clip

    def closed_end(self, clip: LimitClip, qs: np.ndarray, depth: np.ndarray, k_c: int) -> float | None:
        """``qc``, or where the part first comes free towards the opening side; None when it never does."""
        free = (depth - self.base).max(axis=1) <= EXCESS_TOLERANCE
        if free[k_c]:
            return float(self.qc)
        # the closed end itself pushes into another link: first free sample towards the opening side
        step = 1 if self.d > 0 else -1
        k = k_c
        while 0 <= k < len(qs) and not free[k]:
            k += step
        if not 0 <= k < len(qs):
            clip.notes.append("penetrates other links over its whole range: collision geometry, limit kept")
            return None
        q_close, who_c = self.free_end(float(qs[k]), self.qc, samples=4)
        clip.notes.append(f"closed end {self.qc:.4g} -> {q_close:.4g}: at {self.qc:.4g} it runs into {who_c}")
        return q_close

    def far_end(self, clip: LimitClip, far: float, who: str | None, q_close: float, far_raw: float,
                chain_end: _ChainEnd) -> tuple[float, str | None]:
        """(limit on the opening side, the link run into): the chain's end when nearer, else
        ``far`` at its contact's onset when it clips ``far_raw``, else ``far_raw``."""
        side = "upper" if self.d > 0 else "lower"
        far_c, who_c, opened = chain_end.far, chain_end.who, chain_end.opened
        if who_c is not None and (far_c - far) * self.d < 0 and self.clips(far_raw, far_c):
            if self.clips(far_raw, far):  # the parent's stop, at its onset, may still be nearer
                far_s = self.onset(far, q_close)
                if (far_s - far_c) * self.d < 0:
                    far_c, who_c, opened = far_s, who, []
            clip.blocked_by = who_c
            clip.notes.append(_limit_note(side, far_raw, far_c, f"): runs into {who_c}"
                                          + (f" even with {', '.join(opened)} open" if opened else "")))
            return far_c, who_c  # the chain's end, already at its onset
        if self.clips(far_raw, far):
            far = self.onset(far, q_close)
            clip.blocked_by = who
            clip.notes.append(_limit_note(side, far_raw, far, f"): runs into {who}"))
            return far, who
        return float(far_raw), who

    def back_end(self, clip: LimitClip, q_close: float, back_raw: float) -> float:
        """The limit beyond the closed end: the new closed end when it moved, else the
        free end towards ``back_raw`` at its contact's onset when it clips, else ``back_raw``."""
        side = "lower" if self.d > 0 else "upper"
        back = float(back_raw)
        if q_close != self.qc:
            back = q_close
            clip.notes.append(_limit_note(side, back_raw, back, "): the new closed end"))
        elif self.clips(back_raw, self.qc):
            self.session.set_joint_positions({self.name: self.qc})
            b, who_b = self.free_end(self.qc, back_raw, STOP_DEPTH)
            if self.clips(back_raw, b):
                back = b = self.onset(b, self.qc)
                clip.notes.append(_limit_note(side, back_raw, b, f", beyond the closed end): runs into {who_b}"))
        elif back_raw != self.qc:  # a sliver past the closed end: the part meets its body there, which is the stop
            back = float(self.qc)
            clip.notes.append(_limit_note(side, back_raw, back, ", less than "
                                          f"{MIN_CLIP_FRACTION:.0%} of the range beyond the closed end): the closed end is the stop"))
        return back


def apply_clips(overlay: Overlay, clips: dict[str, LimitClip]) -> tuple[Overlay, list[str]]:
    """The overlay with the clipped limits of ``clips`` (``lower`` / ``upper``, ``limit_source``) and one
    note per clipped joint (also in ``overlay.notes.other``)."""
    ov = overlay.model_copy(deep=True)
    notes = []
    for name, c in clips.items():
        dyn = ov.joints.get(name)
        if dyn is None or not c.clipped:
            continue
        why = "; ".join(c.notes)
        ov.joints[name] = dyn.model_copy(update={
            "lower": c.lower if c.lower != c.raw_lower else dyn.lower,
            "upper": c.upper if c.upper != c.raw_upper else dyn.upper,
            "limit_source": f"clipped to the geometry (tasks.geometry.limits): {why}",
        })
        notes.append(f"joint {name}: {why}")
    if notes:
        ov.notes.other = list(ov.notes.other) + [f"limit clipped to the geometry: {n}" for n in notes]
    return ov, notes


def strip_clips(overlay: Overlay) -> Overlay:
    """The overlay without clipped limits: the raw limits are written again."""
    ov = overlay.model_copy(deep=True)
    for name, dyn in ov.joints.items():
        if dyn.lower is not None or dyn.upper is not None or dyn.limit_source:
            ov.joints[name] = dyn.model_copy(update={"lower": None, "upper": None, "limit_source": ""})
    ov.notes.other = [n for n in ov.notes.other if not n.startswith("limit clipped to the geometry: ")]
    return ov
