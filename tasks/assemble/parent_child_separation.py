"""Parent and child separated: the overlap of a child's pieces with its
parent's, at the pose the meshes were modelled in and wherever the joint
carries it, cut off one of the two pieces (:func:`separate_parent_child`)."""

from __future__ import annotations

from collections.abc import Callable, Collection

import numpy as np

from asset2sim import urdf
from asset2sim.tasks.assemble.convex_pieces import CONTAINMENT_TOLERANCE, MAX_PIECES_HARD, Piece, clip_piece, posed
from asset2sim.tasks.assemble.joint_sweep import _joint_motion, _positions_for, reference_state
from asset2sim.tasks.assemble.piece_penetration import _transformed, penetration_depth
from asset2sim.tasks.geometry import limits

#: Overlap (m) along the separating direction that :func:`separate_parent_child` leaves between a parent's and its
#: child's pieces: touching.
SEPARATION_GAP = 0.0
#: Deepest overlap cut at a state inside the range that the pair is clear of at the modelled pose: the limit scan's
#: :data:`~asset2sim.tasks.geometry.limits.STOP_DEPTH` (m) or this fraction of the child's largest extent, the larger
#: (dev doors in their frames: 1-2 %); deeper, the state lies past a stop (a door through a bar of its own body, 16 %).
#: Overlapping as modelled too, or at a limit (within :data:`AT_LIMIT_FRACTION` of the range: folded eyeglasses'
#: temples at the closed end; a lever's closed end found 1 % inside its raw limit, in its slot), any overlap is cut.
STATE_CUT_DEPTH, STATE_CUT_FRACTION, AT_LIMIT_FRACTION, PAST_STOP_NOTE = limits.STOP_DEPTH, 0.05, 0.05, "past a stop"


def _carried(depth: Callable[[int], float], n: int, ref: int) -> list[int]:
    """Indices of the ``n`` positions (ordered over the range) whose depth
    (m, ``depth(i)``) the joint carries from its reference position ``ref``:
    the run of depths above :data:`CONTAINMENT_TOLERANCE` m that contains ``ref`` (empty when
    it is clear; a depth reached after moving clear is a stop)."""
    if depth(ref) <= CONTAINMENT_TOLERANCE:
        return []
    lo = hi = ref
    while lo > 0 and depth(lo - 1) > CONTAINMENT_TOLERANCE:
        lo -= 1
    while hi < n - 1 and depth(hi + 1) > CONTAINMENT_TOLERANCE:
        hi += 1
    return list(range(lo, hi + 1))


def separate_parent_child(model: urdf.UrdfModel, pieces: dict[str, list[Piece]], notes: list[str],
                          state: dict[str, float] | None = None, joints: Collection[str] | None = None) -> None:
    """Clip, in place, the pieces of every parent and child link so that no
    child piece penetrates a parent piece deeper than :data:`CONTAINMENT_TOLERANCE` m
    (:func:`penetration_depth`) at the joint's reference position
    (:func:`reference_state`) and at every position the overlap is carried
    to from there (:func:`_carried`; an overlap met only after moving clear
    is a stop, left to the limit scan); with ``state`` (joint -> rad or m),
    at that state only. Each overlap is removed along its separating
    direction by cutting one of the two pieces (:func:`clip_piece`, up to
    :data:`SEPARATION_GAP`): the side beyond the plane, or a slot
    (:func:`_slot`, at most :data:`SLOT_PIECES` parts and
    :data:`MAX_PIECES_HARD` per link), whichever of the four removes the
    smallest share of its link's volume; a link's last piece is never
    removed (such an overlap is kept and noted); at ``state``, an overlap
    deeper than :data:`STATE_CUT_DEPTH` (or :data:`STATE_CUT_FRACTION`) is a stop the state lies past, kept
    and noted, unless the pair overlaps at the modelled pose too, the child is
    pressed into its parent from that pose on (:func:`_is_stop`) or the joint
    is at a limit. ``joints``: only these joints' pairs (None: every joint)."""
    for joint in model.joints:  # parent and child (P, C: their pieces) cut apart pair by pair; a note when they overlapped
        P, C = pieces.get(joint.parent), pieces.get(joint.child)
        if (joints is not None and joint.name not in joints) or not (P and C):
            continue
        deepest_cut, T_ref, T_near = np.inf, None, None
        if state is None:
            # the child's poses at every position of sweep_positions over the range (reach: its pieces), and the one
            # nearest the reference state
            qs = _positions_for(joint, np.vstack([p.points for p in C]))
            transforms = [_joint_motion(joint, q) for q in qs]
            ref = int(np.argmin(np.abs(qs - reference_state(model).get(joint.name, 0.0))))
        else:
            q_ref = reference_state(model).get(joint.name, 0.0)
            q = float(state.get(joint.name, q_ref))
            size = float(np.ptp(np.vstack([c.points for c in C if c is not None]), axis=0).max())
            transforms, ref, T_ref = [_joint_motion(joint, q)], 0, _joint_motion(joint, q_ref)
            T_near = _toward(joint, q_ref, q)
            deepest_cut = np.inf if _at_limit(joint, q) else max(STATE_CUT_DEPTH, STATE_CUT_FRACTION * size)
        sizes = {"p": sum(p.volume for p in P), "c": sum(c.volume for c in C)}
        before = after = past = 0.0
        cut, kept = {"p": set(), "c": set()}, 0
        i = 0
        while i < len(P):
            k = 0
            while k < len(C) and P[i] is not None:
                overlap = None if C[k] is None else _pair_cuts(P[i], C[k], transforms, ref)
                if overlap is not None and overlap[0] > deepest_cut and _is_stop(P[i], C[k], T_ref, T_near):
                    past = max(past, overlap[0])  # met only after moving clear of the modelled pose: a stop
                    overlap = None
                if overlap is not None:
                    depth, deepest, cuts = overlap
                    before = max(before, depth)
                    options = (_cut_options("p", P[i], sizes["p"], _others(P, i), *cuts["p"], MAX_PIECES_HARD - len(P))
                               + _cut_options("c", C[k], sizes["c"], _others(C, k), *cuts["c"], MAX_PIECES_HARD - len(C)))
                    if not options:
                        kept, after = kept + 1, max(after, deepest)
                    else:
                        _, _, which, parts = min(options, key=lambda o: (o[0], o[1]))
                        target, idx = (P, i) if which == "p" else (C, k)
                        target[idx] = parts[0] if parts else None
                        target.extend(parts[1:])
                        cut[which].add(idx)
                k += 1
            i += 1
        gone = sum(p is None for p in P) + sum(c is None for c in C)
        P[:] = [p for p in P if p is not None]
        C[:] = [c for c in C if c is not None]
        if before > 0.0:  # the pieces cut, removed whole and held whole; swept from the reference position on without a state
            n_p, n_c = len(cut["p"]), len(cut["c"])
            what = ", ".join(x for x in (f"{n_p} of {joint.parent!r}'s pieces" if n_p else "",
                                         f"{n_c} of {joint.child!r}'s" if n_c else "") if x)
            notes.append(f"joint {joint.name!r}: {joint.child!r} penetrated its parent {joint.parent!r} up to "
                         f"{before * 1000:.3g} mm "
                         + ("from its reference position on" if state is None else "at the initial state")
                         + f"; cut {what or 'nothing'}"
                         + (f" ({gone} removed whole)" if gone else "")
                         + (f"; {kept} overlap(s) of a link's last piece held whole inside another kept ({after * 1000:.3g} mm)"
                            if kept else ""))
        if past > 0.0:
            notes.append(f"joint {joint.name!r}: {joint.child!r} lies {past * 1000:.3g} mm inside its parent "
                         f"{joint.parent!r} at the initial state, {PAST_STOP_NOTE} (too deep to cut): the pieces are kept, "
                         "not cut")


def _depth_at(a: Piece, b: Piece, T: np.ndarray) -> tuple[float, np.ndarray]:
    """(depth m, separating direction (3,)) of parent piece ``a`` and child piece ``b`` at the child pose ``T`` (4, 4)
    (:func:`penetration_depth`; (0, 0) when their axis-aligned boxes are more than 1e-9 m (rounding) apart, found
    without moving ``b``'s planes)."""
    moved = posed(b.points, T)
    if np.any(np.minimum(a.points.max(axis=0), moved.max(axis=0)) + 1e-9 < np.maximum(a.points.min(axis=0), moved.min(axis=0))):
        return 0.0, np.zeros(3)
    return penetration_depth(a, _transformed(b, T), CONTAINMENT_TOLERANCE)


def _is_stop(a: Piece, b: Piece, T_ref: np.ndarray, T_near: np.ndarray | None) -> bool:
    """Whether parent piece ``a`` and child piece ``b``, overlapping at the state, meet at a stop: clear at the modelled
    pose ``T_ref`` (4, 4) (within :data:`CONTAINMENT_TOLERANCE` m), and not touching there and pressed deeper a step
    toward the state (``T_near``, :func:`_toward`). A part in contact with its parent at its modelled pose and driven
    into it from there on (a button pressed into a body drawn solid behind it, its recess not modelled) meets no stop:
    the limit scan keeps its limit (``limits.MIN_FREE_FRACTION``), and its pieces are cut at the state as at a limit. A
    part clear of its parent at its modelled pose that runs into it (a door into a bar of its body 2 cm in front of it)
    meets a stop."""
    at_ref = _depth_at(a, b, T_ref)[0]
    if at_ref > CONTAINMENT_TOLERANCE:
        return False
    return T_near is None or at_ref <= PRESSED_GROWTH or _depth_at(a, b, T_near)[0] <= at_ref + PRESSED_GROWTH


def _toward(joint: urdf.UrdfJoint, q_ref: float, q: float) -> np.ndarray | None:
    """The child's pose (4, 4) :data:`limits.MIN_FREE_FRACTION` of ``joint``'s range from ``q_ref`` toward ``q`` (rad or
    m); None without finite limits or when ``q`` is nearer than that."""
    step = limits.MIN_FREE_FRACTION * (joint.upper - joint.lower)
    if not (np.isfinite(step) and step > 0) or abs(q - q_ref) <= step:
        return None
    return _joint_motion(joint, q_ref + np.sign(q - q_ref) * step)


#: Growth of a pair's depth (m) a step toward the state past which the child is pressed into its parent from its modelled
#: pose on (:func:`_is_stop`).
PRESSED_GROWTH = 1e-4


def _at_limit(joint: urdf.UrdfJoint, q: float) -> bool:
    """Whether ``q`` (rad or m) lies within :data:`AT_LIMIT_FRACTION` of ``joint``'s range from one of its finite limits."""
    lo, hi = joint.lower, joint.upper
    if not (np.isfinite(lo) and np.isfinite(hi)) or hi <= lo:
        return False
    return min(abs(q - lo), abs(q - hi)) <= AT_LIMIT_FRACTION * (hi - lo)


def _pair_cuts(a: Piece, b: Piece, transforms: list[np.ndarray], ref: int) -> tuple[float, float, dict] | None:
    """Parent piece ``a`` and child piece ``b`` (child frame) at the child poses ``transforms`` (4, 4) the overlap is
    carried to from ``ref`` (:func:`_carried`): None when they are clear at ``ref``, else (deepest carried depth m,
    deepest depth measured m, ``"p"`` / ``"c"`` -> (half-spaces, slots) that cut that piece off the other, in its frame)."""
    found: dict[int, tuple[float, np.ndarray]] = {}

    def depth_at(t: int) -> float:
        """The pair's depth (m) at position ``t`` (kept in ``found``)."""
        if t not in found:
            found[t] = _depth_at(a, b, transforms[t])
        return found[t][0]

    carried = _carried(depth_at, len(transforms), ref)
    if not carried:
        return None
    planes_p, planes_c, slots_p, slots_c = [], [], [], []
    depth = 0.0
    for t in carried:
        T, (d, n) = transforms[t], found[t]
        c = _transformed(b, T)
        depth = max(depth, d)
        # a on the low side along n: keep n.x <= min(c.n) + gap, or c above max(a.n) - gap
        cn, an = c.points @ n, a.points @ n
        lo_c, hi_p = float(cn.min()), float(an.max())
        planes_p.append((n, -(lo_c + SEPARATION_GAP)))
        nc = T[:3, :3].T @ n  # the same direction in the child frame
        shift = float(n @ T[:3, 3])
        planes_c.append((-nc, hi_p - SEPARATION_GAP - shift))
        # or a slot: the band the other piece spans along n taken out (two pieces left)
        slots_p.append((n, lo_c + SEPARATION_GAP, float(cn.max()) - SEPARATION_GAP, c))
        slots_c.append((nc, float(an.min()) - shift + SEPARATION_GAP, hi_p - shift - SEPARATION_GAP,
                        _transformed(a, np.linalg.inv(T))))
    # the positions not carried read <= tolerance, so the deepest measured is the deepest carried
    return depth, max(d for d, _ in found.values()), {"p": (planes_p, slots_p), "c": (planes_c, slots_c)}


def _cut_options(which: str, piece: Piece, size: float, others: bool, planes: list, slots: list,
                 room: int) -> list[tuple[float, int, str, list[Piece]]]:
    """The cuts of ``piece`` (of link ``which``, whose pieces hold ``size`` m^3; ``others``: it has other pieces) that
    clear the pair: every half-space of ``planes`` (:func:`_clip_all`), or the ``slots`` (:func:`_slot`, ``room``
    pieces to spare), each (share of the link's volume removed, parts left, ``which``, parts)."""
    out = []
    for parts in ([_clip_all(piece, planes)], _slot(piece, slots, min(SLOT_PIECES, 1 + max(room, 0)))):
        if parts is None:
            continue
        parts = [q for q in parts if q is not None]
        if not parts and not others:  # a link's last piece is never removed
            continue
        out.append(((piece.volume - sum(q.volume for q in parts)) / size, len(parts), which, parts))
    return out


def _clip_all(piece: Piece, planes: list[tuple[np.ndarray, float]]) -> Piece | None:
    """``piece`` cut by every half-space ``n . x + offset <= 0`` of ``planes``
    (:func:`clip_piece` in turn); None when nothing with volume is left."""
    for n, off in planes:
        if piece is None:
            return None
        if float((piece.points @ n).max()) + off <= 0.0:
            continue
        piece = clip_piece(piece, n, off)
    return piece


#: Most pieces :func:`_slot` leaves of one piece.
SLOT_PIECES = 4


def _slot(piece: Piece, slots: list[tuple[np.ndarray, float, float, Piece]], most: int) -> list[Piece] | None:
    """``piece`` with, for each slot (n (3,) unit, lo, hi m, other piece), the
    band ``lo < n . x < hi`` taken out of every part that still penetrates
    the other piece deeper than :data:`CONTAINMENT_TOLERANCE` m; None when more than
    ``most`` parts would be left."""
    parts = [piece]
    for n, lo, hi, other in slots:
        parts = [x for q in parts for x in ((q,) if penetration_depth(q, other, CONTAINMENT_TOLERANCE)[0] <= CONTAINMENT_TOLERANCE
                                              else (clip_piece(q, n, -lo), clip_piece(q, -n, hi))) if x is not None]
        if len(parts) > most:
            return None
    return parts


def _others(pieces: list[Piece | None], i: int) -> bool:
    """Whether ``pieces`` holds a piece besides the ``i``-th (removed ones are None)."""
    return any(p is not None for j, p in enumerate(pieces) if j != i)
