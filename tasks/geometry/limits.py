"""Joint limits clipped to what the geometry allows (issue 13; checked by the
joint sweep of issue 15, :mod:`asset2sim.tasks.check.sweep`).

A raw PartNet-Mobility limit can let a part swing or slide *into* its parent
or a sibling (a stapler arm through its base, a lid through its box). The
sweep drives each joint from its geometric closed end to 95 % of its range,
so such a range cannot be reached without penetration. This module finds the
geometric ends by a collision-aware scan, like
:mod:`asset2sim.tasks.geometry.closed_state` finds the closed end.

Method (per movable joint j with closed end q_c, opening direction d and
range R, other joints at the state the sweep starts from, a fixed-base,
gravity-free session at the output scale):

1. Pairs: (link of j's moving subtree, any other link with collision
   geometry), the parent included. Baseline b_p = the deepest penetration
   (m, >= 0) of pair p at q_c for a parent-child pair (a parent hull filling
   a door's cavity is the collision geometry's, not the limit's), and its
   least over the raw range for any other pair (the pairs the sweep
   measures; an overlap present everywhere, e.g. a part touching a wall it
   slides along, is the hulls'). A closed end where the excess (2.) is above
   tol moves to the first free state towards the opening side.
2. Excess e(q) = max_p (depth_p(q) - b_p), m.
3. Opening side: sample q = q_c + d R k / n, k = 1..n (n =
   :data:`SCAN_SAMPLES`); the first sample with e >= :data:`STOP_DEPTH`
   (5 mm, the sweep's bound: a stop) and, walking back from it, the last
   sample with e <= tol ends the free range (overlaps that never get 5 mm
   deeper are the hulls'); bisection (:data:`BISECTIONS` halvings) between it and the previous
   sample gives the geometric far end q_g. Closing side: the same from q_c
   towards the other raw limit.
4. When the refined initial state of j lies outside the free range found,
   the scan disagrees with a state the state search accepted (hull overlap):
   the limit is kept and a note says so.
5. The limit on that side becomes q_g when it lies inside the raw range by
   more than :data:`MIN_CLIP_FRACTION` of R, moved back to where the contact
   begins (excess <= :data:`ONSET_TOLERANCE`, at most
   :data:`BACK_OFF_FRACTION` of R back; :func:`contact_onset`): a
   force-limited drive stalls where the contact force balances it. When the free range is less than
   :data:`MIN_FREE_FRACTION` of R the part is blocked at its closed end: the
   collision geometry (not the limit) is wrong, and the limit is kept (the
   sweep reports the block).

6. A part hinged on a moving part (a stapler's magazine on its top arm,
   102990) can also meet the links of the chain that carries it beyond its
   parent's rigid group (the base): how far depends on the joints between.
   With those joints at their open ends (the most room the mechanism
   gives: a hand lifts the top before the magazine swings down to the base)
   the far end is scanned against the chain as in 3. (baseline: each pair's
   least depth over the raw range in that state); when it ends the range
   before the far end of 5., it becomes the limit: beyond it the part meets
   the chain in every state the mechanism reaches (the magazine's raw limit,
   2.83 rad from the top arm, swings it through the base whatever the top
   does; the joint sweep demanded that range and failed). A part that cannot
   open even then is left to the sweep. Only on request (``chain_open``):
   refine runs it where the joint sweep stopped short (stage 7b).

tol = :data:`EXCESS_TOLERANCE` (1 mm) decides whether the closed end is
pressed into another link (the sweep returns there and allows 5 mm) and
where a stop begins; the end is then put at the stop's onset (:data:`ONSET_TOLERANCE`), because the force-limited drive of
the sweep stalls where the contact begins. The scans and their constants are in
:mod:`asset2sim.tasks.geometry.penetration_scan`.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from asset2sim.schemas.overlay import Overlay
from asset2sim.tasks.geometry.penetration_scan import (
    EXCESS_TOLERANCE,
    SCAN_SAMPLES,
    collision_pairs,
    contact_onset,
    depth_scan,
    free_end,
    pair_depths,
)
from asset2sim.urdf import UrdfModel

#: Excess (m) a contact must reach somewhere on the way to be a stop: the
#: sweep's 5 mm self-penetration bound (an overlap that never gets deeper is
#: the hulls', not a limit's: toilet 102703's seat grows 5.7 -> 8.1 mm over
#: its whole 1.69 rad in the body's hinge piece, suitcase 103755's lid
#: 4.3 -> 7.6 mm; a plain 1 mm tolerance clipped them at 0.32 and 0.43 rad).
STOP_DEPTH = 0.005
#: Farthest a clipped far end is moved back from the tolerance crossing to
#: the contact's onset, as a fraction of the opening range (the 5 % the sweep
#: allows stay free of the contact).
BACK_OFF_FRACTION = 0.1
#: A side is clipped only when the geometric end is inside the raw range by
#: more than this fraction of the opening range (smaller differences are noise).
MIN_CLIP_FRACTION = 0.01
#: Below this fraction of the raw opening range the part is blocked at its
#: closed end: a collision-geometry defect, the limit is kept.
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
    open_range: float
    """opening range from q_closed to the (clipped) far end, rad or m"""
    blocked_by: str | None = None
    """the link the moving part runs into on the opening side (None: free)"""
    notes: list[str] = field(default_factory=list)

    @property
    def clipped(self) -> bool:
        """True when either side was clipped."""
        return self.lower != self.raw_lower or self.upper != self.raw_upper


def subtrees(model: UrdfModel) -> dict[str, list[str]]:
    """Movable joint -> the links it moves (its child and every link below)."""
    out = {}
    for j in model.movable_joints:
        links, stack = [], [j.child]
        while stack:
            ln = stack.pop()
            links.append(ln)
            stack.extend(c.child for c in model.children(ln))
        out[j.name] = links
    return out


def rigid_group(model: UrdfModel, link: str) -> set[str]:
    """``link`` and every link joined to it by fixed joints only (either way):
    the links that keep their pose relative to ``link`` whatever the movable
    joints do."""
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


def chain_links(model: UrdfModel, joint: str) -> set[str]:
    """The links of the chain that carries ``joint`` beyond its parent's
    rigid group (:func:`rigid_group`): its ancestors, posed by the movable
    joints between (a stapler's base for the magazine hinged on the top)."""
    parent_of = {j.child: j.parent for j in model.joints}
    jd = model.joint(joint)
    chain, ln = set(), parent_of.get(jd.parent)
    while ln is not None:
        chain |= rigid_group(model, ln)
        ln = parent_of.get(ln)
    return chain - rigid_group(model, jd.parent)


def _chain_far_end(session, model: UrdfModel, name: str, sub: list[str], closed: dict[str, tuple[float, float, float]],
                   state: dict[str, float], q_close: float, far_raw: float, tol: float, samples: int,
                   range_: float) -> tuple[float, str | None, list[str]]:
    """Step 6 of the module docstring: the far end of ``name`` against the
    links of its carrying chain (:func:`chain_links`) with the movable joints
    between (those of ``closed`` above its parent) at their open ends, moved
    back to the contact's onset (:func:`contact_onset`). Returns (far end,
    the link run into, the joints opened); (``far_raw``, None, ...) when the
    chain does not end the range or the part cannot open from ``q_close``
    even then. The session is left at ``state`` with ``name`` at ``q_close``."""
    pairs = collision_pairs(session, sub, chain_links(model, name) - set(sub))
    if not pairs:
        return float(far_raw), None, []
    parent_of = {j.child: j for j in model.joints}
    opened, ln = {}, model.joint(name).parent
    while ln in parent_of:
        j = parent_of[ln]
        if j.name in closed and j.name in session.joint_limits:
            kc, kd, kr = closed[j.name]
            if kr > 0:
                opened[j.name] = kc + kd * kr
        ln = j.parent
    if not opened:
        return float(far_raw), None, []
    try:
        session.set_joint_positions({**state, **opened, name: q_close})
        _, depth = depth_scan(session, name, pairs, *sorted((q_close, far_raw)), q_close, samples)
        base = depth.min(axis=0)
        session.set_joint_positions({name: q_close})
        if float((pair_depths(session, pairs) - base).max(initial=0.0)) > tol:
            return float(far_raw), None, []  # not free at its closed end even with the chain open: the sweep's finding
        far, who = free_end(session, name, q_close, far_raw, pairs, base, tol, samples, STOP_DEPTH)
        if who is None or abs(far - q_close) < MIN_FREE_FRACTION * range_:
            return float(far_raw), None, []
        far = contact_onset(session, name, far, q_close, pairs, base, BACK_OFF_FRACTION * range_)
        return float(far), who, sorted(opened)
    finally:
        session.set_joint_positions({**state, name: q_close})


def geometric_limits(session, model: UrdfModel, closed: dict[str, tuple[float, float, float]], state: dict[str, float],
                     tol: float = EXCESS_TOLERANCE, samples: int = SCAN_SAMPLES, against: str = "stops",
                     confirm_stops: bool = True, chain_open: bool = False) -> dict[str, LimitClip]:
    """Geometric limits of every joint of ``closed`` (see the module docstring).

    Args:
        session: a fixed-base :class:`~asset2sim.engines.base.SimSession` of
            the URDF ``model`` (any engine answering ``link_distances``).
        model: the same URDF (kinematic tree).
        closed: joint -> (q_closed, direction +-1, open range), rad or m, at the session's scale.
        state: joint -> position (rad or m) the other joints hold (the sweep's start state).
        tol: penetration excess (m) above which a closed end is pressed into another link.
        confirm_stops: a contact ends the range only when it is a stop (its
            excess reaches :data:`STOP_DEPTH` further on, :func:`free_end`);
            the end is then put at the contact's onset. False: any contact.
        samples: samples over the raw range.
        against: ``"stops"``: only the links rigid with the joint's parent
            (:func:`rigid_group`), whose geometry stops the part in every
            state of the other joints (the URDF limit), and on the opening
            side the links of the carrying chain with the joints between
            open (step 6, with ``chain_open``); ``"held"``: only the
            links of the chain that carries the joint beyond its parent's
            rigid group (its ancestors, posed by the held joints between:
            a stapler's base for the magazine hinged on the top), the range
            the joint sweep can demand with them held at ``state``; the far
            end only (a part that cannot shut is the sweep's finding), and
            siblings and other branches are not cut away (a part in the way
            is the sweep's finding too).
        chain_open: with ``against="stops"``, step 6 too (refine's repair
            of a sweep that stopped short, ``tasks/refine.py``: the scan is
            not run on every asset, whose later stages would then start from
            other ranges).

    Returns:
        joint -> :class:`LimitClip` (continuous joints and joints not in the session are left out).
        The session is left at ``state``.
    """
    subs = subtrees(model)
    parent_of = {j.child: j.parent for j in model.joints}
    out: dict[str, LimitClip] = {}
    for name, (qc, d, rng) in closed.items():
        if name not in session.joint_limits or not rng > 0:
            continue
        lo, hi = session.joint_limits[name]
        if not (np.isfinite(lo) and np.isfinite(hi)):
            continue
        session.set_joint_positions({**state, name: qc})
        sub = subs.get(name, [session.joint_child[name]])
        if against == "stops":
            pairs = collision_pairs(session, sub, rigid_group(model, model.joint(name).parent) - set(sub))
        else:  # the links of the chain that carries the joint: its ancestors beyond the parent's rigid group
            pairs = collision_pairs(session, sub, chain_links(model, name) - set(sub))
        out[name] = _raw_clip(name, lo, hi, qc, d, rng)
        if pairs:
            scan = _JointScan(session, name, lo, hi, qc, d, rng, pairs, tol, samples, STOP_DEPTH if confirm_stops else None)
            out[name] = scan.clip(out[name], model, sub, parent_of, closed, state, against == "stops", chain_open)
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
    """The scans of one joint (raw limits ``lo``, ``hi``, closed end ``qc``,
    opening direction ``d`` +-1 and range ``rng``, rad or m) against
    ``pairs``; ``base`` their baseline depths (P,) m once measured."""

    session: object
    name: str
    lo: float
    hi: float
    qc: float
    d: float
    rng: float
    pairs: list[tuple[str, str]]
    tol: float
    samples: int
    stop_depth: float | None
    base: np.ndarray | None = None

    def free_end(self, q_from: float, q_to: float, stop_depth: float | None = None,
                 samples: int | None = None) -> tuple[float, str | None]:
        """:func:`free_end` of the joint from ``q_from`` towards ``q_to``."""
        return free_end(self.session, self.name, q_from, q_to, self.pairs, self.base, self.tol,
                        self.samples if samples is None else samples, stop_depth)

    def onset(self, q_end: float, q_free: float) -> float:
        """:func:`contact_onset`, at most ``BACK_OFF_FRACTION`` of the range back from ``q_end``."""
        return contact_onset(self.session, self.name, q_end, q_free, self.pairs, self.base, BACK_OFF_FRACTION * self.rng)

    def clips(self, raw: float, end: float) -> bool:
        """Whether ``end`` lies inside the raw limit ``raw`` by more than ``MIN_CLIP_FRACTION`` of the range."""
        return abs(raw - end) > MIN_CLIP_FRACTION * self.rng

    def clip(self, clip: LimitClip, model: UrdfModel, sub: list[str], parent_of: dict[str, str],
             closed: dict[str, tuple[float, float, float]], state: dict[str, float], stops: bool,
             chain_open: bool) -> LimitClip:
        """Steps 1-6 of the module docstring: ``clip`` with the clipped
        limits, or the raw limits with a note when the part is blocked or
        the initial state lies outside the free range."""
        qs, depth = depth_scan(self.session, self.name, self.pairs, self.lo, self.hi, self.qc, self.samples)
        k_c = int(np.flatnonzero(qs == self.qc)[0])
        # baseline: a parent-child pair's depth at the closed end (a parent hull
        # filling the closed part's cavity: the hulls', not the limit's); any
        # other pair's least depth over the range (the sweep measures those
        # pairs: a closed end pressed into a sibling is not closed)
        adjacent = np.array([parent_of.get(a) == b or parent_of.get(b) == a for a, b in self.pairs])
        self.base = np.where(adjacent, depth[k_c], depth.min(axis=0))
        q_close = self.closed_end(clip, qs, depth, k_c) if stops else float(self.qc)
        if q_close is None:
            return clip
        far_raw, back_raw = (self.hi, self.lo) if self.d > 0 else (self.lo, self.hi)
        self.session.set_joint_positions({self.name: q_close})
        far, who = self.free_end(q_close, far_raw, self.stop_depth)
        span = abs(far - q_close)
        if span < MIN_FREE_FRACTION * self.rng:
            clip.notes.append(f"blocked at its closed end by {who} (free {span:.3g} of {self.rng:.3g}): collision geometry, limit kept")
            clip.blocked_by = who
            clip.notes = clip.notes[-1:]
            return clip
        chain_end = None
        if stops and chain_open:
            chain_end = _chain_far_end(self.session, model, self.name, sub, closed, state, q_close, far_raw, self.tol,
                                       self.samples, self.rng)
        far, who = self.far_end(clip, far, who, q_close, far_raw, chain_end)
        back = self.back_end(clip, q_close, back_raw, stops)
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
        """``qc``, or where the part first comes free towards the opening side
        when ``qc`` pushes into another link; None when it never does (rad or m)."""
        free = (depth - self.base).max(axis=1) <= self.tol
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
                chain_end: tuple[float, str | None, list[str]] | None) -> tuple[float, str | None]:
        """The limit on the opening side (rad or m) and the link run into:
        the carrying chain's end (step 6, :func:`_chain_far_end`) when
        nearer, else the free end ``far`` at its contact's onset when it
        clips ``far_raw``, else ``far_raw``."""
        side = "upper" if self.d > 0 else "lower"
        if chain_end is not None:
            far_c, who_c, opened = chain_end
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

    def back_end(self, clip: LimitClip, q_close: float, back_raw: float, stops: bool) -> float:
        """The limit beyond the closed end (rad or m): the new closed end when
        it moved, else (``stops`` only) the free end towards ``back_raw`` at
        its contact's onset when it clips ``back_raw``, else ``back_raw``."""
        side = "lower" if self.d > 0 else "upper"
        back = float(back_raw)
        if q_close != self.qc:
            back = q_close
            clip.notes.append(_limit_note(side, back_raw, back, "): the new closed end"))
        elif stops and self.clips(back_raw, self.qc):
            self.session.set_joint_positions({self.name: self.qc})
            b, who_b = self.free_end(self.qc, back_raw, self.stop_depth)
            if self.clips(back_raw, b):
                back = b = self.onset(b, self.qc)
                clip.notes.append(_limit_note(side, back_raw, b, f", beyond the closed end): runs into {who_b}"))
        return back


def apply_clips(overlay: Overlay, clips: dict[str, LimitClip]) -> tuple[Overlay, list[str]]:
    """The overlay with the clipped limits of ``clips`` in its joints'
    ``lower`` / ``upper`` (and ``limit_source``), plus one note per clipped
    joint (also added to ``overlay.notes.other``). Joints not clipped are unchanged."""
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


def clipped_closed(closed: dict, clips: dict[str, LimitClip]) -> dict:
    """``closed`` (joint -> :class:`~asset2sim.tasks.geometry.closed_state.ClosedState`)
    with the clipped joints' limits and opening range."""
    out = dict(closed)
    for name, c in clips.items():
        if name in out and c.clipped:
            out[name] = replace(out[name], q_closed=c.q_closed, lower=c.lower, upper=c.upper, open_range=c.open_range)
    return out


def strip_clips(overlay: Overlay) -> Overlay:
    """The overlay without clipped limits (every joint's ``lower`` /
    ``upper`` None, ``limit_source`` empty): the raw limits are written again."""
    ov = overlay.model_copy(deep=True)
    for name, dyn in ov.joints.items():
        if dyn.lower is not None or dyn.upper is not None or dyn.limit_source:
            ov.joints[name] = dyn.model_copy(update={"lower": None, "upper": None, "limit_source": ""})
    ov.notes.other = [n for n in ov.notes.other if not n.startswith("limit clipped to the geometry: ")]
    return ov
